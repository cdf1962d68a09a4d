"""The seed preset's convergence levers, A/B in one run: error over the first second against time.

    python benchmarks/convergence.py [--rounds 3] [--frames 60] [--threads N] [--scene dam_break]
                                     [--as-filed COMMIT]

Each variant is the preset with some ``--set`` overrides. The measure is issue 14's: the mean over the
first ``--frames`` frames of ``stats()['mean_density_error']`` after each frame, the largest
``max_density_error`` of those frames, and the seconds of compute per simulated second (``step()``
alone, synchronised; the statistics outside the timer). All variants run from rest in one process
(each compiled once before timing), interleaved frame by frame: frame k of every variant, then
frame k + 1. The VM's speed drifts by ±20% over seconds as its neighbours load the host, and
interleaving puts that drift into every row alike: the ratios to the first row repeat within about
2% from round to round, where timing the variants one after another gave ±15%. The table gives the
median over ``--rounds`` rounds and each round's ratio. Errors are the same every round (the solver
is deterministic).

The first row is the preset issue 14 measured, run by its own code: the ``pbf`` package and scenes of
commit ``--as-filed`` (default AS_FILED), extracted with ``git archive`` into a temporary folder and
imported under another name in the same process, so that it is interleaved like the rest. The
ratios are to that row. The next row, "before", is the same configuration on today's code, which
has every per-pass saving made since (so its ratio is the stricter one). Outside a git checkout, or
with ``--as-filed ''``, the first row is left out and the ratios are to "before".
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

from pbf.solver import Simulation, start_backend

AS_FILED = "31d5946"
"""The commit whose seed preset issue 14 measured (2 substeps × 4 plain Jacobi iterations)."""

CHEBYSHEV = ("solver.acceleration=chebyshev", "solver.chebyshev_rho=0.92")
"""The Chebyshev weights of the seed preset before the stable weights (2026-11-25)."""

UNTIL_GHOST = ("solver.kernel_ratio=2.2", "solver.surface_density=false", "solver.target_density_error=0.001",
               "solver.min_iterations=1")
"""The seed preset before the surface ghost (2026-11-24), but for its weights: h = 2.2 s, no ghost,
target 0.1%, at least 1 iteration."""

BEFORE = UNTIL_GHOST + ("solver.acceleration=none", "solver.divergence_iterations=0", "solver.iterations=4",
                        "solver.target_density_error=0", "time.max_cfl=1.2")
"""The seed preset as shipped before issue 14: 4 plain Jacobi iterations, every substep, CFL 1.2."""

VARIANTS = {
    "before: 4 plain Jacobi iterations, CFL 1.2": BEFORE,
    "+ Chebyshev ρ 0.92": BEFORE + CHEBYSHEV,
    "+ stable weights": BEFORE + ("solver.acceleration=stable",),
    "the preset until the ghost (Chebyshev ρ 0.92, target 0.1%, h 2.2 s)": UNTIL_GHOST + CHEBYSHEV,
    "that + h = 2.0 s + surface ghost, target 0.09%": CHEBYSHEV + ("solver.min_iterations=1",
                                                                  "solver.target_density_error=0.0009"),
    "the preset: that with stable weights, ≥ 2 its, target 0.12%": (),
    "preset, Chebyshev ρ 0.92": CHEBYSHEV,
    "preset, ≥ 1 iteration": ("solver.min_iterations=1",),
    "preset, no step back": ("solver.step_back=false",),
    "preset, target 0.09%": ("solver.target_density_error=0.0009",),
    "preset, target 0.15%": ("solver.target_density_error=0.0015",),
    "preset, ≤ 8 iterations": ("solver.iterations=8",),
    "preset without the surface ghost": ("solver.surface_density=false",),
}


def as_filed(commit: str, scene: str, workdir: Path):
    """A Simulation of ``scene`` as shipped at ``commit``, run by that commit's own code (imported as
    ``pbf_as_filed``), or None with a note when git cannot give it."""
    repository = Path(__file__).resolve().parent.parent
    archive = subprocess.run(["git", "-C", str(repository), "archive", commit, "pbf", "scenes"], capture_output=True)
    if archive.returncode != 0:
        print(f"note: no row for commit {commit!r} ({archive.stderr.decode().strip() or 'git archive failed'})")
        return None
    subprocess.run(["tar", "-x", "-C", str(workdir)], input=archive.stdout, check=True)
    package = workdir / "pbf_as_filed"
    (workdir / "pbf").rename(package)
    for module in package.glob("*.py"):  # that commit's package is flat: pbf/*.py
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
    return {name: {"seconds": t["seconds"] / (frames * sims[name].scene.time.frame_dt_s),
                   "mean": float(np.mean(t["means"])), "max": max(t["maxima"]),
                   "iterations": float(np.mean(t["iterations"])), "substeps": float(np.mean(t["substeps"]))}
            for name, t in tallies.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="dam_break")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None, help="Taichi CPU threads (default: all cores)")
    parser.add_argument("--as-filed", default=AS_FILED, metavar="COMMIT",
                        help=f"first row: the preset and code of this commit (default {AS_FILED}; '' for none)")
    args = parser.parse_args(argv)
    start_backend("cpu", cpu_threads=args.threads)
    sims = {}
    workdir = tempfile.TemporaryDirectory()
    if args.as_filed:
        filed = as_filed(args.as_filed, args.scene, Path(workdir.name))
        if filed is not None:
            sims[f"as filed ({args.as_filed}): its preset, its code"] = filed
    sims.update({name: Simulation(args.scene, overrides=overrides, quiet=True) for name, overrides in VARIANTS.items()})
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
    print(f"{'variant':{width}s} {'mean err %':>10s} {'max err %':>9s} {'its/substep*':>12s} {'substeps':>8s} "
          f"{'s per sim s':>11s} {'ratio':>6s}  each round")
    for name, rows in results.items():
        seconds = statistics.median(r["seconds"] for r in rows)
        r = rows[0]
        rounds = " ".join(f"{row['seconds'] / b:.2f}" for row, b in zip(rows, bases))
        print(f"{name:{width}s} {100 * r['mean']:10.3f} {100 * r['max']:9.2f} {r['iterations']:12.1f} {r['substeps']:8.2f} "
              f"{seconds:11.3f} {seconds / base:6.2f}  {rounds}")
    print("* iterations of each frame's last substep, averaged over the frames")


if __name__ == "__main__":
    main()
