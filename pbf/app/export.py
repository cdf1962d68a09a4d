"""Particle data for other tools: binary PLY (Blender, Houdini, ParaView) or NumPy .npz, one file per frame."""

from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement

FORMATS = ("ply", "npz")
"""Particle file formats."""
EXPORTS = FORMATS + ("mesh",)
"""What ``--export`` takes: a particle format, or ``mesh``, the fluid's surface (``pbf.app.mesh``,
in the format of the scene's ``surface.mesh_format``)."""


def write_particles(
    path: Path, positions: np.ndarray, velocities: np.ndarray, time_s: float, extra: dict | None = None
) -> Path:
    """Write positions (m) and velocities (m/s) to ``path`` with the suffix of its format; returns the path.
    ``extra``: more per-particle columns by name (white water's ``kind`` and ``age_s``)."""
    extra = extra or {}
    if path.suffix == ".ply":
        columns = [(name, "<f4") for name in ("x", "y", "z", "vx", "vy", "vz")]
        columns += [(name, "<i4" if np.issubdtype(v.dtype, np.integer) else "<f4") for name, v in extra.items()]
        vertices = np.empty(len(positions), dtype=columns)
        for k, axis in enumerate("xyz"):
            vertices[axis] = positions[:, k]
            vertices["v" + axis] = velocities[:, k]
        for name, values in extra.items():
            vertices[name] = values
        element = PlyElement.describe(vertices, "vertex")
        PlyData([element], comments=[f"pbf frame at t = {time_s:.6f} s; units m and m/s"]).write(str(path))
    elif path.suffix == ".npz":
        np.savez_compressed(path, positions_m=positions, velocities_m_s=velocities, time_s=np.float64(time_s), **extra)
    else:
        raise ValueError(f"{path}: unknown particle format; allowed: {', '.join(FORMATS)}")
    return path
