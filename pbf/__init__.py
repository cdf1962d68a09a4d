"""pbf: real-time Position Based Fluids (Macklin & Müller 2013) in Taichi.

    >>> import pbf
    >>> sim = pbf.Simulation("dam_break")      # a preset name, a TOML path, a dict or a pbf.Scene
    >>> sim.step()

Three wings, by audience: ``pbf.solver`` (the physics), ``pbf.app`` (command line, window, headless
renderer, export) and ``pbf.study`` (benchmarks, sweeps, validation), around the scene schema
``pbf.scene``. ``Simulation`` is imported on first use, so that ``import pbf`` and the scene schema
load without Taichi.
"""
from pbf.scene import Scene, SceneError, load_scene

__all__ = ["Scene", "SceneError", "Simulation", "load_scene"]


def __getattr__(name):
    if name == "Simulation":
        from pbf.solver import Simulation

        return Simulation
    raise AttributeError(f"module 'pbf' has no attribute {name!r}")
