"""Speed against error: the solver settings that trade one for the other, swept and plotted.

    python -m pbf.study.bench sweep [--sizes 8000 64000] [--iterations 1 2 3 4 6 8 12] [--substeps 1 2 4]
                              [--target 0.005] [--frames 60] [--csv docs/speed_vs_error.csv]
                              [--plot docs/speed_vs_error.png]

Each point is a dam break (the seed preset, spacing scaled to the particle count) run for ``frames``
frames from rest with one setting of iterations and substeps per frame. It reports the median ms per
frame (and per substep actually taken: the CFL limit may add substeps), the mean and max density
error max(ρ/ρ0 − 1, 0) over the run, the peak speed (a blow-up shows there first) and the energy
drift of the same setting on a tank at rest. One more point per substep count stops iterating when
the mean error falls under ``--target`` (at most the largest iteration count). The plot puts error
against time per frame on log axes and joins each size's Pareto front: the points that no other
point beats on both.
"""

import statistics
from dataclasses import asdict, dataclass, fields

import numpy as np
from tqdm import tqdm

from pbf.solver import Simulation
from pbf.study.common import scaled, timed

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
    sizes, iteration_counts, substep_counts, target, frames, rest_settle, rest_frames, overrides=()
) -> list[Point]:
    settings = [(i, s, 0.0) for s in substep_counts for i in iteration_counts]
    if target > 0:
        settings += [(max(iteration_counts), s, target) for s in substep_counts]
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
    convert = {int: int, float: float, bool: lambda text: text == "True"}
    with path.open(newline="") as f:
        return [Point(**{k: convert[types[k]](v) for k, v in row.items()}) for row in csv.DictReader(f)]


def plot(points: list[Point], path, title: str) -> None:
    """Mean density error against ms per frame, log-log; Pareto fronts joined, target points as stars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
