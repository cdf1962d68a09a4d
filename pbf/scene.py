"""The scene schema: one validated place for everything a preset sets.

A scene is a TOML file (see ``scenes/``) or a dict of the same shape. Loading checks every key:
unknown keys, wrong types, non-finite, negative or zero values, fluid blocks outside the container or
overlapping each other all raise :class:`SceneError`, whose message names the file, the key and what
is allowed. This module imports nothing of the solver, the application or the studies: the values
the solver derives from a scene (particle mass, grid, the memory check) are ``pbf.solver.model``'s.
"""
from __future__ import annotations

import dataclasses
import math
import os
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"

Vec3 = tuple[float, float, float]


class SceneError(ValueError):
    """A scene that cannot be run; the message names the source, the key and what is allowed."""


def _positive(value):
    return None if value > 0 else "a value > 0"


def _non_negative(value):
    return None if value >= 0 else "a value ≥ 0"


def _unit_interval(value):
    return None if 0 <= value <= 1 else "a value in [0, 1]"


def _at_least(lowest):
    return lambda value: None if value >= lowest else f"a value ≥ {lowest}"


def _between(lowest, highest):
    return lambda value: None if lowest <= value <= highest else f"a value in [{lowest}, {highest}]"


def _vec_positive(value):
    return None if all(c > 0 for c in value) else "three values > 0"


def _vec_non_negative(value):
    return None if all(c >= 0 for c in value) else "three values ≥ 0"


def _rgb(value):
    return None if all(0 <= c <= 1 for c in value) else "three values in [0, 1] (red, green, blue)"


def _even_pixels(value):
    return None if 16 <= value <= 8192 and value % 2 == 0 else "an even number of pixels in [16, 8192] (video needs even sizes)"


def _one_of(*choices):
    return lambda value: None if value in choices else "one of " + ", ".join(repr(c) for c in choices)


def _colour_map(value):
    import matplotlib

    return None if value in matplotlib.colormaps else "a Matplotlib colour map name such as 'viridis' or 'Blues'"


def key(default=dataclasses.MISSING, check=None, doc=""):
    """A scene key: its default (none means required), a check returning what is allowed, and a doc line."""
    return field(default=default, metadata={"check": check, "doc": doc})


@dataclass(frozen=True)
class Container:
    """Axis-aligned box the fluid lives in."""

    min_m: Vec3 = key((0.0, 0.0, 0.0), doc="lower corner of the box, m")
    max_m: Vec3 = key((1.0, 1.0, 1.0), doc="upper corner of the box, m")


@dataclass(frozen=True)
class Block:
    """A box of fluid filled with a simple-cubic lattice at the fluid spacing."""

    min_m: Vec3 = key(doc="lower corner, m")
    max_m: Vec3 = key(doc="upper corner, m")
    velocity_m_s: Vec3 = key((0.0, 0.0, 0.0), doc="initial velocity, m/s")


@dataclass(frozen=True)
class Obstacle:
    """A static box inside the container that the water flows around (collision and wall density,
    like the container's walls)."""

    min_m: Vec3 = key(doc="lower corner, m")
    max_m: Vec3 = key(doc="upper corner, m")


@dataclass(frozen=True)
class Fluid:
    spacing_m: float = key(0.025, _positive, "particle spacing s (the lattice pitch), m")
    rest_density_kg_m3: float = key(1000.0, _positive, "rest density ρ0, kg/m³")
    blocks: tuple[Block, ...] = key((), doc="fluid blocks ([[fluid.blocks]] tables)")
    max_particles: int = key(0, _non_negative, "particle budget, allocated at the start: at least the blocks' "
                             "particles and all that the emitters add; 0: exactly that many")


@dataclass(frozen=True)
class Emitter:
    """A nozzle that shoots water in: a disc of lattice sites at the spacing, perpendicular to the
    direction, emitting a new layer each time the stream has moved one spacing, from start_s to end_s."""

    position_m: Vec3 = key(doc="centre of the nozzle, m")
    direction: Vec3 = key(doc="direction of the stream (any length; normalised)")
    radius_m: float = key(doc="radius of the nozzle, m (at least half a spacing)")
    end_s: float = key(doc="when the stream stops, s")
    speed_m_s: float = key(1.0, _positive, "speed of the stream, m/s")
    start_s: float = key(0.0, _non_negative, "when the stream starts, s")

    def unit_direction(self) -> Vec3:
        length = math.sqrt(sum(c * c for c in self.direction))
        return tuple(c / length for c in self.direction)

    def sites_per_layer(self, spacing: float) -> int:
        """Lattice sites (i s, j s) of the nozzle's plane within its radius."""
        reach = int(math.floor(self.radius_m / spacing + 1e-9))
        limit = (self.radius_m / spacing) ** 2 + 1e-9
        return sum(1 for i in range(-reach, reach + 1) for j in range(-reach, reach + 1) if i * i + j * j <= limit)

    def layers(self, spacing: float) -> int:
        """Layers emitted over the whole interval: one at start_s, one per spacing the stream moves."""
        return int(math.floor((self.end_s - self.start_s) * self.speed_m_s / spacing + 1e-9)) + 1


@dataclass(frozen=True)
class Time:
    frame_dt_s: float = key(1.0 / 60.0, _positive, "time per rendered frame, s")
    substeps: int = key(2, _at_least(1), "PBF steps per frame (Δt = frame_dt_s / substeps)")
    max_cfl: float = key(1.2, _positive, "most particle spacings the fastest particle may travel in one "
                         "substep; a frame takes more substeps when it would go further")
    max_substeps: int = key(64, _at_least(1), "cap on the substeps one frame may take (a warning when reached)")


@dataclass(frozen=True)
class Solver:
    iterations: int = key(4, _at_least(1), "Jacobi iterations of the density constraint per substep (the most, "
                          "with target_density_error)")
    target_density_error: float = key(0.0, _non_negative, "stop iterating once the mean of max(ρ/ρ0 − 1, 0) is "
                                      "below this; 0 always runs all iterations")
    kernel_ratio: float = key(2.2, _between(1.5, 4.0), "smoothing radius over spacing, h/s")
    relaxation: float = key(0.1, _positive, "ε of Eq. (10) in the dimensionless form (ε h²/…); see pbf/density.py")
    clamp_pressure: bool = key(True, doc="use C_i = max(ρ_i/ρ0 − 1, 0): only compressed particles push")
    scorr_k: float = key(0.03, _non_negative, "s_corr strength k (Eq. 11), dimensionless form; 0 disables")
    scorr_n: int = key(8, _at_least(1), "s_corr exponent n (Eq. 11); 8 confines it to pairs closer than ~0.3 h")
    scorr_dq: float = key(0.2, _between(0.0, 0.9), "s_corr reference distance Δq/h (Eq. 11)")
    wall_density: bool = key(True, doc="add the density of the ghost fluid behind walls (no stacking)")


@dataclass(frozen=True)
class Viscosity:
    xsph: float = key(0.01, _unit_interval, "XSPH coefficient c (Eq. 15), dimensionless; 0 disables")


@dataclass(frozen=True)
class WaveMaker:
    """A piston wave maker: the container's lower-x wall swings along x between min_m and
    min_m + stroke_m, x = min + S/2 (1 − cos 2πt/T), starting at rest."""

    stroke_m: float = key(0.0, _non_negative, "piston stroke S, m; 0: no wave maker")
    period_s: float = key(1.0, _positive, "wave period T, s")


@dataclass(frozen=True)
class Vorticity:
    epsilon: float = key(0.0, _non_negative, "vorticity confinement ε (Eqs. 13-14), dimensionless; 0 disables")


@dataclass(frozen=True)
class Camera:
    """Where the window opens and what headless frames show; omitted points are derived from the box."""

    position_m: Vec3 | None = key(None, doc="eye position, m (default: in front of the box, above it)")
    look_at_m: Vec3 | None = key(None, doc="point at the image centre, m (default: the box centre)")
    fov_deg: float = key(45.0, _between(5.0, 150.0), "vertical field of view, degrees")


@dataclass(frozen=True)
class Render:
    colour_by: str = key("speed", _one_of("speed", "density"), "particle colour: speed or density")
    colour_map: str = key("coolwarm", _colour_map, "Matplotlib colour map")
    speed_max_m_s: float = key(3.0, _positive, "speed at the top of the colour map, m/s")
    density_error_max: float = key(0.05, _positive, "colour map spans ρ/ρ0 from 1 − this to 1 + this")
    background_rgb: Vec3 = key((0.96, 0.96, 0.94), _rgb, "background colour")
    container_rgb: Vec3 = key((0.25, 0.25, 0.3), _rgb, "colour of the container's edges")
    width_px: int = key(1280, _even_pixels, "image width, pixels")
    height_px: int = key(720, _even_pixels, "image height, pixels")
    style: str = key("particles", _one_of("particles", "surface"), "frames and the window (at first; key v "
                     "switches) show particles (spheres in the colour map) or the water's surface (see [surface])")


@dataclass(frozen=True)
class Surface:
    """The free surface reconstructed from the particles (``--export mesh``, ``--style surface``).

    Lengths are in particle spacings, so one table serves every resolution. The mesh is the iso
    surface of splashsurf's colour field Σ_j (m_j/ρ_j) W(x − x_j) (about 1 inside, 0 outside),
    smoothed by the weighted Laplacian of Löschner et al. 2023.
    """

    smoothing_length_spacings: float = key(1.2, _between(0.5, 4.0), "SPH smoothing length of the colour "
                                           "field (kernel support twice this), spacings")
    cube_size_spacings: float = key(0.5, _between(0.1, 2.0), "marching-cubes cell edge, spacings")
    iso_level: float = key(0.5, _between(0.05, 0.95), "colour-field value of the surface (1 in the bulk, 0.5 "
                           "where a flat body of the particles' volume ends)")
    smoothing_iterations: int = key(5, _between(0, 1000), "Laplacian smoothing passes over the mesh (each "
                                    "shrinks the water by about 0.3%)")
    mesh_format: str = key("ply", _one_of("ply", "obj"), "file format of --export mesh: binary PLY or text OBJ")
    deterministic: bool = key(True, doc="one thread, no subdomains: the same mesh on every run "
                              "(splashsurf's parallel subdomains vary from run to run); false is faster")
    absorption_per_m: Vec3 = key((5.0, 1.8, 1.0), _vec_non_negative, "Beer–Lambert absorption of red, "
                                 "green and blue light in render.style = surface, 1/m")
    water_rgb: Vec3 = key((0.03, 0.25, 0.4), _rgb, "colour of deep water (the light it absorbs is replaced by this)")


@dataclass(frozen=True)
class Scene:
    source: str = field(default="<dict>", compare=False, metadata={"internal": True})
    """Where the scene came from (a file path or "<dict>"): error messages name it. Not a TOML key."""
    name: str = key("scene", doc="short name")
    description: str = key("", doc="one line shown by --list")
    gravity_m_s2: Vec3 = key((0.0, -9.81, 0.0), doc="gravitational acceleration, m/s² (y is up)")
    container: Container = key(Container())
    fluid: Fluid = key(Fluid())
    obstacles: tuple[Obstacle, ...] = key((), doc="static boxes in the container ([[obstacles]] tables)")
    emitters: tuple[Emitter, ...] = key((), doc="nozzles that add water while the scene runs ([[emitters]] tables)")
    time: Time = key(Time())
    solver: Solver = key(Solver())
    viscosity: Viscosity = key(Viscosity())
    vorticity: Vorticity = key(Vorticity())
    wave_maker: WaveMaker = key(WaveMaker())
    camera: Camera = key(Camera())
    render: Render = key(Render())
    surface: Surface = key(Surface())

    @property
    def dt_s(self) -> float:
        return self.time.frame_dt_s / self.time.substeps

    @property
    def kernel_radius_m(self) -> float:
        return self.solver.kernel_ratio * self.fluid.spacing_m

    @property
    def particle_radius_m(self) -> float:
        return 0.5 * self.fluid.spacing_m

    @property
    def particle_count(self) -> int:
        """Lattice sites of all fluid blocks (see :func:`block_counts`): the particles at the start."""
        return sum(math.prod(block_counts(b, self.fluid.spacing_m)) for b in self.fluid.blocks)

    @property
    def emitted_count(self) -> int:
        """Particles the emitters add over the whole run."""
        spacing = self.fluid.spacing_m
        return sum(e.layers(spacing) * e.sites_per_layer(spacing) for e in self.emitters)

    @property
    def particle_capacity(self) -> int:
        """Particles allocated at the start: fluid.max_particles, or the blocks' and emitters' total."""
        return self.fluid.max_particles or self.particle_count + self.emitted_count


# ----------------------------------------------------------------------------- loading and validation


def _type_name(annotation) -> str:
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(
        annotation, "three numbers [x, y, z]"
    )


def _convert(value, annotation, where):
    """Convert one TOML value to the annotated type, or raise SceneError naming what was expected."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):  # X | None: TOML has no None
        annotation = next(a for a in typing.get_args(annotation) if a is not type(None))
    if annotation is bool:
        if isinstance(value, bool):
            return value
    elif annotation is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif annotation is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if not math.isfinite(value):
                raise SceneError(f"{where}: expected a finite number, got {value}")
            return float(value)
    elif annotation is str:
        if isinstance(value, str):
            return value
    elif annotation == Vec3:
        if (
            isinstance(value, (list, tuple))
            and len(value) == 3
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in value)
        ):
            if not all(math.isfinite(c) for c in value):
                raise SceneError(f"{where}: expected three finite numbers, got {list(value)}")
            return tuple(float(c) for c in value)
    else:
        raise TypeError(annotation)
    raise SceneError(f"{where}: expected {_type_name(annotation)}, got {value!r}")


def _build(cls, table, source, prefix=""):
    """Build dataclass ``cls`` from a TOML table, refusing unknown keys and checking each value."""
    where_table = f"{source}: [{prefix.rstrip('.')}]" if prefix else f"{source}"
    if not isinstance(table, dict):
        raise SceneError(f"{where_table}: expected a table, got {table!r}")
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise SceneError(
            f"{source}: unknown key '{prefix}{unknown[0]}'; allowed keys here: {', '.join(sorted(known))}"
        )
    values = {}
    for name, f in known.items():
        where = f"{source}: key '{prefix}{name}'"
        if name not in table:
            if f.default is dataclasses.MISSING:
                raise SceneError(f"{where} is required ({f.metadata['doc']})")
            continue
        annotation = hints[name]
        raw = table[name]
        if dataclasses.is_dataclass(annotation):
            values[name] = _build(annotation, raw, source, f"{prefix}{name}.")
            continue
        if typing.get_origin(annotation) is tuple and dataclasses.is_dataclass(typing.get_args(annotation)[0]):
            if not isinstance(raw, list):
                raise SceneError(f"{where}: expected a list of tables ([[{prefix}{name}]]), got {raw!r}")
            item = typing.get_args(annotation)[0]
            values[name] = tuple(_build(item, t, source, f"{prefix}{name}[{i}].") for i, t in enumerate(raw))
            continue
        value = _convert(raw, annotation, where)
        check = f.metadata["check"]
        if check is not None:
            allowed = check(value)
            if allowed is not None:
                raise SceneError(f"{where}: expected {allowed} ({f.metadata['doc']}), got {raw!r}")
        values[name] = value
    return cls(**values)


def block_counts(block: Block, spacing: float) -> tuple[int, int, int]:
    """Lattice sites per axis: as many spacings as fit in the block (a rounding tolerance of 1e-6 s)."""
    return tuple(int(math.floor((hi - lo) / spacing + 1e-6)) for lo, hi in zip(block.min_m, block.max_m))


def _check_geometry(scene: Scene, source: str) -> None:
    lo, hi = np.array(scene.container.min_m), np.array(scene.container.max_m)
    if np.any(hi <= lo):
        raise SceneError(
            f"{source}: key 'container.max_m' must exceed 'container.min_m' on every axis, "
            f"got min {list(lo)} and max {list(hi)}"
        )
    spacing = scene.fluid.spacing_m
    if np.any(hi - lo < 2 * scene.kernel_radius_m):
        raise SceneError(
            f"{source}: key 'container.max_m': the box must be at least two smoothing radii "
            f"(2 h = {2 * scene.kernel_radius_m:g} m) wide on every axis for fluid.spacing_m = {spacing:g}"
        )
    if not scene.fluid.blocks and not scene.emitters:
        raise SceneError(f"{source}: key 'fluid.blocks': at least one [[fluid.blocks]] table (or an [[emitters]] "
                         f"table) is required")
    tolerance = 1e-9 * float(np.max(np.abs(np.concatenate([lo, hi]))) + 1.0)
    boxes = []
    for i, block in enumerate(scene.fluid.blocks):
        b_lo, b_hi = np.array(block.min_m), np.array(block.max_m)
        where = f"{source}: key 'fluid.blocks[{i}]"
        if np.any(b_hi <= b_lo):
            raise SceneError(f"{where}.max_m' must exceed min_m on every axis, got {list(b_lo)} and {list(b_hi)}")
        if np.any(b_lo < lo - tolerance) or np.any(b_hi > hi + tolerance):
            raise SceneError(
                f"{where}': block {list(b_lo)}–{list(b_hi)} m lies outside the container "
                f"{list(lo)}–{list(hi)} m; allowed: min_m ≥ container.min_m and max_m ≤ container.max_m"
            )
        if min(block_counts(block, spacing)) < 1:
            raise SceneError(
                f"{where}': block {list(b_lo)}–{list(b_hi)} m is thinner than one spacing "
                f"({spacing:g} m) on some axis, so it holds no particle"
            )
        for j, (o_lo, o_hi) in enumerate(boxes):
            overlap = np.minimum(b_hi, o_hi) - np.maximum(b_lo, o_lo)
            if np.all(overlap > tolerance):
                raise SceneError(f"{where}' overlaps fluid.blocks[{j}]; blocks must not share volume")
        boxes.append((b_lo, b_hi))


MIN_OBSTACLE_SPACINGS = 2
"""An obstacle's least thickness, in spacings. Grown by the particle radius, its half-thickness is
then at least 1.5 spacings, and a particle moves at most time.max_cfl spacings per substep (1.2 by
default, at most OBSTACLE_MAX_CFL with obstacles), so it cannot cross an obstacle's middle in one
substep and be pushed out on the far side."""
OBSTACLE_MAX_CFL = 1.5


def _check_obstacles(scene: Scene, source: str) -> None:
    """Obstacles: inside the container, thick enough, sharing no volume with fluid or each other."""
    def box(lo, hi):
        return "[" + ", ".join(f"{c:g}" for c in lo) + "]–[" + ", ".join(f"{c:g}" for c in hi) + "] m"

    c_lo, c_hi = scene.container.min_m, scene.container.max_m
    thinnest = MIN_OBSTACLE_SPACINGS * scene.fluid.spacing_m
    tolerance = 1e-9 * (max(abs(c) for c in c_lo + c_hi) + 1.0)

    def overlap(a_lo, a_hi, b_lo, b_hi):
        return all(min(ah, bh) - max(al, bl) > tolerance for al, ah, bl, bh in zip(a_lo, a_hi, b_lo, b_hi))

    if scene.obstacles and scene.time.max_cfl > OBSTACLE_MAX_CFL:
        raise SceneError(f"{source}: key 'time.max_cfl' = {scene.time.max_cfl:g} lets particles cross an obstacle in "
                         f"one substep; with [[obstacles]] it must be ≤ {OBSTACLE_MAX_CFL:g}")
    for i, obstacle in enumerate(scene.obstacles):
        lo, hi = obstacle.min_m, obstacle.max_m
        where = f"{source}: key 'obstacles[{i}]"
        if any(h - l < thinnest for l, h in zip(lo, hi)):
            raise SceneError(f"{where}.max_m': obstacle {box(lo, hi)} must be at least {MIN_OBSTACLE_SPACINGS} "
                             f"spacings ({thinnest:g} m) thick on every axis, or particles could cross it")
        if any(l < cl - tolerance or h > ch + tolerance for l, h, cl, ch in zip(lo, hi, c_lo, c_hi)):
            raise SceneError(f"{where}': obstacle {box(lo, hi)} lies outside the container {box(c_lo, c_hi)}; "
                             f"allowed: min_m ≥ container.min_m and max_m ≤ container.max_m")
        for j, block in enumerate(scene.fluid.blocks):
            if overlap(lo, hi, block.min_m, block.max_m):
                raise SceneError(f"{where}' overlaps fluid.blocks[{j}] ({box(block.min_m, block.max_m)}); "
                                 f"move the block or the obstacle so that they share no volume")
        for j, other in enumerate(scene.obstacles[:i]):
            if overlap(lo, hi, other.min_m, other.max_m):
                raise SceneError(f"{where}' overlaps obstacles[{j}]; obstacles must not share volume")


def _check_wave_maker(scene: Scene, source: str) -> None:
    """The piston must leave room behind it for the water and in front of it for the obstacles."""
    stroke = scene.wave_maker.stroke_m
    if stroke == 0.0:
        return
    length = scene.container.max_m[0] - scene.container.min_m[0]
    if stroke > 0.25 * length:
        raise SceneError(f"{source}: key 'wave_maker.stroke_m' = {stroke:g} m is more than a quarter of the "
                         f"container's length along x ({length:g} m); allowed: ≤ {0.25 * length:g} m")
    reach = scene.container.min_m[0] + stroke + 2 * scene.kernel_radius_m
    for i, obstacle in enumerate(scene.obstacles):
        if obstacle.min_m[0] < reach:
            raise SceneError(f"{source}: key 'obstacles[{i}].min_m': the piston sweeps x up to "
                             f"{scene.container.min_m[0] + stroke:g} m; an obstacle must start at least 2 h "
                             f"further, at x ≥ {reach:g} m")


def _check_emitters(scene: Scene, source: str) -> None:
    """Emitters: a real interval and nozzle, inside the container and out of obstacles, within budget."""
    spacing = scene.fluid.spacing_m
    c_lo, c_hi = scene.container.min_m, scene.container.max_m
    for i, emitter in enumerate(scene.emitters):
        where = f"{source}: key 'emitters[{i}]"
        if emitter.end_s <= emitter.start_s:
            raise SceneError(f"{where}.end_s' = {emitter.end_s:g} s must be after start_s = {emitter.start_s:g} s")
        if math.sqrt(sum(c * c for c in emitter.direction)) < 1e-9:
            raise SceneError(f"{where}.direction': expected a non-zero vector, e.g. [0, -1, 0]")
        if emitter.radius_m < 0.5 * spacing:
            raise SceneError(f"{where}.radius_m' = {emitter.radius_m:g} m is less than half a spacing "
                             f"({0.5 * spacing:g} m): the nozzle would hold no particle")
        margin = emitter.radius_m + 0.5 * spacing  # the whole disc, at any orientation, a radius from the walls
        if any(p - margin < lo or p + margin > hi for p, lo, hi in zip(emitter.position_m, c_lo, c_hi)):
            raise SceneError(f"{where}.position_m': the nozzle (radius {emitter.radius_m:g} m) must lie inside the "
                             f"container, at least radius_m + spacing/2 = {margin:g} m from every wall")
        for j, obstacle in enumerate(scene.obstacles):
            if all(lo - margin < p < hi + margin for p, lo, hi in zip(emitter.position_m, obstacle.min_m,
                                                                       obstacle.max_m)):
                raise SceneError(f"{where}.position_m': the nozzle touches obstacles[{j}]; move it at least "
                                 f"{margin:g} m away")
    need = scene.particle_count + scene.emitted_count
    if scene.fluid.max_particles and scene.fluid.max_particles < need:
        raise SceneError(f"{source}: key 'fluid.max_particles' = {scene.fluid.max_particles:,} is less than the "
                         f"{scene.particle_count:,} particles of the blocks and the {scene.emitted_count:,} the "
                         f"emitters add (rate × duration); allowed: ≥ {need:,}, or 0 for exactly that")


def from_dict(table: dict, source: str = "<dict>") -> Scene:
    """Validate a scene given as a dict shaped like the TOML file."""
    scene = dataclasses.replace(_build(Scene, table, source), source=source)
    _check_geometry(scene, source)
    _check_obstacles(scene, source)
    _check_wave_maker(scene, source)
    _check_emitters(scene, source)
    return scene


def resolve_path(name_or_path: str | os.PathLike) -> Path:
    """A preset name (``dam_break``) or a path to a TOML file; a clear error if neither exists."""
    path = Path(name_or_path)
    if path.suffix != ".toml" and not path.exists():
        path = SCENES_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        presets = ", ".join(sorted(p.stem for p in SCENES_DIR.glob("*.toml")))
        raise SceneError(f"{name_or_path}: no such scene file; presets: {presets}")
    return path


def parse_override(assignment: str) -> tuple[list[str], object]:
    """Split ``solver.iterations=6`` into a key path and a TOML value (bare words are strings)."""
    if "=" not in assignment:
        raise SceneError(f"--set {assignment}: expected KEY=VALUE, e.g. solver.iterations=6")
    dotted, text = assignment.split("=", 1)
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    return dotted.strip().split("."), value


def load_scene(name_or_path: str | os.PathLike, overrides: typing.Sequence[str] = ()) -> Scene:
    """Load and validate a preset or TOML file, applying ``KEY=VALUE`` overrides first."""
    path = resolve_path(name_or_path)
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: not valid TOML: {error}") from None
    for assignment in overrides:
        keys, value = parse_override(assignment)
        target = table
        for part in keys[:-1]:
            target = target.setdefault(part, {})
            if not isinstance(target, dict):
                raise SceneError(f"{path}: --set {assignment}: '{part}' is not a table")
        target[keys[-1]] = value
    return from_dict(table, str(path))
