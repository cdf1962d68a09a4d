"""The divergence pre-correction: a velocity-level pass inside the prediction (Algorithm 1, between
the neighbour search and the iterations) that removes the part of v that would compress the fluid,
with pressure warm-started from the previous substep; x* is then predicted again from the new v.

Why. PBF's iterations start every substep from zero pressure. A pool at rest needs the hydrostatic
pressure, built anew each substep from the compression gravity causes, and a few Jacobi iterations
rebuild the long waves of that pressure (the column's height) only partly: the seed pool stayed 1.25%
compressed. Carrying the multipliers of the position iterations over instead acts as an integral
controller on positions and left a pool at rest jittering at 0.1-0.4 m/s (docs/METHOD.md, "Tried and not kept").
Carried over at the velocity level, as in DFSPH's divergence solver (Bender & Koschier 2015) and in
the warm-started velocity solvers of rigid-body contact, the pressure impulse is damped by the very
velocities it acts on, and the position iterations are left with what the velocity pass missed.

What. The change of the density constraint of ``pbf.solver.density`` that v would cause over Δt,

    ΔC_i = (Δt/h) [Σ_j ĝ_ij · (v_i − v_j) + ĝ_wall · (v_i − v_wall)],

is driven to c_i = ΔC_i + min(C_i, 0) ≤ 0 (a particle below ρ0 may fill up to it, one at or above ρ0
may not compress further; its existing error is the position iterations' job, as carrying that over
is what made the integral controller) by Jacobi iterations in the form of Eq. 10:

    δλ̂_i = −ω c_i / (|Σ_j ĝ_ij + ĝ_wall|² + Σ_j |ĝ_ij|² + ε̂),   Λ_i ← min(Λ_i + δλ̂_i, 0)
    Δv_i  = (h/Δt) [Σ_j (δλ̂_i + δλ̂_j) ĝ_ij + δλ̂_i ĝ_wall]

Λ_i, the multiplier accumulated over the substep, is clamped at zero (pressure, never suction: a
separating surface stays free, a lone particle falls freely), and the next substep starts by
applying Λ again (warm start, scaled by (Δt_new/Δt_old)² when the CFL limit changes the step: Λ/Δt²
is a pressure), so its iterations only correct the change. Positions stay at x during the pass; the
neighbour lists are those just built at x* (pairs that only come within h at x are separating, and
the kernel gives pairs beyond h nothing).
"""

import taichi as ti

from pbf.solver.grid import NeighbourList
from pbf.solver.model import DensityParams
from pbf.solver.sph import kernel_scale, scaled_kernel, scaled_kernel_and_gradient, scaled_kernel_gradient


@ti.data_oriented
class DivergenceCorrection:
    """The pass's kernels and scratch. Λ persists between substeps as ``State.multiplier`` = Λ/Δt² (1/s²),
    a pressure, which needs no record of the Δt it was found with."""

    def __init__(self, params: DensityParams, state, boundaries, grid, density):
        self.state = state
        self.boundaries = boundaries
        self.grid = grid
        self.density = density
        self.constants = density.constants
        """h, V, ω and ε̂ as data: the density constraint's (``DensityConstraint.constants``)."""
        self.denominator = ti.field(ti.f32, shape=params.particle_count)
        """|Σ_j ĝ_ij + ĝ_wall|² + Σ_j |ĝ_ij|² + ε̂ at the fixed positions."""
        self.deficit = ti.field(ti.f32, shape=params.particle_count)
        """min(C_i, 0) at x: how far below ρ0 particle i may still fill."""
        self.increment = ti.field(ti.f32, shape=params.particle_count)
        """δλ̂_i of the current iteration (the warm start's Λ_i in the first)."""
        self.wall_gradient = density.wall_gradient
        """ĝ_wall at x_i, looked up by :meth:`start` and read by every iteration (x stays put while v is
        corrected): the density constraint's field, free outside its iterations, which come after this
        pass. The ghost of obstacles and bodies is long code: looked up in both loops of the iteration's
        kernel as well, it took 1.8 s of ``wave_tank_float``'s cold start to compile."""

    @ti.func
    def velocity_change(self, x: ti.template(), i, neighbours: ti.template(), h_over_dt, start: ti.template()):
        """Δv_i from the increments δλ̂ (the Δx of Eq. 12 over Δt); at the ``start``, in the same pass,
        min(C_i, 0) and the denominator of δλ̂_i."""
        xi = x[i]
        h, volume, relaxation = self.constants[None].h, self.constants[None].volume, self.constants[None].relaxation
        scale = kernel_scale(h)  # once per particle, for the neighbour loop
        increment_i = self.increment[i]
        dv = ti.Vector([0.0, 0.0, 0.0])
        ratio = volume * scaled_kernel(0.0, scale)
        gradient_i = ti.Vector([0.0, 0.0, 0.0])
        sum_sq = 0.0
        first, last, stride = self.grid.listed(i, neighbours)
        upcoming = self.grid.upcoming(neighbours, first, last)
        for k in range(first, last):
            j = self.grid.neighbour(neighbours, k, upcoming)
            upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
            if ti.static(start):
                w, grad_w = scaled_kernel_and_gradient(xi - x[j], scale)
                g = volume * h * grad_w
                ratio += volume * w
                gradient_i += g
                sum_sq += g.norm_sqr()
                dv += (increment_i + self.increment[j]) * g
            else:
                dv += (increment_i + self.increment[j]) * volume * h * scaled_kernel_gradient(xi - x[j], scale)
        wall_gradient = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(start):
            wall, at_start = self.boundaries.ghost(xi, False)
            wall_gradient = at_start
            self.wall_gradient[i] = wall_gradient
            self.deficit[i] = ti.min(ratio + wall - 1.0, 0.0)
            self.denominator[i] = (gradient_i + h * wall_gradient).norm_sqr() + sum_sq + relaxation
        else:
            wall_gradient = self.wall_gradient[i]
        dv += increment_i * h * wall_gradient
        return h_over_dt * dv

    @ti.func
    def multiplier_increment(self, x: ti.template(), i, neighbours: ti.template(), dt):
        """δλ̂_i of an iteration from the current v (Λ_i kept as a pressure in ``State.multiplier``)."""
        h, volume, omega = self.constants[None].h, self.constants[None].volume, self.constants[None].omega
        scale = kernel_scale(h)  # once per particle, for the neighbour loop
        xi, vi = x[i], self.state.v[i]
        rate = 0.0
        first, last, stride = self.grid.listed(i, neighbours)
        upcoming = self.grid.upcoming(neighbours, first, last)
        for k in range(first, last):
            j = self.grid.neighbour(neighbours, k, upcoming)
            upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
            rate += volume * h * scaled_kernel_gradient(xi - x[j], scale).dot(vi - self.state.v[j])
        rate += h * self.wall_gradient[i].dot(vi - self.boundaries.velocity(xi))
        carried = self.state.multiplier[i] * dt * dt
        c = dt / h * rate + self.deficit[i]
        total = ti.min(carried - omega * c / self.denominator[i], 0.0)
        self.increment[i] = total - carried
        self.state.multiplier[i] = total / (dt * dt)

    @ti.kernel
    def start(self, x: ti.template(), neighbours: NeighbourList, dt: ti.f32):
        """v += Δv of the warm start (the last substep's Λ), with min(C_i, 0) and the denominators at x."""
        for i in range(self.state.active[None]):
            self.increment[i] = self.state.multiplier[i] * dt * dt
        for i in range(self.state.active[None]):
            self.state.v[i] += self.velocity_change(x, i, neighbours, self.constants[None].h / dt, True)

    @ti.kernel
    def iterate(self, x: ti.template(), neighbours: NeighbourList, dt: ti.f32):
        """One Jacobi iteration: all δλ̂ from the current v, then all Δv."""
        for i in range(self.state.active[None]):
            self.multiplier_increment(x, i, neighbours, dt)
        for i in range(self.state.active[None]):
            self.state.v[i] += self.velocity_change(x, i, neighbours, self.constants[None].h / dt, False)

    def run(self, neighbours, dt: float, iterations: int) -> None:
        """Warm start with the last substep's Λ, then ``iterations`` Jacobi iterations on state.v at state.x:
        a call each, the host's path (the device's runs :meth:`run_loops` in the call of lines 1-7)."""
        self.start(self.state.x, neighbours, dt)
        for _ in range(iterations):
            self.iterate(self.state.x, neighbours, dt)

    @ti.func
    def run_loops(self, x: ti.template(), neighbours: ti.template(), dt: ti.template(), iterations: ti.template()):
        """:meth:`run`'s loops for the top level of a kernel (``pbf.solver.substep``), ``iterations`` of them
        (a count known when it compiles), each over the particles' bucket (no one-thread task for a bound)."""
        for i in range(self.state.live_bound()):
            if i < self.state.active[None]:
                self.increment[i] = self.state.multiplier[i] * dt * dt
        for i in range(self.state.live_bound()):
            if i < self.state.active[None]:
                self.state.v[i] += self.velocity_change(x, i, neighbours, self.constants[None].h / dt, True)
        for _ in ti.static(range(iterations)):
            for i in range(self.state.live_bound()):
                if i < self.state.active[None]:
                    self.multiplier_increment(x, i, neighbours, dt)
            for i in range(self.state.live_bound()):
                if i < self.state.active[None]:
                    self.state.v[i] += self.velocity_change(x, i, neighbours, self.constants[None].h / dt, False)
