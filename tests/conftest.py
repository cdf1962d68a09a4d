"""All tests share one Taichi CPU runtime, compiled for speed of compiling: each Simulation compiles
its kernels anew, and without Taichi's advanced optimisation that takes 1.6 s instead of 6.2 s, with
the same results up to rounding (see pbf.solver.backend.start_backend)."""
import pytest

from pbf.solver.backend import restart_backend, start_backend


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    start_backend("cpu", quiet=True, fast_compile=True)


@pytest.fixture(scope="module", autouse=True)
def fresh_taichi_per_module(taichi_cpu):
    """Each test module frees the fields and kernels of the one before: Taichi holds every
    Simulation's compiled kernels until it is reset, and the whole suite in one runtime peaked at
    1.4-1.6 GB (the limit is 1.5 GB)."""
    yield
    restart_backend()
