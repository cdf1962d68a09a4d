"""A command whose output is piped to a reader that stops early (``pbf --list | head -1``) ends
quietly with status 0: the reader has what it wanted, and a traceback would only hide it."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PBF = Path(sys.executable).with_name("pbf")  # the console script, beside the interpreter that installed it

COMMANDS = {
    "run.py --list": [sys.executable, str(ROOT / "run.py"), "--list"],
    "run.py --keys": [sys.executable, str(ROOT / "run.py"), "--keys"],
    "run.py --help": [sys.executable, str(ROOT / "run.py"), "--help"],
    "pbf --list": [str(PBF), "--list"],
    "pbf --keys": [str(PBF), "--keys"],
    **{
        f"python -m pbf.study.{study} --help": [sys.executable, "-m", f"pbf.study.{study}", "--help"]
        for study in ("sweep", "damping", "headline", "validate")
    },
}


def into_a_closed_pipe(command: list[str]) -> subprocess.CompletedProcess:
    """Run ``command`` with its stdout a pipe whose reader has already gone: its first write fails,
    as after ``| head -1`` once head has read its line."""
    reader, writer = os.pipe()
    os.close(reader)
    try:
        return subprocess.run(command, stdout=writer, stderr=subprocess.PIPE, text=True, cwd=ROOT, timeout=120)
    finally:
        os.close(writer)


@pytest.mark.parametrize("name", COMMANDS)
def test_a_listing_into_a_closed_pipe_ends_quietly(name):
    if name.startswith("pbf ") and not PBF.exists():
        pytest.skip("the pbf console script is not installed beside this interpreter")
    done = into_a_closed_pipe(COMMANDS[name])
    assert (done.returncode, done.stderr) == (0, ""), done.stderr[-2000:]


def test_a_study_that_prints_into_a_closed_pipe_ends_quietly():
    # A study's table is printed as it runs; the pipe may close at any line of it.
    table = "from pbf.study.common import run_command; run_command(lambda: print('row\\n' * 100_000))"
    done = into_a_closed_pipe([sys.executable, "-c", table])
    assert (done.returncode, done.stderr) == (0, ""), done.stderr[-2000:]


@pytest.mark.parametrize("path", sorted((ROOT / "pbf" / "study").glob("*.py")), ids=lambda path: path.name)
def test_every_study_command_runs_through_run_command(path):
    text = path.read_text()
    if 'if __name__ == "__main__":' in text:
        assert text.endswith('if __name__ == "__main__":\n    run_command(main)\n'), path.name
