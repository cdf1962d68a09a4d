"""What a user runs to report speed against error and to validate: the sweep (``sweep``), the validation
against experiment and theory (``validate``, with ``spheric`` and ``damping``), the README's headline
table (``headline``), and their shared helpers (``common``). The lab's other tools live in ``benchmarks/``."""
