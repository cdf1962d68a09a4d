"""Drawing particles: the camera, particle colours, and a ray-cast sphere renderer for headless frames.

The headless renderer needs no Vulkan and no display, and on a CPU it ran 3-10× faster than GGUI on
a software Vulkan driver: each particle projects its bounding square, each pixel in it intersects its
view ray with the particle's sphere, and the nearest hit wins through one 64-bit ``atomic_min`` on
(depth bits, particle id). A second pass shades the winners. The result is the same on every run.
The interactive window (``pbf.app.window``) uses the same View, colours and background, so its frames
look like these. Both read the simulation through its read-outs (``Simulation.readout``,
``Simulation.density_ratios``) and never change it. ``render.style = "surface"`` draws the water's
surface instead, with the screen-space renderer of ``pbf.app.surface_render``.

As the solver's, the renderers' kernels read the scene's numbers (colours, radii, counts of segments
and bodies) as data (``pbf.solver.scene_constants``) and their arrays are sized by buckets
(``pbf.solver.allocation``), so that Taichi's offline cache serves a scene of another spacing,
size or colours with the kernels a run before compiled. The image size stays in the code: a view
setting, the same for most runs.
"""

import math
from dataclasses import dataclass

import numpy as np
import taichi as ti

from pbf.app.constants import colour, padded
from pbf.app.legend import draw_legend
from pbf.app.pinhole import aim, camera_field, to_pixel
from pbf.app.splat import Footprints, per_item
from pbf.app.surface_render import BODY_FLOOR, SEGMENT_FLOOR, SurfaceRenderer
from pbf.app.white_water import WhiteWater
from pbf.scene import Render, Scene
from pbf.solver import allocation as bucket
from pbf.solver import quaternion_matrix_np, scene_constants

EMPTY = np.iinfo(np.int64).max
LIGHT_DIRECTION = np.array([0.35, 0.8, 0.5]) / np.linalg.norm([0.35, 0.8, 0.5])
LUT_SIZE = 256
BODY_POINT_FLOOR = 2**12
"""The fewest rigid-body surface points :class:`BodyPoints` allocates."""


@dataclass
class View:
    """A pinhole camera: eye and target in metres, vertical field of view in degrees, y up."""

    eye: np.ndarray
    target: np.ndarray
    fov_deg: float

    @classmethod
    def of_scene(cls, scene: Scene) -> "View":
        """The scene's camera, with omitted points derived so the whole container is in view."""
        lower, upper = np.array(scene.container.min_m), np.array(scene.container.max_m)
        centre = 0.5 * (lower + upper)
        # A little below the centre: seen from above, the box's near bottom corner reaches lowest.
        below_centre = centre - np.array([0.0, 0.08 * (upper[1] - lower[1]), 0.0])
        target = np.array(scene.camera.look_at_m) if scene.camera.look_at_m is not None else below_centre
        if scene.camera.position_m is not None:
            eye = np.array(scene.camera.position_m)
        else:
            # Back far enough that the box nearly fits the vertical field of view (its bounding sphere is larger).
            radius = 0.5 * np.linalg.norm(upper - lower)
            direction = np.array([0.55, 0.45, 1.0]) / np.linalg.norm([0.55, 0.45, 1.0])
            eye = target + direction * radius / math.sin(math.radians(scene.camera.fov_deg) / 2)
        return cls(eye.astype(float), target.astype(float), scene.camera.fov_deg)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit right, up and forward vectors of the camera."""
        forward = self.target - self.eye
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, [0.0, 1.0, 0.0])
        if np.linalg.norm(right) < 1e-6:  # looking straight up or down
            right = np.array([1.0, 0.0, 0.0])
        right = right / np.linalg.norm(right)
        return right, np.cross(right, forward), forward

    def focal_px(self, height_px: int) -> float:
        """f = (H/2) / tan(fov/2): pixels per unit of image-plane distance."""
        return 0.5 * height_px / math.tan(math.radians(self.fov_deg) / 2)


def box_edges(lower, upper) -> np.ndarray:
    """The 12 edges of an axis-aligned box as a (24, 3) array of segment end points."""
    corners = np.array([[(lower, upper)[(k >> a) & 1][a] for a in range(3)] for k in range(8)], dtype=np.float32)
    pairs = [(k, k | 1 << a) for k in range(8) for a in range(3) if not k >> a & 1]
    return np.array([corners[p] for pair in pairs for p in pair], dtype=np.float32)


def scene_edges(scene: Scene) -> np.ndarray:
    """The edges of the container and of every obstacle, as one (24 k, 3) array of segment end points."""
    boxes = [(scene.container.min_m, scene.container.max_m)] + [(o.min_m, o.max_m) for o in scene.obstacles]
    return np.concatenate([box_edges(lower, upper) for lower, upper in boxes])


@ti.data_oriented
class ParticleColours:
    """Per-particle RGB from speed or density through a Matplotlib colour map (a 256-entry table)."""

    def __init__(self, sim, render: Render):
        import matplotlib

        self.sim = sim
        self.render = render
        # As long as the solver's per-particle arrays (a capacity bucket, not the scene's count): the
        # kernels that fill and read it then compile once for every scene of the bucket.
        self.colours = ti.Vector.field(3, ti.f32, shape=sim.model.allocated)
        table = matplotlib.colormaps[render.colour_map](np.linspace(0.0, 1.0, LUT_SIZE))[:, :3]
        self.table = ti.Vector.field(3, ti.f32, shape=LUT_SIZE)
        self.table.from_numpy(table.astype(np.float32))

    @ti.func
    def _lookup(self, u):
        k = ti.cast(ti.math.clamp(u, 0.0, 1.0) * (LUT_SIZE - 1) + 0.5, ti.i32)
        return self.table[k]

    @ti.kernel
    def _by_speed(self, v: ti.template(), speed_max: ti.f32):
        for i in range(self.colours.shape[0]):
            self.colours[i] = self._lookup(v[i].norm() / speed_max)

    @ti.kernel
    def _by_density(self, ratios: ti.template(), span: ti.f32):
        for i in range(self.colours.shape[0]):
            self.colours[i] = self._lookup((ratios[i] - 1.0 + span) / (2.0 * span))

    def update(self):
        """Recolour every particle from the current state; returns the colour field (in the order of
        ``Simulation.readout``)."""
        if self.render.colour_by == "speed":
            self._by_speed(self.sim.readout().velocities, self.render.speed_max_m_s)
        else:
            self._by_density(self.sim.density_ratios(), self.render.density_error_max)
        return self.colours


SLABS = 1024
"""Depth slabs of the sphere renderer's front-to-back order (see ``SphereRenderer._order``)."""
TILE = 16
"""Side of the tiles the image is transposed in for files (``SphereRenderer._rgb``), pixels."""
OPAQUE = 0xFF000000
"""The alpha byte of a packed RGBA pixel."""


@ti.func
def pack_rgba(colour):
    """An RGB colour in [0, 1] as one little-endian RGBA8 word, the pixel format GGUI's canvas takes."""
    c = ti.cast(ti.min(colour, 1.0) * 255.0 + 0.5, ti.u32)
    return c[0] | (c[1] << 8) | (c[2] << 16) | ti.u32(OPAQUE)


def unpack_rgb(packed: np.ndarray) -> np.ndarray:
    """A (W, H) array of packed RGBA words (x right, y up, as GGUI's canvas takes them) as an (H, W, 3)
    uint8 image with row 0 at the top."""
    rgba = packed.view(np.uint8).reshape(*packed.shape, 4)
    return np.ascontiguousarray(rgba[:, ::-1, :3].transpose(1, 0, 2))


@ti.data_oriented
class SphereRenderer:
    """Ray-cast shaded spheres with a depth test, plus depth-tested line segments, into an RGB image.

    The image is written as packed RGBA words in the layout of GGUI's canvas (``(W, H)``, y up), so
    that the window shows it without a conversion pass; :meth:`render` turns it into an ``(H, W, 3)``
    array for files. Spheres are splatted nearest first (a counting sort of the particles by view depth
    into ``SLABS`` slabs), and a pixel already covered by a nearer sphere is skipped before its ray is
    cast: most particles of a block of water are hidden, and this makes the splat 2-3× cheaper. The
    image does not depend on that order (a pixel keeps the smallest (depth, particle id) key), so it
    is the same on every run."""

    def __init__(self, width_px: int, height_px: int, background_rgb, line_rgb=(0.0, 0.0, 0.0), segments=None):
        # The image size stays in the kernels' code (a view setting, the same for most runs); the
        # scene's colours and segment count are data, so another scene finds these kernels compiled.
        self.width, self.height = int(width_px), int(height_px)
        self.keys = ti.field(ti.i64, shape=(self.width, self.height))
        """(view depth bits << 32) | particle id of the nearest hit per pixel, EMPTY where none; indexed
        [x, y] with y up like ``packed``, so that shading reads and writes both in memory order."""
        self.packed = np.zeros((self.width, self.height), np.uint32)
        """The image: packed RGBA words, (W, H), y up (GGUI's canvas layout), in host memory, where GGUI
        (Taichi 1.7.4) takes it from."""
        on_cpu = ti.cfg.arch in (ti.x64, ti.arm64)
        self.image = self.packed if on_cpu else ti.ndarray(ti.u32, shape=(self.width, self.height))
        """What the kernels draw into: ``packed`` itself on the CPU, a device ndarray on a GPU, copied
        into ``packed`` by one kernel that writes every pixel. A NumPy array given to a kernel is copied
        to the device and back around the launch (by Vulkan and Metal up only where the kernel reads
        it, back whole), so the lines pass, which writes a few pixels of it, brought back stale memory
        everywhere else on Vulkan; and on CUDA each frame cost four copies of it."""
        points = np.zeros((0, 3), np.float32) if segments is None else np.asarray(segments, np.float32)
        self.segment_count = len(points) // 2
        self.segments = ti.Vector.field(3, ti.f32, shape=2 * bucket(self.segment_count, SEGMENT_FLOOR))
        if len(points):
            self.segments.from_numpy(padded(points, self.segments.shape[0]))
        self.constants = scene_constants(
            background=colour(background_rgb), line_colour=colour(line_rgb), segment_count=self.segment_count
        )
        """The background and line colours and the number of segments, as data (``pbf.solver.scene_constants``)."""
        self.depth_range = ti.field(ti.f32, shape=2)
        self.slab_count = ti.field(ti.i32, shape=SLABS)
        self.slab_start = ti.field(ti.i32, shape=SLABS)
        self.capacity = 0
        self.slab = self.rank = self.order = None
        """Per particle: its depth slab, its rank in the slab, and the particles in slab order."""
        self.front_to_back = True
        """Splat in depth order (False: in the simulation's order, for benchmarks/window.py)."""
        self.per_item = per_item()
        """Splat a thread per (particle, pixel) (``pbf.app.splat``; GPU backends), else per particle."""
        self.footprints = None
        self.camera = camera_field()
        """The view and light of the current draw (``pbf.app.pinhole.aim``), set once a draw."""

    def _allocate(self, capacity: int) -> None:
        if capacity > self.capacity:
            self.capacity = capacity
            self.slab, self.rank, self.order = (ti.field(ti.i32, shape=capacity) for _ in range(3))
            self.footprints = Footprints(capacity) if self.per_item else None

    @ti.func
    def _ray(self, row, col, cam):
        """Unit direction of the ray through the centre of pixel (row, col); row 0 is the top."""
        u = (col + 0.5 - 0.5 * self.width) / cam.focal
        w = (0.5 * self.height - row - 0.5) / cam.focal
        return (cam.right * u + cam.up * w + cam.forward).normalized()

    @ti.func
    def _hit(self, centre, direction, radius):
        """Distance along a unit ray from the eye to a sphere at ``centre`` (eye-relative), or -1."""
        b = direction.dot(centre)
        disc = b * b - (centre.norm_sqr() - radius * radius)
        t = -1.0
        if disc >= 0.0:
            t = b - ti.sqrt(disc)
        return t

    @ti.func
    def _pixel_key(self, i, centre, radius, c, r, cam):
        """The depth key of sphere i (eye-relative ``centre``, ``radius``) at pixel (column c,
        row r from the top), or EMPTY where the pixel's ray misses it; both splats test pixels with it.
        The ray eye + t·ray (its forward component 1, so t is the view depth) meets the sphere where
        t² |ray|² − 2 t ray·c + |c|² − r² = 0."""
        ray = (
            cam.right * ((c + 0.5 - 0.5 * self.width) / cam.focal)
            + cam.forward
            + cam.up * ((0.5 * self.height - r - 0.5) / cam.focal)
        )
        a, b = ray.norm_sqr(), ray.dot(centre)
        disc = b * b - a * (centre.norm_sqr() - radius * radius)
        key = ti.i64(EMPTY)
        if disc >= 0.0:
            t = (b - ti.sqrt(disc)) / a
            key = (ti.cast(ti.bit_cast(t, ti.i32), ti.i64) << 32) | ti.cast(i, ti.i64)
        return key

    @ti.kernel
    def _clear(self):
        for x, y in self.keys:
            self.keys[x, y] = ti.i64(EMPTY)

    @ti.kernel
    def _order(self, x: ti.template(), count: ti.i32):
        """``order``: the particles by view depth, nearest slab first (a counting sort; the order within
        a slab is whichever thread came first, which the image does not depend on)."""
        eye, forward = self.camera[None].eye, self.camera[None].forward
        for s in self.slab_count:
            self.slab_count[s] = 0
        self.depth_range[0] = ti.math.inf
        self.depth_range[1] = -ti.math.inf
        for i in range(count):
            depth = (x[i] - eye).dot(forward)
            ti.atomic_min(self.depth_range[0], depth)
            ti.atomic_max(self.depth_range[1], depth)
        nearest = self.depth_range[0]
        scale = SLABS / ti.max(self.depth_range[1] - nearest, 1e-30)
        for i in range(count):
            slab = ti.min(ti.cast(((x[i] - eye).dot(forward) - nearest) * scale, ti.i32), SLABS - 1)
            self.slab[i] = slab
            self.rank[i] = ti.atomic_add(self.slab_count[slab], 1)
        total = 0
        ti.loop_config(serialize=True)
        for s in range(SLABS):
            self.slab_start[s] = total
            total += self.slab_count[s]
        for i in range(count):
            self.order[self.slab_start[self.slab[i]] + self.rank[i]] = i

    @ti.kernel
    def _identity(self, count: ti.i32):
        for i in range(count):
            self.order[i] = i

    @ti.func
    def _projected(self, centre, radius, cam):
        """(visible, column, row, extent) of the sphere at ``centre`` (from the eye): whether it lies wholly
        in front, its image's centre, and the radius in pixels that bounds its image. Off the axis by θ
        the sphere's image is an ellipse of semi-major axis about f r / (d cos θ) = f r |c| / d²; the
        extent bounds it with 10% and a pixel to spare."""
        depth = centre.dot(cam.forward)
        visible = depth > radius * 1.01
        safe = ti.select(visible, depth, 2.0 * radius + 1.0)
        col = 0.5 * self.width + cam.focal * centre.dot(cam.right) / safe
        row = 0.5 * self.height - cam.focal * centre.dot(cam.up) / safe
        extent = 1.1 * cam.focal * radius * centre.norm() / ((safe - radius) * safe) + 1.0
        return visible, col, row, extent

    @ti.func
    def _columns(self, col, extent):
        """The columns [c0, c1) of the extent's disc."""
        return ti.max(0, ti.cast(col - extent, ti.i32)), ti.min(self.width, ti.cast(col + extent, ti.i32) + 1)

    @ti.func
    def _rows_at(self, row, extent, offset):
        """The rows [r0, r1) of the extent's disc at a column ``offset`` pixels from its centre."""
        half = ti.sqrt(ti.max(extent * extent - offset * offset, 0.0))
        return ti.max(0, ti.cast(row - half, ti.i32)), ti.min(self.height, ti.cast(row + half, ti.i32) + 1)

    @ti.func
    def _try_pixel(self, i, centre, radius, c, r, cam):
        """Sphere i's hit at pixel (c, r) into its key, unless the key is already nearer than any hit on
        the sphere can be (depth − r, with a margin for rounding)."""
        depth = centre.dot(cam.forward)
        nearest = ti.cast(ti.bit_cast((depth - radius) * (1.0 - 1e-4), ti.i32), ti.i64) << 32
        y = self.height - 1 - r
        if self.keys[c, y] > nearest:
            key = self._pixel_key(i, centre, radius, c, r, cam)
            if key < self.keys[c, y]:
                ti.atomic_min(self.keys[c, y], key)

    @ti.kernel
    def _splat(self, x: ti.template(), count: ti.i32, radius: ti.f32):
        """Every sphere into the keys. On the CPU a thread per particle, over each column's span of its disc
        (a column is contiguous in ``keys``); on a GPU a thread per (particle, pixel) of each particle's
        bounding square (``pbf.app.splat``), with the same tests."""
        cam = self.camera[None]
        if ti.static(self.per_item):
            for k in range(count):
                visible, col, row, extent = self._projected(x[self.order[k]] - cam.eye, radius, cam)
                c0, c1, r0, r1 = 0, 0, 0, 0
                if visible:
                    c0, c1 = self._columns(col, extent)
                    r0 = ti.max(0, ti.cast(row - extent, ti.i32))
                    r1 = ti.min(self.height, ti.cast(row + extent, ti.i32) + 1)
                self.footprints.set(k, c0, c1, r0, r1)
            self.footprints.scan(count)
            for w in range(self.footprints.total(count)):
                k, c, r = self.footprints.item(w, count)
                i = self.order[k]
                centre = x[i] - cam.eye
                _, col, row, extent = self._projected(centre, radius, cam)
                r0, r1 = self._rows_at(row, extent, c + 0.5 - col)  # the disc, as the CPU visits it
                if r0 <= r < r1:
                    self._try_pixel(i, centre, radius, c, r, cam)
        else:
            for k in range(count):
                i = self.order[k]
                centre = x[i] - cam.eye
                visible, col, row, extent = self._projected(centre, radius, cam)
                if visible:
                    c0, c1 = self._columns(col, extent)
                    for c in range(c0, c1):
                        r0, r1 = self._rows_at(row, extent, c + 0.5 - col)
                        for r in range(r0, r1):
                            self._try_pixel(i, centre, radius, c, r, cam)

    @ti.kernel
    def _shade(
        self,
        x: ti.template(),
        colours: ti.template(),
        radius: ti.f32,
        out: ti.types.ndarray(dtype=ti.u32, ndim=2),
    ):
        cam = self.camera[None]
        light = cam.light
        for col, y in self.keys:
            key = self.keys[col, y]
            word = pack_rgba(self.constants[None].background)  # the same for all: most pixels are background
            if key != ti.i64(EMPTY):
                row = self.height - 1 - y
                i = ti.cast(key & ti.i64(0xFFFFFFFF), ti.i32)
                direction = self._ray(row, col, cam)
                centre = x[i] - cam.eye
                t = self._hit(centre, direction, radius)
                normal = (direction * t - centre) / radius
                diffuse = ti.max(normal.dot(light), 0.0)
                halfway = (light - direction).normalized()
                cosine = ti.max(normal.dot(halfway), 0.0)
                specular = cosine * cosine * cosine * cosine * cosine  # cosine⁴⁰ = (cosine⁵)⁸, by squaring
                for _ in ti.static(range(3)):
                    specular *= specular
                word = pack_rgba(colours[i] * (0.35 + 0.65 * diffuse) + 0.25 * specular)
            out[col, y] = word

    @ti.kernel
    def _lines(self, out: ti.types.ndarray(dtype=ti.u32, ndim=2)):
        cam = self.camera[None]
        for s in range(self.constants[None].segment_count):
            a, b = self.segments[2 * s], self.segments[2 * s + 1]
            samples = 2 * (self.width + self.height)
            for k in range(samples + 1):
                p = a + (b - a) * (k / samples) - cam.eye
                row, col, depth, inside = to_pixel(
                    p, cam.right, cam.up, cam.forward, cam.focal, self.width, self.height
                )
                if inside:
                    key = self.keys[col, self.height - 1 - row]
                    hit = ti.bit_cast(ti.cast(key >> 32, ti.i32), ti.f32)  # the sphere's view depth
                    if key == ti.i64(EMPTY) or depth < hit:
                        out[col, self.height - 1 - row] = pack_rgba(self.constants[None].line_colour)

    @ti.kernel
    def _copy(self, image: ti.types.ndarray(dtype=ti.u32, ndim=2), out: ti.types.ndarray(dtype=ti.u32, ndim=2)):
        for col, y in ti.ndrange(self.width, self.height):
            out[col, y] = image[col, y]

    @ti.kernel
    def _rgb(self, image: ti.types.ndarray(dtype=ti.u32, ndim=2), out: ti.types.ndarray(dtype=ti.u8, ndim=3)):
        """The packed image (W, H, y up) as (H, W, 3) bytes, row 0 at the top: a file's layout, written
        whole by one kernel, so that a GPU backend copies the frame to the host once. A transpose: on
        the CPU in tiles of TILE × TILE pixels, a thread each, whose source columns and destination rows
        stay in the cache (row by row every read was a cache line of its own: 4.8 against 3.0 ms for
        1280 × 720); on a GPU a thread per pixel, the writes of neighbouring threads side by side."""
        if ti.static(self.per_item):
            for row, col in ti.ndrange(self.height, self.width):
                self._rgb_pixel(image, out, row, col)
        else:
            for tile_row, tile_col in ti.ndrange((self.height + TILE - 1) // TILE, (self.width + TILE - 1) // TILE):
                for i, j in ti.ndrange(TILE, TILE):
                    row, col = tile_row * TILE + i, tile_col * TILE + j
                    if row < self.height and col < self.width:
                        self._rgb_pixel(image, out, row, col)

    @ti.func
    def _rgb_pixel(self, image: ti.template(), out: ti.template(), row, col):
        word = image[col, self.height - 1 - row]
        for channel in ti.static(range(3)):
            out[row, col, channel] = ti.cast((word >> (8 * channel)) & 0xFF, ti.u8)

    def depth_at(self, col: int, row_up: int, count: int) -> float | None:
        """The view depth (m) of the sphere drawn at pixel (col, row_up) of the last draw (row 0 at the
        bottom), None where the pixel shows none of the first ``count`` (the water's; the bodies' points
        follow them)."""
        key = int(self.keys[col, row_up])
        if key == EMPTY or key & 0xFFFFFFFF >= count:
            return None
        return float(np.array([key >> 32], np.int32).view(np.float32)[0])

    def draw(self, view: View, positions, colours, count: int, radius_m: float) -> np.ndarray:
        """Render ``count`` spheres of ``radius_m`` (Taichi fields) and the segments into ``packed``
        and return it: (W, H) RGBA words, y up, as GGUI's canvas takes them."""
        self._draw(view, positions, colours, count, radius_m)
        if self.image is not self.packed:
            self._copy(self.image, self.packed)
        return self.packed

    def _draw(self, view: View, positions, colours, count: int, radius_m: float) -> None:
        """The image into ``image`` (on the device on a GPU backend)."""
        aim(self.camera, view, self.height, LIGHT_DIRECTION)
        self._clear()
        if count:
            self._allocate(positions.shape[0])
            if self.front_to_back:
                self._order(positions, count)
            else:
                self._identity(count)
            self._splat(positions, count, radius_m)
        self._shade(positions, colours, radius_m, self.image)
        if self.segment_count:
            self._lines(self.image)

    def render(self, view: View, positions, colours, count: int, radius_m: float) -> np.ndarray:
        """(H, W, 3) uint8 image of ``count`` spheres of ``radius_m`` (Taichi fields) and the segments,
        a new array each call."""
        self._draw(view, positions, colours, count, radius_m)
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        self._rgb(self.image, rgb)
        return rgb


def surface_renderer(sim, width_px: int, height_px: int) -> SurfaceRenderer:
    """The screen-space water renderer for a Simulation's scene: its particle volume, its container's
    floor in tiles an eighth of the box wide, its colours, the container and obstacle edges, and its rigid
    bodies (``Simulation.solids``)."""
    scene = sim.scene
    lower, upper = scene.container.min_m, scene.container.max_m
    return SurfaceRenderer(
        width_px,
        height_px,
        scene.fluid.spacing_m,
        sim.model.particle_mass_kg / scene.fluid.rest_density_kg_m3,
        floor_y_m=lower[1],
        tile_m=(upper[0] - lower[0]) / 8,
        absorption_per_m=scene.surface.absorption_per_m,
        water_rgb=scene.surface.water_rgb,
        horizon_rgb=scene.render.background_rgb,
        line_rgb=scene.render.container_rgb,
        segments=scene_edges(scene),
        solids=sim.solids(),
        body_rgb=BODY_RGB,
        exposure_s=scene.surface.shutter_frames * scene.time.frame_dt_s,
    )


BODY_RGB = (0.85, 0.55, 0.25)
"""The colour of rigid bodies (wood), in particle and surface frames."""


@ti.data_oriented
class BodyPoints:
    """The rigid bodies drawn as solids by the sphere renderer: each body's surface covered with points a
    particle radius apart, placed at its pose each frame and appended to the particles (with the body
    colour), so that water in front hides a body and a body in front hides water."""

    def __init__(self, sim):
        self.sim = sim
        self.colour = ti.Vector(list(BODY_RGB))
        pitch = sim.scene.particle_radius_m
        local, owner = [], []
        for k, body in enumerate(sim.scene.bodies):
            points = _surface_points(body.shape, body.half_extents(), pitch)
            local.append(points)
            owner.append(np.full(len(points), k, np.int32))
        self.count = int(sum(len(p) for p in local))
        # Every array sized by a bucket and the counts as data, so that scenes of other bodies, spacings
        # or sizes find the kernel compiled (``pbf.solver.allocation``).
        points = bucket(self.count, BODY_POINT_FLOOR)
        capacity = sim.model.allocated + points
        self.local = ti.Vector.field(3, ti.f32, shape=points)
        self.owner = ti.field(ti.i32, shape=points)
        if self.count:
            self.local.from_numpy(padded(np.concatenate(local).astype(np.float32), points))
            self.owner.from_numpy(padded(np.concatenate(owner), points))
        self.bodies = bucket(len(sim.scene.bodies), BODY_FLOOR)
        self.centre = ti.Vector.field(3, ti.f32, shape=self.bodies)
        self.rotation = ti.Matrix.field(3, 3, ti.f32, shape=self.bodies)
        self.positions = ti.Vector.field(3, ti.f32, shape=capacity)
        self.colours = ti.Vector.field(3, ti.f32, shape=capacity)
        self.constants = scene_constants(points=self.count)
        """The number of surface points, as data."""

    @ti.kernel
    def _combine(self, positions: ti.template(), colours: ti.template(), count: ti.i32):
        for i in range(count):
            self.positions[i] = positions[i]
            self.colours[i] = colours[i]
        for k in range(self.constants[None].points):
            b = self.owner[k]
            self.positions[count + k] = self.centre[b] + self.rotation[b] @ self.local[k]
            self.colours[count + k] = self.colour

    def combine(self, positions, colours, count: int):
        """The particles and the bodies' points as one positions field, one colours field and a count."""
        states = self.sim.body_states()
        self.centre.from_numpy(padded(states[:, 0:3].astype(np.float32), self.bodies))
        rotations = np.stack([quaternion_matrix_np(q) for q in states[:, 3:7]]).astype(np.float32)
        self.rotation.from_numpy(padded(rotations, self.bodies))
        self._combine(positions, colours, count)
        return self.positions, self.colours, count + self.count


def _surface_points(shape: str, half: np.ndarray, pitch: float) -> np.ndarray:
    """Points covering a body's surface (its own frame) about ``pitch`` apart."""
    if shape == "sphere":
        radius = float(half[0])
        n = max(8, int(4 * math.pi * radius**2 / pitch**2))
        k = np.arange(n) + 0.5  # a Fibonacci lattice on the sphere
        y = 1 - 2 * k / n
        phi = math.pi * (3 - math.sqrt(5)) * k
        ring = np.sqrt(1 - y * y)
        return radius * np.stack([ring * np.cos(phi), y, ring * np.sin(phi)], axis=1)
    faces = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        us = np.linspace(-half[u], half[u], max(2, int(2 * half[u] / pitch) + 1))
        vs = np.linspace(-half[v], half[v], max(2, int(2 * half[v] / pitch) + 1))
        grid_u, grid_v = np.meshgrid(us, vs, indexing="ij")
        for side in (-1.0, 1.0):
            face = np.zeros((grid_u.size, 3))
            face[:, u], face[:, v], face[:, axis] = grid_u.ravel(), grid_v.ravel(), side * half[axis]
            faces.append(face)
    return np.concatenate(faces)


STYLES = ("particles", "surface")
"""What a frame draws: the particles as spheres, or the water's surface."""


class SceneRenderer:
    """A Simulation's frames, for headless files and the window alike: the one place that chooses the style
    (``render.style``, or the window's key v) and gathers the rigid bodies for it. Particles are coloured
    spheres with the bodies' surface points among them (``SphereRenderer``, ``BodyPoints``); the surface
    style draws the water's surface with the bodies as solids (``SurfaceRenderer``). Each style's renderer
    is made on first use, and again when the image size changes (``resize``)."""

    def __init__(self, sim, width_px=None, height_px=None, style=None, white_water=None):
        """``style`` "particles" or "surface" (default: the scene's ``render.style``); ``white_water``: whether
        the surface style draws it (default: the scene's ``white_water.enabled``)."""
        render = sim.scene.render
        self.sim = sim
        self.view = View.of_scene(sim.scene)
        """The scene's camera, which :meth:`frame` draws from."""
        self.width, self.height = int(width_px or render.width_px), int(height_px or render.height_px)
        self.style = style or render.style
        self.spheres = None
        self.surface = None
        """The style's renderers, made on first use for the current size."""
        self.colours = None
        self.bodies = None
        """The particles' colours and the rigid bodies' points (the particle style's), made on first use."""
        self.white_water = None
        """Spray, foam and bubbles (``pbf.app.white_water``; the surface style's), made on first use."""
        self.with_white_water = sim.scene.white_water.enabled if white_water is None else bool(white_water)

    def resize(self, width_px: int, height_px: int) -> None:
        """Draw at another size from the next frame on (a window resized)."""
        if (width_px, height_px) != (self.width, self.height):
            self.width, self.height = int(width_px), int(height_px)
            self.spheres = self.surface = None

    @property
    def renderer(self):
        """The current style's renderer at the current size (``width``, ``height``, ``packed``)."""
        if self.style == "surface":
            if self.surface is None:
                self.surface = surface_renderer(self.sim, self.width, self.height)
            if self.white_water is None and self.with_white_water:
                self.white_water = WhiteWater(self.sim)
            return self.surface
        if self.spheres is None:
            render = self.sim.scene.render
            self.spheres = SphereRenderer(
                self.width, self.height, render.background_rgb, render.container_rgb, scene_edges(self.sim.scene)
            )
        if self.colours is None:
            self.colours = ParticleColours(self.sim, self.sim.scene.render)
            self.bodies = BodyPoints(self.sim) if self.sim.scene.bodies else None
        return self.spheres

    def _spheres(self):
        """The particles' positions and colours with the bodies' points, and their count."""
        particles = self.sim.readout()
        positions, colours, count = particles.positions, self.colours.update(), particles.count
        if self.bodies is not None:
            positions, colours, count = self.bodies.combine(positions, colours, count)
        return positions, colours, count, particles.radius_m

    def _surface(self) -> tuple:
        """The surface renderer's arguments after the view: the particles, the light, the neighbour lists,
        the velocities and the white water, brought to the simulation's frame."""
        particles = self.sim.readout()
        if self.white_water is not None:
            self.white_water.sync()
        return (
            particles.positions,
            particles.count,
            LIGHT_DIRECTION,
            self.sim.neighbourhood(),
            particles.velocities,
            self.white_water,
        )

    def draw(self, view: View) -> np.ndarray:
        """The current state seen through ``view`` as (W, H) packed RGBA words, y up: the layout GGUI's
        canvas shows as it is (the renderer's own array, valid until the next draw)."""
        renderer = self.renderer
        if renderer is self.surface:
            return renderer.draw_packed(view, *self._surface())
        return renderer.draw(view, *self._spheres())

    def frame(self) -> np.ndarray:
        """The current state from the scene's camera as an (H, W, 3) uint8 image, a new array each call
        (copied from the device once), with the colour legend where the style has one."""
        renderer = self.renderer
        if renderer is self.surface:
            return renderer.render(self.view, *self._surface())
        image = renderer.render(self.view, *self._spheres())
        return draw_legend(image, self.sim.scene.render) if self.sim.scene.render.legend else image

    def depth_at(self, col: int, row_up: int) -> float | None:
        """The view depth (m) of the water drawn at pixel (col, row_up) of the last draw (row 0 at the
        bottom), None where there is none (background, a body)."""
        if self.style == "surface":
            return self.renderer.depth_at(col, row_up)
        return self.renderer.depth_at(col, row_up, self.sim.particle_count)
