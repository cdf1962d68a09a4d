"""Taichi's banner never shows: a run prints pbf's one "Starting on" line, which names Taichi's version,
and neither "[Taichi] version …" (printed when Taichi is imported) nor "[Taichi] Starting on …"
(printed by ti.init)."""

import os
import re
import subprocess
import sys

import pytest
import taichi as ti
from command_line import run_cli

BANNER = "[Taichi] version"
STARTING = re.compile(
    r"\[pbf\] Starting on cpu \((x64|arm64), requested\), Taichi " + re.escape(".".join(map(str, ti.__version__)))
)
SWITCH = "ENABLE_TAICHI_HEADER_PRINT"
"""Taichi's own switch for its banner, which ``pbf/__init__.py`` sets; the pytest process inherits
it, so the subprocesses below run without it, as a user's shell would."""


@pytest.fixture
def user_env():
    env = dict(os.environ)
    env.pop(SWITCH, None)
    return env


def test_without_pbf_taichi_prints_its_banner(user_env):
    # What the tests below guard against: a bare import of Taichi in a user's environment.
    result = subprocess.run(
        [sys.executable, "-c", "import taichi"], env=user_env, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0 and BANNER in result.stdout


def test_a_run_prints_one_starting_line_and_no_taichi_banner(tmp_path, user_env):
    result = run_cli("dam_break", "--stats-only", "--frames", "1", "--arch", "cpu", cwd=tmp_path, env=user_env)
    assert result.returncode == 0, result.stderr
    output = result.stdout + result.stderr
    assert "[Taichi]" not in output, output
    starting = [line for line in output.splitlines() if "Starting on" in line]
    assert len(starting) == 1 and STARTING.fullmatch(starting[0]), output


@pytest.mark.parametrize(
    "argv",
    [["--help"], ["--list"], ["no_such_scene"], ["dam_break", "--arch", "cuda", "--stats-only", "--frames", "1"]],
    ids=["help", "list", "bad-scene", "backend-error"],
)
def test_help_list_and_errors_print_no_taichi_banner(tmp_path, user_env, argv):
    result = run_cli(*argv, cwd=tmp_path, env=user_env)
    output = result.stdout + result.stderr
    assert BANNER not in output and "[Taichi] Starting" not in output, output


def test_a_module_entry_point_prints_no_taichi_banner(user_env):
    # python -m pbf.study.sweep and friends: the package is imported before the module, and with it the switch.
    code = "import pbf.study.common, taichi; from pbf.solver import start_backend; start_backend('cpu')"
    result = subprocess.run([sys.executable, "-c", code], env=user_env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert BANNER not in result.stdout + result.stderr
    starting = [line for line in result.stdout.splitlines() if "Starting on" in line]
    assert len(starting) == 1 and STARTING.fullmatch(starting[0]), result.stdout
