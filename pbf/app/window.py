"""The interactive window (Taichi GGUI): orbit camera, keys, a panel of live figures and sliders.

Mouse: left drag on the water pushes it (``pbf.app.interact``), right drag orbits around the
target, shift + right drag (or middle drag) zooms. Keys (``KEYS``): W/A/S/D move the target
forward, left, back and right, Q/E down and up; space pauses and resumes, n steps one frame while
paused, h shows the help, Tab hides the panel, r resets, f turns the emitters on and off, m the wave maker, v switches between particles and the
water's surface, esc quits. Particles are drawn at their simulated radius with the colours of the
headless renderer (``pbf.app.render``), the container and obstacles as lines. The surface is the
headless screen-space renderer (``pbf.app.fluid_render``) run on the window's camera every frame and
shown as the canvas's image: GGUI has no custom shaders, and a mesh reconstructed every frame
(``pbf.app.surface``) would cost more than the whole surface render. ``WindowViewer`` runs it in the
loop of ``pbf.app.loop``.
"""
import math
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
import taichi as ti

from pbf.app.interact import Hand
from pbf.app.keys import HELP
from pbf.app.legend import legend_line
from pbf.app.render import LIGHT_DIRECTION, ParticleColours, View, fluid_renderer, scene_edges

PANEL = (0.01, 0.01, 0.3, 0.40)
"""The panel's x, y, width and height as fractions of the window (origin top left), without the help."""
HELP_HEIGHT = 0.30
"""What the help lines add to the panel's height."""


@ti.kernel
def to_canvas(image: ti.template(), canvas_image: ti.template()):
    """Copy an (H, W) image, row 0 at the top, into the (W, H) image GGUI's canvas takes (y up)."""
    for row, col in image:
        canvas_image[col, image.shape[0] - 1 - row] = image[row, col]


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
        return cls(view.target.astype(float), math.atan2(offset[0], offset[2]),
                   math.asin(offset[1] / distance), distance, view.fov_deg)

    def view(self) -> View:
        direction = np.array([math.cos(self.pitch) * math.sin(self.yaw), math.sin(self.pitch),
                              math.cos(self.pitch) * math.cos(self.yaw)])
        return View(self.target + self.distance * direction, self.target.copy(), self.fov_deg)

    def orbit(self, dx: float, dy: float) -> None:
        """Turn by a drag of (dx, dy) window widths/heights: a full width is half a turn."""
        self.yaw -= math.pi * dx
        self.pitch = min(max(self.pitch - math.pi * dy, -1.5), 1.5)

    def zoom(self, dy: float) -> None:
        """Dolly in (drag up) or out (drag down); each window height of drag is a factor e."""
        self.distance = max(1e-3, self.distance * math.exp(-dy))

    def move(self, forward: float, right: float, up: float) -> None:
        """Move eye and target together, in metres, along the horizontal view direction, right and up."""
        ahead = np.array([-math.sin(self.yaw), 0.0, -math.cos(self.yaw)])
        side = np.array([math.cos(self.yaw), 0.0, -math.sin(self.yaw)])
        self.target = self.target + forward * ahead + right * side + np.array([0.0, up, 0.0])


def open_window(title: str, width: int, height: int):
    """A GGUI window, or WindowUnavailable with the reason in one line."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise WindowUnavailable("no display (DISPLAY is not set)")
    try:
        return ti.ui.Window(title, (width, height), vsync=True)
    except RuntimeError as error:
        raise WindowUnavailable(str(error).strip().splitlines()[-1]) from None


class WindowViewer:
    """The interactive viewer of ``pbf.app.loop.run``: draws each frame in a GGUI window and turns keys
    and mouse into camera moves, pause, single steps and resets, until the user quits."""

    def __init__(self, sim, window):
        self.sim = sim
        self.window = window
        self.render = sim.scene.render
        self.camera = OrbitCamera.from_view(View.of_scene(sim.scene))
        self.colours = ParticleColours(sim, self.render)
        edges = scene_edges(sim.scene)
        self.edges = ti.Vector.field(3, ti.f32, shape=len(edges))
        self.edges.from_numpy(edges)
        self.gg_camera = ti.ui.Camera()
        self.surface = self.render.style == "surface"
        """Draw the water's surface (key v) rather than particles."""
        self.surface_renderer = None
        self.canvas_image = None
        self.paused = False
        self.step_once = False
        self.panel_shown = True
        self.help_shown = False
        self.quit = False
        self.drag = None
        self.hand = Hand(sim)
        self.fps = 0.0
        self.last_frame: float | None = None

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
        return stepping

    def show(self) -> None:
        self.draw()
        self.panel(self.sim.stats())
        self.window.show()

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
        self.camera.move(speed * (keys["w"] - keys["s"]), speed * (keys["d"] - keys["a"]),
                         speed * (keys["e"] - keys["q"]))
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
        """The panel's place and size now: taller while it shows the help."""
        left, top, width, height = PANEL
        return left, top, width, height + (HELP_HEIGHT if self.help_shown else 0.0)

    def panel(self, stats: dict) -> None:
        if not self.panel_shown:
            return
        control = self.sim.control
        with self.window.get_gui().sub_window("pbf (h: help, Tab: hide)", *self.panel_rect()) as gui:
            gui.text(f"{self.sim.scene.name}  ·  {stats['backend']}  ·  {'paused' if self.paused else 'running'}")
            gui.text(f"{self.fps:5.1f} fps   t = {stats['time_s']:.2f} s")
            gui.text(f"{stats['particles']:,} particles, dt = {self.sim.dt_s * 1e3:.2f} ms")
            gui.text(f"density error mean {stats['mean_density_error']:.3%}  max {stats['max_density_error']:.2%}")
            gui.text(f"max speed {stats['max_speed_m_s']:.2f} m/s")
            if not self.surface:
                gui.text(legend_line(self.render))
            # f and m act only where the scene has emitters or a wave maker; say so either way.
            scene = self.sim.scene
            gui.text(f"emitters (f): {('on' if control.emitters_on else 'off') if scene.emitters else 'none here'};  "
                     f"wave maker (m): {('on' if control.wave_maker_on else 'off') if scene.wave_maker.stroke_m else 'none here'}")
            # The CFL limit may take more substeps than asked, and an error target fewer iterations.
            gui.text(f"substeps {control.substeps} asked, {stats['substeps']} used; "
                     f"iterations {stats['iterations']} used")
            control.iterations = gui.slider_int("iterations", control.iterations, 1, 20)
            control.substeps = gui.slider_int("substeps", control.substeps, 1, 16)
            control.xsph = gui.slider_float("XSPH c", control.xsph, 0.0, 0.1)
            control.vorticity = gui.slider_float("vorticity", control.vorticity, 0.0, 0.5)
            gx, gy, gz = control.gravity_m_s2
            control.gravity_m_s2 = (gx, gui.slider_float("gravity y m/s²", gy, -20.0, 0.0), gz)
            for line in HELP if self.help_shown else ():
                gui.text(line)

    def draw(self) -> None:
        if self.surface:
            self.draw_surface()
        else:
            self.draw_particles()

    def draw_surface(self) -> None:
        """The screen-space water surface at the window's size, shown as the canvas's image."""
        width, height = self.window.get_window_shape()
        renderer = self.surface_renderer
        if renderer is None or (renderer.width, renderer.height) != (width, height):  # first use, or resized
            self.surface_renderer = fluid_renderer(self.sim, width, height)
            self.canvas_image = ti.Vector.field(3, ti.u8, shape=(width, height))
        particles = self.sim.readout()
        self.surface_renderer.draw(self.camera.view(), particles.positions, particles.count, LIGHT_DIRECTION)
        to_canvas(self.surface_renderer.image, self.canvas_image)
        self.window.get_canvas().set_image(self.canvas_image)

    def draw_particles(self) -> None:
        view = self.camera.view()
        camera = self.gg_camera
        camera.position(*view.eye)
        camera.lookat(*view.target)
        camera.up(0.0, 1.0, 0.0)
        camera.fov(view.fov_deg)
        scene = self.window.get_scene()
        scene.set_camera(camera)
        scene.ambient_light((0.35, 0.35, 0.35))
        light = view.eye + 10.0 * LIGHT_DIRECTION
        scene.point_light(pos=tuple(light), color=(0.9, 0.9, 0.9))
        width, height = self.window.get_window_shape()
        # GGUI scales particle radii by width/height: undo it so particles show their simulated size.
        particles = self.sim.readout()
        scene.particles(particles.positions, radius=particles.radius_m * height / width,
                        per_vertex_color=self.colours.update(), index_count=particles.count)
        scene.lines(self.edges, width=1.5, color=tuple(self.render.container_rgb))
        canvas = self.window.get_canvas()
        canvas.set_background_color(tuple(self.render.background_rgb))
        canvas.scene(scene)
