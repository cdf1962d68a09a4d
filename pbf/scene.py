"""The scene schema: one validated place for everything a preset sets.

A scene is a TOML file (see ``scenes/``), a dict of the same shape or a :class:`Scene` built by hand.
Every way in ends in ``Scene.__post_init__``, so no scene that fails a check exists: each key's type,
its range (every number has a lower and an upper bound, derived below from what the solver does
with it) and what keys must agree on (geometry, time step, camera) are checked before anything
runs. A failure raises :class:`SceneError`, whose one-line message names the source (the file, the
command line's ``--set`` or ``<dict>``), the key and what is allowed.

This module imports nothing of the solver, the application or the studies: the values the solver
derives from a scene (particle mass, grid, the memory and index checks) are ``pbf.solver.model``'s.
"""
from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import numbers
import os
import re
import sys
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"

Vec3 = tuple[float, float, float]

MAX_SCENE_BYTES = 1 << 20
"""The largest scene file read (1 MiB; the presets are 1-2 kB): a bigger one is refused unread."""
MAX_TABLES = 1000
"""Most [[fluid.blocks]] in a scene: the overlap check compares every pair."""
MAX_OBSTACLES = 100
"""Most [[obstacles]]: each is checked against every block and every obstacle before it."""
MAX_ITERATIONS = 100
"""Most Jacobi iterations a substep may run (solver.iterations): with substeps ≤ 1000, a bound on a
frame's cost."""
MIN_ITERATIONS = 2
"""solver.min_iterations's default; a scene with fewer solver.iterations runs them all (any other value
above solver.iterations is refused)."""
CHEBYSHEV_RHO = 0.9
"""solver.chebyshev_rho's default, which only acceleration = "chebyshev" reads: any other value with
another acceleration is refused (it would do nothing)."""
POSITION_REACH_SPACINGS = 2**16
"""How far from the origin, in spacings, a wall may lie. Positions are float32 (24-bit significand):
at 2¹⁶ spacings one unit in the last place is 2⁻⁷ of a spacing, the finest resolution the neighbour
distances and collisions can still work with. It also keeps every coordinate, and every speed the
box allows (see FLOAT32_SAFE), far inside float32's range."""
CAMERA_REACH_DIAGONALS = 1000
"""How far the camera may stand from the container's centre, in container diagonals: from farther,
the whole box is narrower than a pixel at any allowed field of view and image size."""
FLOAT32_SAFE = 1e30
"""What the derived float32 quantities must stay below (float32 ends at 3.4e38; the margin leaves
room for the sums and products the kernels form from them)."""


class SceneError(ValueError):
    """A scene that cannot be run; the message names the source, the key and what is allowed.

    ``key`` is the dotted key the message names (``"solver.iterations"``), or None when the problem
    is the file itself, so that a caller can say where the key came from (``load_scene`` names the
    command line's ``--set`` for the keys it set).
    """

    def __init__(self, message: str, key: str | None = None):
        super().__init__(message)
        found = re.search(r"\bkey '([^']+)'", message)
        self.key = key if key is not None else (found.group(1) if found else None)


# ----------------------------------------------------------------------------- showing values


def _show(value, limit: int = 60, depth: int = 0) -> str:
    """A value as a message echoes it: TOML spelling, plain Python numbers (0.5, not
    np.float64(0.5)), at most ``limit`` characters, and no conversion that could fail (an integer
    of thousands of digits cannot be printed whole, an array nested a thousand deep not at all)."""
    if depth > 2:
        text = "…"
    elif value is None:
        text = "None"
    elif isinstance(value, (bool, np.bool_)):
        text = "true" if value else "false"
    elif isinstance(value, numbers.Integral):
        value = int(value)
        text = str(value) if abs(value) < 10**18 else f"{'-' if value < 0 else ''}~1e{int(math.log10(abs(value)))}"
    elif isinstance(value, numbers.Real):
        text = repr(float(value))
    elif isinstance(value, (list, tuple, np.ndarray)):
        items = list(value[:4])
        text = "[" + ", ".join(_show(v, limit, depth + 1) for v in items) + (", …" if len(value) > 4 else "") + "]"
        if len(value) > 4:
            text += f" ({len(value):,} items)"
    elif isinstance(value, dict):
        keys = ", ".join(_show(k, 20, depth + 1) for k in list(value)[:4])
        text = "a table {" + keys + (", …" if len(value) > 4 else "") + "}"
    elif isinstance(value, str):
        text = repr(str(_clip(value, limit)))  # str(): NumPy's str_ has a repr of its own
    else:
        text = type(value).__name__
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _clip(text: str, limit: int = 60) -> str:
    """Text a message quotes, cut to ``limit`` characters."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


def echo(text: str) -> str:
    """Text the user typed (an option's value, a --set assignment) as a message echoes it: cut to 60
    characters, and in quotes with escapes where bare text would be unclear or span lines (empty,
    spaces, quotes, control characters)."""
    cut = _clip(text)
    return cut if cut and cut.isprintable() and not any(c in cut for c in " '\"") else repr(cut)


def _num(x: float) -> str:
    """A bound or a derived figure in a message: six significant digits."""
    return f"{float(x):g}"


def _vec(v) -> str:
    return "[" + ", ".join(_num(c) for c in v) + "]"


def _box(lo, hi) -> str:
    return f"{_vec(lo)}–{_vec(hi)} m"


def _closest(word: str, choices) -> str | None:
    found = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return found[0] if found else None


# ----------------------------------------------------------------------------- key checks


def _between(lowest, highest):
    """Allowed: lowest ≤ value ≤ highest (the check carries its ``bounds`` for tests/test_bounds.py)."""
    def check(value):
        return None if lowest <= value <= highest else f"a value in [{_num(lowest)}, {_num(highest)}]"
    check.bounds = (lowest, highest)
    return check


def _vec_between(lowest, highest):
    def check(value):
        inside = all(lowest <= c <= highest for c in value)
        return None if inside else f"three values in [{_num(lowest)}, {_num(highest)}]"
    check.bounds = (lowest, highest)
    return check


def _even_pixels(value):
    allowed = "an even number of pixels in [16, 8192] (video needs even sizes)"
    return None if 16 <= value <= 8192 and value % 2 == 0 else allowed


_even_pixels.bounds = (16, 8192)


def _one_of(*choices):
    """Allowed: one of ``choices``; a refusal also names the closest choice."""
    return lambda value: None if value in choices else ("one of " + ", ".join(map(repr, choices)),
                                                        _closest(value, choices))


def _colour_map(value):
    import matplotlib

    return None if value in matplotlib.colormaps else ("a Matplotlib colour map name such as 'viridis' or 'Blues'",
                                                       _closest(value, matplotlib.colormaps))


def _line(longest):
    """A single line of printable text (it is echoed in titles, progress bars and --list)."""
    return lambda value: (None if len(value) <= longest and value.isprintable()
                          else f"at most {longest} printable characters on one line")


def _at_most_tables(most):
    return lambda value: None if len(value) <= most else f"at most {most} tables"


def key(default=dataclasses.MISSING, check=None, doc=""):
    """A scene key: its default (none means required), a check and a doc line. The check returns None
    for an allowed value, else what is allowed, or (what is allowed, the closest allowed value)."""
    return field(default=default, metadata={"check": check, "doc": doc})


# ----------------------------------------------------------------------------- the schema
#
# The bounds. Lengths: fluid.spacing_m in [1e-4, 100] m keeps the kernel's σ/h⁵ and h⁵ (float32,
# h ≤ 4 s) far inside float32; walls within POSITION_REACH_SPACINGS of the origin keep positions
# resolved. Time: frame_dt_s in [1e-4, 1] s and at most 1000 substeps give Δt ≥ 1e-7 s; the
# fastest a particle can move, across the whole box in one substep (2√3·2¹⁶ s / Δt ≤ 2.3e14 m/s),
# squared, stays below FLOAT32_SAFE, as does the pressure scale ρ0 h²/Δt² ≤ 1.6e24 Pa at
# ρ0 ≤ 1e5 kg/m³. Work: iterations ≤ 100 and substeps ≤ 1000 bound a frame's cost (a billion of
# either would hang). Initial speeds and gravity are bounded by what a frame's substeps can follow
# (see _check_time), and s_corr's float32 power by pbf.solver.model. tests/test_bounds.py checks
# these figures against the bounds.


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
    spacing_m: float = key(0.025, _between(1e-4, 100.0), "particle spacing s (the lattice pitch), m")
    rest_density_kg_m3: float = key(1000.0, _between(1e-3, 1e5), "rest density ρ0, kg/m³")
    blocks: tuple[Block, ...] = key((), _at_most_tables(MAX_TABLES), "fluid blocks ([[fluid.blocks]] tables)")
    max_particles: int = key(0, _between(0, 2**31 - 1), "particle budget, allocated at the start: at least the "
                             "blocks' particles and all that the emitters add; 0: exactly that many")


@dataclass(frozen=True)
class Emitter:
    """A nozzle that shoots water in: a disc of lattice sites at the spacing, perpendicular to the
    direction, emitting a new layer each time the stream has moved one spacing, from start_s to end_s."""

    position_m: Vec3 = key(doc="centre of the nozzle, m")
    direction: Vec3 = key(doc="direction of the stream (any length; normalised)")
    radius_m: float = key(check=_between(0.0, 1e7), doc="radius of the nozzle, m (at least half a spacing, and "
                          "inside the container)")
    end_s: float = key(check=_between(0.0, 1e6), doc="when the stream stops, s")
    speed_m_s: float = key(1.0, _between(1e-6, 1e6), "speed of the stream, m/s (at most what a frame's substeps can "
                           "follow)")
    start_s: float = key(0.0, _between(0.0, 1e6), "when the stream starts, s")

    def unit_direction(self) -> Vec3:
        largest = max(abs(c) for c in self.direction)  # scaled first: any finite length normalises
        scaled = [c / largest for c in self.direction]
        return tuple(c / _length(scaled) for c in scaled)

    def sites_per_layer(self, spacing: float) -> int:
        """Lattice sites (i s, j s) of the nozzle's plane within its radius: per row i, the j with
        j² ≤ limit − i², counted exactly with isqrt (one row at a time, not one site: a nozzle of
        a thousand spacings counts in a millisecond)."""
        reach = int(math.floor(self.radius_m / spacing + 1e-9))
        limit = (self.radius_m / spacing) ** 2 + 1e-9
        return sum(2 * math.isqrt(math.floor(limit - i * i)) + 1 for i in range(-reach, reach + 1))

    def layers(self, spacing: float) -> int:
        """Layers emitted over the whole interval: one at start_s, one per spacing the stream moves."""
        return int(math.floor((self.end_s - self.start_s) * self.speed_m_s / spacing + 1e-9)) + 1


@dataclass(frozen=True)
class Time:
    frame_dt_s: float = key(1.0 / 60.0, _between(1e-4, 1.0), "time per rendered frame, s")
    substeps: int = key(2, _between(1, 1000), "PBF steps per frame (Δt = frame_dt_s / substeps)")
    max_cfl: float = key(1.2, _between(0.01, 4.0), "most particle spacings the fastest particle may travel in one "
                         "substep; a frame takes more substeps when it would go further")
    max_substeps: int = key(64, _between(1, 1000), "cap on the substeps one frame may take (a warning when reached)")
    settle_s: float = key(0.0, _between(0.0, 60.0), "seconds of solver steps, velocities zeroed after each, that "
                          "bring the blocks to the solver's own rest state before t = 0 (not with emitters)")


@dataclass(frozen=True)
class Solver:
    iterations: int = key(10, _between(1, MAX_ITERATIONS), "Jacobi iterations of the density constraint per "
                          "substep (the most, with target_density_error)")
    min_iterations: int = key(MIN_ITERATIONS, _between(1, MAX_ITERATIONS), "Jacobi iterations every substep "
                              "runs, whatever the error (one plain iteration alone leaves the shortest waves "
                              "reversed: pbf.solver.acceleration)")
    target_density_error: float = key(0.001, _between(0.0, 1.0), "stop iterating once the mean of max(ρ/ρ0 − 1, 0) "
                                      "is below this (and min_iterations ran); 0 always runs all iterations")
    acceleration: str = key("stable", _one_of("stable", "chebyshev", "none"), "weights of the Jacobi iterations' "
                            "two-step acceleration: stable (none reverses an error mode enough to pump it), chebyshev "
                            "(Wang 2015, with chebyshev_rho) or none (plain Jacobi); pbf.solver.acceleration")
    chebyshev_rho: float = key(CHEBYSHEV_RHO, _between(0.0, 0.99), "spectral radius ρ assumed by acceleration = "
                               "\"chebyshev\"; 0: plain Jacobi")
    step_back: bool = key(True, doc="when the target stops the iterations, take back the share of the last one it did "
                          "not need (a count between two: a pool at rest holds still); false stops after whole "
                          "iterations, below the target (cheaper error in a splash); only with a target")
    divergence_iterations: int = key(0, _between(0, 100), "Jacobi iterations of the divergence pre-correction "
                                     "(velocity level, before the prediction) per substep; 0 switches it off")
    warm_start: float = key(1.0, _between(0.0, 1.0), "fraction of the last substep's divergence pressure the "
                            "next one starts from")
    kernel_ratio: float = key(2.2, _between(1.5, 4.0), "smoothing radius over spacing, h/s")
    relaxation: float = key(0.1, _between(1e-6, 100.0), "ε of Eq. (10) in the dimensionless form; it keeps λ "
                            "finite for a particle with no neighbour (float32: ≥ 1e-6)")
    clamp_pressure: bool = key(True, doc="use C_i = max(ρ_i/ρ0 − 1, 0): only compressed particles push")
    scorr_k: float = key(0.03, _between(0.0, 1.0), "s_corr strength k (Eq. 11), dimensionless form, beside λ "
                         "of order 1; 0 disables")
    scorr_n: int = key(8, _between(1, 32), "s_corr exponent n (Eq. 11); 8 confines it to pairs closer than ~0.3 h")
    scorr_dq: float = key(0.2, _between(0.0, 0.9), "s_corr reference distance Δq/h (Eq. 11)")
    wall_density: bool = key(True, doc="add the density of the ghost fluid behind walls (no stacking)")
    wall_mirror: bool = key(False, doc="the ghost fluid behind the container's walls is the mirror image of the "
                            "fluid, moving with it, instead of a fixed lattice: particles at a wall carry the pressure "
                            "of their neighbours, not twice it (needs wall_density)")
    surface_density: bool = key(False, doc="add the density of ghost fluid beyond the free surface, placed by "
                                "each particle's colour gradient (the surface layer sits a spacing high)")


@dataclass(frozen=True)
class Viscosity:
    xsph: float = key(0.01, _between(0.0, 1.0), "XSPH coefficient c (Eq. 15), dimensionless; 0 disables")


@dataclass(frozen=True)
class WaveMaker:
    """A piston wave maker: the container's lower-x wall swings along x between min_m and
    min_m + stroke_m, x = min + S/2 (1 − cos 2πt/T), starting at rest."""

    stroke_m: float = key(0.0, _between(0.0, 1e7), "piston stroke S, m, at most a quarter of the container's "
                          "length; 0: no wave maker")
    period_s: float = key(1.0, _between(1e-3, 1e6), "wave period T, s (the piston's top speed π S / T at most what "
                          "a frame's substeps can follow)")


@dataclass(frozen=True)
class Vorticity:
    epsilon: float = key(0.0, _between(0.0, 1.0), "vorticity confinement ε (Eqs. 13-14), dimensionless, an "
                         "acceleration ε h |ω|² that beyond 1 outgrows the vortex it restores; 0 disables")


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
    speed_max_m_s: float = key(3.0, _between(1e-6, 1e6), "speed at the top of the colour map, m/s")
    density_error_max: float = key(0.05, _between(1e-6, 1.0), "colour map spans ρ/ρ0 from 1 − this to 1 + this "
                                   "(ρ/ρ0 ≥ 0, and float32 resolves 1e-6)")
    background_rgb: Vec3 = key((0.96, 0.96, 0.94), _vec_between(0.0, 1.0), "background colour (red, green, blue)")
    container_rgb: Vec3 = key((0.25, 0.25, 0.3), _vec_between(0.0, 1.0), "colour of the container's edges")
    width_px: int = key(1280, _even_pixels, "image width, pixels")
    height_px: int = key(720, _even_pixels, "image height, pixels")
    legend: bool = key(False, doc="draw the colour legend (bar, range and unit) on headless frames; the "
                       "window's panel always shows it")
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
    absorption_per_m: Vec3 = key((5.0, 1.8, 1.0), _vec_between(0.0, 1e6), "Beer–Lambert absorption of red, "
                                 "green and blue light in render.style = surface, 1/m")
    water_rgb: Vec3 = key((0.03, 0.25, 0.4), _vec_between(0.0, 1.0), "colour of deep water (the light it absorbs "
                          "is replaced by this)")


@dataclass(frozen=True)
class Scene:
    source: str = field(default="<Scene>", compare=False, metadata={"internal": True})
    """Where the scene came from (a file path, "<dict>" or "<Scene>"): error messages name it. Not a TOML key."""
    name: str = key("scene", _line(64), "short name")
    description: str = key("", _line(200), "one line shown by --list")
    gravity_m_s2: Vec3 = key((0.0, -9.81, 0.0), doc="gravitational acceleration, m/s² (y is up)")
    container: Container = key(Container())
    fluid: Fluid = key(Fluid())
    obstacles: tuple[Obstacle, ...] = key((), _at_most_tables(MAX_OBSTACLES), "static boxes in the container "
                                          "([[obstacles]] tables)")
    emitters: tuple[Emitter, ...] = key((), _at_most_tables(MAX_OBSTACLES), "nozzles that add water while the "
                                        "scene runs ([[emitters]] tables)")
    time: Time = key(Time())
    solver: Solver = key(Solver())
    viscosity: Viscosity = key(Viscosity())
    vorticity: Vorticity = key(Vorticity())
    wave_maker: WaveMaker = key(WaveMaker())
    camera: Camera = key(Camera())
    render: Render = key(Render())
    surface: Surface = key(Surface())

    def __post_init__(self):
        # Every value converted to its annotated type and checked, nested tables included, so a
        # Scene built by hand is held to the same rules as a file; then what keys must agree on.
        if not isinstance(self.source, str):
            raise SceneError(f"<Scene>: source: expected a string naming where the scene came from, "
                             f"got {_show(self.source)}")
        for name, value in _table_values(Scene, self, self.source, "").items():
            object.__setattr__(self, name, value)
        _check_scene(self)

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
        """Lattice sites of all fluid blocks (see :func:`block_counts`): the particles at the start, an
        exact integer."""
        return sum(math.prod(block_counts(b, self.fluid.spacing_m)) for b in self.fluid.blocks)

    @property
    def fastest_followed_m_s(self) -> float:
        """The fastest speed a frame's substeps can follow: time.max_substeps substeps of at most
        time.max_cfl spacings each (``Simulation.substeps_needed``)."""
        t = self.time
        return t.max_substeps * t.max_cfl * self.fluid.spacing_m / t.frame_dt_s

    @property
    def emitted_count(self) -> int:
        """Particles the emitters add over the whole run."""
        spacing = self.fluid.spacing_m
        return sum(e.layers(spacing) * e.sites_per_layer(spacing) for e in self.emitters)

    @property
    def particle_capacity(self) -> int:
        """Particles allocated at the start: fluid.max_particles, or the blocks' and emitters' total."""
        return self.fluid.max_particles or self.particle_count + self.emitted_count



# ----------------------------------------------------------------------------- values and types


def _type_name(annotation) -> str:
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(
        annotation, "three numbers [x, y, z]"
    )


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _finite_float(value) -> float | None:
    """float(value) if it is a finite float64, else None (an integer past 1e308 included)."""
    try:
        converted = float(value)
    except OverflowError:
        return None
    return converted if math.isfinite(converted) else None


def _convert(value, annotation, where):
    """Convert one value to the annotated type, or raise SceneError naming what was expected."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):  # X | None: None only from Python
        if value is None:
            return None
        annotation = next(a for a in typing.get_args(annotation) if a is not type(None))
    if annotation is bool:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
    elif annotation is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
            return int(value)
    elif annotation is float:
        if _is_number(value):
            converted = _finite_float(value)
            if converted is None:
                raise SceneError(f"{where}: expected a finite number, got {_show(value)}")
            return converted
    elif annotation is str:
        if isinstance(value, str):
            return str(value)
    elif annotation == Vec3:
        if isinstance(value, (list, tuple, np.ndarray)) and len(value) == 3 and all(_is_number(c) for c in value):
            converted = [_finite_float(c) for c in value]
            if None in converted:
                raise SceneError(f"{where}: expected three finite numbers, got {_show(value)}")
            return tuple(converted)
    else:
        raise TypeError(annotation)
    raise SceneError(f"{where}: expected {_type_name(annotation)}, got {_show(value)}")


def _schema_keys(cls, prefix="") -> list[str]:
    """Every dotted key of the schema under ``cls`` (for "did you mean")."""
    found = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):
            continue
        annotation = hints[f.name]
        found.append(prefix + f.name)
        if dataclasses.is_dataclass(annotation):
            found += _schema_keys(annotation, f"{prefix}{f.name}.")
    return found


def _unknown_key(name: str, prefix: str, known, source: str) -> SceneError:
    """The error for an unknown key: the closest key of this table, else a key of the same name
    elsewhere (``iterations`` → ``solver.iterations``), and the keys allowed here."""
    dotted = f"{prefix}{name}"
    closest = _closest(name, known)
    if closest is not None:
        hint = f"did you mean '{prefix}{closest}'? "
    else:
        leaves = {k: k.rsplit(".", 1)[-1] for k in _schema_keys(Scene)}
        leaf = _closest(name, set(leaves.values()))
        hint = next((f"did you mean '{k}'? " for k, l in leaves.items() if leaf is not None and l == leaf), "")
    return SceneError(f"{source}: unknown key '{_clip(dotted)}'; {hint}allowed keys here: {', '.join(sorted(known))}",
                      key=dotted)


def _table_values(cls, table, source: str, prefix: str) -> dict:
    """The checked values of dataclass ``cls`` from a TOML table (a dict) or an instance of ``cls``:
    unknown and missing keys refused, each value converted to its type and checked, nested tables
    built the same way."""
    where_table = f"{source}: key '{prefix.rstrip('.')}'" if prefix else source
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}
    if isinstance(table, cls):
        raw = {name: getattr(table, name) for name in known}
    elif isinstance(table, dict):
        strange = [k for k in table if not isinstance(k, str)]
        if strange:
            raise SceneError(f"{where_table}: key {_show(strange[0])} is not a string; keys are names such as "
                             f"{next(iter(known))!r}")
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise _unknown_key(unknown[0], prefix, known, source)
        raw = table
    else:
        raise SceneError(f"{where_table}: expected a table ([{prefix.rstrip('.') or 'scene'}]), got {_show(table)}")
    values = {}
    for name, f in known.items():
        where = f"{source}: key '{prefix}{name}'"
        if name not in raw:
            if f.default is dataclasses.MISSING:
                raise SceneError(f"{where} is required ({f.metadata['doc']})")
            continue
        annotation, value = hints[name], raw[name]
        if dataclasses.is_dataclass(annotation):
            value = annotation(**_table_values(annotation, value, source, f"{prefix}{name}."))
        elif typing.get_origin(annotation) is tuple and dataclasses.is_dataclass(typing.get_args(annotation)[0]):
            if not isinstance(value, (list, tuple)):
                raise SceneError(f"{where}: expected a list of tables ([[{prefix}{name}]]), got {_show(value)}")
            item = typing.get_args(annotation)[0]
            check = f.metadata["check"]
            allowed = None if check is None else check(value)
            if allowed is not None:
                raise SceneError(f"{where}: expected {allowed} ({f.metadata['doc']}), got {len(value):,}")
            value = tuple(item(**_table_values(item, t, source, f"{prefix}{name}[{i}]."))
                          for i, t in enumerate(value))
        else:
            value = _convert(value, annotation, where)
            check = f.metadata["check"]
            allowed = None if check is None or value is None else check(value)
            if allowed is not None:
                allowed, closest = allowed if isinstance(allowed, tuple) else (allowed, None)
                hint = f"; did you mean {closest!r}?" if closest else ""
                raise SceneError(f"{where}: expected {allowed} ({f.metadata['doc']}), got {_show(value)}{hint}")
        values[name] = value
    return values


# ----------------------------------------------------------------------------- what keys must agree on


def block_counts(block: Block, spacing: float) -> tuple[int, int, int]:
    """Lattice sites per axis: as many spacings as fit in the block (a rounding tolerance of 1e-6 s)."""
    return tuple(int(math.floor((hi - lo) / spacing + 1e-6)) for lo, hi in zip(block.min_m, block.max_m))


def _check_container(scene: Scene, source: str) -> None:
    lo, hi = scene.container.min_m, scene.container.max_m
    spacing = scene.fluid.spacing_m
    reach = POSITION_REACH_SPACINGS * spacing
    for name, corner in (("min_m", lo), ("max_m", hi)):
        farthest = max(abs(c) for c in corner)
        if farthest > reach:
            raise SceneError(
                f"{source}: key 'container.{name}': a wall at {_num(farthest)} m lies {_num(farthest / spacing)} "
                f"spacings from the origin; float32 positions resolve 1/128 spacing only within "
                f"{POSITION_REACH_SPACINGS:,} spacings ({_num(reach)} m at fluid.spacing_m = {_num(spacing)}): "
                f"move the container towards the origin or use a larger spacing")
    if any(h <= l for l, h in zip(lo, hi)):
        raise SceneError(f"{source}: key 'container.max_m' must exceed 'container.min_m' on every axis, "
                         f"got min {_vec(lo)} and max {_vec(hi)}")
    if any(h - l < 2 * scene.kernel_radius_m for l, h in zip(lo, hi)):
        raise SceneError(f"{source}: key 'container.max_m': the box must be at least two smoothing radii "
                         f"(2 h = {_num(2 * scene.kernel_radius_m)} m) wide on every axis for fluid.spacing_m = "
                         f"{_num(spacing)}")


def _check_blocks(scene: Scene, source: str) -> None:
    blocks = scene.fluid.blocks
    if not blocks:
        if scene.emitters:
            return
        raise SceneError(f"{source}: key 'fluid.blocks': at least one [[fluid.blocks]] table (or an [[emitters]] "
                         f"table) is required")
    c_lo, c_hi = np.array(scene.container.min_m), np.array(scene.container.max_m)
    spacing = scene.fluid.spacing_m
    tolerance = 1e-9 * (float(np.max(np.abs(np.concatenate([c_lo, c_hi])))) + 1.0)
    lows = np.array([b.min_m for b in blocks])
    highs = np.array([b.max_m for b in blocks])
    for i, block in enumerate(blocks):
        where = f"{source}: key 'fluid.blocks[{i}]"
        b_lo, b_hi = lows[i], highs[i]
        if np.any(b_hi <= b_lo):
            raise SceneError(f"{where}.max_m' must exceed min_m on every axis, got {_vec(b_lo)} and {_vec(b_hi)}")
        if np.any(b_lo < c_lo - tolerance) or np.any(b_hi > c_hi + tolerance):
            raise SceneError(f"{where}': block {_box(b_lo, b_hi)} lies outside the container {_box(c_lo, c_hi)}; "
                             f"allowed: min_m ≥ container.min_m and max_m ≤ container.max_m")
        if min(block_counts(block, spacing)) < 1:
            raise SceneError(f"{where}': block {_box(b_lo, b_hi)} is thinner than one spacing ({_num(spacing)} m) "
                             f"on some axis, so it holds no particle")
        # One vectorised comparison against all earlier blocks: a thousand blocks check in milliseconds.
        overlap = np.all(np.minimum(b_hi, highs[:i]) - np.maximum(b_lo, lows[:i]) > tolerance, axis=1)
        if overlap.any():
            raise SceneError(f"{where}' overlaps fluid.blocks[{int(np.argmax(overlap))}]; blocks must not share volume")


MIN_OBSTACLE_SPACINGS = 2
"""An obstacle's least thickness, in spacings. Grown by the particle radius, its half-thickness is
then at least 1.5 spacings, and a particle moves at most time.max_cfl spacings per substep (1.2 by
default, at most OBSTACLE_MAX_CFL with obstacles), so it cannot cross an obstacle's middle in one
substep and be pushed out on the far side."""
OBSTACLE_MAX_CFL = 1.5


def _check_obstacles(scene: Scene, source: str) -> None:
    """Obstacles: inside the container, thick enough, sharing no volume with fluid or each other."""
    c_lo, c_hi = scene.container.min_m, scene.container.max_m
    thinnest = MIN_OBSTACLE_SPACINGS * scene.fluid.spacing_m
    tolerance = 1e-9 * (max(abs(c) for c in c_lo + c_hi) + 1.0)

    def overlap(a_lo, a_hi, b_lo, b_hi):
        return all(min(ah, bh) - max(al, bl) > tolerance for al, ah, bl, bh in zip(a_lo, a_hi, b_lo, b_hi))

    if scene.obstacles and scene.time.max_cfl > OBSTACLE_MAX_CFL:
        raise SceneError(f"{source}: key 'time.max_cfl' = {_num(scene.time.max_cfl)} lets particles cross an "
                         f"obstacle in one substep; with [[obstacles]] it must be ≤ {_num(OBSTACLE_MAX_CFL)}")
    for i, obstacle in enumerate(scene.obstacles):
        lo, hi = obstacle.min_m, obstacle.max_m
        where = f"{source}: key 'obstacles[{i}]"
        if any(h - l < thinnest for l, h in zip(lo, hi)):
            raise SceneError(f"{where}.max_m': obstacle {_box(lo, hi)} must be at least {MIN_OBSTACLE_SPACINGS} "
                             f"spacings ({_num(thinnest)} m) thick on every axis, or particles could cross it")
        if any(l < cl - tolerance or h > ch + tolerance for l, h, cl, ch in zip(lo, hi, c_lo, c_hi)):
            raise SceneError(f"{where}': obstacle {_box(lo, hi)} lies outside the container {_box(c_lo, c_hi)}; "
                             f"allowed: min_m ≥ container.min_m and max_m ≤ container.max_m")
        for j, block in enumerate(scene.fluid.blocks):
            if overlap(lo, hi, block.min_m, block.max_m):
                raise SceneError(f"{where}' overlaps fluid.blocks[{j}] ({_box(block.min_m, block.max_m)}); "
                                 f"move the block or the obstacle so that they share no volume")
        for j, other in enumerate(scene.obstacles[:i]):
            if overlap(lo, hi, other.min_m, other.max_m):
                raise SceneError(f"{where}' overlaps obstacles[{j}]; obstacles must not share volume")


def _length(v) -> float:
    """|v|, scaled by its largest component so that no square overflows (inf only past 1.8e308, and
    inf compares). Not math.hypot or math.dist: once Taichi has started, the process flushes
    subnormals to zero and they return NaN for large inputs, and every comparison with NaN is
    false, so a check would pass."""
    largest = max(abs(c) for c in v)
    return 0.0 if largest == 0.0 else largest * math.sqrt(sum((c / largest) ** 2 for c in v))


def _check_wave_maker(scene: Scene, source: str) -> None:
    """The piston must leave room behind it for the water and in front of it for the obstacles."""
    stroke = scene.wave_maker.stroke_m
    if stroke == 0.0:
        return
    length = scene.container.max_m[0] - scene.container.min_m[0]
    if not stroke <= 0.25 * length:
        raise SceneError(f"{source}: key 'wave_maker.stroke_m' = {_num(stroke)} m is more than a quarter of the "
                         f"container's length along x ({_num(length)} m); allowed: ≤ {_num(0.25 * length)} m")
    reach = scene.container.min_m[0] + stroke + 2 * scene.kernel_radius_m
    for i, obstacle in enumerate(scene.obstacles):
        if obstacle.min_m[0] < reach:
            raise SceneError(f"{source}: key 'obstacles[{i}].min_m': the piston sweeps x up to "
                             f"{_num(scene.container.min_m[0] + stroke)} m; an obstacle must start at least 2 h "
                             f"further, at x ≥ {_num(reach)} m")


def _check_emitters(scene: Scene, source: str) -> None:
    """Emitters: a real interval and nozzle, inside the container and out of obstacles, within budget."""
    spacing = scene.fluid.spacing_m
    c_lo, c_hi = scene.container.min_m, scene.container.max_m
    for i, emitter in enumerate(scene.emitters):
        where = f"{source}: key 'emitters[{i}]"
        if not emitter.end_s > emitter.start_s:
            raise SceneError(f"{where}.end_s' = {_num(emitter.end_s)} s must be after start_s = "
                             f"{_num(emitter.start_s)} s")
        if not _length(emitter.direction) >= 1e-9:
            raise SceneError(f"{where}.direction': expected a non-zero vector, e.g. [0, -1, 0]")
        if emitter.radius_m < 0.5 * spacing:
            raise SceneError(f"{where}.radius_m' = {_num(emitter.radius_m)} m is less than half a spacing "
                             f"({_num(0.5 * spacing)} m): the nozzle would hold no particle")
        margin = emitter.radius_m + 0.5 * spacing  # the whole disc, at any orientation, a radius from the walls
        if any(p - margin < lo or p + margin > hi for p, lo, hi in zip(emitter.position_m, c_lo, c_hi)):
            raise SceneError(f"{where}.position_m': the nozzle (radius {_num(emitter.radius_m)} m) must lie inside "
                             f"the container, at least radius_m + spacing/2 = {_num(margin)} m from every wall")
        for j, obstacle in enumerate(scene.obstacles):
            if all(lo - margin < p < hi + margin for p, lo, hi in zip(emitter.position_m, obstacle.min_m,
                                                                       obstacle.max_m)):
                raise SceneError(f"{where}.position_m': the nozzle touches obstacles[{j}]; move it at least "
                                 f"{_num(margin)} m away")
    need = scene.particle_count + scene.emitted_count
    if scene.fluid.max_particles and scene.fluid.max_particles < need:
        raise SceneError(f"{source}: key 'fluid.max_particles' = {scene.fluid.max_particles:,} is less than the "
                         f"{scene.particle_count:,} particles of the blocks and the {scene.emitted_count:,} the "
                         f"emitters add (rate × duration); allowed: ≥ {need:,}, or 0 for exactly that")


def _check_time(scene: Scene, source: str) -> None:
    """Substeps, the CFL limit, initial speeds and gravity must fit what a frame can follow."""
    t = scene.time
    if t.substeps > t.max_substeps:
        raise SceneError(f"{source}: key 'time.substeps' = {t.substeps} is more than time.max_substeps = "
                         f"{t.max_substeps}, the cap on a frame's substeps; raise time.max_substeps or lower "
                         f"time.substeps")
    if not t.max_cfl <= scene.solver.kernel_ratio:
        raise SceneError(f"{source}: key 'time.max_cfl' = {_num(t.max_cfl)} would let a particle pass its whole "
                         f"neighbourhood (solver.kernel_ratio = {_num(scene.solver.kernel_ratio)} spacings) in one "
                         f"substep; allowed: ≤ solver.kernel_ratio")
    # Simulation.substeps_needed takes (fastest speed + |g| · frame_dt) · frame_dt / (max_cfl · s)
    # substeps, capped at max_substeps: beyond the cap particles tunnel from the first frame on.
    followed = scene.fastest_followed_m_s
    fall = _length(scene.gravity_m_s2) * t.frame_dt_s
    limits = "(time.max_substeps × time.max_cfl × fluid.spacing_m / time.frame_dt_s)"
    if not fall <= followed:
        raise SceneError(f"{source}: key 'gravity_m_s2': |g| = {_num(fall / t.frame_dt_s)} m/s² gains "
                         f"{_num(fall)} m/s in one frame, more than the {_num(followed)} m/s its substeps can follow "
                         f"{limits}; allowed: |g| ≤ {_num(followed / t.frame_dt_s)} m/s², or raise "
                         f"time.max_substeps")
    for i, block in enumerate(scene.fluid.blocks):
        speed = _length(block.velocity_m_s)
        if not speed + fall <= followed:
            raise SceneError(f"{source}: key 'fluid.blocks[{i}].velocity_m_s': {_num(speed)} m/s (plus "
                             f"{_num(fall)} m/s of gravity in the first frame) is faster than the {_num(followed)} m/s "
                             f"a frame's substeps can follow {limits}; allowed: ≤ {_num(followed - fall)} m/s, or "
                             f"raise time.max_substeps")
    for i, emitter in enumerate(scene.emitters):
        if not emitter.speed_m_s + fall <= followed:
            raise SceneError(f"{source}: key 'emitters[{i}].speed_m_s' = {_num(emitter.speed_m_s)} m/s (plus "
                             f"{_num(fall)} m/s of gravity in a frame) is faster than the {_num(followed)} m/s a "
                             f"frame's substeps can follow {limits}; allowed: ≤ {_num(followed - fall)} m/s")
    piston = math.pi * scene.wave_maker.stroke_m / scene.wave_maker.period_s  # the piston's top speed, π S / T
    if not piston + fall <= followed:
        raise SceneError(f"{source}: key 'wave_maker.period_s' = {_num(scene.wave_maker.period_s)} s moves the piston "
                         f"at up to π S / T = {_num(piston)} m/s, faster than the {_num(followed)} m/s a frame's "
                         f"substeps can follow {limits}; allowed: period_s ≥ "
                         f"{_num(math.pi * scene.wave_maker.stroke_m / max(followed - fall, 1e-300))} s")


def default_look_at_m(scene: Scene) -> Vec3:
    """Where the camera looks when camera.look_at_m is omitted: a little below the box centre (the
    renderer's ``View.of_scene``; seen from above, the box's near bottom corner reaches lowest)."""
    lo, hi = scene.container.min_m, scene.container.max_m
    centre = [0.5 * (a + b) for a, b in zip(lo, hi)]
    return (centre[0], centre[1] - 0.08 * (hi[1] - lo[1]), centre[2])


def _check_settle(scene: Scene, source: str) -> None:
    """Settling runs the blocks alone: water that an emitter adds later cannot be settled beforehand."""
    if scene.time.settle_s > 0.0 and scene.emitters:
        raise SceneError(f"{source}: key 'time.settle_s' = {_num(scene.time.settle_s)} settles the blocks before t = 0, "
                         f"but this scene has emitters, whose water arrives later; allowed: 0 with emitters")


def _check_solver(scene: Scene, source: str) -> None:
    """The iteration counts must leave room between the least and the most; ρ only goes with Chebyshev
    weights and the step back with a target; a mirrored wall needs a wall."""
    s = scene.solver
    if s.min_iterations > s.iterations and s.min_iterations != MIN_ITERATIONS:
        raise SceneError(f"{source}: key 'solver.min_iterations' = {s.min_iterations} is more than solver.iterations = "
                         f"{s.iterations}, the most a substep runs; allowed: 1 to {s.iterations}")
    if s.acceleration != "chebyshev" and s.chebyshev_rho != CHEBYSHEV_RHO:
        raise SceneError(f"{source}: key 'solver.chebyshev_rho' = {_num(s.chebyshev_rho)} sets the ρ of Chebyshev "
                         f"weights, but solver.acceleration = \"{s.acceleration}\" does not use them; allowed: "
                         f"solver.acceleration = \"chebyshev\", or no solver.chebyshev_rho")
    if not s.step_back and s.target_density_error == 0.0:
        raise SceneError(f"{source}: key 'solver.step_back' = false changes where the error target stops the "
                         f"iterations, but solver.target_density_error = 0 runs them all; allowed: true, or a "
                         f"target above 0")
    if s.wall_mirror and not s.wall_density:
        raise SceneError(f"{source}: key 'solver.wall_mirror' = true mirrors the ghost fluid behind the walls, but "
                         f"solver.wall_density = false leaves none; allowed: false, or solver.wall_density = true")


def _check_camera(scene: Scene, source: str) -> None:
    lo, hi = scene.container.min_m, scene.container.max_m
    centre = [0.5 * (a + b) for a, b in zip(lo, hi)]
    diagonal = _length([b - a for a, b in zip(lo, hi)])
    farthest = CAMERA_REACH_DIAGONALS * diagonal
    for name in ("position_m", "look_at_m"):
        point = getattr(scene.camera, name)
        distance = None if point is None else _length([a - b for a, b in zip(point, centre)])
        if distance is not None and not distance <= farthest:
            raise SceneError(f"{source}: key 'camera.{name}': {_vec(point)} m is {_num(distance)} m "
                             f"from the container's centre; allowed: within {CAMERA_REACH_DIAGONALS} container "
                             f"diagonals ({_num(farthest)} m), beyond which the box is smaller than a pixel")
    eye = scene.camera.position_m
    target = scene.camera.look_at_m if scene.camera.look_at_m is not None else default_look_at_m(scene)
    if eye is not None and not _length([a - b for a, b in zip(eye, target)]) > 1e-6 * diagonal:
        given = "camera.look_at_m" if scene.camera.look_at_m is not None else "the default look-at point"
        raise SceneError(f"{source}: key 'camera.position_m': the eye {_vec(eye)} m is at {given} {_vec(target)} m, "
                         f"so it looks nowhere; move camera.position_m or set camera.look_at_m elsewhere")


def _check_render(scene: Scene, source: str) -> None:
    if scene.render.legend and scene.render.style == "surface":
        raise SceneError(f"{source}: key 'render.legend': the surface style has no colour map to explain; "
                         f"set render.legend = false or render.style = \"particles\"")


def _check_scene(scene: Scene) -> None:
    source = scene.source
    _check_container(scene, source)
    _check_blocks(scene, source)
    _check_obstacles(scene, source)
    _check_wave_maker(scene, source)
    _check_emitters(scene, source)
    _check_time(scene, source)
    _check_solver(scene, source)
    _check_settle(scene, source)
    _check_camera(scene, source)
    _check_render(scene, source)


# ----------------------------------------------------------------------------- files, overrides, loading


def from_dict(table: dict, source: str = "<dict>") -> Scene:
    """Validate a scene given as a dict shaped like the TOML file."""
    return Scene(source=source, **_table_values(Scene, table, source, ""))


def _presets() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def resolve_path(name_or_path: str | os.PathLike) -> Path:
    """A preset name (``dam_break``) or a path to a TOML file; a clear error if neither exists."""
    text = os.fspath(name_or_path)
    if not isinstance(text, str) or not text or not text.isprintable():
        raise SceneError(f"{_show(text)}: expected a preset name or the path of a TOML file")
    shown = _clip(text, 200)
    path = Path(text)
    try:
        if path.suffix != ".toml" and not path.exists() and re.fullmatch(r"[\w-]+", text):
            path = SCENES_DIR / f"{text}.toml"
        if path.is_dir():
            raise SceneError(f"{shown}: is a folder; expected a TOML scene file or a preset name")
        if not path.exists():
            closest = _closest(path.stem, _presets())
            hint = f"did you mean {closest}? " if closest else ""
            raise SceneError(f"{shown}: no such scene file; {hint}presets: {', '.join(_presets())}")
        if not path.is_file():
            raise SceneError(f"{shown}: not a regular file; expected a TOML scene file")
    except OSError as error:
        raise SceneError(f"{shown}: cannot be read ({error.strerror or error})") from None
    return path


def _parse_toml(text: str, source: str) -> dict:
    """TOML text as a dict; every way tomllib can fail becomes one SceneError naming ``source``."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:
        raise SceneError(f"{source}: not valid TOML: arrays or tables nested deeper than Python can read") from None
    except ValueError:  # an integer longer than int() reads (sys.int_info.default_max_str_digits)
        raise SceneError(f"{source}: holds an integer of more than {sys.get_int_max_str_digits():,} digits; "
                         f"every number in a scene has far fewer") from None


def read_table(path: Path) -> dict:
    """The TOML table of a scene file, or SceneError: unreadable, too large, not UTF-8 text or not TOML."""
    try:
        with path.open("rb") as file:
            data = file.read(MAX_SCENE_BYTES + 1)  # no more, whatever the file's size
    except OSError as error:
        raise SceneError(f"{path}: cannot be read ({error.strerror or error})") from None
    if len(data) > MAX_SCENE_BYTES:
        raise SceneError(f"{path}: more than {MAX_SCENE_BYTES:,} bytes; a scene file is at most {MAX_SCENE_BYTES:,} "
                         f"bytes (the presets are 1-2 kB)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError(f"{path}: not UTF-8 text (byte 0x{data[error.start]:02x} at offset {error.start}); a scene "
                         f"is a TOML text file") from None
    return _parse_toml(text.removeprefix("\ufeff"), str(path))


def parse_override(assignment: str) -> tuple[list[str], object]:
    """Split ``solver.iterations=6`` into a key path and a TOML value (bare words are strings)."""
    label = f"command line --set {echo(assignment) if isinstance(assignment, str) else _show(assignment)}"
    if not isinstance(assignment, str):
        raise SceneError(f"{label}: expected a 'KEY=VALUE' string")
    if not assignment.isprintable():
        raise SceneError(f"{label}: expected one line of printable text (a newline would start a second TOML "
                         f"statement)")
    if "=" not in assignment:
        raise SceneError(f"{label}: expected KEY=VALUE, e.g. solver.iterations=6")
    dotted, text = assignment.split("=", 1)
    keys = dotted.strip().split(".")
    if not all(re.fullmatch(r"[A-Za-z0-9_-]+", k) for k in keys):
        raise SceneError(f"{label}: '{_clip(dotted.strip())}' is not a dotted key such as solver.iterations")
    try:
        document = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return keys, text.strip()
    except (RecursionError, ValueError):
        document = _parse_toml(f"v = {text}", label)
    return keys, document["v"]


def _table_of(scene: Scene) -> dict:
    """A Scene as the dict of its TOML file (omitted camera points left out)."""
    def plain(value):
        if dataclasses.is_dataclass(value):
            return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                    if not f.metadata.get("internal") and getattr(value, f.name) is not None}
        if isinstance(value, tuple):
            return [plain(v) for v in value]
        return value

    return plain(scene)


def _set(table: dict, keys: list[str], value, label: str) -> None:
    """table[k0][k1]…[kn] = value, making the tables on the way."""
    target = table
    for depth, part in enumerate(keys[:-1]):
        target = target.setdefault(part, {})
        if isinstance(target, list):
            raise SceneError(f"{label}: '{'.'.join(keys[:depth + 1])}' is a list of tables; set it whole, e.g. "
                             f"--set '{'.'.join(keys[:depth + 1])}=[{{min_m = [0, 0, 0], max_m = [0.5, 0.5, 0.5]}}]'")
        if not isinstance(target, dict):
            raise SceneError(f"{label}: '{'.'.join(keys[:depth + 1])}' is not a table")
    target[keys[-1]] = value


def load_scene(source: str | os.PathLike | dict | Scene, overrides: typing.Sequence[str] = ()) -> Scene:
    """Load and validate a preset name, a TOML path, a dict or a Scene, applying ``KEY=VALUE``
    overrides first. An error in a key an override set names the override, not the file."""
    if isinstance(overrides, (str, bytes)) or not isinstance(overrides, typing.Iterable):
        raise SceneError(f"overrides: expected a list of 'KEY=VALUE' strings, got {_show(overrides)}")
    if isinstance(source, Scene) and not overrides:
        return source  # checked when it was made
    if isinstance(source, Scene):
        table, origin = _table_of(source), source.source
    elif isinstance(source, dict):
        table, origin = copy.deepcopy(source), "<dict>"  # the overrides must not change the caller's dict
    elif isinstance(source, (str, os.PathLike)):
        path = resolve_path(source)
        table, origin = read_table(path), str(path)
    else:
        raise SceneError(f"{_show(source)}: expected a preset name, a TOML path, a dict or a pbf.Scene")
    overridden = {}
    for assignment in overrides:
        keys, value = parse_override(assignment)
        label = f"command line --set {echo(assignment)}"
        _set(table, keys, value, label)
        overridden[".".join(keys)] = label
    try:
        return from_dict(table, origin)
    except SceneError as error:
        raise attribute(error, overridden) from None


def attribute(error: SceneError, labels: dict[str, str]) -> SceneError:
    """``error`` said of the command line when its key (or a table holding it) is one ``labels``
    maps to a label (``{"solver.iterations": "command line --set solver.iterations=0"}``): the
    user typed that value, not the file. Otherwise ``error`` itself."""
    key = error.key
    label = next((label for dotted, label in labels.items()
                  if key is not None and re.match(re.escape(dotted) + r"($|[.\[])", key)), None)
    if label is None:
        return error
    message = str(error)
    start = message.find(f"key '{_clip(key)}'")
    start -= len("unknown ") if message[:start].endswith("unknown ") else 0
    return SceneError(f"{label}: {message[max(start, 0):]}", key)
