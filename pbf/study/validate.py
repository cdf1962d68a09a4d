"""Validation against experiment and theory: the Martin & Moyce dam break, a hydrostatic tank, a
wave maker and the SPHERIC Test 2 dam break against a box.

    python -m pbf.study.validate [martin_moyce] [hydrostatic] [wave_tank] [spheric2] [--divisors 9 12 24]
                                 [--frames 600] [--spheric-across N] [--spheric-seconds 7.39] [--out docs]

``martin_moyce`` runs the ``martin_moyce`` preset at spacings a/n for each n of ``--divisors``, tracks
the surge front (the largest x reached by water, spray ignored) against dimensionless time
T = t·sqrt(2g/a), and compares Z = x/a with Martin & Moyce (1952), Table 2
(``docs/data/martin_moyce_1952_surge_front.csv``). ``hydrostatic`` runs the ``hydrostatic`` preset for
``--frames`` frames and compares pressure against depth with ρ0 g (H − y) and the free surface with the
fill height H. ``wave_tank`` runs the ``wave_tank`` preset and compares the height of the waves its
piston makes with linear wave-maker theory (Biésel's transfer function). Each prints its figures and
writes a plot (and the curves as CSV) under ``--out``.
"""

import argparse
import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pbf.scene import load_scene
from pbf.solver import Simulation, start_backend
from pbf.study import spheric
from pbf.study.common import colour_surface_height, fill_height_m, run_command

MARTIN_MOYCE_CSV = Path(__file__).resolve().parents[2] / "docs" / "data" / "martin_moyce_1952_surge_front.csv"
SPRAY_NEIGHBOURS = 4
"""A particle with fewer neighbours within h than this is spray, not the front (a full one has ~40)."""


def martin_moyce_data() -> tuple[np.ndarray, np.ndarray]:
    """The measured (T, Z) of the surge front, Martin & Moyce (1952) Table 2, n² = 2."""
    lines = [
        line.strip() for line in MARTIN_MOYCE_CSV.read_text().splitlines() if line.strip() and not line.startswith("#")
    ]
    if lines[0] != "T,Z":
        raise ValueError(f"{MARTIN_MOYCE_CSV}: expected the columns T,Z, found {lines[0]!r}")
    table = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    return table[:, 0], table[:, 1]


def surge_front(positions: np.ndarray, neighbour_counts: np.ndarray, spacing_m: float) -> float:
    """The largest x reached by water: the foremost particle with at least SPRAY_NEIGHBOURS neighbours,
    plus half a spacing (each particle stands for a cube of water one spacing wide; the initial
    column's edge at x = a is half a spacing beyond its last particles)."""
    connected = neighbour_counts >= SPRAY_NEIGHBOURS
    return float(positions[connected, 0].max()) + 0.5 * spacing_m


@dataclass
class SurgeRun:
    divisor: int
    """The spacing is a / divisor."""
    particles: int
    T: np.ndarray
    Z: np.ndarray
    max_deviation: float
    """max |Z_sim − Z_exp| over the measured points."""
    at_T: float
    mean_offset: float
    """Mean of Z_sim − Z_exp (positive: the simulation runs ahead)."""


def martin_moyce(divisor: int, end_T: float = 3.5, overrides=()) -> SurgeRun:
    """The ``martin_moyce`` preset at spacing a/divisor (Δt scaled with it), run until T = end_T."""
    base = load_scene("martin_moyce")
    column = base.fluid.blocks[0]
    a = column.max_m[0] - column.min_m[0]
    spacing = a / divisor
    substeps = math.ceil(base.time.substeps * base.fluid.spacing_m / spacing - 1e-9)
    # One substep per "frame": the front is sampled every substep and the CFL limit still applies.
    scene = load_scene(
        "martin_moyce",
        [
            f"fluid.spacing_m={spacing!r}",
            "time.substeps=1",
            f"time.frame_dt_s={base.time.frame_dt_s / substeps!r}",
            *overrides,
        ],
    )
    sim = Simulation(scene, quiet=True)
    g = float(np.linalg.norm(scene.gravity_m_s2))
    to_T = math.sqrt(2 * g / a)
    times, fronts = [0.0], [surge_front(sim.positions(), sim.neighbour_counts(), spacing)]
    while times[-1] * to_T < end_T:
        sim.step()
        times.append(sim.time_s)
        fronts.append(surge_front(sim.positions(), sim.neighbour_counts(), spacing))
    T, Z = np.array(times) * to_T, np.array(fronts) / a
    measured_T, measured_Z = martin_moyce_data()
    deviation = np.interp(measured_T, T, Z) - measured_Z
    worst = int(np.argmax(np.abs(deviation)))
    return SurgeRun(
        divisor,
        sim.particle_count,
        T,
        Z,
        float(abs(deviation[worst])),
        float(measured_T[worst]),
        float(deviation.mean()),
    )


def plot_martin_moyce(runs: list[SurgeRun], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    measured_T, measured_Z = martin_moyce_data()
    fig, ax = plt.subplots(figsize=(6.5, 4.5), constrained_layout=True)
    ax.plot(measured_T, measured_Z, "ko", label="Martin & Moyce (1952), n² = 2")
    for run in runs:
        ax.plot(
            run.T,
            run.Z,
            label=f"PBF, spacing a/{run.divisor} ({run.particles:,} particles): max |ΔZ| {run.max_deviation:.2f}",
        )
    ax.set_xlabel("T = t·sqrt(2g/a)")
    ax.set_ylabel("Z = surge front x / a")
    ax.set_xlim(0, max(run.T[-1] for run in runs))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Collapse of a water column: surge front", fontsize=10)
    fig.savefig(path, dpi=130)
    plt.close(fig)


@dataclass
class HydrostaticRun:
    particles: int
    fill_height_m: float
    """H: the analytic fill height (:func:`fill_height_m`)."""
    depth_m: np.ndarray
    """Bin centres of depth H − y."""
    pressure_pa: np.ndarray
    """Mean pressure of the particles in each depth bin."""
    slope_pa_m: float
    """Least-squares dp/d(depth) over the interior particles; ρ0 g in theory."""
    expected_slope_pa_m: float
    pressure_rms_error: float
    """rms of (p − ρ0 g (H − y)) over the interior particles, relative to ρ0 g H."""
    times_s: np.ndarray
    surface_m: np.ndarray
    """The free surface (colour field ½) over time."""


PRESSURE_FRAMES = 60
"""The pressure against depth is each particle's mean over the last this many frames (and its mean
position): one substep's multipliers swing by ±10-15% in the slope from frame to frame as the
iteration count the error target stops at changes."""


def hydrostatic(frames: int = 600, samples: int = 30, overrides=()) -> HydrostaticRun:
    """Run the ``hydrostatic`` preset ``frames`` frames; sample the surface ``samples`` times, and the
    pressure over the last PRESSURE_FRAMES frames."""
    if frames < 1 or samples < 1:
        raise ValueError(f"hydrostatic: frames = {frames}, samples = {samples}; allowed: 1 or more each")
    scene = load_scene("hydrostatic", overrides)
    sim = Simulation(scene, quiet=True)
    lower, upper = np.array(scene.container.min_m), np.array(scene.container.max_m)
    spacing = scene.fluid.spacing_m
    H = fill_height_m(sim)
    h = scene.kernel_radius_m
    volume = sim.model.particle_volume_m3
    # Probes away from the walls by h, where the colour field is not cut by the container.
    xs = np.linspace(lower[0] + h, upper[0] - h, 3)
    zs = np.linspace(lower[2] + h, upper[2] - h, 3)
    y_range = (lower[1] + 0.5 * H, lower[1] + 1.5 * H)
    times, surfaces = [0.0], [colour_surface_height(sim.positions(), volume, h, xs, zs, y_range)]
    sampled = {frames * (k + 1) // samples for k in range(samples)}
    averaged = min(PRESSURE_FRAMES, frames)
    x, p = 0.0, 0.0
    for frame in range(1, frames + 1):
        sim.step()
        if frame > frames - averaged:
            x, p = x + sim.positions() / averaged, p + sim.pressures() / averaged
        if frame in sampled:
            times.append(sim.time_s)
            surfaces.append(colour_surface_height(sim.positions(), volume, h, xs, zs, y_range))
    depth = lower[1] + H - x[:, 1]
    rho_g = scene.fluid.rest_density_kg_m3 * float(np.linalg.norm(scene.gravity_m_s2))
    # Interior: a smoothing radius from the side walls and floor, and below the surface layer, where
    # the kernel sees a full neighbourhood or the wall term completes it.
    inner = (
        (x[:, 0] > lower[0] + h)
        & (x[:, 0] < upper[0] - h)
        & (x[:, 2] > lower[2] + h)
        & (x[:, 2] < upper[2] - h)
        & (depth > h)
        & (x[:, 1] > lower[1] + h)
    )
    slope = float(np.polyfit(depth[inner], p[inner], 1)[0])
    rms = float(np.sqrt(np.mean((p[inner] - rho_g * depth[inner]) ** 2)) / (rho_g * H))
    edges = np.arange(0.0, H + spacing, spacing)
    which = np.digitize(depth, edges) - 1
    bins = [k for k in range(len(edges) - 1) if np.any(which == k)]
    binned = np.array([p[which == k].mean() for k in bins])
    return HydrostaticRun(
        sim.particle_count, H, edges[bins] + spacing / 2, binned, slope, rho_g, rms, np.array(times), np.array(surfaces)
    )


def plot_hydrostatic(run: HydrostaticRun, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    left.plot(run.pressure_pa, run.depth_m, "o", ms=4, label="PBF, mean per layer")
    left.plot(run.expected_slope_pa_m * run.depth_m, run.depth_m, "k-", label="ρ0 g (H − y)")
    left.invert_yaxis()
    left.set_xlabel("pressure (Pa)")
    left.set_ylabel("depth H − y (m)")
    left.set_title(f"slope {run.slope_pa_m:,.0f} Pa/m against ρ0 g = {run.expected_slope_pa_m:,.0f}", fontsize=10)
    left.legend(fontsize=8)
    left.grid(True, alpha=0.3)
    right.plot(run.times_s, run.surface_m, "o-", ms=3, label="free surface (colour field ½)")
    right.axhline(run.fill_height_m, color="k", label=f"fill height H = {run.fill_height_m:.3f} m")
    right.axhspan(0.99 * run.fill_height_m, 1.01 * run.fill_height_m, color="grey", alpha=0.2, label="±1%")
    right.set_xlabel("time (s)")
    right.set_ylabel("surface height (m)")
    right.legend(fontsize=8)
    right.grid(True, alpha=0.3)
    fig.suptitle(f"Hydrostatic tank, {run.particles:,} particles", fontsize=11)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def linear_wave_number(period_s: float, depth_m: float, g: float) -> float:
    """k of the linear dispersion relation ω² = g k tanh(k d), by Newton's method from the deep-water k."""
    omega = 2 * math.pi / period_s
    k = omega**2 / g
    for _ in range(50):
        f = g * k * math.tanh(k * depth_m) - omega**2
        slope = g * math.tanh(k * depth_m) + g * k * depth_m / math.cosh(k * depth_m) ** 2
        k -= f / slope
    return k


def biesel_height_ratio(kd: float) -> float:
    """Wave height over piston stroke, H/S = 2 (cosh 2kd − 1) / (sinh 2kd + 2kd): linear theory of a
    piston wave maker far from the paddle (Biésel & Suquet 1951; Dean & Dalrymple, Sec. 6.3)."""
    return 2 * (math.cosh(2 * kd) - 1) / (math.sinh(2 * kd) + 2 * kd)


@dataclass
class WaveRun:
    particles: int
    depth_m: float
    kd: float
    expected_height_m: float
    """Biésel's H for the preset's stroke."""
    gauges_m: tuple
    """Distances of the wave gauges from the piston's rest position."""
    times_s: np.ndarray
    elevation_m: np.ndarray
    """(gauges, times): the free surface (colour field ½) at each gauge."""
    windows_s: list
    """Per gauge, the time after the first full wave arrived and before the far wall's reflection returned."""
    heights_m: list
    """Per gauge, crest to trough over its window."""


def wave_tank(end_s: float = 4.0, gauges_in_depths=(2.0, 3.0), overrides=()) -> WaveRun:
    """Run the ``wave_tank`` preset until ``end_s`` and measure the waves at gauges placed a given number
    of depths from the piston (two depths and more, where the evanescent modes have decayed)."""
    scene = load_scene("wave_tank", overrides)
    sim = Simulation(scene, quiet=True)
    g = float(np.linalg.norm(scene.gravity_m_s2))
    lower, upper = np.array(scene.container.min_m), np.array(scene.container.max_m)
    depth = fill_height_m(sim)  # the lattice's top layer, not the block's top: a whole number of spacings
    period, stroke = scene.wave_maker.period_s, scene.wave_maker.stroke_m
    k = linear_wave_number(period, depth, g)
    kd = k * depth
    group_speed = 0.5 * (2 * math.pi / period) / k * (1 + 2 * kd / math.sinh(2 * kd))
    gauges = tuple(lower[0] + n * depth for n in gauges_in_depths)
    h = scene.kernel_radius_m
    middle = [0.5 * (lower[2] + upper[2])]
    times, elevations = [], []
    while sim.time_s < end_s:
        sim.step()
        x = sim.positions()
        times.append(sim.time_s)
        elevations.append(
            [
                colour_surface_height(
                    x,
                    sim.model.particle_volume_m3,
                    h,
                    [gauge],
                    middle,
                    (lower[1] + 0.25 * depth, lower[1] + 2.0 * depth),
                )
                - lower[1]
                - depth
                for gauge in gauges
            ]
        )
    times, elevation = np.array(times), np.array(elevations).T
    windows, heights = [], []
    for gauge, eta in zip(gauges, elevation):
        start = (gauge - lower[0]) / group_speed + period
        stop = min((2 * (upper[0] - lower[0]) - (gauge - lower[0])) / group_speed, times[-1])
        inside = (times >= start) & (times <= stop)
        windows.append((start, stop))
        heights.append(float(eta[inside].max() - eta[inside].min()) if inside.any() else math.nan)
    return WaveRun(
        sim.particle_count, depth, kd, biesel_height_ratio(kd) * stroke, gauges, times, elevation, windows, heights
    )


def plot_wave_tank(run: WaveRun, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    for gauge, eta, (start, stop), height in zip(run.gauges_m, run.elevation_m, run.windows_s, run.heights_m):
        (line,) = ax.plot(
            run.times_s,
            eta * 1e3,
            label=f"x = {gauge:.2f} m ({gauge / run.depth_m:.0f} depths): H = {height * 1e3:.1f} mm",
        )
        ax.axvspan(start, stop, color=line.get_color(), alpha=0.08)
    for sign in (-1, 1):
        ax.axhline(sign * 0.5e3 * run.expected_height_m, color="k", ls="--", lw=1)
    ax.plot([], [], "k--", lw=1, label=f"± H/2 of linear theory (Biésel), H = {run.expected_height_m * 1e3:.1f} mm")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("surface elevation (mm)")
    ax.set_title(
        f"Piston wave maker, {run.particles:,} particles, kd = {run.kd:.2f} (shaded: the measured windows)", fontsize=10
    )
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def write_curves(path: Path, columns: dict) -> None:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        writer.writerows(zip(*columns.values()))


def parse_args(argv=None) -> argparse.Namespace:
    """The command line; no cases named means all of them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cases = ("martin_moyce", "hydrostatic", "wave_tank", "spheric2")
    # Checked by hand: Python 3.11's argparse rejects an empty list of a positional that has choices.
    parser.add_argument("cases", nargs="*", help=f"any of {', '.join(cases)} (default: all)")
    parser.add_argument(
        "--divisors",
        type=int,
        nargs="+",
        default=[9, 12, 24],
        help="martin_moyce: spacings a/n (n a multiple of 3: the tank is 2a/3 deep)",
    )
    parser.add_argument("--frames", type=int, default=600, help="hydrostatic: frames to run (60 per second)")
    parser.add_argument(
        "--spheric-across",
        type=int,
        default=None,
        help="spheric2: particles over the tank's width (default: the preset's spacing)",
    )
    parser.add_argument(
        "--spheric-seconds",
        type=float,
        default=7.39,
        help="spheric2: full-scale seconds to run (the measurements end at 7.39)",
    )
    parser.add_argument("--arch", default=None)
    parser.add_argument("--out", type=Path, default=Path("docs"))
    args = parser.parse_args(argv)
    unknown = sorted(set(args.cases) - set(cases))
    if unknown:
        parser.error(f"unknown case {', '.join(unknown)}: choose from {', '.join(cases)}")
    args.cases = args.cases or cases
    if args.spheric_across is not None and not 8 <= args.spheric_across <= 200:
        parser.error(f"--spheric-across: {args.spheric_across}; allowed: 8 to 200 particles over the width")
    if not 0.5 <= args.spheric_seconds <= 7.39:
        parser.error(f"--spheric-seconds: {args.spheric_seconds}; allowed: 0.5 to 7.39 s (the measured span)")
    if args.frames < 1:
        parser.error(f"--frames: {args.frames} frames; allowed: 1 or more")
    bad = [n for n in args.divisors if n % 3 or n < 3]
    if bad:
        parser.error(
            f"--divisors: {bad} are not positive multiples of 3 (the tank is 2a/3 deep, a whole number of spacings)"
        )
    return args


def main(argv=None):
    args = parse_args(argv)
    start_backend(args.arch)
    args.out.mkdir(parents=True, exist_ok=True)
    if "martin_moyce" in args.cases:
        runs = [martin_moyce(n) for n in args.divisors]
        print(f"{'spacing':>8} {'particles':>9} {'max |ΔZ|':>8} {'at T':>5} {'mean ΔZ':>8}")
        for run in runs:
            print(
                f"{'a/' + str(run.divisor):>8} {run.particles:>9,} {run.max_deviation:>8.3f} {run.at_T:>5.2f} "
                f"{run.mean_offset:>+8.3f}"
            )
            write_curves(args.out / f"martin_moyce_a{run.divisor}.csv", {"T": run.T, "Z": run.Z})
        plot_martin_moyce(runs, args.out / "martin_moyce.png")
    if "hydrostatic" in args.cases:
        run = hydrostatic(args.frames)
        late = run.surface_m[len(run.surface_m) // 2 :]
        print(
            f"hydrostatic, {run.particles:,} particles, {args.frames} frames: dp/d(depth) {run.slope_pa_m:,.0f} Pa/m "
            f"against {run.expected_slope_pa_m:,.0f} ({run.slope_pa_m / run.expected_slope_pa_m - 1:+.1%}), "
            f"rms pressure error {run.pressure_rms_error:.2%} of ρ0 g H; surface {run.surface_m[0]:.4f} m at "
            f"the start, {late.mean():.4f} m mean over the second half (range {late.min():.4f}-{late.max():.4f}), "
            f"H = {run.fill_height_m:.4f} m"
        )
        write_curves(args.out / "hydrostatic_pressure.csv", {"depth_m": run.depth_m, "pressure_pa": run.pressure_pa})
        write_curves(args.out / "hydrostatic_surface.csv", {"time_s": run.times_s, "surface_m": run.surface_m})
        plot_hydrostatic(run, args.out / "hydrostatic.png")
    if "wave_tank" in args.cases:
        run = wave_tank()
        for gauge, height in zip(run.gauges_m, run.heights_m):
            print(
                f"wave_tank, {run.particles:,} particles: at {gauge:.2f} m from the piston H = {height * 1e3:.1f} mm "
                f"against Biésel's {run.expected_height_m * 1e3:.1f} mm ({height / run.expected_height_m:.2f}), "
                f"kd = {run.kd:.2f}"
            )
        write_curves(
            args.out / "wave_tank.csv",
            {"time_s": run.times_s, **{f"eta_m_at_{g:.2f}_m": e for g, e in zip(run.gauges_m, run.elevation_m)}},
        )
        plot_wave_tank(run, args.out / "wave_tank.png")
    if "spheric2" in args.cases:
        data = spheric.measured()
        run = spheric.run(args.spheric_across, args.spheric_seconds, data=data)
        print(
            f"spheric2, {run.particles:,} particles (spacing {run.spacing_m * 1e3:.3f} mm at scale "
            f"1/{1 / run.scale:g}; water {run.volume_error:+.2%} of the experiment's volume), "
            f"{run.substeps_per_frame:.2f} substeps and {run.seconds_per_frame:.3f} s a frame:"
        )
        for name, simulated, expected in spheric.summary_rows(run):
            print(f"  {name:<40} {simulated:>24}" + (f"   measured {expected}" if expected else ""))
        write_curves(
            args.out / "spheric2.csv",
            {
                "time_s": run.times_s,
                **{f"{n}_m": v for n, v in run.heights_m.items()},
                **{f"{n}_Pa": v for n, v in run.pressures_pa.items()},
            },
        )
        spheric.plot(run, data, args.out / "spheric2_heights.png", args.out / "spheric2_pressures.png")
    print(f"wrote plots and curves under {args.out}/")


if __name__ == "__main__":
    run_command(main)
