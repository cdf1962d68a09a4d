"""The window's frames without a display: each is our renderer's image handed to GGUI's canvas as
packed RGBA words (checked against GGUI itself where Vulkan is available), the panel shows the
simulation's and the renderer's milliseconds apart, and its statistics are not recomputed every
frame."""

import re
import time
from types import SimpleNamespace

import numpy as np
import pytest
import taichi as ti

from pbf import Simulation
from pbf.app import window as window_module
from pbf.app.keys import HELP
from pbf.app.render import EMPTY, SphereRenderer, scene_edges, unpack_rgb
from pbf.app.window import WindowViewer, show_packed
from scenes import small_dam_break

W, H = 160, 90


class Recorder:
    """GGUI's C++ canvas as ``show_packed`` sees it: records what it was handed."""

    def __init__(self):
        self.images = []

    def set_image(self, info):
        self.images.append(info)


class Panel:
    def __init__(self, texts):
        self.texts = texts

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def text(self, line):
        self.texts.append(line)

    def slider_int(self, name, value, low, high):
        return value

    slider_float = slider_int


class DrawingWindow:
    """What WindowViewer asks of a GGUI window to draw a frame: a canvas, a panel, show()."""

    running = True

    def __init__(self, cursor=(0.5, 0.5)):
        self.canvas = Recorder()
        self.texts = []
        self.shown = 0
        self.cursor = cursor

    def get_events(self, kind):
        return []

    def is_pressed(self, key):
        return False

    def get_cursor_pos(self):
        return self.cursor

    def get_window_shape(self):
        return (W, H)

    def get_canvas(self):
        return self

    def get_gui(self):
        return self

    def sub_window(self, name, x, y, width, height):
        return Panel(self.texts)

    def show(self):
        self.shown += 1

    def set_background_color(self, rgb):
        self.background = rgb


def small_scene():
    scene = small_dam_break()
    scene["render"] = {"width_px": W, "height_px": H}
    return scene


@pytest.fixture(scope="module")
def shared_sim():
    """One simulation for the tests that only draw it (each Simulation compiles its kernels anew)."""
    return Simulation(small_scene())


@pytest.fixture
def sim(shared_sim):
    shared_sim.reset()
    shared_sim.control.push = None
    return shared_sim


def test_a_frame_is_the_sphere_renderers_image_handed_over_as_it_is(sim):
    window = DrawingWindow(cursor=(-1.0, -1.0))  # the mouse outside the window: no marker
    viewer = WindowViewer(sim, window)
    viewer.advance()
    viewer.show()
    assert window.shown == 1 and len(window.canvas.images) == 1
    info = window.canvas.images[0]
    packed = viewer.frames.spheres.packed
    assert list(info.shape) == [W, H] and info.field_source.name == "HostMappedPtr"
    assert info.dev_alloc.alloc_id == packed.ctypes.data  # the renderer's own array, no copy in between
    # The same picture as the headless renderer draws from the window's camera.
    particles = sim.readout()
    reference = SphereRenderer(
        W, H, sim.scene.render.background_rgb, sim.scene.render.container_rgb, scene_edges(sim.scene)
    )
    expected = reference.render(
        viewer.camera.view(), particles.positions, viewer.frames.colours.update(), particles.count, particles.radius_m
    )
    assert np.array_equal(unpack_rgb(packed), expected)
    viewer.surface = True  # key v: the surface renderer's image, through the same hand-over
    viewer.show()
    assert window.canvas.images[-1].dev_alloc.alloc_id == viewer.frames.surface.packed.ctypes.data
    image = unpack_rgb(viewer.frames.surface.packed)
    assert np.array_equal(image, viewer.frames.surface.image.to_numpy())


def ring_pixels(before, after):
    """The (x, y) of the pixels that changed between two packed frames, and whether all are the marker's."""
    changed = np.argwhere(before != after)
    return changed, bool(np.all(after[before != after] == window_module.MARKER_WORD))


def test_a_ring_marks_the_water_under_the_mouse_and_the_hand_that_holds_it(sim):
    """The ring is the hand's reach (Hand.radius_m) at the depth of the water under the cursor, seen through
    the window's camera: a circle of f R / depth pixels around it, two pixels wide. Over empty space there
    is none (a press there takes nothing); while the left button holds water it rings the hand."""
    window = DrawingWindow(cursor=(-1.0, -1.0))
    viewer = WindowViewer(sim, window)
    viewer.advance()
    viewer.show()
    renderer = viewer.frames.spheres
    plain = renderer.packed.copy()
    keys = renderer.keys.to_numpy()
    water = np.argwhere((keys != EMPTY) & ((keys & 0xFFFFFFFF) < sim.particle_count))
    col, row = water[len(water) // 2]  # a pixel of water, (x, y) with y up
    depth = float(np.array([keys[col, row] >> 32], np.int32).view(np.float32)[0])
    view = viewer.camera.view()
    radius_px = view.focal_px(H) * viewer.hand.radius_m / depth
    window.cursor = ((col + 0.5) / W, (row + 0.5) / H)
    viewer.advance()
    viewer.show()
    changed, all_marker = ring_pixels(plain, renderer.packed)
    assert all_marker and len(changed) > 2 * np.pi * radius_px  # a ring around, not a dot
    distances = np.hypot(changed[:, 0] + 0.5 - (col + 0.5), changed[:, 1] + 0.5 - (row + 0.5))
    assert distances.min() >= radius_px - 1.0 and distances.max() <= radius_px + 2.0 + 1.0  # pixel rounding

    empty = np.argwhere(keys == EMPTY)[0]
    window.cursor = ((empty[0] + 0.5) / W, (empty[1] + 0.5) / H)
    viewer.advance()
    viewer.show()
    assert np.array_equal(renderer.packed, plain)  # nothing under the cursor: no ring

    viewer.hand.grab(view, (col + 0.5) / W, (row + 0.5) / H, W / H)  # the left button, pressed on the water
    viewer.show()
    changed, all_marker = ring_pixels(plain, renderer.packed)
    offset = viewer.hand.point - view.eye
    right, up, forward = view.basis()
    centre = (
        W / 2 + view.focal_px(H) * (offset @ right) / (offset @ forward),
        H / 2 + view.focal_px(H) * (offset @ up) / (offset @ forward),
    )
    radius_px = view.focal_px(H) * viewer.hand.radius_m / (offset @ forward)
    distances = np.hypot(changed[:, 0] + 0.5 - centre[0], changed[:, 1] + 0.5 - centre[1])
    assert all_marker and distances.min() >= radius_px - 1.0 and distances.max() <= radius_px + 3.0


def test_the_panel_shows_simulation_and_render_milliseconds_apart(sim):
    window = DrawingWindow()
    viewer = WindowViewer(sim, window)
    viewer.show()
    assert [text for text in window.texts if text.startswith(("sim ", "render "))] == [
        "sim - ms per frame",
        "render - ms (draw - + show -)",
    ]  # nothing stepped or drawn yet
    assert viewer.advance()
    time.sleep(0.05)  # a step of 50 ms, as the loop's sim.step() would take
    viewer.show()
    viewer.show()  # the panel of a frame shows the previous frame's rendering
    sim_line = [text for text in window.texts if text.startswith("sim ")][-1]
    render_line = [text for text in window.texts if text.startswith("render ")][-1]
    sim_ms = float(re.fullmatch(r"sim (\S+) ms per frame", sim_line).group(1))
    render_ms, draw_ms, show_ms = map(
        float, re.fullmatch(r"render (\S+) ms \(draw (\S+) \+ show (\S+)\)", render_line).groups()
    )
    assert 50.0 <= sim_ms < 1000.0
    assert draw_ms > 0.0 and show_ms >= 0.0 and render_ms == pytest.approx(draw_ms + show_ms, abs=0.11)


TEXT_PX, SLIDER_PX, FRAME_PX = 17, 23, 36
"""The panel's pixels at GGUI's default font, read off a screenshot of ``python run.py`` under Xvfb (key h
pressed with xdotool, ``import -window root``): a line of text, a slider, and the title bar with the
padding above and below the lines."""


class LinePanel(Panel):
    """A panel that records its sliders as lines too, marked."""

    def slider_int(self, name, value, low, high):
        self.texts.append(("slider", name))
        return value

    slider_float = slider_int


class HelpWindow(DrawingWindow):
    """A 1280 × 720 window whose key h is pressed once; records each panel's name and height."""

    def __init__(self):
        super().__init__()
        self.events = [SimpleNamespace(key="h")]
        self.panels = []

    def get_events(self, kind):
        events, self.events = self.events, []
        return events

    def get_window_shape(self):
        return (1280, 720)

    def sub_window(self, name, x, y, width, height):
        self.texts.clear()
        self.panels.append((name, height))
        return LinePanel(self.texts)


def needed_px(lines) -> int:
    sliders = sum(isinstance(line, tuple) for line in lines)
    return FRAME_PX + SLIDER_PX * sliders + TEXT_PX * (len(lines) - sliders)


def test_the_panel_grows_to_show_the_help_without_scrolling(sim):
    """GGUI's Dear ImGui takes a panel's size only when it first meets the panel's name (and keeps it in
    imgui.ini), so the panel with the help must be another name, of the same title, tall enough for its
    lines."""
    window = HelpWindow()
    viewer = WindowViewer(sim, window)
    viewer.panel(viewer.current_stats())
    name, height = window.panels[-1]
    assert needed_px(window.texts) <= height * 720
    assert viewer.advance()  # key h
    viewer.panel(viewer.current_stats())
    help_name, help_height = window.panels[-1]
    assert HELP[-1] in window.texts
    assert needed_px(window.texts) <= help_height * 720 <= 720, (needed_px(window.texts), help_height * 720)
    assert help_name != name and help_name.split("###")[0] == name.split("###")[0] == window_module.PANEL_TITLE


@pytest.mark.slow
def test_statistics_are_recomputed_at_most_every_interval_while_running(monkeypatch):
    monkeypatch.setattr(window_module, "STATS_INTERVAL_S", 1e9)
    sim = Simulation(small_scene())
    viewer = WindowViewer(sim, DrawingWindow())
    assert viewer.current_stats()["frame"] == 0
    sim.step()
    assert viewer.current_stats()["frame"] == 0  # running: the figures of a moment ago
    viewer.paused = True
    assert viewer.current_stats()["frame"] == 1  # paused (or a single step): at once
    monkeypatch.setattr(window_module, "STATS_INTERVAL_S", 0.0)
    viewer.paused = False
    sim.step()
    assert viewer.current_stats()["frame"] == 2


def test_ggui_shows_a_packed_image_as_its_own_set_image_does():
    # Against GGUI itself, offscreen; needs Vulkan (a GPU driver, or Mesa's lavapipe).
    try:
        window = ti.ui.Window("packed", (64, 48), show_window=False)
    except RuntimeError as error:
        pytest.skip(f"no GGUI here: {str(error).strip().splitlines()[-1]}")
    rgb = np.zeros((64, 48, 3), np.uint8)
    rgb[...] = (20, 40, 60)
    rgb[:32, 24:] = (250, 10, 10)  # x < 32 and y ≥ 24, y up: the top left quarter
    packed = np.zeros((64, 48), np.uint32)
    packed.view(np.uint8).reshape(64, 48, 4)[...] = np.concatenate([rgb, np.full((64, 48, 1), 255, np.uint8)], -1)
    show_packed(window.get_canvas(), packed)
    ours = np.round(window.get_image_buffer_as_numpy()[..., :3] * 255).astype(np.uint8)  # (W, H), y up
    window.get_canvas().set_image(rgb)  # GGUI's public way, through its conversion kernel
    theirs = np.round(window.get_image_buffer_as_numpy()[..., :3] * 255).astype(np.uint8)
    assert np.array_equal(ours, theirs)
    assert tuple(ours[5, 45]) == (250, 10, 10) and tuple(ours[50, 5]) == (20, 40, 60)


def test_the_window_says_what_it_waits_for_before_the_first_picture():
    # Drawn twice: Dear ImGui does not draw a window in the frame it first lays it out.
    window = DrawingWindow()
    window_module.show_waiting(window, (0.9, 0.9, 0.8), ["compiling kernels ..."])
    assert window.shown == 2 and window.texts == ["compiling kernels ..."] * 2
    assert window.background == (0.9, 0.9, 0.8)


def test_the_window_places_itself_inside_the_screen():
    # Xvfb's default screens (1280 × 1024, and 1280 × 720 as the README once gave it) cut a 1280 × 720
    # window at Taichi's (100, 100); it opens nearer the corner there, at (100, 100) where there is room.
    from pbf.app.window import WINDOW_OFFSET, window_position

    assert window_position(1280, 720, (1280, 1024)) == (0, WINDOW_OFFSET)
    assert window_position(1280, 720, (1280, 720)) == (0, 0)
    assert window_position(1280, 720, (1920, 1080)) == (WINDOW_OFFSET, WINDOW_OFFSET)
    assert window_position(1280, 720, (1330, 770)) == (50, 50)
    assert window_position(1280, 720, (800, 600)) == (0, 0)  # larger than the screen: its corner shows
    assert window_position(1280, 720, None) == (WINDOW_OFFSET, WINDOW_OFFSET)  # no X display to ask
