"""The screen-space fluid renderer (``--style surface``) on pixels: a still pool is flat, thickness is
the depth of water, a ball's silhouette stays on the ball, and every run gives the same image. (Its
use in headless runs and the window is tested in ``test_mesh.py``, beside the meshes, so that one
Simulation serves them all.)"""

import math

import numpy as np
import pytest
import taichi as ti

from pbf.app import cli, pinhole
from pbf.app.render import LIGHT_DIRECTION, View
from pbf.app.surface_render import FAR, SPLAT_RADIUS_SPACINGS, SurfaceRenderer

SPACING = 0.025
W, H = 320, 240


def lattice(counts, lower=(0.0, 0.0, 0.0)):
    """Particles at lower + (i + ½) s, as the solver seeds a block."""
    axes = [lo + (np.arange(n) + 0.5) * SPACING for lo, n in zip(lower, counts)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float32)


def as_field(particles):
    field = ti.Vector.field(3, ti.f32, shape=max(1, len(particles)))
    if len(particles):
        field.from_numpy(particles)
    return field


def render(particles, view, renderer=None):
    """Render with ``renderer`` or a new W × H one over a floor at y = 0; returns it (for its fields)
    and the image."""
    renderer = renderer or SurfaceRenderer(
        W,
        H,
        SPACING,
        SPACING**3,
        floor_y_m=0.0,
        tile_m=0.1,
        absorption_per_m=(2.0, 0.7, 0.35),
        water_rgb=(0.05, 0.3, 0.45),
        horizon_rgb=(0.96, 0.96, 0.94),
    )
    return renderer, renderer.render(view, as_field(particles), len(particles), LIGHT_DIRECTION)


def coarse_rays(view, renderer):
    """Unit view rays through the centres of the coarse pixels, (h, w, 3)."""
    right, up, forward = view.basis()
    focal = view.focal_px(renderer.coarse_height)
    rows, cols = np.mgrid[0 : renderer.coarse_height, 0 : renderer.coarse_width]
    u = (cols + 0.5 - 0.5 * renderer.coarse_width) / focal
    w = (0.5 * renderer.coarse_height - rows - 0.5) / focal
    rays = u[..., None] * right + w[..., None] * up + forward
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def test_a_still_pool_renders_flat():
    side, layers = 24, 4  # 0.6 m square, 0.1 m deep
    pool = lattice((side, layers, side))
    top = layers * SPACING
    centre = np.array([side * SPACING / 2, top, side * SPACING / 2])
    view = View(centre + np.array([0.3, 0.9, 0.7]), centre, 45.0)
    renderer, _ = render(pool, view)
    # Coarse pixels whose ray meets the top face at least 3 spacings in from its edges.
    rays = coarse_rays(view, renderer)
    t = (top - view.eye[1]) / rays[..., 1]
    hits = view.eye + t[..., None] * rays
    margin = 3 * SPACING
    inner = (
        (hits[..., 0] > margin)
        & (hits[..., 0] < side * SPACING - margin)
        & (hits[..., 2] > margin)
        & (hits[..., 2] < side * SPACING - margin)
    )
    assert inner.sum() > 2000
    normals = renderer.normal.to_numpy()[inner]
    tilt = np.degrees(np.arccos(np.clip(normals[:, 1], -1.0, 1.0)))
    assert np.median(tilt) < 1.0
    assert np.percentile(tilt, 95) < 5.0
    # And the surface lies on the water: its depth within a spacing of the top face's.
    _, _, forward = view.basis()
    expected = (t * (rays @ forward))[inner]
    assert np.abs(renderer.smooth_depth.to_numpy()[inner] - expected).max() < SPACING


def test_thickness_is_the_depth_of_water():
    side = 16
    measured = []
    renderer = None
    for layers in (2, 4, 8):
        pool = lattice((side, layers, side))
        centre = np.array([side * SPACING / 2, 0.0, side * SPACING / 2])
        view = View(centre + np.array([0.0, 1.0, 0.0]), centre, 30.0)  # straight down
        renderer, _ = render(pool, view, renderer)
        h, w = renderer.coarse_height, renderer.coarse_width
        middle = renderer.thickness.to_numpy()[h // 2 - 10 : h // 2 + 10, w // 2 - 10 : w // 2 + 10]
        measured.append(np.median(middle))
        # Looking straight down, the path through the water is its depth.
        assert np.median(middle) == pytest.approx(layers * SPACING, rel=0.05)
    assert measured[0] < measured[1] < measured[2]


def test_a_ball_of_water_stays_where_the_ball_is():
    k = np.arange(-6, 7)
    offsets = np.stack(np.meshgrid(k, k, k, indexing="ij"), axis=-1).reshape(-1, 3)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= 6.0]
    centre = np.array([0.4, 0.3, 0.2])
    ball = (centre + SPACING * offsets).astype(np.float32)
    view = View(centre + np.array([0.5, 0.3, 0.8]), centre, 40.0)
    renderer, image = render(ball, view)
    water = renderer.image_depth.to_numpy() < FAR
    rows, cols = np.nonzero(water)
    # The silhouette is centred on the ball's projection and is as large as the ball of particles
    # and their splat radius: within half a spacing.
    focal = view.focal_px(H)
    distance = np.linalg.norm(view.eye - centre)
    assert cols.mean() + 0.5 == pytest.approx(W / 2, abs=1.0)
    assert rows.mean() + 0.5 == pytest.approx(H / 2, abs=1.0)
    outermost = SPACING * (6.0 + SPLAT_RADIUS_SPACINGS)  # the farthest particle and its splat sphere
    radius_px = math.sqrt(water.sum() / math.pi)
    expected_px = focal * outermost / math.sqrt(distance**2 - outermost**2)
    assert radius_px == pytest.approx(expected_px, abs=0.5 * focal * SPACING / distance)
    # Water looks like water: bluer than the floor and sky around it.
    assert (image[water][:, 2].astype(int) - image[water][:, 0]).mean() > 20


def test_no_particles_render_the_background_and_runs_repeat_exactly():
    view = View(np.array([1.0, 0.8, 1.5]), np.array([0.2, 0.1, 0.2]), 45.0)
    renderer, empty = render(np.zeros((0, 3), np.float32), view)
    assert not (renderer.image_depth.to_numpy() < FAR).any()
    assert np.array_equal(empty, renderer.background.to_numpy())
    rng = np.random.default_rng(3)
    splash = (np.array([0.3, 0.3, 0.3]) + rng.normal(0.0, 0.08, (1500, 3))).astype(np.float32)
    _, first = render(splash, view, renderer)  # after the empty frame: nothing of it stays
    other, second = render(splash, view)  # a renderer of its own
    assert np.array_equal(first, second)
    again = other.render(view, as_field(splash), len(splash), LIGHT_DIRECTION)
    assert np.array_equal(first, again)


def test_bad_style_is_refused(tmp_path, capsys):
    assert cli.main(["dam_break", "--headless", "--out", str(tmp_path / "out"), "--set", "render.style=glass"]) == 2
    assert "render.style" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    with pytest.raises(SystemExit):
        cli.parse_args(["dam_break", "--style", "glass"])


def test_the_gpu_backends_splat_per_pixel_draws_the_same_image():
    # GPU backends splat a thread per (particle, pixel) (pbf.app.splat); here on the CPU against the
    # per-particle loops: the same pixels covered, the same image up to rounding.
    view = View(np.array([0.9, 0.7, 1.3]), np.array([0.2, 0.1, 0.2]), 45.0)
    rng = np.random.default_rng(12)
    splash = (np.array([0.3, 0.3, 0.3]) + rng.normal(0.0, 0.08, (1500, 3))).astype(np.float32)
    per_particle, first = render(splash, view)
    per_pixel = SurfaceRenderer(
        W,
        H,
        SPACING,
        SPACING**3,
        floor_y_m=0.0,
        tile_m=0.1,
        absorption_per_m=(2.0, 0.7, 0.35),
        water_rgb=(0.05, 0.3, 0.45),
        horizon_rgb=(0.96, 0.96, 0.94),
    )
    per_pixel.per_item = True
    _, second = render(splash, view, per_pixel)
    # The same pairs of particle and pixel; the two kernels round the same formulas apart (LLVM fuses
    # multiply-adds per kernel), so a thickness differs by a few of its thousands of steps at most.
    thick, thin = per_particle.thickness_steps.to_numpy(), per_pixel.thickness_steps.to_numpy()
    assert np.array_equal(thick > 0, thin > 0)
    assert np.abs(thick - thin).max() <= 1e-2 * thick.max()
    differ = np.abs(first.astype(int) - second.astype(int)).max(axis=2)
    assert (differ > 2).mean() < 0.002


def luminance(image):
    return image.astype(float) @ [0.299, 0.587, 0.114]


def test_the_floor_blends_its_tiles_where_they_are_smaller_than_a_pixel():
    # Point-sampled, tiles smaller than a pixel alias into moiré: neighbouring pixels jump between the
    # two tile colours. Box-filtered over each pixel's footprint they blend to their mean far away
    # and keep their full contrast close by.
    view = View(np.array([0.0, 0.25, 2.0]), np.array([0.0, 0.0, 0.0]), 45.0)
    renderer, image = render(np.zeros((0, 3), np.float32), view)
    right, up, forward = view.basis()
    rows, cols = np.mgrid[0:H, 0:W]
    focal = view.focal_px(H)
    rays = ((cols + 0.5 - W / 2) / focal)[..., None] * right + ((H / 2 - rows - 0.5) / focal)[..., None] * up + forward
    distance = -view.eye[1] / np.minimum(rays[..., 1], -1e-9) * np.linalg.norm(rays, axis=-1)
    footprint_tiles = distance / focal / 0.1  # a pixel's width on the floor, across the view, in tiles
    lum = luminance(image)
    step = np.abs(np.diff(lum, axis=1))
    far = (rays[..., 1] < 0) & (footprint_tiles > 0.5)
    near = (rays[..., 1] < 0) & (footprint_tiles < 0.1)
    assert far[:, 1:].sum() > 1000 and near.sum() > 1000
    assert step[far[:, 1:] & far[:, :-1]].mean() < 1.0  # in 0-255 steps: smooth
    # Close by the two tiles keep their colours: the brightest and darkest near floor pixels differ by
    # most of the tiles' difference (0.80 against 0.63 in luminance, dimmed by the fade to the horizon).
    assert np.percentile(lum[near], 95) - np.percentile(lum[near], 5) > 0.6 * 255 * (0.80 - 0.63)


def aim(renderer):
    """A camera for the composition alone (no bodies: it reads none of it)."""
    pinhole.aim(renderer.camera, View(np.zeros(3), np.array([0.0, 0.0, -1.0]), 60.0), H, (0.0, 1.0, 0.0))


def test_the_composition_changes_only_the_pixels_with_water_or_white_water_around():
    # Patches of water and of white water (sprites' sums) apart, on a random background: a pixel shows
    # the background as it is exactly where none of its four coarse pixels holds water or visible white,
    # and every pixel next to a coarse pixel of white alone is whitened (the rows' spans take in both).
    renderer = SurfaceRenderer(W, H, SPACING, SPACING**3, 0.0, 0.1, (2.0, 0.7, 0.35), (0.05, 0.3, 0.45), (0.9,) * 3)
    shape = (renderer.coarse_height, renderer.coarse_width)
    rng = np.random.default_rng(3)
    water = np.zeros(shape, bool)
    water[20:30, 40:70] = water[90:95, 5:9] = True
    white = np.zeros(shape, np.int32)
    white[60:62, 100:103] = 4096
    white[10, 150] = 4096
    renderer.smooth_depth.from_numpy(np.where(water, 1.0, FAR).astype(np.float32))
    renderer.colour.from_numpy(rng.random(shape + (3,), np.float32))
    background = rng.integers(0, 256, (H, W, 3), np.uint8)
    renderer.background.from_numpy(background)
    renderer.sprites.opacity.from_numpy(white)
    renderer.sprites.row_used.from_numpy(white.any(axis=1).astype(np.int32))
    aim(renderer)
    renderer._compose()
    image = renderer.image.to_numpy()
    # The four coarse pixels around each image pixel (COARSE = 2; the edges clamped as the composition does).
    first = lambda n, coarse: np.clip(np.floor((np.arange(n) + 0.5) / 2 - 0.5), 0, coarse - 2).astype(int)  # noqa: E731
    rows, cols = first(H, shape[0])[:, None], first(W, shape[1])[None, :]
    around = lambda mask: mask[rows, cols] | mask[rows + 1, cols] | mask[rows, cols + 1] | mask[rows + 1, cols + 1]  # noqa: E731
    near_water, near_white = around(water), around(white > 0)
    changed = (image != background).any(axis=2)
    assert not changed[~near_water & ~near_white].any()
    assert changed[near_white & ~near_water].all()
    assert changed[near_water].mean() > 0.9  # water of random colours over a random background


def test_the_outline_of_the_water_is_anti_aliased():
    # The composition at full resolution, alone: white water on a black background, its edge the line
    # x = 100 + 0.3 y (pixels) as the coarse pixels see it. Each image pixel takes the water's share
    # by how far its centre is from the outline, so the edge is a ramp, not a staircase of pure water
    # and pure background, and the share falls monotonically away from the water.
    renderer = SurfaceRenderer(W, H, SPACING, SPACING**3, 0.0, 0.1, (2.0, 0.7, 0.35), (0.05, 0.3, 0.45), (0.9,) * 3)
    rows, cols = np.mgrid[0 : renderer.coarse_height, 0 : renderer.coarse_width]
    inside = (cols + 0.5) * 2 < 100 + 0.3 * (rows + 0.5) * 2
    renderer.smooth_depth.from_numpy(np.where(inside, 1.0, FAR).astype(np.float32))
    renderer.colour.from_numpy(np.ones(inside.shape + (3,), np.float32))
    renderer.background.from_numpy(np.zeros((H, W, 3), np.uint8))
    aim(renderer)
    renderer._compose()
    share = renderer.image.to_numpy()[..., 0] / 255.0
    assert np.all(np.diff(share, axis=1) <= 1e-6)
    partial = (share > 0.1) & (share < 0.9)
    assert partial.sum(axis=1).mean() >= 0.8  # about one pixel of every row on the edge is partly water
    edge = 100 + 0.3 * (np.arange(H) + 0.5)  # the true outline's column in each row
    assert np.abs(share.sum(axis=1) - edge).max() < 1.5  # each row's water adds up to the true width
    # Where the share crosses ½ (to a fraction of a pixel) moves along the straight edge without steps of a
    # pixel from one row to the next: the bilinear coverage of the coarse pixels alone steps by more
    # (docs/RENDERING.md, "Straight edges").
    crossing = []
    for row in share[4:-4]:  # the rows the image's border leaves alone
        k = np.nonzero((row[:-1] >= 0.5) & (row[1:] < 0.5))[0][0]
        crossing.append(k + 0.5 + (row[k] - 0.5) / (row[k] - row[k + 1]))
    assert np.abs(np.diff(crossing)).max() < 1.0


@pytest.mark.slow
def test_a_splash_has_no_isolated_bright_pixels():
    # In a splash the surface's normal turns from pixel to pixel; a sharp highlight on it lights single
    # pixels, which sparkle from frame to frame (the seed dam break's frame 30 had 7 pixels brighter
    # than all 8 neighbours by 20 of 255 with the fixed exponent). The highlight widens where the
    # normals disagree.
    from pbf.app.render import SceneRenderer
    from pbf.solver import Simulation

    sim = Simulation("dam_break", overrides=["render.style=surface"], quiet=True)
    for _ in range(30):
        sim.step()
    image = SceneRenderer(sim).frame()
    lum = luminance(image)
    height, width = lum.shape
    padded = np.pad(lum, 1, mode="edge")
    around = np.max(
        [
            padded[1 + dr : 1 + dr + height, 1 + dc : 1 + dc + width]
            for dr in (-1, 0, 1)
            for dc in (-1, 0, 1)
            if dr or dc
        ],
        axis=0,
    )
    assert ((lum - around) > 20).sum() <= 2


def test_a_level_surface_mirrors_the_sky(monkeypatch):
    # The top of a pool mirrors the sky's glow (Fresnel's few percent at these angles): without the
    # glow it shows the same blue as the water, and reads as jelly. Compared with the glow off.
    from pbf.app import surface_render

    pool = lattice((16, 6, 16), lower=(-0.2, 0.0, -0.2))
    view = View(np.array([0.55, 0.45, 1.0]) * 0.9, np.array([0.0, 0.1, 0.0]), 45.0)
    renderer, lit = render(pool, view)
    top = (renderer.image_depth.to_numpy() < FAR) & (renderer.normal.to_numpy()[..., 1].repeat(2, 0).repeat(2, 1) > 0.9)
    monkeypatch.setattr(surface_render, "SUN_GLOW", 0.0)
    _, unlit = render(pool, view)  # a new renderer compiles its kernels with the glow off
    assert top.sum() > 2000
    assert (luminance(lit) - luminance(unlit))[top].mean() > 10.0


@pytest.mark.slow
def test_bodies_are_drawn_in_the_air_and_through_the_water():
    # A box above a pool and a ball under its surface. The box's centre shows the body's colour (wood:
    # red over green over blue); the ball, seen through the water, turns the water there warmer than the
    # same pool without it (the water's own colour is blue-green).
    from dataclasses import replace

    from pbf.app.render import SceneRenderer
    from pbf.scene import load_scene
    from pbf.solver import Simulation

    scene = load_scene(
        {
            "name": "bodies in view",
            "container": {"max_m": [0.4, 0.4, 0.4]},
            "fluid": {"spacing_m": SPACING, "blocks": [{"min_m": [0, 0, 0], "max_m": [0.4, 0.15, 0.4]}]},
            "bodies": [
                {"size_m": [0.05, 0.03, 0.05], "density_kg_m3": 500, "position_m": [0.12, 0.3, 0.2]},
                {
                    "shape": "sphere",
                    "size_m": [0.05, 0.05, 0.05],
                    "density_kg_m3": 900,
                    "position_m": [0.28, 0.08, 0.2],
                },
            ],
            "camera": {"position_m": [0.2, 0.3, 0.9], "look_at_m": [0.2, 0.15, 0.2]},
        }
    )
    images, views = {}, {}
    for name, variant in (("with", scene), ("without", replace(scene, bodies=()))):
        renderer = SceneRenderer(Simulation(variant, quiet=True), W, H, style="surface")
        images[name], views[name] = renderer.frame().astype(int), renderer.view

    def pixel(point):
        view = views["with"]
        right, up, forward = view.basis()
        offset = np.asarray(point) - view.eye
        focal = view.focal_px(H)
        return (
            int(0.5 * H - focal * (offset @ up) / (offset @ forward)),
            int(0.5 * W + focal * (offset @ right) / (offset @ forward)),
        )

    box = images["with"][pixel([0.12, 0.3, 0.25])]  # the box's front face
    assert box[0] > box[1] > box[2] and box[0] > 100
    assert (np.abs(images["without"][pixel([0.12, 0.3, 0.25])] - box) > 40).any()  # sky or floor there before
    row, col = pixel([0.28, 0.08, 0.25])  # the ball's front, under the surface
    ball, water = images["with"][row, col], images["without"][row, col]
    assert ball[0] - ball[2] > water[0] - water[2] + 20


def axis_aligned_steps(colour: np.ndarray, water: np.ndarray, jump: float = 0.05, run: int = 6) -> float:
    """The share of the water's pixels on axis-aligned steps of its shading: a jump of luminance of more
    than ``jump`` between two neighbouring pixels of water, twice the jumps beside it (a step, not a
    steep ramp), repeated at the same place on ``run`` or more consecutive pixels across it. The
    curved edges of a real splash (drops, crests) stay at one column or row for a pixel or two."""
    lum = colour @ np.array([0.2126, 0.7152, 0.0722])
    marked = 0
    for values, inside in ((lum, water), (lum.T, water.T)):
        step = np.abs(np.diff(values, axis=1))
        beside = np.zeros_like(step)
        beside[:, 1:-1] = np.maximum(step[:, :-2], step[:, 2:])
        on_step = inside[:, 1:] & inside[:, :-1] & (step > jump) & (step > 2.0 * beside)
        length = np.zeros(on_step.shape[1], int)
        for row in on_step:  # runs down each column of jumps
            length = np.where(row, length + 1, 0)
            marked += run * np.sum(length == run) + np.sum(length > run)
    return marked / max(int(water.sum()), 1)


@pytest.mark.slow
def test_a_splash_has_no_axis_aligned_blocks():
    # The seed dam break's frame 60 (t = 1 s) is a churned bed under spray. A separable edge-keeping
    # filter whose decisions jump from pixel to pixel along one axis (a sample clamped into range, a
    # range grown by each pair taken) spread each jump along the other axis, and the splash was covered
    # with rectangles of different shades: 0.31% of its water's pixels on such steps (runs of 6 coarse
    # pixels, 12 in the image), against 0.05% once the range follows the surface's slope and keeps to it
    # (0.38% and 0.08% with Taichi's advanced optimisation, another splash).
    from pbf.app.render import View, surface_renderer
    from pbf.solver import Simulation

    sim = Simulation("dam_break", quiet=True)
    sim.step(60)
    renderer = surface_renderer(sim, 1280, 720)
    particles = sim.readout()
    renderer.draw(View.of_scene(sim.scene), particles.positions, particles.count, LIGHT_DIRECTION, sim.neighbourhood())
    water = renderer.smooth_depth.to_numpy() < FAR
    assert water.sum() > 20000  # the splash fills a good part of the frame
    assert axis_aligned_steps(renderer.colour.to_numpy(), water) < 0.0015
