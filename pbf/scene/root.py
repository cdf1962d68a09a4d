"""The whole scene: one table of tables, each built and checked by its own module, then the checks
of what keys in different tables must agree on, in order."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pbf.scene.bodies import MAX_BODIES, Body, _check_bodies
from pbf.scene.emitters import Emitter, _check_emitter_room, _check_emitters
from pbf.scene.export import Export
from pbf.scene.fluid import Fluid
from pbf.scene.geometry import Container, Obstacle, _check_blocks, _check_container, _check_obstacles, block_counts
from pbf.scene.schema import SceneError, Vec3, _at_most_tables, _line, _show, _table_values, key
from pbf.scene.solver import Solver, Viscosity, Vorticity, _check_solver
from pbf.scene.timestep import Time, _check_settle, _check_time, travel_spacings
from pbf.scene.view import Camera, Render, Surface, WhiteWater, _check_camera
from pbf.scene.wave_maker import WaveMaker, _check_wave_maker

MAX_OBSTACLES = 100
"""Most [[obstacles]]: each is checked against every block and every obstacle before it."""


@dataclass(frozen=True)
class Scene:
    source: str = field(default="<Scene>", compare=False, metadata={"internal": True})
    """Where the scene came from (a file path, "<dict>" or "<Scene>"): error messages name it. Not a TOML key."""
    name: str = key("scene", _line(64), "short name")
    description: str = key("", _line(200), "one line shown by --list")
    gravity_m_s2: Vec3 = key((0.0, -9.81, 0.0), doc="gravitational acceleration, m/s² (y is up)")
    container: Container = key(Container())
    fluid: Fluid = key(Fluid())
    obstacles: tuple[Obstacle, ...] = key(
        (), _at_most_tables(MAX_OBSTACLES), "static boxes in the container ([[obstacles]] tables)"
    )
    emitters: tuple[Emitter, ...] = key(
        (), _at_most_tables(MAX_OBSTACLES), "nozzles that add water while the scene runs ([[emitters]] tables)"
    )
    bodies: tuple[Body, ...] = key(
        (), _at_most_tables(MAX_BODIES), "rigid boxes and spheres two-way coupled with the water ([[bodies]] tables)"
    )
    time: Time = key(Time())
    solver: Solver = key(Solver())
    viscosity: Viscosity = key(Viscosity())
    vorticity: Vorticity = key(Vorticity())
    wave_maker: WaveMaker = key(WaveMaker())
    camera: Camera = key(Camera())
    render: Render = key(Render())
    surface: Surface = key(Surface())
    white_water: WhiteWater = key(WhiteWater())
    export: Export = key(Export())

    def __post_init__(self):
        # Every value converted to its annotated type and checked, nested tables included, so a
        # Scene built by hand is held to the same rules as a file; then what keys must agree on.
        if not isinstance(self.source, str):
            raise SceneError(
                f"<Scene>: source: expected a string naming where the scene came from, got {_show(self.source)}"
            )
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

    def travel_per_substep_m(self, iterations: int | None = None) -> float:
        """The most a particle may travel in one substep of ``iterations`` Jacobi iterations (default:
        solver.iterations): time.max_cfl spacings, less under 4 iterations
        (``pbf.scene.timestep.travel_spacings``)."""
        iterations = self.solver.iterations if iterations is None else iterations
        return travel_spacings(self.time.max_cfl, iterations) * self.fluid.spacing_m

    @property
    def fastest_followed_m_s(self) -> float:
        """The fastest speed a frame's substeps can follow: time.max_substeps substeps of at most
        :meth:`travel_per_substep_m` each (``Simulation.substeps_needed``)."""
        t = self.time
        return t.max_substeps * self.travel_per_substep_m() / t.frame_dt_s

    @property
    def emitted_count(self) -> int:
        """Particles the emitters add over the whole run."""
        spacing = self.fluid.spacing_m
        return sum(e.layers(spacing) * e.sites_per_layer(spacing) for e in self.emitters)

    @property
    def particle_capacity(self) -> int:
        """Particles allocated at the start: fluid.max_particles, or the blocks' and emitters' total."""
        return self.fluid.max_particles or self.particle_count + self.emitted_count


def _check_scene(scene: Scene) -> None:
    source = scene.source
    _check_container(scene, source)
    _check_blocks(scene, source)
    _check_obstacles(scene, source)
    _check_wave_maker(scene, source)
    _check_emitters(scene, source)
    _check_time(scene, source)
    _check_emitter_room(scene, source)  # after the speeds: a stream too fast to follow is the first thing to say
    _check_bodies(scene, source)
    _check_solver(scene, source)
    _check_settle(scene, source)
    _check_camera(scene, source)
