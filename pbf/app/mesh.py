"""The fluid's free surface as a triangle mesh, reconstructed from the particles with splashsurf.

splashsurf (Löschner et al., pysplashsurf on PyPI) is the surface reconstruction SPlisHSPlasH users
mesh with: it interpolates the SPH colour field c(x) = Σ_j (m_j/ρ_j) W(x − x_j), about 1 inside the
fluid and 0 outside, on a sparse marching-cubes grid, takes the iso surface c = ``iso_level`` and
smooths it with the feature-weighted Laplacian of Löschner, Böttcher, Jeske & Bender 2023 ("Weighted
Laplacian smoothing for surface reconstruction of particle-based fluids"). The parameters come from
the scene's ``[surface]`` table in particle spacings. The mesh is written as binary PLY or as OBJ
(text: the format has no binary form) for Blender, Houdini or ParaView.

Why the kernel is narrow (0.8 spacings, support 1.6) and the walls have images: the colour field is
normalised per particle (m_j/ρ_j), so every particle counts as inside however few neighbours it has,
and the iso surface wraps each one at the kernel's reach. A wide kernel wraps a splash's rough
surface, its one-particle sheets and its spray in an envelope well above the water's volume
(docs/BENCHMARKS.md, "Surfaces"); a narrow one follows the particles. It also reaches less far past
water against a wall, where clamping used to hide what smoothing takes, so each particle within a
kernel's reach of a wall has an image on the wall's plane: the field stays high up to the wall, and
the mesh meets the wall flat once clamped. On the plane, not mirrored across it: beyond the wall every
particle and image then lies behind, so the field falls monotonically outward and the surface there is
a height field over the wall, which clamping lays on the wall as one layer. Mirrored images continue
the water's shape through the wall, overhangs included, and clamping folded those onto the wall in
several layers facing both ways (Cycles renders such coincident faces as black patches; Blender's
"Recalculate Outside" flips them), with triangles seen edge-on left of no area.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pysplashsurf
from plyfile import PlyData, PlyElement

from pbf.app.export import to_export_axes
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
    velocities: np.ndarray | None = None
    """(n, 3) float32, m/s: the particles' velocity interpolated at each vertex (splashsurf's SPH
    interpolation, normalised), or None when the mesh was made without it."""

    def speeds(self) -> np.ndarray | None:
        """|velocity| at each vertex, m/s (float32), or None."""
        return None if self.velocities is None else np.linalg.norm(self.velocities, axis=1).astype(np.float32)

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


def reconstruct(positions: np.ndarray, scene: Scene, velocities: np.ndarray | None = None) -> Mesh:
    """The surface of the particles at ``positions`` ((n, 3) m) with the scene's ``[surface]``
    settings, its vertices clamped into the container and the mesh cleaned (``clean``: no zero-area
    triangles, no duplicate vertices, no flat pieces; the faces on the walls left open where
    ``export.wall_faces`` is false). With ``velocities`` ((n, 3) m/s) the mesh carries them
    interpolated at its vertices. No particle gives an empty mesh; a single particle gives a small
    closed droplet. SurfaceError when splashsurf fails at every level of ``ISO_NUDGES``."""
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions: expected an (n, 3) array, got shape {positions.shape}")
    if velocities is not None:
        velocities = np.ascontiguousarray(velocities, dtype=np.float32)
        if velocities.shape != positions.shape:
            raise ValueError(f"velocities: expected shape {positions.shape} like the positions, got {velocities.shape}")
    if len(positions) == 0:
        empty = np.zeros((0, 3), np.float32)
        return Mesh(empty, np.zeros((0, 3), np.int32), None if velocities is None else empty)
    if not np.isfinite(positions).all():
        raise ValueError("positions: some particle positions are not finite; the simulation has blown up")
    settings = scene.surface
    support_m = 2.0 * settings.smoothing_length_spacings * scene.fluid.spacing_m
    lower, upper = scene.container.min_m, scene.container.max_m
    particles, images = with_wall_images(positions, lower, upper, support_m, velocities)
    reasons = []
    for nudge in ISO_NUDGES:
        try:
            surface = _splashsurf(particles, scene, settings.iso_level * (1.0 + nudge), images)
            break
        except Exception as error:  # pysplashsurf raises RuntimeError with its Rust error chain
            reasons.append(_reason(error))
    else:
        tried = ", ".join(f"{settings.iso_level * (1.0 + nudge):.7g}" for nudge in ISO_NUDGES)
        raise SurfaceError(f"splashsurf failed at surface.iso_level {tried}: {reasons[0]}")
    vertices = surface.mesh.vertices
    # The water's wall images carry the surface through the walls. Clamping moves the vertices beyond
    # a wall onto it and keeps every triangle (those wholly outside become the cap on the wall), so
    # the mesh stays closed and meets the wall flat; ``clean`` then removes what clamping flattens to
    # nothing.
    vertices = np.clip(vertices, lower, upper).astype(np.float32)
    interpolated = None
    if velocities is not None:
        interpolated = np.asarray(surface.point_attributes["velocity"], dtype=np.float32).reshape(-1, 3)
    raw = Mesh(vertices, surface.mesh.triangles.astype(np.int32), interpolated)
    return clean(raw, lower, upper, wall_faces=scene.export.wall_faces, spacing_m=scene.fluid.spacing_m)


SLIVER_HEIGHT = 1e-6
"""A triangle whose height over its longest edge is below this fraction of that edge has no area to
speak of (float32 rounding of a flat triangle): ``clean`` removes it."""

FLAT_VOLUME = 1e-6
"""A piece of the mesh that encloses less than this fraction of (its area)^(3/2) is flat: clamped
wholly onto a wall."""

SPECK_AREA_SPACINGS2 = 0.01
"""A piece of the mesh smaller than this, in square spacings, is a speck: marching cubes and smoothing
collapsed to a point (micrometres across, where a particle's images meet in a corner), not water. A
drop of one particle meshes with an area of about 3 square spacings."""

SPECK_VOLUME_SPACINGS3 = 1e-3
"""A piece enclosing less than this, in cubic spacings (either way round: a bubble's surface faces
in), is a speck too; a drop of one particle holds about half a cubic spacing."""


def clean(mesh: Mesh, lower, upper, wall_faces: bool = True, spacing_m: float = 0.0) -> Mesh:
    """``mesh`` (its vertices clamped into the box ``lower``–``upper``) without what clamping leaves
    behind: the triangles of water imaged beyond a wall fall onto the wall plane, where those seen
    edge-on become triangles of no area and where vertices clamped to the same point stay unmerged,
    and the images of drops that never reach the wall become flat pieces of no volume. Cleaned: the
    vertices at one position are merged (the first's velocity kept), the triangles left with a repeated
    vertex dropped (their neighbours meet), the slivers removed by splitting the neighbour across their
    longest edge at the vertex lying on it (the surface stays closed), and the flat pieces and the
    specks (``SPECK_AREA_SPACINGS2``, ``SPECK_VOLUME_SPACINGS3`` of ``spacing_m``) dropped. With
    ``wall_faces`` false, the triangles lying on a wall are dropped first: the mesh is open there."""
    vertices, triangles = mesh.vertices, mesh.triangles.astype(np.int64)
    if not wall_faces:
        on_wall = np.zeros(len(triangles), bool)
        for axis in range(3):
            for wall in (lower[axis], upper[axis]):
                on_wall |= (vertices[:, axis] == np.float32(wall))[triangles].all(axis=1)
        triangles = triangles[~on_wall]
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    triangles = inverse.reshape(-1)[triangles]
    vertices = vertices[first]
    velocities = None if mesh.velocities is None else mesh.velocities[first]
    triangles = triangles[
        (triangles[:, 0] != triangles[:, 1])
        & (triangles[:, 1] != triangles[:, 2])
        & (triangles[:, 2] != triangles[:, 0])
    ]
    triangles = _split_slivers(vertices, triangles)
    triangles = _without_flat_pieces(vertices, triangles, spacing_m)
    used = np.unique(triangles)
    index = np.full(len(vertices), -1, np.int64)
    index[used] = np.arange(len(used))
    return Mesh(
        vertices[used],
        index[triangles].astype(np.int32).reshape(-1, 3),
        None if velocities is None else velocities[used],
    )


def sliver_mask(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Which triangles have no area to speak of (``SLIVER_HEIGHT``)."""
    a, b, c = (vertices[triangles[:, k]].astype(np.float64) for k in range(3))
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max(
        [np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1)], axis=0
    )
    return twice_area <= SLIVER_HEIGHT * longest**2


def _split_slivers(vertices: np.ndarray, triangles: np.ndarray, passes: int = 8) -> np.ndarray:
    """Triangles (i, j, k) of no area, k on the edge i–j: the neighbour (j, i, d) becomes (j, k, d)
    and (k, i, d), which take the sliver's edges j→k and k→i, and the sliver goes; the directed edges
    still pair up. Splits can make slivers of their own (d on the line too): a few passes. A sliver
    whose split would join k and d twice stays (rare): dropping it would open the surface. Only the
    triangles that touch a sliver's vertices are looked at (its neighbours, and any edge k–d, are
    among them)."""
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    points = vertices.astype(np.float64)
    for _ in range(passes):
        bad = np.flatnonzero(sliver_mask(vertices, triangles))
        if not len(bad):
            break
        near = np.flatnonzero(np.isin(triangles, np.unique(triangles[bad])).any(axis=1))
        rows = {int(f): tuple(triangles[f].tolist()) for f in near}
        owner = {}
        for f, (a, b, c) in rows.items():
            owner[(a, b)] = owner[(b, c)] = owner[(c, a)] = f
        dead, added = set(), []
        for f in bad.tolist():
            if f in dead:
                continue
            a, b, c = rows[f]
            # the longest edge i→j, with k opposite it
            lengths = [np.sum((points[b] - points[a]) ** 2), np.sum((points[c] - points[b]) ** 2)]
            lengths.append(np.sum((points[a] - points[c]) ** 2))
            i, j, k = ((a, b, c), (b, c, a), (c, a, b))[int(np.argmax(lengths))]
            g = owner.get((j, i))
            if g is None or g in dead:  # an open edge (walls left open): the sliver just goes
                dead.add(f)
                for edge in ((i, j), (j, k), (k, i)):
                    if owner.get(edge) == f:
                        del owner[edge]
                continue
            d = next(v for v in rows[g] if v not in (i, j))
            if d == k:  # the sliver's twin, the same three vertices the other way round: both go
                dead.update((f, g))
                for edge, who in (((i, j), f), ((j, k), f), ((k, i), f), ((j, i), g), ((i, k), g), ((k, j), g)):
                    if owner.get(edge) == who:
                        del owner[edge]
                continue
            if (k, d) in owner or (d, k) in owner:  # k and d already joined: a split would double that edge
                continue
            dead.add(f)
            for edge in ((i, j), (j, k), (k, i)):
                if owner.get(edge) == f:
                    del owner[edge]
            new = len(triangles) + len(added)
            rows[g], rows[new] = (j, k, d), (k, i, d)
            added.append(new)
            owner.pop((j, i), None)
            owner[(j, k)] = owner[(k, d)] = owner[(d, j)] = g
            owner[(k, i)] = owner[(i, d)] = owner[(d, k)] = new
        extra = np.array([rows[n] for n in added], np.int64).reshape(-1, 3)
        triangles = np.concatenate([triangles, extra])
        for f in near.tolist():
            triangles[f] = rows[f]
        keep = np.ones(len(triangles), bool)
        keep[list(dead)] = False
        triangles = triangles[keep]
    return triangles


def pieces(vertex_count: int, triangles: np.ndarray) -> np.ndarray:
    """The connected piece of each vertex (its lowest vertex index), by the triangles' edges."""
    label = np.arange(vertex_count)
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]]])
    while True:
        a, b = label[edges[:, 0]], label[edges[:, 1]]
        joined = label.copy()
        np.minimum.at(joined, a, np.minimum(a, b))
        np.minimum.at(joined, b, np.minimum(a, b))
        while True:  # pointer jumping: each label to its label's label until none moves
            jumped = joined[joined]
            if (jumped == joined).all():
                break
            joined = jumped
        if (joined == label).all():
            return label
        label = joined


def _piece_measures(vertices: np.ndarray, triangles: np.ndarray):
    """Each triangle's piece (0, 1, …), and each piece's area and enclosed volume."""
    label = pieces(len(vertices), triangles)
    _, piece = np.unique(label[triangles[:, 0]], return_inverse=True)
    piece = piece.reshape(-1)
    a, b, c = (vertices[triangles[:, k]].astype(np.float64) for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    return piece, np.bincount(piece, weights=area), np.bincount(piece, weights=volume)


def _specks(area: np.ndarray, volume: np.ndarray, spacing_m: float) -> np.ndarray:
    """Which pieces are flat (``FLAT_VOLUME``) or specks (``SPECK_AREA_SPACINGS2``, ``SPECK_VOLUME_SPACINGS3``)."""
    flat = np.abs(volume) <= FLAT_VOLUME * area**1.5
    return (
        flat | (area < SPECK_AREA_SPACINGS2 * spacing_m**2) | (np.abs(volume) < SPECK_VOLUME_SPACINGS3 * spacing_m**3)
    )


def _without_flat_pieces(vertices: np.ndarray, triangles: np.ndarray, spacing_m: float) -> np.ndarray:
    if not len(triangles):
        return triangles
    piece, area, volume = _piece_measures(vertices, triangles)
    return triangles[~_specks(area, volume, spacing_m)[piece]]


def defects(mesh: Mesh, spacing_m: float = 0.0) -> dict:
    """What ``clean`` removes, counted: triangles of no area (``SLIVER_HEIGHT``), groups of vertices at
    one position, pieces of no volume (``FLAT_VOLUME``) and other specks (``SPECK_AREA_SPACINGS2``,
    ``SPECK_VOLUME_SPACINGS3`` of ``spacing_m``); and, counted on the vertices merged, the directed
    edges that two triangles share (not manifold) and those whose reverse no triangle has (a hole);
    with the vertex, triangle and piece counts."""
    triangles = mesh.triangles.astype(np.int64)
    _, first, inverse, counts = np.unique(
        mesh.vertices, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    welded = inverse.reshape(-1)[triangles]
    result = {"vertices": len(mesh.vertices), "triangles": len(triangles)}
    result["zero_area_triangles"] = int(sliver_mask(mesh.vertices, triangles).sum()) if len(triangles) else 0
    result["duplicate_vertex_groups"] = int((counts > 1).sum())
    result["pieces"] = result["flat_pieces"] = result["specks"] = 0
    result["edges_shared"] = result["edges_open"] = 0
    if len(triangles):
        piece, area, volume = _piece_measures(mesh.vertices[first], welded)
        result["pieces"] = len(area)
        result["flat_pieces"] = int((np.abs(volume) <= FLAT_VOLUME * area**1.5).sum())
        flat = np.abs(volume) <= FLAT_VOLUME * area**1.5
        result["specks"] = int((_specks(area, volume, spacing_m) & ~flat).sum())
        n = len(counts)
        edges = np.concatenate([welded[:, [0, 1]], welded[:, [1, 2]], welded[:, [2, 0]]])
        keys = edges[:, 0] * n + edges[:, 1]
        unique, uses = np.unique(keys, return_counts=True)
        result["edges_shared"] = int((uses > 1).sum())
        result["edges_open"] = int((~np.isin(edges[:, 1] * n + edges[:, 0], unique)).sum())
    return result


def _splashsurf(particles: np.ndarray, scene: Scene, iso_level: float, velocities: np.ndarray | None):
    settings = scene.surface
    # pysplashsurf takes lengths in multiples of the particle radius it is given. The colour field
    # does not depend on the particles' mass (m_j/ρ_j = 1/Σ_k W_jk), so passing the spacing as the
    # "radius" makes the table's values in spacings the arguments as they stand.
    surface, _ = pysplashsurf.reconstruction_pipeline(
        particles,
        # splashsurf's SPH interpolation at the vertices, normalised (Shepard): a uniform field comes out
        # as it went in.
        attributes_to_interpolate=None if velocities is None else {"velocity": velocities},
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


def with_wall_images(positions: np.ndarray, lower, upper, reach_m: float, velocities: np.ndarray | None = None):
    """``positions`` followed by their images on each container wall they are within ``reach_m`` of
    (the point on the wall's plane nearest to them; one axis after the other, so that a particle in a
    corner has images on both walls and in the corner itself): the colour field stays high up to the
    walls and falls monotonically beyond them (module docstring). Deterministic: the images follow in
    a fixed order. Returns the points and their velocities (the component across the wall reversed,
    as a mirror image moves), or None without ``velocities``."""
    points, moving = positions, velocities
    for axis in range(3):
        images, speeds = [points], [moving]
        for wall, inward in ((lower[axis], 1.0), (upper[axis], -1.0)):
            near = inward * (points[:, axis] - wall) < reach_m
            image = points[near].copy()
            image[:, axis] = wall
            images.append(image)
            if moving is not None:
                reflected = moving[near].copy()
                reflected[:, axis] = -reflected[:, axis]
                speeds.append(reflected)
        points = np.concatenate(images)
        moving = None if moving is None else np.concatenate(speeds)
    points = np.ascontiguousarray(points, dtype=np.float32)
    return points, None if moving is None else np.ascontiguousarray(moving, dtype=np.float32)


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
        [0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5],
        np.int32,
    ).reshape(12, 3)
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


def write_mesh(path: Path, mesh: Mesh, time_s: float, up_axis: str = "y") -> Path:
    """Write ``mesh`` to ``path`` as binary PLY (``.ply``) or OBJ (``.obj``) in the axes of
    ``up_axis`` (``pbf.app.export.to_export_axes``); returns the path. A PLY carries the vertices'
    velocity (vx, vy, vz) and speed when the mesh has them; OBJ has no place for them."""
    comment = f"pbf fluid surface at t = {time_s:.6f} s; units m and m/s; {up_axis} up"
    points = to_export_axes(mesh.vertices, up_axis)
    if path.suffix == ".ply":
        names = ("x", "y", "z") + (() if mesh.velocities is None else ("vx", "vy", "vz", "speed"))
        vertices = np.empty(len(points), dtype=[(name, "<f4") for name in names])
        for k, axis in enumerate("xyz"):
            vertices[axis] = points[:, k]
        if mesh.velocities is not None:
            velocities = to_export_axes(mesh.velocities, up_axis)
            for k, axis in enumerate("xyz"):
                vertices["v" + axis] = velocities[:, k]
            vertices["speed"] = mesh.speeds()
        faces = np.empty(len(mesh.triangles), dtype=[("vertex_indices", "<i4", (3,))])
        faces["vertex_indices"] = mesh.triangles
        elements = [PlyElement.describe(vertices, "vertex"), PlyElement.describe(faces, "face")]
        PlyData(elements, comments=[comment]).write(str(path))
    elif path.suffix == ".obj":
        with open(path, "w") as obj:
            obj.write(f"# {comment}\n")
            np.savetxt(obj, points, fmt="v %.6f %.6f %.6f")
            np.savetxt(obj, mesh.triangles + 1, fmt="f %d %d %d")  # OBJ counts vertices from 1
    else:
        raise ValueError(f"{path}: unknown mesh format; allowed: {', '.join(MESH_FORMATS)}")
    return path
