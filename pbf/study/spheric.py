"""SPHERIC Test 2: the MARIN dam break against a box (Kleefsman et al. 2005), its probes and its measures.

The experiment (``docs/data/spheric_test2_marin.csv``, its header has the provenance): a tank 3.22 m
long, 1 m wide and 1 m high; water 1.228 m long and 0.55 m deep held at one end by a door lifted at
t = 0; a box 0.161 × 0.403 × 0.161 m in the water's path; four water-height probes H1-H4 and eight
pressure sensors P1-P8 on the box. The experiment's X runs along the tank from the wall behind the
box, Y across, Z up. A model at scale k (the ``dam_break_obstacle`` preset: k = 1/4, the water at
x = 0, y up, z across) is placed by

    x = k (3.22 − X),   y = k Z,   z = k Y,

and compares with the experiment in Froude similarity: lengths and pressures × 1/k, times × 1/sqrt(k).

Each measure is defined once here, on full-scale time series, so the simulation and the experiment
are measured alike (``tests/test_flow_measures.py`` checks them on synthetic series):

* a water height (:func:`column_top_m`) is the top of the water in a thin vertical column at the
  probe: the highest particle with at least ``SPRAY_NEIGHBOURS`` neighbours within one spacing of the
  probe's vertical line, plus half a spacing (each particle stands for a cube of water a spacing high);
* a pressure (:func:`sensor_pressure_pa`) is the kernel-weighted mean of ``Simulation.pressures()``
  (itself a mean over the frame's substeps) of the particles within h of the sensor;
* :func:`rms_over_range`: the rms of simulated minus measured height over the run, over the measured
  series' range;
* :func:`arrival_s`: the first time a height exceeds ARRIVAL_HEIGHT_M (the front reaches a probe);
* :func:`return_s`: after the lowest point of H4 before RETURN_SEARCH_END_S, the first time it has risen
  RETURN_RISE_M above it (the wave reflected from the wall behind the box is back in the reservoir);
* :func:`frame_mean_peak_pa`: the largest mean of P1 over one frame (the simulation reports frame
  means; the measurement, sampled every millisecond, is averaged over the same duration);
* :func:`impulse_pa_s`: ∫ P1 dt over IMPACT_WINDOW_S from the onset of the impact (P1 first above
  IMPACT_ONSET_PA).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pbf.scene import Scene, block_counts, load_scene
from pbf.solver.sph import kernel_np

DATA_CSV = Path(__file__).resolve().parents[2] / "docs" / "data" / "spheric_test2_marin.csv"
PRESET = "dam_break_obstacle"

TANK_LENGTH_M = 3.22
"""Full scale, along X."""
TANK_WIDTH_M = 1.0
WATER_M = (1.228, 0.55, 1.0)
"""The water column at full scale: length (X), depth (Z), width (Y)."""
BOX_M = ((0.6635, 0.8245), (0.295, 0.698), (0.0, 0.161))
"""The box: X, Y and Z extents at full scale."""
HEIGHT_PROBES_M = {"H1": (0.496, 0.5), "H2": (0.992, 0.5), "H3": (1.488, 0.5), "H4": (2.638, 0.5)}
"""(X, Y) of each water-height probe at full scale."""
PRESSURE_SENSORS_M = {
    "P1": (0.8245, 0.471, 0.021),
    "P2": (0.8245, 0.471, 0.061),
    "P3": (0.8245, 0.471, 0.101),
    "P4": (0.8245, 0.471, 0.141),
    "P5": (0.8035, 0.471, 0.161),
    "P6": (0.7635, 0.471, 0.161),
    "P7": (0.7235, 0.471, 0.161),
    "P8": (0.6835, 0.471, 0.161),
}
"""(X, Y, Z) of each pressure sensor at full scale: P1-P4 on the face towards the water, P5-P8 on top."""

SPRAY_NEIGHBOURS = 4
"""A particle with fewer neighbours within h than this is spray, not water a probe reads (a full one
has about 40; ``pbf.study.validate.SPRAY_NEIGHBOURS`` for the surge front)."""
ARRIVAL_HEIGHT_M = 0.02
"""The front has reached a probe when the height there first exceeds this (full scale): the measured
series read below 1 mm before."""
RETURN_SEARCH_END_S = 3.4
"""H4's lowest point is sought before this (full scale): after it, the second wave (3.6 s) comes."""
RETURN_RISE_M = 0.05
"""The reflected wave is back at H4 when H4 has risen this much (full scale) above its lowest point."""
IMPACT_ONSET_PA = 1000.0
"""The impact on P1 begins when P1 first exceeds this (full scale; the sensors' noise is ±70 Pa)."""
IMPACT_WINDOW_S = 0.2
"""The impulse is P1's integral over this long (full scale) from the onset: the peak and its fall
to about half (the measured P1 falls from 9.8 kPa at 0.42 s to 4.8 kPa at 0.60 s)."""


# ----------------------------------------------------------------------------- the experiment


@dataclass(frozen=True)
class Measured:
    """The experiment's series at full scale."""

    times_s: np.ndarray
    heights_m: dict
    """Probe name → (samples,) heights, m."""
    pressures_pa: dict
    """Sensor name → (samples,) gauge pressures, Pa."""


def measured(path: Path = DATA_CSV) -> Measured:
    """The measured series (columns t_s, P1_Pa … P8_Pa, H1_m … H4_m; '#' lines are the header's notes)."""
    lines = [line for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    names = lines[0].split(",")
    expected = ["t_s", *(f"{p}_Pa" for p in PRESSURE_SENSORS_M), *(f"{h}_m" for h in HEIGHT_PROBES_M)]
    if names != expected:
        raise ValueError(f"{path}: expected the columns {','.join(expected)}, found {lines[0]!r}")
    table = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    column = {name: table[:, k] for k, name in enumerate(names)}
    return Measured(
        column["t_s"],
        {h: column[f"{h}_m"] for h in HEIGHT_PROBES_M},
        {p: column[f"{p}_Pa"] for p in PRESSURE_SENSORS_M},
    )


# ----------------------------------------------------------------------------- the model


def scale_of(scene: Scene) -> float:
    """k, the model's lengths over the experiment's: the container's length over the tank's."""
    return (scene.container.max_m[0] - scene.container.min_m[0]) / TANK_LENGTH_M


def to_model(point_m, k: float) -> np.ndarray:
    """A full-scale point (X, Y, Z) in the model's coordinates (x, y, z) = k (3.22 − X, Z, Y)."""
    X, Y, Z = point_m
    return k * np.array([TANK_LENGTH_M - X, Z, Y])


def column_fill(k: float, across: int) -> tuple[float, tuple[float, float, float], float]:
    """The spacing and the water block that hold the experiment's column at scale k with ``across``
    particles over the tank's width: s = k · 1 m / across (the water fills the width wall to wall),
    and per the other two axes the whole number of spacings, rounded down or up, whose lattice holds
    the column's volume best (the kernel's particle volume V = m/ρ0 counted, not s³).

    Returns (s, the block's upper corner, N V over the column's volume − 1)."""
    from pbf.solver.sph import lattice_density_sum

    spacing = k * TANK_WIDTH_M / across
    length, depth, width = (k * w for w in WATER_M)
    volume = 1.0 / lattice_density_sum(spacing, load_scene(PRESET).solver.kernel_ratio * spacing)
    best = None
    for nx in (math.floor(length / spacing), math.ceil(length / spacing)):
        for ny in (math.floor(depth / spacing), math.ceil(depth / spacing)):
            error = nx * ny * across * volume / (length * depth * width) - 1.0
            shape = abs(nx * spacing / length - 1) + abs(ny * spacing / depth - 1)
            if best is None or (abs(error), shape) < (abs(best[2]), best[3]):
                best = (nx, ny, error, shape)
    nx, ny, error, _ = best
    return spacing, (nx * spacing, ny * spacing, width), error


def spheric_scene(across: int | None = None, overrides=()) -> Scene:
    """The ``dam_break_obstacle`` preset, or with ``across`` the same filled by :func:`column_fill` at
    that many particles over the width (the substeps scaled with the spacing), and ``overrides``."""
    base = load_scene(PRESET)
    if across is None:
        return load_scene(PRESET, overrides)
    spacing, upper, _ = column_fill(scale_of(base), across)
    substeps = max(base.time.substeps, math.ceil(base.time.substeps * base.fluid.spacing_m / spacing - 1e-9))
    block = f"fluid.blocks=[{{min_m = [0.0, 0.0, 0.0], max_m = [{upper[0]!r}, {upper[1]!r}, {upper[2]!r}]}}]"
    return load_scene(PRESET, [f"fluid.spacing_m={spacing!r}", block, f"time.substeps={substeps}", *overrides])


def water_volume_error(scene: Scene, particle_volume_m3: float) -> float:
    """The scene's water (N V) over the experiment's column at the scene's scale, − 1."""
    k = scale_of(scene)
    count = sum(math.prod(block_counts(b, scene.fluid.spacing_m)) for b in scene.fluid.blocks)
    return count * particle_volume_m3 / math.prod(k * w for w in WATER_M) - 1.0


# ----------------------------------------------------------------------------- probes


def column_top_m(
    positions: np.ndarray, neighbour_counts: np.ndarray, x_m: float, z_m: float, spacing_m: float, floor_m: float = 0.0
) -> float:
    """The top of the water in a vertical column one spacing in radius around (x, z), above the floor:
    the highest particle there with at least SPRAY_NEIGHBOURS neighbours, plus half a spacing; 0 where
    the column holds none."""
    inside = ((positions[:, 0] - x_m) ** 2 + (positions[:, 2] - z_m) ** 2 < spacing_m**2) & (
        neighbour_counts >= SPRAY_NEIGHBOURS
    )
    return float(positions[inside, 1].max() - floor_m + 0.5 * spacing_m) if inside.any() else 0.0


def sensor_pressure_pa(positions: np.ndarray, pressures_pa: np.ndarray, point_m, h_m: float) -> float:
    """The pressure at a sensor: Σ_j W_j p_j / Σ_j W_j over the particles within h of it (a Shepard
    mean, exact for a uniform pressure); 0 (gauge: dry) where none is."""
    weights = kernel_np(np.linalg.norm(positions - np.asarray(point_m), axis=1), h_m)
    total = weights.sum()
    return float(weights @ pressures_pa / total) if total > 0.0 else 0.0


# ----------------------------------------------------------------------------- measures (full scale)


def rms_over_range(times_s, simulated, measured_times_s, measured_values) -> float:
    """rms of (simulated − measured) at the measured samples within the simulated span (the simulation
    interpolated linearly), over the measured values' range there."""
    times_s, measured_times_s = np.asarray(times_s), np.asarray(measured_times_s)
    inside = (measured_times_s >= times_s[0]) & (measured_times_s <= times_s[-1])
    reference = np.asarray(measured_values)[inside]
    difference = np.interp(measured_times_s[inside], times_s, simulated) - reference
    return float(np.sqrt(np.mean(difference**2)) / (reference.max() - reference.min()))


def first_crossing_s(times_s, values, level: float, start: int = 0) -> float:
    """The first time at or after sample ``start`` that ``values`` rises past ``level``, interpolated
    linearly between the samples around it; NaN if it never does."""
    values = np.asarray(values)
    above = np.nonzero(values[start:] > level)[0]
    if len(above) == 0:
        return math.nan
    k = start + int(above[0])
    if k == 0 or values[k - 1] > level:
        return float(times_s[k])
    fraction = (level - values[k - 1]) / (values[k] - values[k - 1])
    return float(times_s[k - 1] + fraction * (times_s[k] - times_s[k - 1]))


def arrival_s(times_s, heights_m) -> float:
    """When the front reaches a probe: the height first exceeds ARRIVAL_HEIGHT_M."""
    return first_crossing_s(times_s, heights_m, ARRIVAL_HEIGHT_M)


def return_s(times_s, heights_m) -> float:
    """When the wave reflected behind the box is back at H4: after H4's lowest point before
    RETURN_SEARCH_END_S, the first time H4 is RETURN_RISE_M above that point."""
    times_s, heights_m = np.asarray(times_s), np.asarray(heights_m)
    before = np.nonzero(times_s <= RETURN_SEARCH_END_S)[0]
    lowest = int(before[np.argmin(heights_m[before])])
    return first_crossing_s(times_s, heights_m, heights_m[lowest] + RETURN_RISE_M, lowest)


def frame_means(times_s, values, frame_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A finely sampled series averaged over consecutive frames of ``frame_s`` (trapezoids, the series
    interpolated at the frames' ends): (each frame's end, its mean)."""
    times_s, values = np.asarray(times_s), np.asarray(values)
    ends = np.arange(times_s[0] + frame_s, times_s[-1] + 1e-12, frame_s)
    if len(ends) == 0:
        return ends, ends
    grid = np.union1d(times_s, np.concatenate([[times_s[0]], ends]))
    integral = np.concatenate(
        [
            [0.0],
            np.cumsum(
                np.diff(grid) * 0.5 * (np.interp(grid[1:], times_s, values) + np.interp(grid[:-1], times_s, values))
            ),
        ]
    )
    at_ends = np.interp(np.concatenate([[times_s[0]], ends]), grid, integral)
    return ends, np.diff(at_ends) / frame_s


def frame_mean_peak_pa(times_s, pressures_pa, frame_s: float | None = None) -> float:
    """The largest frame mean of a pressure series: its largest value when it already is frame means
    (``frame_s`` None), else the largest mean over any window of ``frame_s`` (the frames slid over
    the samples, so that where the frames fall does not move the peak)."""
    values = np.asarray(pressures_pa)
    if frame_s is None:
        return float(values.max())
    times_s = np.asarray(times_s)
    integral = np.concatenate([[0.0], np.cumsum(np.diff(times_s) * 0.5 * (values[1:] + values[:-1]))])
    starts = times_s[times_s <= times_s[-1] - frame_s]
    windows = np.interp(starts + frame_s, times_s, integral) - np.interp(starts, times_s, integral)
    return float(windows.max() / frame_s)


def impulse_pa_s(times_s, pressures_pa, frame_means_given: bool = False) -> float:
    """∫ p dt over IMPACT_WINDOW_S from the impact's onset (p first above IMPACT_ONSET_PA); NaN without
    an impact. With ``frame_means_given``, each value is the mean over the frame that ends at its
    time, so the integral takes each frame's share of the window whole (not a trapezoid through
    the means, which would shift the impact by half a frame)."""
    times_s, values = np.asarray(times_s, dtype=float), np.asarray(pressures_pa, dtype=float)
    if frame_means_given:
        # A frame mean p̄_k over (t_{k−1}, t_k]: a staircase. The onset is the end of the last frame
        # below the level, where the frames' staircase first rises past it.
        k = np.nonzero(values > IMPACT_ONSET_PA)[0]
        if len(k) == 0:
            return math.nan
        onset = times_s[k[0] - 1] if k[0] > 0 else times_s[0]
        starts = np.concatenate([[times_s[0] - (times_s[1] - times_s[0])], times_s[:-1]])
        overlap = np.clip(np.minimum(times_s, onset + IMPACT_WINDOW_S) - np.maximum(starts, onset), 0.0, None)
        return float(overlap @ values)
    onset = first_crossing_s(times_s, values, IMPACT_ONSET_PA)
    if math.isnan(onset):
        return math.nan
    grid = np.union1d(
        times_s[(times_s > onset) & (times_s < onset + IMPACT_WINDOW_S)], [onset, onset + IMPACT_WINDOW_S]
    )
    p = np.interp(grid, times_s, values)
    return float(np.sum(np.diff(grid) * 0.5 * (p[1:] + p[:-1])))


@dataclass
class Figures:
    """The table's measures of one run (full scale)."""

    rms_over_range: dict
    """Probe name → rms(simulated − measured) / measured range."""
    arrival_s: dict
    """'H3', 'H2' → (simulated, measured) arrival of the front."""
    return_s: tuple
    """(simulated, measured) return of the reflected wave at H4."""
    p1_peak_pa: tuple
    """(simulated, measured) P1 peak, frame mean."""
    p1_impulse_pa_s: tuple
    """(simulated, measured) ∫ P1 dt over the impact."""


def measure(times_s, heights_m: dict, pressures_pa: dict, data: Measured, frame_s: float) -> Figures:
    """The figures of a simulated run (full-scale series sampled once a frame of ``frame_s``, the
    pressures frame means) against the experiment."""
    rms = {name: rms_over_range(times_s, heights_m[name], data.times_s, data.heights_m[name]) for name in heights_m}
    arrivals = {
        name: (arrival_s(times_s, heights_m[name]), arrival_s(data.times_s, data.heights_m[name]))
        for name in ("H3", "H2")
    }
    back = (return_s(times_s, heights_m["H4"]), return_s(data.times_s, data.heights_m["H4"]))
    peak = (
        frame_mean_peak_pa(times_s, pressures_pa["P1"]),
        frame_mean_peak_pa(data.times_s, data.pressures_pa["P1"], frame_s),
    )
    impulse = (
        impulse_pa_s(times_s, pressures_pa["P1"], frame_means_given=True),
        impulse_pa_s(data.times_s, data.pressures_pa["P1"]),
    )
    return Figures(rms, arrivals, back, peak, impulse)


# ----------------------------------------------------------------------------- the run


@dataclass
class SphericRun:
    particles: int
    spacing_m: float
    scale: float
    volume_error: float
    """The water's volume over the experiment's column, − 1."""
    times_s: np.ndarray
    """Full scale, one per frame (the first at t = 0)."""
    heights_m: dict
    pressures_pa: dict
    figures: Figures
    seconds_per_frame: float
    substeps_per_frame: float
    overrides: tuple = field(default_factory=tuple)


def run(
    across: int | None = None, seconds: float = 7.39, overrides=(), data: Measured | None = None, progress=None
) -> SphericRun:
    """Run the experiment (``seconds`` at full scale) and measure it; ``progress`` (a callable) is told the
    full-scale time after every frame."""
    import time

    from pbf.solver import Simulation

    data = data or measured()
    scene = spheric_scene(across, overrides)
    sim = Simulation(scene, quiet=True)
    k = scale_of(scene)
    spacing, h = scene.fluid.spacing_m, scene.kernel_radius_m
    probes = {name: to_model((X, Y, 0.0), k) for name, (X, Y) in HEIGHT_PROBES_M.items()}
    sensors = {name: to_model(point, k) for name, point in PRESSURE_SENSORS_M.items()}
    to_time, to_length, to_pressure = 1.0 / math.sqrt(k), 1.0 / k, 1.0 / k
    times, heights, pressures = [], {n: [] for n in probes}, {n: [] for n in sensors}
    substeps = []

    def sample(with_pressure: bool):
        x, counts = sim.positions(), sim.neighbour_counts()
        times.append(sim.time_s * to_time)
        for name, probe in probes.items():
            heights[name].append(column_top_m(x, counts, probe[0], probe[2], spacing) * to_length)
        p = sim.pressures() if with_pressure else np.zeros(len(x), np.float32)
        for name, point in sensors.items():
            pressures[name].append(sensor_pressure_pa(x, p, point, h) * to_pressure)

    sample(False)
    started = time.perf_counter()
    while sim.time_s * to_time < seconds - 1e-9:
        sim.step()
        substeps.append(sim.frame_substeps)
        sample(True)
        if progress is not None:
            progress(sim.time_s * to_time)
    elapsed = time.perf_counter() - started
    times = np.array(times)
    heights = {n: np.array(v) for n, v in heights.items()}
    pressures = {n: np.array(v) for n, v in pressures.items()}
    figures = measure(times, heights, pressures, data, scene.time.frame_dt_s * to_time)
    return SphericRun(
        sim.particle_count,
        spacing,
        k,
        water_volume_error(scene, sim.model.particle_volume_m3),
        times,
        heights,
        pressures,
        figures,
        elapsed / max(len(substeps), 1),
        float(np.mean(substeps)) if substeps else 0.0,
        tuple(overrides),
    )


def summary_rows(run_: SphericRun) -> list[tuple[str, str, str]]:
    """(measure, simulated, measured) rows of the table (measured empty for the rms errors)."""
    f = run_.figures
    rows = [(f"{name} rms error / measured range", f"{value:.3f}", "") for name, value in f.rms_over_range.items()]
    for name, (sim_s, exp_s) in f.arrival_s.items():
        rows.append(
            (
                f"front at {name} (> {ARRIVAL_HEIGHT_M * 100:g} cm)",
                f"{sim_s:.3f} s ({sim_s - exp_s:+.3f})",
                f"{exp_s:.3f} s",
            )
        )
    sim_s, exp_s = f.return_s
    rows.append(
        (
            f"reflected wave back at H4 (+{RETURN_RISE_M * 100:g} cm)",
            f"{sim_s:.3f} s ({sim_s - exp_s:+.3f})",
            f"{exp_s:.3f} s",
        )
    )
    sim_p, exp_p = f.p1_peak_pa
    rows.append(("P1 peak, frame mean", f"{sim_p / 1e3:.2f} kPa ({sim_p / exp_p:.2f})", f"{exp_p / 1e3:.2f} kPa"))
    sim_i, exp_i = f.p1_impulse_pa_s
    rows.append(
        (
            f"P1 impulse over {IMPACT_WINDOW_S:g} s of impact",
            f"{sim_i:.0f} Pa s ({sim_i / exp_i:.2f})",
            f"{exp_i:.0f} Pa s",
        )
    )
    return rows


def plot(run_: SphericRun, data: Measured, heights_path: Path, pressures_path: Path) -> None:
    """H1-H4 and P1-P8 against the measured series, full scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    label = f"PBF, {run_.particles:,} particles (spacing {run_.spacing_m * 1e3:.2f} mm at 1/{1 / run_.scale:g} scale)"
    end = run_.times_s[-1]
    shown = data.times_s <= end
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), constrained_layout=True, sharex=True)
    for ax, name in zip(axes.flat, HEIGHT_PROBES_M):
        ax.plot(data.times_s[shown], data.heights_m[name][shown], "k-", lw=0.8, label="experiment (MARIN)")
        ax.plot(run_.times_s, run_.heights_m[name], "-", color="tab:blue", lw=1.2, label=label)
        ax.set_title(
            f"{name} (X = {HEIGHT_PROBES_M[name][0]} m): rms error "
            f"{run_.figures.rms_over_range[name]:.3f} of the range",
            fontsize=9,
        )
        ax.set_ylabel("water height (m)")
        ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s, full scale)")
    axes.flat[0].legend(fontsize=8)
    fig.suptitle("SPHERIC Test 2 (Kleefsman et al. 2005): water heights, Froude-scaled", fontsize=11)
    fig.savefig(heights_path, dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(4, 2, figsize=(11, 9), constrained_layout=True, sharex=True)
    for ax, name in zip(axes.T.flat, PRESSURE_SENSORS_M):
        ax.plot(data.times_s[shown], data.pressures_pa[name][shown] / 1e3, "k-", lw=0.5, label="experiment (MARIN)")
        ax.plot(run_.times_s, run_.pressures_pa[name] / 1e3, "-", color="tab:red", lw=1.2, label="PBF, frame mean")
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("kPa")
        ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s, full scale)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"SPHERIC Test 2: pressures on the box, {label}", fontsize=10)
    fig.savefig(pressures_path, dpi=110)
    plt.close(fig)
