"""The README's shell commands, run in the order a newcomer meets them, from a fresh copy: each must
work after the ones before it (they once refused one another over out/dam_break), with frames cut
short so that the whole takes a minute or two."""

import os
import re
import shlex
import stat
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
FRAMES = "2"
"""Frames each command runs instead of its own: enough to write a frame, a video and files after the start."""
SKIPPED = {
    "pip install": "installing is the test environment's own set-up; the commands after it run",
    "python3 -m venv": "installing is the test environment's own set-up; the commands after it run",
    ". .venv/bin/activate": "installing is the test environment's own set-up; the commands after it run",
    "python -m pytest": "the test suite itself, which this test is part of",
}
"""Parts of a command chain (``a && b``) that are not run, and why. Commands that open a window run
anyway, where none can open (no DISPLAY), so they take the headless fallback the README promises."""


def commands() -> list[str]:
    """The README's commands in order: every line of its ```bash blocks (comments dropped) and every
    inline `python run.py …` (the figure captions' and the text's). The studies and benchmark scripts
    it names in passing (``python -m pbf.study…``, ``benchmarks/…``) take minutes and have their own
    smoke tests in tests/test_benchmark_scripts.py."""
    text = README.read_text(encoding="utf-8")
    found = []
    for block in re.finditer(r"^```bash\n(.*?)^```", text, flags=re.DOTALL | re.MULTILINE):
        for line in block.group(1).splitlines():
            command = re.sub(r"\s+#.*$", "", line).strip()
            if command:
                found.append((block.start(), command))
    outside = re.sub(r"^```.*?^```", lambda m: " " * len(m.group(0)), text, flags=re.DOTALL | re.MULTILINE)
    for span in re.finditer(r"`(python run\.py[^`]*)`", outside):
        found.append((span.start(), span.group(1)))
    return [command for _, command in sorted(found)]


def runnable(command: str) -> str | None:
    """``command`` as the test runs it: the chain's skipped parts dropped, ``--frames N`` cut to
    FRAMES (added where a run would take its default 180 frames, or run until its window closes)."""
    parts = [p.strip() for p in command.split("&&")]
    parts = [p for p in parts if not any(p.startswith(skipped) for skipped in SKIPPED)]
    shortened = []
    for part in parts:
        words = shlex.split(part)
        if words[:2] == ["python", "run.py"] and not {"--help", "--list", "--keys"} & set(words):
            if "--frames" in words:
                part = re.sub(r"--frames \d+", f"--frames {FRAMES}", part)
            else:
                part += f" --frames {FRAMES}"
        shortened.append(part)
    return " && ".join(shortened) or None


def test_the_readme_commands_are_found_in_order():
    found = commands()
    # The figure caption's comes first, then the quick start's run; the examples follow in the text's order.
    assert found[0] == "python run.py dam_break --headless --frames 27 --out out/figure"
    assert found[1].endswith("pip install -e . && python run.py")
    video = found.index("python run.py dam_break --headless --frames 120 --video out/dam_break.mp4 --no-png")
    mesh = found.index("python run.py dam_break --headless --frames 60 --export mesh --style surface")
    own = found.index("python run.py dam_break --set solver.iterations=6 --set fluid.spacing_m=0.02")
    assert 1 < video < mesh < own
    assert runnable(found[0]) == "python run.py dam_break --headless --frames 2 --out out/figure"
    assert runnable(found[1]) == "python run.py --frames 2"
    assert runnable(found[own]).endswith("--set fluid.spacing_m=0.02 --frames 2")
    assert runnable("python3 -m venv .venv && . .venv/bin/activate && pip install -e . && python -m pytest -q") is None


@pytest.mark.slow
def test_the_readme_commands_run_in_order_from_a_fresh_copy(tmp_path):
    # What a clone gives the commands (run.py, the package and the presets in scenes/), in a folder of
    # its own, so nothing is written into the repo.
    (tmp_path / "run.py").write_text((ROOT / "run.py").read_text())
    (tmp_path / "pbf").symlink_to(ROOT / "pbf")
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    bin_dir = tmp_path / ".bin"
    bin_dir.mkdir()
    python = bin_dir / "python"
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')  # `python` is this test's interpreter
    python.chmod(python.stat().st_mode | stat.S_IEXEC)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "PBF_ARCH")}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    ran = []
    for command in commands():
        run = runnable(command)
        if run is None:
            continue
        result = subprocess.run(["bash", "-c", run], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, f"{command}\n(run as: {run})\n{result.stderr[-3000:]}"
        assert "error:" not in result.stderr, f"{command}\n{result.stderr[-3000:]}"
        ran.append((run, result.stdout))
    assert len(ran) >= 12
    # Every dam_break run after the quick start's that writes frames took a free default folder of its
    # own and said so; the --no-png video run writes none.
    taken = [re.search(r"writing to (out/dam_break-\d+)/ instead", out) for _, out in ran]
    folders = [m.group(1) for m in taken if m]
    assert folders == [f"out/dam_break-{k}" for k in range(2, len(folders) + 2)] and len(folders) >= 3, folders
    assert sorted(p.name for p in (tmp_path / "out" / "figure").iterdir()) == [f"frame_0000{k}.png" for k in range(3)]
    assert (tmp_path / "out" / "dam_break.mp4").stat().st_size > 0
    assert any((tmp_path / "out").glob("dam_break-*/surface_00002.ply"))
