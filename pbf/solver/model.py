"""The Model, what the solver derives from a scene once (a parameter object per stage), and :class:`Control`,
what may change between substeps (docs/ARCHITECTURE.md, "How a parameter travels")."""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
from dataclasses import dataclass, replace

import numpy as np

from pbf.scene import (
    FLOAT32_SAFE,
    MAX_ITERATIONS,
    Expert,
    Scene,
    SceneError,
    Solver,
    Time,
    Viscosity,
    Vorticity,
    block_counts,
)
from pbf.scene.schema import _finite_float, _is_number, _num, _show
from pbf.solver import acceleration, backend, sph

Vec3 = tuple[float, float, float]

NEIGHBOUR_REACH = 2
"""Grid cells per h: a particle checks the 5×5×5 cells h/2 wide around it, (5/2)³ h³ against 27 h³."""
MAX_CORRECTION = 0.1
"""Largest position correction of one iteration, in h (a fifth of a spacing at h = 2.2 s)."""
SCORR_N = 8
"""n of s_corr (Eq. 11): 8 confines it to pairs closer than about 0.3 h (docs/METHOD.md, "Artificial pressure")."""
SCORR_DQ = 0.2
"""Δq/h of s_corr (Eq. 11), the paper's."""
STABLE_GAIN = 1.8
"""Largest per-iteration gain ω·μ allowed for any error mode: below 2, so every mode decays."""
BYTES_PER_PARTICLE = 600
"""Memory one particle needs: its fields and neighbour slots, with room for the compact list of an overflow."""
BYTES_PER_CELL = 12
"""Grid memory per cell: count, start and a scan scratch, int32 each."""
PARTICLE_BUCKET_FLOOR = 2**14
"""The smallest particle allocation (:func:`allocation`): every preset below it shares one compile."""
CELL_BUCKET_FLOOR = 2**16


def allocation(count: int, floor: int) -> int:
    """The entries allocated for ``count``: the next power of two, at least ``floor``. A field's shape keys
    Taichi's offline cache, so a scene in the buckets of a run before starts from the cache."""
    return max(int(floor), 1 << max(int(count) - 1, 0).bit_length())


def reused_allocation(own: tuple[int, int], compiled, limit_bytes: int) -> tuple[int, int]:
    """The (particles, cells) buckets a scene allocates: ``own``, or the smallest ``compiled`` pair at most one
    size up on each that adds at most ``limit_bytes``."""
    particles, cells = own
    if own in compiled:
        return own

    def extra(pair):
        return (pair[0] - particles) * BYTES_PER_PARTICLE + (pair[1] - cells) * BYTES_PER_CELL

    def fits(pair):
        return particles <= pair[0] <= 2 * particles and cells <= pair[1] <= 2 * cells and extra(pair) <= limit_bytes

    return min(filter(fits, compiled), key=lambda pair: (extra(pair), pair), default=own)


@dataclass(frozen=True)
class GridParams:
    """The uniform grid of the neighbour search (``pbf.solver.grid``)."""

    particle_count: int
    lower_m: Vec3
    """Lower corner of the gridded box (the container), m."""
    upper_m: Vec3
    kernel_radius_m: float
    resolution: tuple[int, int, int]
    reach: int
    allocated_particles: int = 0
    """Per-particle arrays' length (:func:`allocation` of ``particle_count``; 0: that)."""
    cell_bucket: int = 0
    """Per-cell arrays' length, when not :func:`allocation` of the cell count (0: that)."""

    @classmethod
    def covering(
        cls, particle_count: int, lower_m, upper_m, kernel_radius_m: float, reach: int = NEIGHBOUR_REACH
    ) -> GridParams:
        """The finest grid over the box with cells at least h / reach wide (a 1e-4 margin for float32)."""
        extent = np.array(upper_m, np.float64) - np.array(lower_m, np.float64)
        cell = kernel_radius_m / reach * (1 + 1e-4)
        resolution = tuple(max(1, int(math.floor(e / cell))) for e in extent)
        lower, upper = tuple(map(float, lower_m)), tuple(map(float, upper_m))
        return cls(particle_count, lower, upper, float(kernel_radius_m), resolution, reach)

    @property
    def cell_count(self) -> int:
        return math.prod(self.resolution)

    @property
    def allocated_cells(self) -> int:
        return self.cell_bucket or allocation(self.cell_count, CELL_BUCKET_FLOOR)


@dataclass(frozen=True)
class BodyParams:
    """The rigid bodies (``pbf.solver.bodies``): per body, in the scene's order; all SI."""

    shapes: tuple[str, ...] = ()
    """"box" or "sphere"."""
    half_extents_m: tuple[Vec3, ...] = ()
    """A box's half extents along its own axes; a sphere's radius on every axis."""
    masses_kg: tuple[float, ...] = ()
    inertia_kg_m2: tuple[Vec3, ...] = ()
    """The principal moments of inertia about the centre of mass, along the body's own axes."""
    initial: tuple[tuple[float, ...], ...] = ()
    """Each body's 13 numbers at the start: position, quaternion (w, x, y, z), velocity, angular velocity."""
    rest_density_kg_m3: float = 1000.0
    particle_volume_m3: float = 0.0
    """V = m/ρ0 of a fluid particle: the reaction is −Σ_i V p_i ∇ψ_b(x_i) (``pbf.solver.bodies``)."""

    @property
    def count(self) -> int:
        return len(self.shapes)

    @classmethod
    def from_scene(cls, scene: Scene, particle_volume_m3: float) -> BodyParams:
        rows = []  # one per body: shape, half extents, mass, inertia, initial state
        for body in scene.bodies:
            half, mass = body.half_extents(), body.mass_kg()
            a2, b2, c2 = (x**2 for x in half)
            if body.shape == "sphere":
                inertia = np.full(3, 0.4 * mass * a2)
            else:  # a box of edges 2a, 2b, 2c: I_x = m (b² + c²) / 3
                inertia = mass / 3.0 * np.array([b2 + c2, a2 + c2, a2 + b2])
            state = (*body.position_m, *body.quaternion(), *body.velocity_m_s, *body.angular_velocity_rad_s)
            rows.append(
                (body.shape, tuple(map(float, half)), float(mass), tuple(map(float, inertia)), tuple(map(float, state)))
            )
        columns = tuple(zip(*rows)) or ((),) * 5
        return cls(*columns, scene.fluid.rest_density_kg_m3, particle_volume_m3)


@dataclass(frozen=True)
class BoundaryParams:
    """The container, its piston, obstacles and bodies (``pbf.solver.boundary``); flags: the solver keys so named."""

    lower_m: Vec3
    upper_m: Vec3
    particle_radius_m: float
    """Particle centres stay this far inside the walls."""
    spacing_m: float
    """The fluid lattice's pitch: the ghost lattice behind the walls mirrors it."""
    kernel_radius_m: float
    wall_density: bool
    wall_mirror: bool
    obstacles: tuple[tuple[Vec3, Vec3], ...] = ()
    """(lower, upper) corners of each static box obstacle, m."""
    piston_stroke_m: float = 0.0
    """``wave_maker.stroke_m``: 0, the lower-x wall stands still."""
    piston_period_s: float = 1.0
    bodies: BodyParams = BodyParams()
    """The rigid bodies (none: compiled out)."""

    def wall_constants(self) -> dict:
        """The container's numbers every boundary part reads as data (``pbf.solver.scene_constants``)."""
        return dict(
            radius=float(self.particle_radius_m),
            lower=tuple(float(v) for v in self.lower_m),
            upper=tuple(float(v) for v in self.upper_m),
            kernel_radius=float(self.kernel_radius_m),
            wall_density=int(self.wall_density),
        )


@dataclass(frozen=True)
class DensityParams:
    """The density constraint in dimensionless form (``pbf.solver.density``); flags: the solver keys so named."""

    particle_count: int
    kernel_radius_m: float
    particle_volume_m3: float
    relaxation: float
    """ε̂ of Eq. (10), dimensionless."""
    omega: float
    """ω, the Jacobi under-relaxation of λ: STABLE_GAIN over the largest gain of any error mode."""
    scorr_k: float
    inverse_w_dq: float
    """1 / W(Δq h, h), the s_corr reference of Eq. (11), 1/m⁻³."""
    max_correction: float
    surface_density: bool = False
    surface_calibration: tuple[float, float, float] = (0.0, 1.0, 0.0)
    """(g_below, g_top, ψ_top) of ``pbf.solver.sph.surface_ghost_calibration``."""
    wall_mirror: bool = False


@dataclass(frozen=True)
class VelocityParams:
    """The end of a substep (``pbf.solver.postprocess``): vorticity confinement and XSPH."""

    particle_count: int
    kernel_radius_m: float
    particle_volume_m3: float


@dataclass(frozen=True)
class Push:
    """A hand in the water (the mouse): velocities within ``radius_m`` of ``point_m`` blended toward
    ``velocity_m_s`` by w = (1 − (d/R)²)³."""

    point_m: Vec3
    velocity_m_s: Vec3
    radius_m: float

    def __post_init__(self):  # no NaN or overflow reaches a kernel
        for name in ("point_m", "velocity_m_s"):
            object.__setattr__(self, name, _checked_vector(f"control.push.{name}", getattr(self, name), FLOAT32_SAFE))
        bounds, meaning = (0.0, FLOAT32_SAFE), "radius of the hand, m"
        radius = _checked_number("control.push.radius_m", self.radius_m, float, bounds, meaning, above_lowest=True)
        object.__setattr__(self, "radius_m", radius)

    def capped(self, speed_limit_m_s: float) -> Push:
        """This push with its velocity capped at ``speed_limit_m_s``, for the water and the bodies alike."""
        velocity = np.asarray(self.velocity_m_s, np.float64)
        speed = float(np.linalg.norm(velocity))
        if speed > speed_limit_m_s:
            velocity *= speed_limit_m_s / speed
        return replace(self, velocity_m_s=tuple(velocity.tolist()))


@dataclass
class Control:
    """What may change between substeps (sliders, a sweep): kernel arguments, from the scene's values. The
    fields in MIRRORED mean what their scene keys do (docs/KEYS.md), within the same bounds: iterations,
    min_iterations, target_density_error, divergence_iterations (solver.*), step_back (solver.expert.*),
    substeps (time.*), xsph (viscosity.xsph), vorticity (vorticity.epsilon), gravity_m_s2."""

    iterations: int
    min_iterations: int
    substeps: int
    target_density_error: float
    step_back: bool
    divergence_iterations: int
    xsph: float
    vorticity: float
    gravity_m_s2: Vec3
    push: Push | None = None
    """The hand in the water while the user drags it, else None."""
    emitters_on: bool = True
    """Whether the emitters pour (while off, their layers are skipped)."""
    wave_maker_on: bool = True
    """Whether the piston moves (it resumes from where it stopped)."""

    def __setattr__(self, name: str, value) -> None:
        """Every assignment checked against its scene key's bounds (MIRRORED), or a TypeError/ValueError
        naming control.<field>; an unknown name is refused."""
        if name not in CONTROL_CHECKS:
            closest = [CONTROL_NAMES_SAID[name]] if name in CONTROL_NAMES_SAID else []
            closest = closest or difflib.get_close_matches(name, list(CONTROL_CHECKS), n=1)
            hint = f"did you mean control.{closest[0]}? " if closest else ""
            raise AttributeError(f"control.{name}: no such setting; {hint}settings: {', '.join(CONTROL_CHECKS)}")
        object.__setattr__(self, name, CONTROL_CHECKS[name](self, value))

    @classmethod
    def from_scene(cls, scene: Scene) -> Control:
        control = cls.__new__(cls)
        # The largest |g| the scene's frames can follow, set before any field.
        object.__setattr__(control, "_most_gravity_m_s2", scene.fastest_followed_m_s / scene.time.frame_dt_s)
        start = {field: functools.reduce(getattr, dotted.split("."), scene) for field, *_, dotted in MIRRORED}
        start["min_iterations"] = min(start["min_iterations"], start["iterations"])
        control.__init__(**start, gravity_m_s2=scene.gravity_m_s2)
        return control


@dataclass(frozen=True)
class Features:
    """What a substep's kernels compile in, one compile per value; build it with :meth:`of`."""

    measure: bool
    """An error target is set: the iterations' error sums and the stopping rule."""
    divergence: bool
    """The divergence pre-correction runs (its count is data, ``Control.divergence_iterations``)."""
    vorticity: bool

    @classmethod
    def of(cls, model: Model, control: Control) -> Features:
        """The features of ``model``'s scene under ``control`` (a restore's too: it runs no divergence
        iteration, the same compiled kernel)."""
        return _features(
            control.target_density_error > 0.0,
            control.divergence_iterations > 0,
            control.vorticity > 0.0,
        )


@functools.cache
def _features(*values) -> Features:
    """One Features object per value: Taichi tells template objects apart by identity."""
    return Features(*values)


def _given(value) -> str:
    return f"{_show(value)} ({type(value).__name__})"


def _checked_number(
    label: str, value, kind: type, bounds: tuple[float, float], meaning: str, above_lowest: bool = False
):
    """``value`` as an int or a finite float within ``bounds``, or a TypeError/ValueError naming ``label``."""
    lowest, highest = bounds
    interval = f"{'(' if above_lowest else '['}{_num(lowest)}, {_num(highest)}]"
    allowed = f"{'an integer' if kind is int else 'a finite number'} in {interval} ({meaning})"
    if not _is_number(value) or (kind is int and not isinstance(value, numbers.Integral)):
        raise TypeError(f"{label}: expected {allowed}, got {_given(value)}")
    converted = int(value) if kind is int else _finite_float(value)
    inside = converted is not None and lowest <= converted <= highest and not (above_lowest and converted == lowest)
    if not inside:
        raise ValueError(f"{label}: expected {allowed}, got {_show(value)}")
    return converted


def _checked_vector(label: str, value, largest: float, meaning: str = "m or m/s") -> Vec3:
    """Three finite numbers each within ±``largest``, as a tuple of floats, or TypeError/ValueError."""
    allowed = f"three finite numbers [x, y, z] within ±{_num(largest)} ({meaning})"
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 3 or not all(map(_is_number, value)):
        raise TypeError(f"{label}: expected {allowed}, got {_given(value)}")
    converted = tuple(_finite_float(c) for c in value)
    if not all(c is not None and abs(c) <= largest for c in converted):
        raise ValueError(f"{label}: expected {allowed}, got {_show(value)}")
    return converted


def _checked_bool(label: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{label}: expected True or False, got {_given(value)}")
    return bool(value)


def _setting(field_name: str, kind: type, table, name: str, dotted: str):
    """The check of Control's ``field_name``: the declared bounds of scene key ``dotted`` (``table``'s ``name``)."""
    label = f"control.{field_name}"
    if kind is bool:
        return lambda control, value: _checked_bool(label, value)
    bounds = {f.name: f for f in dataclasses.fields(table)}[name].metadata["check"].bounds
    meaning = f"the bounds of {dotted}"
    return lambda control, value: _checked_number(label, value, kind, bounds, meaning)


def _gravity(control, value) -> Vec3:
    """Finite, and no stronger than the scene's frames can follow (pbf.scene.timestep._check_time)."""
    most = getattr(control, "_most_gravity_m_s2", FLOAT32_SAFE)
    vector = _checked_vector("control.gravity_m_s2", value, FLOAT32_SAFE, "m/s²")
    largest = max(abs(c) for c in vector)
    length = 0.0 if largest == 0.0 else largest * math.sqrt(sum((c / largest) ** 2 for c in vector))
    if length > most:
        raise ValueError(
            f"control.gravity_m_s2: expected |g| ≤ {_num(most)} m/s², what the scene's frames can "
            f"follow (time.max_substeps × time.max_cfl (less under 4 solver.iterations) × fluid.spacing_m / "
            f"time.frame_dt_s²), got |g| = {_num(length)} m/s²"
        )
    return vector


def _push(control, value) -> Push | None:
    if value is not None and not isinstance(value, Push):
        raise TypeError(f"control.push: expected a pbf.solver.Push or None, got {_given(value)}")
    return value


MIRRORED = (
    ("iterations", int, Solver, "iterations", "solver.iterations"),
    ("min_iterations", int, Solver, "min_iterations", "solver.min_iterations"),
    ("substeps", int, Time, "substeps", "time.substeps"),
    ("target_density_error", float, Solver, "target_density_error", "solver.target_density_error"),
    ("step_back", bool, Expert, "step_back", "solver.expert.step_back"),
    ("divergence_iterations", int, Solver, "divergence_iterations", "solver.divergence_iterations"),
    ("xsph", float, Viscosity, "xsph", "viscosity.xsph"),
    ("vorticity", float, Vorticity, "epsilon", "vorticity.epsilon"),
)
"""(Control field, type, schema table, its field, scene key): the fields that start from a scene key, in its bounds."""
CONTROL_CHECKS = {
    **{field: _setting(field, *rest) for field, *rest in MIRRORED},
    "gravity_m_s2": _gravity,
    "push": _push,
    "emitters_on": lambda control, value: _checked_bool("control.emitters_on", value),
    "wave_maker_on": lambda control, value: _checked_bool("control.wave_maker_on", value),
}

CONTROL_NAMES_SAID = {
    "viscosity": "xsph",
    "xsph_c": "xsph",
    "epsilon": "vorticity",
    "vorticity_epsilon": "vorticity",
    "gravity": "gravity_m_s2",
    "g": "gravity_m_s2",
    "solver_iterations": "iterations",
}
"""What a user may call a control field by its meaning (the window's slider, the paper's symbol), for the hint
of an unknown name: ``control.viscosity`` is the XSPH viscosity's c, ``control.xsph``."""


def iteration_weights(expert, lowest: float) -> tuple[float, ...]:
    """The weights of ``solver.expert.acceleration``; ``lowest``: the smallest factor 1 − ω μ of an iteration."""
    if expert.acceleration == "stable":
        return acceleration.stable_weights(lowest, MAX_ITERATIONS)
    rho = expert.chebyshev_rho if expert.acceleration == "chebyshev" else 0.0
    return acceleration.chebyshev_weights(rho, MAX_ITERATIONS)


def available_memory_bytes() -> int:
    """Memory the fields can still take (``pbf.solver.backend.device_memory_bytes``)."""
    return backend.device_memory_bytes()


@dataclass(frozen=True)
class Model:
    """A scene's derived quantities and stage parameters; build with :meth:`from_scene`."""

    scene: Scene
    capacity: int
    """The scene's particles: the blocks' and all that the emitters will add."""
    allocated: int
    """The length of the per-particle arrays: ``capacity`` rounded up to its bucket (:func:`allocation`)."""
    particle_mass_kg: float
    """m = ρ0 / Σ_j W(x_j): the lattice at exactly ρ0 (``pbf.solver.sph.lattice_density_sum``)."""
    particle_volume_m3: float
    """V = m/ρ0, the volume each particle stands for."""
    grid: GridParams
    boundary: BoundaryParams
    density: DensityParams
    velocity: VelocityParams
    iteration_weights: tuple[float, ...]
    """w_1 … w_100 of the iterations' acceleration (``pbf.solver.acceleration``), the most a substep may run."""

    @classmethod
    def from_scene(cls, scene: Scene, compiled=frozenset(), reuse_limit_bytes: int = 0) -> Model:
        """Derive everything once; SceneError if it would not fit in memory. ``compiled``, ``reuse_limit_bytes``:
        the buckets the arrays may take instead (:func:`reused_allocation`)."""
        spacing, h = scene.fluid.spacing_m, scene.kernel_radius_m
        n = scene.particle_capacity
        lower, upper = scene.container.min_m, scene.container.max_m
        covering = GridParams.covering(n, lower, upper, h)
        own = (allocation(n, PARTICLE_BUCKET_FLOOR), covering.allocated_cells)
        allocated, cells = reused_allocation(own, compiled, reuse_limit_bytes)
        try:
            _check_memory(scene, n, covering.cell_count, allocated, cells)
        except SceneError:  # the larger buckets do not fit: the scene's own, checked again
            allocated, cells = own
            _check_memory(scene, n, covering.cell_count, allocated, cells)
        grid = dataclasses.replace(covering, allocated_particles=allocated, cell_bucket=cells)
        mass = scene.fluid.rest_density_kg_m3 / sph.lattice_density_sum(spacing, h)
        volume = mass / scene.fluid.rest_density_kg_m3
        s = scene.solver
        gain = sph.jacobi_gain(h / spacing, s.expert.relaxation)
        omega = min(1.0, STABLE_GAIN / gain)
        density = DensityParams(
            particle_count=allocated,
            kernel_radius_m=h,
            particle_volume_m3=volume,
            relaxation=s.expert.relaxation,
            omega=omega,
            scorr_k=s.scorr_k,
            inverse_w_dq=1.0 / float(sph.kernel_np(SCORR_DQ * h, h)),
            max_correction=MAX_CORRECTION,
            surface_density=s.surface_density,
            surface_calibration=sph.surface_ghost_calibration(spacing, h) if s.surface_density else (0.0, 1.0, 0.0),
            wall_mirror=s.wall_mirror,
        )
        boundary = BoundaryParams(
            lower,
            upper,
            scene.particle_radius_m,
            spacing,
            h,
            s.expert.wall_density,
            s.wall_mirror,
            tuple((o.min_m, o.max_m) for o in scene.obstacles),
            scene.wave_maker.stroke_m,
            scene.wave_maker.period_s,
            BodyParams.from_scene(scene, volume),
        )
        weights = iteration_weights(s.expert, 1.0 - omega * gain)
        return cls(
            scene, n, allocated, mass, volume, grid, boundary, density, VelocityParams(allocated, h, volume), weights
        )

    def initial_particles(self) -> tuple[np.ndarray, np.ndarray]:
        """Every block's lattice, (n, 3) float32 positions (m) at min + (i + ½) s and velocities (m/s)."""
        spacing = self.scene.fluid.spacing_m
        positions, velocities = [np.zeros((0, 3))], [np.zeros((0, 3))]
        for block in self.scene.fluid.blocks:
            counts = block_counts(block, spacing)
            axes = [lo + (np.arange(n) + 0.5) * spacing for lo, n in zip(block.min_m, counts)]
            lattice = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            if self.scene.bodies:  # the water a body stands in is removed (a half spacing from its surface)
                inside = np.zeros(len(lattice), bool)
                for body in self.scene.bodies:
                    inside |= body.contains(lattice, 0.499 * spacing)
                lattice = lattice[~inside]
            positions.append(lattice)
            velocities.append(np.broadcast_to(np.array(block.velocity_m_s), lattice.shape))
        return np.concatenate(positions).astype(np.float32), np.concatenate(velocities).astype(np.float32)


def _culprit(scene: Scene) -> tuple[str, str]:
    """The key that makes a scene's particle count what it is (budget, largest emitter or spacing), and a remedy."""
    blocks, emitted = scene.particle_count, scene.emitted_count
    if scene.fluid.max_particles > blocks + emitted:
        return "fluid.max_particles", (
            f"lower fluid.max_particles to {blocks + emitted:,} or 0 (exactly the blocks' and emitters' particles)"
        )
    if emitted > blocks:
        spacing = scene.fluid.spacing_m
        added = [e.layers(spacing) * e.sites_per_layer(spacing) for e in scene.emitters]
        k = added.index(max(added))
        return f"emitters[{k}].end_s", f"emitters[{k}] adds {added[k]:,}: shorten its stream or narrow its nozzle"
    return "fluid.spacing_m", "use a larger spacing or smaller blocks"


def _check_memory(scene: Scene, particles: int, cells: int, allocated: int, allocated_cells: int) -> None:
    """Refuse a scene whose arrays would not fit in memory or outgrow int32 indices, naming the key to change."""
    need = allocated * BYTES_PER_PARTICLE + allocated_cells * BYTES_PER_CELL
    have = available_memory_bytes()
    if need > 0.8 * have:
        if allocated * BYTES_PER_PARTICLE >= allocated_cells * BYTES_PER_CELL:
            culprit, remedy = _culprit(scene)
        else:
            culprit, remedy = "container.max_m", "use a smaller container or a larger spacing"
        raise SceneError(
            f"{scene.source}: key '{culprit}': {particles:,} particles and {cells:,} grid cells (arrays for "
            f"{allocated:,} and {allocated_cells:,}) need about "
            f"{need / 2**30:.1f} GiB, more than 80% of the {have / 2**30:.1f} GiB {backend.memory_place()}; {remedy}"
        )
    _check_indices(scene, particles, cells)


INT32_MAX = 2**31 - 1
"""The largest index of a Taichi field or ndarray the kernels address with int32."""


def _check_indices(scene: Scene, particles: int, cells: int, slots: int = 64) -> None:
    """The neighbour slots (``slots`` a particle: pbf.solver.grid.SLOTS) and cell starts must fit int32 indices."""
    if particles * slots > INT32_MAX:
        culprit, remedy = _culprit(scene)
        raise SceneError(
            f"{scene.source}: key '{culprit}': {particles:,} particles × {slots} neighbour slots "
            f"= {particles * slots:,} entries, more than the {INT32_MAX:,} an int32 index reaches; allowed: at most "
            f"{INT32_MAX // slots:,} particles; {remedy}"
        )
    if cells + 1 > INT32_MAX:
        raise SceneError(
            f"{scene.source}: key 'container.max_m': the neighbour grid (cells of h/{NEIGHBOUR_REACH}) over the "
            f"container has {cells:,} cells, more than the {INT32_MAX:,} an int32 index reaches; use a smaller "
            f"container or a larger spacing"
        )
