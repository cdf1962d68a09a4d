"""Each preset frames its action: its water (and the container, where no camera is set) in the image,
and the window's panel beside it, not over it."""

import itertools

import numpy as np
import pytest

from pbf.app.render import View
from pbf.app.window import PANEL, OrbitCamera
from pbf.scene import SCENES_DIR, load_scene

PRESETS = sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def project(view: View, point, width: int, height: int) -> tuple[float, float]:
    """(column, row) of a world point in pixels, row 0 at the top."""
    right, up, forward = view.basis()
    p = np.asarray(point, float) - view.eye
    depth = p @ forward
    assert depth > 0.0
    focal = view.focal_px(height)
    return 0.5 * width + focal * (p @ right) / depth, 0.5 * height - focal * (p @ up) / depth


def corners(lower, upper):
    return [np.choose(bits, [lower, upper]) for bits in itertools.product((0, 1), repeat=3)]


@pytest.mark.parametrize("name", PRESETS)
def test_the_water_is_in_view_and_clear_of_the_window_panel(name):
    scene = load_scene(name)
    width, height = scene.render.width_px, scene.render.height_px
    camera = OrbitCamera.from_view(View.of_scene(scene))
    camera.clear_of(PANEL[0] + PANEL[2], width / height)
    view = camera.view()
    points = [c for b in scene.fluid.blocks for c in corners(np.array(b.min_m), np.array(b.max_m))]
    points += [np.array(e.position_m) for e in scene.emitters]
    panel_right, panel_bottom = (PANEL[0] + PANEL[2]) * width, (PANEL[1] + PANEL[3]) * height
    for point in points:
        col, row = project(view, point, width, height)
        assert 0 <= col <= width and 0 <= row <= height, (name, point, col, row)
        assert not (col < panel_right and row < panel_bottom), (name, "under the panel", point, col, row)
    if scene.camera.position_m is None:  # the derived view holds the whole container
        for point in corners(np.array(scene.container.min_m), np.array(scene.container.max_m)):
            col, row = project(View.of_scene(scene), point, width, height)
            assert 0 <= col <= width and 0 <= row <= height, (name, point)


def test_clearing_the_panel_moves_the_centre_right_by_half_its_width():
    scene = load_scene("dam_break")
    view = View.of_scene(scene)
    camera = OrbitCamera.from_view(view)
    camera.clear_of(0.3, 16 / 9)
    col, row = project(camera.view(), view.target, 1600, 900)
    assert col == pytest.approx(800 + 0.15 * 1600, abs=1.0) and row == pytest.approx(450, abs=1.0)


def test_the_panel_grows_to_show_the_help_without_scrolling():
    from pbf.app.keys import HELP
    from pbf.app.window import PANEL_ROWS, ROW_PX, WindowViewer

    class Shape:
        def __init__(self, height):
            self.height = height

        def get_window_shape(self):
            return (1280, self.height)

    viewer = WindowViewer.__new__(WindowViewer)  # the panel's size alone: no simulation needed
    for height in (480, 720, 1080):
        viewer.window, viewer.help_shown = Shape(height), False
        assert viewer.panel_rect()[3] * height == pytest.approx(PANEL_ROWS * ROW_PX)
        viewer.help_shown = True
        rows = viewer.panel_rect()[3] * height / ROW_PX
        assert rows >= min(PANEL_ROWS + len(HELP), (1 - 2 * PANEL[1]) * height / ROW_PX) - 1e-9
