"""The headless renderer against the pinhole-camera formula, and the application's outputs end to end."""

import math

import imageio.v3 as iio
import numpy as np
import pytest
import taichi as ti
from plyfile import PlyData

from pbf import Simulation, load_scene
from pbf.app import cli
from pbf.app.render import SceneRenderer, SphereRenderer, View
from pbf.app.window import OrbitCamera
from scenes import small_dam_break

WHITE = (1.0, 1.0, 1.0)
W, H = 320, 240


def spheres(centres, rgbs, radius, view, background=WHITE):
    """Render spheres (NumPy arrays) with the headless renderer; returns the uint8 image."""
    n = len(centres)
    x = ti.Vector.field(3, ti.f32, shape=n)
    c = ti.Vector.field(3, ti.f32, shape=n)
    x.from_numpy(np.asarray(centres, np.float32))
    c.from_numpy(np.asarray(rgbs, np.float32))
    return SphereRenderer(W, H, background).render(view, x, c, n, radius)


def covered(image, background=WHITE):
    return np.any(image != np.round(np.array(background) * 255).astype(np.uint8), axis=2)


def test_background_only():
    view = View(np.array([0.0, 0.0, 2.0]), np.zeros(3), 45.0)
    image = spheres(np.array([[0.0, 0.0, 5.0]]), [[1, 0, 0]], 0.1, view, background=(0.2, 0.4, 0.6))
    assert image.shape == (H, W, 3)
    assert (image == np.array([51, 102, 153], np.uint8)).all()  # the sphere is behind the eye


@pytest.mark.parametrize("distance, radius", [(2.0, 0.1), (1.0, 0.25)])
def test_sphere_centroid_and_radius_follow_the_pinhole_formula(distance, radius):
    eye = np.array([0.3, 0.2, 0.1])
    direction = np.array([0.6, 0.0, -0.8])
    view = View(eye, eye + distance * direction, 50.0)
    mask = covered(spheres([view.target], [[1, 0, 0]], radius, view))
    rows, cols = np.nonzero(mask)
    focal = (H / 2) / math.tan(math.radians(50.0) / 2)
    expected = focal * radius / math.sqrt(distance**2 - radius**2)
    assert cols.mean() + 0.5 == pytest.approx(W / 2, abs=0.05)
    assert rows.mean() + 0.5 == pytest.approx(H / 2, abs=0.05)
    assert math.sqrt(mask.sum() / math.pi) == pytest.approx(expected, abs=0.6)


def test_nearer_sphere_wins():
    view = View(np.array([0.0, 0.0, 3.0]), np.zeros(3), 45.0)
    near, far = [0.05, 0.0, 0.2], [-0.05, 0.0, 0.0]
    # Particle 0 is green, particle 1 red; they overlap at the image centre, whichever is drawn first.
    for centres, expected in (([near, far], "green"), ([far, near], "red")):
        image = spheres(np.array(centres), [[0, 1, 0], [1, 0, 0]], 0.15, view)
        red, green, _ = image[H // 2, W // 2].astype(int)
        assert ("green" if green > red else "red") == expected


def test_headless_frame_shows_water_where_the_particles_are():
    scene = small_dam_break()
    scene["render"] = {
        "width_px": W,
        "height_px": H,
        "background_rgb": list(WHITE),
        "container_rgb": [1, 1, 1],
        "legend": False,  # only the particles differ from the background
    }
    sim = Simulation(scene)
    renderer = SceneRenderer(sim)
    water = covered(renderer.frame())
    # Project every particle centre: each lands on water (the front ones are seen, the others are
    # hidden behind water), and no water lies outside the particles' projected extent.
    view = renderer.view
    right, up, forward = view.basis()
    rel = sim.positions() - view.eye
    depth = rel @ forward
    focal = view.focal_px(H)
    cols = (W / 2 + focal * (rel @ right) / depth).astype(int)
    rows = (H / 2 - focal * (rel @ up) / depth).astype(int)
    assert water[rows, cols].mean() > 0.99
    margin = focal * sim.scene.particle_radius_m / depth.min() + 2
    wr, wc = np.nonzero(water)
    assert wr.min() >= rows.min() - margin and wr.max() <= rows.max() + margin
    assert wc.min() >= cols.min() - margin and wc.max() <= cols.max() + margin
    assert 0.05 < water.mean() < 0.9


def test_orbit_camera_round_trip():
    view = View(np.array([1.0, 0.7, 2.0]), np.array([0.2, 0.1, 0.3]), 45.0)
    again = OrbitCamera.from_view(view).view()
    assert np.allclose(again.eye, view.eye) and np.allclose(again.target, view.target)


def test_headless_run_writes_frames_video_and_particles(tmp_path, capsys):
    out = tmp_path / "frames"
    argv = [
        "dam_break",
        "--headless",
        "--frames",
        "3",
        "--out",
        str(out),
        "--video",
        str(tmp_path / "v.mp4"),
        "--export",
        "ply",
        "--size",
        "160x90",
        "--set",
        "fluid.spacing_m=0.05",
    ]
    assert cli.main(argv) == 0
    frames = sorted(out.glob("frame_*.png"))
    assert [p.name for p in frames] == [f"frame_{k:05d}.png" for k in range(4)]
    assert iio.imread(frames[0]).shape == (90, 160, 3)
    assert len(list(iio.imiter(tmp_path / "v.mp4"))) == 4
    size = cli._size(sum(path.stat().st_size for path in [*out.iterdir(), tmp_path / "v.mp4"]))
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"[pbf] wrote 4 frames in {out}/, video {tmp_path / 'v.mp4'}, ply files in {out}/: {size} "
        f"(PNG frames at 160×90)"
    )
    ply = PlyData.read(str(out / "particles_00003.ply"))
    assert ply["vertex"].count == load_scene("dam_break", ["fluid.spacing_m=0.05"]).particle_count
    # falling: down is −z in the files (export.up_axis = "z", the default)
    assert np.isfinite(ply["vertex"]["vz"]).all() and ply["vertex"]["vz"].min() < -0.1


def test_no_png_writes_the_video_alone(tmp_path, monkeypatch, capsys):
    # In the default place: no out/ folder appears, only the video, and the last line gives its size.
    monkeypatch.chdir(tmp_path)
    argv = ["dam_break", "--headless", "--frames", "3", "--video", "v.mp4", "--no-png", "--size", "160x90"]
    assert cli.main([*argv, "--set", "fluid.spacing_m=0.05"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]
    frames = list(iio.imiter(tmp_path / "v.mp4"))
    assert len(frames) == 4 and frames[0].shape == (90, 160, 3)
    lines = capsys.readouterr().out.splitlines()
    assert "[pbf] rendering 4 frames (the start and 3 steps) into v.mp4" in lines
    size = cli._size((tmp_path / "v.mp4").stat().st_size)
    assert lines[-1] == f"[pbf] wrote 4 frames as a video, v.mp4: {size} (H.264 at 160×90)"


@pytest.mark.slow
def test_no_png_keeps_the_exports(tmp_path, capsys):
    out = tmp_path / "frames"
    argv = ["dam_break", "--headless", "--frames", "2", "--out", str(out), "--video", str(tmp_path / "v.mp4")]
    argv += ["--no-png", "--export", "npz", "--size", "64x48", "--set", "fluid.spacing_m=0.05"]
    assert cli.main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == [f"particles_{k:05d}.npz" for k in range(3)] + ["run.json"]
    assert len(list(iio.imiter(tmp_path / "v.mp4"))) == 3
    video = cli._size((tmp_path / "v.mp4").stat().st_size)
    npz = cli._size(sum(p.stat().st_size for p in out.glob("particles_*.npz")))
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"[pbf] wrote 3 frames as a video, {tmp_path / 'v.mp4'}: {video} (H.264 at 64×48); npz files in {out}/: {npz}"
    )


@pytest.mark.slow
def test_npz_export(tmp_path, capsys):
    assert (
        cli.main(
            [
                "dam_break",
                "--headless",
                "--frames",
                "1",
                "--out",
                str(tmp_path),
                "--export",
                "npz",
                "--size",
                "64x48",
                "--set",
                "fluid.spacing_m=0.05",
            ]
        )
        == 0
    )
    data = np.load(tmp_path / "particles_00001.npz")
    # A --headless run's last line says how to write the video instead of the PNG frames, as it is typed.
    last = capsys.readouterr().out.splitlines()[-1]
    assert last.endswith(
        f"a video instead: --video {tmp_path}.mp4 --no-png; fewer or smaller frames: --frames N, --size WxH"
    )
    assert data["positions_m"].shape == data["velocities_m_s"].shape == (1000, 3)
    assert data["time_s"] == pytest.approx(1 / 60)


def test_without_display_the_window_falls_back_to_headless(tmp_path, monkeypatch, capsys):
    # The run's own lines (the start line aside: the tests' backend is already running): the window given
    # up in one line, the frames said and written alike, and the pour, empty at the start, saying how
    # many particles its nozzle will add.
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert cli.main(["pour", "--frames", "1", "--out", str(tmp_path), "--size", "64x48"]) == 0
    output = capsys.readouterr().out
    lines = [line for line in output.splitlines() if line.startswith("[pbf]")]
    assert lines[1] in (cli.COMPILING, cli.LOADING), output  # the kernel cache held kernels before or not
    assert lines[:4] == [
        "[pbf] no window: DISPLAY is not set; rendering headless instead",
        lines[1],
        "[pbf] pour: 0 particles now, up to 9,772 from its emitters; Δt = 8.33 ms, 10 iterations",
        f"[pbf] rendering 2 frames (the start and 1 step) into {tmp_path}/",
    ], output
    assert lines[4].startswith("[pbf] kernels ready and the first frame drawn in "), output
    size = cli._size(sum(path.stat().st_size for path in tmp_path.glob("frame_*.png")))
    assert lines[5:] == [
        f"[pbf] wrote 2 frames in {tmp_path}/: {size} (PNG frames at 64×48); a video instead: "
        f"--headless --video {tmp_path}.mp4 --no-png; fewer or smaller frames: --frames N, --size WxH"
    ], output
    assert len(list(tmp_path.glob("frame_*.png"))) == 2
    assert "((" not in output


@pytest.mark.parametrize(
    "argv, message",
    [
        (["no_such_scene"], "no such scene file"),
        (["dam_break", "--set", "render.colour_by=pressure"], "render.colour_by"),
        (["dam_break", "--size", "641x480"], "render.width_px"),
    ],
)
def test_bad_input_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    assert cli.main(argv + ["--headless", "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_legend_shows_the_colour_map_and_its_range(monkeypatch):
    # Only the top right corner changes, and the bar holds the colour map's top and bottom colours. The
    # frame without it: the same renderer's, the legend's blend left out (one Simulation compiled, not
    # two; a frame of legend = false is test_headless_frame_shows_water_where_the_particles_are's).
    import matplotlib

    from pbf.app.legend import BAR_PX, legend_line

    scene = small_dam_break()
    scene["render"] = {"width_px": 640, "height_px": 360, "legend": True, "colour_map": "viridis"}
    sim = Simulation(scene)
    renderer = SceneRenderer(sim)
    with_legend = renderer.frame()
    monkeypatch.setattr("pbf.app.render.draw_legend", lambda image, _: image)
    plain = renderer.frame()
    rows, cols = np.nonzero(np.any(with_legend != plain, axis=2))
    assert cols.min() > 640 * 0.6 and rows.max() < 360 * 0.7
    column = with_legend[:, cols.min() + BAR_PX[0] // 2].astype(int)
    for end in (0.0, 1.0):
        colour = np.round(np.array(matplotlib.colormaps["viridis"](end)[:3]) * 255)
        assert np.any(np.all(np.abs(column - colour) <= 2, axis=1))
    assert legend_line(sim.scene.render) == "colour: speed, viridis from 0 m/s to 3 m/s"


def test_the_gpu_backends_splat_per_pixel_draws_the_same_image():
    # GPU backends splat a thread per (particle, pixel) (pbf.app.splat); here on the CPU against the
    # per-particle loops, with particles near and far and some behind the eye, in both orders. Both
    # test pixels with the same function, but in kernels compiled apart, and the result depends on the
    # CPU: on an AMD EPYC the images were equal, on an Intel Xeon one pixel at the rim of a sphere is
    # hit by the per-item splat and left empty by the loops (cause not found). So a handful of pixels
    # may differ; a splat that lost or misplaced work items would change thousands.
    rng = np.random.default_rng(11)
    view = View(np.array([0.0, 0.2, 1.2]), np.array([0.0, 0.0, 0.0]), 60.0)
    centres = rng.uniform(-0.6, 0.6, size=(2000, 3)) * [1.0, 1.0, 2.0]
    colours = rng.uniform(0.0, 1.0, size=(2000, 3))
    x, c = ti.Vector.field(3, ti.f32, shape=2000), ti.Vector.field(3, ti.f32, shape=2000)
    x.from_numpy(centres.astype(np.float32))
    c.from_numpy(colours.astype(np.float32))
    edges = np.array([[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]], np.float32)
    for front_to_back in (True, False):
        images = []
        for per_item in (False, True):
            renderer = SphereRenderer(W, H, WHITE, segments=edges)
            renderer.per_item, renderer.front_to_back = per_item, front_to_back
            images.append(renderer.render(view, x, c, 2000, 0.02))
        assert np.count_nonzero(np.any(images[0] != images[1], axis=2)) <= 8  # of 76,800 pixels
        assert 0.05 < covered(images[0]).mean() < 0.95


def test_the_legends_labels_are_letters_not_empty_boxes():
    # Pillow's default font has no ρ and no minus sign: it drew both as the box of a missing glyph,
    # the same pixels as a code point no font has (one of Unicode's private use).
    from pbf.app.legend import legend_font, legend_range

    render = load_scene("dam_break", ['render.colour_by="density"']).render
    labels = "".join(legend_range(render))
    assert "ρ" in labels and "−" in labels
    for height in (90, 360, 1080):
        font = legend_font(height)
        missing = np.asarray(font.getmask("\U000f0000"))
        for character in set(labels) - {" "}:
            assert not np.array_equal(np.asarray(font.getmask(character)), missing), (character, height)


def test_the_legend_is_blended_into_its_corner_alone():
    # On a plain frame the legend changes only the top right corner, holds the colour map's two ends in
    # its bar, and its dark text on the light background: no pixel elsewhere moves.
    import matplotlib

    from pbf.app.legend import draw_legend

    render = load_scene("dam_break", ['render.colour_by="density"']).render
    background = np.round(np.array(render.background_rgb) * 255).astype(np.uint8)
    plain = np.broadcast_to(background, (360, 640, 3)).copy()
    image = draw_legend(plain.copy(), render)
    rows, cols = np.nonzero(np.any(image != plain, axis=2))
    assert cols.min() > 640 * 0.7 and rows.max() < 360 * 0.7
    corner = image[: rows.max() + 1, cols.min() :].reshape(-1, 3).astype(int)
    for end in (0.0, 1.0):  # within 2 of 255 for the blend's rounding
        colour = np.round(np.array(matplotlib.colormaps[render.colour_map](end)[:3]) * 255)
        assert np.any(np.all(np.abs(corner - colour) <= 2, axis=1)), end
    assert corner.sum(axis=1).min() < 3 * 60  # the labels' ink (20, 20, 20), antialiased at its edges


@pytest.mark.slow
def test_particle_frames_carry_the_legend_unless_told_not_to():
    # Colour means speed or density on every particle frame, so the default frames explain it; the
    # surface style's colours are the water's own and its frames draw none (a scene may keep the key on).
    def legend(*argv):
        return cli.load(cli.parse_args(["dam_break", *argv])).render.legend

    assert legend() and legend("--colour-by", "density") and legend("--colour-by", "speed")
    assert not legend("--colour-by", "density", "--set", "render.legend=false")  # --set wins
    assert legend("--style", "surface")  # accepted: the surface frames draw no legend
    scene = small_dam_break()
    scene["render"] = {"width_px": 320, "height_px": 180}
    sim = Simulation(scene)
    plain = SceneRenderer(Simulation(dict(scene, render={**scene["render"], "legend": False}))).frame()
    assert (SceneRenderer(sim).frame() != plain).any()
