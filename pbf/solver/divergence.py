"""The divergence pre-correction: after the neighbour search, v loses the part that would compress the
fluid, warm-started from the last substep's pressure; x* is then predicted again (docs/METHOD.md, "Rest").
With ΔC_i = (Δt/h) [Σ_j ĝ_ij · (v_i − v_j) + ĝ_wall · (v_i − v_wall)], Jacobi iterations in the form of
Eq. 10 drive c_i = ΔC_i + min(C_i, 0) to ≤ 0 at fixed x:

    δλ̂_i = −ω c_i / (|Σ_j ĝ_ij + ĝ_wall|² + Σ_j |ĝ_ij|² + ε̂),   Λ_i ← min(Λ_i + δλ̂_i, 0)  (no suction)
    Δv_i  = (h/Δt) [Σ_j (δλ̂_i + δλ̂_j) ĝ_ij + δλ̂_i ĝ_wall]
"""

import taichi as ti

from pbf.solver.density import multiplier_denominator, pair_terms
from pbf.solver.grid import named
from pbf.solver.model import DensityParams
from pbf.solver.sph import scaled_kernel, scaled_kernel_gradient


@ti.data_oriented
class DivergenceCorrection:
    """The pass's loops and scratch; Λ persists as ``State.multiplier`` = Λ/Δt² (1/s²), free of Δt."""

    PER_CALL = 1
    """Iterations a kernel call runs (copies of an iteration's code, each skipped past the count): the
    presets that run the pass run one, so a second copy would be two empty launches a substep for them."""

    def __init__(self, params: DensityParams, state, boundaries, grid, density):
        self.state = state
        self.boundaries = boundaries
        self.grid = grid
        self.density = density  # its constants (h, V, ω and ε̂) and its choice of the walls' ghost
        self.constants = density.constants
        self.denominator = ti.field(ti.f32, shape=params.particle_count)  # of δλ̂_i, at the fixed positions
        self.deficit = ti.field(ti.f32, shape=params.particle_count)  # min(C_i, 0) at x: what i may still fill
        self.increment = ti.field(ti.f32, shape=params.particle_count)  # δλ̂_i (the warm start's Λ_i first)
        # ĝ_wall at x_i from the warm start: the density constraint's field, free until its iterations.
        self.wall_gradient = density.wall_gradient

    @ti.func
    def change_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s (δλ̂_i + δλ̂_j) ĝ_ij into Δv_i; at the ``start`` also its density and gradient."""
        if ti.static(p.start):
            g, terms = pair_terms(p.xi - p.x[j], p.volume, p.h, p.scale)
            p.sums += terms
            p.dv += (p.increment_i + self.increment[j]) * g
        else:
            p.dv += (
                (p.increment_i + self.increment[j]) * p.volume * p.h * scaled_kernel_gradient(p.xi - p.x[j], p.scale)
            )

    @ti.func
    def velocity_change(self, x: ti.template(), i, neighbours: ti.template(), dt, start: ti.template()):
        """Δv_i from the increments δλ̂ (Eq. 12's Δx over Δt); at the ``start`` also min(C_i, 0) and the denominator."""
        h, volume, scale = self.density.particle_constants()
        sums = ti.Vector([volume * scaled_kernel(0.0, scale), 0.0, 0.0, 0.0, 0.0])
        dv = ti.Vector([0.0, 0.0, 0.0])
        increment_i = self.increment[i]
        p = ti.static(
            named(x=x, xi=x[i], h=h, volume=volume, scale=scale, start=start, increment_i=increment_i, sums=sums, dv=dv)
        )
        self.grid.for_each_neighbour(i, neighbours, self.change_pair, p)
        wall_gradient = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(start):
            wall, wall_gradient = self.density.ghost(x[i], True)
            self.wall_gradient[i] = wall_gradient
            gradient_i = ti.Vector([sums[1], sums[2], sums[3]])
            self.deficit[i] = ti.min(sums[0] + wall - 1.0, 0.0)
            relaxation = self.constants[None].relaxation
            self.denominator[i] = multiplier_denominator(gradient_i + h * wall_gradient, sums[4], relaxation)
        else:
            wall_gradient = self.wall_gradient[i]
        dv += increment_i * h * wall_gradient
        return h / dt * dv

    @ti.func
    def rate_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s ĝ_ij · (v_i − v_j) into the rate of compression."""
        p.rate += p.volume * p.h * scaled_kernel_gradient(p.xi - p.x[j], p.scale).dot(p.vi - self.state.v[j])

    @ti.func
    def multiplier_increment(self, x: ti.template(), i, neighbours: ti.template(), dt):
        """δλ̂_i of an iteration from the current v (Λ_i kept as a pressure in ``State.multiplier``)."""
        h, volume, scale = self.density.particle_constants()
        omega = self.constants[None].omega
        xi, vi = x[i], self.state.v[i]
        rate = 0.0
        p = ti.static(named(x=x, xi=xi, vi=vi, h=h, volume=volume, scale=scale, rate=rate))
        self.grid.for_each_neighbour(i, neighbours, self.rate_pair, p)
        rate += h * self.wall_gradient[i].dot(vi - self.boundaries.velocity(xi))
        carried = self.state.multiplier[i] * dt * dt
        c = dt / h * rate + self.deficit[i]
        total = ti.min(carried - omega * c / self.denominator[i], 0.0)
        self.increment[i] = total - carried
        self.state.multiplier[i] = total / (dt * dt)

    @ti.func
    def start(self, x: ti.template(), neighbours: ti.template(), dt: ti.template(), count: ti.template()):
        """For the top level of a kernel: v += Δv of the warm start, with min(C, 0), the denominators and the
        walls' gradient at the fixed positions; nothing if ``count`` is 0 (a restore, Δt = 0)."""
        for i in range(self.state.live_bound()):
            if i < self.state.active[None] and count > 0:
                self.increment[i] = self.state.multiplier[i] * dt * dt
        for i in range(self.state.live_bound()):
            if i < self.state.active[None] and count > 0:
                self.state.v[i] += self.velocity_change(x, i, neighbours, dt, True)

    @ti.func
    def iterate(
        self, x: ti.template(), neighbours: ti.template(), dt: ti.template(), first: ti.template(), count: ti.template()
    ):
        """For the top level of a kernel: iterations ``first`` … ``first + PER_CALL − 1`` of those below
        ``count``, each every δλ̂, then every Δv. The count is data: every count compiles the same code."""
        for u in ti.static(range(self.PER_CALL)):
            for i in range(self.state.live_bound()):
                if first + u < count and i < self.state.active[None]:
                    self.multiplier_increment(x, i, neighbours, dt)
            for i in range(self.state.live_bound()):
                if first + u < count and i < self.state.active[None]:
                    self.state.v[i] += self.velocity_change(x, i, neighbours, dt, False)
