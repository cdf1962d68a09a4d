"""Speed against error: the solver settings that trade one for the other, swept and plotted.

    python -m pbf.study.sweep [--sizes 8000 64000] [--iterations 1 2 3 4 6 8 12] [--substeps 1 2 4]
                              [--target 0.005] [--frames 60] [--flow] [--csv docs/speed_vs_error.csv]
                              [--plot docs/speed_vs_error.png] [--arch cpu] [--threads N] [--set KEY=VALUE]
    python -m pbf.study.sweep --from-csv docs/speed_vs_error.csv     # re-plot the points a CSV holds

Each point is a dam break (the seed preset, spacing scaled to the particle count) run for ``frames``
frames from rest with one setting of iterations and substeps per frame. It reports the median ms per
frame (and per substep actually taken: the CFL limit may add substeps), the mean and max density
error max(ρ/ρ0 − 1, 0) over the run, the peak speed (a blow-up shows there first) and the energy
drift of the same setting on a tank at rest. One more point per substep count stops iterating when
the mean error falls under ``--target`` (at most the largest iteration count). The plot puts error
against time per frame on log axes and joins each size's Pareto front: the points that no other
point beats on both.

With ``--flow`` each setting is also run on the flow cases (:func:`flow_measures`, at their presets'
own particle counts, the setting's iterations, substeps and target applied to them): SPHERIC Test 2
(the rms errors of H2 and H4 over their ranges and the delay of the reflected wave at H4, over the
first ``FLOW_SPHERIC_SECONDS``), the wave tank's height over Biésel's two depths from the piston, and
the standing wave's decay per period (``pbf.study.damping``). The plot then gains a panel of those
against the same time per frame, so that a setting is chosen on its flow as well as its density.
"""

import argparse
import math
import platform
import statistics
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pbf.solver import ARCHES, Simulation, start_backend
from pbf.study.common import run_command, scaled, timed

ITERATIONS = (1, 2, 3, 4, 6, 8, 12)
SUBSTEPS = (1, 2, 4)


@dataclass
class Point:
    particles: int
    iterations: int
    """Iterations per substep; with a target, the most allowed."""
    substeps: int
    """Substeps per frame asked for; ``substeps_used`` may be more (the CFL limit)."""
    target_density_error: float
    substeps_used: float
    iterations_used: float
    """Mean over the frames of the last substep's iteration count (below ``iterations`` with a target)."""
    ms_per_frame: float
    ms_per_substep: float
    particle_substeps_per_s: float
    mean_density_error: float
    max_density_error: float
    peak_speed_m_s: float
    rest_energy_drift: float
    """(E_end − E_start) / (M g H) on the tank at rest, E = kinetic + potential energy."""
    rest_max_speed_m_s: float
    pareto: bool = False
    spheric_h2_rms: float = math.nan
    """SPHERIC Test 2, the ``dam_break_obstacle`` preset with this setting: rms(H2 − measured) / measured range."""
    spheric_h4_rms: float = math.nan
    spheric_return_delay_s: float = math.nan
    """The reflected wave's return at H4, simulated − measured (full-scale s)."""
    wave_height_ratio: float = math.nan
    """The ``wave_tank`` preset with this setting: H / H_Biésel two depths from the piston."""
    sloshing_decay: float = math.nan
    """The ``sloshing`` preset's standing wave with this setting: amplitude lost per period."""


def configure(sim: Simulation, iterations: int, substeps: int, target: float) -> None:
    """Back to the scene's start (settled once, with time.settle_s), then the point's solver setting."""
    sim.reset()
    sim.control.iterations = iterations
    sim.control.substeps = substeps
    sim.control.target_density_error = target


def run_dam_break(sim: Simulation, frames: int) -> dict:
    """Step ``frames`` frames, timing each (the first, which may compile kernels, is not counted)."""
    frame_ms, substeps, iterations, mean_errors, max_errors, speeds = [], [], [], [], [], []
    for frame in range(frames):
        seconds = timed(sim.step)
        stats = sim.stats()
        if frame > 0:
            frame_ms.append(seconds * 1e3)
        substeps.append(sim.frame_substeps)
        iterations.append(sim.iterations_used)
        mean_errors.append(stats["mean_density_error"])
        max_errors.append(stats["max_density_error"])
        speeds.append(stats["max_speed_m_s"])
    ms = statistics.median(frame_ms)
    per_substep = statistics.median(f / s for f, s in zip(frame_ms, substeps[1:]))
    return {
        "substeps_used": statistics.fmean(substeps),
        "iterations_used": statistics.fmean(iterations),
        "ms_per_frame": ms,
        "ms_per_substep": per_substep,
        "particle_substeps_per_s": sim.particle_count / (per_substep / 1e3),
        "mean_density_error": statistics.fmean(mean_errors),
        "max_density_error": max(max_errors),
        "peak_speed_m_s": max(speeds),
    }


def energy(sim: Simulation) -> float:
    """Kinetic plus potential energy in J (potential measured from the container floor, along −g)."""
    g = np.asarray(sim.control.gravity_m_s2, dtype=np.float64)
    height = -(sim.positions().astype(np.float64) - sim.scene.container.min_m) @ g
    return sim.stats()["kinetic_energy_j"] + sim.model.particle_mass_kg * float(height.sum())


def run_rest(sim: Simulation, settle_frames: int, frames: int) -> dict:
    """Energy drift and the fastest particle of a tank at rest, after it settles from its lattice."""
    sim.step(settle_frames)
    start = energy(sim)
    sim.step(frames)
    depth = max(b.max_m[1] for b in sim.scene.fluid.blocks) - sim.scene.container.min_m[1]
    scale = sim.particle_count * sim.model.particle_mass_kg * float(np.linalg.norm(sim.control.gravity_m_s2)) * depth
    return {"rest_energy_drift": (energy(sim) - start) / scale, "rest_max_speed_m_s": sim.stats()["max_speed_m_s"]}


FLOW_SPHERIC_SECONDS = 3.4
"""Full-scale seconds of SPHERIC Test 2 a sweep point runs: past the reflected wave's return at H4 (2.74 s)."""


def flow_overrides(scene, iterations: int, substeps: int, target: float) -> list[str]:
    """A sweep setting as overrides of a flow preset: its iterations (all of them without a target),
    substeps and target; the preset's least iterations kept where the setting allows them."""
    least = iterations if target == 0.0 else min(scene.solver.min_iterations, iterations)
    return [
        f"solver.iterations={iterations}",
        f"solver.min_iterations={least}",
        f"time.substeps={substeps}",
        f"solver.target_density_error={target!r}",
    ]


def flow_measures(iterations: int, substeps: int, target: float, overrides=()) -> dict:
    """The flow figures of one setting (module docstring)."""
    from pbf.scene import load_scene
    from pbf.study import damping, spheric, validate

    def settings(preset):
        return [*flow_overrides(load_scene(preset), iterations, substeps, target), *overrides]

    figures = spheric.run(None, FLOW_SPHERIC_SECONDS, settings(spheric.PRESET)).figures
    wave = validate.wave_tank(overrides=settings("wave_tank"))
    slosh = damping.sloshing(settings(damping.PRESET), periods=3.0)
    return {
        "spheric_h2_rms": figures.rms_over_range["H2"],
        "spheric_h4_rms": figures.rms_over_range["H4"],
        "spheric_return_delay_s": figures.return_s[0] - figures.return_s[1],
        "wave_height_ratio": wave.heights_m[0] / wave.expected_height_m,
        "sloshing_decay": slosh.decay_per_period,
    }


def mark_pareto(points: list[Point]) -> None:
    """Flag, per particle count, the points no other point beats on both time per frame and mean error."""
    for p in points:
        p.pareto = not any(
            q.particles == p.particles
            and q is not p
            and q.ms_per_frame <= p.ms_per_frame
            and q.mean_density_error <= p.mean_density_error
            and (q.ms_per_frame, q.mean_density_error) != (p.ms_per_frame, p.mean_density_error)
            for q in points
        )


def sweep(
    sizes, iteration_counts, substep_counts, target, frames, rest_settle, rest_frames, overrides=(), flow: bool = False
) -> list[Point]:
    settings = [(i, s, 0.0) for s in substep_counts for i in iteration_counts]
    if target > 0:
        settings += [(max(iteration_counts), s, target) for s in substep_counts]
    flows = {}
    if flow:
        for setting in tqdm(settings, desc="flow cases", unit="setting"):
            flows[setting] = flow_measures(*setting, overrides)
    points = []
    with tqdm(total=len(sizes) * len(settings), desc="sweep", unit="point") as bar:
        for particles in sizes:
            dam = Simulation(scaled("dam_break", particles, 8000, overrides), quiet=True)
            tank = Simulation(scaled("hydrostatic", particles, 5120, overrides), quiet=True)
            for iterations, substeps, goal in settings:
                bar.set_postfix_str(
                    f"{dam.particle_count:,} particles, {iterations} it, {substeps} substeps"
                    + (f", target {goal:.2%}" if goal else "")
                )
                configure(dam, iterations, substeps, goal)
                figures = run_dam_break(dam, frames)
                configure(tank, iterations, substeps, goal)
                figures.update(run_rest(tank, rest_settle, rest_frames))
                figures.update(flows.get((iterations, substeps, goal), {}))
                points.append(Point(dam.particle_count, iterations, substeps, goal, **figures))
                bar.update()
    mark_pareto(points)
    return points


def print_table(points: list[Point]) -> None:
    print(
        f"{'particles':>9} {'iters':>5} {'subst':>5} {'target':>6} {'used s/i':>9} {'ms/frame':>9} "
        f"{'ms/subst':>8} {'particle-subst/s':>16} {'mean err':>8} {'max err':>8} {'peak v':>7} "
        f"{'rest drift':>10} {'rest v':>7} pareto"
    )
    for p in points:
        target = f"{p.target_density_error:.2%}" if p.target_density_error else "-"
        print(
            f"{p.particles:>9,} {p.iterations:>5} {p.substeps:>5} {target:>6} "
            f"{p.substeps_used:>4.1f}/{p.iterations_used:<4.1f} {p.ms_per_frame:>9.1f} {p.ms_per_substep:>8.2f} "
            f"{p.particle_substeps_per_s:>16,.0f} {p.mean_density_error:>8.3%} {p.max_density_error:>8.2%} "
            f"{p.peak_speed_m_s:>7.2f} {p.rest_energy_drift:>10.2e} {p.rest_max_speed_m_s:>7.3f} "
            f"{'*' if p.pareto else ''}"
        )
    flowing = [p for p in points if not math.isnan(p.sloshing_decay)]
    if flowing:
        print(
            f"\n{'iters':>5} {'subst':>5} {'target':>6} {'H2 rms':>7} {'H4 rms':>7} {'H4 return':>9} "
            f"{'wave H/H_B':>10} {'slosh decay':>11}   (flow cases, their presets' particle counts)"
        )
        seen = set()
        for p in flowing:
            if (p.iterations, p.substeps, p.target_density_error) in seen:
                continue
            seen.add((p.iterations, p.substeps, p.target_density_error))
            target = f"{p.target_density_error:.2%}" if p.target_density_error else "-"
            print(
                f"{p.iterations:>5} {p.substeps:>5} {target:>6} {p.spheric_h2_rms:>7.3f} {p.spheric_h4_rms:>7.3f} "
                f"{p.spheric_return_delay_s:>+8.2f}s {p.wave_height_ratio:>10.2f} {p.sloshing_decay:>10.1%}"
            )


def write_csv(points: list[Point], path) -> None:
    import csv

    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=[f.name for f in fields(Point)])
        writer.writeheader()
        writer.writerows(asdict(p) for p in points)


def read_csv(path) -> list[Point]:
    """Points written by :func:`write_csv` (to re-plot a sweep without running it again)."""
    import csv

    types = {f.name: f.type for f in fields(Point)}
    convert = {"int": int, "float": float, "bool": lambda text: text == "True"}
    with path.open(newline="") as f:  # a CSV from before the flow columns reads them as NaN
        return [
            Point(**{k: convert[str(getattr(types[k], "__name__", types[k]))](v) for k, v in row.items() if k in types})
            for row in csv.DictReader(f)
        ]


def plot(points: list[Point], path, title: str) -> None:
    """Mean density error against ms per frame, log-log; Pareto fronts joined, target points as stars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    flowing = [p for p in points if not math.isnan(p.sloshing_decay)]
    if flowing:
        fig, (ax, flow_ax) = plt.subplots(1, 2, figsize=(15, 5.5), constrained_layout=True)
        plot_flow(flow_ax, flowing)
    else:
        fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    shapes = "o^sDvPXh"
    markers = {s: shapes[k % len(shapes)] for k, s in enumerate(sorted({p.substeps for p in points}))}
    for k, particles in enumerate(sorted({p.particles for p in points})):
        colour = plt.cm.tab10(k % 10)
        mine = [p for p in points if p.particles == particles]
        for p in mine:
            if p.target_density_error:
                ax.scatter(
                    p.ms_per_frame, p.mean_density_error, marker="*", s=220, color=colour, edgecolor="black", zorder=4
                )
                ax.annotate(
                    f"{p.substeps} sub",
                    (p.ms_per_frame, p.mean_density_error),
                    xytext=(7, -9),
                    textcoords="offset points",
                    fontsize=7,
                )
            else:
                ax.scatter(
                    p.ms_per_frame,
                    p.mean_density_error,
                    marker=markers[p.substeps],
                    color=colour,
                    alpha=0.9 if p.pareto else 0.35,
                    zorder=3,
                )
                ax.annotate(
                    str(p.iterations),
                    (p.ms_per_frame, p.mean_density_error),
                    xytext=(3, 3),
                    textcoords="offset points",
                    fontsize=7,
                )
        front = sorted((p for p in mine if p.pareto), key=lambda p: p.ms_per_frame)
        ax.step(
            [p.ms_per_frame for p in front],
            [p.mean_density_error for p in front],
            where="post",
            color=colour,
            label=f"{particles:,} particles: Pareto front",
        )
    for substeps, marker in markers.items():
        ax.scatter([], [], marker=marker, color="grey", label=f"{substeps} substep{'s' * (substeps > 1)} per frame")
    targets = sorted({p.target_density_error for p in points if p.target_density_error})
    if targets:
        ax.scatter(
            [],
            [],
            marker="*",
            s=120,
            color="grey",
            edgecolor="black",
            label=f"stop under {', '.join(f'{t:.2%}' for t in targets)} mean error (substeps marked)",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("median time per frame (ms)")
    ax.set_ylabel("mean density error over the run, max(ρ/ρ0 − 1, 0)")
    ax.yaxis.set_major_formatter(matplotlib.ticker.PercentFormatter(1.0, decimals=2))
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def plot_flow(ax, points: list[Point]) -> None:
    """The flow measures of each setting against the time per frame of the smallest dam break: each
    measure over its goal (SPHERIC's H4 return within 0.1 s, H2 and H4 rms within 6% of their ranges,
    the wave tank at 0.9 of Biésel's height or more: its shortfall over 0.1), so that 1 is the goal."""
    import matplotlib

    smallest = min(p.particles for p in points)
    mine = sorted((p for p in points if p.particles == smallest), key=lambda p: p.ms_per_frame)
    measures = {
        "H4 return delay / 0.1 s": lambda p: abs(p.spheric_return_delay_s) / 0.1,
        "H2 rms / 0.06": lambda p: p.spheric_h2_rms / 0.06,
        "H4 rms / 0.06": lambda p: p.spheric_h4_rms / 0.06,
        "wave tank (1 − H/H_Biésel) / 0.1": lambda p: (1 - p.wave_height_ratio) / 0.1,
        "standing wave's decay per period / 0.13": lambda p: p.sloshing_decay / 0.13,
    }
    for marker, (label, value) in zip("os^Dv", measures.items()):
        ax.scatter([p.ms_per_frame for p in mine], [value(p) for p in mine], marker=marker, label=label, alpha=0.8)
    for p in mine:
        tag = f"{p.iterations}i/{p.substeps}s" + (f"/{p.target_density_error:.2%}" if p.target_density_error else "")
        ax.annotate(
            tag,
            (p.ms_per_frame, measures["H4 return delay / 0.1 s"](p)),
            xytext=(3, 3),
            textcoords="offset points",
            fontsize=6,
        )
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"median time per frame of the {smallest:,}-particle dam break (ms)")
    ax.set_ylabel("flow error over its goal (1: at the goal)")
    ax.yaxis.set_major_locator(matplotlib.ticker.FixedLocator([0.25, 0.5, 1, 2, 4, 8, 16]))
    ax.yaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_title("Flow: SPHERIC Test 2, the wave tank and the standing wave at each setting", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


RUN_OPTIONS = ("sizes", "iterations", "substeps", "rest_settle", "rest_frames", "flow", "set", "csv", "threads")
"""What only a sweep that runs reads, not one re-plotted ``--from-csv``."""


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=None, help="particle counts (default: 8000 64000)")
    parser.add_argument("--iterations", type=int, nargs="+", default=None, help="default: 1 2 3 4 6 8 12")
    parser.add_argument("--substeps", type=int, nargs="+", default=None, help="substeps a frame (default: 1 2 4)")
    parser.add_argument("--target", type=float, default=0.005, help="also stop under this mean error (0: none)")
    parser.add_argument("--frames", type=int, default=60, help="frames a point runs")
    parser.add_argument("--rest-settle", type=int, default=None, help="frames the rest tank settles (20)")
    parser.add_argument("--rest-frames", type=int, default=None, help="frames of energy drift at rest (40)")
    parser.add_argument("--flow", action="store_true", help="also the flow cases (flow_measures)")
    parser.add_argument("--set", action="append", default=None, metavar="KEY=VALUE", help="a scene key (repeatable)")
    parser.add_argument("--arch", choices=ARCHES, default=None, help="Taichi backend (default: $PBF_ARCH or auto)")
    parser.add_argument("--threads", type=int, default=None, metavar="N", help="the CPU backend's threads")
    parser.add_argument("--csv", type=Path, default=None, help="default: docs/speed_vs_error.csv")
    parser.add_argument("--plot", type=Path, default=Path("docs/speed_vs_error.png"))
    parser.add_argument("--from-csv", type=Path, default=None, help="re-plot this CSV instead of running")
    args = parser.parse_args(argv)
    given = [name for name in RUN_OPTIONS if getattr(args, name) not in (None, False)]
    if args.from_csv is not None and given:
        parser.error(f"--{given[0].replace('_', '-')}: applies to a sweep that runs, not to one re-plotted --from-csv")
    return args


def main(argv=None):
    args = parse_args(argv)
    if args.from_csv:
        points, made = read_csv(args.from_csv), f"the points of {args.from_csv.name}"
    else:
        backend = start_backend(args.arch, quiet=True, cpu_threads=args.threads)
        made = f"{platform.processor() or platform.machine()}, {backend} backend"
        points = sweep(
            args.sizes or [8000, 64000],
            args.iterations or list(ITERATIONS),
            args.substeps or list(SUBSTEPS),
            args.target,
            args.frames,
            args.rest_settle or 20,
            args.rest_frames or 40,
            args.set or [],
            args.flow,
        )
        args.csv = args.csv or Path("docs/speed_vs_error.csv")
        write_csv(points, args.csv)
    print_table(points)
    # Re-plotted, the points are the CSV's machine's, not this one's (--frames says how long they ran).
    plot(points, args.plot, f"PBF dam break, {args.frames} frames from rest ({made})")
    print(f"wrote {args.plot}" if args.from_csv else f"wrote {args.csv} and {args.plot}")
    return points


if __name__ == "__main__":
    run_command(main)
