"""Benchmarks: speed, the speed/error trade-off and what each term costs, printed as tables.

    python -m pbf.study.bench [sizes] [--sizes 8000 64000] [--iterations 4] [--frames 60] [--csv F]
    python -m pbf.study.bench sweep   (see pbf.study.sweep: iterations × substeps × sizes, CSV and plot)
    python -m pbf.study.bench terms   [--sizes 8000] [--iterations 4]
    python -m pbf.study.bench presets [--presets dam_break ...] [--frames 30] [--csv F]
    python -m pbf.study.bench compare CPU.csv ... OTHER.csv   (presets tables of several runs)
    python -m pbf.study.bench counts  [--sizes 8000] [--iterations 4 | --presets ...] [--gpu-blocks]   (launches)
    python -m pbf.study.bench start   [--presets dam_break ...] [--no-shared | --first-calls]   (see pbf.study.start)
    python -m pbf.study.bench traffic [--sizes 8000] [--iterations 4] [--particles 1000000]   (bytes moved)
    python -m pbf.study.bench frames  [options of python -m pbf.study.frames]   (the renderers and writer alone)

``sizes`` runs the ``dam_break`` preset with the spacing scaled to reach each particle count, warms
up (JIT and the first impact), then times whole frames with a device sync: median ms per substep,
particle-substeps per second, the mean and max density error over the timed frames, a per-stage
breakdown of the substeps that follow, and, over ten frames more, the kernel launches and the
device-to-host reads per substep (``pbf.study.common.TransferCounter`` says what counts as a read).
One backend per run: ``--arch`` (or $PBF_ARCH), named in the first line with its device. ``terms``
times one substep of the same state, stage by stage, with each optional term (vorticity confinement,
XSPH, s_corr, wall density) switched off in turn, in interleaved rounds, and reports what each
costs. Stages are timed by a hook inside the step (``pbf.study.common.StageTimer``). Medians
throughout: the machines are shared and noisy.

``counts`` runs substeps of the seed scene at a fixed iteration count, on the host's decisions and on
the device's (as GPU backends take them), and of the shipped preset with its error target (or, with
``--presets``, those presets as shipped), under Taichi's kernel profiler, and prints the Python
kernel calls and the offloaded tasks per substep (``pbf.study.launches``); with ``--gpu-blocks`` the
sums take a GPU backend's blocks of 32, whose extra levels are launches of their own on a GPU (the
float sums as Vulkan and Metal add them up; CUDA takes one or two launches a sum). ``start`` times
cold and warm starts of every preset in fresh processes (``pbf.study.start``). ``traffic`` measures
the neighbour and candidate counts of the seed scene in its splash and prints the bytes a substep
moves per particle by stage, with neighbour lists and without (``pbf.study.traffic``), scaled to
``--particles``.

``presets`` runs every preset from its start on this backend and prints the means of its statistics
over the second half of the frames, with reads and launches per substep; ``compare`` reads such
tables from several runs (backends, or the CPU with ``--fast-compile``, ``--device-decisions`` or
``--perturb``, which differ from it only as roundings do; ``--threads`` does not: the sums are trees
in a fixed order, so every thread count gives the same bits) and says, per preset and statistic, whether
each non-CPU run lies within the CPU runs' own spread, widened by as much again on either side.
"""

import argparse
import csv
import platform
import statistics
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pbf.scene import SCENES_DIR, SceneError, load_scene
from pbf.solver import ARCHES, Simulation, start_backend
from pbf.solver.backend import choices, describe, running_device
from pbf.study import sweep as speed_error
from pbf.study.common import StageTimer, TransferCounter, dam_break, run_command, timed

COUNTED_FRAMES = 10
"""``sizes``: frames whose launches and reads are counted, after the timed ones."""
STAGE_SUBSTEPS = 9
"""``sizes``: substeps of one stage-breakdown round, all from the state the timed frames end in."""
STAGE_ROUNDS = 5
"""``sizes``: rounds of the stage breakdown, each the same substeps timed whole and then stage by stage."""


def stage_pass(sim: Simulation, substeps: int, rounds: int, bar=None) -> dict:
    """The stage breakdown beside the same substeps untimed, so that the two can be compared.

    Each round restores the state it started from and runs ``substeps`` substeps at the last Δt twice:
    first whole, with the device synchronised once before and once after (``untimed``: what the
    substeps cost), then with ``StageTimer``, which synchronises the device around every stage and
    times each. Rounds alternate the two, so noise falls on both alike. Returns medians over the rounds
    of each stage's ms per substep (``stages``), of their sum (``stages_sum``) and of the untimed ms
    per substep (``untimed``). The sum gains the synchronisations' cost (little on the CPU; on a GPU,
    where launches are queued, no stage overlaps the next any more) and lacks the host's work between
    stages, which no stage encloses: it may come out larger or smaller than the untimed figure."""
    start, dt, previous = sim.snapshot(), sim.dt_s, sim.hook
    per_stage: dict[str, list[float]] = {}
    sums, untimed = [], []
    try:
        for _ in range(rounds):
            sim.restore(start)
            untimed.append(timed(lambda: [sim.substep(dt) for _ in range(substeps)]) * 1e3 / substeps)
            sim.restore(start)
            sim.hook = timer = StageTimer()
            for _ in range(substeps):
                sim.substep(dt)
            sim.hook = previous
            means = {name: sum(timer.ms[name]) / substeps for name in timer.medians()}
            for name, ms in means.items():
                per_stage.setdefault(name, []).append(ms)
            sums.append(sum(means.values()))
            if bar is not None:
                bar.update()
    finally:
        sim.hook = previous
        sim.restore(start)
    return {
        "stages": {name: statistics.median(ms) for name, ms in per_stage.items()},
        "stages_sum": statistics.median(sums),
        "untimed": statistics.median(untimed),
    }


def run_size(
    particles: int, iterations: int, frames: int, warmup_frames: int, overrides=(), device_decisions: bool = False
) -> dict:
    substep_ms, mean_errors, max_errors = [], [], []
    dt_ms = []
    counted = min(frames, COUNTED_FRAMES)
    # On stderr, so that the table on stdout stays clean. Every part of a size is on the bar (building
    # and settling the scene compiles the kernels: seconds with nothing else to show).
    total = 1 + warmup_frames + frames + STAGE_ROUNDS + counted
    with tqdm(total=total, desc=f"{particles:,} particles", unit="part") as bar:
        bar.set_postfix_str("compiling")
        path = choices(decisions_on_device=True if device_decisions else None)
        sim = Simulation(dam_break(particles, iterations, overrides), quiet=True, choices=path)
        bar.update()
        bar.set_postfix_str("warm-up frames")
        for _ in range(warmup_frames):
            sim.step()
            bar.update()
        bar.set_postfix_str("timed frames")
        for _ in range(frames):
            # Whole frames, so the CFL limit may add substeps as in a real run; per substep = frame / substeps.
            frame_ms = timed(sim.step) * 1e3
            substep_ms.append(frame_ms / sim.frame_substeps)
            dt_ms.append(sim.dt_s * 1e3)
            stats = sim.stats()
            mean_errors.append(stats["mean_density_error"])
            max_errors.append(stats["max_density_error"])
            bar.update()
        bar.set_postfix_str("stage breakdown")
        stages = stage_pass(sim, STAGE_SUBSTEPS, STAGE_ROUNDS, bar)
        bar.set_postfix_str("counting launches and reads")
        substeps = 0
        with TransferCounter() as counter:
            for _ in range(counted):
                sim.step()
                substeps += sim.frame_substeps
                bar.update()
    median_ms = statistics.median(substep_ms)
    return {
        "particles": sim.particle_count,
        "iterations": iterations,
        "dt_ms": statistics.median(dt_ms),
        "median_ms_per_substep": median_ms,
        "particle_substeps_per_s": sim.particle_count / (median_ms / 1e3),
        "mean_density_error": statistics.fmean(mean_errors),
        "max_density_error": max(max_errors),
        "reads_per_substep": counter.reads / substeps,
        "launches_per_substep": counter.launches / substeps,
        "stages_ms": stages,
        "backend": sim.backend,
    }


def sizes(args) -> list[dict]:
    rows = [run_size(n, args.iterations, args.frames, args.warmup, args.set, args.device_decisions) for n in args.sizes]
    print(
        f"{'backend':>7} {'particles':>10} {'iters':>5} {'dt ms':>6} {'ms/substep':>11} {'particle-substeps/s':>20} "
        f"{'mean err':>9} {'max err':>8} {'reads/substep':>13} {'launches/substep':>16}"
    )
    for r in rows:
        print(
            f"{r['backend']:>7} {r['particles']:>10,} {r['iterations']:>5} {r['dt_ms']:>6.2f} "
            f"{r['median_ms_per_substep']:>11.2f} {r['particle_substeps_per_s']:>20,.0f} "
            f"{r['mean_density_error']:>9.3%} {r['max_density_error']:>8.2%} {r['reads_per_substep']:>13.2f} "
            f"{r['launches_per_substep']:>16.1f}"
        )
    print(
        f"\nstage breakdown, ms per substep: {STAGE_SUBSTEPS} substeps from the state the timed frames end in, "
        f"medians of {STAGE_ROUNDS} rounds that time them whole (untimed: one device sync at each end) and "
        f"stage by stage (each stage between two device syncs):"
    )
    for r in rows:
        parts = r["stages_ms"]
        print(
            f"  {r['particles']:,}: "
            + ", ".join(f"{k} {v:.2f}" for k, v in parts["stages"].items())
            + f"; sum {parts['stages_sum']:.2f}, the same substeps untimed {parts['untimed']:.2f}"
        )
    print(
        "  The sum differs from the untimed substeps by the syncs around each stage (on a GPU no stage's "
        "launches overlap the next's then) and the host's work between stages; the table's ms/substep is "
        "over the timed frames before this state, with each frame's CFL check, so it is near the untimed "
        "figure, not equal to it."
    )
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[k for k in rows[0] if k != "stages_ms"])
            writer.writeheader()
            writer.writerows({k: v for k, v in r.items() if k != "stages_ms"} for r in rows)
    return rows


TERMS = {
    "all terms (preset)": [],
    "no vorticity confinement": ["vorticity.epsilon=0"],
    "no XSPH viscosity": ["viscosity.xsph=0"],
    "no s_corr": ["solver.scorr_k=0"],
    "no wall density": ["solver.expert.wall_density=false"],
    "none of the four": [
        "vorticity.epsilon=0",
        "viscosity.xsph=0",
        "solver.scorr_k=0",
        "solver.expert.wall_density=false",
    ],
}


def terms(args) -> list[dict]:
    """Per-substep cost of each optional term: every variant restored to the same mid-splash state and
    timed stage by stage, variants interleaved round by round so that machine noise hits all alike."""
    rows = []
    for particles in args.sizes:
        base = dam_break(particles, args.iterations, args.set)
        variants = {
            name: Simulation(load_scene("dam_break", _overrides(base) + args.set + extra), quiet=True)
            for name, extra in TERMS.items()
        }
        reference = next(iter(variants.values()))
        reference.step(args.warmup)
        snapshot, dt = reference.snapshot(), reference.dt_s
        for sim in variants.values():
            sim.hook = StageTimer()
        for _ in tqdm(range(args.rounds), desc=f"{reference.particle_count:,} particles: rounds", unit="round"):
            for sim in variants.values():
                sim.restore(snapshot)
                sim.substep(dt)
        medians = {name: sim.hook.medians() for name, sim in variants.items()}
        full = sum(medians["all terms (preset)"].values())
        for name, stages in medians.items():
            total = sum(stages.values())
            rows.append(
                {
                    "particles": reference.particle_count,
                    "variant": name,
                    "ms_per_substep": total,
                    "solver_ms": stages["solver iterations"],
                    "velocity_ms": stages["velocity, vorticity, XSPH, x = x*"],
                    "saving_ms": full - total,
                    "ratio_to_all": total / full,
                    "mean_density_error": variants[name].stats()["mean_density_error"],
                }
            )
    print(
        f"{'particles':>9}  {'variant':<26} {'ms/substep':>10} {'solver':>7} {'velocity':>8} {'saves ms':>9} "
        f"{'ratio':>6} {'mean err':>9}"
    )
    for r in rows:
        print(
            f"{r['particles']:>9,}  {r['variant']:<26} {r['ms_per_substep']:>10.2f} {r['solver_ms']:>7.2f} "
            f"{r['velocity_ms']:>8.2f} {r['saving_ms']:>9.2f} {r['ratio_to_all']:>6.2f} {r['mean_density_error']:>9.3%}"
        )
    return rows


PERTURBATION_M = 1e-7
"""``--perturb``: positions moved by this much, per coordinate: float32's rounding at half a metre."""
PERTURBATION_G = 2e-7
"""``--perturb``: gravity scaled by 1 + this × seed, a float32 rounding or two of it: it reaches the
scenes that settle before t = 0 (whose settled start a move of the positions after it would not
change) and those that start empty and fill from a nozzle (with no positions to move)."""


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


PRESET_STATISTICS = (
    "mean_density_error",
    "max_density_error",
    "max_speed_m_s",
    "kinetic_energy_j",
    "mean_neighbours",
    "iterations",
)


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
            {
                "preset": name,
                "backend": args.backend,
                "variant": args.variant,
                "particles": sim.particle_count,
                "frames": args.frames,
                "s_per_frame": seconds / args.frames,
                "reads_per_substep": reads / substeps,
                "launches_per_substep": launches / substeps,
                **{key: statistics.fmean(s[key] for s in samples) for key in PRESET_STATISTICS},
            }
        )
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
                verdicts.append(
                    {
                        "preset": name,
                        "statistic": key,
                        "backend": row["backend"],
                        "value": value,
                        "cpu_low": low,
                        "cpu_high": high,
                        "inside": inside,
                    }
                )
                print(
                    f"{name:<20} {key:<20} {row['backend']:>7} {value:>12.5g}   cpu {low:>12.5g} … {high:<12.5g}"
                    f"  {'inside' if inside else 'OUTSIDE'}"
                )
    print(f"{sum(v['inside'] for v in verdicts)} of {len(verdicts)} inside the CPU's own spread")
    return verdicts


def counts(args) -> list:
    """``counts``: kernel calls and offloaded tasks per substep (``pbf.study.launches``)."""
    from pbf.study import launches

    def path(on_device):  # main started the backend: its choices, a GPU's where asked
        device = True if on_device or args.device_decisions else None
        return choices(decisions_on_device=device, gpu_blocks=True if args.gpu_blocks else None)

    rows = []
    for name in args.presets or ():  # the presets as shipped, on each path
        scene = load_scene(name, args.set)
        for label, on_device in ((name, False), (f"{name}, device decisions", True)):
            sim = Simulation(scene, arch=args.backend, quiet=True, choices=path(on_device))
            sim.step(3)  # past the compile of every kernel variant the counted substeps use
            rows.append((label, launches.count_substeps(sim, COUNTED_FRAMES)))
    for particles in (args.sizes or [8000]) if not args.presets else ():
        fixed = dam_break(particles, args.iterations, ["solver.target_density_error=0", *args.set])
        for name, scene, on_device in (
            (f"{particles:,}, {args.iterations} iterations", fixed, False),
            (f"{particles:,}, {args.iterations} its., device decisions", fixed, True),
            (f"{particles:,}, the preset's error target", dam_break(particles, 10, args.set), False),
            (f"{particles:,}, preset's target, device", dam_break(particles, 10, args.set), True),
        ):
            sim = Simulation(scene, arch=args.backend, quiet=True, choices=path(on_device))
            sim.step(2)  # past the compile of every kernel variant the counted substeps use
            rows.append((name, launches.count_substeps(sim, COUNTED_FRAMES)))
    print(launches.table(rows))
    return rows


def traffic(args) -> str:
    """``traffic``: the bytes-moved model (``pbf.study.traffic``) at the seed scene's counts in its splash."""
    from pbf.study import traffic as model

    particles = (args.sizes or [8000])[0]
    sim = Simulation(dam_break(particles, args.iterations, args.set), arch=args.backend, quiet=True)
    sim.step(args.warmup)  # into the splash: more neighbours at the walls and in the pile than at rest
    neighbours, candidates, cells = model.measured_counts(sim)
    print(f"counts of the {particles:,}-particle seed scene at frame {sim.frame}")
    text = model.table(args.particles, args.iterations, round(neighbours, 1), round(candidates, 1), round(cells, 2))
    print(text)
    return text


def _overrides(scene) -> list[str]:
    return [
        f"fluid.spacing_m={scene.fluid.spacing_m!r}",
        f"solver.iterations={scene.solver.iterations}",
        f"time.substeps={scene.time.substeps}",
    ]


def sweep(args):
    if args.from_csv:
        points = speed_error.read_csv(args.from_csv)
    else:
        points = speed_error.sweep(
            args.sizes,
            args.iterations,
            args.substeps,
            args.target,
            args.frames,
            args.rest_settle,
            args.rest_frames,
            args.set,
            args.flow,
        )
        speed_error.write_csv(points, args.csv)
    speed_error.print_table(points)
    # Re-plotted, the points are the CSV's machine's, not this one's (--frames says how long they ran).
    made = (
        f"the points of {args.from_csv.name}"
        if args.from_csv
        else f"{platform.processor() or platform.machine()}, {args.backend} backend"
    )
    speed_error.plot(points, args.plot, f"PBF dam break, {args.frames} frames from rest ({made})")
    print(f"wrote {args.plot}" if args.from_csv else f"wrote {args.csv} and {args.plot}")
    return points


def _thread_count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 256:
        raise argparse.ArgumentTypeError(f"expected a whole number of threads from 1 to 256, got {text!r}")
    return value


MODES = ("sizes", "sweep", "terms", "presets", "compare", "counts", "start", "traffic")
"""The modes of ``main`` (``frames`` aside: it hands its arguments to ``pbf.study.frames``)."""
BACKEND_MODES = ("sizes", "sweep", "terms", "presets", "counts", "traffic")
"""The modes that start a backend in this process (``main``'s ``start_backend``, which takes ``--arch``,
``--threads`` and ``--fast-compile``): all but ``compare``, which only reads tables, and ``start``, whose
starts are processes of their own that are handed ``--arch`` alone."""
OPTION_MODES: dict[str, tuple[str, ...]] = {
    "tables": ("compare",),
    "--presets": ("presets", "start", "counts"),
    "--no-shared": ("start",),
    "--first-calls": ("start",),
    # Only where a Simulation is built with a GPU's choices (``Simulation(choices=...)``): terms, traffic
    # and sweep build theirs on the backend's own path (the device's only on a GPU, with or without the option).
    "--device-decisions": ("sizes", "presets", "counts"),
    "--gpu-blocks": ("counts",),
    "--fast-compile": BACKEND_MODES,
    "--perturb": ("presets",),
    "--perturb-each-frame": ("presets",),
    "--sizes": ("sizes", "sweep", "terms", "counts", "traffic"),  # traffic: the first count only
    "--iterations": ("sizes", "sweep", "terms", "counts", "traffic"),
    "--substeps": ("sweep",),
    "--target": ("sweep",),
    "--frames": ("sizes", "sweep", "presets"),  # terms times substeps in --rounds; counts, a fixed number
    "--particles": ("traffic",),
    "--warmup": ("sizes", "terms", "traffic"),
    "--rest-settle": ("sweep",),
    "--rest-frames": ("sweep",),
    "--flow": ("sweep",),
    "--rounds": ("terms",),
    "--set": BACKEND_MODES,  # start's processes run the presets as shipped
    "--arch": ("sizes", "sweep", "terms", "presets", "counts", "start", "traffic"),
    "--csv": ("sizes", "sweep", "presets", "start"),  # sweep writes it unless --from-csv
    "--threads": BACKEND_MODES,
    "--from-csv": ("sweep",),
    "--plot": ("sweep",),
}
"""Every option of ``main`` (``tables`` for the positional tables), and the modes that read it, found by
reading each mode's code down through the helpers it calls: ``main`` refuses an option given to any
other mode, which would run as if it had not been given. A mode that reads an option only in some of
its runs (sweep's ``--sizes`` not with ``--from-csv``) is listed: the option is not refused there.
tests/test_bench_options.py checks that every option of the parser is here."""

SWEEP_RUN_OPTIONS = (
    "--sizes",
    "--iterations",
    "--substeps",
    "--target",
    "--rest-settle",
    "--rest-frames",
    "--flow",
    "--set",
    "--csv",
    "--threads",
    "--fast-compile",
)
"""The options a sweep reads only when it runs its points, not when it re-plots them ``--from-csv``."""

_NOT_GIVEN = object()


def given_options(parser: argparse.ArgumentParser, argv: list[str]) -> set[str]:
    """The options ``argv`` gives, by their option string (``tables`` where it names any).

    argparse itself says, not a comparison with the defaults, which would miss an option given at its
    default's value (``--frames 60``), nor a scan of argv's tokens, which would miss argparse's own
    spellings (``--frame 3``, ``--frames=3``) and take an option's value for another option: argparse
    sets a default only on a namespace that lacks the attribute, so each option's attribute set first
    to a marker keeps the marker unless the option was given. ``--set`` appends to what is there, so
    it starts from an empty list instead; the tables, a positional, are given when there are any."""
    namespace = argparse.Namespace()
    for action in parser._actions:
        if action.option_strings and action.dest != "help":
            setattr(namespace, action.dest, [] if isinstance(action, argparse._AppendAction) else _NOT_GIVEN)
    parser.parse_args(argv, namespace=namespace)
    given = {"tables"} if namespace.tables else set()
    for action in parser._actions:
        value = getattr(namespace, action.dest, _NOT_GIVEN) if action.option_strings else _NOT_GIVEN
        if value is not _NOT_GIVEN and value != []:
            given.add(action.option_strings[0])
    return given


def build_parser() -> argparse.ArgumentParser:
    """``main``'s parser: it runs nothing (the tests read its options)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", nargs="?", choices=MODES, default="sizes")
    parser.add_argument("tables", nargs="*", type=Path, help="compare: the CSV tables of presets runs")
    parser.add_argument(
        "--presets",
        nargs="+",
        default=None,
        help="presets, start: which (default: all); counts: these presets as shipped, instead of the seed at --sizes",
    )
    parser.add_argument("--no-shared", action="store_true", help="start: leave out the starts in one shared cache")
    parser.add_argument(
        "--first-calls", action="store_true", help="start: each kernel's first call (its compile) instead, per preset"
    )
    parser.add_argument(
        "--device-decisions",
        action="store_true",
        help="keep the substep's decisions on the device, as GPU backends do, on any backend",
    )
    parser.add_argument(
        "--gpu-blocks",
        action="store_true",
        help="lay the prefix sums and tree sums out in a GPU backend's blocks on any backend: a GPU's launches "
        "(the float sums as on Vulkan and Metal; CUDA adds them up in shared memory, in 1-2 launches)",
    )
    parser.add_argument("--fast-compile", action="store_true", help="Taichi without its advanced optimisation")
    parser.add_argument(
        "--perturb",
        type=int,
        default=None,
        metavar="SEED",
        help="presets: start from positions moved by 1e-7 m (rounding-sized noise) drawn from SEED, "
        "gravity off by 2e-7 × SEED",
    )
    parser.add_argument(
        "--perturb-each-frame",
        action="store_true",
        help="presets, with --perturb: the positions moved by such noise again after every frame, "
        "as a backend that rounds differently departs all along",
    )
    parser.add_argument(
        "--sizes", type=int, nargs="+", default=None, help="particle counts (default: 8000 64000; terms: 8000)"
    )
    parser.add_argument(
        "--iterations", type=int, nargs="+", default=None, help="solver iterations (default: 4; sweep: 1 2 3 4 6 8 12)"
    )
    parser.add_argument(
        "--substeps", type=int, nargs="+", default=None, help="sweep: substeps per frame (default: 1 2 4)"
    )
    parser.add_argument(
        "--target",
        type=float,
        default=0.005,
        help="sweep: also stop iterating under this mean density error (0: no such points)",
    )
    parser.add_argument("--frames", type=int, default=60, help="timed frames per size, sweep point or preset")
    parser.add_argument(
        "--particles", type=int, default=1_000_000, help="traffic: the particle count the bytes are scaled to"
    )
    parser.add_argument("--warmup", type=int, default=30, help="untimed frames first (sizes, terms, traffic)")
    parser.add_argument("--rest-settle", type=int, default=20, help="sweep: frames the rest tank settles")
    parser.add_argument("--rest-frames", type=int, default=40, help="sweep: frames of energy drift at rest")
    parser.add_argument(
        "--flow",
        action="store_true",
        help="sweep: also run each setting on the flow cases "
        "(SPHERIC Test 2, the wave tank, the standing wave; pbf.study.sweep.flow_measures)",
    )
    parser.add_argument("--rounds", type=int, default=25, help="terms: interleaved timing rounds")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scene key of the benchmark scenes, e.g. solver.kernel_ratio=2.0 (repeatable)",
    )
    parser.add_argument("--arch", choices=ARCHES, default=None, help="Taichi backend (default: $PBF_ARCH or auto)")
    parser.add_argument(
        "--csv", type=Path, default=None, help="write the table as CSV (sweep default: docs/speed_vs_error.csv)"
    )
    parser.add_argument(
        "--threads",
        type=_thread_count,
        metavar="N",
        default=None,
        help="the CPU backend's threads (default: one per core)",
    )
    parser.add_argument("--from-csv", type=Path, default=None, help="sweep: re-plot this CSV instead of running")
    parser.add_argument("--plot", type=Path, default=Path("docs/speed_vs_error.png"), help="sweep: the plot")
    return parser


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["frames"]:  # the headless frames' own study, with its own options
        from pbf.study import frames

        return frames.main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    given = given_options(parser, argv)
    for option, modes in OPTION_MODES.items():  # before anything starts: no backend, no process
        if option in given and args.mode not in modes:
            names = [mode for mode in MODES if mode in modes]
            listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
            parser.error(
                f"{option}: applies to the {listed} mode{'s' if len(names) > 1 else ''} only, not to {args.mode}"
            )
    # A sweep from --from-csv re-plots the points the CSV holds and runs nothing.
    for option in SWEEP_RUN_OPTIONS:
        if args.from_csv is not None and option in given:
            parser.error(f"{option}: applies to a sweep that runs, not to one re-plotted --from-csv")
    if args.first_calls and (args.no_shared or args.csv is not None):  # the starts' options, not this table's
        parser.error(
            f"{'--no-shared' if args.no_shared else '--csv'}: applies to the starts' table, not to --first-calls"
        )
    if args.perturb_each_frame and args.perturb is None:
        parser.error("--perturb-each-frame: needs --perturb SEED (the noise's seed)")
    if args.mode == "counts" and args.presets and {"--sizes", "--iterations"} & given:
        option = "--sizes" if "--sizes" in given else "--iterations"
        parser.error(f"{option}: counts the seed scene scaled; with --presets each preset runs as shipped")
    if args.mode != "sweep" and len(args.iterations or [4]) > 1:
        parser.error(f"--iterations: {args.mode} takes one count (several are for sweep)")
    for name in args.presets or ():  # every scene read before any runs (each start reads its own again)
        try:
            load_scene(name)
        except SceneError as error:
            parser.error(f"--presets: {error}")
    if args.mode == "compare":
        for table in args.tables:  # each table read before any is judged
            needed = {"preset", "backend", *PRESET_STATISTICS}
            try:
                with table.open(newline="") as file:
                    missing = needed - set(next(csv.reader(file), []))
            except (OSError, UnicodeDecodeError) as error:
                parser.error(f"tables: {table}: cannot be read ({error.__class__.__name__}: {error})")
            if missing:
                parser.error(f"tables: {table}: not a presets table (no column {', '.join(sorted(missing))})")
        return compare(args.tables)
    if args.mode == "start":  # each start a process of its own: this one starts no backend
        from pbf.study import start

        names = args.presets or sorted(path.stem for path in SCENES_DIR.glob("*.toml"))
        if args.first_calls:
            return start.first_calls(names, args.arch)
        return start.run(names, args.arch, not args.no_shared, args.csv)
    args.backend = start_backend(
        args.arch,
        quiet=True,
        cpu_threads=args.threads,
        fast_compile=args.fast_compile,
        kernel_profiler=args.mode == "counts",
    )
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
    if args.mode == "sweep":
        args.sizes = args.sizes or [8000, 64000]
        args.iterations = args.iterations or list(speed_error.ITERATIONS)
        args.substeps = args.substeps or list(speed_error.SUBSTEPS)
        args.csv = args.csv or Path("docs/speed_vs_error.csv")
        return sweep(args)
    args.iterations = (args.iterations or [4])[0]
    if args.mode == "terms":
        args.sizes = args.sizes or [8000]
        return terms(args)
    if args.mode == "presets":
        return presets(args)
    if args.mode == "counts":
        return counts(args)
    if args.mode == "traffic":
        return traffic(args)
    args.sizes = args.sizes or [8000, 64000]
    return sizes(args)


if __name__ == "__main__":
    run_command(main)
