"""The application wing: the command line (``cli``), the loop and its viewers (``loop``, ``window``,
``headless``), the renderer (``render``) and particle export (``export``). It uses only the solver's
public face, ``pbf.solver``."""
