"""How far a preset's pool is from rest, by time: the tops of its particles' columns.

    python benchmarks/pool_at_rest.py                          # the seed at 2, 3, 4, 6 and 8 s
    python benchmarks/pool_at_rest.py --preset hydrostatic --times 1 2

The container's floor is cut into ``--columns`` × ``--columns`` columns; a column's top is the mean height
of its three highest particles. Printed per time: the tops' spread (standard deviation), the highest
less the lowest, the slope between neighbouring columns (median and most) and the particles' rms speed.
A pool whose columns differ by centimetres still sloshes, and a rendered surface that follows the water
shows those waves (docs/RENDERING.md, "Measured").
"""

import argparse
import math

import numpy as np

from pbf.scene import SceneError, load_scene
from pbf.solver import Simulation
from pbf.solver.backend import BackendError, start_backend


def column_tops(positions: np.ndarray, lower, upper, columns: int) -> np.ndarray:
    """(columns, columns) heights, m: the mean of the three highest particles of each column (NaN: none)."""
    cells = [
        np.clip(((positions[:, a] - lower[a]) / (upper[a] - lower[a]) * columns).astype(int), 0, columns - 1)
        for a in (0, 2)
    ]
    tops = np.full((columns, columns), np.nan)
    for i in range(columns):
        for k in range(columns):
            heights = positions[(cells[0] == i) & (cells[1] == k), 1]
            if heights.size:
                tops[i, k] = np.sort(heights)[-3:].mean()
    return tops


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="dam_break", help="preset or TOML file (default: dam_break)")
    parser.add_argument("--times", type=float, nargs="+", default=[2, 3, 4, 6, 8], help="seconds (default: 2 3 4 6 8)")
    parser.add_argument("--columns", type=int, default=8, help="columns along x and along z (default: 8)")
    parser.add_argument("--arch", default=None, help="Taichi backend (default: auto)")
    args = parser.parse_args(argv)
    if args.columns < 2:
        parser.error(f"--columns: expected at least 2, got {args.columns}")
    if any(not math.isfinite(t) or t < 0 for t in args.times):
        parser.error(f"--times: expected finite seconds ≥ 0, got {' '.join(map(str, args.times))}")
    try:  # before the backend starts
        scene = load_scene(args.preset)
        start_backend(args.arch)
    except (SceneError, BackendError) as error:
        parser.error(str(error))
    sim = Simulation(scene, quiet=True)
    lower, upper = np.asarray(sim.scene.container.min_m), np.asarray(sim.scene.container.max_m)
    width = (upper[0] - lower[0]) / args.columns, (upper[2] - lower[2]) / args.columns
    print(f"{sim.scene.name}: the tops of {args.columns} × {args.columns} columns")
    print()
    print("| t | the tops' spread (std) | highest − lowest | columns' slope, median (most) | rms speed |")
    print("|---:|---:|---:|---:|---:|")
    for t in sorted(args.times):
        while sim.time_s < t - 1e-6:
            sim.step()
        tops = column_tops(sim.positions(), lower, upper, args.columns)
        steps = np.concatenate(
            [(np.abs(np.diff(tops, axis=0)) / width[0]).ravel(), (np.abs(np.diff(tops, axis=1)) / width[1]).ravel()]
        )
        slopes = np.degrees(np.arctan(steps[np.isfinite(steps)]))
        speed = math.sqrt(float(np.mean(np.sum(sim.velocities().astype(np.float64) ** 2, axis=1))))
        print(
            f"| {sim.time_s:.2f} s | {np.nanstd(tops) * 1000:.1f} mm | {np.nanmax(tops) - np.nanmin(tops):.3f} m "
            f"| {np.median(slopes):.1f}° ({slopes.max():.1f}°) | {speed:.3f} m/s |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
