"""Rules for the tests themselves, read from their source: a test passes or fails by what the code
does, never by how busy the machine it runs on is."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
CLOCKS = {"perf_counter", "perf_counter_ns", "monotonic", "monotonic_ns", "time", "time_ns", "process_time"}


def _reads_clock(node: ast.AST, timed: set[str]) -> bool:
    """Whether ``node`` calls one of the clocks or reads a name assigned from one."""
    for part in ast.walk(node):
        if isinstance(part, ast.Call) and isinstance(part.func, ast.Attribute) and part.func.attr in CLOCKS:
            if isinstance(part.func.value, ast.Name) and part.func.value.id == "time":
                return True
        if isinstance(part, ast.Name) and part.id in timed:
            return True
    return False


def clock_assertions(source: str) -> list[int]:
    """The lines of the asserts whose condition depends on a clock: directly (``assert
    time.perf_counter() - start < 2``) or through a name (``wall = time.perf_counter() - began``)."""
    tree = ast.parse(source)
    timed: set[str] = set()
    while True:  # names assigned from clocks or from names assigned from clocks, until none is new
        found = {
            target.id
            for node in ast.walk(tree)
            if isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None
            for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
            if isinstance(target, ast.Name) and _reads_clock(node.value, timed)
        }
        if found <= timed:
            break
        timed |= found
    # A clock in an assert's message only reports; it is the condition that passes or fails.
    return [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Assert) and _reads_clock(node.test, timed)]


def test_the_rule_sees_a_clock_directly_and_through_a_name():
    assert clock_assertions("import time\nstart = time.perf_counter()\nassert time.perf_counter() - start < 2.0\n")
    assert clock_assertions("import time\nt0 = time.monotonic()\nwall = time.monotonic() - t0\nassert wall < 5\n")
    assert not clock_assertions("import time\nt0 = time.time()\nassert 1 + 1 == 2, f'{time.time() - t0:.1f} s'\n")


@pytest.mark.parametrize("path", sorted(TESTS.glob("*.py")), ids=lambda path: path.name)
def test_no_test_asserts_a_wall_clock_time(path):
    lines = clock_assertions(path.read_text())
    assert not lines, (
        f"{path.name}: lines {lines} assert a wall-clock time, which fails on a busy machine; count the "
        f"work instead (calls, launches, compiles), or time it in a benchmark script under benchmarks/"
    )


def test_a_test_run_shows_no_noise_of_taichis():
    # One test in one pytest-xdist worker, as the default run starts its workers, in an environment
    # without this run's settings: Taichi's expected deprecation warning and its log line about a
    # "graphical python shell" (pytest's stdout is not the console's) must not show.
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "TI_ENABLE_PYBUF"))}
    test = "tests/test_suite_rules.py::test_the_rule_sees_a_clock_directly_and_through_a_name"
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-n", "1", "-p", "no:cacheprovider", test],
        cwd=TESTS.parent,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-3000:]
    assert "Graphical python shell" not in output, output[-3000:]
    assert "DeprecationWarning" not in output and "warning" not in output.splitlines()[-1], output[-3000:]
