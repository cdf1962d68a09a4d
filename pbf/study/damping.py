"""Numerical damping: a standing wave's decay in a closed tank, and the wave tank's height along its length.

    python -m pbf.study.damping [sloshing] [wave_tank] [--set KEY=VALUE ...] [--periods 6] [--amplitude 0.01]
    python -m pbf.study.damping --ab [SOURCE ...] [--ab-cases sloshing wave_tank spheric2]   # the A/B table

``sloshing`` settles the ``sloshing`` preset (a closed tank half a wavelength long, the ``wave_tank``
preset's depth and resolution), gives it the velocity field of its first linear sloshing mode and
follows the mode's amplitude in the particles' velocities (:func:`mode_amplitude`): its decay per
period (:func:`decay_per_period`)
is the method's numerical damping, to be set against the viscous decay of real water in the same tank
(:func:`viscous_decay_rate`: 2νk² in the bulk, and with the laminar boundary layers of no-slip walls).

``wave_tank`` runs the ``wave_tank`` preset with gauges from two to eight depths from the piston and
reports each gauge's height over Biésel's, and the spatial decay rate fitted to them.

The linear mode (Lamb, *Hydrodynamics*, §257; Dean & Dalrymple, Sec. 4.5), tank length L, depth d, the
floor at y = 0: η = A cos kx sin ωt with k = π/L, ω² = g k tanh kd, and at t = 0 (η = 0, the velocity
at its largest) u = −A ω cosh(ky)/sinh(kd) sin kx, v = A ω sinh(ky)/sinh(kd) cos kx.
"""

from __future__ import annotations

import argparse
import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from pbf.scene import load_scene
from pbf.study.common import fill_height_m, run_command

KINEMATIC_VISCOSITY_M2_S = 1.0e-6
"""ν of water at 20 °C (1.004e-6 m²/s)."""
PRESET = "sloshing"


# ----------------------------------------------------------------------------- theory


def sloshing_mode(length_m: float, depth_m: float, g: float, mode: int = 1) -> tuple[float, float]:
    """(k, ω) of a closed tank's n-th sloshing mode: k = nπ/L, ω² = g k tanh kd."""
    k = mode * math.pi / length_m
    return k, math.sqrt(g * k * math.tanh(k * depth_m))


def mode_velocities(
    positions: np.ndarray, amplitude_m: float, k: float, omega: float, depth_m: float, lower_m
) -> np.ndarray:
    """The first mode's velocity at t = 0 (module docstring) at each position, (n, 3) float32 m/s."""
    x = positions[:, 0] - lower_m[0]
    y = np.clip(positions[:, 1] - lower_m[1], 0.0, None)
    scale = amplitude_m * omega / math.sinh(k * depth_m)
    velocities = np.zeros_like(positions, dtype=np.float64)
    velocities[:, 0] = -scale * np.cosh(k * y) * np.sin(k * x)
    velocities[:, 1] = scale * np.sinh(k * y) * np.cos(k * x)
    return velocities.astype(np.float32)


def viscous_decay_rate(
    k: float,
    omega: float,
    depth_m: float,
    length_m: float,
    width_m: float,
    nu_m2_s: float = KINEMATIC_VISCOSITY_M2_S,
    walls: bool = False,
) -> float:
    """γ (1/s), the amplitude's decay rate A ∝ e^{−γt} of a closed tank's first sloshing mode in water
    of viscosity ν.

    In the bulk γ = 2νk² (Lamb, §348). With no-slip walls the laminar (Stokes) boundary layers
    dissipate far more: over a wall where the potential flow slides at amplitude U_t the mean
    dissipation per area is ½ ρ U_t² sqrt(νω/2) (Stokes' second problem); summed over the floor, the
    two end walls and the two side walls with the mode's velocities, over twice the wave's energy
    E = ρ g A² L b / 4, it adds D / 2E."""
    gamma = 2.0 * nu_m2_s * k * k
    if not walls:
        return gamma
    b, d, L = width_m, depth_m, length_m
    u0_sq = (omega / math.sinh(k * d)) ** 2  # per unit A²: (A ω / sinh kd)²
    floor = u0_sq * (L / 2) * b  # u = U0 sin kx at y = 0
    ends = 2 * b * u0_sq * (math.sinh(2 * k * d) / (4 * k) - d / 2)  # v = U0 sinh ky at x = 0, L
    sides = 2 * u0_sq * (L / 2) * math.sinh(2 * k * d) / (2 * k)  # u² + v² over z = 0, b
    dissipation = 0.5 * (floor + ends + sides) * math.sqrt(nu_m2_s * omega / 2)  # per ρ A²
    energy = 9.81 * L * b / 4  # per ρ A²
    return gamma + dissipation / (2 * energy)


# ----------------------------------------------------------------------------- measures


def mode_amplitude(positions: np.ndarray, velocities: np.ndarray, amplitude_field) -> float:
    """The first mode's amplitude A (m) in the particles' velocities: the least-squares fit of v = A u(x),
    u the mode's velocity field at unit amplitude (``amplitude_field(positions)``, (n, 3)). It swings
    between ±A e^{−γt} as cos ωt (the surface's amplitude swings as sin ωt), at every particle, so
    particle noise averages out and a drift of the surface's level or tilt, which moves nothing, does
    not enter it."""
    u = np.asarray(amplitude_field(positions), dtype=np.float64)
    return float(np.sum(np.asarray(velocities, dtype=np.float64) * u) / np.sum(u * u))


def extrema(times_s, values, band: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """The largest |values| of each half period of an oscillation, each refined by the parabola through
    the sample and its two neighbours: (times, |values| there). A half period ends where the series
    crosses to the other side of ±``band`` × its largest |value| (a hysteresis: noise about a zero
    crossing starts no half period of its own); the first and the unfinished last are left out."""
    times_s, values = np.asarray(times_s, dtype=float), np.asarray(values, dtype=float)
    found_t, found_v = [], []
    level = band * np.abs(values).max()
    side, changes = 0, []
    for k, value in enumerate(values):
        now = 1 if value > level else -1 if value < -level else side
        if now != side and side != 0:
            # The half period began at the zero crossing just before the band was left.
            start = k
            while start > 0 and np.sign(values[start - 1]) == now:
                start -= 1
            changes.append(start)
        side = now
    changes = np.array(changes, dtype=int)
    for start, stop in itertools.pairwise(changes):
        k = start + int(np.argmax(np.abs(values[start:stop])))
        if k == 0 or k == len(values) - 1:
            continue
        a, b, c = np.abs(values[k - 1 : k + 2])
        curvature = a - 2 * b + c
        shift = 0.5 * (a - c) / curvature if curvature < 0 else 0.0
        found_t.append(times_s[k] + shift * (times_s[k + 1] - times_s[k - 1]) / 2)
        found_v.append(b - 0.25 * (a - c) * shift)
    return np.array(found_t), np.array(found_v)


def decay_per_period(times_s, values) -> tuple[float, float, float]:
    """Of a decaying oscillation: (1 − e^{−γT}, the fraction of its amplitude lost per period; γ, the
    rate fitted to the logarithm of its extrema by least squares; T, twice the mean spacing of the
    extrema). NaN where fewer than three extrema are found."""
    t, v = extrema(times_s, values)
    if len(t) < 3:
        return math.nan, math.nan, math.nan
    slope = np.polyfit(t, np.log(v), 1)[0]
    period = 2.0 * float(np.mean(np.diff(t)))
    return float(1.0 - math.exp(slope * period)), float(-slope), period


def spatial_decay_per_m(gauges_m, heights_m) -> float:
    """α (1/m) of heights H(x) ∝ e^{−αx} fitted to the gauges by least squares on ln H."""
    return float(-np.polyfit(np.asarray(gauges_m), np.log(np.asarray(heights_m)), 1)[0])


# ----------------------------------------------------------------------------- the sloshing run


@dataclass
class SloshingRun:
    particles: int
    depth_m: float
    length_m: float
    k: float
    omega_theory: float
    amplitude_start_m: float
    times_s: np.ndarray
    amplitude_m: np.ndarray
    """The first mode's amplitude in the velocities (:func:`mode_amplitude`) each frame."""
    decay_per_period: float
    decay_rate_1_s: float
    period_s: float
    viscous_bulk_per_period: float
    """1 − e^{−γT} of real water, bulk viscosity alone (free-slip walls, as the simulation's)."""
    viscous_walls_per_period: float
    """The same with no-slip walls' boundary layers."""
    seconds: float
    """Wall time of the run."""
    noise_rms_m_s: float
    """Median over the frames of the rms velocity that is not the mode's, v − A u(x): the particles'
    jitter. A variant that makes the tank boil can shake the mode loose from the packing and seem to
    damp it less; this shows it."""


def sloshing(overrides=(), periods: float = 6.0, amplitude_m: float = 0.01) -> SloshingRun:
    """Settle the ``sloshing`` preset, start its first mode at amplitude A and follow it ``periods`` periods."""
    import time

    from pbf.solver import Simulation

    scene = load_scene(PRESET, overrides)
    sim = Simulation(scene, quiet=True)
    lower, upper = np.array(scene.container.min_m), np.array(scene.container.max_m)
    length, width = upper[0] - lower[0], upper[2] - lower[2]
    depth = fill_height_m(sim)
    g = float(np.linalg.norm(scene.gravity_m_s2))
    k, omega = sloshing_mode(length, depth, g)
    settled = sim.snapshot()
    sim.restore(
        replace(
            settled,
            velocities_m_s=mode_velocities(settled.positions_m, amplitude_m, k, omega, depth, lower),
            fields={name: values for name, values in settled.fields.items() if name != "multiplier"},
        )
    )

    def unit_mode(positions):
        return mode_velocities(positions, 1.0, k, omega, depth, lower)

    noise = []

    def amplitude() -> float:
        x, v = sim.positions(), sim.velocities()
        value = mode_amplitude(x, v, unit_mode)
        noise.append(float(np.sqrt(np.mean(np.sum((v - value * unit_mode(x)) ** 2, axis=1)))))
        return value

    times, amplitudes = [0.0], [amplitude()]
    began = time.perf_counter()
    end = periods * 2 * math.pi / omega
    while sim.time_s < end:
        sim.step()
        times.append(sim.time_s)
        amplitudes.append(amplitude())
    seconds = time.perf_counter() - began
    times, amplitudes = np.array(times), np.array(amplitudes)
    decay, rate, period = decay_per_period(times, amplitudes)
    theory_period = 2 * math.pi / omega
    bulk = viscous_decay_rate(k, omega, depth, length, width)
    walls = viscous_decay_rate(k, omega, depth, length, width, walls=True)
    return SloshingRun(
        sim.particle_count,
        depth,
        length,
        k,
        omega,
        amplitude_m,
        times,
        amplitudes,
        decay,
        rate,
        period,
        1 - math.exp(-bulk * theory_period),
        1 - math.exp(-walls * theory_period),
        seconds,
        float(np.median(noise[1:])),
    )


def plot_sloshing(runs: dict, path) -> None:
    """Each run's amplitude over time, with its fitted envelope."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2), constrained_layout=True)
    for label, run in runs.items():
        (line,) = ax.plot(
            run.times_s, run.amplitude_m * 1e3, lw=1.2, label=f"{label}: {run.decay_per_period:.1%} per period"
        )
        envelope = run.amplitude_start_m * np.exp(-run.decay_rate_1_s * run.times_s) * 1e3
        ax.plot(run.times_s, envelope, "--", color=line.get_color(), lw=0.8)
        ax.plot(run.times_s, -envelope, "--", color=line.get_color(), lw=0.8)
    first = next(iter(runs.values()))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("first mode's amplitude (mm)")
    ax.set_title(
        f"Standing wave in a closed tank ({first.particles:,} particles, kd = {first.k * first.depth_m:.2f}); "
        f"real water: {first.viscous_bulk_per_period:.3%} per period (bulk), "
        f"{first.viscous_walls_per_period:.2%} (no-slip walls)",
        fontsize=9,
    )
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=130)
    plt.close(fig)


# ----------------------------------------------------------------------------- the wave tank along its length


@dataclass
class AlongRun:
    gauges_m: tuple
    ratios: list
    """Each gauge's height over Biésel's."""
    decay_per_m: float
    """α of H ∝ e^{−αx} fitted over the gauges."""
    wavelength_m: float
    seconds: float
    run: object
    """The ``pbf.study.validate.WaveRun``."""


def wave_tank_along(overrides=(), gauges_in_depths=(2.0, 3.0, 4.0, 6.0, 8.0), end_s: float = 6.0) -> AlongRun:
    """The ``wave_tank`` preset with gauges along it (``pbf.study.validate.wave_tank``)."""
    import time

    from pbf.study import validate

    began = time.perf_counter()
    run = validate.wave_tank(end_s, gauges_in_depths, overrides)
    seconds = time.perf_counter() - began
    ratios = [h / run.expected_height_m for h in run.heights_m]
    valid = [(g, h) for g, h in zip(run.gauges_m, run.heights_m) if np.isfinite(h)]
    alpha = spatial_decay_per_m(*zip(*valid)) if len(valid) >= 2 else math.nan
    return AlongRun(run.gauges_m, ratios, alpha, 2 * math.pi * run.depth_m / run.kd, seconds, run)


# ----------------------------------------------------------------------------- the A/B table of damping sources


def _scaled_substeps(factor: int):
    return lambda scene: [f"time.substeps={scene.time.substeps * factor}"]


SOURCES = {
    # name: (what it switches, overrides of a scene); every one valid in the three presets measured
    "preset": ("the preset as shipped", lambda scene: []),
    "XSPH off": ("viscosity.xsph = 0", lambda scene: ["viscosity.xsph=0"]),
    "XSPH 0.05": ("viscosity.xsph = 0.05 (5x)", lambda scene: ["viscosity.xsph=0.05"]),
    "s_corr off": ("solver.scorr_k = 0", lambda scene: ["solver.scorr_k=0"]),
    "all 10 iterations": (
        "no error target: every substep runs solver.iterations",
        lambda scene: ["solver.target_density_error=0"],
    ),
    "30 iterations": (
        "30 iterations every substep, no target",
        lambda scene: ["solver.target_density_error=0", "solver.iterations=30", "solver.min_iterations=30"],
    ),
    "plain Jacobi": ("solver.expert.acceleration = none", lambda scene: ["solver.expert.acceleration=none"]),
    "divergence off": ("solver.divergence_iterations = 0", lambda scene: ["solver.divergence_iterations=0"]),
    "divergence 4": ("solver.divergence_iterations = 4", lambda scene: ["solver.divergence_iterations=4"]),
    "dt / 2": ("twice the substeps", _scaled_substeps(2)),
    "dt / 4": ("four times the substeps", _scaled_substeps(4)),
    "walls mirrored": (
        "solver.wall_mirror = true: the ghost behind the container's walls mirrors the fluid",
        lambda scene: ["solver.wall_mirror=true"],
    ),
    "h = 2.0 s": ("solver.kernel_ratio = 2.0", lambda scene: ["solver.kernel_ratio=2.0"]),
    "surface ghost": ("solver.surface_density = true", lambda scene: ["solver.surface_density=true"]),
    "vorticity 0.05": ("vorticity.epsilon = 0.05", lambda scene: ["vorticity.epsilon=0.05"]),
}
"""The damping sources the A/B table switches, one at a time."""


@dataclass
class SourceRow:
    name: str
    sloshing_decay: float = math.nan
    sloshing_period_s: float = math.nan
    sloshing_noise_m_s: float = math.nan
    wave_ratios: tuple = ()
    spheric: object = None
    """``pbf.study.spheric.Figures`` over the first ``AB_SPHERIC_SECONDS``."""
    seconds: float = 0.0


AB_SPHERIC_SECONDS = 3.4
"""Full-scale seconds of SPHERIC Test 2 the A/B table runs: past the reflected wave's return at H4 (2.74 s)."""
AB_SLOSHING_PERIODS = 3.0


def source_table(names, cases=("sloshing", "wave_tank", "spheric2"), extra=(), progress=print) -> list[SourceRow]:
    """Each named source switched alone (``SOURCES``), with ``extra`` overrides on every run, measured on
    ``cases``: the standing wave's decay, the wave tank's height at two and three depths, and SPHERIC
    Test 2 over its first AB_SPHERIC_SECONDS."""
    import time

    from pbf.study import spheric, validate

    rows = []
    data = spheric.measured() if "spheric2" in cases else None
    for name in names:
        _, overrides_of = SOURCES[name]
        row, began = SourceRow(name), time.perf_counter()
        if "sloshing" in cases:
            run = sloshing([*overrides_of(load_scene(PRESET)), *extra], AB_SLOSHING_PERIODS)
            row.sloshing_decay, row.sloshing_period_s = run.decay_per_period, run.period_s
            row.sloshing_noise_m_s = run.noise_rms_m_s
        if "wave_tank" in cases:
            run = validate.wave_tank(overrides=[*overrides_of(load_scene("wave_tank")), *extra])
            row.wave_ratios = tuple(h / run.expected_height_m for h in run.heights_m)
        if "spheric2" in cases:
            run = spheric.run(None, AB_SPHERIC_SECONDS, [*overrides_of(load_scene(spheric.PRESET)), *extra], data)
            row.spheric = run.figures
        row.seconds = time.perf_counter() - began
        rows.append(row)
        progress(format_source_row(row))
    return rows


SOURCE_HEADER = (
    f"{'source':<18} {'slosh decay':>11} {'period':>7} {'jitter':>9} {'wave H/H_B':>11} {'H2 rms':>7} {'H4 rms':>7} "
    f"{'H4 return':>9} {'P1 peak':>7} {'P1 impulse':>10} {'run s':>6}"
)


def format_source_row(row: SourceRow) -> str:
    wave = "/".join(f"{r:.2f}" for r in row.wave_ratios) if row.wave_ratios else "-"
    if row.spheric is not None:
        f = row.spheric
        sim_r, exp_r = f.return_s
        spheric_cells = (
            f"{f.rms_over_range['H2']:>7.3f} {f.rms_over_range['H4']:>7.3f} {sim_r - exp_r:>+8.2f}s "
            f"{f.p1_peak_pa[0] / f.p1_peak_pa[1]:>7.2f} {f.p1_impulse_pa_s[0] / f.p1_impulse_pa_s[1]:>10.2f}"
        )
    else:
        spheric_cells = f"{'-':>7} {'-':>7} {'-':>9} {'-':>7} {'-':>10}"
    return (
        f"{row.name:<18} {row.sloshing_decay:>10.1%} {row.sloshing_period_s:>6.3f}s "
        f"{row.sloshing_noise_m_s * 1e3:>5.1f}mm/s {wave:>11} {spheric_cells} "
        f"{row.seconds:>6.0f}"
    )


# ----------------------------------------------------------------------------- the command line


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cases = ("sloshing", "wave_tank")
    parser.add_argument("cases", nargs="*", help=f"any of {', '.join(cases)} (default: sloshing)")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a scene override for every run (repeatable)",
    )
    parser.add_argument("--periods", type=float, default=6.0, help="sloshing: periods to follow (default 6)")
    parser.add_argument("--amplitude", type=float, default=0.01, help="sloshing: the mode's amplitude, m (0.01)")
    parser.add_argument("--plot", default=None, help="sloshing: write the amplitude's plot here (PNG)")
    parser.add_argument(
        "--ab",
        nargs="*",
        default=None,
        metavar="SOURCE",
        help=f"the A/B table of damping sources (default all): {', '.join(SOURCES)}",
    )
    parser.add_argument(
        "--ab-cases",
        nargs="+",
        default=["sloshing", "wave_tank", "spheric2"],
        help="the runs of each A/B row (default: sloshing wave_tank spheric2)",
    )
    parser.add_argument("--arch", default=None)
    args = parser.parse_args(argv)
    if args.ab is not None:
        bad = [n for n in args.ab if n not in SOURCES] + [
            c for c in args.ab_cases if c not in ("sloshing", "wave_tank", "spheric2")
        ]
        if bad:
            parser.error(
                f"--ab: unknown {', '.join(map(repr, bad))}; sources: {', '.join(SOURCES)}; "
                f"cases: sloshing, wave_tank, spheric2"
            )
        args.ab = args.ab or list(SOURCES)
    unknown = sorted(set(args.cases) - set(cases))
    if unknown:
        parser.error(f"unknown case {', '.join(unknown)}: choose from {', '.join(cases)}")
    args.cases = args.cases or ["sloshing"]
    if not args.periods >= 2:
        parser.error(f"--periods: {args.periods}; allowed: 2 or more (the decay is fitted to the extrema)")
    if not 0 < args.amplitude < 0.05:
        parser.error(f"--amplitude: {args.amplitude} m; allowed: between 0 and 0.05 m (a linear wave)")
    return args


def main(argv=None):
    from pathlib import Path

    from pbf.scene import SceneError
    from pbf.solver import start_backend

    args = parse_args(argv)
    try:
        for case in args.cases:
            load_scene(PRESET if case == "sloshing" else case, args.overrides)
    except SceneError as error:
        raise SystemExit(f"error: {error}") from None
    start_backend(args.arch)
    if args.ab is not None:
        print(SOURCE_HEADER, flush=True)
        source_table(args.ab, args.ab_cases, args.overrides, progress=lambda line: print(line, flush=True))
        return
    if "sloshing" in args.cases:
        run = sloshing(args.overrides, args.periods, args.amplitude)
        print(
            f"sloshing, {run.particles:,} particles, kd = {run.k * run.depth_m:.2f}: decay {run.decay_per_period:.2%} "
            f"per period (γ = {run.decay_rate_1_s:.3f}/s), period {run.period_s:.3f} s against linear theory's "
            f"{2 * math.pi / run.omega_theory:.3f} s; real water {run.viscous_bulk_per_period:.4%} per period in "
            f"the bulk, {run.viscous_walls_per_period:.2%} with no-slip walls; the particles' jitter "
            f"{run.noise_rms_m_s * 1e3:.1f} mm/s rms ({run.seconds:.0f} s)"
        )
        if args.plot:
            plot_sloshing({"PBF": run}, Path(args.plot))
    if "wave_tank" in args.cases:
        along = wave_tank_along(args.overrides)
        cells = ", ".join(f"{g:.2f} m: {r:.2f}" for g, r in zip(along.gauges_m, along.ratios))
        print(
            f"wave_tank: H / H_Biésel at {cells}; decay {along.decay_per_m:.3f}/m "
            f"({1 - math.exp(-along.decay_per_m * along.wavelength_m):.1%} per wavelength) ({along.seconds:.0f} s)"
        )


if __name__ == "__main__":
    run_command(main)
