"""pbf: real-time Position Based Fluids (Macklin & Müller 2013) in Taichi.

    >>> import pbf
    >>> sim = pbf.Simulation("dam_break")      # a preset name, a TOML path, a dict or a pbf.Scene
    >>> sim.step()

Three wings, by audience: ``pbf.solver`` (the physics), ``pbf.app`` (command line, window, headless
renderer, export) and ``pbf.study`` (benchmarks, sweeps, validation), around the scene schema
``pbf.scene``. ``Simulation`` is imported on first use, so that ``import pbf`` and the scene schema
load without Taichi.
"""

import importlib.util
import os
import sys

PYTHONS = "3.10-3.13"
"""The Pythons pbf runs on: those Taichi 1.7.4 (the version pbf pins) has wheels for, from 3.10."""
NEWEST_PYTHON = (3, 13)


def python_problem(version: tuple[int, int], taichi_installed: bool) -> str | None:
    """Why pbf cannot run on Python ``version``, or None. A newer Python with Taichi somehow installed
    (built from source) is let through: Taichi itself would then say what it lacks."""
    if version <= NEWEST_PYTHON or taichi_installed:
        return None
    shown = f"{version[0]}.{version[1]}"
    return (
        f"pbf runs on Python {PYTHONS}, not {shown}: Taichi 1.7.4 has no wheel for Python {shown}; "
        f"use {PYTHONS} (python3.13 -m venv .venv)"
    )


# Said at the first import, before anything else fails on the missing Taichi with a less useful line.
_problem = python_problem(sys.version_info[:2], importlib.util.find_spec("taichi") is not None)
if _problem:
    raise ImportError(_problem)

# Taichi prints a banner ("[Taichi] version 1.7.4, llvm …, commit …") when it is first imported,
# unless this variable says no (taichi/_lib/utils.py reads it once, at that import). Every way into
# the program (run.py, the pbf command, python -m pbf.study.*, the tests' conftest) imports this
# package before Taichi; the version is named in pbf's own "Starting on" line (pbf.solver.backend).
# An explicit ENABLE_TAICHI_HEADER_PRINT=1 still brings the banner back.
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

from pbf.scene import Scene, SceneError, load_scene  # noqa: E402 (after the Python check and Taichi's banner setting)

__all__ = ["Scene", "SceneError", "Simulation", "load_scene"]


def __getattr__(name):
    if name == "Simulation":
        from pbf.solver import Simulation

        return Simulation
    raise AttributeError(f"module 'pbf' has no attribute {name!r}")
