"""The boundary: the container (an axis-aligned box) and static box obstacles inside it, with
collision and the density of the missing wall neighbours.

A particle next to a wall has fewer neighbours than one inside the fluid, so its density reads low and
the solver pulls it into the wall, where clamping stacks it. We add the density of ghost fluid behind
each wall (``pbf.solver.sph.wall_density_table``), and its gradient, to the density constraint; the table is
computed once per scene and looked up by wall distance. Near an edge or a corner the ghost lattices
of two or three walls overlap; inclusion–exclusion tables (``pbf.solver.sph.wall_overlap_tables``) remove
what would be counted twice, so a block in a corner also starts exactly at ρ0.

An obstacle is the intersection of three slabs, so its ghost lattice is too. Per axis, a particle
is either outside the slab (one half-space at distance a stands for the slab) or inside it (the
slab is everything minus the two half-spaces beyond its faces, at distances d_lo and d_hi). The
product over the three axes expands into at most 27 signed terms, each the ghost density of one,
two or three orthogonal half-spaces: the wall, edge and corner tables of the container. So the
ghost of an obstacle is exact (to the tables) at its faces, its convex edges and its corners, and a
block resting on an obstacle starts at ρ0 as it does on the floor.
"""
import math

import numpy as np
import taichi as ti

from pbf.solver import sph
from pbf.solver.model import BoxParams

TABLE_SAMPLES = 512
OVERLAP_SAMPLES = 32


@ti.data_oriented
class Box:
    def __init__(self, params: BoxParams):
        self.radius = params.particle_radius_m
        self.lower = ti.Vector(list(params.lower_m))
        self.upper = ti.Vector(list(params.upper_m))
        self.kernel_radius = params.kernel_radius_m
        self.with_wall_density = params.wall_density
        self.mirror_reach = params.kernel_radius_m - params.particle_radius_m
        """A wall's mirror images of the fluid come within h of a particle only if the particle is closer
        than this to the wall, as no particle comes closer to it than r (the collision)."""
        spacing_m, kernel_radius_m = params.spacing_m, params.kernel_radius_m
        density, slope = sph.wall_density_table(spacing_m, kernel_radius_m, TABLE_SAMPLES)
        self.density_table = ti.field(ti.f32, shape=TABLE_SAMPLES)
        self.slope_table = ti.field(ti.f32, shape=TABLE_SAMPLES)
        self.density_table.from_numpy(density.astype(np.float32))
        self.slope_table.from_numpy(slope.astype(np.float32))
        n = OVERLAP_SAMPLES
        tables = sph.wall_overlap_tables(spacing_m, kernel_radius_m, n) if params.wall_density else (
            np.zeros((n, n)), np.zeros((n, n, 2)), np.zeros((n, n, n)), np.zeros((n, n, n, 3)))
        self.edge = ti.field(ti.f32, shape=(n, n))
        self.edge_gradient = ti.Vector.field(2, ti.f32, shape=(n, n))
        self.corner = ti.field(ti.f32, shape=(n, n, n))
        self.corner_gradient = ti.Vector.field(3, ti.f32, shape=(n, n, n))
        for field, table in zip((self.edge, self.edge_gradient, self.corner, self.corner_gradient), tables):
            field.from_numpy(table.astype(np.float32))
        self.wave_maker = params.piston_stroke_m > 0.0
        """Whether the container's lower-x wall is a piston wave maker (compiled out when not)."""
        self.piston_stroke_m = params.piston_stroke_m
        self.piston_period_s = params.piston_period_s
        self.piston_x = ti.field(ti.f32, shape=())
        """Where the piston wall stands now (m); set by :meth:`move_walls` before each substep."""
        self.piston_v = ti.field(ti.f32, shape=())
        """The piston's velocity over the coming substep (m/s, along x)."""
        self.piston_rest_x = params.lower_m[0]
        self.piston_x[None] = params.lower_m[0]
        self.obstacle_count = len(params.obstacles)
        slots = max(1, self.obstacle_count)
        self.obstacle_lower = ti.Vector.field(3, ti.f32, shape=slots)
        self.obstacle_upper = ti.Vector.field(3, ti.f32, shape=slots)
        # A face flush with a container wall is no way out of an obstacle: collision never pushes there.
        self.obstacle_exit_lower = ti.Vector.field(3, ti.i32, shape=slots)
        self.obstacle_exit_upper = ti.Vector.field(3, ti.i32, shape=slots)
        for k, (lower, upper) in enumerate(params.obstacles):
            self.obstacle_lower[k] = lower
            self.obstacle_upper[k] = upper
            self.obstacle_exit_lower[k] = [int(lower[a] - params.lower_m[a] > 2 * self.radius) for a in range(3)]
            self.obstacle_exit_upper[k] = [int(params.upper_m[a] - upper[a] > 2 * self.radius) for a in range(3)]

    def piston_position_m(self, piston_time_s: float) -> float:
        """The piston wall after it has run ``piston_time_s``: x = x_min + S/2 (1 − cos 2πt/T), at rest
        at t = 0 and swinging between x_min and x_min + S. Its clock stops while it is switched off."""
        phase = 2.0 * math.pi * piston_time_s / self.piston_period_s
        return self.piston_rest_x + 0.5 * self.piston_stroke_m * (1.0 - math.cos(phase))

    def piston_speed_limit_m_s(self) -> float:
        """The piston's largest speed, π S / T (0 without a wave maker): the CFL limit counts it."""
        return math.pi * self.piston_stroke_m / self.piston_period_s if self.wave_maker else 0.0

    def move_walls(self, piston_time_s: float, dt: float = 0.0) -> None:
        """Place moving walls where they stand at the end of the coming substep of ``dt``, where x* is
        projected, so a particle the piston pushes leaves with the piston's velocity (v = (x* − x)/Δt);
        the piston's velocity over that substep is what the divergence pre-correction sees (0 when
        ``dt`` is 0: placed, not moved)."""
        if self.wave_maker:
            position = self.piston_position_m(piston_time_s)
            self.piston_v[None] = (position - self.piston_x[None]) / dt if dt > 0.0 else 0.0
            self.piston_x[None] = position

    @ti.func
    def _lower(self):
        """The container's lower corner now (the piston moves its x)."""
        lower = self.lower
        if ti.static(self.wave_maker):
            lower[0] = self.piston_x[None]
        return lower

    @ti.func
    def wall_velocity(self, p):
        """Velocity of the wall ghost that p sees (m/s): the piston's within h of it, else zero."""
        velocity = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.wave_maker):
            below = p[0] - self.piston_x[None]
            if below < self.kernel_radius and below <= self.upper[0] - p[0]:
                velocity[0] = self.piston_v[None]
        return velocity

    @ti.func
    def clamp(self, p):
        """Project p into the container shrunk by the particle radius and out of every obstacle grown
        by it (the collision of Algorithm 1, line 15)."""
        q = ti.max(self._lower() + self.radius, ti.min(p, self.upper - self.radius))
        if ti.static(self.obstacle_count > 0):
            for o in range(self.obstacle_count):
                q = self._push_out(q, o)
        return q

    @ti.func
    def _push_out(self, p, o):
        """p moved out of obstacle o (grown by the particle radius) through the nearest open face.
        Obstacles are at least two spacings thick and a particle moves at most time.max_cfl spacings
        in a substep, so the nearest face is the one it came through."""
        lower = self.obstacle_lower[o] - self.radius
        upper = self.obstacle_upper[o] + self.radius
        q = p
        if (p > lower).all() and (p < upper).all():
            best, axis, target = 1e30, 0, 0.0
            for a in ti.static(range(3)):
                if self.obstacle_exit_lower[o][a] and p[a] - lower[a] < best:
                    best, axis, target = p[a] - lower[a], a, lower[a]
                if self.obstacle_exit_upper[o][a] and upper[a] - p[a] < best:
                    best, axis, target = upper[a] - p[a], a, upper[a]
            if best < 1e30:
                q[axis] = target
        return q

    @ti.func
    def _lookup(self, distance):
        """Ghost density ρ_wall/ρ0 and its slope d(ρ_wall/ρ0)/dd at wall distance d (linear interpolation)."""
        u = ti.max(distance, 0.0) / self.kernel_radius * (TABLE_SAMPLES - 1)
        k = ti.min(ti.cast(u, ti.i32), TABLE_SAMPLES - 2)
        t = u - k
        density = (1 - t) * self.density_table[k] + t * self.density_table[k + 1]
        slope = (1 - t) * self.slope_table[k] + t * self.slope_table[k + 1]
        return density, slope

    @ti.func
    def _cell(self, distance):
        """Cell index and fraction of a wall distance on the overlap tables' grid."""
        u = ti.min(ti.max(distance, 0.0) / self.kernel_radius, 1.0) * (OVERLAP_SAMPLES - 1)
        k = ti.min(ti.cast(u, ti.i32), OVERLAP_SAMPLES - 2)
        return k, u - k

    @ti.func
    def _edge(self, da, db):
        """Bilinear quadrant density and its gradient in (da, db)."""
        i, s = self._cell(da)
        k, t = self._cell(db)
        value = 0.0
        gradient = ti.Vector([0.0, 0.0])
        for a, b in ti.static(ti.ndrange(2, 2)):
            weight = (s if a else 1.0 - s) * (t if b else 1.0 - t)
            value += weight * self.edge[i + a, k + b]
            gradient += weight * self.edge_gradient[i + a, k + b]
        return value, gradient

    @ti.func
    def _corner(self, d):
        """Trilinear octant density and its gradient in the three wall distances d."""
        i, s = self._cell(d[0])
        j, t = self._cell(d[1])
        k, u = self._cell(d[2])
        value = 0.0
        gradient = ti.Vector([0.0, 0.0, 0.0])
        for a, b, c in ti.static(ti.ndrange(2, 2, 2)):
            weight = (s if a else 1.0 - s) * (t if b else 1.0 - t) * (u if c else 1.0 - u)
            value += weight * self.corner[i + a, j + b, k + c]
            gradient += weight * self.corner_gradient[i + a, j + b, k + c]
        return value, gradient

    @ti.func
    def mirror_walls(self, p):
        """The container walls that mirror the fluid near p (``solver.wall_mirror``, ``pbf.solver.density``):
        per axis, 1 where the nearer wall is closer than h − r, and that wall's coordinate."""
        near = ti.Vector([0, 0, 0])
        plane = ti.Vector([0.0, 0.0, 0.0])
        lower = self._lower()
        for axis in ti.static(range(3)):
            below = p[axis] - lower[axis]
            above = self.upper[axis] - p[axis]
            if ti.min(below, above) < self.mirror_reach:
                near[axis] = 1
                plane[axis] = self.upper[axis]
                if below <= above:
                    plane[axis] = lower[axis]
        return near, plane

    @ti.func
    def obstacle_density(self, p):
        """The obstacles' part of :meth:`wall_density`: their ghost density ρ/ρ0 and its gradient (1/m)."""
        density = 0.0
        gradient = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.with_wall_density and self.obstacle_count > 0):
            for o in range(self.obstacle_count):
                d, g = self._obstacle_ghost(p, o)
                density += d
                gradient += g
        return density, gradient

    @ti.func
    def wall_density(self, p):
        """Ghost density ρ_wall/ρ0 of the walls within h (walls − edges + corner), and its gradient
        with respect to p (1/m)."""
        density = 0.0
        gradient = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.with_wall_density):
            lower = self._lower()
            distance = ti.Vector([0.0, 0.0, 0.0])
            side = ti.Vector([0.0, 0.0, 0.0])  # +1: near the lower wall, −1: the upper, 0: neither
            for axis in ti.static(range(3)):
                below = p[axis] - lower[axis]
                above = self.upper[axis] - p[axis]
                distance[axis] = ti.min(below, above)
                if distance[axis] < self.kernel_radius:
                    side[axis] = 1.0 if below <= above else -1.0
                    d, s = self._lookup(distance[axis])
                    density += d
                    gradient[axis] += side[axis] * s
            for a, b in ti.static(((0, 1), (0, 2), (1, 2))):
                if side[a] != 0.0 and side[b] != 0.0:
                    q, g = self._edge(distance[a], distance[b])
                    density -= q
                    gradient[a] -= side[a] * g[0]
                    gradient[b] -= side[b] * g[1]
            if side[0] != 0.0 and side[1] != 0.0 and side[2] != 0.0:
                o, g = self._corner(distance)
                density += o
                gradient += side * g
            obstacles, obstacle_gradient = self.obstacle_density(p)
            density += obstacles
            gradient += obstacle_gradient
        return density, gradient

    @ti.func
    def _obstacle_ghost(self, p, o):
        """Ghost density of obstacle o and its gradient: the 27-term expansion of the module docstring."""
        lower, upper = self.obstacle_lower[o], self.obstacle_upper[o]
        h = self.kernel_radius
        density = 0.0
        gradient = ti.Vector([0.0, 0.0, 0.0])
        nearest = ti.max(ti.max(lower - p, p - upper), 0.0)
        if nearest.norm() < h:
            outside = ti.Vector([0, 0, 0])
            far = ti.Vector([0.0, 0.0, 0.0])  # outside: distance to the slab; its derivative's sign
            far_sign = ti.Vector([0.0, 0.0, 0.0])
            for a in ti.static(range(3)):
                if p[a] < lower[a]:
                    outside[a], far[a], far_sign[a] = 1, lower[a] - p[a], -1.0
                elif p[a] > upper[a]:
                    outside[a], far[a], far_sign[a] = 1, p[a] - upper[a], 1.0
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
                    if choice == 0:
                        if outside[a]:
                            active[a], d[a], d_sign[a] = 1, far[a], far_sign[a]
                    elif outside[a]:
                        valid = False
                    else:
                        sign = -sign
                        active[a] = 1
                        if choice == 1:
                            d[a], d_sign[a] = p[a] - lower[a], 1.0
                        else:
                            d[a], d_sign[a] = upper[a] - p[a], -1.0
                    if active[a] and d[a] >= h:
                        valid = False
                if valid:
                    value, slope = self._ghost(active, d)
                    density += sign * value
                    gradient += sign * d_sign * slope
        return density, gradient

    @ti.func
    def _ghost(self, active, d):
        """Ghost density of the half-spaces marked in ``active`` (one, two or three axes, at distances
        d), and its derivative in each distance; no half-space at all is the full lattice, ρ/ρ0 = 1."""
        value = 0.0
        slope = ti.Vector([0.0, 0.0, 0.0])
        count = active.sum()
        if count == 0:
            value = 1.0
        elif count == 1:
            for a in ti.static(range(3)):
                if active[a]:
                    value, slope[a] = self._lookup(d[a])
        elif count == 2:
            for a, b in ti.static(((0, 1), (0, 2), (1, 2))):
                if active[a] and active[b]:
                    q, g = self._edge(d[a], d[b])
                    value, slope[a], slope[b] = q, g[0], g[1]
        else:
            value, slope = self._corner(d)
        return value, slope
