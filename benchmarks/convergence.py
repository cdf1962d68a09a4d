"""The seed preset's convergence levers, A/B in one run: density error over the first second against time.

    python benchmarks/convergence.py [--rounds 3] [--frames 60] [--threads N] [--scene dam_break]
                                     [--variants preset,before,...] [--as-filed COMMIT]

Each variant is the preset with some ``--set`` overrides (VARIANTS; ``--variants`` picks some by their
short names, the first being the one the ratios are to). The measure: the mean over the first
``--frames`` frames of ``stats()['mean_density_error']`` after each frame, the largest
``max_density_error`` of those frames, and the seconds of compute per simulated second (``step()``
alone, synchronised; the statistics outside the timer). All variants run from rest in one process
(each compiled once before timing), interleaved frame by frame: frame k of every variant, then
frame k + 1. A shared machine's speed drifts by ±20% over seconds, and interleaving puts that drift
into every row alike: the ratios repeat within about 2% from round to round, where timing the
variants one after another gave ±15%. The table gives the median over ``--rounds`` rounds and each
round's ratio. Errors are the same every round (the solver is deterministic).

``--as-filed COMMIT`` adds a first row, and the ratios are then to it: the ``pbf`` package and scenes
of an earlier commit, extracted with ``git archive`` into a temporary folder and imported under
another name in the same process, so that it is interleaved like the rest. It needs a clone with
history, and a commit whose package is flat (``pbf/*.py``); docs/BENCHMARKS.md's table was measured
with ``--as-filed 31d5946``, the seed preset of 2 substeps × 4 plain Jacobi iterations as first
filed. Without it the ratios are to the first of ``--variants``.
"""

import argparse
import importlib
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import taichi as ti

from pbf.scene import SceneError, load_scene
from pbf.solver import Simulation, start_backend

CHEBYSHEV = ("solver.expert.acceleration=chebyshev", "solver.expert.chebyshev_rho=0.92")
"""Chebyshev weights at ρ 0.92 (Wang 2015), as the seed preset ran them before the stable weights."""

H_2_2 = (
    "solver.kernel_ratio=2.2",
    "solver.surface_density=false",
    "solver.target_density_error=0.001",
    "solver.min_iterations=1",
)
"""h = 2.2 s, no free-surface ghost, target 0.1%, at least 1 iteration: the seed preset before the
ghost, but for its weights."""

BEFORE = H_2_2 + (
    "solver.expert.acceleration=none",
    "solver.divergence_iterations=0",
    "solver.iterations=4",
    "solver.target_density_error=0",
    "time.max_cfl=1.2",
)
"""4 plain Jacobi iterations every substep, CFL 1.2, h = 2.2 s: the seed preset as first filed, run by
the current code."""

VARIANTS = {
    "before": ("before: 4 plain Jacobi iterations, CFL 1.2", BEFORE),
    "before+chebyshev": ("+ Chebyshev ρ 0.92", BEFORE + CHEBYSHEV),
    "before+stable": ("+ stable weights", BEFORE + ("solver.expert.acceleration=stable",)),
    "chebyshev-h2.2": ("Chebyshev ρ 0.92, ≥ 1 iteration, target 0.1%, h = 2.2 s", H_2_2 + CHEBYSHEV),
    "chebyshev-h2.0": (
        "that, h = 2.0 s + surface ghost, target 0.09%",
        CHEBYSHEV + ("solver.min_iterations=1", "solver.target_density_error=0.0009"),
    ),
    "preset": ("the preset: stable weights, ≥ 2 iterations, step back, target 0.12%", ()),
    "preset+chebyshev": ("preset, Chebyshev ρ 0.92", CHEBYSHEV),
    "preset-min1": ("preset, ≥ 1 iteration", ("solver.min_iterations=1",)),
    "preset-no-step-back": ("preset, no step back", ("solver.expert.step_back=false",)),
    "preset-target0.09": ("preset, target 0.09%", ("solver.target_density_error=0.0009",)),
    "preset-target0.15": ("preset, target 0.15%", ("solver.target_density_error=0.0015",)),
    "preset-max8": ("preset, ≤ 8 iterations", ("solver.iterations=8",)),
    "preset-no-ghost": ("preset without the surface ghost", ("solver.surface_density=false",)),
}
"""Short name: (the table's label, the overrides of the preset)."""


def as_filed(commit: str, scene: str, workdir: Path):
    """A Simulation of ``scene`` as shipped at ``commit``, run by that commit's own code (imported as
    ``pbf_as_filed``), or None with a note when git cannot give it."""
    repository = Path(__file__).resolve().parent.parent
    archive = subprocess.run(["git", "-C", str(repository), "archive", commit, "pbf", "scenes"], capture_output=True)
    if archive.returncode != 0:
        print(
            f"note: --as-filed {commit}: no such row ({archive.stderr.decode().strip() or 'git archive failed'}); "
            f"it needs a git clone with that commit's history",
            file=sys.stderr,
        )
        return None
    subprocess.run(["tar", "-x", "-C", str(workdir)], input=archive.stdout, check=True)
    package = workdir / "pbf_as_filed"
    (workdir / "pbf").rename(package)
    if not (package / "simulation.py").is_file():
        print(
            f"note: --as-filed {commit}: its package is not flat (no pbf/simulation.py); no such row", file=sys.stderr
        )
        return None
    for module in package.glob("*.py"):  # such a commit's package is flat: pbf/*.py
        text = module.read_text()
        module.write_text(re.sub(r"\b(from|import) pbf\b", r"\1 pbf_as_filed", text))
    sys.path.insert(0, str(workdir))
    backend = importlib.import_module("pbf_as_filed.backend")
    backend._started = "cpu"  # Taichi already runs (start_backend): its start() must not ti.init again
    simulation = importlib.import_module("pbf_as_filed.simulation")
    return simulation.Simulation(str(workdir / "scenes" / f"{scene}.toml"), quiet=True)


def run(sims: dict, frames: int) -> dict:
    """One round: every simulation from rest, ``frames`` frames, interleaved frame by frame."""
    tallies = {name: {"seconds": 0.0, "means": [], "maxima": [], "iterations": [], "substeps": []} for name in sims}
    for sim in sims.values():
        sim.reset()
    for _ in range(frames):
        for name, sim in sims.items():
            tally = tallies[name]
            ti.sync()
            start = time.perf_counter()
            sim.step()
            ti.sync()
            tally["seconds"] += time.perf_counter() - start
            stats = sim.stats()
            tally["means"].append(stats["mean_density_error"])
            tally["maxima"].append(stats["max_density_error"])
            tally["iterations"].append(stats["iterations"])
            tally["substeps"].append(stats["substeps"])
    return {
        name: {
            "seconds": t["seconds"] / (frames * sims[name].scene.time.frame_dt_s),
            "mean": float(np.mean(t["means"])),
            "max": max(t["maxima"]),
            "iterations": float(np.mean(t["iterations"])),
            "substeps": float(np.mean(t["substeps"])),
        }
        for name, t in tallies.items()
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="dam_break")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None, help="Taichi CPU threads (default: all cores)")
    parser.add_argument(
        "--variants",
        default=",".join(VARIANTS),
        help=f"comma-separated short names, the first the base of the ratios: {', '.join(VARIANTS)}",
    )
    parser.add_argument(
        "--as-filed",
        default="",
        metavar="COMMIT",
        help="a first row run by this commit's own code (needs git history; see above)",
    )
    args = parser.parse_args(argv)
    names = [name.strip() for name in args.variants.split(",") if name.strip()]
    unknown = [name for name in names if name not in VARIANTS]
    if unknown or not names:
        parser.error(f"--variants: unknown {unknown[0]!r}" if unknown else "--variants: none given")
    if args.frames < 1 or args.rounds < 1:
        parser.error(f"--frames {args.frames}, --rounds {args.rounds}: allowed 1 or more each")
    try:  # every scene checked before Taichi starts
        scenes = {VARIANTS[name][0]: load_scene(args.scene, VARIANTS[name][1]) for name in names}
    except SceneError as error:
        parser.error(str(error))
    start_backend("cpu", cpu_threads=args.threads)
    sims = {}
    workdir = tempfile.TemporaryDirectory()
    if args.as_filed:
        filed = as_filed(args.as_filed, args.scene, Path(workdir.name))
        if filed is not None:
            sims[f"as filed ({args.as_filed}): its preset, its code"] = filed
    sims.update({label: Simulation(scene, quiet=True) for label, scene in scenes.items()})
    for sim in sims.values():
        sim.step(2)  # compile every kernel before any timing
    results = {name: [] for name in sims}
    for _ in range(args.rounds):
        for name, row in run(sims, args.frames).items():
            results[name].append(row)
    bases = [r["seconds"] for r in results[next(iter(results))]]
    base = statistics.median(bases)
    print(f"{args.scene}, first {args.frames} frames, {args.rounds} rounds interleaved frame by frame (median time)")
    width = max(map(len, results))
    print(
        f"{'variant':{width}s} {'mean err %':>10s} {'max err %':>9s} {'its/substep*':>12s} {'substeps':>8s} "
        f"{'s per sim s':>11s} {'ratio':>6s}  each round"
    )
    for name, rows in results.items():
        seconds = statistics.median(r["seconds"] for r in rows)
        r = rows[0]
        rounds = " ".join(f"{row['seconds'] / b:.2f}" for row, b in zip(rows, bases))
        print(
            f"{name:{width}s} {100 * r['mean']:10.3f} {100 * r['max']:9.2f} {r['iterations']:12.1f} "
            f"{r['substeps']:8.2f} {seconds:11.3f} {seconds / base:6.2f}  {rounds}"
        )
    print("* iterations of each frame's last substep, averaged over the frames")


if __name__ == "__main__":
    main()
