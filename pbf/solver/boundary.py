"""The boundaries of the fluid, behind one interface: the container (an axis-aligned box whose
lower-x wall may be a piston wave maker), the static box obstacles and the rigid bodies.

Every boundary offers the same Taichi functions of a position p: ``project(p)`` (line 15's
collision), ``ghost(p)`` (the ghost fluid's density ρ/ρ0 behind it and its gradient) and
``velocity(p)`` (that ghost's velocity); on the host ``move(clock_s, dt)`` and ``speed_limit_m_s()``.
:class:`Boundaries` holds them in a fixed order. The ghost is looked up in tables by wall distance
(inclusion–exclusion at edges and corners); an obstacle, three slabs' intersection, expands into at
most 27 signed terms of them (:meth:`GhostTables.box`; docs/METHOD.md, "Walls and obstacles").
"""

import math

import numpy as np
import taichi as ti

from pbf.solver import sph
from pbf.solver.bodies import Bodies, SolidParts, component
from pbf.solver.constants import array_loader, scene_constants
from pbf.solver.launch import Launcher
from pbf.solver.model import BoundaryParams, allocation

TABLE_SAMPLES = 512
OVERLAP_SAMPLES = 32


@ti.data_oriented
class GhostTables:
    """The ghost density of a half-space (a wall), a quadrant (an edge) and an octant (a corner) of the
    fluid lattice, by wall distance, with their gradients (``pbf.solver.sph``); shared by every boundary."""

    def __init__(self, spacing_m: float, kernel_radius_m: float, edges_and_corners: bool):
        self.constants = scene_constants(kernel_radius=kernel_radius_m)  # the tables' distances are in h
        density, slope = sph.wall_density_table(spacing_m, kernel_radius_m, TABLE_SAMPLES)
        self.density_table = ti.field(ti.f32, shape=TABLE_SAMPLES)
        self.slope_table = ti.field(ti.f32, shape=TABLE_SAMPLES)
        n = OVERLAP_SAMPLES
        tables = (
            sph.wall_overlap_tables(spacing_m, kernel_radius_m, n)
            if edges_and_corners
            else (np.zeros((n, n)), np.zeros((n, n, 2)), np.zeros((n, n, n)), np.zeros((n, n, n, 3)))
        )
        self.edge = ti.field(ti.f32, shape=(n, n))
        self.edge_gradient = ti.Vector.field(2, ti.f32, shape=(n, n))
        self.corner = ti.field(ti.f32, shape=(n, n, n))
        self.corner_gradient = ti.Vector.field(3, ti.f32, shape=(n, n, n))
        array_loader(
            (self.density_table, self.slope_table, self.edge, self.edge_gradient, self.corner, self.corner_gradient)
        )((density, slope, *tables))

    @ti.func
    def wall(self, distance):
        """Ghost density ρ_wall/ρ0 and its slope d(ρ_wall/ρ0)/dd at wall distance d (linear interpolation)."""
        u = ti.max(distance, 0.0) / self.constants[None].kernel_radius * (TABLE_SAMPLES - 1)
        k = ti.min(ti.cast(u, ti.i32), TABLE_SAMPLES - 2)
        t = u - k
        density = (1 - t) * self.density_table[k] + t * self.density_table[k + 1]
        slope = (1 - t) * self.slope_table[k] + t * self.slope_table[k + 1]
        return density, slope

    @ti.func
    def cell(self, distance):
        """Cell index and fraction of a wall distance on the overlap tables' grid."""
        u = ti.min(ti.max(distance, 0.0) / self.constants[None].kernel_radius, 1.0) * (OVERLAP_SAMPLES - 1)
        k = ti.min(ti.cast(u, ti.i32), OVERLAP_SAMPLES - 2)
        return k, u - k

    @ti.func
    def quadrant(self, da, db):
        """Bilinear quadrant density and its gradient in (da, db)."""
        i, s = self.cell(da)
        k, t = self.cell(db)
        value, gradient = 0.0, ti.Vector([0.0, 0.0])
        for a, b in ti.static(ti.ndrange(2, 2)):
            weight = (s if a else 1.0 - s) * (t if b else 1.0 - t)
            value += weight * self.edge[i + a, k + b]
            gradient += weight * self.edge_gradient[i + a, k + b]
        return value, gradient

    @ti.func
    def octant(self, d):
        """Trilinear octant density and its gradient in the three wall distances d."""
        i, s = self.cell(d[0])
        j, t = self.cell(d[1])
        k, u = self.cell(d[2])
        value, gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        for a, b, c in ti.static(ti.ndrange(2, 2, 2)):
            weight = (s if a else 1.0 - s) * (t if b else 1.0 - t) * (u if c else 1.0 - u)
            value += weight * self.corner[i + a, j + b, k + c]
            gradient += weight * self.corner_gradient[i + a, j + b, k + c]
        return value, gradient

    @ti.func
    def box(self, p, lower, upper):
        """Ghost density ρ/ρ0 of the axis-aligned box lower–upper at p and its gradient (1/m), the 27-term
        expansion, with selections and one lookup of each table: it is inlined in the iterations' kernel,
        whose compile time grows faster than its length (docs/BODIES.md, "Compile time")."""
        h = self.constants[None].kernel_radius
        density, gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        nearest = ti.max(ti.max(lower - p, p - upper), 0.0)
        if nearest.norm() < h:
            below, above = p < lower, p > upper
            outside = below | above
            far = ti.select(below, lower - p, ti.select(above, p - upper, 0.0))  # outside: distance to the slab
            far_sign = ti.select(below, -1.0, ti.select(above, 1.0, 0.0))  # and its derivative's sign
            for term in range(27):
                # Per axis, choice 0: the slab itself (outside: its half-space; inside: everything),
                # 1 and 2: minus the half-space beyond the lower or upper face (inside only).
                sign = 1.0
                valid = True
                active = ti.Vector([0, 0, 0])
                d = ti.Vector([0.0, 0.0, 0.0])
                d_sign = ti.Vector([0.0, 0.0, 0.0])
                for a in ti.static(range(3)):
                    choice = term // (9 if a == 0 else 3 if a == 1 else 1) % 3
                    face = choice != 0
                    valid = valid and not (face and outside[a])
                    sign = ti.select(face, -sign, sign)
                    active[a] = ti.select(face, 1, outside[a])
                    d[a] = ti.select(face, ti.select(choice == 1, p[a] - lower[a], upper[a] - p[a]), far[a])
                    d_sign[a] = ti.select(face, ti.select(choice == 1, 1.0, -1.0), far_sign[a])
                    valid = valid and not (active[a] and d[a] >= h)
                if valid:
                    value, slope = self.half_spaces(active, d)
                    density += sign * value
                    gradient += sign * d_sign * slope
        return density, gradient

    @ti.func
    def half_spaces(self, active, d):
        """Ghost density of the half-spaces marked in ``active`` (at distances d), and its derivative in
        each distance; none at all is the full lattice, ρ/ρ0 = 1."""
        value, slope = 0.0, ti.Vector([0.0, 0.0, 0.0])
        count = active.sum()
        if count == 0:
            value = 1.0
        elif count == 1:
            a = ti.select(active[0], 0, ti.select(active[1], 1, 2))
            value, wall_slope = self.wall(component(d, a))
            slope = ti.Vector([ti.select(a == i, wall_slope, 0.0) for i in ti.static(range(3))])
        elif count == 2:
            left_out = ti.select(active[0] == 0, 0, ti.select(active[1] == 0, 1, 2))
            a, b = ti.select(left_out == 0, 1, 0), ti.select(left_out == 2, 1, 2)
            value, g = self.quadrant(component(d, a), component(d, b))
            slope = ti.Vector([ti.select(a == i, g[0], ti.select(b == i, g[1], 0.0)) for i in ti.static(range(3))])
        else:
            value, slope = self.octant(d)
        return value, slope


@ti.data_oriented
class Container:
    """The axis-aligned box the fluid lives in; with a wave maker its lower-x wall is a piston."""

    def __init__(self, params: BoundaryParams, tables: GhostTables):
        self.tables = tables
        # mirror_reach: a wall's mirror images come within h of a particle only if it is closer than h − r.
        self.constants = scene_constants(
            **params.wall_constants(),
            mirror_reach=params.kernel_radius_m - params.particle_radius_m,
            wave_maker=int(params.piston_stroke_m > 0.0),
        )
        # mirrored: the ghost behind these walls is the fluid's mirror image (solver.wall_mirror): the density
        # constraint then leaves out ghost() and mirrors the fluid in mirror_walls().
        self.mirrored = params.wall_mirror
        self.wave_maker = params.piston_stroke_m > 0.0
        self.piston_stroke_m = params.piston_stroke_m
        self.piston_period_s = params.piston_period_s
        self.piston_x = ti.field(ti.f32, shape=())  # where the piston wall stands now, m (set by move)
        self.piston_v = ti.field(ti.f32, shape=())  # its velocity over the coming substep, m/s along x
        self.piston_rest_x = params.lower_m[0]
        self.piston_x[None] = params.lower_m[0]
        self._launch_place = Launcher(self._place)  # past Taichi's per-call Python (pbf.solver.launch)
        self._piston_x_host = float(np.float32(params.lower_m[0]))  # piston_x as the device has it: no read back

    def piston_position_m(self, piston_time_s: float) -> float:
        """The piston wall after it has run ``piston_time_s``: x = x_min + S/2 (1 − cos 2πt/T), at rest
        at t = 0 and swinging between x_min and x_min + S. Its clock stops while it is switched off."""
        phase = 2.0 * math.pi * piston_time_s / self.piston_period_s
        return self.piston_rest_x + 0.5 * self.piston_stroke_m * (1.0 - math.cos(phase))

    def speed_limit_m_s(self) -> float:
        """The piston's largest speed, π S / T (0 without a wave maker): the CFL limit counts it."""
        return math.pi * self.piston_stroke_m / self.piston_period_s if self.wave_maker else 0.0

    def move(self, piston_time_s: float, dt: float = 0.0) -> None:
        """Place moving walls where they stand at the end of the coming substep of ``dt`` (where x* is
        projected: a particle the piston pushes leaves with its velocity)."""
        if self.wave_maker:
            position = self.piston_position_m(piston_time_s)
            velocity = (position - self._piston_x_host) / dt if dt > 0.0 else 0.0
            self._launch_place(position, velocity)
            self._piston_x_host = float(np.float32(position))

    @ti.kernel
    def _place(self, position: ti.f32, velocity: ti.f32):
        """Both of :meth:`move`'s values in one launch, not a field write (a launch) each."""
        self.piston_x[None] = position
        self.piston_v[None] = velocity

    @ti.func
    def _lower(self):
        """The container's lower corner now (the piston moves its x; without one it stays at lower_m)."""
        lower = self.constants[None].lower
        lower[0] = self.piston_x[None]
        return lower

    @ti.func
    def velocity(self, p):
        """Velocity of the wall ghost that p sees (m/s): the piston's within h of it, else zero."""
        velocity = ti.Vector([0.0, 0.0, 0.0])
        if self.constants[None].wave_maker:
            below = p[0] - self.piston_x[None]
            kernel_radius, upper = self.constants[None].kernel_radius, self.constants[None].upper
            if below < kernel_radius and below <= upper[0] - p[0]:
                velocity[0] = self.piston_v[None]
        return velocity

    @ti.func
    def project(self, p):
        """p moved into the container shrunk by the particle radius."""
        radius, upper = self.constants[None].radius, self.constants[None].upper
        return ti.max(self._lower() + radius, ti.min(p, upper - radius))

    @ti.func
    def mirror_walls(self, p):
        """The container walls that mirror the fluid near p (``solver.wall_mirror``, ``pbf.solver.density``):
        per axis, 1 where the nearer wall is closer than h − r, and that wall's coordinate."""
        near = ti.Vector([0, 0, 0])
        plane = ti.Vector([0.0, 0.0, 0.0])
        lower = self._lower()
        upper, mirror_reach = self.constants[None].upper, self.constants[None].mirror_reach
        for axis in ti.static(range(3)):
            below = p[axis] - lower[axis]
            above = upper[axis] - p[axis]
            if ti.min(below, above) < mirror_reach:
                near[axis] = 1
                plane[axis] = lower[axis] if below <= above else upper[axis]
        return near, plane

    @ti.func
    def ghost(self, p):
        """Ghost density ρ_wall/ρ0 of the walls within h (walls − edges + corner) and its gradient (1/m)."""
        density, gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        if self.constants[None].wall_density:
            lower = self._lower()
            upper, kernel_radius = self.constants[None].upper, self.constants[None].kernel_radius
            distance = ti.Vector([0.0, 0.0, 0.0])
            side = ti.Vector([0.0, 0.0, 0.0])  # +1: near the lower wall, −1: the upper, 0: neither
            for axis in ti.static(range(3)):
                below = p[axis] - lower[axis]
                above = upper[axis] - p[axis]
                distance[axis] = ti.min(below, above)
                if distance[axis] < kernel_radius:
                    side[axis] = 1.0 if below <= above else -1.0
                    d, s = self.tables.wall(distance[axis])
                    density += d
                    gradient[axis] += side[axis] * s
            for a, b in ti.static(((0, 1), (0, 2), (1, 2))):
                if side[a] != 0.0 and side[b] != 0.0:
                    q, g = self.tables.quadrant(distance[a], distance[b])
                    density -= q
                    gradient[a] -= side[a] * g[0]
                    gradient[b] -= side[b] * g[1]
            if side[0] != 0.0 and side[1] != 0.0 and side[2] != 0.0:
                o, g = self.tables.octant(distance)
                density += o
                gradient += side * g
        return density, gradient


@ti.data_oriented
class Obstacles(SolidParts):
    """Static boxes inside the container that the water flows around."""

    def __init__(self, params: BoundaryParams, tables: GhostTables):
        self.tables = tables
        self.params = params
        self.count = len(params.obstacles)

    def allocate(self) -> None:
        """The obstacles' arrays, in slots of a bucket as many for none as for a few (their count is data;
        their code is compiled in only where there are obstacles, ``SolidParts.ghost``)."""
        params = self.params
        radius, count = params.particle_radius_m, len(params.obstacles)
        slots = allocation(count, 8)
        self.constants = scene_constants(**params.wall_constants(), count=count)
        lower, upper = np.zeros((slots, 3), np.float32), np.zeros((slots, 3), np.float32)
        # A face flush with a container wall is no way out of an obstacle: collision never pushes there.
        exit_lower, exit_upper = np.zeros((slots, 3), np.int32), np.zeros((slots, 3), np.int32)
        for k, (low, high) in enumerate(params.obstacles):
            lower[k], upper[k] = low, high
            exit_lower[k] = [int(low[a] - params.lower_m[a] > 2 * radius) for a in range(3)]
            exit_upper[k] = [int(params.upper_m[a] - high[a] > 2 * radius) for a in range(3)]
        self.lower = ti.Vector.field(3, ti.f32, shape=slots)
        self.upper = ti.Vector.field(3, ti.f32, shape=slots)
        self.exit_lower = ti.Vector.field(3, ti.i32, shape=slots)
        self.exit_upper = ti.Vector.field(3, ti.i32, shape=slots)
        if count:  # new fields hold zeros: a scene without obstacles launches (and compiles) no copy
            array_loader((self.lower, self.upper, self.exit_lower, self.exit_upper))(
                (lower, upper, exit_lower, exit_upper)
            )

    def move(self, clock_s: float, dt: float = 0.0) -> None:
        """Obstacles stand still."""

    def speed_limit_m_s(self) -> float:
        return 0.0

    @ti.func
    def velocity(self, p):
        return ti.Vector([0.0, 0.0, 0.0])

    @ti.func
    def project(self, p):
        """p moved out of every obstacle grown by the particle radius, through the nearest open face: the one
        it came through, as obstacles are thicker than a substep's move."""
        q = p
        if ti.static(self.count > 0):  # as in SolidParts.ghost
            for o in range(self.constants[None].count):
                radius = self.constants[None].radius
                lower = self.lower[o] - radius
                upper = self.upper[o] + radius
                if (q > lower).all() and (q < upper).all():
                    best, axis, target = 1e30, 0, 0.0
                    for a in ti.static(range(3)):
                        if self.exit_lower[o][a] and q[a] - lower[a] < best:
                            best, axis, target = q[a] - lower[a], a, lower[a]
                        if self.exit_upper[o][a] and upper[a] - q[a] < best:
                            best, axis, target = upper[a] - q[a], a, upper[a]
                    if best < 1e30:
                        q[axis] = target
        return q

    @ti.func
    def ghost_of(self, p, o):
        """Ghost density of obstacle o and its gradient: the 27-term expansion of the module docstring."""
        return self.tables.box(p, self.lower[o], self.upper[o])


@ti.data_oriented
class Boundaries:
    """Every boundary of the fluid in a fixed order (the container, then the obstacles): what the
    stages call. Each call visits the parts in that order, so sums come out the same bit for bit."""

    def __init__(self, params: BoundaryParams, capacity: int = 1, solids: bool = True):
        """The ghost tables and the container; with ``solids`` also the obstacles' and bodies' arrays
        (else :meth:`allocate_solids` later, after every array all scenes have)."""
        self.params = params
        self.tables = GhostTables(params.spacing_m, params.kernel_radius_m, params.wall_density)
        self.container = Container(params, self.tables)
        self.obstacles = Obstacles(params, self.tables)
        self.parts = (self.container, self.obstacles)
        self.bodies = None
        self.with_bodies = params.bodies.count > 0  # the last part is the bodies; without, no code of theirs
        if solids:
            self.allocate_solids(capacity)

    def allocate_solids(self, capacity: int) -> None:
        """The obstacles' arrays, and the bodies (``capacity``: the per-particle arrays' length)."""
        self.obstacles.allocate()
        if self.with_bodies:
            self.bodies = Bodies(self.params, self.tables, self.obstacles, capacity)
            self.parts += (self.bodies,)

    def move(self, clock_s: float, dt: float = 0.0) -> None:
        """Place moving boundaries where they stand at the end of the coming substep of ``dt``
        (``clock_s``: the wave maker's clock)."""
        for part in self.parts:
            part.move(clock_s, dt)

    def speed_limit_m_s(self, bodies_m_s: float) -> float:
        """The fastest any boundary moves (the CFL limit counts it); ``bodies_m_s``: the bodies' part as
        already read from the device (``Diagnostics.frame_read``), instead of a read of its own."""
        return max(bodies_m_s if part is self.bodies else part.speed_limit_m_s() for part in self.parts)

    @ti.func
    def project(self, p):
        """p moved inside the fluid's domain: into the container, out of every solid (line 15); the
        projection of :meth:`project_recorded`, recorded nowhere."""
        return self.project_recorded(p, 0, "", 0.0)

    @ti.func
    def project_recorded(self, p, i, stage: ti.template(), amount):
        """p projected for particle i's x* at ``stage`` "start", "iteration" (of weight ``amount``) or
        "between" (stepped back by ``amount``); with bodies, their push, less what the container took back
        (a particle caught between a body and a wall lifts no body), goes on the record their reaction reads
        (``Bodies.record_start``, ``record_iteration``, ``record_between``)."""
        q = p
        for k in ti.static(range(len(self.parts) - int(self.with_bodies))):  # the bodies' push last
            q = self.parts[k].project(q)
        if ti.static(self.with_bodies):
            before = q
            q, pusher = self.bodies.push_out(q)
            q = self.container.project(q)  # a body at a wall may have pushed p through it
            pushed = q - before
            if ti.static(stage == "start"):
                self.bodies.record_start(i, pushed, pusher)
            elif ti.static(stage == "iteration"):
                self.bodies.record_iteration(i, pushed, pusher, amount)
            elif ti.static(stage == "between"):
                self.bodies.record_between(i, pushed, pusher, amount)
        return q

    @ti.func
    def ghost(self, p, leave_out_mirrored: ti.template()):
        """Ghost density ρ/ρ0 behind every boundary within h of p, and its gradient (1/m); with
        ``leave_out_mirrored`` without the boundaries whose ghost is the fluid's mirror image."""
        density, gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(len(self.parts))):
            if ti.static(not (leave_out_mirrored and self.parts[k].mirrored)):
                d, g = self.parts[k].ghost(p)
                density += d
                gradient += g
        return density, gradient

    @ti.func
    def mirror_walls(self, p):
        return self.container.mirror_walls(p)

    @ti.func
    def velocity(self, p):
        """Velocity of the ghost fluid p sees (m/s): the sum of the boundaries' (at most one moves near p)."""
        v = ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(len(self.parts))):
            v += self.parts[k].velocity(p)
        return v
