"""The README's headline figures, in one table: what the seed dam break costs and how incompressible it
stays over its first second, and the three validation cases against experiment and theory, on the
machine it runs on.

    python -m pbf.study.headline [--arch auto|cpu|cuda] [--rounds 3]

The seed scene (``dam_break``, as shipped) runs its first second (60 frames: fall, impact, run-up)
``--rounds`` times from rest; the time is ``step()`` alone with the device synchronised, the median
over the rounds, after a first frame that compiles the kernels. The density errors are the mean over
the frames of ``stats()['mean_density_error']`` and the largest ``max_density_error`` of any frame;
they are the same in every round (the solver is deterministic). The validation rows are those of
``python -m pbf.study.validate`` (docs/VALIDATION.md): the Martin & Moyce surge front at spacing a/12
(the preset), the ``hydrostatic`` tank over 600 frames and the ``wave_tank`` gauge two depths from the
piston. The whole table takes about three minutes on a 2-core CPU. ``--quick`` runs every row a few
frames only, to check that the command works (its figures mean nothing).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import subprocess
import sys

import numpy as np

from pbf.solver import Simulation, start_backend
from pbf.solver.backend import taichi_version
from pbf.study import validate
from pbf.study.common import run_command, timed

SEED_SCENE = "dam_break"
SEED_FRAMES = 60
"""The seed scene's first second at 60 frames per second."""
MARTIN_MOYCE_DIVISOR = 12
"""The ``martin_moyce`` preset's own spacing, a/12."""
HYDROSTATIC_FRAMES = 600
"""10 s, as ``python -m pbf.study.validate hydrostatic`` runs it by default."""


def machine(backend: str) -> str:
    """The processor (and GPU, on CUDA), its cores, the backend, Taichi and Python: what a figure of
    time depends on."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            cpu = next(line.split(":", 1)[1].strip() for line in info if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    described = f"{cpu}, {os.cpu_count()} cores"
    if backend == "cuda":
        try:
            gpu = (
                subprocess.run(
                    ["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                    capture_output=True,
                    text=True,
                    timeout=10,
                )
                .stdout.strip()
                .splitlines()
            )
            described = f"{gpu[0]}; {described}" if gpu else described
        except (OSError, subprocess.SubprocessError):
            pass
    return (
        f"{described}; Taichi {taichi_version()} on {backend}, Python {platform.python_version()}, "
        f"{platform.system()} {platform.machine()}"
    )


def load_average() -> float | None:
    """The machine's load over the last minute, where the system tells it: on a shared machine the
    time of a run moves with it."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def seed_second(frames: int, rounds: int) -> dict:
    """The seed scene's first ``frames`` frames, ``rounds`` times from rest."""
    sim = Simulation(SEED_SCENE, quiet=True)
    sim.step()  # compiles every kernel the run uses (the same bits afterwards: reset() replays)
    seconds, means, maxima = [], [], []
    for _ in range(rounds):
        sim.reset()
        elapsed, means, maxima = 0.0, [], []
        for _ in range(frames):
            elapsed += timed(sim.step)
            stats = sim.stats()
            means.append(stats["mean_density_error"])
            maxima.append(stats["max_density_error"])
        seconds.append(elapsed)
    simulated_s = frames * sim.scene.time.frame_dt_s
    return {
        "particles": sim.particle_count,
        "frames": frames,
        "simulated_s": simulated_s,
        "load": load_average(),
        "seconds_per_simulated_s": statistics.median(seconds) / simulated_s,
        "mean_error": float(np.mean(means)),
        "max_error": max(maxima),
    }


def rows(quick: bool, rounds: int) -> tuple[list[tuple[str, str]], float | None]:
    """(measure, value) of every line of the table, and the load average when the timing ended."""
    seed = seed_second(3 if quick else SEED_FRAMES, 1 if quick else rounds)
    surge = validate.martin_moyce(9 if quick else MARTIN_MOYCE_DIVISOR, end_T=0.5 if quick else 3.5)
    unsettled = ["time.settle_s=0", "time.settle_substeps=0"]  # --quick: no settling before t = 0
    tank = validate.hydrostatic(
        3 if quick else HYDROSTATIC_FRAMES, samples=2 if quick else 30, overrides=unsettled if quick else ()
    )
    waves = validate.wave_tank(end_s=0.1 if quick else 4.0, gauges_in_depths=(2.0,))
    late_surface = tank.surface_m[len(tank.surface_m) // 2 :].mean()
    wave_ratio = waves.heights_m[0] / waves.expected_height_m
    speed = seed["seconds_per_simulated_s"]
    return [
        (
            f"`{SEED_SCENE}` ({seed['particles']:,} particles), first {seed['frames']} frames "
            f"({seed['simulated_s']:.3g} s): compute time",
            f"{speed:.2f} s per simulated second ({1 / speed:.2f}× real time)",
        ),
        (
            "the same frames: density error, mean over the frames / largest",
            f"{seed['mean_error']:.3%} / {seed['max_error']:.2%}",
        ),
        (
            f"Martin & Moyce (1952) surge front, spacing a/{surge.divisor} ({surge.particles:,} particles)",
            f"max \\|Z − Z_exp\\| = {surge.max_deviation:.2f} a, mean Z − Z_exp = {surge.mean_offset:+.2f} a",
        ),
        (
            f"hydrostatic tank ({tank.particles:,} particles, {tank.times_s[-1]:.3g} s): dp/d(depth) against ρ0 g",
            f"{tank.slope_pa_m / tank.expected_slope_pa_m - 1:+.1%}",
        ),
        (
            "the same tank: free surface against the fill height H (second half)",
            f"{late_surface / tank.fill_height_m - 1:+.2%}",
        ),
        (
            f"wave tank ({waves.particles:,} particles): wave height two depths from the piston",
            wave_value(wave_ratio, quick),
        ),
    ], seed["load"]


def wave_value(ratio: float, quick: bool) -> str:
    """The wave row's value: the measured height over linear theory's, or why there is none (--quick's
    0.1 s ends before the first wave reaches the gauge two depths down the tank, whose window is NaN)."""
    if math.isfinite(ratio):
        return f"{ratio:.2f} of linear theory (Biésel)"
    if quick:
        return "not measured in --quick (the run ends before the waves reach the gauge)"
    return "not measured (the run ended before the waves reached the gauge)"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--arch", default=None, help="Taichi backend: auto, cpu or cuda (default: $PBF_ARCH or auto)")
    parser.add_argument("--rounds", type=int, default=3, help="runs of the seed scene's first second (median time)")
    parser.add_argument("--quick", action="store_true", help="a few frames of each row: checks the command only")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds: {args.rounds}; allowed: 1 or more")
    backend = start_backend(args.arch)
    table, load = rows(args.quick, args.rounds)
    print(
        f"\nmachine: {machine(backend)}"
        + ("" if load is None else f"; load average {load:.1f} after the timing")
        + (" (--quick: not figures to quote)" if args.quick else "")
    )
    width = max(len(measure) for measure, _ in table)
    print(f"\n| {'measure':{width}s} | value |\n|{'-' * (width + 2)}|---|")
    for measure, value in table:
        print(f"| {measure:{width}s} | {value} |")
    sys.stdout.flush()


if __name__ == "__main__":
    run_command(main)
