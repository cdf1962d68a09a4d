"""The fluid's free surface as a triangle mesh, reconstructed from the particles with splashsurf.

splashsurf (Löschner et al., pysplashsurf on PyPI) is the surface reconstruction SPlisHSPlasH users
mesh with: it interpolates the SPH colour field c(x) = Σ_j (m_j/ρ_j) W(x − x_j), about 1 inside the
fluid and 0 outside, on a sparse marching-cubes grid, takes the iso surface c = ``iso_level`` and
smooths it with the feature-weighted Laplacian of Löschner, Böttcher, Jeske & Bender 2023 ("Weighted
Laplacian smoothing for surface reconstruction of particle-based fluids"). The parameters come from
the scene's ``[surface]`` table in particle spacings. The mesh is written as binary PLY or as OBJ
(text: the format has no binary form) for Blender, Houdini or ParaView.

Why the kernel is narrow (0.8 spacings, support 1.6) and the walls are mirrored: the colour field is
normalised per particle (m_j/ρ_j), so every particle counts as inside however few neighbours it has,
and the iso surface wraps each one at the kernel's reach. A wide kernel wraps a splash's rough
surface, its one-particle sheets and its spray in an envelope well above the water's volume
(docs/BENCHMARKS.md, "Surfaces"); a narrow one follows the particles. It also reaches less far past
water against a wall, where clamping used to hide what smoothing takes, so the particles within a
kernel's reach of a wall are mirrored across it (as the solver's wall mirror does): the field is that
of water continuing through the wall, and the mesh meets the wall flat once clamped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pysplashsurf
from plyfile import PlyData, PlyElement

from pbf.scene import Scene
from pbf.solver import quaternion_matrix_np

MESH_FORMATS = ("ply", "obj")


@dataclass(frozen=True)
class Mesh:
    """A closed triangle mesh: vertices in metres, triangles as vertex indices, counter-clockwise
    seen from outside (normals point out of the water)."""

    vertices: np.ndarray
    """(n, 3) float32, m."""
    triangles: np.ndarray
    """(m, 3) int32 indices into ``vertices``."""

    def is_closed(self) -> bool:
        """Closed and consistently oriented: every directed edge appears once, and its reverse once
        (a watertight surface whose enclosed volume is meaningful)."""
        t = self.triangles.astype(np.int64)
        edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        keys = edges[:, 0] * len(self.vertices) + edges[:, 1]
        reverse = edges[:, 1] * len(self.vertices) + edges[:, 0]
        return len(np.unique(keys)) == len(keys) and bool(np.isin(reverse, keys).all())

    def enclosed_volume_m3(self) -> float:
        """Σ over triangles of (a · (b × c)) / 6: the signed volume the surface encloses (divergence
        theorem), exact for a closed mesh, positive when the normals point out."""
        a, b, c = (self.vertices[self.triangles[:, k]].astype(np.float64) for k in range(3))
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


class SurfaceError(RuntimeError):
    """splashsurf could not mesh a particle set, even at the nudged iso levels of ``ISO_NUDGES``; the
    message is one line: its reason, without the Rust backtrace."""


ISO_NUDGES = (0.0, 1e-6, -1e-6)
"""Relative changes of ``surface.iso_level`` tried in turn when splashsurf fails. Its one-grid
marching cubes (``deterministic``) counts a grid point whose colour value equals the iso level exactly
as inside when it places the surface's vertices on the edges, and as outside when it classifies the
cells' corners: where such a point has only inside neighbours in a cell, that cell's triangles ask for
a vertex that was never made ("Missing iso surface vertex at edge …. This is a bug."). A float32 tie is
rare, and where one falls depends on the positions' last bits, which differ from machine to machine.
Moving the level by a millionth breaks the tie, moves the surface by far less than a cube (the colour
field changes by about 1 across a spacing) and is itself deterministic. splashsurf's subdomains
(``deterministic = false``, where the particles are many enough for it to keep them) compare alike in
both places."""


def reconstruct(positions: np.ndarray, scene: Scene) -> Mesh:
    """The surface of the particles at ``positions`` ((n, 3) m) with the scene's ``[surface]``
    settings, its vertices clamped into the container. No particle gives an empty mesh; a single
    particle gives a small closed droplet. SurfaceError when splashsurf fails at every level of
    ``ISO_NUDGES``."""
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions: expected an (n, 3) array, got shape {positions.shape}")
    if len(positions) == 0:
        return Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    if not np.isfinite(positions).all():
        raise ValueError("positions: some particle positions are not finite; the simulation has blown up")
    settings = scene.surface
    support_m = 2.0 * settings.smoothing_length_spacings * scene.fluid.spacing_m
    lower, upper = scene.container.min_m, scene.container.max_m
    particles = with_wall_images(positions, lower, upper, support_m)
    reasons = []
    for nudge in ISO_NUDGES:
        try:
            surface = _splashsurf(particles, scene, settings.iso_level * (1.0 + nudge))
            break
        except Exception as error:  # pysplashsurf raises RuntimeError with its Rust error chain
            reasons.append(_reason(error))
    else:
        tried = ", ".join(f"{settings.iso_level * (1.0 + nudge):.7g}" for nudge in ISO_NUDGES)
        raise SurfaceError(f"splashsurf failed at surface.iso_level {tried}: {reasons[0]}")
    vertices = surface.mesh.vertices
    # The water's wall images carry the surface through the walls. Clamping moves the vertices beyond
    # a wall onto it and keeps every triangle (those wholly outside become slivers on the wall), so
    # the mesh stays closed and meets the wall flat.
    vertices = np.clip(vertices, lower, upper).astype(np.float32)
    return Mesh(vertices, surface.mesh.triangles.astype(np.int32))


def _splashsurf(particles: np.ndarray, scene: Scene, iso_level: float):
    settings = scene.surface
    # pysplashsurf takes lengths in multiples of the particle radius it is given. The colour field
    # does not depend on the particles' mass (m_j/ρ_j = 1/Σ_k W_jk), so passing the spacing as the
    # "radius" makes the table's values in spacings the arguments as they stand.
    surface, _ = pysplashsurf.reconstruction_pipeline(
        particles,
        particle_radius=scene.fluid.spacing_m,
        rest_density=scene.fluid.rest_density_kg_m3,
        smoothing_length=settings.smoothing_length_spacings,
        cube_size=settings.cube_size_spacings,
        iso_surface_threshold=iso_level,
        mesh_smoothing_iters=settings.smoothing_iterations or None,
        mesh_smoothing_weights=True,
        mesh_smoothing_weights_normalization=smoothing_weight_normalization(settings.smoothing_length_spacings),
        # splashsurf's parallel subdomains stitch in a varying order: the mesh differs from run to
        # run (vertex order and the last bits of positions). One thread on one global grid does not.
        multi_threading=not settings.deterministic,
        subdomain_grid=not settings.deterministic,
    )
    return surface


def _reason(error: Exception) -> str:
    """splashsurf's error in one line: its innermost cause ("Missing iso surface vertex at edge 9. This
    is a bug."), without the chain's other lines and the Rust backtrace it appends."""
    text = str(error).split("Stack backtrace:", 1)[0]
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    causes = [line.split(":", 1)[1].strip() for line in lines if line.split(":", 1)[0].isdigit()]
    return (causes[-1] if causes else lines[0] if lines else type(error).__name__)[:200]


SMOOTHING_WEIGHT_NEIGHBOURS = 3.0
"""Löschner et al.'s smoothing weight of a vertex is its weighted count of nearby particles over this
normalisation, at most 1: where the water is thinner the mesh is smoothed less, so that droplets keep
their size. splashsurf's default, 13, is for wider kernels; with 0.8 spacings it spares so much of a
surface that a ball of particles meshes with bumps of 0.17 spacing (its radius's standard deviation;
0.13 at 6.7), and 3 brings them under 0.1 spacing (``tests/test_mesh.py``). It scales with the
kernel's volume, like the count it normalises."""

SMOOTHING_WEIGHT_LENGTH_SPACINGS = 0.8
"""The smoothing length at which ``SMOOTHING_WEIGHT_NEIGHBOURS`` holds."""


def smoothing_weight_normalization(smoothing_length_spacings: float) -> float:
    """The count of neighbours at which a vertex is smoothed fully, scaled to the kernel's volume."""
    return SMOOTHING_WEIGHT_NEIGHBOURS * (smoothing_length_spacings / SMOOTHING_WEIGHT_LENGTH_SPACINGS) ** 3


def with_wall_images(positions: np.ndarray, lower, upper, reach_m: float) -> np.ndarray:
    """``positions`` followed by their mirror images across each container wall they are within
    ``reach_m`` of (one axis after the other, so that a particle in a corner has its images across
    both walls and the corner itself): the colour field inside the container is then that of water
    continuing through the walls. Deterministic: the images follow in a fixed order."""
    points = positions
    for axis in range(3):
        images = [points]
        for wall, inward in ((lower[axis], 1.0), (upper[axis], -1.0)):
            near = points[inward * (points[:, axis] - wall) < reach_m]
            mirrored = near.copy()
            mirrored[:, axis] = 2.0 * wall - near[:, axis]
            images.append(mirrored)
        points = np.concatenate(images)
    return np.ascontiguousarray(points, dtype=np.float32)


BODY_SPHERE_RINGS = 12
"""Latitude rings of a sphere body's mesh (twice as many meridians)."""


def body_mesh(shapes, half_extents_m, states) -> Mesh:
    """The rigid bodies' surfaces as one closed triangle mesh (outward normals): a box's 12 triangles,
    a sphere's latitude–longitude grid, each placed at its pose (``Simulation.body_states``' rows)."""
    vertices, triangles = [], []
    for shape, half, row in zip(shapes, half_extents_m, states):
        local, faces = _box_mesh(np.asarray(half)) if shape == "box" else _sphere_mesh(float(half[0]))
        rotation = quaternion_matrix_np(row[3:7])
        triangles.append(faces + sum(len(v) for v in vertices))
        vertices.append(local @ rotation.T + row[0:3])
    if not vertices:
        return Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    return Mesh(np.concatenate(vertices).astype(np.float32), np.concatenate(triangles).astype(np.int32))


def _box_mesh(half: np.ndarray):
    corners = np.array([[(-1, 1)[k >> a & 1] * half[a] for a in range(3)] for k in range(8)], np.float64)
    # Two triangles per face, counter-clockwise seen from outside (corner k has bit a set for +half on axis a).
    faces = np.array(
        [
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ],
        np.int32,
    )
    return corners, faces


def _sphere_mesh(radius: float):
    rings, sectors = BODY_SPHERE_RINGS, 2 * BODY_SPHERE_RINGS
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, sectors, endpoint=False)
    ring = np.stack(
        [
            np.outer(np.sin(theta), np.cos(phi)),
            np.repeat(np.cos(theta)[:, None], sectors, 1),
            np.outer(np.sin(theta), np.sin(phi)),
        ],
        axis=-1,
    ).reshape(-1, 3)
    points = np.concatenate([[[0, 1, 0]], ring, [[0, -1, 0]]]) * radius
    top, bottom = 0, len(points) - 1
    faces = []
    for s in range(sectors):
        t = (s + 1) % sectors
        faces.append([top, 1 + t, 1 + s])
        for r in range(rings - 2):
            a, b = 1 + r * sectors, 1 + (r + 1) * sectors
            faces += [[a + s, a + t, b + s], [a + t, b + t, b + s]]
        last = 1 + (rings - 2) * sectors
        faces.append([bottom, last + s, last + t])
    return points, np.array(faces, np.int32)


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
