"""Benchmark: median time per substep of the dam break at 8,000 and 64,000 particles.

    python -m pbf.bench [--sizes 8000 64000] [--iterations 4] [--frames 60] [--csv docs/bench.csv]

Each size runs the ``dam_break`` preset with the spacing scaled to reach the particle count, warms up
(JIT and the first impact), then times every substep with a device sync. Prints a table: median ms per
substep, particle-substeps per second, and the mean and max density error over the timed frames,
plus a per-stage breakdown of one substep.
"""
import argparse
import csv
import platform
import statistics
import time
from pathlib import Path

import taichi as ti

from pbf import config
from pbf.simulation import Simulation


def dam_break(particles: int, iterations: int) -> config.Scene:
    """The dam break with the spacing scaled to ``particles``, and Δt with it (Δt ∝ spacing keeps the
    distance a particle moves per substep, in spacings, the same: the scene stays equally hard)."""
    per_side = round(particles ** (1 / 3))
    base = config.load("dam_break")
    spacing = base.fluid.spacing_m * 20 / per_side
    substeps = max(1, round(base.time.substeps * per_side / 20))
    return config.load("dam_break", [f"fluid.spacing_m={spacing!r}", f"solver.iterations={iterations}",
                                     f"time.substeps={substeps}"])


def timed(function, *args):
    ti.sync()
    start = time.perf_counter()
    function(*args)
    ti.sync()
    return time.perf_counter() - start


def stage_times(sim: Simulation) -> dict:
    """Milliseconds of each stage of one substep (run stage by stage, with syncs in between)."""
    dt = sim.dt_s
    s = sim.settings
    x_pred = sim.integrator.x_pred
    stages = {
        "predict": timed(sim.integrator.predict, dt, s.gravity_m_s2),
        "sort by cell": timed(lambda: (sim.grid.sort(x_pred), sim.integrator.reorder(sim.grid.sorted_from))),
        "neighbour lists": timed(sim.grid.build_neighbours, x_pred),
        "solver iterations": timed(lambda: [sim.density.project(x_pred, sim.grid.neighbours)
                                            for _ in range(s.iterations)]),
        "velocity, vorticity, XSPH": timed(lambda: (sim.integrator.update_velocity(dt),
                                                    sim.postprocess.run(x_pred, sim.grid.neighbours, dt,
                                                                        s.vorticity, s.xsph))),
        "commit": timed(sim.integrator.commit),
    }
    return {name: seconds * 1e3 for name, seconds in stages.items()}


def run(particles: int, iterations: int, frames: int, warmup_frames: int) -> dict:
    sim = Simulation(dam_break(particles, iterations), quiet=True)
    sim.step(warmup_frames)
    substep_ms, mean_errors, max_errors = [], [], []
    dt_ms = []
    for _ in range(frames):
        # Whole frames, so the CFL limit may add substeps as in a real run; per substep = frame / substeps.
        frame_ms = timed(sim.step) * 1e3
        substep_ms.append(frame_ms / sim.frame_substeps)
        dt_ms.append(sim.dt_s * 1e3)
        stats = sim.stats()
        mean_errors.append(stats["mean_density_error"])
        max_errors.append(stats["max_density_error"])
    breakdown = [stage_times(sim) for _ in range(9)]
    stages = {name: statistics.median(b[name] for b in breakdown) for name in breakdown[0]}
    median_ms = statistics.median(substep_ms)
    return {
        "particles": sim.particle_count,
        "iterations": iterations,
        "dt_ms": statistics.median(dt_ms),
        "median_ms_per_substep": median_ms,
        "particle_substeps_per_s": sim.particle_count / (median_ms / 1e3),
        "mean_density_error": statistics.fmean(mean_errors),
        "max_density_error": max(max_errors),
        "stages_ms": stages,
        "backend": sim.backend,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[8000, 64000])
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--frames", type=int, default=60, help="timed frames per size")
    parser.add_argument("--warmup", type=int, default=30, help="untimed frames first")
    parser.add_argument("--arch", default=None)
    parser.add_argument("--csv", type=Path, default=None, help="also write the table as CSV")
    args = parser.parse_args(argv)
    from pbf import backend

    backend.start(args.arch)
    rows = [run(n, args.iterations, args.frames, args.warmup) for n in args.sizes]
    print(f"\nmachine: {platform.processor() or platform.machine()}, {platform.system()}, backend {rows[0]['backend']}")
    print(f"{'particles':>10} {'iters':>5} {'dt ms':>6} {'ms/substep':>11} {'particle-substeps/s':>20} "
          f"{'mean err':>9} {'max err':>8}")
    for r in rows:
        print(f"{r['particles']:>10,} {r['iterations']:>5} {r['dt_ms']:>6.2f} {r['median_ms_per_substep']:>11.2f} "
              f"{r['particle_substeps_per_s']:>20,.0f} {r['mean_density_error']:>9.3%} {r['max_density_error']:>8.2%}")
    print("\nstage breakdown, median ms per substep:")
    for r in rows:
        print(f"  {r['particles']:,}: " + ", ".join(f"{k} {v:.2f}" for k, v in r["stages_ms"].items()))
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[k for k in rows[0] if k != "stages_ms"])
            writer.writeheader()
            writer.writerows({k: v for k, v in r.items() if k != "stages_ms"} for r in rows)
    return rows


if __name__ == "__main__":
    main()
