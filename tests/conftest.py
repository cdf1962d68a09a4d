"""The tests run in two worker processes by default (pytest-xdist, ``-n 2`` in pyproject.toml's
addopts), one per core of the 2-core machine the suite is sized for, each test file whole on one worker
(``--dist loadfile``: a module's shared fixtures are built once); a later ``-n`` wins, so
``python -m pytest -n 0`` runs one process (as a debugger wants) and ``-n auto`` one worker per core
(CONTRIBUTING.md). Each worker runs one Taichi CPU runtime compiled for speed of compiling: each
Simulation compiles its kernels anew, and without Taichi's advanced optimisation that is several
times quicker, with the same results up to rounding (see pbf.solver.backend.start_backend)."""

import os

import pytest

# Under pytest (a worker's stdout is pytest-xdist's, not the console's) Taichi takes itself to be in a
# graphical shell and logs "[I …] Graphical python shell detected, using wrapped sys.stdout", which
# then shows after the run's summary. Its own print buffer is for notebooks; the tests print nothing
# from kernels, so it is switched off before Taichi is imported.
os.environ.setdefault("TI_ENABLE_PYBUF", "0")

from pbf.solver.backend import restart_backend, start_backend  # noqa: E402 (after Taichi's setting)

# Taichi's on-disk kernel cache (~/.cache/taichi) keeps 100 MB by default, and the suite's kernels take
# more, so each run evicted what the next needed and a second run took as long as the first. With room
# for them a second run reuses them (CONTRIBUTING.md). An explicit TI_ setting of the user's still wins.
os.environ.setdefault("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", str(1 << 29))


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    # Under pytest-xdist each worker takes one Taichi thread (one worker per core); alone, all cores.
    threads = 1 if os.environ.get("PYTEST_XDIST_WORKER") else None
    start_backend("cpu", quiet=True, fast_compile=True, cpu_threads=threads)


@pytest.fixture(scope="module", autouse=True)
def fresh_taichi_per_module(taichi_cpu):
    """Each test module frees the fields and kernels of the one before: Taichi holds every
    Simulation's compiled kernels until it is reset, and the whole suite in one runtime outgrew the
    1.5 GB the default run may take."""
    yield
    restart_backend()
