"""What a frame of a preset costs in substeps and iterations, the density error it holds, and the frame rate
a GPU would reach at those counts.

    python benchmarks/frame_budget.py                                   # dam_break_large as shipped
    python benchmarks/frame_budget.py --setting "" --setting "time.max_cfl=4,time.substeps=5,solver.iterations=6"

Each ``--setting`` is a comma-separated list of ``KEY=VALUE`` overrides of the preset (``""``: the preset
as it is), run for ``--frames`` frames on this machine's backend. Printed per setting: substeps a frame
(mean and most), Jacobi iterations a substep (mean, and the share of substeps that ran all
``solver.iterations``), the mean density error over the frames of ``--window`` (the mean of each frame's
mean; the worst frame's; the largest of one particle), whether every particle stayed inside the
container, and the seconds a frame took here.

A frame's cost on a GPU is predicted from those counts as substeps × (F + I × (iterations + divergence
iterations)): F the part of a substep that does not repeat with the iterations (the sort, the neighbour
lists, the velocity passes, the launches past the error target), I one iteration (the λ and Δx passes,
the error's sum; an iteration of the divergence pre-correction, ``solver.divergence_iterations``, makes
the same two passes over the lists). Both were
measured on an H200 at 1,000,000 particles (docs/BENCHMARKS.md, "Time steps that fit a frame"): give
``--gpu-fixed-ms`` and ``--gpu-iteration-ms`` for another card or size. The host decides the iterations
here as the device does there, so the counts carry over; the prediction is the model's, to be checked on
the GPU with ``benchmarks/substep_time.py --arch cuda --preset``.
"""

import argparse
import statistics
import time

import taichi as ti

from pbf import Simulation
from pbf.scene import SceneError, load_scene
from pbf.solver import start_backend

H200_FIXED_MS = 1.04
"""F: a substep's cost besides its iterations, an H200 at 1,000,000 particles (ms)."""
H200_ITERATION_MS = 0.44
"""I: one Jacobi iteration's cost there (ms)."""


def overrides_of(setting: str) -> list[str]:
    return [item.strip() for item in setting.split(",") if item.strip()]


def run(preset: str, overrides: list[str], frames: int, window: tuple[int, int]) -> dict:
    """``frames`` frames of ``preset`` with ``overrides`` by ``Simulation.step``, the iterations of each
    substep read after it (a read from the device on a GPU backend, so the seconds a frame there
    include a wait each substep)."""
    sim = Simulation(load_scene(preset, overrides), quiet=True)
    box_min, box_max = sim.scene.container.min_m, sim.scene.container.max_m
    most_iterations = sim.control.iterations
    substeps, iterations, seconds = [], [], []
    errors, worst_particle, inside = [], 0.0, True
    counts = []
    substep = sim.substep

    def counted(dt):
        substep(dt)
        counts.append(sim.iterations_used)

    sim.substep = counted  # step() calls it for each substep of the frame
    for frame in range(1, frames + 1):
        began = time.perf_counter()
        counts.clear()
        sim.step()
        ti.sync()
        seconds.append(time.perf_counter() - began)
        if window[0] <= frame <= window[1]:
            figures = sim.stats()
            substeps.append(sim.frame_substeps)
            iterations.extend(counts)
            errors.append(figures["mean_density_error"])
            worst_particle = max(worst_particle, figures["max_density_error"])
        x = sim.positions()
        inside = inside and bool((x >= box_min).all() and (x <= box_max).all())
    return {
        "substeps": statistics.fmean(substeps),
        "most_substeps": max(substeps),
        "iterations": statistics.fmean(iterations),
        "all_iterations": sum(count == most_iterations for count in iterations) / len(iterations),
        "mean_error": statistics.fmean(errors),
        "worst_frame": max(errors),
        "worst_particle": worst_particle,
        "inside": inside,
        "s_per_frame": statistics.median(seconds),
        "particles": sim.particle_count,
        "divergence": sim.control.divergence_iterations,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="dam_break_large")
    parser.add_argument("--setting", action="append", default=None, help='comma-separated KEY=VALUE ("": as shipped)')
    parser.add_argument("--frames", type=int, default=64)
    parser.add_argument(
        "--window",
        type=int,
        nargs=2,
        default=None,
        metavar=("FIRST", "LAST"),
        help="frames whose counts and errors are averaged (default: 10 to --frames, the impact on)",
    )
    parser.add_argument("--gpu-fixed-ms", type=float, default=H200_FIXED_MS)
    parser.add_argument("--gpu-iteration-ms", type=float, default=H200_ITERATION_MS)
    parser.add_argument("--arch", default="cpu", help="Taichi's backend here (default cpu)")
    args = parser.parse_args(argv)
    settings = args.setting if args.setting is not None else [""]
    first, last = args.window or (min(10, args.frames), args.frames)
    if not 1 <= first <= last <= args.frames:
        parser.error(f"--window: expected 1 <= FIRST <= LAST <= --frames ({args.frames}), got {first} {last}")
    try:  # every setting checked before the first runs
        for setting in settings:
            load_scene(args.preset, overrides_of(setting))
    except SceneError as error:
        parser.error(str(error))
    backend = start_backend(args.arch, quiet=True)
    print(
        f"{args.preset}, {backend}: frames {first}-{last} of {args.frames}; a GPU frame predicted as substeps × "
        f"({args.gpu_fixed_ms} + {args.gpu_iteration_ms} × (iterations + divergence)) ms"
    )
    header = (
        "substeps",
        "most",
        "iterations",
        "all",
        "mean error",
        "worst frame",
        "worst particle",
        "inside",
        "s/frame here",
        "GPU ms/frame",
        "GPU frames/s",
        "setting",
    )
    print(" | ".join(header))
    for setting in settings:
        r = run(args.preset, overrides_of(setting), args.frames, (first, last))
        passes = r["iterations"] + r["divergence"]
        gpu_ms = r["substeps"] * (args.gpu_fixed_ms + args.gpu_iteration_ms * passes)
        print(
            f"{r['substeps']:.2f} | {r['most_substeps']} | {r['iterations']:.2f} | {r['all_iterations']:.0%} | "
            f"{r['divergence']} | "
            f"{r['mean_error']:.3%} | {r['worst_frame']:.3%} | {r['worst_particle']:.2%} | "
            f"{'yes' if r['inside'] else 'NO'} | {r['s_per_frame']:.2f} | {gpu_ms:.1f} | {1e3 / gpu_ms:.1f} | "
            f"{setting or '(as shipped)'}",
            flush=True,
        )


if __name__ == "__main__":
    main()
