"""Reaching into the water with the mouse.

A press casts a ray from the camera through the cursor; the first particle it passes within a
spacing of (the water each particle stands for, gaps between drawn spheres included) is where the hand grabs, at
that distance from the eye. While the button is held
the hand follows the cursor at that distance, and its velocity (how far it moved since the last frame,
over the frame's time) is handed to the solver as a ``Push``: the water around it is pulled along,
smoothly in space and never faster than the hand. Releasing lets go.
"""

from __future__ import annotations

import numpy as np

from pbf.app.render import View
from pbf.solver import Push

HAND_RADIUS_H = 2.0
"""The hand's radius in smoothing radii: it moves a few particles across, not one."""


def cursor_ray(view: View, x: float, y: float, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """Eye and unit direction of the ray through the cursor at (x, y), fractions of the window with the
    origin at the bottom left (GGUI's convention); ``aspect`` is width / height."""
    right, up, forward = view.basis()
    half_height = np.tan(np.radians(view.fov_deg) / 2)
    direction = forward + (2 * x - 1) * half_height * aspect * right + (2 * y - 1) * half_height * up
    return view.eye, direction / np.linalg.norm(direction)


def pick(positions: np.ndarray, radius_m: float, eye: np.ndarray, direction: np.ndarray) -> float | None:
    """Distance from the eye to the nearest particle the ray passes within ``radius_m`` of, or None."""
    along = (positions - eye) @ direction
    across = np.linalg.norm(positions - eye - along[:, None] * direction, axis=1)
    hit = (along > 0) & (across < radius_m)
    return float(along[hit].min()) if hit.any() else None


class Hand:
    """The mouse's grip on the water: :meth:`grab` on press, :meth:`drag` every frame, :meth:`release`."""

    def __init__(self, sim):
        self.sim = sim
        self.radius_m = HAND_RADIUS_H * sim.scene.kernel_radius_m
        self.distance_m: float | None = None
        self.point: np.ndarray | None = None

    @property
    def holding(self) -> bool:
        return self.point is not None

    def grab(self, view: View, x: float, y: float, aspect: float) -> bool:
        """Grab the water under the cursor; False (and nothing held) when the ray misses it."""
        eye, direction = cursor_ray(view, x, y, aspect)
        self.distance_m = pick(self.sim.positions(), self.sim.scene.fluid.spacing_m, eye, direction)
        if self.distance_m is None:
            return False
        self.point = eye + self.distance_m * direction
        return True

    def drag(self, view: View, x: float, y: float, aspect: float, seconds: float) -> None:
        """Move the hand to the cursor (at the grab's distance) and push the water with its velocity."""
        eye, direction = cursor_ray(view, x, y, aspect)
        point = eye + self.distance_m * direction
        velocity = (point - self.point) / max(seconds, 1e-3)
        self.point = point
        self.sim.control.push = Push(tuple(point), tuple(velocity), self.radius_m)

    def release(self) -> None:
        self.point = self.distance_m = None
        self.sim.control.push = None
