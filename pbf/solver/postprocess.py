"""The end of a substep (Algorithm 1, lines 20-23): new velocities, vorticity confinement (Eqs. 13-14),
XSPH viscosity (Eq. 15) and the position update, as one kernel.

Both terms are made dimensionless like the density constraint (V = m/ρ0 is the particle volume):

    v_i   = (x*_i − x_i) / Δt                            line 21
    ω_i   = Σ_j V ∇_i W_ij × (v_j − v_i)                  SPH curl of v (1/s), Eq. 13
    η_i   = Σ_j V (|ω_j| − |ω_i|) ∇_i W_ij,  N = η/|η|    location vector
    Δv_i  = Δt ε h |ω_i| (N × ω_i)                        Eq. 14; ε h |ω|² is an acceleration
    Δv_i += c Σ_j V (v_j − v_i) W_ij                      Eq. 15

The h in Eq. 14 makes confinement fade as resolution rises, as the vorticity it restores is the part
lost to coarse particles. Every pass reads v_j as (x*_j − x_j)/Δt instead of a stored velocity, so
the velocity update needs no pass of its own and the smoothed velocity can be written straight into
v (nothing in that pass reads v): two particle loops fewer than update, smooth into a copy, copy back.
With confinement on, the ω pass keeps each v_i (``velocity_now``) and the last pass reads v_j from
there, not from x_j, so it also moves x to x*: no loop of its own for line 23 (a launch on a GPU).
"""

import taichi as ti

from pbf.solver.constants import scene_constants
from pbf.solver.grid import NeighbourList
from pbf.solver.model import VelocityParams
from pbf.solver.sph import kernel_scale, scaled_kernel_and_gradient, scaled_kernel_gradient


@ti.data_oriented
class VelocityPostprocess:
    """Lines 20-23 of Algorithm 1 and their scratch: ω and |ω| per particle."""

    def __init__(self, params: VelocityParams, state, grid):
        self.state = state
        self.constants = scene_constants(h=params.kernel_radius_m, volume=params.particle_volume_m3)
        """h (m) and V (m³) as data (``pbf.solver.constants``)."""
        self.grid = grid
        self.omega = ti.Vector.field(3, ti.f32, shape=params.particle_count)
        self.omega_norm = ti.field(ti.f32, shape=params.particle_count)
        """|ω_i|, read once per pair by the location vector η: computed once per particle."""
        self.velocity_now = ti.Vector.field(3, ti.f32, shape=params.particle_count)
        """v_i = (x*_i − x_i)/Δt as the ω pass read it, for the pass after it (the module docstring)."""

    @ti.func
    def velocity(self, x_pred: ti.template(), i, inverse_dt):
        """v_i = (x*_i − x_i) / Δt (Algorithm 1, line 21)."""
        return (x_pred[i] - self.state.x[i]) * inverse_dt

    @ti.func
    def particle(self, x_pred: ti.template(), i, dt):
        """What a pass over particle i's neighbours reads once for the particle: h, V, the kernel's scale,
        1/Δt, x*_i and v_i."""
        h, volume = self.constants[None].h, self.constants[None].volume
        inverse_dt = 1.0 / dt
        return h, volume, kernel_scale(h), inverse_dt, x_pred[i], self.velocity(x_pred, i, inverse_dt)

    @ti.kernel
    def finish(
        self,
        x_pred: ti.template(),
        neighbours: NeighbourList,
        dt: ti.f32,
        vorticity: ti.f32,
        xsph: ti.f32,
        with_vorticity: ti.template(),
        with_xsph: ti.template(),
        impulse: ti.template(),
        pressure_per_impulse: ti.f32,
        first_of_frame: ti.i32,
        max_speed: ti.f32,
    ):
        """Lines 20-23 of Algorithm 1 in one launch: v = (x* − x)/Δt, confinement (``with_vorticity``, at
        ε = ``vorticity``) and XSPH (``with_xsph``, c = ``xsph``) on v, v capped at ``max_speed`` (m/s,
        ``time.max_speed_m_s``; 0: no cap), then x = x*; and the pressure (Pa) of the multipliers
        ``impulse`` (L, per particle) and Λ, at ``pressure_per_impulse`` Pa per unit of L, added to
        ``State.pressure_sum`` (which starts again at the ``first_of_frame`` substep). Every loop runs
        over the particles' bucket and reads what it needs itself: a loop bound or a value worked out
        outside the loops would be a one-thread task, a launch on a GPU."""
        self.finish_loops(
            x_pred,
            neighbours,
            dt,
            vorticity,
            xsph,
            with_vorticity,
            with_xsph,
            impulse,
            pressure_per_impulse,
            first_of_frame,
            max_speed,
        )

    @ti.func
    def finish_loops(
        self,
        x_pred: ti.template(),
        neighbours: ti.template(),
        dt: ti.template(),
        vorticity: ti.template(),
        xsph: ti.template(),
        with_vorticity: ti.template(),
        with_xsph: ti.template(),
        impulse: ti.template(),
        pressure_per_impulse: ti.template(),
        first_of_frame: ti.template(),
        max_speed: ti.template(),
    ):
        """The loops of :meth:`finish`, for the top level of a kernel (``pbf.solver.substep`` runs them in
        the launch that ends the iterations). Every argument is a template: a value argument of a
        ``ti.func`` is copied at the call, outside the loops, which is a one-thread task."""
        if ti.static(with_vorticity):
            for i in range(self.state.live_bound()):
                if i < self.state.active[None]:
                    h, volume, scale, inverse_dt, xi, vi = self.particle(x_pred, i, dt)
                    omega = ti.Vector([0.0, 0.0, 0.0])
                    first, last, stride = self.grid.listed(i, neighbours)
                    upcoming = self.grid.upcoming(neighbours, first, last)
                    for k in range(first, last):
                        j = self.grid.neighbour(neighbours, k, upcoming)
                        upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
                        omega += volume * scaled_kernel_gradient(xi - x_pred[j], scale).cross(
                            self.velocity(x_pred, j, inverse_dt) - vi
                        )
                    self.omega[i] = omega
                    self.omega_norm[i] = omega.norm()
                    self.velocity_now[i] = vi
        # x = x* in the pass below when it reads no x_j: with confinement (v_j kept by the ω pass) or
        # without neighbour sums at all.
        moves_x = ti.static(with_vorticity or not with_xsph)
        for i in range(self.state.live_bound()):
            if i < self.state.active[None]:
                h, volume, scale, inverse_dt, xi, vi = self.particle(x_pred, i, dt)
                dv = ti.Vector([0.0, 0.0, 0.0])
                if ti.static(with_vorticity or with_xsph):
                    eta = ti.Vector([0.0, 0.0, 0.0])
                    smoothing = ti.Vector([0.0, 0.0, 0.0])
                    omega_i = ti.Vector([0.0, 0.0, 0.0])
                    omega_i_norm = 0.0
                    if ti.static(with_vorticity):
                        omega_i = self.omega[i]
                        omega_i_norm = self.omega_norm[i]
                    first, last, stride = self.grid.listed(i, neighbours)
                    upcoming = self.grid.upcoming(neighbours, first, last)
                    for k in range(first, last):
                        j = self.grid.neighbour(neighbours, k, upcoming)
                        upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
                        w, grad_w = scaled_kernel_and_gradient(xi - x_pred[j], scale)
                        if ti.static(with_xsph):
                            vj = ti.Vector([0.0, 0.0, 0.0])
                            if ti.static(moves_x):
                                vj = self.velocity_now[j]
                            else:
                                vj = self.velocity(x_pred, j, inverse_dt)
                            smoothing += volume * (vj - vi) * w
                        if ti.static(with_vorticity):
                            eta += volume * (self.omega_norm[j] - omega_i_norm) * grad_w
                    dv = xsph * smoothing
                    if ti.static(with_vorticity):
                        eta_norm = eta.norm()
                        if eta_norm > 0.0:
                            dv += dt * vorticity * h * omega_i_norm * (eta / eta_norm).cross(omega_i)
                v = vi + dv
                if max_speed > 0.0:  # time.max_speed_m_s: the same bits as before when there is no cap
                    speed = v.norm()
                    if speed > max_speed:
                        v *= max_speed / speed
                self.state.v[i] = v
                if ti.static(moves_x):
                    self.move(x_pred, i, dt, impulse, pressure_per_impulse, first_of_frame)
        if ti.static(not moves_x):
            for i in range(self.state.live_bound()):
                if i < self.state.active[None]:
                    self.move(x_pred, i, dt, impulse, pressure_per_impulse, first_of_frame)

    @ti.func
    def move(
        self,
        x_pred: ti.template(),
        i,
        dt: ti.template(),
        impulse: ti.template(),
        pressure_per_impulse: ti.template(),
        first_of_frame: ti.template(),
    ):
        """x_i = x*_i (line 23), and the substep's pressure added to particle i's sum."""
        self.state.x[i] = x_pred[i]
        # The pressure of this substep, from the position iterations' multiplier L and the
        # divergence pass's Λ (pbf.solver.density.DensityConstraint.pressure_scale).
        pressure = pressure_per_impulse * (impulse[i] + self.state.multiplier[i] * dt * dt)
        self.state.pressure_sum[i] = ti.select(first_of_frame, 0.0, self.state.pressure_sum[i]) + pressure
