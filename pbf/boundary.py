"""The container: an axis-aligned box, with collision and the density of the missing wall neighbours.

A particle next to a wall has fewer neighbours than one inside the fluid, so its density reads low and
the solver pulls it into the wall, where clamping stacks it. We add the density of ghost fluid behind
each wall (``pbf.sph.wall_density_table``), and its gradient, to the density constraint; the table is
computed once per scene and looked up by wall distance. At a corner or edge the terms of the two or
three walls add up; the small region behind both walls is not counted.
"""
import numpy as np
import taichi as ti

from pbf import sph

TABLE_SAMPLES = 512


@ti.data_oriented
class Box:
    def __init__(self, lower_m, upper_m, particle_radius_m: float, spacing_m: float, kernel_radius_m: float,
                 wall_density: bool):
        self.radius = float(particle_radius_m)
        self.lower = ti.Vector([float(c) for c in lower_m])
        self.upper = ti.Vector([float(c) for c in upper_m])
        self.kernel_radius = float(kernel_radius_m)
        self.with_wall_density = wall_density
        density, slope = sph.wall_density_table(spacing_m, kernel_radius_m, TABLE_SAMPLES)
        self.density_table = ti.field(ti.f32, shape=TABLE_SAMPLES)
        self.slope_table = ti.field(ti.f32, shape=TABLE_SAMPLES)
        self.density_table.from_numpy(density.astype(np.float32))
        self.slope_table.from_numpy(slope.astype(np.float32))

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
    def wall_density(self, p):
        """Σ over walls within h of ρ_wall/ρ0, and its gradient with respect to p (1/m)."""
        density = 0.0
        gradient = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.with_wall_density):
            for axis in ti.static(range(3)):
                below = p[axis] - self.lower[axis]
                if below < self.kernel_radius:
                    d, s = self._lookup(below)
                    density += d
                    gradient[axis] += s
                above = self.upper[axis] - p[axis]
                if above < self.kernel_radius:
                    d, s = self._lookup(above)
                    density += d
                    gradient[axis] -= s
        return density, gradient
