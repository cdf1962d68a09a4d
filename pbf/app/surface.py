"""The fluid's free surface as a triangle mesh, reconstructed from the particles with splashsurf.

splashsurf (Löschner et al., pysplashsurf on PyPI) is the surface reconstruction SPlisHSPlasH users
mesh with: it interpolates the SPH colour field c(x) = Σ_j (m_j/ρ_j) W(x − x_j), about 1 inside the
fluid and 0 outside, on a sparse marching-cubes grid, takes the iso surface c = ``iso_level`` and
smooths it with the feature-weighted Laplacian of Löschner, Böttcher, Jeske & Bender 2023 ("Weighted
Laplacian smoothing for surface reconstruction of particle-based fluids"). The parameters come from
the scene's ``[surface]`` table in particle spacings. The mesh is written as binary PLY or as OBJ
(text: the format has no binary form) for Blender, Houdini or ParaView.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pysplashsurf
from plyfile import PlyData, PlyElement

from pbf.scene import Scene

MESH_FORMATS = ("ply", "obj")


@dataclass(frozen=True)
class Mesh:
    """A closed triangle mesh: vertices in metres, triangles as vertex indices, counter-clockwise
    seen from outside (normals point out of the water)."""

    vertices: np.ndarray
    """(n, 3) float32, m."""
    triangles: np.ndarray
    """(m, 3) int32 indices into ``vertices``."""

    def enclosed_volume_m3(self) -> float:
        """Σ over triangles of (a · (b × c)) / 6: the signed volume the surface encloses (divergence
        theorem), exact for a closed mesh, positive when the normals point out."""
        a, b, c = (self.vertices[self.triangles[:, k]].astype(np.float64) for k in range(3))
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def reconstruct(positions: np.ndarray, scene: Scene) -> Mesh:
    """The surface of the particles at ``positions`` ((n, 3) m) with the scene's ``[surface]``
    settings, its vertices clamped into the container. No particle gives an empty mesh; a single
    particle gives a small closed droplet."""
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions: expected an (n, 3) array, got shape {positions.shape}")
    if len(positions) == 0:
        return Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    if not np.isfinite(positions).all():
        raise ValueError("positions: some particle positions are not finite; the simulation has blown up")
    settings = scene.surface
    # pysplashsurf takes lengths in multiples of the particle radius it is given. The colour field
    # does not depend on the particles' mass (m_j/ρ_j = 1/Σ_k W_jk), so passing the spacing as the
    # "radius" makes the table's values in spacings the arguments as they stand.
    surface, _ = pysplashsurf.reconstruction_pipeline(
        positions,
        particle_radius=scene.fluid.spacing_m,
        rest_density=scene.fluid.rest_density_kg_m3,
        smoothing_length=settings.smoothing_length_spacings,
        cube_size=settings.cube_size_spacings,
        iso_surface_threshold=settings.iso_level,
        mesh_smoothing_iters=settings.smoothing_iterations or None,
        mesh_smoothing_weights=True,
        # splashsurf's parallel subdomains stitch in a varying order: the mesh differs from run to
        # run (vertex order and the last bits of positions). One thread on one global grid does not.
        multi_threading=not settings.deterministic,
        subdomain_grid=not settings.deterministic,
    )
    vertices = surface.mesh.vertices
    # The colour field reaches a little past the outermost particles, so water at rest against a wall
    # would poke through it by about 0.1 spacing. Clamping moves those vertices onto the wall and
    # keeps every triangle, so the mesh stays closed.
    vertices = np.clip(vertices, scene.container.min_m, scene.container.max_m).astype(np.float32)
    return Mesh(vertices, surface.mesh.triangles.astype(np.int32))


def write_mesh(path: Path, mesh: Mesh, time_s: float) -> Path:
    """Write ``mesh`` to ``path`` as binary PLY (``.ply``) or OBJ (``.obj``); returns the path."""
    comment = f"pbf fluid surface at t = {time_s:.6f} s; units m"
    if path.suffix == ".ply":
        vertices = np.empty(len(mesh.vertices), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
        for k, axis in enumerate("xyz"):
            vertices[axis] = mesh.vertices[:, k]
        faces = np.empty(len(mesh.triangles), dtype=[("vertex_indices", "<i4", (3,))])
        faces["vertex_indices"] = mesh.triangles
        elements = [PlyElement.describe(vertices, "vertex"), PlyElement.describe(faces, "face")]
        PlyData(elements, comments=[comment]).write(str(path))
    elif path.suffix == ".obj":
        with open(path, "w") as obj:
            obj.write(f"# {comment}\n")
            np.savetxt(obj, mesh.vertices, fmt="v %.6f %.6f %.6f")
            np.savetxt(obj, mesh.triangles + 1, fmt="f %d %d %d")  # OBJ counts vertices from 1
    else:
        raise ValueError(f"{path}: unknown mesh format; allowed: {', '.join(MESH_FORMATS)}")
    return path
