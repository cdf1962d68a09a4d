"""The tests run in two worker processes (pytest-xdist, ``-n 2`` in pyproject.toml), one per core,
each with one Taichi CPU runtime compiled for speed of compiling: each Simulation compiles its
kernels anew, and without Taichi's advanced optimisation that takes 1.6 s instead of 6.2 s, with the
same results up to rounding (see pbf.solver.backend.start_backend)."""
import os

import pytest

from pbf.solver.backend import restart_backend, start_backend

# Taichi's on-disk kernel cache (~/.cache/taichi) keeps 100 MB by default, and the suite's kernels take
# 140-160 MB, so each run evicted what the next needed: a second run took as long as the first (2 min
# 55 s). With room for them it takes 1 min 55 s. An explicit TI_ setting of the user's still wins.
os.environ.setdefault("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", str(1 << 29))


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    # pytest-xdist (pyproject.toml: -n 2) runs two workers on the two cores: one Taichi thread each.
    threads = 1 if os.environ.get("PYTEST_XDIST_WORKER") else None
    start_backend("cpu", quiet=True, fast_compile=True, cpu_threads=threads)


@pytest.fixture(scope="module", autouse=True)
def fresh_taichi_per_module(taichi_cpu):
    """Each test module frees the fields and kernels of the one before: Taichi holds every
    Simulation's compiled kernels until it is reset, and the whole suite in one runtime peaked at
    1.4-1.6 GB (the limit is 1.5 GB)."""
    yield
    restart_backend()
