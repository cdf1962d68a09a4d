"""Settled starts kept on disk, beside Taichi's compiled kernels: a warm start skips settling.

A scene with ``time.settle_s`` steps its blocks for that long before t = 0 (``Simulation._settle``).
Settling is deterministic, so a start that finds its result on disk restores it instead; since
``restore(snapshot())`` is exact, a start from the file steps bit for bit as one that settled.

The file is named by a hash of everything the settled state depends on (:func:`settled_key`): the
scene's physics (every table but the view's: name, description, camera, render, surface), the
package's solver and scene code (every ``.py`` file of ``pbf/solver`` and ``pbf/scene``), Taichi's and
NumPy's versions, the backend's ``ti.init`` options and device (the compile mode rounds differently)
and whether the GPU backends' choices are taken (other rounding). A change to any of them names
another file; stale files are never read, only left behind.

The files live in ``pbf_settled/`` of Taichi's offline cache folder (``TI_OFFLINE_CACHE_FILE_PATH``),
only while the offline cache is on: an empty folder is a cold start in every respect.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from pbf.solver import backend
from pbf.solver.launch import compile_config
from pbf.solver.state import Snapshot

FOLDER = "pbf_settled"
"""The settled starts' folder inside Taichi's offline cache folder."""
VIEW_KEYS = ("source", "name", "description", "camera", "render", "surface")
"""Scene fields that do not move a particle: left out of the key, so a scene that differs only in
them shares its settled start."""
CODE = ("solver", "scene")
"""The package folders whose code the settled state depends on."""


@functools.cache
def _code() -> str:
    """A hash of every ``.py`` file of the package folders in CODE, by relative path and content (read once
    a process)."""
    digest = hashlib.sha256()
    package = Path(__file__).resolve().parent.parent
    for folder in CODE:
        for path in sorted((package / folder).rglob("*.py")):
            digest.update(str(path.relative_to(package)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def settled_key(scene) -> str:
    """The hash that names ``scene``'s settled start on this backend (module docstring)."""
    physics = {f.name: getattr(scene, f.name) for f in dataclasses.fields(scene) if f.name not in VIEW_KEYS}
    digest = hashlib.sha256()
    options = sorted((name, str(value)) for name, value in backend._options.items())  # str: a type's name
    for part in (
        repr(physics),
        _code(),
        backend.taichi_version(),
        np.__version__,  # the initial lattice is laid out in NumPy
        repr(options),
        repr(backend._started),
        repr(backend.keeps_decisions_on_device()),  # the device path's substep rounds differently
    ):
        digest.update(part.encode())
        digest.update(b"\0")
    return digest.hexdigest()[:32]


def _folder() -> Path | None:
    """Where settled starts are kept: None while Taichi's offline cache is off."""
    config = compile_config()
    if not config.offline_cache:
        return None
    return Path(config.offline_cache_file_path) / FOLDER


def load(scene) -> Snapshot | None:
    """``scene``'s settled start from disk, or None if none is kept (or the file cannot be read)."""
    folder = _folder()
    if folder is None:
        return None
    path = folder / f"{settled_key(scene)}.npz"
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {name[len("field_") :]: data[name] for name in data.files if name.startswith("field_")}
            bodies = data["bodies"] if "bodies" in data.files else None
            return Snapshot(data["positions_m"], data["velocities_m_s"], 0.0, 0, (), None, fields, bodies)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # none kept, or cut short: settle
        return None


def store(scene, snapshot: Snapshot) -> None:
    """Keep ``snapshot`` (the settled start at t = 0) as ``scene``'s; a folder that cannot be written
    is skipped (the next start settles again)."""
    folder = _folder()
    if folder is None:
        return
    arrays = {"positions_m": snapshot.positions_m, "velocities_m_s": snapshot.velocities_m_s}
    arrays.update({f"field_{name}": values for name, values in snapshot.fields.items()})
    if snapshot.bodies is not None:
        arrays["bodies"] = snapshot.bodies
    try:
        folder.mkdir(parents=True, exist_ok=True)
        # Written under a temporary name and renamed: a start that runs beside this one reads the
        # whole file or none.
        handle, temporary = tempfile.mkstemp(dir=folder, suffix=".tmp")
    except OSError:
        return
    try:
        with os.fdopen(handle, "wb") as file:
            np.savez(file, **arrays)
        os.replace(temporary, folder / f"{settled_key(scene)}.npz")
    except OSError:
        Path(temporary).unlink(missing_ok=True)
