"""The interactive window (Taichi GGUI): orbit camera, keys, a panel of live figures and sliders.

Mouse: left drag on the water pushes it (``pbf.app.interact``; an amber ring marks the hand's reach
where the cursor meets the water, and the hand while it holds), right drag orbits around the
target, shift + right drag (or middle drag) zooms. Keys (``KEYS``): W/A/S/D move the target
forward, left, back and right, Q/E down and up; space pauses and resumes, n steps one frame while
paused, h shows the help, Tab hides the panel, r resets, f turns the emitters on and off, m the wave maker, v
switches between particles and the
water's surface, esc quits.

Every frame is rendered by the project's own Taichi renderers on the window's camera and handed to
GGUI's canvas as one image: particles as ray-cast shaded spheres of their simulated radius with the
container and obstacle edges (``pbf.app.render.SphereRenderer``, the headless frames' renderer), or
the water's surface (``pbf.app.surface_render``), both chosen by ``pbf.app.render.SceneRenderer``.
GGUI draws that image and the panel. On a CPU with a software Vulkan driver (lavapipe) this costs a third of
what GGUI's own particles cost, whose fragment shader writes depth and so shades every hidden layer of water
(docs/BENCHMARKS.md, "The window"); GGUI has no custom shaders, and a mesh reconstructed every frame
(``pbf.app.mesh``) would cost more than the whole surface render. The panel shows the simulation's and the
renderer's milliseconds apart. ``WindowViewer`` runs it in the loop of ``pbf.app.loop``.
"""

import contextlib
import ctypes
import ctypes.util
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np
import taichi as ti
from taichi.ui.utils import get_field_info

from pbf.app.interact import Hand
from pbf.app.keys import HELP
from pbf.app.legend import legend_line
from pbf.app.render import SceneRenderer, View

PANEL = (0.01, 0.01, 0.3, 0.455)
"""The panel's x, y, width and height as fractions of the window (origin top left), without the help, in
a window 720 pixels high (``WindowViewer.panel_rect`` sizes it by its lines for the window it is in)."""
ROW_PX = 22
"""The height of one line of the panel at GGUI's default font (0.455 of a 720-pixel window holds its 15)."""
PANEL_ROWS = 15
PANEL_TITLE = "pbf (h: help, Tab: hide)"
"""The panel's lines without the help: text, sliders and the title bar."""
MARKER_RGB = (255, 200, 0)
"""The ring that marks where the mouse meets the water (and, while dragging, the hand): amber, apart from
the colour maps' blues and reds and from both backgrounds."""
MARKER_WORD = MARKER_RGB[0] | (MARKER_RGB[1] << 8) | (MARKER_RGB[2] << 16) | 0xFF000000
"""The ring's colour as a packed RGBA word (``pbf.app.render.pack_rgba``)."""
STATS_INTERVAL_S = 0.1
"""The panel's statistics are recomputed at most this often while the simulation runs (a reduction
over every particle; ten times a second is as often as figures can be read)."""
SMOOTHING = 0.1
"""Weight of the newest frame in the running means of the panel's frame rate and milliseconds."""


def show_packed(canvas, packed: np.ndarray) -> None:
    """Show a (W, H) array of packed RGBA8 words (y up) as the canvas's image. ``Canvas.set_image``
    converts whatever it is given into exactly this array with a Taichi kernel, a pass over every pixel
    (``to_rgba8`` in taichi/ui/staging_buffer.py), and hands the result to the C++ canvas; the
    renderers write this layout themselves, so it goes to the C++ canvas directly (Taichi 1.7.4, pinned
    in pyproject.toml)."""
    assert packed.dtype == np.uint32 and packed.ndim == 2 and packed.flags.c_contiguous
    canvas.canvas.set_image(get_field_info(packed))


def running_mean(mean: float | None, value: float) -> float:
    """The running mean of the panel's figures, started from the first value."""
    return value if mean is None else (1.0 - SMOOTHING) * mean + SMOOTHING * value


class WindowUnavailable(RuntimeError):
    """No window can open here (no display, no Vulkan); the message says why."""


@dataclass
class OrbitCamera:
    """Eye on a sphere around a target: yaw about y, pitch above the horizon, distance in metres."""

    target: np.ndarray
    yaw: float
    pitch: float
    distance: float
    fov_deg: float

    @classmethod
    def from_view(cls, view: View) -> "OrbitCamera":
        offset = view.eye - view.target
        distance = float(np.linalg.norm(offset))
        return cls(
            view.target.astype(float),
            math.atan2(offset[0], offset[2]),
            math.asin(offset[1] / distance),
            distance,
            view.fov_deg,
        )

    def view(self) -> View:
        direction = np.array(
            [math.cos(self.pitch) * math.sin(self.yaw), math.sin(self.pitch), math.cos(self.pitch) * math.cos(self.yaw)]
        )
        return View(self.target + self.distance * direction, self.target.copy(), self.fov_deg)

    def orbit(self, dx: float, dy: float) -> None:
        """Turn by a drag of (dx, dy) window widths/heights: a full width is half a turn."""
        self.yaw -= math.pi * dx
        self.pitch = min(max(self.pitch - math.pi * dy, -1.5), 1.5)

    def zoom(self, dy: float) -> None:
        """Dolly in (drag up) or out (drag down); each window height of drag is a factor e."""
        self.distance = max(1e-3, self.distance * math.exp(-dy))

    def clear_of(self, fraction: float, aspect: float) -> None:
        """Move eye and target together to the left by half of ``fraction`` of the view's width at the
        target, so that what was centred is centred in the part of the window right of a panel that
        covers ``fraction`` of its width (``aspect``: width over height)."""
        width = 2.0 * self.distance * math.tan(math.radians(self.fov_deg) / 2) * aspect
        self.move(0.0, -0.5 * fraction * width, 0.0)

    def move(self, forward: float, right: float, up: float) -> None:
        """Move eye and target together, in metres, along the horizontal view direction, right and up."""
        ahead = np.array([-math.sin(self.yaw), 0.0, -math.cos(self.yaw)])
        side = np.array([math.cos(self.yaw), 0.0, -math.sin(self.yaw)])
        self.target = self.target + forward * ahead + right * side + np.array([0.0, up, 0.0])


LAVAPIPE_SETTINGS = {"LP_PERF": "no_linear"}
"""For Mesa's software Vulkan driver (lavapipe; ignored by every other driver): sample textures
nearest instead of bilinear. GGUI draws the frame as a texture exactly the window's size, texel
centres on pixel centres, where both give the same colours; nearest saves 2.4 ms of CPU a frame at
1280 × 720 (docs/BENCHMARKS.md, "The window"). Set before the driver starts, unless the user set it."""


TAICHI_WINDOW_NOISE = ("RHI Error",)
"""The beginnings of the lines Taichi's C++ side writes to stderr when GGUI cannot start Vulkan ("RHI Error:
Can not create Vulkan instance"); WindowUnavailable says the same in the program's own words."""
NO_VULKAN = (
    "no Vulkan driver for the window (on Debian/Ubuntu 'apt-get install mesa-vulkan-drivers libvulkan1' "
    "gives a software one)"
)
"""The reason given for Taichi's "Vulkan must be available for GGUI"."""


@contextlib.contextmanager
def stderr_caught(caught: list[str]):
    """Run the body with file descriptor 2 (where Taichi's C++ logger writes, past Python's sys.stderr)
    sent to a temporary file; its lines are appended to ``caught`` afterwards."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            caught.extend(sink.read().decode(errors="replace").splitlines(keepends=True))


def xlib():
    """Xlib through ctypes, with XOpenDisplay and XCloseDisplay typed, where $DISPLAY names an X display on
    Linux and the library is there; else None."""
    on_x = os.environ.get("DISPLAY") and sys.platform.startswith("linux")
    library = ctypes.util.find_library("X11") if on_x else None
    if library is None:
        return None
    try:
        x11 = ctypes.CDLL(library)
    except OSError:
        return None
    x11.XOpenDisplay.restype, x11.XOpenDisplay.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    return x11


def unreachable_display() -> str | None:
    """Why the X display that $DISPLAY names cannot be opened, or None (it can, or there is no X library to
    ask, or no DISPLAY). GGUI's GLFW, given a display it cannot open, prints "cannot initialize GLFW" and
    ends the process, so the display is tried first with Xlib's ``XOpenDisplay``."""
    display = os.environ.get("DISPLAY")
    x11 = xlib()
    if x11 is None:
        return None
    with stderr_caught([]):  # Xlib may say why on stderr; the reason below says it once
        handle = x11.XOpenDisplay(None)
    if not handle:
        return f"the display DISPLAY={display} cannot be opened"
    x11.XCloseDisplay(handle)
    return None


WINDOW_OFFSET = 100
"""Pixels from the screen's top left corner to the window's, as Taichi places it, where the screen leaves room."""


def screen_size() -> tuple[int, int] | None:
    """(width, height) of the default screen of the X display $DISPLAY names, or None where there is no X
    display or library to ask (Wayland, macOS, Windows: the window system places the window itself)."""
    x11 = xlib()
    if x11 is None:
        return None
    x11.XDefaultScreen.argtypes = [ctypes.c_void_p]
    x11.XDisplayWidth.argtypes = x11.XDisplayHeight.argtypes = [ctypes.c_void_p, ctypes.c_int]
    with stderr_caught([]):
        handle = x11.XOpenDisplay(None)
    if not handle:
        return None
    try:
        screen = x11.XDefaultScreen(handle)
        return int(x11.XDisplayWidth(handle, screen)), int(x11.XDisplayHeight(handle, screen))
    finally:
        x11.XCloseDisplay(handle)


def window_position(width: int, height: int, screen: tuple[int, int] | None) -> tuple[int, int]:
    """Where a window of ``width`` × ``height`` opens: WINDOW_OFFSET from the top left corner where the
    screen leaves room, nearer the corner where it does not, so that the whole window is on the screen
    (Xvfb's 1280 × 720 or 1280 × 1024 screen cut a 1280 × 720 window at (100, 100)); the corner itself
    for a window larger than the screen."""
    if screen is None:
        return WINDOW_OFFSET, WINDOW_OFFSET
    return tuple(max(0, min(WINDOW_OFFSET, room - size)) for room, size in zip(screen, (width, height)))


def open_window(title: str, width: int, height: int, vsync: bool = True, show_window: bool = True):
    """A GGUI window, or WindowUnavailable with the reason in one line. Taichi's own error lines about a
    window that cannot open are dropped (the reason replaces them); anything else it writes passes.
    ``show_window=False``: GGUI draws offscreen, needing Vulkan but no display (benchmarks/window.py
    --offscreen); such a window's frames are drawn by ``get_image_buffer_as_numpy``, as its ``show``
    (which presents) crashes in Taichi 1.7.4 without a surface."""
    if show_window:
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise WindowUnavailable("DISPLAY is not set")
        unreachable = unreachable_display()
        if unreachable is not None:
            raise WindowUnavailable(unreachable)
    for name, value in LAVAPIPE_SETTINGS.items():
        os.environ.setdefault(name, value)
    caught: list[str] = []
    try:
        with stderr_caught(caught):
            position = window_position(width, height, screen_size() if show_window else None)
            return ti.ui.Window(title, (width, height), vsync=vsync, show_window=show_window, pos=position)
    except RuntimeError as error:
        reason = str(error).strip().splitlines()[-1]
        caught = [line for line in caught if not line.startswith(TAICHI_WINDOW_NOISE)]
        raise WindowUnavailable(NO_VULKAN if "Vulkan must be available" in reason else reason) from None
    finally:
        sys.stderr.write("".join(caught))


def show_waiting(gui_window, background_rgb, lines) -> None:
    """Present one frame of the scene's background with ``lines`` in a small panel, so that the window says
    what it waits for (the kernels compiling) instead of standing black until the first picture."""
    for _ in range(2):  # Dear ImGui lays out a window it has not seen before in a first frame it does not draw
        gui_window.get_canvas().set_background_color(tuple(float(c) for c in background_rgb))
        height = (len(lines) + 2) * ROW_PX / gui_window.get_window_shape()[1]
        with gui_window.get_gui().sub_window("pbf", 0.01, 0.01, 0.5, height) as gui:
            for line in lines:
                gui.text(line)
        gui_window.show()


class WindowViewer:
    """The interactive viewer of ``pbf.app.loop.run``: draws each frame in a GGUI window and turns keys
    and mouse into camera moves, pause, single steps and resets, until the user quits."""

    def __init__(self, sim, window):
        self.sim = sim
        self.window = window
        self.render = sim.scene.render
        self.camera = OrbitCamera.from_view(View.of_scene(sim.scene))
        width, height = window.get_window_shape()
        self.camera.clear_of(PANEL[0] + PANEL[2], width / height)  # the scene's framing, beside the panel
        self.frames = SceneRenderer(sim, width, height)
        """The frames in the scene's style, at the window's size (``pbf.app.render.SceneRenderer``)."""
        self.paused = False
        self.step_once = False
        self.panel_shown = True
        self.help_shown = False
        self.quit = False
        self.drag = None
        self.hand = Hand(sim)
        self.cursor: tuple[float, float] | None = None
        """The cursor in window fractions (origin bottom left) where it may touch the water: inside the
        window and off the panel; None elsewhere."""
        self.fps = 0.0
        self.last_frame: float | None = None
        self.sim_ms: float | None = None
        """Running means: the simulation's step, our renderer's draw, GGUI's show (canvas image, panel,
        present); ms."""
        self.draw_ms: float | None = None
        self.show_ms: float | None = None
        self.step_started: float | None = None
        self.stats: dict | None = None
        self.stats_key = None
        self.stats_time = 0.0

    def running(self) -> bool:
        return self.window.running and not self.quit

    def advance(self) -> bool:
        """Handle the input since the last frame; whether the simulation steps a frame now."""
        now = time.perf_counter()
        seconds = now - self.last_frame if self.last_frame is not None else 1.0 / 60.0
        # A running mean of the frame rate from the second frame on, started from that frame's own
        # rate (from 0 it would take dozens of frames to read right).
        if self.last_frame is not None:
            rate = 1.0 / max(seconds, 1e-6)
            self.fps = rate if self.fps == 0.0 else 0.9 * self.fps + 0.1 * rate
        self.last_frame = now
        self.quit = not self.handle_input(seconds)
        stepping = not self.quit and (not self.paused or self.step_once)
        self.step_once = False
        self.step_started = time.perf_counter() if stepping else None  # the loop steps now
        return stepping

    def show(self) -> None:
        started = time.perf_counter()
        if self.step_started is not None:  # the time since advance() is the simulation's step
            ti.sync()  # on CUDA kernels run asynchronously: count them in the step, not in the draw
            started = time.perf_counter()
            self.sim_ms = running_mean(self.sim_ms, 1e3 * (started - self.step_started))
            self.step_started = None
        self.draw()
        drawn = time.perf_counter()
        self.panel(self.current_stats())
        self.window.show()
        self.draw_ms = running_mean(self.draw_ms, 1e3 * (drawn - started))
        self.show_ms = running_mean(self.show_ms, 1e3 * (time.perf_counter() - drawn))

    def current_stats(self) -> dict:
        """The simulation's statistics, recomputed when it has changed and at most every
        ``STATS_INTERVAL_S`` while it runs (a single step, a reset or a pause shows at once)."""
        key = (self.sim.frame, self.sim.time_s)
        now = time.perf_counter()
        if self.stats is None or (key != self.stats_key and (self.paused or now - self.stats_time >= STATS_INTERVAL_S)):
            self.stats, self.stats_key, self.stats_time = self.sim.stats(), key, now
        return self.stats

    def close(self) -> None:
        """Nothing to release: GGUI closes the window when the process ends."""

    def handle_input(self, seconds: float) -> bool:
        """Keys and mouse since the last frame; False when the user quits."""
        window = self.window
        for event in window.get_events(ti.ui.PRESS):
            if event.key == ti.ui.ESCAPE:
                return False
            if event.key == ti.ui.SPACE:
                self.paused = not self.paused
            elif event.key == "n" and self.paused:
                self.step_once = True
            elif event.key == "h":
                self.help_shown = not self.help_shown
            elif event.key == "Tab":
                self.panel_shown = not self.panel_shown
            elif event.key == "r":
                self.sim.reset()
            elif event.key == "f":
                self.sim.control.emitters_on = not self.sim.control.emitters_on
            elif event.key == "m":
                self.sim.control.wave_maker_on = not self.sim.control.wave_maker_on
            elif event.key == "v":
                self.surface = not self.surface
        speed = 0.5 * self.camera.distance * seconds  # half the viewing distance per second
        keys = {key: window.is_pressed(key) for key in "wasdqe"}
        self.camera.move(
            speed * (keys["w"] - keys["s"]), speed * (keys["d"] - keys["a"]), speed * (keys["e"] - keys["q"])
        )
        self.handle_mouse(seconds)
        return True

    def handle_mouse(self, seconds: float) -> None:
        """Left drag pushes the water (if the press hit it), right drag orbits, shift + right or middle
        drag zooms; presses over the panel belong to the panel."""
        window = self.window
        x, y = window.get_cursor_pos()
        width, height = window.get_window_shape()
        left, top, panel_width, panel_height = self.panel_rect()
        over_panel = self.panel_shown and left <= x <= left + panel_width and top <= 1.0 - y <= top + panel_height
        self.cursor = (x, y) if 0.0 <= x < 1.0 and 0.0 <= y < 1.0 and not over_panel else None
        if window.is_pressed(ti.ui.LMB):
            if self.hand.holding:
                self.hand.drag(self.camera.view(), x, y, width / height, seconds)
            elif self.drag is None and not over_panel:
                self.hand.grab(self.camera.view(), x, y, width / height)
                self.drag = (x, y)  # a press that missed the water does nothing until released
            return
        if self.hand.holding:
            self.hand.release()
        zooming = window.is_pressed(ti.ui.MMB) or (window.is_pressed(ti.ui.RMB) and window.is_pressed(ti.ui.SHIFT))
        if not (zooming or window.is_pressed(ti.ui.RMB)) or (self.drag is None and over_panel):
            self.drag = None
        elif self.drag is not None:
            dx, dy = x - self.drag[0], y - self.drag[1]
            self.camera.zoom(dy) if zooming else self.camera.orbit(dx, -dy)
            self.drag = (x, y)
        else:
            self.drag = (x, y)

    def panel_rect(self) -> tuple[float, float, float, float]:
        """The panel's place and size now: taller by the help's lines while it shows them, so that
        nothing needs scrolling (up to the window's height)."""
        left, top, width, _ = PANEL
        rows = PANEL_ROWS + (len(HELP) + 1 if self.help_shown else 0)
        return left, top, width, min(1.0 - 2 * top, rows * ROW_PX / self.window.get_window_shape()[1])

    def panel_name(self) -> str:
        """The panel's GGUI name: its title and, after ``###``, what Dear ImGui (under GGUI) tells its windows
        apart by. ImGui takes a window's size from ``sub_window`` only the first time it meets the name, and
        remembers it (in imgui.ini, across runs too), so a panel grown for the help under the same name would
        keep its first size and need scrolling: each height the panel takes is a window of its own name."""
        height_px = round(self.panel_rect()[3] * self.window.get_window_shape()[1])
        return f"{PANEL_TITLE}###pbf panel {height_px} px"

    def panel(self, stats: dict) -> None:
        if not self.panel_shown:
            return
        control = self.sim.control
        with self.window.get_gui().sub_window(self.panel_name(), *self.panel_rect()) as gui:
            gui.text(f"{self.sim.scene.name}  ·  {stats['backend']}  ·  {'paused' if self.paused else 'running'}")
            gui.text(f"{self.fps:5.1f} fps   t = {stats['time_s']:.2f} s")
            for line in timing_lines(self.sim_ms, self.draw_ms, self.show_ms):
                gui.text(line)
            gui.text(f"{stats['particles']:,} particles, dt = {self.sim.dt_s * 1e3:.2f} ms")
            gui.text(f"density error mean {stats['mean_density_error']:.3%}  max {stats['max_density_error']:.2%}")
            gui.text(f"max speed {stats['max_speed_m_s']:.2f} m/s")
            if not self.surface:
                gui.text(legend_line(self.render))
            # f and m act only where the scene has emitters or a wave maker; say so either way.
            scene = self.sim.scene
            gui.text(
                f"emitters (f): {('on' if control.emitters_on else 'off') if scene.emitters else 'none here'};  "
                f"wave maker (m): "
                f"{('on' if control.wave_maker_on else 'off') if scene.wave_maker.stroke_m else 'none here'}"
            )
            # The CFL limit may take more substeps than asked, and an error target fewer iterations.
            gui.text(
                f"substeps {control.substeps} asked, {stats['substeps']} used; iterations {stats['iterations']} used"
            )
            control.iterations = gui.slider_int("iterations", control.iterations, 1, 20)
            control.substeps = gui.slider_int("substeps", control.substeps, 1, 16)
            control.xsph = gui.slider_float("XSPH c", control.xsph, 0.0, 0.1)
            control.vorticity = gui.slider_float("vorticity", control.vorticity, 0.0, 0.5)
            gx, gy, gz = control.gravity_m_s2
            control.gravity_m_s2 = (gx, gui.slider_float("gravity y m/s²", gy, -20.0, 0.0), gz)
            for line in HELP if self.help_shown else ():
                gui.text(line)

    @property
    def surface(self) -> bool:
        """Whether the window draws the water's surface (key v) rather than particles."""
        return self.frames.style == "surface"

    @surface.setter
    def surface(self, on: bool) -> None:
        self.frames.style = "surface" if on else "particles"

    def draw(self) -> None:
        """Render the frame at the window's size and hand it to GGUI's canvas."""
        self.frames.resize(*self.window.get_window_shape())
        view = self.camera.view()
        packed = self.frames.draw(view)
        self.mark(packed, view)
        show_packed(self.window.get_canvas(), packed)

    def cursor_depth(self) -> float | None:
        """The view depth (m) of the water drawn under the cursor in the last frame, None where there is none."""
        if self.cursor is None:
            return None
        width, height = self.frames.width, self.frames.height
        col, row_up = min(int(self.cursor[0] * width), width - 1), min(int(self.cursor[1] * height), height - 1)
        return self.frames.depth_at(col, row_up)

    def mark(self, packed: np.ndarray, view: View) -> None:
        """Ring in ``packed`` what a left press would take hold of: the hand's reach (``Hand.radius_m``) around
        the water under the cursor, or around the hand while it holds the water; nothing over empty space,
        where a press does nothing."""
        width, height = self.frames.width, self.frames.height
        right, up, forward = view.basis()
        focal = view.focal_px(height)
        if self.hand.holding:
            offset = self.hand.point - view.eye
            depth = float(offset @ forward)
            if depth <= 0.0:
                return
            x = 0.5 * width + focal * float(offset @ right) / depth
            y = 0.5 * height + focal * float(offset @ up) / depth
        else:
            depth = self.cursor_depth()
            if depth is None or depth <= 0.0:
                return
            x, y = self.cursor[0] * width, self.cursor[1] * height
        ring(packed, x, y, focal * self.hand.radius_m / depth, MARKER_WORD)


def timing_lines(sim_ms: float | None, draw_ms: float | None, show_ms: float | None) -> tuple[str, str]:
    """The panel's milliseconds per frame: the simulation's step, and apart from it the rendering (our
    renderer's draw, then GGUI's show: the canvas image, the panel and the present)."""

    def ms(value):
        return "-" if value is None else f"{value:.1f}"

    render = None if draw_ms is None or show_ms is None else draw_ms + show_ms
    return f"sim {ms(sim_ms)} ms per frame", f"render {ms(render)} ms (draw {ms(draw_ms)} + show {ms(show_ms)})"


def ring(packed: np.ndarray, x: float, y: float, radius_px: float, word: int) -> None:
    """Set the pixels of a ring two pixels wide, of radius ``radius_px`` around (x, y) (pixels, y up), in a
    (W, H) packed image to ``word``; what falls outside the image is left out."""
    radius_px = max(radius_px, 3.0)
    angles = np.linspace(0.0, 2.0 * np.pi, max(32, int(4 * np.pi * (radius_px + 1))), endpoint=False)
    for r in (radius_px, radius_px + 1.0):
        cols = np.floor(x + r * np.cos(angles)).astype(np.int64)
        rows = np.floor(y + r * np.sin(angles)).astype(np.int64)
        inside = (cols >= 0) & (cols < packed.shape[0]) & (rows >= 0) & (rows < packed.shape[1])
        packed[cols[inside], rows[inside]] = word
