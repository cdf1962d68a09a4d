"""The container: an axis-aligned box, with collision and the density of the missing wall neighbours.

A particle next to a wall has fewer neighbours than one inside the fluid, so its density reads low and
the solver pulls it into the wall, where clamping stacks it. We add the density of ghost fluid behind
each wall (``pbf.solver.sph.wall_density_table``), and its gradient, to the density constraint; the table is
computed once per scene and looked up by wall distance. Near an edge or a corner the ghost lattices
of two or three walls overlap; inclusion–exclusion tables (``pbf.solver.sph.wall_overlap_tables``) remove
what would be counted twice, so a block in a corner also starts exactly at ρ0.
"""
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

    @ti.func
    def clamp(self, p):
        """Project p into the box shrunk by the particle radius (the collision of Algorithm 1, line 15)."""
        return ti.max(self.lower + self.radius, ti.min(p, self.upper - self.radius))

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
    def wall_density(self, p):
        """Ghost density ρ_wall/ρ0 of the walls within h (walls − edges + corner), and its gradient
        with respect to p (1/m)."""
        density = 0.0
        gradient = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.with_wall_density):
            distance = ti.Vector([0.0, 0.0, 0.0])
            side = ti.Vector([0.0, 0.0, 0.0])  # +1: near the lower wall, −1: the upper, 0: neither
            for axis in ti.static(range(3)):
                below = p[axis] - self.lower[axis]
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
        return density, gradient
