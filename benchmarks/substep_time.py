"""A substep timed whole on any backend, the host's share of it, and a preset's frame rate: the GPU's figures.

    python benchmarks/substep_time.py --arch cuda --sizes 8000 64000 1000000
    python benchmarks/substep_time.py --arch cuda --preset dam_break_large

``--sizes``: the seed dam break scaled to each (at most 4 iterations), after 5 frames ``--substeps``
substeps timed whole, ``--rounds`` times: medians of ms a substep, of the host's time to issue them
and of the issuing thread's CPU time. ``--preset``: 30 frames timed after 3, 30 more with the density
error read.
"""

import argparse
import statistics
import time

import taichi as ti

from pbf import Simulation
from pbf.scene import SceneError, load_scene
from pbf.solver import start_backend
from pbf.study.common import dam_break

WARMUP_FRAMES = 5


def substep_times(particles: int, substeps: int, rounds: int) -> dict:
    began = time.perf_counter()
    sim = Simulation(dam_break(particles, 4), quiet=True)
    sim.step(WARMUP_FRAMES)
    dt = sim.dt_s
    ti.sync()
    built = time.perf_counter() - began
    rounds_ms = []  # each round's ms a substep: whole, the host's to issue them, the issuing thread's CPU
    for _ in range(rounds):
        ti.sync()
        start, thread_start = time.perf_counter(), time.thread_time()
        for _ in range(substeps):
            sim.substep(dt)
        issued, thread_done = time.perf_counter(), time.thread_time()
        ti.sync()
        spent = (time.perf_counter() - start, issued - start, thread_done - thread_start)
        rounds_ms.append([t * 1e3 / substeps for t in spent])
    ms, host_ms, host_cpu_ms = (statistics.median(column) for column in zip(*rounds_ms))
    return dict(particles=sim.particle_count, ms=ms, host_ms=host_ms, host_cpu_ms=host_cpu_ms, built_s=built)


def preset_rate(preset: str, frames: int = 30) -> dict:
    began = time.perf_counter()
    sim = Simulation(load_scene(preset), quiet=True)
    sim.step(3)
    ti.sync()
    start = time.perf_counter()
    substeps = 0
    for _ in range(frames):
        sim.step()
        substeps += sim.frame_substeps
    ti.sync()
    seconds = time.perf_counter() - start
    errors = []
    for _ in range(frames):
        sim.step()
        errors.append(sim.stats()["mean_density_error"])
    x = sim.positions()
    return dict(particles=sim.particle_count, frames_per_s=frames / seconds, substeps=substeps / frames,
                mean_error=statistics.fmean(errors), worst_error=max(errors), lowest_m=x.min(axis=0),
                highest_m=x.max(axis=0), built_s=start - began)  # fmt: skip


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default=None, help="Taichi's backend (default: as the program picks)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[])
    parser.add_argument("--substeps", type=int, default=40, help="substeps of one timed round")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--preset", default=None, help="a preset whose frame rate to measure")
    args = parser.parse_args(argv)
    if not args.sizes and args.preset is None:
        parser.error("give --sizes, --preset or both")
    if args.preset is not None:
        try:  # before the backend starts
            load_scene(args.preset)
        except SceneError as error:
            parser.error(str(error))
    backend = start_backend(args.arch, quiet=True)
    if args.sizes:
        print(f"backend {backend}; {args.substeps} substeps a round, medians of {args.rounds} rounds")
        print(
            f"{'particles':>10} {'ms/substep':>11} {'host issue ms':>14} {'host CPU ms':>12} {'built and warmed s':>19}"
        )
        for particles in args.sizes:
            r = substep_times(particles, args.substeps, args.rounds)
            times = f"{r['ms']:>11.3f} {r['host_ms']:>14.3f} {r['host_cpu_ms']:>12.3f} {r['built_s']:>19.1f}"
            print(f"{r['particles']:>10,} {times}", flush=True)
    if args.preset is not None:
        r = preset_rate(args.preset)
        lowest, highest = (r[k].astype(float).round(4).tolist() for k in ("lowest_m", "highest_m"))
        print(
            f"{args.preset}, {backend}: {r['particles']:,} particles, {r['frames_per_s']:.1f} frames of "
            f"simulation a second, {r['substeps']:.2f} substeps a frame; mean density error "
            f"{r['mean_error']:.3%} (the worst frame {r['worst_error']:.3%}); particles from {lowest} to {highest} m; "
            f"built and warmed in {r['built_s']:.1f} s"
        )


if __name__ == "__main__":
    main()
