"""Running the command line as a user does, and what every refusal must look like."""

import subprocess
import sys
from pathlib import Path

from pbf.app import cli

RUN = Path(__file__).resolve().parent.parent / "run.py"


def run_cli(*args, cwd, env=None, timeout=120) -> subprocess.CompletedProcess:
    """``python run.py ARGS`` in a fresh process, in ``cwd`` (where a default out/ would appear)."""
    return subprocess.run(
        [sys.executable, str(RUN), *map(str, args)], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )


def files_under(folder: Path) -> set[Path]:
    return set(folder.rglob("*"))


def assert_one_error(stderr: str, *names: str) -> str:
    """stderr is one line, ``error: …``, naming each of ``names``: no traceback, no NumPy repr."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    for name in names:
        assert name in lines[0], (name, lines[0])
    assert "np.float" not in lines[0] and "np.int" not in lines[0], lines[0]
    return lines[0]


def refused(capsys, argv, *names, cwd: Path) -> str:
    """Run ``cli.main(argv)`` in-process from ``cwd``: it must return 2 with one error line naming
    ``names`` and write nothing under ``cwd``. Returns the line."""
    before = files_under(cwd)
    capsys.readouterr()
    assert cli.main([str(a) for a in argv]) == 2
    captured = capsys.readouterr()
    assert files_under(cwd) == before, "a refused run wrote files"
    return assert_one_error(captured.err, *names)
