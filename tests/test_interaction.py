"""The mouse moves the water: driven through the window's own input handling, with a stand-in for the
GGUI window (no display needed)."""

import numpy as np
import pytest
import taichi as ti

from pbf import Simulation
from pbf.app.render import View
from pbf.app.window import OrbitCamera, WindowViewer

POOL = {
    "name": "pool",
    "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [1.2, 0.4, 0.3]},
    "fluid": {"spacing_m": 0.025, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [1.2, 0.1, 0.3]}]},
    "time": {"substeps": 1},
    "solver": {"iterations": 2},
}


class StandInWindow:
    """What WindowViewer asks of a GGUI window: events, buttons, the cursor, the size."""

    running = True

    def __init__(self):
        self.cursor = (0.5, 0.5)
        self.pressed = set()

    def get_events(self, kind):
        return []

    def is_pressed(self, key):
        return key in self.pressed

    def get_cursor_pos(self):
        return self.cursor

    def get_window_shape(self):
        return (1280, 720)


def grab_the_pool(sim):
    """A window over ``sim`` looking down at the pool's surface near its left end (x to the right of
    the image), the left button pressed at the centre: the ray hits the water and the hand grabs."""
    window = StandInWindow()
    viewer = WindowViewer(sim, window)
    viewer.camera = OrbitCamera.from_view(View(np.array([0.2, 0.5, 0.6]), np.array([0.2, 0.1, 0.15]), 45.0))
    window.pressed = {ti.ui.LMB}
    viewer.handle_input(1 / 60)
    return window, viewer


@pytest.mark.slow
def test_dragging_pushes_the_water_under_the_cursor_and_nothing_else():
    sim, reference = Simulation(POOL), Simulation(POOL)
    window, viewer = grab_the_pool(sim)
    assert viewer.hand.holding and sim.control.push is None
    grabbed = viewer.hand.point.copy()
    window.cursor = (0.53, 0.5)  # drag to the right
    viewer.handle_input(1 / 60)
    push = sim.control.push
    assert push is not None and push.velocity_m_s[0] > 0.5 and abs(push.velocity_m_s[2]) < 0.1 * push.velocity_m_s[0]
    sim.step()
    reference.step()
    x, v = sim.positions(), sim.velocities()
    x_ref, v_ref = reference.positions(), reference.velocities()
    near = np.linalg.norm(x_ref - grabbed, axis=1) < 0.5 * push.radius_m
    assert near.sum() > 5
    assert (v - v_ref)[near, 0].mean() > 0.2 * push.velocity_m_s[0]  # pulled along the drag
    # Beyond the hand and the distance one frame carries a change, nothing changed, to the bit: per
    # substep, each iteration reads neighbours twice (λ from their positions, Δx from their λ) and
    # the velocity pass twice more (ω, then the location vector from |ω|), h each time.
    reach = push.radius_m + sim.frame_substeps * (2 * sim.control.iterations + 2) * sim.scene.kernel_radius_m
    far = np.linalg.norm(x_ref - grabbed, axis=1) > reach
    assert far.sum() > 100 and np.array_equal(x[far], x_ref[far]) and np.array_equal(v[far], v_ref[far])
    window.pressed = set()
    viewer.handle_input(1 / 60)  # release: the hand lets go
    assert not viewer.hand.holding and sim.control.push is None


def test_a_press_that_misses_the_water_grabs_nothing():
    sim = Simulation(POOL)
    window = StandInWindow()
    viewer = WindowViewer(sim, window)
    viewer.camera = OrbitCamera.from_view(View(np.array([0.6, 0.3, 1.5]), np.array([0.6, 0.35, 0.0]), 45.0))
    window.pressed = {ti.ui.LMB}
    window.cursor = (0.5, 0.9)  # the sky above the pool
    viewer.handle_input(1 / 60)
    window.cursor = (0.6, 0.9)
    viewer.handle_input(1 / 60)
    assert not viewer.hand.holding and sim.control.push is None


class Key:
    def __init__(self, key):
        self.key = key


def test_keys_switch_the_emitters_and_the_wave_maker():
    scene = {
        "name": "toggles",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.6, 0.4, 0.2]},
        "fluid": {"spacing_m": 0.025, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.6, 0.1, 0.2]}]},
        "wave_maker": {"stroke_m": 0.03, "period_s": 0.5},
        "emitters": [{"position_m": [0.4, 0.3, 0.1], "direction": [0, -1, 0], "radius_m": 0.03, "end_s": 2.0}],
    }
    sim = Simulation(scene)
    window = StandInWindow()
    viewer = WindowViewer(sim, window)
    window.get_events = lambda kind: [Key("f"), Key("m")]
    viewer.handle_input(1 / 60)
    window.get_events = lambda kind: []
    assert not sim.control.emitters_on and not sim.control.wave_maker_on
    count = sim.particle_count
    sim.step(10)
    assert sim.particle_count == count  # no water poured
    assert float(sim.boundaries.container.piston_x[None]) == 0.0  # the piston stood still
    window.get_events = lambda kind: [Key("f"), Key("m")]
    viewer.handle_input(1 / 60)
    sim.step(10)
    # Resumed at 40 layers a second of 9 particles: 10 frames add 7 layers; releasing the layers held
    # back while off as well would add 14.
    assert sim.particle_count - count <= 8 * 9
    assert sim.particle_count > count and float(sim.boundaries.container.piston_x[None]) > 0.0


def test_every_key_is_one_ggui_delivers_and_each_does_what_the_help_says():
    # GGUI never reports '.', ',', digits or F-keys (measured under Xvfb): a key bound to one of them
    # could never be pressed.
    from pbf.app.keys import ESCAPE, GGUI_KEYS, HELP, KEYS, SPACE

    assert (SPACE, ESCAPE) == (ti.ui.SPACE, ti.ui.ESCAPE)
    assert set(KEYS) <= GGUI_KEYS
    assert all(any(what in line for line in HELP) for what in KEYS.values())
    sim = Simulation(POOL)
    window = StandInWindow()
    viewer = WindowViewer(sim, window)
    window.get_events = lambda kind: [Key(ti.ui.SPACE), Key("h"), Key("Tab")]
    viewer.handle_input(1 / 60)
    assert viewer.paused and viewer.help_shown and not viewer.panel_shown
    window.get_events = lambda kind: [Key("n")]
    assert viewer.advance()  # n: one frame ...
    window.get_events = lambda kind: []
    assert not viewer.advance()  # ... and paused again


@pytest.mark.slow
def test_a_slow_drag_carries_the_water_under_the_hand_along():
    # A slow, steady drag (the hand at about 5 cm/s) moves the water it holds with it, not only a quick
    # flick: after 40 frames the particles that started within half the hand's radius have followed
    # it by most of its way (94% here), while water a hand's width and more away has barely moved.
    sim = Simulation(POOL)
    window, viewer = grab_the_pool(sim)
    start, before = viewer.hand.point.copy(), sim.positions()
    near = np.linalg.norm(before - start, axis=1) < 0.5 * viewer.hand.radius_m
    far = np.linalg.norm(before - start, axis=1) > 0.3
    for frame in range(40):
        window.cursor = (0.5 + 0.001 * (frame + 1), 0.5)
        viewer.handle_input(1 / 60)
        sim.step()
    hand = viewer.hand.point[0] - start[0]
    assert 0.02 < hand < 0.06  # a slow drag: 3-4 cm in two thirds of a second
    moved = sim.positions() - before
    assert near.sum() > 5 and moved[near, 0].mean() > 0.6 * hand
    assert abs(moved[far, 0].mean()) < 0.1 * hand
