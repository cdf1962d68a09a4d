"""Rigid bodies: boxes and spheres that float, sink and are thrown, two-way coupled with the water
(``pbf.solver.bodies``), and what their poses must agree on."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pbf.scene.schema import SceneError, Vec3, _between, _length, _num, _one_of, _vec, _vec_between, key

MAX_BODIES = 16
"""Most [[bodies]]: each body is one more boundary every particle looks at in every iteration, and
its contacts with every other body are checked each substep."""
MIN_BODY_SPACINGS = 2
"""A body's least thickness (a box's every edge, a sphere's diameter), in spacings: as for obstacles
(``MIN_OBSTACLE_SPACINGS``), a particle moving at most time.max_cfl spacings a substep relative to
it cannot cross its middle and be pushed out on the far side."""
BODY_MAX_CFL = 1.5
"""The largest time.max_cfl with bodies (as with obstacles, ``OBSTACLE_MAX_CFL``)."""


@dataclass(frozen=True)
class Body:
    """A rigid body: a box or a sphere of uniform density, with an initial pose and velocity. Water
    inside it at the start (grown by half a spacing) is removed."""

    size_m: Vec3 = key(
        doc="a box's half extents along its own axes, m; a sphere's radius is the first value (the others are ignored)"
    )
    density_kg_m3: float = key(check=_between(1.0, 1e5), doc="the body's density, kg/m³ (below the water's it floats)")
    position_m: Vec3 = key(doc="centre of mass at the start, m")
    shape: str = key("box", _one_of("box", "sphere"), "box or sphere")
    orientation_deg: Vec3 = key(
        (0.0, 0.0, 0.0),
        _vec_between(-360.0, 360.0),
        "rotation at the start about x, then y, then z (fixed axes), degrees",
    )
    velocity_m_s: Vec3 = key((0.0, 0.0, 0.0), doc="initial velocity of the centre of mass, m/s")
    angular_velocity_rad_s: Vec3 = key(
        (0.0, 0.0, 0.0), _vec_between(-1e3, 1e3), "initial angular velocity, rad/s (world axes)"
    )

    def half_extents(self) -> np.ndarray:
        """The body's half extents along its own axes (a sphere: its radius on every axis), m."""
        if self.shape == "sphere":
            return np.full(3, float(self.size_m[0]))
        return np.array(self.size_m, np.float64)

    def bounding_radius(self) -> float:
        """The farthest any point of the body lies from its centre, m."""
        return float(np.linalg.norm(self.half_extents())) if self.shape == "box" else float(self.size_m[0])

    def volume_m3(self) -> float:
        if self.shape == "sphere":
            return 4.0 / 3.0 * math.pi * self.size_m[0] ** 3
        return 8.0 * math.prod(self.size_m)

    def mass_kg(self) -> float:
        return self.density_kg_m3 * self.volume_m3()

    def rotation(self) -> np.ndarray:
        """The initial rotation matrix, R = R_z R_y R_x (float64)."""
        ax, ay, az = (math.radians(a) for a in self.orientation_deg)
        rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
        ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
        rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
        return rz @ ry @ rx

    def quaternion(self) -> np.ndarray:
        """The initial orientation as a unit quaternion (w, x, y, z)."""
        return rotation_to_quaternion(self.rotation())

    def world_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The axis-aligned box around the body at its initial pose, m."""
        centre = np.array(self.position_m, np.float64)
        if self.shape == "sphere":
            reach = np.full(3, float(self.size_m[0]))
        else:
            reach = np.abs(self.rotation()) @ self.half_extents()
        return centre - reach, centre + reach

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which of the (n, 3) ``points`` lie inside the body at its initial pose grown by ``margin``."""
        local = (np.asarray(points, np.float64) - np.array(self.position_m)) @ self.rotation()
        if self.shape == "sphere":
            return np.linalg.norm(local, axis=1) < self.size_m[0] + margin
        return np.all(np.abs(local) < self.half_extents() + margin, axis=1)


def rotation_to_quaternion(r: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method, float64)."""
    trace = np.trace(r)
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0] * 4
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.array(q)
    return q / np.linalg.norm(q)


def _check_bodies(scene, source: str) -> None:
    """Bodies: thick enough, inside the container, clear of the obstacles and of each other."""
    spacing = scene.fluid.spacing_m
    thinnest = MIN_BODY_SPACINGS * spacing
    c_lo, c_hi = np.array(scene.container.min_m), np.array(scene.container.max_m)
    for i, body in enumerate(scene.bodies):
        where = f"{source}: key 'bodies[{i}]"
        if (
            body.shape == "box"
            and min(body.size_m) * 2 < thinnest
            or body.shape == "sphere"
            and body.size_m[0] * 2 < thinnest
        ):
            raise SceneError(
                f"{where}.size_m' = {_vec(body.size_m)}: a body must be at least {MIN_BODY_SPACINGS} "
                f"spacings ({_num(thinnest)} m) thick on every axis (size_m holds half extents, or the "
                f"radius), or particles could cross it"
            )
        lo, hi = body.world_bounds()
        if np.any(lo < c_lo) or np.any(hi > c_hi):
            raise SceneError(
                f"{where}.position_m': the body reaches {_vec(lo)}–{_vec(hi)} m, outside the container "
                f"{_vec(c_lo)}–{_vec(c_hi)} m; move it inside"
            )
        for j, obstacle in enumerate(scene.obstacles):
            if np.all(np.minimum(hi, obstacle.max_m) > np.maximum(lo, obstacle.min_m)):
                raise SceneError(f"{where}.position_m' overlaps obstacles[{j}]; bodies must start clear of obstacles")
        for j, other in enumerate(scene.bodies[:i]):
            gap = np.linalg.norm(np.array(body.position_m) - np.array(other.position_m))
            if gap < body.bounding_radius() + other.bounding_radius():
                raise SceneError(
                    f"{where}.position_m' is within reach of bodies[{j}] ({_num(gap)} m between "
                    f"centres, less than their bounding radii {_num(body.bounding_radius())} + "
                    f"{_num(other.bounding_radius())} m); bodies must start apart"
                )
        followed = scene.fastest_followed_m_s
        fall = _length(scene.gravity_m_s2) * scene.time.frame_dt_s
        speed = _length(body.velocity_m_s) + _length(body.angular_velocity_rad_s) * body.bounding_radius()
        if not speed + fall <= followed:
            raise SceneError(
                f"{where}.velocity_m_s': its fastest point moves at {_num(speed)} m/s (|v| + |ω| r, plus "
                f"{_num(fall)} m/s of gravity in the first frame), faster than the {_num(followed)} m/s "
                f"a frame's substeps can follow (time.max_substeps × time.max_cfl × fluid.spacing_m / "
                f"time.frame_dt_s); allowed: ≤ {_num(followed - fall)} m/s, or raise time.max_substeps"
            )
    if scene.bodies and scene.time.max_cfl > BODY_MAX_CFL:
        raise SceneError(
            f"{source}: key 'time.max_cfl' = {_num(scene.time.max_cfl)} lets particles cross a body "
            f"in one substep; with [[bodies]] it must be ≤ {_num(BODY_MAX_CFL)}: set time.max_cfl = "
            f"{_num(BODY_MAX_CFL)} beside them"
        )
