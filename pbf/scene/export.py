"""The ``[export]`` table: how ``--export`` files are laid out for the tools that read them (the up
axis, the surface mesh's faces on the walls). The simulation itself is y-up; this changes the files
only."""

from __future__ import annotations

from dataclasses import dataclass

from pbf.scene.schema import _one_of, key

UP_AXES = ("z", "y")
"""What ``export.up_axis`` takes: z (Blender's convention) or y (the simulation's, ParaView's and
Houdini's)."""


@dataclass(frozen=True)
class Export:
    """Exported particles and meshes (``--export ply|npz|mesh``), in metres and m/s."""

    up_axis: str = key(
        "z",
        _one_of(*UP_AXES),
        "up axis of exported particles and meshes: z (Blender; a file's (x, y, z) is the simulation's "
        "(x, −z, y)) or y (as simulated; ParaView, Houdini)",
    )
    wall_faces: bool = key(
        True,
        doc="surface meshes close the water with faces lying on the container's walls; false leaves them "
        "open (water rendered inside a glass tank, whose walls are its own)",
    )
