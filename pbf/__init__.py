"""pbf: real-time Position Based Fluids (Macklin & Müller 2013) in Taichi.

    >>> import pbf
    >>> sim = pbf.Simulation("dam_break")      # a preset name, a TOML path, a dict or a pbf.Scene
    >>> sim.step()

Three wings, by audience: ``pbf.solver`` (the physics), ``pbf.app`` (command line, window, headless
renderer, export) and ``pbf.study`` (benchmarks, sweeps, validation), around the scene schema
``pbf.scene``. ``Simulation`` is imported on first use, so that ``import pbf`` and the scene schema
load without Taichi.
"""

import os

# Taichi prints a banner ("[Taichi] version 1.7.4, llvm …, commit …") when it is first imported,
# unless this variable says no (taichi/_lib/utils.py reads it once, at that import). Every way into
# the program (run.py, the pbf command, python -m pbf.study.*, the tests' conftest) imports this
# package before Taichi; the version is named in pbf's own "Starting on" line (pbf.solver.backend).
# An explicit ENABLE_TAICHI_HEADER_PRINT=1 still brings the banner back.
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

from pbf.scene import Scene, SceneError, load_scene

__all__ = ["Scene", "SceneError", "Simulation", "load_scene"]


def __getattr__(name):
    if name == "Simulation":
        from pbf.solver import Simulation

        return Simulation
    raise AttributeError(f"module 'pbf' has no attribute {name!r}")
