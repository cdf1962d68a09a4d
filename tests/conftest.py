"""All tests share one Taichi CPU runtime, compiled for speed of compiling: each Simulation compiles
its kernels anew, and without Taichi's advanced optimisation that takes 1.6 s instead of 6.2 s, with
the same results (see pbf.solver.backend.start_backend)."""
import pytest

from pbf.solver import start_backend


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    start_backend("cpu", quiet=True, fast_compile=True)
