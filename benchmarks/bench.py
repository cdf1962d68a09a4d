"""The lab's tables of the presets, the launches and the start (docs/BENCHMARKS.md).

    python -m benchmarks.bench presets [--presets dam_break ...] [--frames 30] [--csv F]   (statistics)
    python -m benchmarks.bench compare CPU.csv ... OTHER.csv      (each other run against the CPU's spread)
    python -m benchmarks.bench counts [--sizes 8000] [--iterations 4 | --presets ...] [--gpu-blocks]  (launches)
    python -m benchmarks.bench start [--presets dam_break ...] [--first-calls]    (benchmarks.start)

``presets``: every preset from its start, the means of its statistics over the second half of the
frames, reads and launches a substep. ``compare``: per preset and statistic, whether each non-CPU run
lies within the CPU runs' spread widened by as much again on either side. ``counts``: kernel calls and
offloaded tasks a substep under Taichi's profiler, on the host's decisions and the device's.
"""

import argparse
import csv
import platform
import statistics
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from benchmarks import start
from benchmarks.instruments import TransferCounter, count_substeps, counts_table
from pbf.scene import SCENES_DIR, SceneError, load_scene
from pbf.solver import ARCHES, Simulation, start_backend
from pbf.solver.backend import choices, describe, running_device
from pbf.study.common import dam_break, run_command, timed

COUNTED_FRAMES = 10  # counts: substeps counted
PERTURBATION_M = 1e-7  # --perturb: positions moved by this much a coordinate (float32's rounding at 0.5 m)
PERTURBATION_G = 2e-7
"""``--perturb``: gravity scaled by 1 + this × seed, a rounding or two: it reaches the scenes that settle
before t = 0 and those that start empty and fill from a nozzle (with no positions to move)."""


def perturbed(scene, seed: int):
    """The scene with gravity off by a rounding or two (``PERTURBATION_G``): from its settling
    (``time.settle_s``) on, a run of it differs as one that rounds differently does."""
    return replace(scene, gravity_m_s2=tuple(g * (1.0 + PERTURBATION_G * seed) for g in scene.gravity_m_s2))


def jiggle_in_place(sim, rng: np.random.Generator) -> None:
    """The live particles' positions moved by rounding-sized noise where they lie in the solver's
    state, between frames: only the positions change (a restore would also reset the frame's counters,
    the pressure's average and a wave maker's motion)."""
    positions = sim.state.x.to_numpy()
    live = sim.particle_count
    positions[:live] += rng.normal(0.0, PERTURBATION_M, (live, 3)).astype(np.float32)
    sim.state.x.from_numpy(positions)


def jiggle(sim, rng: np.random.Generator) -> None:
    """Every particle's position moved by rounding-sized noise (``PERTURBATION_M`` per coordinate)."""
    state = sim.snapshot()
    noise = rng.normal(0.0, PERTURBATION_M, state.positions_m.shape)
    sim.restore(replace(state, positions_m=(state.positions_m + noise).astype(np.float32)))


PRESET_STATISTICS = ("mean_density_error", "max_density_error", "max_speed_m_s", "kinetic_energy_j",
                     "mean_neighbours", "iterations")  # fmt: skip


def presets(args) -> list[dict]:
    """Each preset for ``--frames`` frames from its start: statistics averaged over the second half."""
    rows = []
    for name in args.presets or sorted(path.stem for path in SCENES_DIR.glob("*.toml")):
        scene = load_scene(name, args.set)
        path = choices(decisions_on_device=True if args.device_decisions else None)
        sim = Simulation(scene if args.perturb is None else perturbed(scene, args.perturb), quiet=True, choices=path)
        if args.perturb is not None:  # and the start's positions (the settled ones, where it settles)
            jiggle(sim, np.random.default_rng(args.perturb))
        rng = np.random.default_rng([args.perturb or 0, 1])
        samples, reads, launches, substeps, seconds = [], 0, 0, 0, 0.0
        for frame in tqdm(range(args.frames), desc=f"{name}, {sim.particle_count:,} particles", unit="frame"):
            with TransferCounter() as counter:
                seconds += timed(sim.step)
            reads, launches = reads + counter.reads, launches + counter.launches
            substeps += sim.frame_substeps
            if frame >= args.frames // 2:
                samples.append(sim.stats())
            if args.perturb_each_frame:
                jiggle_in_place(sim, rng)
        rows.append(
            dict(preset=name, backend=args.backend, variant=args.variant, particles=sim.particle_count,
                 frames=args.frames, s_per_frame=seconds / args.frames, reads_per_substep=reads / substeps,
                 launches_per_substep=launches / substeps,
                 **{key: statistics.fmean(s[key] for s in samples) for key in PRESET_STATISTICS})
        )  # fmt: skip
    print(
        f"{'preset':<20} {'particles':>9} {'s/frame':>8} {'reads/substep':>13} {'launches/substep':>16} "
        f"{'mean err':>9} {'max err':>8} {'max v':>6} {'KE J':>9} {'neighbours':>10} {'iters':>5}"
    )
    for r in rows:
        print(
            f"{r['preset']:<20} {r['particles']:>9,} {r['s_per_frame']:>8.2f} {r['reads_per_substep']:>13.2f} "
            f"{r['launches_per_substep']:>16.1f} {r['mean_density_error']:>9.3%} {r['max_density_error']:>8.2%} "
            f"{r['max_speed_m_s']:>6.2f} {r['kinetic_energy_j']:>9.4g} {r['mean_neighbours']:>10.2f} "
            f"{r['iterations']:>5.2f}"
        )
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return rows


def compare(paths: list[Path]) -> list[dict]:
    """Per preset and statistic: the CPU runs' range, and whether each other run lies inside it widened
    by its own width on either side. Returns the verdicts."""
    rows = [row for path in paths for row in csv.DictReader(path.open())]
    verdicts = []
    for name in sorted({row["preset"] for row in rows}):
        cpu = [row for row in rows if row["preset"] == name and row["backend"] == "cpu"]
        others = [row for row in rows if row["preset"] == name and row["backend"] != "cpu"]
        if not cpu or not others:
            continue
        for key in PRESET_STATISTICS:
            values = [float(row[key]) for row in cpu]
            low, high = min(values), max(values)
            spread = high - low
            for row in others:
                value = float(row[key])
                inside = low - spread <= value <= high + spread
                verdicts.append(dict(preset=name, statistic=key, backend=row["backend"], value=value, cpu_low=low,
                                     cpu_high=high, inside=inside))  # fmt: skip
                print(
                    f"{name:<20} {key:<20} {row['backend']:>7} {value:>12.5g}   cpu {low:>12.5g} … {high:<12.5g}"
                    f"  {'inside' if inside else 'OUTSIDE'}"
                )
    print(f"{sum(v['inside'] for v in verdicts)} of {len(verdicts)} inside the CPU's own spread")
    return verdicts


def counts(args) -> list:
    """``counts``: kernel calls and offloaded tasks per substep (``benchmarks.instruments``)."""
    cases = []  # (label, scene, a GPU's decisions, frames run first: past every kernel variant's compile)
    for name in args.presets or ():  # the presets as shipped, on each path
        scene = load_scene(name, args.set)
        cases += [(name, scene, False, 3), (f"{name}, device decisions", scene, True, 3)]
    for particles in (args.sizes or [8000]) if not args.presets else ():
        fixed = dam_break(particles, args.iterations, ["solver.target_density_error=0", *args.set])
        n, target = f"{particles:,}", dam_break(particles, 10, args.set)
        cases += [(f"{n}, {args.iterations} iterations", fixed, False, 2)]
        cases += [(f"{n}, {args.iterations} its., device decisions", fixed, True, 2)]
        cases += [(f"{n}, the preset's error target", target, False, 2)]
        cases += [(f"{n}, preset's target, device", target, True, 2)]
    rows = []
    for label, scene, on_device, frames in cases:  # main started the backend: its choices, a GPU's where asked
        device = True if on_device or args.device_decisions else None
        path = choices(decisions_on_device=device, gpu_blocks=True if args.gpu_blocks else None)
        sim = Simulation(scene, arch=args.backend, quiet=True, choices=path)
        sim.step(frames)
        rows.append((label, count_substeps(sim, COUNTED_FRAMES)))
    print(counts_table(rows))
    return rows


def _thread_count(text: str) -> int:
    value = int(text) if text.isdigit() else 0
    if not 1 <= value <= 256:
        raise argparse.ArgumentTypeError(f"expected a whole number of threads from 1 to 256, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """``main``'s parser, a sub-command a mode, each with the options it reads."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # What a mode without the option reads.
    parser.set_defaults(presets=None, device_decisions=False, perturb=None, perturb_each_frame=False)
    modes = parser.add_subparsers(dest="mode", required=True)
    run = argparse.ArgumentParser(add_help=False)  # what the modes that run the solver here share
    run.add_argument("--arch", choices=ARCHES, default=None, help="Taichi backend (default: $PBF_ARCH or auto)")
    run.add_argument("--threads", type=_thread_count, default=None, metavar="N", help="the CPU backend's threads")
    run.add_argument("--fast-compile", action="store_true", help="Taichi without its advanced optimisation")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a scene key (repeatable)")
    run.add_argument("--device-decisions", action="store_true", help="a GPU's decisions on any backend")
    run.add_argument("--presets", nargs="+", default=None, help="which presets (default: all)")
    presets_mode, counts_mode = (modes.add_parser(mode, parents=[run]) for mode in ("presets", "counts"))
    counts_mode.add_argument("--sizes", type=int, nargs="+", default=None, help="particle counts (default 8000)")
    counts_mode.add_argument("--iterations", type=int, default=4, help="solver iterations a substep")
    counts_mode.add_argument("--gpu-blocks", action="store_true", help="the sums in a GPU's blocks")
    presets_mode.add_argument("--frames", type=int, default=30, help="frames each preset runs")
    presets_mode.add_argument("--csv", type=Path, default=None, help="write the table as CSV")
    presets_mode.add_argument("--perturb", type=int, default=None, metavar="SEED", help="rounding-sized noise")
    presets_mode.add_argument("--perturb-each-frame", action="store_true", help="the noise again every frame")
    modes.add_parser("compare").add_argument("tables", nargs="+", type=Path, help="CSV tables of presets runs")
    start_mode = modes.add_parser("start")
    start_mode.add_argument("--presets", nargs="+", default=None, help="which presets (default: all)")
    start_mode.add_argument("--arch", choices=ARCHES, default=None, help="Taichi backend of the starts")
    start_mode.add_argument("--first-calls", action="store_true", help="each kernel's first call instead, per preset")
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in args.presets or ():  # every scene read before any runs
        try:
            load_scene(name)
        except SceneError as error:
            parser.error(f"--presets: {error}")
    if args.mode == "compare":
        return compare(args.tables)
    if args.mode == "start":  # each start a process of its own: this one starts no backend
        names = args.presets or sorted(path.stem for path in SCENES_DIR.glob("*.toml"))
        if args.first_calls:
            return start.first_calls(names, args.arch)
        return start.run(names, args.arch)
    if args.mode == "counts" and args.presets and args.sizes:
        parser.error("--sizes: counts the seed scene scaled; with --presets each preset runs as shipped")
    if args.perturb_each_frame and args.perturb is None:
        parser.error("--perturb-each-frame: needs --perturb SEED (the noise's seed)")
    args.backend = start_backend(args.arch, quiet=True, cpu_threads=args.threads, fast_compile=args.fast_compile,
                                 kernel_profiler=args.mode == "counts")  # fmt: skip
    if args.threads is not None and args.backend != "cpu":
        parser.error(f"--threads: sets the CPU backend's threads; the backend here is {args.backend}")
    args.variant = "+".join(
        [f"{args.threads} threads"] * (args.threads is not None)
        + ["fast compile"] * args.fast_compile
        + ["device decisions"] * args.device_decisions
        + [f"perturbed {args.perturb}"] * (args.perturb is not None)
        + ["each frame"] * args.perturb_each_frame
    )
    device = describe(running_device())
    print(
        f"machine: {platform.processor() or platform.machine()}, {platform.system()}, backend {args.backend} ({device})"
    )
    return presets(args) if args.mode == "presets" else counts(args)


if __name__ == "__main__":
    run_command(main)
