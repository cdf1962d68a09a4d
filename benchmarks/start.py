"""How long a user waits before the first frame: cold and warm starts of every preset, each a fresh process.

    python -m benchmarks.bench start [--presets dam_break ...] [--arch cpu]
    python -m benchmarks.bench start --first-calls [--presets hydrostatic ...]

A start is ``pbf PRESET --stats-only --frames 1`` timed by its "kernels ready in" line, the ``.tic``
files it adds to its own cache folder the kernels it compiled: ``cold`` (empty), ``warm`` (again),
``spacing`` (10% larger). ``--first-calls``: with an empty cache, each kernel's first call timed.
"""

from __future__ import annotations

import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.lab import CHECKOUT, RunFailed, fresh
from pbf.scene import load_scene

SPACING_FACTOR = 1.1  # ``spacing``: the preset's spacing times this (fewer particles: never the slower run)
READY = re.compile(r"kernels ready(?: and the first frame drawn)? in ([0-9.]+) s")
TIMEOUT_S = 1200  # a start this long is reported as failed (a cold start of bodies under load takes minutes)
LAUNCH = "import sys; from pbf.app.cli import main; sys.exit(main(sys.argv[1:]))"


def cached_kernels(folder: Path) -> set[str]:
    """The compiled kernels in a Taichi offline cache folder (one ``.tic`` file each, at any depth)."""
    return {path.name for path in folder.rglob("*.tic")}


def one_start(preset: str, folder: Path, arch: str | None, overrides: list[str]) -> dict:
    """One start of ``preset`` in a fresh process whose offline cache is ``folder``: its wall time, its
    "kernels ready" time and the kernels it compiled (files it added to the folder)."""
    before = cached_kernels(folder)
    command = [sys.executable, "-c", LAUNCH, preset, "--stats-only", "--frames", "1"]
    command += ["--arch", arch] if arch else []
    for override in overrides:
        command += ["--set", override]
    began = time.perf_counter()
    try:
        output, error = fresh(command, timeout=TIMEOUT_S, TI_OFFLINE_CACHE_FILE_PATH=str(folder)), ""
    except RunFailed as failure:
        output, error = failure.output, str(failure)
    wall, ready = time.perf_counter() - began, READY.search(output)
    ready_s, compiled = float(ready.group(1)) if ready else float("nan"), len(cached_kernels(folder) - before)
    error = error or ("" if ready else "no 'kernels ready' line")
    return {"wall_s": wall, "ready_s": ready_s, "compiled": compiled, "error": error}


FIRST_CALLS_SHOWN = 8  # kernels each ``--first-calls`` table lists


def first_calls(presets: list[str], arch: str | None) -> None:
    """For each preset, :func:`first_calls_here` in a fresh process with an empty offline cache."""
    for preset in presets:
        with tempfile.TemporaryDirectory(prefix="pbf-first-calls-") as folder:
            code = f"from benchmarks.start import first_calls_here; first_calls_here({preset!r}, {arch!r})"
            try:  # the checkout on the path, where ``benchmarks`` is
                printed = fresh([sys.executable, "-c", code], [CHECKOUT], TIMEOUT_S, TI_OFFLINE_CACHE_FILE_PATH=folder)
            except RunFailed as failure:  # what it printed, then why it stopped
                printed = f"{failure.output.strip()}\n{preset}: failed: {failure}"
            print(printed.strip() + "\n", flush=True)


def first_calls_here(preset: str, arch: str | None) -> None:
    """In this process: ``preset`` built with its settling off (a start that settles runs its substeps
    on kernels already compiled) and stepped one substep, each kernel's first call per compiled
    variant timed in wall seconds; prints the total and the FIRST_CALLS_SHOWN longest."""
    import taichi as ti

    from benchmarks.instruments import Observer, watching
    from pbf.solver import Simulation, start_backend

    start_backend(arch or "cpu", quiet=True)
    seconds: dict[str, float] = {}

    class FirstCalls(Observer):
        def compiled(self, kernel: str, spent: float) -> None:
            seconds[kernel] = seconds.get(kernel, 0.0) + spent

    with watching(FirstCalls()):
        scene = load_scene(preset)
        off = ["time.settle_s=0", "time.settle_substeps=0"] if scene.time.settle_s > 0 else []
        began = time.perf_counter()
        sim = Simulation(load_scene(preset, off), quiet=True)
        sim.substep()
        ti.sync()
        total = time.perf_counter() - began
    firsts = f"{sum(seconds.values()):.2f} s of it the first calls of {len(seconds)} kernels"
    print(f"{preset}: built and one substep in {total:.2f} s, {firsts}")
    for name, value in sorted(seconds.items(), key=lambda item: -item[1])[:FIRST_CALLS_SHOWN]:
        print(f"  {value:6.2f} s  {name}")


def cell(result: dict) -> str:
    """A table cell: ready time and kernels compiled, or why the start failed."""
    return f"failed: {result['error'][:60]}" if result["error"] else f"{result['ready_s']:.1f} s ({result['compiled']})"


def run(presets: list[str], arch: str | None) -> list[dict]:
    """Every start of the module docstring, printed as a table as they finish; returns the rows."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="pbf-start-") as root:
        print("ready time of each start, in brackets the kernels it compiled (0: all from the cache)")
        print(f"{'preset':<20} {'cold':>16} {'warm':>16} {'spacing x1.1':>16}", flush=True)
        for preset in presets:
            folder = Path(root) / preset
            folder.mkdir()
            spacing = f"fluid.spacing_m={load_scene(preset).fluid.spacing_m * SPACING_FACTOR:.6g}"
            row = {"preset": preset}
            for name, overrides in (("cold", []), ("warm", []), ("spacing", [spacing])):
                row[name] = one_start(preset, folder, arch, overrides)
            cells = " ".join(f"{cell(row[name]):>16}" for name in ("cold", "warm", "spacing"))
            print(f"{preset:<20} {cells}", flush=True)
            rows.append(row)
    ready, warm = ([row[name]["ready_s"] for row in rows if not row[name]["error"]] for name in ("cold", "warm"))
    if ready and warm:
        print(f"\nmedian cold {statistics.median(ready):.1f} s, median warm {statistics.median(warm):.1f} s")
    return rows
