"""The study wing: benchmarks (``bench``), the speed-against-error sweep (``sweep``) and validation
against experiment and theory (``validate``), with their shared helpers in ``common``."""
