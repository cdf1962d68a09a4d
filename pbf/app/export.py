"""Particle data for other tools: binary PLY (Blender, Houdini, ParaView) or NumPy .npz, one file per
frame; the axes every exported point set is written in (``export.up_axis``); and ``run.json``, what
a run's files are (frame rate, camera, container) for the Blender script (``pbf/app/blender_load.py``)."""

import json
from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement

FORMATS = ("ply", "npz")
"""Particle file formats."""
EXPORTS = FORMATS + ("mesh",)
"""What ``--export`` takes: a particle format, or ``mesh``, the fluid's surface (``pbf.app.mesh``,
in the format of the scene's ``surface.mesh_format``)."""

Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""The simulation's y-up axes to Blender's z-up: (x, y, z) → (x, −z, y), a quarter turn about x (a
rotation, determinant 1: the meshes' winding stays outward). The simulation's front (+z, where the
default camera stands) becomes Blender's −y, the side Blender's front view looks from."""

RUN_INFO = "run.json"
"""What a run with ``--export`` writes beside its files for the Blender script."""


def to_export_axes(vectors: np.ndarray, up_axis: str) -> np.ndarray:
    """Points or vectors ((n, 3) or (3,), the simulation's y-up axes) in the axes of the exported
    files (``export.up_axis``: ``"z"`` rotates them by ``Z_UP``, ``"y"`` keeps them), float32. Every
    exported point set (particles, meshes, the camera in ``run.json``) goes through here."""
    vectors = np.asarray(vectors, dtype=np.float32)
    if up_axis == "y":
        return vectors.copy()
    if up_axis == "z":
        return (vectors @ Z_UP.T.astype(np.float32)).astype(np.float32)
    raise ValueError(f"up_axis: expected 'z' or 'y', got {up_axis!r}")


def write_particles(
    path: Path,
    positions: np.ndarray,
    velocities: np.ndarray,
    time_s: float,
    up_axis: str = "y",
    extra: dict | None = None,
) -> Path:
    """Write positions (m), velocities (m/s) and speeds (m/s) to ``path`` with the suffix of its
    format, in the axes of ``up_axis``; returns the path. The PLY's vertex properties are x, y, z, vx,
    vy, vz and speed (float32), then ``extra``'s per-particle columns by name (white water's ``kind`` and
    ``age_s``); the npz holds ``positions_m``, ``velocities_m_s``, ``speeds_m_s``, ``time_s``, ``up_axis``
    and ``extra``'s arrays."""
    extra = extra or {}
    positions = to_export_axes(positions, up_axis)
    velocities = to_export_axes(velocities, up_axis)
    speeds = np.linalg.norm(velocities, axis=1).astype(np.float32)
    if path.suffix == ".ply":
        columns = [(name, "<f4") for name in ("x", "y", "z", "vx", "vy", "vz", "speed")]
        columns += [(name, "<i4" if np.issubdtype(v.dtype, np.integer) else "<f4") for name, v in extra.items()]
        vertices = np.empty(len(positions), dtype=columns)
        for k, axis in enumerate("xyz"):
            vertices[axis] = positions[:, k]
            vertices["v" + axis] = velocities[:, k]
        vertices["speed"] = speeds
        for name, values in extra.items():
            vertices[name] = values
        element = PlyElement.describe(vertices, "vertex")
        comment = f"pbf frame at t = {time_s:.6f} s; units m and m/s; {up_axis} up"
        PlyData([element], comments=[comment]).write(str(path))
    elif path.suffix == ".npz":
        np.savez_compressed(
            path,
            positions_m=positions,
            velocities_m_s=velocities,
            speeds_m_s=speeds,
            time_s=np.float64(time_s),
            up_axis=np.str_(up_axis),
            **extra,
        )
    else:
        raise ValueError(f"{path}: unknown particle format; allowed: {', '.join(FORMATS)}")
    return path


def run_info(
    scene, eye_m, look_at_m, fov_deg: float, frames: int, exports, mesh_format: str, diffuse: str | None = None
) -> dict:
    """What the Blender script needs to know of a run, in the exported files' axes: the frame rate
    and count, the camera, the container, the up axis and which files there are (``diffuse``: the
    format of white water's files, None without them)."""
    up = scene.export.up_axis
    corners = to_export_axes(np.array([scene.container.min_m, scene.container.max_m]), up)

    def listed(vector):
        return [round(float(c), 6) for c in vector]

    return {
        "scene": scene.name,
        "up_axis": up,
        "frame_rate_hz": round(1.0 / scene.time.frame_dt_s, 6),
        "frames": frames + 1,
        "camera": {
            "position_m": listed(to_export_axes(eye_m, up)),
            "look_at_m": listed(to_export_axes(look_at_m, up)),
            "fov_deg": float(fov_deg),
            "width_px": scene.render.width_px,
            "height_px": scene.render.height_px,
        },
        "container": {"min_m": listed(corners.min(axis=0)), "max_m": listed(corners.max(axis=0))},
        "wall_faces": scene.export.wall_faces,
        "particles": next((name for name in exports if name in FORMATS), None),
        "surface": mesh_format if "mesh" in exports else None,
        "diffuse": diffuse,
        "spacing_m": scene.fluid.spacing_m,
        "absorption_per_m": listed(scene.surface.absorption_per_m),
        "water_rgb": listed(scene.surface.water_rgb),
    }


def write_run_info(folder: Path, info: dict) -> Path:
    path = folder / RUN_INFO
    path.write_text(json.dumps(info, indent=1) + "\n")
    return path
