"""Settled starts (``time.settle_s``) kept in Taichi's offline cache folder, named by a hash of all they
depend on (:func:`settled_key`): settling is deterministic, so a start restores the file, bit for bit."""

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
from pbf.solver.buckets import cache_folder
from pbf.solver.state import Snapshot

FOLDER = "pbf_settled"
VIEW_KEYS = ("source", "name", "description", "camera", "render", "surface")
"""Scene fields that do not move a particle, left out of the key."""
CODE = ("solver", "scene")
"""The package folders whose code the settled state depends on."""


@functools.cache
def _code() -> str:
    """A hash of every ``.py`` file of the package folders in CODE, by path and content."""
    digest = hashlib.sha256()
    package = Path(__file__).resolve().parent.parent
    for folder in CODE:
        for path in sorted((package / folder).rglob("*.py")):
            digest.update(str(path.relative_to(package)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def settled_key(scene, choices: backend.Choices) -> str:
    """The hash naming ``scene``'s settled start: its physics, the code, the versions, the backend's options
    and ``choices``."""
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
        repr(choices.decisions_on_device),  # the device path's substep rounds differently
    ):
        digest.update(part.encode())
        digest.update(b"\0")
    return digest.hexdigest()[:32]


def load(scene, choices: backend.Choices) -> Snapshot | None:
    """``scene``'s settled start from disk, or None if none is kept (or the file cannot be read)."""
    folder = cache_folder(FOLDER)
    if folder is None:
        return None
    path = folder / f"{settled_key(scene, choices)}.npz"
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {name[len("field_") :]: data[name] for name in data.files if name.startswith("field_")}
            bodies = data["bodies"] if "bodies" in data.files else None
            return Snapshot(data["positions_m"], data["velocities_m_s"], 0.0, 0, (), None, fields, bodies)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # none kept, or cut short: settle
        return None


def store(scene, snapshot: Snapshot, choices: backend.Choices) -> None:
    """Keep ``snapshot`` (the settled start at t = 0) as ``scene``'s; a folder that cannot be written
    is skipped (the next start settles again)."""
    folder = cache_folder(FOLDER)
    if folder is None:
        return
    arrays = {"positions_m": snapshot.positions_m, "velocities_m_s": snapshot.velocities_m_s}
    arrays.update({f"field_{name}": values for name, values in snapshot.fields.items()})
    if snapshot.bodies is not None:
        arrays["bodies"] = snapshot.bodies
    try:
        folder.mkdir(parents=True, exist_ok=True)
        # Written under a temporary name and renamed: a start beside this one reads all or nothing.
        handle, temporary = tempfile.mkstemp(dir=folder, suffix=".tmp")
    except OSError:
        return
    try:
        with os.fdopen(handle, "wb") as file:
            np.savez(file, **arrays)
        os.replace(temporary, folder / f"{settled_key(scene, choices)}.npz")
    except OSError:
        Path(temporary).unlink(missing_ok=True)
