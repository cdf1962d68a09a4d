"""A screen-space fluid renderer for headless frames: water as a smooth, refracting, tinted surface.

The method is van der Laan, Green & Sainz 2009 ("Screen space fluid rendering with curvature
flow", I3D), with the depth smoothed by the narrow-range filter of Truong & Yuksel 2018 ("A
narrow-range filter for screen-space fluid rendering", PACMCGIT 1(1)), all as Taichi kernels. Passes
1-4 run at half the image's resolution in each direction (the filter's width in pixels halves too, so
a quarter of the pixels costs an eighth); only the composition is at full resolution.

1. *Splat.* Every particle is an ellipsoid (``pbf.app.splat.Ellipsoids``: a sphere without neighbour
   lists); each pixel keeps the nearest one's view depth and adds the chord its ray cuts through each,
   scaled by (particle volume / splat volume) so that the sum is the ray's path length through water
   however much the splats overlap. The chords are added as fixed-point integers, so the sum does not
   depend on the order they are added in and the image is the same on every run. On the CPU a thread
   per band of rows owns its pixels; on a GPU a thread per (splat, pixel) adds by atomics.
2. *Smooth.* The narrow-range filter, separably along rows then columns: a Gaussian over the pixels
   within a few spacings (its width in pixels shrinks with depth), in which a sample more than the
   threshold μ off the surface, behind it (another layer, the background) or in front of it (a drop),
   belongs to another surface. We take the samples in pairs about the centre and put in place of a
   sample off the surface its partner's mirror image about the centre (a pair with both off is left
   out), so that every pixel of a surface keeps the Gaussian's full weight and a slope stays balanced.
   From the second pass on, the range at each tap is centred on the plane through the centre with
   the slope of its nearest neighbours, so that a surface seen at a slant is smoothed over the
   filter's whole width. The range never depends on the samples taken: a rule that clamped samples
   in front into it and widened it around each pair let one pixel of a row take in a layer that the
   next left out, and the pass along the other axis spread each such jump into a band, covering
   splashes with axis-aligned rectangles. Silhouettes stay where the particles are; the bumps of
   single particles go. The thickness gets a plain Gaussian.
3. *Normals* from the smoothed depth by finite differences, taking on each axis the smaller of the
   forward and backward difference so that normals do not bend over edges (van der Laan et al., §4).
4. *Shade.* Schlick's Fresnel term mixes the reflection of a sky gradient with the refracted view of
   a tiled floor (Snell's law, n = 1.33), tinted by Beer–Lambert absorption along the thickness:
   T = exp(−σ d) per colour channel, the absorbed part replaced by the colour of deep water.
5. *Compose* at full resolution. A pixel's share of water is the interpolation of the coarse
   pixels' coverage (1 water, 0 not): bilinear inside the water, by the cubic B-spline over the 4 × 4
   around a pixel on an outline. It blends the water's colour, interpolated from the coarse pixels
   that are water, over the view without water (floor and sky, computed once per camera and kept):
   silhouettes are anti-aliased curves rather than 2-pixel steps (bilinear coverage alone left a
   sawtooth along a block's straight edges). Where the bilinear coverage reaches ½ the pixel has the
   water's depth, against which the lines are drawn.

Everything reads positions as Taichi fields and writes an (H, W, 3) uint8 image; nothing here
changes the simulation.
"""

import math

import numpy as np
import taichi as ti

from pbf.app.constants import colour
from pbf.app.pinhole import aim, camera_field
from pbf.app.splat import Ellipsoids, Footprints, per_item
from pbf.app.white_water import Sprites
from pbf.solver import allocation as bucket
from pbf.solver import scene_constants

FAR = 1e30
"""Depth of a pixel no water covers, m."""
NEAR_M = 1e-3
"""Line segments are clipped this far in front of the eye."""
COARSE = 2
"""The surface passes run at 1/COARSE of the image's width and height."""
BAND_ROWS = 16
"""On the CPU backend the splat pass gives each thread a band of this many coarse rows (``_splat``)."""
SPLAT_RADIUS_SPACINGS = 0.75
"""Sphere radius of a particle in the splat, in spacings: more than √2/2, so that a lattice of
particles seen along one of its axes leaves no pinholes between its spheres."""
FILTER_SIGMA_SPACINGS = 1.5
"""Standard deviation of the smoothing, in spacings (in pixels: f σ / depth)."""
FILTER_ROUNDS = 1
"""Rounds of (rows, columns), each a Gaussian of σ/√rounds (together one of σ). Two rounds hid some of
the streaks the separable filter left while its range grew with the samples it took; with a range
that follows the surface's slope, one round leaves no more axis-aligned steps (tests/test_surface_render.py)
and costs a quarter less."""
ROUND_SIGMA_SPACINGS = FILTER_SIGMA_SPACINGS / math.sqrt(FILTER_ROUNDS)
FILTER_MAX_RADIUS_PX = 24
"""Widest filter, in coarse pixels each side: bounds the cost of water close to the camera."""
THRESHOLD_SPACINGS = 1.0
"""The narrow range μ: a sample this far off the surface (behind or in front of the centre pixel, or of
its plane) belongs to another surface."""
THICKNESS_STEPS_PER_SPACING = 4096
"""Fixed-point resolution of the thickness sum (integer atomics are order-independent)."""
WATER_IOR = 1.33
FRESNEL_F0 = 0.02
"""Reflectance of water at normal incidence, ((n − 1)/(n + 1))² (Schlick 1994)."""
ZENITH_RGB = (0.42, 0.6, 0.85)
SUN_DIRECTION = tuple(c / math.sqrt(0.5**2 + 0.6**2 + 1.0**2) for c in (-0.5, 0.6, -1.0))
"""Towards the sky's sun: behind the scene and up, where the default camera (in front, to the right,
above) sees it mirrored in a level surface near the middle of the image."""
SUN_GLOW = 4.0
"""Brightness of the sun's glow over the sky's (the water mirrors it by Fresnel's 2-10% at these angles)."""
SUN_GLOW_POWER = 24.0
"""Sharpness of the glow: it falls to half about 14° from the sun."""
SPECULAR_EXPONENT = 256.0
"""Blinn-Phong exponent of the sun's highlight on a smooth surface (lowered where the surface is rough)."""
THROUGH_BLUR = 0.3
"""How much what is seen through water blurs, per metre of water per metre of distance (an angle per the
path's share of the ray): through a block half a metre thick, the floor's tiles blend; through a film, no
blur."""
FLOOR_RGB = ((0.80, 0.80, 0.78), (0.62, 0.64, 0.66))
"""The two colours of the floor's tiles."""
BODY_AMBIENT = 0.35
"""A rigid body's brightness on its faces turned from the light, of its lit colour."""
SEGMENT_FLOOR = 16
"""The fewest line segments the renderers allocate (``pbf.solver.allocation``): the container's 12
edges fit, and with an obstacle's the next bucket, so most scenes share the line kernels' compile."""
BODY_FLOOR = 8
"""The fewest rigid bodies the renderers allocate poses for (``pbf.solver.allocation``)."""


@ti.func
def _bspline(t):
    """The uniform cubic B-spline's weights of the four samples around t ∈ [0, 1] (at −1, 0, 1, 2)."""
    s = 1.0 - t
    middle = ti.Vector([(3.0 * t - 6.0) * t * t + 4.0, ((-3.0 * t + 3.0) * t + 3.0) * t + 1.0])
    return ti.Vector([s * s * s, middle[0], middle[1], t * t * t]) / 6.0


@ti.data_oriented
class SurfaceRenderer:
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
        solids=None,
        body_rgb=None,
        exposure_s=0.0,
    ):
        """The floor is the plane y = ``floor_y_m`` in square tiles of ``tile_m``; ``absorption_per_m``
        is Beer–Lambert's σ for red, green and blue; ``water_rgb`` the colour of deep water;
        ``horizon_rgb`` the sky's colour at the horizon (the zenith is blue). ``solids``: a
        simulation's rigid bodies (``Simulation.solids()``), drawn as solids of ``body_rgb`` from their
        device fields as they stand at each draw. ``exposure_s``: how long a frame's exposure lasts (motion
        blur of drops and white water), s."""
        # The image size stays in the kernels' code (a view setting, the same for most runs); what
        # depends on the scene is data (``constants``, and fields sized by buckets), so that a scene of
        # another spacing, container or colours finds these kernels compiled (``pbf.solver.scene_constants``).
        self.width, self.height = int(width_px), int(height_px)
        self.coarse_width, self.coarse_height = self.width // COARSE, self.height // COARSE
        self.spacing = float(spacing_m)
        self.floor_y = float(floor_y_m)
        self.radius = SPLAT_RADIUS_SPACINGS * self.spacing
        self.quantum = self.spacing / THICKNESS_STEPS_PER_SPACING
        """The thickness sum's step, m (a fixed-point unit)."""
        self.solids = solids if solids is not None and solids.count else None
        self.with_solids = self.solids is not None
        """Whether the kernels draw rigid bodies: a switch that removes code, so part of the compile."""
        body_count = self.solids.count if self.with_solids else 0
        self.constants = scene_constants(
            spacing=self.spacing,
            radius=self.radius,
            # Each sphere's chord counts (particle volume / sphere volume): overlapping spheres then add
            # up to the path length through the water they stand for.
            chord_scale=particle_volume_m3 / (4.0 / 3.0 * math.pi * self.radius**3),
            floor_y=float(floor_y_m),
            # Reciprocals, multiplied by: a division by a number in the code compiled to that product,
            # and a division by data would round otherwise and move pixels by a level.
            inverse_quantum=1.0 / self.quantum,
            inverse_tile=1.0 / float(tile_m),
            inverse_fade=1.0 / (20.0 * float(tile_m)),
            absorption=colour(absorption_per_m),
            water=colour(water_rgb),
            horizon=colour(horizon_rgb),
            line_colour=colour(line_rgb),
            body_colour=colour(body_rgb or (0.0, 0.0, 0.0)),
            body_count=body_count,
        )
        """The scene's numbers the kernels read: spacing and splat radius (m), the chord's scale, the floor's
        height (m), 1 / the thickness sum's step, 1 / the tile and 1 / the floor's fading distance (1/m),
        the water's absorption (1/m), the colours, and the number of rigid bodies."""
        slots = bucket(body_count, BODY_FLOOR)
        self.solid_sphere = ti.field(ti.i32, shape=slots)
        self.solid_half = ti.Vector.field(3, ti.f32, shape=slots)
        self.solid_position = ti.Vector.field(3, ti.f32, shape=slots)
        self.solid_rotation = ti.Matrix.field(3, 3, ti.f32, shape=slots)
        """The rigid bodies' shapes and poses, copied from the solver's fields at each draw
        (:meth:`_take_solids`) into fields of a bucket's size, so that the kernels that draw them do not
        depend on the shapes of the solver's fields, which are sized by the scene's count of bodies."""
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
        self.camera = camera_field()
        """The view (the focal lengths of the frame and of the coarse image) and light of the current draw
        (``pbf.app.pinhole.aim``), set once a draw for its kernels and the white water's sprites."""
        self.span = ti.Vector.field(2, ti.i32, shape=self.coarse_height)
        """Per coarse row, the first and last column of water or white water (first > last: none), from
        which :meth:`_compose` tells the pixels that show the background alone."""
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
        self.exposure = float(exposure_s)
        self.sprites = Sprites(self.coarse_width, self.coarse_height, self.spacing, self.per_item)
        """White water's sprites (``pbf.app.white_water``): their sums, filled where a draw is given white
        water, whiten the frame in :meth:`_compose`."""
        self.footprints = None
        self.splats = None
        """The particles' splats (``pbf.app.splat.Ellipsoids``), allocated on first use for the positions'
        capacity."""
        self.splat_rows = None
        """Per splat, the coarse rows [first, last + 1) of its bounding disc (``_splat``, CPU backend)."""
        points = np.zeros((0, 3), np.float32) if segments is None else np.asarray(segments, np.float32)
        self.segment_points = points.reshape(-1, 2, 3).astype(np.float64)
        """The line segments' end points, m (a few: the container's edges)."""
        segment_slots = bucket(len(self.segment_points), SEGMENT_FLOOR)
        self.screen_segments = ti.Vector.field(6, ti.f32, shape=segment_slots)
        """Per segment on screen, for the view of the last draw: (column, row, 1/depth) of each end."""
        self.line_steps = ti.field(ti.i32, shape=segment_slots)
        """Pixels each segment spans along its longer screen axis (0: not in view)."""

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
        """The sky along unit direction d: horizon colour below, blending to blue at the zenith, with the
        glow of a low sun behind the scene (as the default camera sees it), which a calm water surface
        mirrors as a bright sheen: without it the sky it reflects is as blue as the water."""
        horizon = self.constants[None].horizon
        sky = horizon + (ti.Vector(ZENITH_RGB) - horizon) * ti.sqrt(ti.max(d.y, 0.0))
        glow = ti.max(d.dot(ti.Vector(SUN_DIRECTION)), 0.0) ** SUN_GLOW_POWER
        return sky + SUN_GLOW * glow * (d.y > 0.0)

    @ti.func
    def _tiles(self, x, width):
        """Mean over [x − width/2, x + width/2] (in tiles) of the square wave that is 1 on odd tiles:
        (F(x + w/2) − F(x − w/2)) / w with F(x) = ⌊x/2⌋ + max(x − 2⌊x/2⌋ − 1, 0) its integral, the
        point value where the window is far below a tile."""
        value = ti.cast(ti.cast(ti.floor(x), ti.i32) & 1, ti.f32)
        if width > 1e-3:
            a, b = x - 0.5 * width, x + 0.5 * width
            upper = ti.floor(0.5 * b) + ti.max(b - 2.0 * ti.floor(0.5 * b) - 1.0, 0.0)
            lower = ti.floor(0.5 * a) + ti.max(a - 2.0 * ti.floor(0.5 * a) - 1.0, 0.0)
            value = (upper - lower) / width
        return value

    @ti.func
    def _environment(self, origin, d, spread, travelled):
        """What a ray from ``origin`` along unit ``d`` sees without water: the tiled floor plane, fading
        into the horizon with distance, or the sky. ``spread`` is the angle one pixel spans (radians)
        and ``travelled`` how far its ray came from the eye to ``origin`` (m): the floor is averaged
        over the pixel's footprint on it (a box filter of the checkerboard), so tiles smaller than a
        pixel blend to their mean instead of aliasing into moiré."""
        (inverse_tile, floor_y, inverse_fade, horizon) = (
            self.constants[None].inverse_tile,
            self.constants[None].floor_y,
            self.constants[None].inverse_fade,
            self.constants[None].horizon,
        )
        colour = self._sky(d)
        if d.y < -1e-6:
            t = (floor_y - origin.y) / d.y
            if t > 0.0:
                hit = origin + t * d
                # The footprint is an ellipse t·spread across the ray and t·spread/|d.y| along its track
                # on the floor; the box filter takes its extent along x and along z.
                across = (travelled + t) * spread
                along = across / ti.max(-d.y, 1e-3)
                track = ti.Vector([d.x, d.z])
                track = track / ti.max(track.norm(), 1e-12)
                width_x = ti.sqrt((along * track[0]) ** 2 + (across * track[1]) ** 2) * inverse_tile
                width_z = ti.sqrt((along * track[1]) ** 2 + (across * track[0]) ** 2) * inverse_tile
                odd_x, odd_z = self._tiles(hit.x * inverse_tile, width_x), self._tiles(hit.z * inverse_tile, width_z)
                tile = odd_x + odd_z - 2.0 * odd_x * odd_z  # the mean of odd_x XOR odd_z (the box is separable)
                floor = ti.Vector(FLOOR_RGB[0]) * (1.0 - tile) + ti.Vector(FLOOR_RGB[1]) * tile
                fade = 1.0 / (1.0 + t * inverse_fade)  # the floor greys out into the horizon
                colour = floor * fade + horizon * (1.0 - fade)
        return colour

    @ti.func
    def _hit_solid(self, origin, d):
        """The nearest rigid body along the ray origin + t d, t > 0: (t, the body's unit normal there);
        t = FAR where it meets none. A box by the slab method in its own frame, a sphere by the
        quadratic; the axes are a static loop (no runtime index into a vector: SPIR-V)."""
        nearest, normal = FAR, ti.Vector([0.0, 1.0, 0.0])
        for b in range(self.constants[None].body_count):
            centre = self.solid_position[b]
            half = self.solid_half[b]
            if self.solid_sphere[b]:
                offset = origin - centre
                a, half_b = d.norm_sqr(), offset.dot(d)
                disc = half_b * half_b - a * (offset.norm_sqr() - half[0] * half[0])
                if disc >= 0.0:
                    t = (-half_b - ti.sqrt(disc)) / a
                    if 1e-6 < t < nearest:
                        nearest, normal = t, (offset + t * d) / half[0]
            else:
                rotation = self.solid_rotation[b]
                o, local = rotation.transpose() @ (origin - centre), rotation.transpose() @ d
                enter, leave, face = -FAR, FAR, ti.Vector([0.0, 1.0, 0.0])
                for axis in ti.static(range(3)):
                    step = ti.select(ti.abs(local[axis]) > 1e-12, local[axis], 1e-12)
                    t1, t2 = (-half[axis] - o[axis]) / step, (half[axis] - o[axis]) / step
                    if ti.min(t1, t2) > enter:
                        enter = ti.min(t1, t2)
                        face = ti.Vector([float(axis == 0), float(axis == 1), float(axis == 2)]) * -ti.math.sign(step)
                    leave = ti.min(leave, ti.max(t1, t2))
                if enter <= leave and 1e-6 < enter < nearest:
                    nearest, normal = enter, rotation @ face
        return nearest, normal

    @ti.kernel
    def _take_solids(
        self, sphere: ti.template(), half: ti.template(), position: ti.template(), rotation: ti.template()
    ):
        """The solver's bodies' shapes and poses into this renderer's fields. The one kernel here that
        touches the solver's body fields (sized by the scene's count of bodies): a scene of another
        count recompiles it alone."""
        for b in range(self.constants[None].body_count):
            self.solid_sphere[b] = sphere[b]
            self.solid_half[b] = half[b]
            self.solid_position[b] = position[b]
            self.solid_rotation[b] = rotation[b]

    @ti.func
    def view(self):
        """The draw's eye, its unit axes and the coarse image's focal length (``camera``)."""
        cam = self.camera[None]
        return cam.eye, cam.right, cam.up, cam.forward, cam.coarse_focal

    @ti.func
    def front_depth(self, row, col, eye, right, up, forward, focal):
        """The view depth of the nearest water or body at coarse pixel (row, col) (FAR where there is
        neither), for the white water's sprites; ``focal`` of the coarse image."""
        depth = self.smooth_depth[row, col]
        if ti.static(self.with_solids):
            ray = self._ray(row, col, right, up, forward, focal, self.coarse_width, self.coarse_height)
            depth = ti.min(depth, self._hit_solid(eye, ray)[0])
        return depth

    @ti.func
    def _solid_colour(self, normal, light):
        """A body's colour lit from unit ``light`` (towards the light), with an ambient part."""
        return self.constants[None].body_colour * (BODY_AMBIENT + (1.0 - BODY_AMBIENT) * ti.max(normal.dot(light), 0.0))

    @ti.kernel
    def _environment_image(self):
        for row, col in self.background:
            cam = self.camera[None]
            eye, right, up, forward, focal = cam.eye, cam.right, cam.up, cam.forward, cam.focal
            ray = self._ray(row, col, right, up, forward, focal, self.width, self.height)
            # A pixel spans 1/focal in the image plane at unit depth: 1/(focal |ray|²) radians off axis.
            colour = self._environment(eye, ray.normalized(), 1.0 / (focal * ray.norm_sqr()), 0.0)
            self.background[row, col] = ti.cast(ti.min(colour, 1.0) * 255.0 + 0.5, ti.u8)

    # ------------------------------------------------------------------ the coarse surface passes

    @ti.kernel
    def _clear(self):
        for row, col in ti.ndrange(self.coarse_height, self.coarse_width):
            self.depth[row, col] = FAR
            self.thickness_steps[row, col] = 0

    @ti.func
    def _bound(self, splats: ti.template(), i, eye, right, up, forward, focal):
        """Splat i's screen disc on the coarse image: (row, column of its centre's image, its radius in
        pixels), radius 0 where the splat is not wholly in front of the eye. The bounding sphere of
        radius ``reach`` images to an ellipse of semi-major axis f r √(|c|² − r²) / (d² − r²), within
        f r |c| / ((d − r) d) of the centre's image; the 10% covers the ellipse's centre lying a little
        off the centre's image (by about (r/d)² of its distance from the middle), and the bounds'
        rounding takes in every pixel whose centre is inside. (A pixel more of margin, as the sphere
        renderer keeps, gave the same frames here and a third more pixels to test.)"""
        reach = splats.reach[i]
        centre = splats.centre[i] - eye
        depth = centre.dot(forward)
        row, col, extent = 0.0, 0.0, 0.0
        if depth > reach * 1.01:
            col = 0.5 * self.coarse_width + focal * centre.dot(right) / depth
            row = 0.5 * self.coarse_height - focal * centre.dot(up) / depth
            extent = 1.1 * focal * reach * centre.norm() / ((depth - reach) * depth)
        return row, col, extent

    @ti.func
    def _row(self, splats: ti.template(), seen: ti.template(), r, focal):
        """Row r of a splat (``seen``: its ``Ellipsoids.frame``): its rays' coefficients
        (``Ellipsoids.row``), and the columns [c0, c1) whose pixel centres lie within its outline."""
        w = (0.5 * self.coarse_height - r - 0.5) / focal
        a, b, d, lower, upper = splats.row(seen, w)
        c0, c1 = 0, 0
        if lower <= upper:
            middle = 0.5 * self.coarse_width - 0.5  # the column whose centre is at u = 0
            first = ti.cast(ti.ceil(ti.max(lower * focal + middle, -1.0)), ti.i32)
            last = ti.cast(ti.floor(ti.min(upper * focal + middle, self.coarse_width)), ti.i32)
            c0, c1 = ti.max(0, first), ti.min(self.coarse_width, last + 1)
        return a, b, d, w, c0, c1

    @ti.func
    def _splat_pixel(self, splats: ti.template(), a, b, d, w, scale, r, c, focal):
        """A splat's row r (a, b, d, w: :meth:`_row`'s) at coarse pixel (r, c), by atomics (threads of
        other splats write the pixel too): the nearest depth, and the chord its ray cuts times ``scale``
        (particle volume / sphere volume × the splat's share of the sphere's volume / the thickness step)
        as fixed-point steps."""
        u = (c + 0.5 - 0.5 * self.coarse_width) / focal
        t, chord = splats.hit(a, b, d, u, w)
        if t > 0.0:
            if t < self.depth[r, c]:  # a plain read first: most splats lie behind a nearer one
                ti.atomic_min(self.depth[r, c], t)
            ti.atomic_add(self.thickness_steps[r, c], ti.cast(chord * scale + 0.5, ti.i32))

    @ti.func
    def _chord_scale(self, splats: ti.template(), i):
        return splats.chord[i] * self.constants[None].chord_scale * self.constants[None].inverse_quantum

    @ti.kernel
    def _splat(self, splats: ti.template(), count: ti.i32):
        """The CPU backend's splat: a thread per band of ``BAND_ROWS`` coarse rows, which walks the splats
        in order and, of those whose bounding disc reaches into its band, the rows within the band and on
        each the columns within the splat's outline (:meth:`_row`). A thread alone writes its band's
        pixels, so it keeps the nearest depth and adds the chords with plain reads and writes, not the
        atomics that a thread per splat needs (their cost was most of the pass); the sums are of integers
        and the least depth is the least in any order, so the image is the same. Half of the bounding
        disc's pixels lie outside the outline of a flattened splat, and testing them cost more than their
        share: a hit and a miss side by side defeat the branch predictor."""
        height = self.coarse_height
        for i in range(count):
            eye, right, up, forward, focal = self.view()
            row, col, extent = self._bound(splats, i, eye, right, up, forward, focal)
            r0, r1 = 0, 0
            if extent > 0.0:
                r0, r1 = ti.max(0, ti.cast(row - extent, ti.i32)), ti.min(height, ti.cast(row + extent, ti.i32) + 1)
            self.splat_rows[i] = ti.Vector([r0, r1])
        for band in range((height + BAND_ROWS - 1) // BAND_ROWS):
            low, high = band * BAND_ROWS, ti.min((band + 1) * BAND_ROWS, height)
            eye, right, up, forward, focal = self.view()
            for i in range(count):
                rows = self.splat_rows[i]
                if rows[0] < high and rows[1] > low:
                    seen = splats.frame(i, eye, right, up, forward)
                    scale = self._chord_scale(splats, i)
                    for r in range(ti.max(rows[0], low), ti.min(rows[1], high)):
                        a, b, d, w, c0, c1 = self._row(splats, seen, r, focal)
                        for c in range(c0, c1):
                            u = (c + 0.5 - 0.5 * self.coarse_width) / focal
                            t, chord = splats.hit(a, b, d, u, w)
                            if t > 0.0:  # (``+=`` would compile to an atomic add)
                                steps = self.thickness_steps[r, c] + ti.cast(chord * scale + 0.5, ti.i32)
                                self.depth[r, c] = ti.min(self.depth[r, c], t)
                                self.thickness_steps[r, c] = steps

    @ti.kernel
    def _splat_items(self, splats: ti.template(), count: ti.i32):
        """:meth:`_splat` on a GPU backend: a thread per (particle, pixel) of each particle's bounding
        square (``pbf.app.splat``), by atomics; the same tests and integer sums, so the same image."""
        width, height = self.coarse_width, self.coarse_height
        for i in range(count):
            eye, right, up, forward, focal = self.view()
            row, col, extent = self._bound(splats, i, eye, right, up, forward, focal)
            c0, c1, r0, r1 = 0, 0, 0, 0
            if extent > 0.0:
                r0, r1 = ti.max(0, ti.cast(row - extent, ti.i32)), ti.min(height, ti.cast(row + extent, ti.i32) + 1)
                c0, c1 = ti.max(0, ti.cast(col - extent, ti.i32)), ti.min(width, ti.cast(col + extent, ti.i32) + 1)
            self.footprints.set(i, c0, c1, r0, r1)
        self.footprints.scan(count)
        for item in range(self.footprints.total(count)):
            i, c, r = self.footprints.item(item, count)
            eye, right, up, forward, focal = self.view()
            # The CPU's bands visit only the columns within the splat's outline; so does this.
            seen = splats.frame(i, eye, right, up, forward)
            a, b, d, w, c0, c1 = self._row(splats, seen, r, focal)
            if c0 <= c < c1:
                self._splat_pixel(splats, a, b, d, w, self._chord_scale(splats, i), r, c, focal)

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
        follow_slope: ti.template(),
    ):
        """One separable pass of the narrow-range filter along (step_row, step_col), and of a plain
        Gaussian over the thickness when ``with_thickness``. ``follow_slope``: the range is centred on
        the plane through the centre pixel with the slope of its nearest neighbours along the pass (for
        a smoothed input; on the splat's raw depth one pixel's slope is the bumps of single spheres)."""
        for row, col in ti.ndrange(self.coarse_height, self.coarse_width):
            spacing = self.constants[None].spacing
            mu = THRESHOLD_SPACINGS * spacing
            z = depth_in[row, col]
            depth_out[row, col] = z
            if ti.static(with_thickness):
                thickness_out[row, col] = thickness_in[row, col] * thickness_unit
            if z < FAR:
                sigma = focal * ROUND_SIGMA_SPACINGS * spacing / z
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
                # The surface's change of depth per pixel along the pass, from the nearest pair (or the one
                # neighbour) within the range: the range at tap k is centred on z ± k · slope.
                slope = 0.0
                if ti.static(follow_slope) and reach >= 1:
                    after, before = depth_in[row + step_row, col + step_col], depth_in[row - step_row, col - step_col]
                    after_in, before_in = ti.abs(after - z) <= mu, ti.abs(before - z) <= mu
                    if after_in and before_in:
                        slope = 0.5 * (after - before)
                    elif after_in:
                        slope = after - z
                    elif before_in:
                        slope = z - before
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
                    # A sample more than μ off the plane (behind it: the background or a layer behind; in
                    # front: a drop or a layer in front) is another surface. Its partner's mirror image
                    # about the centre takes its place, so that every pixel of a surface keeps the full
                    # Gaussian's weight and a slope stays balanced about the centre; a pair with both
                    # samples off is left out. The range is the same at every pixel, neither clamped nor
                    # grown from the samples: a decision that jumped from one pixel to the next along this
                    # pass (a layer let in here, left out there) was spread along the other axis by the
                    # next pass, which covered splashes with axis-aligned rectangles of different shades.
                    a_in, b_in = ti.abs(a - (z + k * slope)) <= mu, ti.abs(b - (z - k * slope)) <= mu
                    if a_in or b_in:
                        if not a_in:
                            a = 2.0 * z - b
                        if not b_in:
                            b = 2.0 * z - a
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
        """The change of surface position to the next pixel along (step_row, step_col): the central
        difference where both neighbours lie on this surface (within the filter's range μ), else the
        one-sided difference that changes depth less and lies on water (van der Laan et al. 2009, §4).
        Picking the smaller one-sided difference everywhere flipped between the two sides from pixel to
        pixel wherever the smoothed surface curved a little, and the normals had the grain of single
        pixels (speckle, ``python -m benchmarks.frames look``)."""
        here = self._position(row, col, eye, right, up, forward, focal)
        z = self.smooth_depth[row, col]
        mu = THRESHOLD_SPACINGS * self.constants[None].spacing
        best = ti.Vector([0.0, 0.0, 0.0])
        best_change = FAR
        both = 0
        for sign in ti.static((1, -1)):
            r, c = row + sign * step_row, col + sign * step_col
            if 0 <= r < self.coarse_height and 0 <= c < self.coarse_width:
                neighbour = self.smooth_depth[r, c]
                if neighbour < FAR and ti.abs(neighbour - z) <= mu:
                    both += 1
                if neighbour < FAR and ti.abs(neighbour - z) < best_change:
                    best_change = ti.abs(neighbour - z)
                    best = sign * (self._position(r, c, eye, right, up, forward, focal) - here)
        if both == 2:
            after = self._position(row + step_row, col + step_col, eye, right, up, forward, focal)
            before = self._position(row - step_row, col - step_col, eye, right, up, forward, focal)
            best = 0.5 * (after - before)
        return best

    @ti.kernel
    def _normals(self):
        for row, col in ti.ndrange(self.coarse_height, self.coarse_width):
            normal = ti.Vector([0.0, 0.0, 0.0])
            if self.smooth_depth[row, col] < FAR:
                eye, right, up, forward, focal = self.view()
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
    def _shade(self):
        """The colour of every coarse pixel of water."""
        for row, col in ti.ndrange(self.coarse_height, self.coarse_width):
            z = self.smooth_depth[row, col]
            if z < FAR:
                eye, right, up, forward, focal = self.view()
                light = self.camera[None].light
                normal = self.normal[row, col]
                direction = self._ray(row, col, right, up, forward, focal, self.coarse_width, self.coarse_height)
                point = eye + z * direction
                # The floor seen in and through the water is averaged over two coarse pixels' angle: the
                # colours are interpolated between coarse pixels, and a footprint of one would leave a
                # tile's edge as steps of a coarse pixel.
                spread = 2.0 / (focal * direction.norm_sqr())
                travelled = z * direction.norm()
                direction = direction.normalized()
                cosine = ti.max(-normal.dot(direction), 0.0)
                grazing = 1.0 - cosine
                fresnel = FRESNEL_F0 + (1.0 - FRESNEL_F0) * grazing * grazing * grazing * grazing * grazing
                reflected = self._environment(point, direction + 2.0 * cosine * normal, spread, travelled)
                eta = 1.0 / WATER_IOR
                k = 1.0 - eta * eta * (1.0 - cosine * cosine)
                refracted = (eta * direction + (eta * cosine - ti.sqrt(ti.max(k, 0.0))) * normal).normalized()
                path = self.thickness[row, col]
                # Deep water blurs what lies behind it (scattering, and the normals' error over a long path):
                # the view through it is averaged over a footprint that widens with the path. A sharp view
                # squeezed the floor's tiles into horizontal bands across every block of water.
                through = spread + THROUGH_BLUR * path / (travelled + path)
                behind = self._environment(point, refracted, through, travelled)
                if ti.static(self.with_solids):  # a body under the surface, seen through the water
                    hit, hit_normal = self._hit_solid(point, refracted)
                    if hit < FAR:
                        path = ti.min(path, hit)
                        behind = self._solid_colour(hit_normal, light)
                transmittance = ti.exp(-self.constants[None].absorption * path)
                transmitted = behind * transmittance + self.constants[None].water * (1.0 - transmittance)
                # Blinn-Phong, its exponent lowered where the normals within the pixel's neighbourhood
                # disagree (Toksvig 2005, "Mipmapping normal maps": with n̄ the mean of the unit normals,
                # s' = |n̄| s / (|n̄| + s (1 − |n̄|))) and scaled by (s' + 8)/(s + 8) to keep its energy: a
                # bumpy patch of spray then shows a dim broad sheen instead of single bright pixels.
                mean_normal = ti.Vector([0.0, 0.0, 0.0])
                count = 0.0
                for dr, dc in ti.static(ti.ndrange((-1, 2), (-1, 2))):
                    r, c = row + dr, col + dc
                    if 0 <= r < self.coarse_height and 0 <= c < self.coarse_width:
                        around = self.normal[r, c]
                        mean_normal += around
                        count += around.norm_sqr()  # 1 for water, 0 for none
                agreement = ti.min(mean_normal.norm() / ti.max(count, 1.0), 1.0)
                exponent = agreement * SPECULAR_EXPONENT / (agreement + SPECULAR_EXPONENT * (1.0 - agreement))
                halfway = (light - direction).normalized()
                specular = (
                    ti.pow(ti.max(normal.dot(halfway), 0.0), exponent) * (exponent + 8.0) / (SPECULAR_EXPONENT + 8.0)
                )
                self.colour[row, col] = (1.0 - fresnel) * transmitted + fresnel * reflected + 0.8 * specular

    @ti.kernel
    def _compose(self):
        """Full resolution: water where the coarse coverage interpolates to ½ or more, its colour and
        depth interpolated from the coarse pixels of water; elsewhere the background, or a rigid body
        where one is nearer than the water; all of it whitened by the white water's sprites. First each
        coarse row's span of water and white water, so that a pixel far from both copies the background
        at once; last the sprites' sums cleared for the next frame."""
        for r in range(self.coarse_height):
            first, last = self.coarse_width, -1
            for c in range(self.coarse_width):
                if self.smooth_depth[r, c] < FAR or self.sprites.visible(r, c):
                    first = ti.min(first, c)
                    last = c
            self.span[r] = ti.Vector([first, last])
        if ti.static(self.per_item):  # a GPU backend: a thread per pixel
            for row, col in self.image:
                self._compose_pixel(row, col, self.camera[None])
        else:
            # The CPU backend: a thread per row, along it in order, which costs less than a loop over the
            # field's pixels for this light work per pixel (docs/RENDERING.md, "Cost").
            for row in range(self.height):
                cam = self.camera[None]
                for col in range(self.width):
                    self._compose_pixel(row, col, cam)
        self.sprites.clear()

    @ti.func
    def _compose_pixel(self, row, col, cam):
        """:meth:`_compose` at one pixel; ``cam`` the draw's (``camera``)."""
        # The four coarse pixels around this pixel's centre, and their bilinear weights.
        y = (row + 0.5) / COARSE - 0.5
        x = (col + 0.5) / COARSE - 0.5
        r0 = ti.min(ti.max(ti.cast(ti.floor(y), ti.i32), 0), self.coarse_height - 2)
        c0 = ti.min(ti.max(ti.cast(ti.floor(x), ti.i32), 0), self.coarse_width - 2)
        near = 1  # with bodies, every pixel: a body may lie anywhere, and the pixel casts its ray
        if ti.static(not self.with_solids):  # most pixels have neither water nor white water around them
            first = ti.min(self.span[r0][0], self.span[r0 + 1][0])
            near = first <= c0 + 1 and c0 <= ti.max(self.span[r0][1], self.span[r0 + 1][1])
        if not near:  # the view without water, as it is
            self.image[row, col] = self.background[row, col]
            self.image_depth[row, col] = FAR
        else:
            self._compose_near(row, col, r0, c0, y - r0, x - c0, cam)

    @ti.func
    def _compose_near(self, row, col, r0, c0, fy, fx, cam):
        """:meth:`_compose` at a pixel (row, col) with water, white water or a body near: (r0, c0) the first
        of the four coarse pixels around it, (fy, fx) its place between them."""
        solid, solid_colour = FAR, ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.with_solids):
            ray = self._ray(row, col, cam.right, cam.up, cam.forward, cam.focal, self.width, self.height)
            hit_normal = ti.Vector([0.0, 1.0, 0.0])
            solid, hit_normal = self._hit_solid(cam.eye, ray)  # t along a ray of forward part 1: view depth
            solid_colour = self._solid_colour(hit_normal, cam.light)
        fy = ti.min(ti.max(fy, 0.0), 1.0)
        fx = ti.min(ti.max(fx, 0.0), 1.0)
        coverage, depth, corners = 0.0, 0.0, 0
        colour = ti.Vector([0.0, 0.0, 0.0])
        for dr, dc in ti.static(ti.ndrange(2, 2)):
            w = (fy if dr else 1.0 - fy) * (fx if dc else 1.0 - fx)
            sample = self.smooth_depth[r0 + dr, c0 + dc]
            if sample < solid:  # water, and nearer than any body here
                coverage += w
                depth += w * sample
                colour += w * self.colour[r0 + dr, c0 + dc]
                corners += 1
        share = coverage
        if 0 < corners < 4:  # on an outline
            share = self._outline_share(r0, c0, fy, fx, solid)
        white = self.sprites.share(r0, c0, fy, fx)  # white water, over and through the water alike
        if coverage == 0.0 and solid == FAR and white == 0.0:
            self.image[row, col] = self.background[row, col]
        else:
            background = ti.cast(self.background[row, col], ti.f32) / 255.0
            if solid < FAR:
                background = solid_colour
            water = background
            if coverage > 0.0:
                water = ti.min(colour / coverage, 1.0)
            blended = self.sprites.whiten(share * water + (1.0 - share) * background, white)
            self.image[row, col] = ti.cast(blended * 255.0 + 0.5, ti.u8)
        self.image_depth[row, col] = solid
        if coverage >= 0.5:
            self.image_depth[row, col] = depth / coverage

    @ti.func
    def _outline_share(self, r0, c0, fy, fx, solid):
        """The water's share of a pixel on an outline: the coarse pixels' coverage (1 water nearer than
        ``solid``, 0 not) over the 4 × 4 around it, weighted by the cubic B-spline. The bilinear weights of
        the 2 × 2 around it would ramp from 0 to 1 over one coarse pixel too, but their ½ contour follows
        every step of the coarse pixels, which showed as a sawtooth along a block's straight edges; the
        B-spline's is as smooth as its weights (second derivatives continuous) and centred on the outline."""
        wy, wx = _bspline(fy), _bspline(fx)
        share = 0.0
        for i in ti.static(range(4)):
            r = ti.min(ti.max(r0 + i - 1, 0), self.coarse_height - 1)
            across = 0.0
            for j in ti.static(range(4)):
                c = ti.min(ti.max(c0 + j - 1, 0), self.coarse_width - 1)
                across += ti.select(self.smooth_depth[r, c] < solid, wx[j], 0.0)
            share += wy[i] * across
        return share

    def _project_segments(self, view, focal: float) -> None:
        """The segments clipped to the space in front of the eye and projected to the image, into
        ``screen_segments``, with the steps along each one's longer screen axis (a handful of points,
        on the host, once per camera)."""
        right, up, forward = view.basis()
        ends = np.zeros(self.screen_segments.shape + (6,), np.float32)
        steps = np.zeros(self.line_steps.shape, np.int32)  # 0 for the slots past the segments: not drawn
        for s, (a, b) in enumerate(self.segment_points - view.eye):
            depth_a, depth_b = a @ forward, b @ forward
            if depth_a < NEAR_M and depth_b < NEAR_M:
                continue  # behind the eye: no steps
            if depth_a < NEAR_M or depth_b < NEAR_M:  # clip at the near plane
                t = (NEAR_M - depth_a) / (depth_b - depth_a)
                a, b = (a + t * (b - a), b) if depth_a < NEAR_M else (a, a + t * (b - a))
            row = []
            for p in (a, b):
                depth = p @ forward
                row += [0.5 * self.width + focal * (p @ right) / depth, 0.5 * self.height - focal * (p @ up) / depth]
                row.append(1.0 / depth)
            ends[s] = row
            # One step per pixel along the longer axis, clipped to the image (a far-off end point would
            # otherwise ask for millions of steps); 0 when the segment misses the image.
            axis = 0 if abs(row[3] - row[0]) >= abs(row[4] - row[1]) else 1
            size = (self.width, self.height)[axis]
            low = max(math.floor(min(row[axis], row[axis + 3])), 0)
            high = min(math.floor(max(row[axis], row[axis + 3])), size - 1)
            steps[s] = max(high - low + 1, 0)
        self.screen_segments.from_numpy(ends)
        self.line_steps.from_numpy(steps)

    @ti.kernel
    def _lines(self):
        """The segments over the image, anti-aliased: a pixel takes the line's colour by the share of it
        a line one pixel wide covers (1 − the distance from its centre to the segment), where the
        segment is nearer than the water there (depth interpolated as 1/depth, which is linear on the
        screen). Each segment is a parallel loop over its steps along its longer axis, three pixels
        across each step, so no two threads touch one pixel; the segments follow one another, so
        where two cross the later one blends over the earlier, the same way on every run. The loops are
        unrolled over the segments' bucket (``SEGMENT_FLOOR``); a slot past the scene's segments has no
        steps."""
        for s in ti.static(range(self.screen_segments.shape[0])):
            for k in range(self.line_steps[s] * 3):
                ends = self.screen_segments[s]
                a, b = ti.Vector([ends[0], ends[1]]), ti.Vector([ends[3], ends[4]])
                along = b - a
                # The longer axis is "major"; components picked with selects, not a runtime index into
                # a vector (which Taichi's SPIR-V code generator does not compile).
                x_major = ti.abs(along[0]) >= ti.abs(along[1])
                a_major, a_minor = ti.select(x_major, a[0], a[1]), ti.select(x_major, a[1], a[0])
                b_major = ti.select(x_major, b[0], b[1])
                along_major, along_minor = b_major - a_major, ti.select(x_major, along[1], along[0])
                step = ti.max(ti.floor(ti.min(a_major, b_major)), 0.0) + k // 3
                # Where the segment crosses the middle of this step, and the pixels on either side.
                t = 0.0
                if along_major != 0.0:
                    t = ti.min(ti.max((step + 0.5 - a_major) / along_major, 0.0), 1.0)
                across = ti.floor(a_minor + t * along_minor) + (k % 3 - 1)
                col = ti.cast(ti.select(x_major, step, across), ti.i32)
                row = ti.cast(ti.select(x_major, across, step), ti.i32)
                if 0 <= col < self.width and 0 <= row < self.height:
                    centre = ti.Vector([col + 0.5, row + 0.5])
                    nearest = 0.0
                    if along.norm_sqr() > 0.0:
                        nearest = ti.min(ti.max((centre - a).dot(along) / along.norm_sqr(), 0.0), 1.0)
                    distance = (a + nearest * along - centre).norm()
                    depth = 1.0 / ((1.0 - nearest) * ends[2] + nearest * ends[5])
                    if distance < 1.0 and depth < self.image_depth[row, col]:
                        share = 1.0 - distance
                        colour = ti.cast(self.image[row, col], ti.f32) / 255.0
                        blended = share * self.constants[None].line_colour + (1.0 - share) * colour
                        self.image[row, col] = ti.cast(blended * 255.0 + 0.5, ti.u8)

    @ti.kernel
    def _pack(self, out: ti.types.ndarray(dtype=ti.u32, ndim=2)):
        """``image`` as packed RGBA words in GGUI's canvas layout ((W, H), y up)."""
        if ti.static(self.per_item):
            for row, col in self.image:
                self._pack_pixel(out, row, col)
        else:  # the CPU backend: a thread per row, as in _compose
            for row in range(self.height):
                for col in range(self.width):
                    self._pack_pixel(out, row, col)

    @ti.func
    def _pack_pixel(self, out: ti.template(), row, col):
        c = ti.cast(self.image[row, col], ti.u32)
        out[col, self.height - 1 - row] = c[0] | (c[1] << 8) | (c[2] << 16) | ti.u32(0xFF000000)

    @ti.kernel
    def _rgb(self, out: ti.types.ndarray(dtype=ti.u8, ndim=3)):
        """``image`` as an (H, W, 3) host array: on a GPU backend the frame's one copy to the host."""
        if ti.static(self.per_item):
            for row, col in self.image:
                self._rgb_pixel(out, row, col)
        else:  # the CPU backend: a thread per row, as in _compose (a field's to_numpy loops per pixel)
            for row in range(self.height):
                for col in range(self.width):
                    self._rgb_pixel(out, row, col)

    @ti.func
    def _rgb_pixel(self, out: ti.template(), row, col):
        c = self.image[row, col]
        for channel in ti.static(range(3)):
            out[row, col, channel] = c[channel]

    def surface(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The last draw's surface at the coarse passes' resolution (``coarse_height`` × ``coarse_width``,
        row 0 at the top): world-space unit normals (h, w, 3), the water mask (h, w) and the smoothed view
        depth (h, w, m; FAR where no water), for measures of how the surface reads
        (``python -m benchmarks.frames look``)."""
        depth = self.smooth_depth.to_numpy()
        return self.normal.to_numpy(), depth < FAR, depth

    def depth_at(self, col: int, row_up: int) -> float | None:
        """The view depth (m) of the water drawn at pixel (col, row_up) of the last draw (row 0 at the
        bottom), None where there is none."""
        depth = float(self.image_depth[self.height - 1 - row_up, col])
        return depth if depth < FAR else None

    def draw_packed(
        self, view, positions, count: int, light_direction, neighbourhood=None, velocities=None, white_water=None
    ) -> np.ndarray:
        """Like :meth:`render`, as a (W, H) array of packed RGBA words, y up, the layout GGUI's canvas
        shows without a conversion pass (the window's surface mode)."""
        self.draw(view, positions, count, light_direction, neighbourhood, velocities, white_water)
        if self.packed is None:
            self.packed = np.zeros((self.width, self.height), np.uint32)
        self._pack(self.packed)
        return self.packed

    def render(
        self, view, positions, count: int, light_direction, neighbourhood=None, velocities=None, white_water=None
    ) -> np.ndarray:
        """(H, W, 3) uint8 image of the ``count`` particles at ``positions`` (a Taichi vector field, m)
        seen through ``view`` (a ``pbf.app.render.View``), lit from unit ``light_direction``: each particle
        an ellipsoid from ``neighbourhood`` (``Simulation.neighbourhood()`` of these positions), or a sphere
        without it; a drop stretched along its velocity over the exposure where ``velocities`` are given;
        with the diffuse particles of ``white_water`` (``pbf.app.white_water.WhiteWater``) over the water."""
        self.draw(view, positions, count, light_direction, neighbourhood, velocities, white_water)
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        self._rgb(rgb)
        return rgb

    def draw(
        self, view, positions, count: int, light_direction, neighbourhood=None, velocities=None, white_water=None
    ) -> None:
        """Like :meth:`render`, into the device field ``image`` only (row 0 at the top)."""
        focal = view.focal_px(self.height)
        coarse_focal = view.focal_px(self.coarse_height)
        aim(self.camera, view, self.height, light_direction, self.coarse_height)
        key = (tuple(view.eye), tuple(view.target), view.fov_deg)
        if key != self.background_view:  # the view without water and the lines: once per camera
            self._environment_image()
            self._project_segments(view, focal)
            self.background_view = key
        if self.with_solids:
            solids = self.solids
            self._take_solids(solids.sphere, solids.half, solids.position, solids.rotation)
        self._clear()
        if count:
            if self.splats is None or self.splats.capacity < positions.shape[0]:
                self.splats = Ellipsoids(positions.shape[0], self.radius, self.spacing, self.floor_y)
                self.splat_rows = ti.Vector.field(2, ti.i32, shape=self.splats.capacity)
            self.splats.update(positions, count, neighbourhood, velocities, self.exposure)
        if count and self.per_item:
            if self.footprints is None or self.footprints.capacity < positions.shape[0]:
                self.footprints = Footprints(positions.shape[0])
            self._splat_items(self.splats, count)
        elif count:
            self._splat(self.splats, count)
        # The thickness is smoothed in the first round only: it needs no edges kept, and one round of
        # σ/√rounds is smooth enough for a tint. Every pass but the first follows the surface's slope: the
        # splat's raw depth has the bumps of single spheres, a row-smoothed one no longer along rows.
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
            False,
        )
        self._filter(
            self.depth_pass,
            self.smooth_depth,
            1,
            0,
            coarse_focal,
            self.thickness_pass,
            1.0,
            self.thickness,
            True,
            True,
        )
        for _ in range(FILTER_ROUNDS - 1):
            for source, target, step_row, step_col in (
                (self.smooth_depth, self.depth_pass, 0, 1),
                (self.depth_pass, self.smooth_depth, 1, 0),
            ):
                self._filter(
                    source, target, step_row, step_col, coarse_focal, self.thickness, 1.0, self.thickness, False, True
                )
        self._normals()
        self._shade()
        if white_water is not None:
            self.sprites.splat(white_water, self, self.exposure)
        self._compose()
        if len(self.segment_points):
            self._lines()
