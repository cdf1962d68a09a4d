"""The scene schema: one validated place for everything a preset sets.

A scene is a TOML file (see ``scenes/``), a dict of the same shape or a :class:`Scene` built by hand.
Every way in ends in ``Scene.__post_init__``, so no scene that fails a check exists: each key's type,
its range (every number has a lower and an upper bound, derived from what the solver does with it)
and what keys must agree on (geometry, time step, camera) are checked before anything runs. A
failure raises :class:`SceneError`, whose one-line message names the source (the file, the command
line's ``--set`` or ``<dict>``), the key and what is allowed.

One module per table, each holding its dataclass beside the checks of its keys: ``geometry``
(container, blocks, obstacles), ``fluid``, ``emitters``, ``timestep``, ``solver`` (with XSPH and
vorticity), ``wave_maker``, ``bodies`` (rigid boxes and spheres), ``view`` (camera, render, surface: the
application's), ``export`` (the exported files' up axis and walls). ``schema`` is the
machinery they share, ``root`` the whole scene, ``files`` the TOML files and overrides, ``reference``
the key reference generated from the keys' own docs (``pbf --keys``, docs/KEYS.md).

This package imports nothing of the solver, the application or the studies: the values the solver
derives from a scene (particle mass, grid, the memory and index checks) are ``pbf.solver.model``'s.
"""

from pbf.scene.bodies import BODY_MAX_CFL, MAX_BODIES, MIN_BODY_SPACINGS, Body
from pbf.scene.emitters import Emitter
from pbf.scene.export import UP_AXES, Export
from pbf.scene.files import (
    COMMAND_LINE,
    MAX_SCENE_BYTES,
    SCENES_DIR,
    attribute,
    from_dict,
    load_scene,
    parse_override,
    read_table,
    resolve_path,
)
from pbf.scene.fluid import MAX_TABLES, Fluid
from pbf.scene.geometry import (
    MIN_OBSTACLE_SPACINGS,
    OBSTACLE_MAX_CFL,
    POSITION_REACH_SPACINGS,
    Block,
    Container,
    Obstacle,
    block_counts,
)
from pbf.scene.root import MAX_OBSTACLES, Scene
from pbf.scene.schema import FLOAT32_SAFE, SceneError, Vec3, echo
from pbf.scene.solver import CHEBYSHEV_RHO, MAX_ITERATIONS, MIN_ITERATIONS, Expert, Solver, Viscosity, Vorticity
from pbf.scene.timestep import Time
from pbf.scene.view import CAMERA_REACH_DIAGONALS, Camera, Render, Surface, WhiteWater, default_look_at_m
from pbf.scene.wave_maker import WaveMaker

__all__ = [
    "BODY_MAX_CFL",
    "COMMAND_LINE",
    "MAX_BODIES",
    "MIN_BODY_SPACINGS",
    "Body",
    "CAMERA_REACH_DIAGONALS",
    "CHEBYSHEV_RHO",
    "FLOAT32_SAFE",
    "MAX_ITERATIONS",
    "MAX_OBSTACLES",
    "MAX_SCENE_BYTES",
    "MAX_TABLES",
    "MIN_ITERATIONS",
    "MIN_OBSTACLE_SPACINGS",
    "OBSTACLE_MAX_CFL",
    "POSITION_REACH_SPACINGS",
    "SCENES_DIR",
    "Block",
    "Camera",
    "Container",
    "Emitter",
    "Expert",
    "Export",
    "Fluid",
    "Obstacle",
    "Render",
    "Scene",
    "SceneError",
    "Solver",
    "Surface",
    "WhiteWater",
    "Time",
    "UP_AXES",
    "Vec3",
    "Viscosity",
    "Vorticity",
    "WaveMaker",
    "attribute",
    "block_counts",
    "default_look_at_m",
    "echo",
    "from_dict",
    "load_scene",
    "parse_override",
    "read_table",
    "resolve_path",
]
