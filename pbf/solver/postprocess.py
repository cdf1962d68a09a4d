"""The end of a substep (Algorithm 1, lines 20-23): new velocities, vorticity confinement (Eqs. 13-14),
XSPH viscosity (Eq. 15) and the position update, as one kernel.

Both terms are made dimensionless like the density constraint (V = m/ρ0 is the particle volume):

    v_i   = (x*_i − x_i) / Δt                            line 21
    ω_i   = Σ_j V ∇_i W_ij × (v_j − v_i)                  SPH curl of v (1/s), Eq. 13
    η_i   = Σ_j V (|ω_j| − |ω_i|) ∇_i W_ij,  N = η/|η|    location vector
    Δv_i  = Δt ε h |ω_i| (N × ω_i)                        Eq. 14; ε h |ω|² is an acceleration
    Δv_i += c Σ_j V (v_j − v_i) W_ij                      Eq. 15

The h in Eq. 14 makes confinement fade as resolution rises (it restores what coarse particles lose).
The first pass reads v_j as (x*_j − x_j)/Δt and keeps v_i (``velocity_now``); the second reads v_j
from there, so it writes v and moves x to x* in the same loop: no pass of its own for lines 21 or 23.
"""

import taichi as ti

from pbf.solver.constants import scene_constants
from pbf.solver.density import pressure
from pbf.solver.grid import named
from pbf.solver.model import VelocityParams
from pbf.solver.sph import kernel_scale, scaled_kernel_and_gradient, scaled_kernel_gradient


@ti.data_oriented
class VelocityPostprocess:
    """Lines 20-23 of Algorithm 1 as loops for the substep's last kernel, and their scratch: ω and |ω|
    per particle."""

    def __init__(self, params: VelocityParams, state, grid):
        self.state = state
        self.constants = scene_constants(h=params.kernel_radius_m, volume=params.particle_volume_m3)
        self.grid = grid
        self.omega = ti.Vector.field(3, ti.f32, shape=params.particle_count)
        self.omega_norm = ti.field(ti.f32, shape=params.particle_count)  # |ω_i|, read per pair by η
        self.velocity_now = ti.Vector.field(3, ti.f32, shape=params.particle_count)
        """v_i = (x*_i − x_i)/Δt from the first pass, for the pass after it (the module docstring)."""

    @ti.func
    def velocity(self, x_pred: ti.template(), i, inverse_dt):
        """v_i = (x*_i − x_i) / Δt (Algorithm 1, line 21)."""
        return (x_pred[i] - self.state.x[i]) * inverse_dt

    @ti.func
    def particle(self, x_pred: ti.template(), i, run: ti.template()):
        """What a walk reads once for particle i: h, V, the kernel's scale, 1/Δt, x*_i and v_i."""
        h, volume = self.constants[None].h, self.constants[None].volume
        inverse_dt = 1.0 / run.dt
        return h, volume, kernel_scale(h), inverse_dt, x_pred[i], self.velocity(x_pred, i, inverse_dt)

    @ti.func
    def curl_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s V ∇_i W_ij × (v_j − v_i) into ω_i (Eq. 13)."""
        p.omega += p.volume * scaled_kernel_gradient(p.xi - p.x[j], p.scale).cross(
            self.velocity(p.x, j, p.inverse_dt) - p.vi
        )

    @ti.func
    def smoothing_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s XSPH term V (v_j − v_i) W_ij (Eq. 15) and, with confinement, its term of the
        location vector η (Eq. 14)."""
        w, grad_w = scaled_kernel_and_gradient(p.xi - p.x[j], p.scale)
        p.smoothing += p.volume * (self.velocity_now[j] - p.vi) * w
        if ti.static(p.with_vorticity):
            p.eta += p.volume * (self.omega_norm[j] - p.omega_i_norm) * grad_w

    @ti.func
    def finish(self, x_pred: ti.template(), neighbours: ti.template(), impulse: ti.template(), run: ti.template()):
        """Lines 20-23 for the top level of a kernel: v = (x* − x)/Δt, confinement (at ε = ``run.epsilon``)
        and XSPH (c = ``run.xsph_c``), v capped at ``run.max_speed`` (0: no cap), x = x*; and the pressure
        of the multipliers ``impulse`` (L) and Λ, at ``run.pressure_per_impulse`` Pa per unit of L, added
        to ``State.pressure_sum`` (restarted at the ``run.first_of_frame`` substep)."""
        for i in range(self.state.live_bound()):  # line 21, v_i kept for the pass below; Eq. 13
            if i < self.state.active[None]:
                h, volume, scale, inverse_dt, xi, vi = self.particle(x_pred, i, run)
                if ti.static(run.vorticity):
                    omega = ti.Vector([0.0, 0.0, 0.0])
                    p = ti.static(
                        named(x=x_pred, xi=xi, vi=vi, volume=volume, scale=scale, inverse_dt=inverse_dt, omega=omega)
                    )
                    self.grid.for_each_neighbour(i, neighbours, self.curl_pair, p)
                    self.omega[i] = omega
                    self.omega_norm[i] = omega.norm()
                self.velocity_now[i] = vi
        # Eqs. 14-15 and line 23: the pairs read v_j as kept above, never x_j, so x moves in the same pass.
        for i in range(self.state.live_bound()):
            if i < self.state.active[None]:
                h, volume, scale, inverse_dt, xi, vi = self.particle(x_pred, i, run)
                dv = ti.Vector([0.0, 0.0, 0.0])
                if run.xsph_c > 0.0 or run.epsilon > 0.0:
                    omega_i_norm = self.omega_norm[i]
                    eta, smoothing = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
                    p = ti.static(
                        named(
                            x=x_pred,
                            xi=xi,
                            vi=vi,
                            volume=volume,
                            scale=scale,
                            omega_i_norm=omega_i_norm,
                            eta=eta,
                            smoothing=smoothing,
                            with_vorticity=run.vorticity,
                        )
                    )
                    self.grid.for_each_neighbour(i, neighbours, self.smoothing_pair, p)
                    dv = run.xsph_c * smoothing
                    if ti.static(run.vorticity):
                        eta_norm = eta.norm()
                        if eta_norm > 0.0:
                            dv += run.dt * run.epsilon * h * omega_i_norm * (eta / eta_norm).cross(self.omega[i])
                v = vi + dv
                if run.max_speed > 0.0:  # time.max_speed_m_s: the same bits as before when there is no cap
                    speed = v.norm()
                    if speed > run.max_speed:
                        v *= run.max_speed / speed
                self.state.v[i] = v
                self.move(x_pred, i, impulse, run)

    @ti.func
    def move(self, x_pred: ti.template(), i, impulse: ti.template(), run: ti.template()):
        """x_i = x*_i (line 23), and the substep's pressure added to particle i's sum."""
        self.state.x[i] = x_pred[i]
        # The pressure of this substep, from the position iterations' multiplier L and the divergence pass's Λ.
        p = pressure(impulse[i], self.state.multiplier[i], run.pressure_per_impulse, run.pressure_per_multiplier)
        self.state.pressure_sum[i] = ti.select(run.first_of_frame, 0.0, self.state.pressure_sum[i]) + p
