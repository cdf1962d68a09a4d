"""Rigid bodies two-way coupled with the water: boxes and spheres as moving boundaries with ghost density.

A body is one more part of ``pbf.solver.boundary.Boundaries``: the fluid sees the ghost fluid inside it
and, in the divergence pre-correction, its velocity v + ω × (p − c). It takes the reaction of the
water's pressure and of the collision's push, summed over fixed blocks of particles in order,

    F_b = Σ_i V p_i ∇ψ_b(x_i) − Σ_{i pushed by b} m D_i / Δt²,   τ_b = Σ_i (x_i − c_b) × f_i,

and each substep takes a symplectic Euler step, then its contacts by sequential impulses in a fixed
order. The method and why: docs/BODIES.md.
"""

import math

import numpy as np
import taichi as ti

from pbf.solver import backend
from pbf.solver.constants import array_loader, scene_constants
from pbf.solver.density import pressure, pressure_scales
from pbf.solver.launch import Launcher
from pbf.solver.model import BoundaryParams, allocation

STATE_LAYOUT = (
    ("position_m", 3),
    ("quaternion", 4),
    ("velocity_m_s", 3),
    ("angular_velocity_rad_s", 3),
    ("force_n", 3),
    ("torque_n_m", 3),
)
"""A body's row in :meth:`Bodies.state` (a snapshot's ``bodies``), the last substep's reaction included."""
STATE_WIDTH = sum(width for _, width in STATE_LAYOUT)
_STARTS = tuple(sum(width for _, width in STATE_LAYOUT[:k]) for k in range(len(STATE_LAYOUT)))
FRICTION = 0.4  # Coulomb friction coefficient of body contacts (wet wood or plastic on plastic)
COLLISION_AT_REST = 1.0
"""Particle centres stay this fraction of the particle radius r outside a body at rest, as at the walls: a
floating box then floats at its draft (docs/VALIDATION.md)."""
COLLISION_MOVING = 0.2
"""The least fraction of r, for a moving body: its ghost's pressure, not the collision, must meet the water."""
COLLISION_GIVE = 1.0
"""The collision distance is r less this many times the distance the body's fastest point moves in a
substep: at 1 a moving body does not sweep the water with its collision (docs/BODIES.md)."""
CONTACT_SWEEPS = 8  # passes over all contacts per substep: a box on four corners needs several to settle
CORNERS = 8  # a box's corners; the candidates of a body against an obstacle (a sphere uses the first)
CONTAINER_CANDIDATES = 6 * CORNERS  # against the container: per corner, below and above each axis's walls
EDGE_PAIRS = 12 * 12  # edge-across-edge candidates of two boxes


@ti.func
def component(vector, axis):
    """vector[axis] for a runtime axis, by selection (no runtime index into a local vector)."""
    return ti.select(axis == 0, vector[0], ti.select(axis == 1, vector[1], vector[2]))


@ti.func
def quaternion_multiply(a, b):
    """The Hamilton product a b of quaternions (w, x, y, z)."""
    return ti.Vector(
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    )


@ti.pyfunc
def quaternion_matrix(q):
    """The rotation matrix of a unit quaternion (w, x, y, z), in a kernel or on the host (a ``ti.Matrix`` there)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ti.Matrix(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_matrix_np(q) -> np.ndarray:
    """:func:`quaternion_matrix` on the host as a float64 NumPy array (renderers, exports, tests)."""
    return quaternion_matrix([float(c) for c in q]).to_numpy()


@ti.func
def _closest_on_segments(p0, d1, q0, d2):
    """The closest points of non-parallel segments p0 + s d1, q0 + t d2, s, t in [0, 1] (Ericson, §5.1.9)."""
    r = p0 - q0
    a, e, f = d1.dot(d1), d2.dot(d2), d2.dot(r)
    c, b = d1.dot(r), d1.dot(d2)
    denominator = a * e - b * b
    s = ti.min(ti.max((b * f - c * e) / denominator, 0.0), 1.0)
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, ti.min(ti.max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, ti.min(ti.max((b - c) / a, 0.0), 1.0)
    return p0 + s * d1, q0 + t * d2


@ti.func
def _no_contact():
    """(found, point, normal, depth) of a candidate that touches nothing."""
    return False, ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]), 0.0


@ti.data_oriented
class SolidParts:
    """What the bodies and the obstacles (``pbf.solver.boundary.Obstacles``) share as parts of ``Boundaries``:
    their ghost, never the fluid's mirror image. A subclass has ``tables`` (``GhostTables``), ``constants``
    (the container's and ``count``), ``count`` on the host and ``ghost_of(p, k)``, solid k's ghost."""

    mirrored = False

    @ti.func
    def ghost(self, p):
        """The solids' ghost density ρ/ρ0 at p and its gradient (1/m): ``ghost_of(p, k)`` summed over their
        ``constants.count``, none without wall density."""
        density, gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        # A switch, not only a count: the box's 27 terms in a λ pass hold registers on a GPU even where no
        # solid is (docs/BENCHMARKS.md, "Registers and occupancy").
        if ti.static(self.count > 0):
            if self.constants[None].wall_density:
                for k in range(self.constants[None].count):
                    d, g = self.ghost_of(p, k)
                    density += d
                    gradient += g
        return density, gradient


@ti.data_oriented
class Bodies(SolidParts):
    """The rigid bodies: their state on the device, the boundary interface the fluid sees (``ghost``,
    ``project``, ``velocity``), the rigid step (:meth:`advance`) and the reaction (:meth:`gather`). The host
    writes and reads the state through one kernel each way: a from_numpy per field compiles a kernel each."""

    def __init__(self, params: BoundaryParams, tables, obstacles, capacity: int):
        """``capacity``: the per-particle arrays' length (a bucket). The bodies' slots are a bucket too and
        every number the kernels read is data, so every scene with bodies shares one compile."""
        bodies = params.bodies
        self.params = bodies
        self.tables = tables
        self.obstacles = obstacles
        self.count = bodies.count  # for the host side; kernels read constants[None].count
        self.kernel_radius = params.kernel_radius_m
        slots = allocation(self.count, 8)
        # The particles' arrays first, closed into a SNode tree of their own by a launch (the fill), then
        # the bodies' slots: the rigid step's kernels are then shared by scenes of any particle bucket.
        block = max(64, math.ceil(capacity / 1024))  # particles a thread sums the reaction of (_gather)
        blocks = math.ceil(capacity / block)
        self.partial_force = ti.Vector.field(3, ti.f32, shape=(slots, blocks))
        self.partial_torque = ti.Vector.field(3, ti.f32, shape=(slots, blocks))
        self.shift = ti.Vector.field(3, ti.f32, shape=capacity)  # D_i: x*_i's move by the bodies' collision
        self.shift_before = ti.Vector.field(3, ti.f32, shape=capacity)  # D_i as the iteration before left it
        self.pusher = ti.field(ti.i32, shape=capacity)  # the body that pushed i last (−1: none) takes D_i
        self.pusher.fill(-1)
        self.sphere = ti.field(ti.i32, shape=slots)
        self.half = ti.Vector.field(3, ti.f32, shape=slots)  # half extents (a sphere: its radius on each), m
        self.inverse_mass = ti.field(ti.f32, shape=slots)
        self.inertia = ti.Vector.field(3, ti.f32, shape=slots)  # principal moments along its axes, kg m²
        self.position = ti.Vector.field(3, ti.f32, shape=slots)
        self.quaternion = ti.Vector.field(4, ti.f32, shape=slots)
        self.linear_velocity = ti.Vector.field(3, ti.f32, shape=slots)
        self.angular_velocity = ti.Vector.field(3, ti.f32, shape=slots)
        self.force = ti.Vector.field(3, ti.f32, shape=slots)  # the fluid's reaction over the last substep, N
        self.torque = ti.Vector.field(3, ti.f32, shape=slots)  # its torque about the centre of mass, N m
        self.rotation = ti.Matrix.field(3, 3, ti.f32, shape=slots)  # the quaternion's, for the fluid's kernels
        state = (self.position, self.quaternion, self.linear_velocity, self.angular_velocity, self.force, self.torque)
        self._state = tuple(zip(state, _STARTS))  # STATE_LAYOUT's fields and their first columns
        self.particle_mass = bodies.rest_density_kg_m3 * bodies.particle_volume_m3
        self.reach = ti.field(ti.f32, shape=slots)  # the collision distance this substep, m (collision_reach)
        self.bounding = ti.field(ti.f32, shape=slots)  # bounding sphere's radius about the centre, m
        self.fastest = ti.field(ti.f32, shape=())  # speed_limit_m_s, kept by each launch that changes it
        pairs = [(a, b) for a in range(self.count) for b in range(a + 1, self.count)]
        pair_slots = allocation(len(pairs), 8)
        self.pair_first = ti.field(ti.i32, shape=pair_slots)  # the pairs a < b in order (_contacts)
        self.pair_second = ti.field(ti.i32, shape=pair_slots)
        self.constants = scene_constants(
            **params.wall_constants(),
            count=self.count,
            pairs=len(pairs),
            static_candidates=CONTAINER_CANDIDATES + CORNERS * obstacles.count,
            block=block,
            blocks=blocks,
            wall_margin=0.99 * float(params.particle_radius_m),  # how far inside the walls a way out ends (_exit)
            volume=float(bodies.particle_volume_m3),
        )
        rows = np.zeros((slots, 9), np.float32)  # sphere, half extents, 1/mass, inertia, bounding radius
        for b, (shape, extents) in enumerate(zip(bodies.shapes, bodies.half_extents_m)):
            bounding = float(np.linalg.norm(extents)) if shape == "box" else extents[0]
            rows[b] = [shape == "sphere", *extents, 1.0 / bodies.masses_kg[b], *bodies.inertia_kg_m2[b], bounding]
        pair_rows = np.zeros((pair_slots, 2), np.int32)
        if pairs:
            pair_rows[: len(pairs)] = pairs
        columns = (self.sphere, self.half, self.inverse_mass, self.inertia, self.bounding)  # rows' columns
        array_loader((*columns, self.pair_first, self.pair_second))(
            (rows[:, 0], rows[:, 1:4], rows[:, 4], rows[:, 5:8], rows[:, 8], pair_rows[:, 0], pair_rows[:, 1])
        )
        self._rest_reach()
        self._launch_step = Launcher(self._step)  # past Taichi's per-call Python (pbf.solver.launch)
        self.held = False  # while True (settling before t = 0) advance leaves the bodies where they are

    # ------------------------------------------------------------------ host side

    def initial_state(self) -> np.ndarray:
        """(count, STATE_WIDTH) float32: the scene's poses and velocities, no reaction yet."""
        state = np.zeros((self.count, STATE_WIDTH), np.float32)
        state[:, :13] = np.array(self.params.initial, np.float32).reshape(self.count, 13)
        return state

    def load(self, state) -> None:
        """Set every body from a (count, STATE_WIDTH) array (:meth:`state`'s layout)."""
        state = np.array(state, np.float32).reshape(self.count, STATE_WIDTH)
        state[:, 3:7] /= np.linalg.norm(state[:, 3:7], axis=1, keepdims=True)
        if self.count:
            self._load(np.ascontiguousarray(state))

    def state(self) -> np.ndarray:
        """(count, STATE_WIDTH) float32 copy of every body's state (STATE_LAYOUT)."""
        state = np.zeros((self.count, STATE_WIDTH), np.float32)
        if self.count:
            self._store(state)
        return state

    @ti.kernel
    def _load(self, rows: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        for b in range(self.constants[None].count):
            for field, start in ti.static(self._state):
                field[b] = ti.Vector([rows[b, start + i] for i in ti.static(range(field.n))])
            self.rotation[b] = quaternion_matrix(self.quaternion[b])
        for _ in range(1):
            self._set_fastest()

    @ti.kernel
    def _store(self, rows: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        for b in range(self.constants[None].count):
            for field, start in ti.static(self._state):
                for i in ti.static(range(field.n)):
                    rows[b, start + i] = field[b][i]

    def move(self, clock_s: float, dt: float = 0.0) -> None:
        """Bodies move by their own dynamics (:meth:`advance`), not by a clock."""

    def speed_limit_m_s(self) -> float:
        """The fastest any point of a body moves, |v| + |ω| r_bound, for the CFL limit (a read from the device;
        ``Diagnostics.frame_read`` brings it with the water's)."""
        return float(self.fastest[None]) if self.count else 0.0

    @ti.func
    def _set_fastest(self):
        """``fastest`` for the bodies as they move now (one thread, after their velocities changed)."""
        top = 0.0
        for b in range(self.constants[None].count):
            top = ti.max(top, self.fastest_point(b))
        self.fastest[None] = top

    def advance(self, dt: float, gravity) -> None:
        """One rigid step of Δt under gravity and the last reaction, then the contacts (module docstring)."""
        if self.held:  # still, so at rest: the collision at its full distance (collision_reach)
            self._rest_reach()
        else:
            # The contacts are most of the step's compile, far less without Taichi's advanced IR
            # optimisation (docs/BODIES.md, "Compile time").
            with backend.light_compile():
                self._launch_step(dt, *gravity)

    @ti.kernel
    def _grab(self, point: ti.types.vector(3, ti.f32), hand: ti.types.vector(3, ti.f32), radius: ti.f32):
        for b in range(self.constants[None].count):
            gap = ti.max(self.outside_distance(b, point), 0.0)
            q2 = gap * gap / (radius * radius)
            if q2 < 1.0:
                w = (1.0 - q2) ** 3
                self.linear_velocity[b] += w * (hand - self.linear_velocity[b])
                self.angular_velocity[b] *= 1.0 - w
        for _ in range(1):
            self._set_fastest()

    def grab(self, push) -> None:
        """The hand in the water (``model.Push``, capped by the caller) carries a body as the water: velocity
        blended toward the hand's by w = (1 − (d/R)²)³, d from its surface, spin damped."""
        self._grab(push.point_m, push.velocity_m_s, push.radius_m)

    # ------------------------------------------------------------------ the rigid step

    @ti.func
    def _inverse_inertia(self, b, vector):
        """I_b⁻¹ vector in world axes: R diag(1/I) Rᵀ vector."""
        r = self.rotation[b]
        return r @ ((r.transpose() @ vector) / self.inertia[b])

    @ti.func
    def _advance(self, b, dt, gravity):
        """Body b's symplectic Euler step under gravity and the last reaction (module docstring)."""
        r = quaternion_matrix(self.quaternion[b])
        v = self.linear_velocity[b] + dt * (gravity + self.inverse_mass[b] * self.force[b])
        inertia = self.inertia[b]
        w_body = r.transpose() @ self.angular_velocity[b]
        torque_body = r.transpose() @ self.torque[b]
        w_body += dt * (torque_body - w_body.cross(inertia * w_body)) / inertia  # Euler's equations
        w = r @ w_body
        self.linear_velocity[b] = v
        self.angular_velocity[b] = w
        self.position[b] += dt * v
        q = self.quaternion[b]
        q += 0.5 * dt * quaternion_multiply(ti.Vector([0.0, w[0], w[1], w[2]]), q)
        q = q.normalized()
        self.quaternion[b] = q
        self.rotation[b] = quaternion_matrix(q)

    @ti.kernel
    def _step(self, dt: ti.f32, gx: ti.f32, gy: ti.f32, gz: ti.f32):
        # One thread: the work grows with the few bodies, and a launch per part would cost more than the part.
        for _ in range(1):
            count = self.constants[None].count
            for b in range(count):
                self._advance(b, dt, ti.Vector([gx, gy, gz]))
            self._contacts()
            for b in range(count):
                self.reach[b] = self.collision_reach(b, dt)
            self._set_fastest()

    @ti.kernel
    def _rest_reach(self):
        # Not ``reach.fill(number)``: Taichi's fill compiles its value into the kernel.
        for b in range(self.constants[None].count):
            self.reach[b] = COLLISION_AT_REST * self.constants[None].radius

    @ti.func
    def collision_reach(self, b, dt):
        """How far outside body b the collision keeps particle centres this substep (COLLISION_GIVE)."""
        r = self.constants[None].radius
        return ti.max(COLLISION_MOVING * r, COLLISION_AT_REST * r - COLLISION_GIVE * self.fastest_point(b) * dt)

    @ti.func
    def fastest_point(self, b):
        """|v| + |ω| r_bound: no point of body b moves faster, m/s."""
        return self.linear_velocity[b].norm() + self.angular_velocity[b].norm() * self.bounding[b]

    @ti.func
    def _contacts(self):
        """Every contact, CONTACT_SWEEPS times over, in a fixed order (sequential impulses): each body against
        the container and the obstacles, then each pair of bodies (corners inside the other box, then,
        where none is, edges across). The candidates are numbered and walked by runtime loops, so that
        :meth:`_resolve` is inlined once (docs/BODIES.md, "Compile time")."""
        count, pairs = self.constants[None].count, self.constants[None].pairs
        static_candidates = self.constants[None].static_candidates
        for _sweep in range(CONTACT_SWEEPS):
            for slot in range(count + pairs):
                a, b = slot, -1  # a body against the container and the obstacles
                candidates = static_candidates
                if slot >= count:  # a pair, a < b
                    a, b = self.pair_first[slot - count], self.pair_second[slot - count]
                    candidates = self._pair_candidates(a, b)
                corners = 0
                for m in range(candidates):
                    found, point, normal, depth = _no_contact()
                    first, second = a, b
                    if b < 0:
                        found, point, normal, depth = self._static_candidate(a, m)
                    elif self.sphere[a] or self.sphere[b]:
                        found, first, second, point, normal, depth = self._sphere_pair_candidate(a, b)
                    elif m < 2 * CORNERS or corners == 0:  # edges only where no corner is inside
                        found, first, second, point, normal, depth = self._box_pair_candidate(a, b, m)
                    if found:
                        self._resolve(first, second, point, normal, depth)
                        if m < 2 * CORNERS:
                            corners += 1

    @ti.func
    def _pair_candidates(self, a, b):
        """How many candidates bodies a and b have (:meth:`_box_pair_candidate`): one unless both are boxes;
        none for two boxes whose bounding spheres are apart (no corner or edge test)."""
        candidates = 1
        if not (self.sphere[a] or self.sphere[b]):
            candidates = 0
            if (self.position[a] - self.position[b]).norm() < self.bounding[a] + self.bounding[b]:
                candidates = 2 * CORNERS + EDGE_PAIRS
        return candidates

    @ti.func
    def _corner(self, b, k):
        """Corner k (0-7) of box b in world coordinates."""
        signs = ti.Vector([ti.select(k & 1, 1.0, -1.0), ti.select(k & 2, 1.0, -1.0), ti.select(k & 4, 1.0, -1.0)])
        return self.position[b] + self.rotation[b] @ (signs * self.half[b])

    @ti.func
    def _static_candidate(self, b, m):
        """Candidate m of body b against what does not move (found, point, outward normal, depth): m <
        CONTAINER_CANDIDATES the container at corner m // 6 along axis m // 2 % 3, below the lower wall (m even)
        or above the upper (a sphere: m < 6, its extreme point); then CORNERS per obstacle (a sphere: the first)."""
        found, point, normal, depth = _no_contact()
        sphere, radius = self.sphere[b], self.half[b][0]
        if m < CONTAINER_CANDIDATES and (m < 6 or not sphere):
            axis, above = m // 2 % 3, m % 2
            unit = ti.Vector([ti.select(axis == i, 1.0, 0.0) for i in ti.static(range(3))])
            low, high = component(self.constants[None].lower, axis), component(self.constants[None].upper, axis)
            if sphere:
                centre = component(self.position[b], axis)
                if above:
                    depth, point, normal = centre + radius - high, self.position[b] + radius * unit, -unit
                else:
                    depth, point, normal = low - (centre - radius), self.position[b] - radius * unit, unit
            else:
                point = self._corner(b, m // 6)
                if above:
                    depth, normal = component(point, axis) - high, -unit
                else:
                    depth, normal = low - component(point, axis), unit
            found = depth > 0.0
        if m >= CONTAINER_CANDIDATES:
            o, k = (m - CONTAINER_CANDIDATES) // CORNERS, (m - CONTAINER_CANDIDATES) % CORNERS
            lower, upper = self.obstacles.lower[o], self.obstacles.upper[o]
            centre, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
            if sphere and k == 0:
                found, _closest, normal, depth = self._sphere_at_box(self.position[b] - centre, radius, half)
                point = self.position[b] - radius * normal
            elif not sphere:
                point = self._corner(b, k)
                local = point - centre
                if (ti.abs(local) < half).all():
                    normal, depth = self._box_exit(local, half)
                    found = True
        return found, point, normal, depth

    @ti.func
    def _sphere_at_box(self, c, radius, half):
        """A sphere at c in a box's frame (centre 0, half extents ``half``): whether they overlap, the box's
        point closest to c, the normal from the box toward the sphere and the depth."""
        closest = ti.max(-half, ti.min(c, half))
        gap = c - closest
        distance = gap.norm()
        normal = ti.Vector([0.0, 1.0, 0.0])
        depth = radius - distance
        if distance > 1e-9:
            normal = gap / distance
        else:  # the centre inside the box
            n, inside = self._box_exit(c, half)
            normal, depth = n, radius + inside
        return distance < radius, closest, normal, depth

    @ti.func
    def _box_exit(self, local, half):
        """The outward normal of the face nearest ``local`` inside a box of half extents ``half``, and its depth."""
        best, axis = 1e30, 0
        for a in ti.static(range(3)):
            gap = half[a] - ti.abs(local[a])
            if gap < best:
                best, axis = gap, a
        normal = ti.Vector([0.0, 0.0, 0.0])
        normal[axis] = 1.0 if local[axis] >= 0.0 else -1.0
        return normal, best

    @ti.func
    def _resolve(self, a, b, point, normal, depth):
        """A contact at ``point``, ``depth`` deep, ``normal`` pointing into body a (b < 0: a fixed wall): the
        bodies move apart by inverse mass, then the approach is taken away (no bounce) and, within
        Coulomb's cone, the sliding (one loop over the two impulses: their code inlined once)."""
        pair = b >= 0
        other = ti.max(b, 0)  # (a valid index where there is no other body; its terms are left out)
        ma = self.inverse_mass[a]
        mb = 0.0
        contact = point + depth * normal  # the point moved with the body (against a wall)
        if pair:
            mb = self.inverse_mass[other]
            self.position[a] += depth * ma / (ma + mb) * normal
            self.position[b] -= depth * mb / (ma + mb) * normal
            contact = point
        else:
            self.position[a] += depth * normal
        ra, rb = contact - self.position[a], point - self.position[other]
        going = True
        j = 0.0
        for phase in range(2):  # 0: the normal impulse; 1: friction, after an approach only
            if going:
                relative = self.linear_velocity[a] + self.angular_velocity[a].cross(ra)
                if pair:
                    relative = relative - self.linear_velocity[b] - self.angular_velocity[b].cross(rb)
                direction, amount = normal, 0.0
                if phase == 0:
                    approach = relative.dot(normal)
                    going = approach < 0.0
                    amount = -approach
                else:
                    slide = relative - relative.dot(normal) * normal
                    speed = slide.norm()
                    going = speed > 1e-9
                    if going:
                        direction, amount = slide / speed, speed
                if going:
                    k = ma + mb
                    for side in range(2):  # Σ (r × d) · I⁻¹ (r × d) over the bodies, a first
                        if side == 0 or pair:
                            body, arm = a, ra
                            if side == 1:
                                body, arm = b, rb
                            turn = arm.cross(direction)
                            k += turn.dot(self._inverse_inertia(body, turn))
                    strength = amount / k  # into a: j along the normal, −min(jt, μ j) along the sliding
                    if phase == 0:
                        j = strength
                    else:
                        strength = -ti.min(strength, FRICTION * j)
                    for side in range(2):
                        if side == 0 or pair:
                            body, impulse, arm = a, strength * direction, ra
                            if side == 1:
                                body, impulse, arm = b, -strength * direction, rb
                            self.linear_velocity[body] += self.inverse_mass[body] * impulse
                            self.angular_velocity[body] += self._inverse_inertia(body, arm.cross(impulse))

    @ti.func
    def _sphere_pair_candidate(self, a, b):
        """Two spheres, or a sphere and a box: their one candidate (found, the body the normal points to
        and the other, point, normal, depth)."""
        found, point, normal, depth = _no_contact()
        first, second = a, b
        if self.sphere[a] and self.sphere[b]:
            gap = self.position[a] - self.position[b]
            distance = gap.norm()
            reach = self.half[a][0] + self.half[b][0]
            if distance < reach:
                normal = ti.Vector([0.0, 1.0, 0.0])
                if distance > 1e-9:
                    normal = gap / distance
                point, depth, found = self.position[b] + self.half[b][0] * normal, reach - distance, True
        else:
            s, box = a, b
            if self.sphere[b]:
                s, box = b, a
            r = self.rotation[box]
            local = r.transpose() @ (self.position[s] - self.position[box])
            found, closest, normal_local, depth = self._sphere_at_box(local, self.half[s][0], self.half[box])
            point, normal = self.position[box] + r @ closest, r @ normal_local
            first, second = s, box
        return found, first, second, point, normal, depth

    @ti.func
    def _box_pair_candidate(self, a, b, m):
        """Two boxes: m < 16 the corners of a inside b, then of b inside a; then edge (m − 16) // 12 of a
        across edge (m − 16) % 12 of b (:meth:`_edge_candidate`)."""
        found, point, normal, depth = _no_contact()
        first, second = a, b
        if m < 2 * CORNERS:
            inner, outer = a, b
            if m >= CORNERS:
                inner, outer = b, a
            point = self._corner(inner, m % CORNERS)
            r = self.rotation[outer]
            local = r.transpose() @ (point - self.position[outer])
            if (ti.abs(local) < self.half[outer]).all():
                n, inside = self._box_exit(local, self.half[outer])
                normal, depth = r @ n, inside
                first, second, found = inner, outer, True
        else:
            found, point, normal, depth = self._edge_candidate(a, b, m - 2 * CORNERS)
        return found, first, second, point, normal, depth

    @ti.func
    def _edge(self, b, k):
        """Edge k (0-11) of box b in world coordinates: its two ends. Edges 4a to 4a + 3 run along the
        box's axis a, at the four sign combinations of the other two half extents."""
        axis = k // 4
        first, second = ti.select(k & 1, 1.0, -1.0), ti.select(k & 2, 1.0, -1.0)
        half = self.half[b]
        start, end = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
        for i in ti.static(range(3)):  # a static index per component: no runtime index into a vector
            across = ti.select(i == (axis + 1) % 3, first, second) * half[i]
            start[i] = ti.select(i == axis, -half[i], across)
            end[i] = ti.select(i == axis, half[i], across)
        r = self.rotation[b]
        return self.position[b] + r @ start, self.position[b] + r @ end

    @ti.func
    def _edge_candidate(self, a, b, k):
        """Edge k // 12 of box a across edge k % 12 of box b: where the closest points of edges that are not
        parallel lie each inside the other box, the normal is the edges' cross product (from b to a) and
        the depth the boxes' overlap along it (their projected half widths less the centres' distance)."""
        found, point, normal, depth = _no_contact()
        p0, p1 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
        q0, q1 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
        for side in range(2):  # a's edge, then b's: the edge code once in the kernel
            start, end = self._edge(ti.select(side == 0, a, b), ti.select(side == 0, k // 12, k % 12))
            if side == 0:
                p0, p1 = start, end
            else:
                q0, q1 = start, end
        d1, d2 = p1 - p0, q1 - q0
        axis = d1.cross(d2)
        if axis.norm_sqr() > 1e-12 * d1.norm_sqr() * d2.norm_sqr():
            p, q = _closest_on_segments(p0, d1, q0, d2)
            inside = True
            for side in range(2):  # p inside b, then q inside a
                body, at = b, p
                if side == 1:
                    body, at = a, q
                local = self.rotation[body].transpose() @ (at - self.position[body])
                inside = inside and (ti.abs(local) < self.half[body]).all()
            if inside:
                normal = axis.normalized()
                gap = (self.position[a] - self.position[b]).dot(normal)
                if gap < 0.0:
                    normal, gap = -normal, -gap
                widths = 0.0  # the two boxes' half widths along the normal, a's first
                for side in range(2):
                    body = ti.select(side == 0, a, b)
                    widths += (ti.abs(self.rotation[body].transpose() @ normal) * self.half[body]).sum()
                depth = widths - gap
                point, found = 0.5 * (p + q), depth > 0.0
        return found, point, normal, depth

    # ------------------------------------------------------------------ the boundary the fluid sees

    @ti.func
    def ghost_of(self, p, b):
        """Body b's ghost density ρ/ρ0 at p and its gradient (1/m): a sphere's is the half-space table at the
        distance from its surface, along the radius; a box's the obstacles' (``GhostTables.box``) in its frame."""
        density, gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        centre = self.position[b]
        if self.sphere[b]:
            offset = p - centre
            distance = offset.norm()
            surface = distance - self.half[b][0]
            if surface < self.constants[None].kernel_radius:
                density, slope = self.tables.wall(surface)
                gradient = slope * offset / ti.max(distance, 1e-12)
        else:
            r, half = self.rotation[b], self.half[b]
            density, local_gradient = self.tables.box(r.transpose() @ (p - centre), -half, half)
            gradient = r @ local_gradient
        return density, gradient

    @ti.func
    def push_out(self, p):
        """p moved out of every body grown by its collision distance (:meth:`collision_reach`), through
        the nearest face (a box) or along the radius (a sphere); and the last body that moved it (−1: none)."""
        q = p
        pusher = -1
        for b in range(self.constants[None].count):
            moved = False
            centre = self.position[b]
            if self.sphere[b]:
                offset = q - centre
                distance = offset.norm()
                reach = self.half[b][0] + self.reach[b]
                moved = distance < reach
                if moved:
                    direction = ti.Vector([0.0, 1.0, 0.0])
                    if distance > 1e-12:
                        direction = offset / distance
                    q = centre + reach * direction
            else:
                r = self.rotation[b]
                local = r.transpose() @ (q - centre)
                grown = self.half[b] + self.reach[b]
                moved = (ti.abs(local) < grown).all()
                if moved:
                    q = self._exit(q, centre, r, local, grown)
            if moved:
                pusher = b
        return q, pusher

    @ti.func
    def _exit(self, p, centre, r, local, grown):
        """p (at ``local`` in a box grown to ``grown``) moved out through the nearest face whose way out stays
        ``wall_margin`` inside the container (under a box on the floor: a side), else the nearest face. The margin
        is a little less than the walls' collision distance, so that rounding does not shut a way flush with it."""
        wall_margin = self.constants[None].wall_margin
        low, high = self.constants[None].lower + wall_margin, self.constants[None].upper - wall_margin
        best, exit = 1e30, p
        nearest, fallback = 1e30, p
        for face in range(6):  # a runtime loop: the face's transform once in the kernel, not six times
            a, side = face // 2, face % 2
            sign = 2.0 * side - 1.0
            depth = component(grown, a) - sign * component(local, a)
            out = ti.Vector([ti.select(a == i, sign * grown[i], local[i]) for i in ti.static(range(3))])
            target = centre + r @ out
            if depth < nearest:
                nearest, fallback = depth, target
            open_way = (target > low).all() and (target < high).all()
            if open_way and depth < best:
                best, exit = depth, target
        if best == 1e30:
            exit = fallback
        return exit

    @ti.func
    def project(self, p):
        q, _pusher = self.push_out(p)
        return q

    # The collision's push per particle, for the body's reaction (:meth:`gather`): it follows the
    # iterations' recurrence, D^{k+1} = D^{k−1} + w (D^k − D^{k−1}) + c^{k+1}, c the push of iteration k + 1.

    @ti.func
    def record_start(self, i, pushed, pusher):
        """x*_i predicted and collided, the bodies' push ``pushed``: the record starts from it."""
        self.shift[i] = pushed
        self.shift_before[i] = pushed
        self.pusher[i] = pusher

    @ti.func
    def record_iteration(self, i, pushed, pusher, weight):
        """A Jacobi iteration of weight w moved x*_i and the bodies pushed it by ``pushed``."""
        now = self.shift[i]
        base = ti.select(weight == 1.0, now, self.shift_before[i] + weight * (now - self.shift_before[i]))
        self.shift_before[i] = now
        self.shift[i] = base + pushed
        if pusher >= 0:
            self.pusher[i] = pusher

    @ti.func
    def record_between(self, i, pushed, pusher, fraction):
        """x*_i stepped back by ``fraction`` toward the iteration before, then collided."""
        now = self.shift[i]
        self.shift[i] = now + fraction * (self.shift_before[i] - now) + pushed
        if pusher >= 0:
            self.pusher[i] = pusher

    @ti.func
    def velocity(self, p):
        """The velocity v + ω × (p − c) of the body whose ghost p sees (within h of its surface)."""
        v = ti.Vector([0.0, 0.0, 0.0])
        for b in range(self.constants[None].count):
            if self.outside_distance(b, p) < self.constants[None].kernel_radius:
                v += self.linear_velocity[b] + self.angular_velocity[b].cross(p - self.position[b])
        return v

    @ti.func
    def outside_distance(self, b, p):
        """How far p lies outside body b (0 inside a box, negative inside a sphere), m."""
        offset = p - self.position[b]
        distance = offset.norm() - self.half[b][0]
        if not self.sphere[b]:
            distance = ti.max(ti.abs(self.rotation[b].transpose() @ offset) - self.half[b], 0.0).norm()
        return distance

    # ------------------------------------------------------------------ the reaction

    @ti.kernel
    def _gather(
        self,
        x: ti.template(),
        lam_total: ti.template(),
        multiplier: ti.template(),
        active: ti.template(),
        position_scale: ti.f32,
        velocity_scale: ti.f32,
        push_scale: ti.f32,
    ):
        # Both loops run over the arrays' slots, bounds the kernel knows (no one-thread task for a bound).
        for b, k in ti.ndrange(self.partial_force.shape[0], self.partial_force.shape[1]):
            if b < self.constants[None].count:
                block, volume = self.constants[None].block, self.constants[None].volume
                force, torque = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
                centre = self.position[b]
                for i in range(k * block, ti.min((k + 1) * block, active[None])):
                    f = ti.Vector([0.0, 0.0, 0.0])
                    _density, gradient = self.ghost_of(x[i], b)
                    if gradient.norm_sqr() > 0.0:
                        f = volume * pressure(lam_total[i], multiplier[i], position_scale, velocity_scale) * gradient
                    if self.pusher[i] == b:
                        f += push_scale * self.shift[i]
                    force += f
                    torque += (x[i] - centre).cross(f)
                self.partial_force[b, k] = force
                self.partial_torque[b, k] = torque
        for b in range(self.force.shape[0]):
            if b < self.constants[None].count:
                force, torque = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
                for k in range(self.partial_force.shape[1]):  # in order: the same sum on any thread count
                    force += self.partial_force[b, k]
                    torque += self.partial_torque[b, k]
                self.force[b] = force
                self.torque[b] = torque

    def gather(self, x, lam_total, multiplier, active, dt: float) -> None:
        """The fluid's reaction on every body over the substep just solved (module docstring), with
        p_i = −ρ0 h² (L_i/Δt² + Λ_i); the next :meth:`advance` applies it."""
        scales = pressure_scales(self.params.rest_density_kg_m3, self.kernel_radius, dt)
        self._gather(x, lam_total, multiplier, active, *scales, -self.particle_mass / dt**2)
