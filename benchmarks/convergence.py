"""The seed preset's convergence levers, A/B in one run: error over the first second against time.

    python benchmarks/convergence.py [--rounds 3] [--frames 60] [--threads N] [--scene dam_break]

Each variant is the preset with some ``--set`` overrides. The measure is issue 14's: the mean over the
first ``--frames`` frames of ``stats()['mean_density_error']`` after each frame, the largest
``max_density_error`` of those frames, and the seconds of compute per simulated second (``step()``
alone, synchronised; the statistics outside the timer). Variants run frame by frame from rest in
turn, ``--rounds`` times, in one process (each compiled once before timing): the table gives the
median time of the rounds and its ratio to the first row, so rows of one run compare fairly on a
noisy machine. Errors are the same every round (the solver is deterministic).
"""
import argparse
import statistics
import time

import numpy as np
import taichi as ti

from pbf.solver import Simulation, start_backend

BEFORE = ("solver.chebyshev_rho=0", "solver.divergence_iterations=0", "solver.iterations=4",
          "solver.target_density_error=0", "time.max_cfl=1.2")
"""The seed preset as shipped before issue 14: 4 plain Jacobi iterations, every substep, CFL 1.2."""

VARIANTS = {
    "before: 4 plain Jacobi iterations, CFL 1.2": BEFORE,
    "+ Chebyshev ρ 0.9": ("solver.divergence_iterations=0", "solver.iterations=4", "solver.target_density_error=0",
                          "time.max_cfl=1.2"),
    "+ divergence pre-correction": ("solver.chebyshev_rho=0", "solver.divergence_iterations=1", "solver.iterations=4",
                                    "solver.target_density_error=0", "time.max_cfl=1.2"),
    "+ error target 0.1% (≤ 10 iterations)": ("solver.chebyshev_rho=0", "solver.divergence_iterations=0",
                                              "time.max_cfl=1.2"),
    "Chebyshev + target": ("solver.divergence_iterations=0", "time.max_cfl=1.2"),
    "Chebyshev + divergence + target": ("solver.divergence_iterations=1", "time.max_cfl=1.2"),
    "Chebyshev + divergence + target, CFL 2.0": ("solver.divergence_iterations=1",),
    "the preset (Chebyshev + target, CFL 2.0)": (),
}


def run(sim: Simulation, frames: int) -> dict:
    sim.reset()
    seconds, means, maxima, iterations, substeps = 0.0, [], [], [], []
    for _ in range(frames):
        ti.sync()
        start = time.perf_counter()
        sim.step()
        ti.sync()
        seconds += time.perf_counter() - start
        stats = sim.stats()
        means.append(stats["mean_density_error"])
        maxima.append(stats["max_density_error"])
        iterations.append(stats["iterations"])
        substeps.append(stats["substeps"])
    return {"seconds": seconds / (frames * sim.scene.time.frame_dt_s), "mean": float(np.mean(means)),
            "max": max(maxima), "iterations": float(np.mean(iterations)), "substeps": float(np.mean(substeps))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="dam_break")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None, help="Taichi CPU threads (default: all cores)")
    args = parser.parse_args(argv)
    start_backend("cpu", cpu_threads=args.threads)
    sims = {name: Simulation(args.scene, overrides=overrides, quiet=True) for name, overrides in VARIANTS.items()}
    for sim in sims.values():
        sim.step(2)  # compile every kernel before any timing
    results = {name: [] for name in sims}
    for _ in range(args.rounds):
        for name, sim in sims.items():
            results[name].append(run(sim, args.frames))
    base = statistics.median(r["seconds"] for r in results[next(iter(results))])
    print(f"{args.scene}, first {args.frames} frames, {args.rounds} rounds (median time)")
    print(f"{'variant':42s} {'mean err %':>10s} {'max err %':>9s} {'its/substep*':>12s} {'substeps':>8s} "
          f"{'s per sim s':>11s} {'ratio':>6s}")
    for name, rows in results.items():
        seconds = statistics.median(r["seconds"] for r in rows)
        r = rows[0]
        print(f"{name:42s} {100 * r['mean']:10.3f} {100 * r['max']:9.2f} {r['iterations']:12.1f} {r['substeps']:8.2f} "
              f"{seconds:11.3f} {seconds / base:6.2f}")
    print("* iterations of each frame's last substep, averaged over the frames")


if __name__ == "__main__":
    main()
