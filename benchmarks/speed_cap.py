"""What capping the particles' speed (``time.max_speed_m_s``) buys and what it costs the flow.

    python benchmarks/speed_cap.py [--particles 64000] [--frames 90] [--factors 0 2 1.5] [--divisor 12]

At high resolution the fastest drop of the splash sets every particle's substeps (the CFL limit
takes the fastest particle), though the water's own flow is several times slower. NVIDIA FleX caps
the speed instead. A cap is stated here as a multiple of the free-fall speed √(2 g y_top) of the
scene's highest water above the floor (1.5: the cap at 1.5 times the speed a particle falling that
height reaches), 0 meaning no cap, and each factor is run on

* the seed dam break scaled to ``--particles`` with the preset's solver (10 iterations, target
  0.12%): substeps a frame (the cost), density error, fastest particle, seconds per frame;
* the Martin & Moyce collapse at spacing a/``--divisor``: the surge front against the experiment
  (max |Z − Z_exp| and the mean offset, as ``python -m pbf.study.validate martin_moyce``).
"""

import argparse
import math
import statistics
import time

import numpy as np

from pbf import Simulation
from pbf.scene import load_scene
from pbf.study import validate
from pbf.study.common import dam_break


def free_fall_speed(scene) -> float:
    """√(2 g y), y the height of the scene's highest water above the container's floor (m/s)."""
    g = float(np.linalg.norm(scene.gravity_m_s2))
    top = max(block.max_m[1] for block in scene.fluid.blocks) - scene.container.min_m[1]
    return math.sqrt(2.0 * g * top)


def cap_override(scene, factor: float) -> list[str]:
    return [] if factor == 0 else [f"time.max_speed_m_s={factor * free_fall_speed(scene):.4g}"]


def dam_break_run(particles: int, frames: int, factor: float) -> dict:
    base = dam_break(particles, 10)
    sim = Simulation(dam_break(particles, 10, cap_override(base, factor)), quiet=True)
    substeps, errors, fastest, seconds = [], [], [], []
    for _ in range(frames):
        began = time.perf_counter()
        sim.step()
        seconds.append(time.perf_counter() - began)
        figures = sim.stats()
        substeps.append(sim.frame_substeps)
        errors.append(figures["mean_density_error"])
        fastest.append(figures["max_speed_m_s"])
    return {
        "cap_m_s": sim.scene.time.max_speed_m_s,
        "substeps": statistics.mean(substeps),
        "most_substeps": max(substeps),
        "mean_error": statistics.mean(errors),
        "worst_error": max(errors),
        "fastest": max(fastest),
        "s_per_frame": statistics.median(seconds),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=64000)
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--factors", type=float, nargs="+", default=[0.0, 2.0, 1.5])
    parser.add_argument("--divisor", type=int, default=12, help="Martin & Moyce: spacing a/divisor (0: skip)")
    args = parser.parse_args(argv)
    print(f"the seed dam break at {args.particles:,} particles, the preset's solver, {args.frames} frames")
    header = ("cap", "m/s", "substeps", "most", "mean error", "worst", "fastest", "s/frame")
    print(" ".join(f"{name:>{width}}" for name, width in zip(header, (12, 6, 9, 5, 11, 8, 8, 8))))
    for factor in args.factors:
        r = dam_break_run(args.particles, args.frames, factor)
        name = "none" if factor == 0 else f"{factor:g} √(2gy)"
        print(
            f"{name:>12} {r['cap_m_s']:>6.2f} {r['substeps']:>9.2f} {r['most_substeps']:>5d} "
            f"{r['mean_error'] * 100:>10.3f}% {r['worst_error'] * 100:>7.2f}% {r['fastest']:>8.2f} "
            f"{r['s_per_frame']:>8.3f}",
            flush=True,
        )
    if args.divisor:
        scene = load_scene("martin_moyce")
        print(f"\nMartin & Moyce at a/{args.divisor}: the surge front against the experiment (Z = x/a)")
        print(f"{'cap':>12} {'m/s':>6} {'max |Z − Z_exp|':>16} {'mean offset':>12}")
        for factor in args.factors:
            run = validate.martin_moyce(args.divisor, overrides=cap_override(scene, factor))
            name = "none" if factor == 0 else f"{factor:g} √(2gy)"
            cap = factor * free_fall_speed(scene)
            print(f"{name:>12} {cap:>6.2f} {run.max_deviation:>14.2f} a {run.mean_offset:>+10.2f} a", flush=True)


if __name__ == "__main__":
    main()
