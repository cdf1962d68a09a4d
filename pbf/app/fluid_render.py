"""A screen-space fluid renderer for headless frames: water as a smooth, refracting, tinted surface.

The method is van der Laan, Green & Sainz 2009 ("Screen space fluid rendering with curvature
flow", I3D), with the depth smoothed by the narrow-range filter of Truong & Yuksel 2018 ("A
narrow-range filter for screen-space fluid rendering", PACMCGIT 1(1)), all as Taichi kernels. Passes
1-4 run at half the image's resolution in each direction (the filter's width in pixels halves too, so
a quarter of the pixels costs an eighth); only the composition is at full resolution.

1. *Splat.* Every particle is a sphere; each pixel keeps the nearest sphere's view depth (an
   ``atomic_min``) and adds the chord its ray cuts through the sphere, scaled by (particle
   volume / sphere volume) so that the sum is the ray's path length through water however much the
   spheres overlap. The chords are added as fixed-point integers, so the sum does not depend on the
   order the threads add them in and the image is the same on every run.
2. *Smooth.* The narrow-range filter, separably along rows then columns: a Gaussian over the pixels
   within a few spacings (its width in pixels shrinks with depth), in which samples more than the
   threshold μ behind the centre belong to another layer or the background and are left out, and
   samples more than μ in front are clamped to μ in front. We take the samples in pairs about the
   centre and leave a pair out whole, and widen the range by μ around each pair taken, so that a
   surface seen at a slant is smoothed over the filter's whole width without being pulled forward or
   back. Silhouettes stay where the particles are; the bumps of single particles go. The thickness
   gets a plain Gaussian.
3. *Normals* from the smoothed depth by finite differences, taking on each axis the smaller of the
   forward and backward difference so that normals do not bend over edges (van der Laan et al., §4).
4. *Shade.* Schlick's Fresnel term mixes the reflection of a sky gradient with the refracted view of
   a tiled floor (Snell's law, n = 1.33), tinted by Beer–Lambert absorption along the thickness:
   T = exp(−σ d) per colour channel, the absorbed part replaced by the colour of deep water.
5. *Compose* at full resolution. A pixel is water where the bilinear interpolation of the coarse
   pixels' coverage (1 water, 0 not) reaches ½, so silhouettes are smooth curves rather than 2-pixel
   steps; its colour and depth are interpolated from the coarse pixels that are water. Elsewhere it
   shows the view without water (floor and sky), computed once per camera and kept.

Everything reads positions as Taichi fields and writes an (H, W, 3) uint8 image; nothing here
changes the simulation.
"""

import math

import numpy as np
import taichi as ti

from pbf.app.pinhole import to_pixel
from pbf.app.splat import Footprints, per_item

vec3 = ti.types.vector(3, ti.f32)

FAR = 1e30
"""Depth of a pixel no water covers, m."""
COARSE = 2
"""The surface passes run at 1/COARSE of the image's width and height."""
SPLAT_RADIUS_SPACINGS = 0.75
"""Sphere radius of a particle in the splat, in spacings: more than √2/2, so that a lattice of
particles seen along one of its axes leaves no pinholes between its spheres."""
FILTER_SIGMA_SPACINGS = 1.5
"""Standard deviation of the smoothing, in spacings (in pixels: f σ / depth)."""
FILTER_ROUNDS = 2
"""Rounds of (rows, columns), each a Gaussian of σ/√rounds (together one of σ). A single round
leaves streaks along the second axis wherever the first one's samples changed from pixel to pixel;
two rounds cost 41% more and remove most of them."""
ROUND_SIGMA_SPACINGS = FILTER_SIGMA_SPACINGS / math.sqrt(FILTER_ROUNDS)
FILTER_MAX_RADIUS_PX = 24
"""Widest filter, in coarse pixels each side: bounds the cost of water close to the camera."""
THRESHOLD_SPACINGS = 1.0
"""The narrow range μ: a sample this far behind the centre pixel is another layer."""
THICKNESS_STEPS_PER_SPACING = 4096
"""Fixed-point resolution of the thickness sum (integer atomics are order-independent)."""
WATER_IOR = 1.33
FRESNEL_F0 = 0.02
"""Reflectance of water at normal incidence, ((n − 1)/(n + 1))² (Schlick 1994)."""
ZENITH_RGB = (0.42, 0.6, 0.85)
FLOOR_RGB = ((0.80, 0.80, 0.78), (0.62, 0.64, 0.66))
"""The two colours of the floor's tiles."""


@ti.data_oriented
class FluidRenderer:
    """Renders particles as a water surface over a floor and under a sky, with line segments."""

    def __init__(
        self,
        width_px: int,
        height_px: int,
        spacing_m: float,
        particle_volume_m3: float,
        floor_y_m: float,
        tile_m: float,
        absorption_per_m,
        water_rgb,
        horizon_rgb,
        line_rgb=(0.0, 0.0, 0.0),
        segments=None,
    ):
        """The floor is the plane y = ``floor_y_m`` in square tiles of ``tile_m``; ``absorption_per_m``
        is Beer–Lambert's σ for red, green and blue; ``water_rgb`` the colour of deep water;
        ``horizon_rgb`` the sky's colour at the horizon (the zenith is blue)."""
        self.width, self.height = int(width_px), int(height_px)
        self.coarse_width, self.coarse_height = self.width // COARSE, self.height // COARSE
        self.spacing = float(spacing_m)
        self.radius = SPLAT_RADIUS_SPACINGS * self.spacing
        # Each sphere's chord counts (particle volume / sphere volume): overlapping spheres then add
        # up to the path length through the water they stand for.
        self.chord_scale = particle_volume_m3 / (4.0 / 3.0 * math.pi * self.radius**3)
        self.quantum = self.spacing / THICKNESS_STEPS_PER_SPACING
        self.floor_y, self.tile = float(floor_y_m), float(tile_m)
        self.absorption = ti.Vector([float(c) for c in absorption_per_m])
        self.water = ti.Vector([float(c) for c in water_rgb])
        self.horizon = ti.Vector([float(c) for c in horizon_rgb])
        self.line_colour = ti.Vector([float(c) for c in line_rgb])
        coarse = (self.coarse_height, self.coarse_width)
        self.depth = ti.field(ti.f32, shape=coarse)
        """View depth (distance along the camera's forward axis) of the nearest sphere, m; FAR if none."""
        self.thickness_steps = ti.field(ti.i32, shape=coarse)
        self.depth_pass = ti.field(ti.f32, shape=coarse)
        self.thickness_pass = ti.field(ti.f32, shape=coarse)
        self.smooth_depth = ti.field(ti.f32, shape=coarse)
        self.thickness = ti.field(ti.f32, shape=coarse)
        """Path length of the view ray through water, smoothed, m."""
        self.normal = ti.Vector.field(3, ti.f32, shape=coarse)
        """World-space unit normal of the smoothed surface (zero where there is no water)."""
        self.colour = ti.Vector.field(3, ti.f32, shape=coarse)
        full = (self.height, self.width)
        self.background = ti.Vector.field(3, ti.u8, shape=full)
        self.background_view = None
        """(eye, target, fov) the background was computed for."""
        self.image_depth = ti.field(ti.f32, shape=full)
        self.image = ti.Vector.field(3, ti.u8, shape=full)
        self.packed = None
        """``image`` for the window (``draw_packed``), allocated on first use: a NumPy array, which the
        one kernel that writes it fills whole (so that Vulkan and Metal, which copy it back after the
        launch but up only where a kernel reads it, return every pixel)."""
        self.per_item = per_item()
        """Splat a thread per (particle, pixel) (``pbf.app.splat``; GPU backends), else per particle."""
        self.footprints = None
        points = np.zeros((0, 3), np.float32) if segments is None else np.asarray(segments, np.float32)
        self.segment_count = len(points) // 2
        self.segments = ti.Vector.field(3, ti.f32, shape=max(1, len(points)))
        if len(points):
            self.segments.from_numpy(points)

    # ------------------------------------------------------------------ camera and environment

    @ti.func
    def _ray(self, row, col, right, up, forward, focal, width, height):
        """Direction through the centre of pixel (row, col) of a width × height image, scaled so its
        forward component is 1: the point at view depth z on it is eye + z · ray."""
        u = (col + 0.5 - 0.5 * width) / focal
        w = (0.5 * height - row - 0.5) / focal
        return right * u + up * w + forward

    @ti.func
    def _sky(self, d):
        """The sky along unit direction d: horizon colour below, blending to blue at the zenith."""
        return self.horizon + (ti.Vector(ZENITH_RGB) - self.horizon) * ti.sqrt(ti.max(d.y, 0.0))

    @ti.func
    def _environment(self, origin, d):
        """What a ray from ``origin`` along unit ``d`` sees without water: the tiled floor plane, fading
        into the horizon with distance, or the sky."""
        colour = self._sky(d)
        if d.y < -1e-6:
            t = (self.floor_y - origin.y) / d.y
            if t > 0.0:
                hit = origin + t * d
                tile = ti.cast(ti.floor(hit.x / self.tile) + ti.floor(hit.z / self.tile), ti.i32) & 1
                floor = ti.Vector(FLOOR_RGB[0]) * (1 - tile) + ti.Vector(FLOOR_RGB[1]) * tile
                fade = 1.0 / (1.0 + t / (20.0 * self.tile))  # the floor greys out into the horizon
                colour = floor * fade + self.horizon * (1.0 - fade)
        return colour

    @ti.kernel
    def _environment_image(self, eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32):
        for row, col in self.background:
            ray = self._ray(row, col, right, up, forward, focal, self.width, self.height)
            colour = self._environment(eye, ray.normalized())
            self.background[row, col] = ti.cast(ti.min(colour, 1.0) * 255.0 + 0.5, ti.u8)

    # ------------------------------------------------------------------ the coarse surface passes

    @ti.kernel
    def _clear(self):
        for row, col in self.depth:
            self.depth[row, col] = FAR
            self.thickness_steps[row, col] = 0

    @ti.kernel
    def _splat(self, x: ti.template(), count: ti.i32, eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32):
        radius = self.radius
        width, height = self.coarse_width, self.coarse_height
        for i in range(count):
            centre = x[i] - eye
            depth = centre.dot(forward)
            if depth > radius * 1.01:
                col = 0.5 * width + focal * centre.dot(right) / depth
                row = 0.5 * height - focal * centre.dot(up) / depth
                # The sphere's image lies within f r |c| / ((d − r) d) of its centre's (see SphereRenderer):
                # each row visits the span of that disc.
                extent = 1.1 * focal * radius * centre.norm() / ((depth - radius) * depth) + 1.0
                r0, r1 = ti.max(0, ti.cast(row - extent, ti.i32)), ti.min(height, ti.cast(row + extent, ti.i32) + 1)
                for r in range(r0, r1):
                    offset = r + 0.5 - row
                    half = ti.sqrt(ti.max(extent * extent - offset * offset, 0.0))
                    c0, c1 = ti.max(0, ti.cast(col - half, ti.i32)), ti.min(width, ti.cast(col + half, ti.i32) + 1)
                    for c in range(c0, c1):
                        # The ray eye + t·ray (t the view depth) meets the sphere where
                        # t² |ray|² − 2 t ray·c + |c|² − r² = 0.
                        ray = self._ray(r, c, right, up, forward, focal, width, height)
                        a, b = ray.norm_sqr(), ray.dot(centre)
                        disc = b * b - a * (centre.norm_sqr() - radius * radius)
                        if disc > 0.0:
                            root = ti.sqrt(disc)
                            ti.atomic_min(self.depth[r, c], (b - root) / a)
                            steps = 2.0 * root / ti.sqrt(a) * self.chord_scale / self.quantum
                            ti.atomic_add(self.thickness_steps[r, c], ti.cast(steps + 0.5, ti.i32))

    @ti.kernel
    def _splat_items(
        self, x: ti.template(), count: ti.i32, eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32
    ):
        """:meth:`_splat` with a thread per (particle, pixel) of each particle's bounding square
        (``pbf.app.splat``): the same tests and integer sums, so the same image."""
        radius = self.radius
        width, height = self.coarse_width, self.coarse_height
        for i in range(count):
            centre = x[i] - eye
            depth = centre.dot(forward)
            c0, c1, r0, r1 = 0, 0, 0, 0
            if depth > radius * 1.01:
                col = 0.5 * width + focal * centre.dot(right) / depth
                row = 0.5 * height - focal * centre.dot(up) / depth
                extent = 1.1 * focal * radius * centre.norm() / ((depth - radius) * depth) + 1.0
                r0, r1 = ti.max(0, ti.cast(row - extent, ti.i32)), ti.min(height, ti.cast(row + extent, ti.i32) + 1)
                c0, c1 = ti.max(0, ti.cast(col - extent, ti.i32)), ti.min(width, ti.cast(col + extent, ti.i32) + 1)
            self.footprints.set(i, c0, c1, r0, r1)
        self.footprints.scan(count)
        for w in range(self.footprints.total(count)):
            i, c, r = self.footprints.item(w, count)
            centre = x[i] - eye
            # The per-particle loops visit only the disc of the bounding square; so does this.
            depth = centre.dot(forward)
            col = 0.5 * width + focal * centre.dot(right) / depth
            row = 0.5 * height - focal * centre.dot(up) / depth
            extent = 1.1 * focal * radius * centre.norm() / ((depth - radius) * depth) + 1.0
            offset = r + 0.5 - row
            half = ti.sqrt(ti.max(extent * extent - offset * offset, 0.0))
            in_disc = ti.max(0, ti.cast(col - half, ti.i32)) <= c < ti.min(width, ti.cast(col + half, ti.i32) + 1)
            ray = self._ray(r, c, right, up, forward, focal, width, height)
            a, b = ray.norm_sqr(), ray.dot(centre)
            disc = b * b - a * (centre.norm_sqr() - radius * radius)
            if in_disc and disc > 0.0:
                root = ti.sqrt(disc)
                ti.atomic_min(self.depth[r, c], (b - root) / a)
                steps = 2.0 * root / ti.sqrt(a) * self.chord_scale / self.quantum
                ti.atomic_add(self.thickness_steps[r, c], ti.cast(steps + 0.5, ti.i32))

    @ti.kernel
    def _filter(
        self,
        depth_in: ti.template(),
        depth_out: ti.template(),
        step_row: ti.i32,
        step_col: ti.i32,
        focal: ti.f32,
        thickness_in: ti.template(),
        thickness_unit: ti.f32,
        thickness_out: ti.template(),
        with_thickness: ti.template(),
    ):
        """One separable pass of the narrow-range filter along (step_row, step_col), and of a plain
        Gaussian over the thickness when ``with_thickness``."""
        mu = THRESHOLD_SPACINGS * self.spacing
        for row, col in depth_in:
            z = depth_in[row, col]
            depth_out[row, col] = z
            if ti.static(with_thickness):
                thickness_out[row, col] = thickness_in[row, col] * thickness_unit
            if z < FAR:
                sigma = focal * ROUND_SIGMA_SPACINGS * self.spacing / z
                # Taps stop at 2σ (95% of the Gaussian) and at the image's edge: a pair with a tap
                # outside would be left out anyway.
                border = ti.min(col, self.coarse_width - 1 - col)
                if step_row:
                    border = ti.min(row, self.coarse_height - 1 - row)
                reach = ti.min(FILTER_MAX_RADIUS_PX, ti.cast(2.0 * sigma, ti.i32), border)
                # Gaussian weights by recurrence, exp(−(k+1)²/2σ²) = exp(−k²/2σ²) · exp(−(2k+1)/2σ²):
                # two exponentials per pixel rather than one per tap.
                decay = ti.exp(-0.5 / (sigma * sigma))
                decay_step = decay * decay
                weights, depths = 1.0, z
                thickness_weights, thicknesses = 1.0, 0.0
                if ti.static(with_thickness):
                    thicknesses = thickness_in[row, col] * thickness_unit
                far, near = z + mu, z - mu
                w, ratio = 1.0, decay
                for k in range(1, reach + 1):
                    w *= ratio
                    ratio *= decay_step
                    r_a, c_a = row + k * step_row, col + k * step_col
                    r_b, c_b = row - k * step_row, col - k * step_col
                    a, b = depth_in[r_a, c_a], depth_in[r_b, c_b]
                    if ti.static(with_thickness):
                        thickness_weights += 2.0 * w
                        thicknesses += w * (thickness_in[r_a, c_a] + thickness_in[r_b, c_b]) * thickness_unit
                    # A pair with a sample beyond the range behind (background, or a layer behind this
                    # one) is left out whole, so that a slope's samples stay balanced about the centre;
                    # samples in front of the range are clamped to it. The range then grows by μ around
                    # the samples taken, which lets the filter follow a slope over its whole width.
                    if a <= far and b <= far:
                        a, b = ti.max(a, near), ti.max(b, near)
                        far = ti.max(far, ti.max(a, b) + mu)
                        near = ti.min(near, ti.min(a, b) - mu)
                        weights += 2.0 * w
                        depths += w * (a + b)
                depth_out[row, col] = depths / weights
                if ti.static(with_thickness):
                    thickness_out[row, col] = thicknesses / thickness_weights

    @ti.func
    def _position(self, row, col, eye, right, up, forward, focal):
        ray = self._ray(row, col, right, up, forward, focal, self.coarse_width, self.coarse_height)
        return eye + self.smooth_depth[row, col] * ray

    @ti.func
    def _difference(self, row, col, step_row, step_col, eye, right, up, forward, focal):
        """The change of surface position to the next pixel along (step_row, step_col): forward or
        backward, whichever changes depth less and lies on water (van der Laan et al. 2009, §4)."""
        here = self._position(row, col, eye, right, up, forward, focal)
        z = self.smooth_depth[row, col]
        best = ti.Vector([0.0, 0.0, 0.0])
        best_change = FAR
        for sign in ti.static((1, -1)):
            r, c = row + sign * step_row, col + sign * step_col
            if 0 <= r < self.coarse_height and 0 <= c < self.coarse_width:
                neighbour = self.smooth_depth[r, c]
                if neighbour < FAR and ti.abs(neighbour - z) < best_change:
                    best_change = ti.abs(neighbour - z)
                    best = sign * (self._position(r, c, eye, right, up, forward, focal) - here)
        return best

    @ti.kernel
    def _normals(self, eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32):
        for row, col in self.smooth_depth:
            normal = ti.Vector([0.0, 0.0, 0.0])
            if self.smooth_depth[row, col] < FAR:
                along_row = self._difference(row, col, 0, 1, eye, right, up, forward, focal)
                along_col = self._difference(row, col, -1, 0, eye, right, up, forward, focal)
                normal = along_row.cross(along_col)
                towards_eye = eye - self._position(row, col, eye, right, up, forward, focal)
                if normal.norm() == 0.0:  # a lone pixel of water: face the camera
                    normal = towards_eye
                if normal.dot(towards_eye) < 0.0:
                    normal = -normal
                normal = normal.normalized()
            self.normal[row, col] = normal

    # ------------------------------------------------------------------ full resolution

    @ti.kernel
    def _shade(self, eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32, light: vec3):
        """The colour of every coarse pixel of water."""
        for row, col in self.smooth_depth:
            z = self.smooth_depth[row, col]
            if z < FAR:
                normal = self.normal[row, col]
                direction = self._ray(row, col, right, up, forward, focal, self.coarse_width, self.coarse_height)
                point = eye + z * direction
                direction = direction.normalized()
                cosine = ti.max(-normal.dot(direction), 0.0)
                grazing = 1.0 - cosine
                fresnel = FRESNEL_F0 + (1.0 - FRESNEL_F0) * grazing * grazing * grazing * grazing * grazing
                reflected = self._environment(point, direction + 2.0 * cosine * normal)
                eta = 1.0 / WATER_IOR
                k = 1.0 - eta * eta * (1.0 - cosine * cosine)
                refracted = (eta * direction + (eta * cosine - ti.sqrt(ti.max(k, 0.0))) * normal).normalized()
                transmittance = ti.exp(-self.absorption * self.thickness[row, col])
                transmitted = self._environment(point, refracted) * transmittance + self.water * (1.0 - transmittance)
                halfway = (light - direction).normalized()
                specular = ti.max(normal.dot(halfway), 0.0)
                for _ in ti.static(range(8)):  # a Phong exponent of 256, by squaring
                    specular *= specular
                self.colour[row, col] = (1.0 - fresnel) * transmitted + fresnel * reflected + 0.8 * specular

    @ti.kernel
    def _compose(self):
        """Full resolution: water where the coarse coverage interpolates to ½ or more, its colour and
        depth interpolated from the coarse pixels of water; elsewhere the background."""
        for row, col in self.image:
            # The four coarse pixels around this pixel's centre, and their bilinear weights.
            y = (row + 0.5) / COARSE - 0.5
            x = (col + 0.5) / COARSE - 0.5
            r0 = ti.min(ti.max(ti.cast(ti.floor(y), ti.i32), 0), self.coarse_height - 2)
            c0 = ti.min(ti.max(ti.cast(ti.floor(x), ti.i32), 0), self.coarse_width - 2)
            fy = ti.min(ti.max(y - r0, 0.0), 1.0)
            fx = ti.min(ti.max(x - c0, 0.0), 1.0)
            coverage, depth = 0.0, 0.0
            colour = ti.Vector([0.0, 0.0, 0.0])
            for dr, dc in ti.static(ti.ndrange(2, 2)):
                w = (fy if dr else 1.0 - fy) * (fx if dc else 1.0 - fx)
                sample = self.smooth_depth[r0 + dr, c0 + dc]
                if sample < FAR:
                    coverage += w
                    depth += w * sample
                    colour += w * self.colour[r0 + dr, c0 + dc]
            if coverage >= 0.5:
                self.image[row, col] = ti.cast(ti.min(colour / coverage, 1.0) * 255.0 + 0.5, ti.u8)
                self.image_depth[row, col] = depth / coverage
            else:
                self.image[row, col] = self.background[row, col]
                self.image_depth[row, col] = FAR

    @ti.kernel
    def _lines(self, eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32):
        for s in range(self.segment_count):
            a, b = self.segments[2 * s], self.segments[2 * s + 1]
            samples = 2 * (self.width + self.height)
            for k in range(samples + 1):
                p = a + (b - a) * (k / samples) - eye
                row, col, depth, inside = to_pixel(p, right, up, forward, focal, self.width, self.height)
                if inside and depth < self.image_depth[row, col]:
                    self.image[row, col] = ti.cast(self.line_colour * 255.0 + 0.5, ti.u8)

    @ti.kernel
    def _pack(self, out: ti.types.ndarray(dtype=ti.u32, ndim=2)):
        """``image`` as packed RGBA words in GGUI's canvas layout ((W, H), y up)."""
        for row, col in self.image:
            c = ti.cast(self.image[row, col], ti.u32)
            out[col, self.height - 1 - row] = c[0] | (c[1] << 8) | (c[2] << 16) | ti.u32(0xFF000000)

    def draw_packed(self, view, positions, count: int, light_direction) -> np.ndarray:
        """Like :meth:`render`, as a (W, H) array of packed RGBA words, y up, the layout GGUI's canvas
        shows without a conversion pass (the window's surface mode)."""
        self.draw(view, positions, count, light_direction)
        if self.packed is None:
            self.packed = np.zeros((self.width, self.height), np.uint32)
        self._pack(self.packed)
        return self.packed

    def render(self, view, positions, count: int, light_direction) -> np.ndarray:
        """(H, W, 3) uint8 image of the ``count`` particles at ``positions`` (a Taichi vector field, m)
        seen through ``view`` (a ``pbf.app.render.View``), lit from unit ``light_direction``."""
        self.draw(view, positions, count, light_direction)
        return self.image.to_numpy()

    def draw(self, view, positions, count: int, light_direction) -> None:
        """Like :meth:`render`, into the device field ``image`` only (row 0 at the top)."""
        right, up, forward = (ti.Vector(v.astype(np.float32)) for v in view.basis())
        eye = ti.Vector(view.eye.astype(np.float32))
        focal = view.focal_px(self.height)
        coarse_focal = view.focal_px(self.coarse_height)
        key = (tuple(view.eye), tuple(view.target), view.fov_deg)
        if key != self.background_view:
            self._environment_image(eye, right, up, forward, focal)
            self.background_view = key
        self._clear()
        if count and self.per_item:
            if self.footprints is None or self.footprints.capacity < positions.shape[0]:
                self.footprints = Footprints(positions.shape[0])
            self._splat_items(positions, count, eye, right, up, forward, coarse_focal)
        elif count:
            self._splat(positions, count, eye, right, up, forward, coarse_focal)
        # The thickness is smoothed in the first round only: it needs no edges kept, and one round of
        # σ/√rounds is smooth enough for a tint.
        self._filter(
            self.depth,
            self.depth_pass,
            0,
            1,
            coarse_focal,
            self.thickness_steps,
            self.quantum,
            self.thickness_pass,
            True,
        )
        self._filter(
            self.depth_pass, self.smooth_depth, 1, 0, coarse_focal, self.thickness_pass, 1.0, self.thickness, True
        )
        for _ in range(FILTER_ROUNDS - 1):
            for source, target, step_row, step_col in (
                (self.smooth_depth, self.depth_pass, 0, 1),
                (self.depth_pass, self.smooth_depth, 1, 0),
            ):
                self._filter(
                    source, target, step_row, step_col, coarse_focal, self.thickness, 1.0, self.thickness, False
                )
        self._normals(eye, right, up, forward, coarse_focal)
        self._shade(eye, right, up, forward, coarse_focal, ti.Vector(np.asarray(light_direction, np.float32)))
        self._compose()
        if self.segment_count:
            self._lines(eye, right, up, forward, focal)
