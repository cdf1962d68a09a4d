"""What the lab's scripts share: an earlier commit's package, a run in a fresh process, image sizes,
whole numbers of at least one, medians with their range, Markdown tables, and wall and CPU time taken
together."""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import tarfile
import time
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parent.parent


def revision(given: str) -> str | None:
    """The commit ``given`` names in this checkout, or None where git does not know it (or is absent)."""
    try:
        done = subprocess.run(
            ["git", "-C", str(CHECKOUT), "rev-parse", "--verify", "--quiet", f"{given}^{{commit}}"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return (done.returncode == 0 and done.stdout.strip()) or None


def export(commit: str, into: Path) -> Path:
    """The checkout's tree at ``commit`` (package, scenes) written under ``into`` by ``git archive``: no
    work tree, nothing for git to remember."""
    archive, folder = into / f"{commit[:12]}.tar", into / commit[:12]
    with archive.open("wb") as out:
        subprocess.run(["git", "-C", str(CHECKOUT), "archive", commit], stdout=out, check=True, timeout=600)
    folder.mkdir()
    with tarfile.open(archive) as tar:
        try:
            tar.extractall(folder, filter="data")  # the archive's own files only (Python 3.11.4 and later)
        except TypeError:  # an older Python: git's own archive of its own commit
            tar.extractall(folder)
    archive.unlink()
    return folder


class RunFailed(Exception):
    """A fresh process that failed or ran out of time: why, in a line, and what it printed before."""

    def __init__(self, why: str, output: str = ""):
        super().__init__(why)
        self.output = output


def fresh(command: list, first_on_path=(), timeout: float | None = None, cwd=None, **env) -> str:
    """What ``command`` prints, run in a process of its own with the folders ``first_on_path`` ahead of
    PYTHONPATH (a version's package, this checkout's lab) and ``env`` added to the environment."""
    path = os.pathsep.join([*map(str, first_on_path), *filter(None, [os.environ.get("PYTHONPATH")])])
    try:
        done = subprocess.run(command, cwd=cwd, env={**os.environ, **env, "PYTHONPATH": path}, capture_output=True,
                              text=True, timeout=timeout)  # fmt: skip
    except subprocess.TimeoutExpired:
        raise RunFailed(f"over {timeout:g} s") from None
    if done.returncode != 0:
        last = [line for line in (done.stderr or done.stdout).splitlines() if line.strip()][-1:] or ["no output"]
        raise RunFailed(last[0].strip(), done.stdout)
    return done.stdout


def image_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` in pixels, each side 16 to 8192 (an argparse type)."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WIDTHxHEIGHT, e.g. 1280x720") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise argparse.ArgumentTypeError(f"{text!r}: each side between 16 and 8192 pixels")
    return width, height


def at_least(minimum: int):
    """An argparse type: a whole number of at least ``minimum`` (rounds, repeats, threads)."""

    def whole(text: str) -> int:
        value = int(text) if text.lstrip("-").isdigit() else None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"at least {minimum}, not {text!r}")
        return value

    return whole


def spread(values, digits: int = 2) -> str:
    """``median (least-most)``."""
    values = list(values)
    return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f}-{max(values):.{digits}f})"


def markdown(header, rows) -> str:
    """A Markdown table as the docs quote it: the first column left-aligned, the figures right."""
    lines = ["| " + " | ".join(map(str, cells)) + " |" for cells in [header, *rows]]
    return "\n".join([lines[0], "|---|" + "---:|" * (len(header) - 1), *lines[1:]])


def medians(pairs) -> tuple[float, ...]:
    """The median of each column of ``pairs`` (such as (wall, CPU) seconds)."""
    return tuple(statistics.median(column) for column in zip(*pairs))


class Clock:
    """Wall and process CPU seconds (every thread's), started when made: ``wall, cpu = clock.lap()``."""

    def __init__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()

    def lap(self) -> tuple[float, float]:
        """The seconds since the start or the last lap, and a new start."""
        wall, cpu = time.perf_counter(), time.process_time()
        spent, (self.wall, self.cpu) = (wall - self.wall, cpu - self.cpu), (wall, cpu)
        return spent
