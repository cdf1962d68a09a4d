"""All tests share one Taichi CPU runtime, so every kernel compiles once per session."""
import pytest

from pbf.solver import start_backend


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    start_backend("cpu", quiet=True)
