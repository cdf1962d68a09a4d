"""Velocity post-processing: vorticity confinement (Eqs. 13-14) and XSPH viscosity (Eq. 15).

Both are made dimensionless like the density constraint (V = m/ρ0 is the particle volume):

    ω_i   = Σ_j V ∇_i W_ij × (v_j − v_i)                  SPH curl of v (1/s), Eq. 13
    η_i   = Σ_j V (|ω_j| − |ω_i|) ∇_i W_ij,  N = η/|η|    location vector
    Δv_i  = Δt ε h |ω_i| (N × ω_i)                        Eq. 14; ε h |ω|² is an acceleration
    Δv_i += c Σ_j V (v_j − v_i) W_ij                      Eq. 15

The h in Eq. 14 makes confinement fade as resolution rises, as the vorticity it restores is the part
lost to coarse particles. Both read velocities and write new ones (Jacobi), then copy back.
"""
import taichi as ti

from pbf.sph import kernel_and_gradient, kernel_gradient

NeighbourList = ti.types.ndarray(dtype=ti.i32, ndim=1)


@ti.data_oriented
class VelocityPostprocess:
    def __init__(self, state, particle_volume_m3, kernel_radius_m, grid):
        self.state = state
        self.count = state.count
        self.volume = float(particle_volume_m3)
        self.h = float(kernel_radius_m)
        self.grid = grid
        self.omega = ti.Vector.field(3, ti.f32, shape=state.count)
        self.omega_norm = ti.field(ti.f32, shape=state.count)
        """|ω_i|, read once per pair by the location vector η: computed once per particle."""
        self.v_next = ti.Vector.field(3, ti.f32, shape=state.count)

    @ti.kernel
    def apply(self, x: ti.template(), neighbours: NeighbourList, dt: ti.f32, vorticity: ti.f32,
              xsph: ti.f32, with_vorticity: ti.template()):
        """ω (if confining), then the new velocities, then the copy back: three loops, one launch."""
        h = self.h
        if ti.static(with_vorticity):
            for i in range(self.count):
                xi, vi = x[i], self.state.v[i]
                omega = ti.Vector([0.0, 0.0, 0.0])
                for k in range(self.grid.neighbour_start[i], self.grid.neighbour_end[i]):
                    j = neighbours[k]
                    omega += self.volume * kernel_gradient(xi - x[j], h).cross(self.state.v[j] - vi)
                self.omega[i] = omega
                self.omega_norm[i] = omega.norm()
        for i in range(self.count):
            xi, vi = x[i], self.state.v[i]
            eta = ti.Vector([0.0, 0.0, 0.0])
            smoothing = ti.Vector([0.0, 0.0, 0.0])
            omega_i = ti.Vector([0.0, 0.0, 0.0])
            omega_i_norm = 0.0
            if ti.static(with_vorticity):
                omega_i = self.omega[i]
                omega_i_norm = self.omega_norm[i]
            for k in range(self.grid.neighbour_start[i], self.grid.neighbour_end[i]):
                j = neighbours[k]
                w, grad_w = kernel_and_gradient(xi - x[j], h)
                smoothing += self.volume * (self.state.v[j] - vi) * w
                if ti.static(with_vorticity):
                    eta += self.volume * (self.omega_norm[j] - omega_i_norm) * grad_w
            dv = xsph * smoothing
            if ti.static(with_vorticity):
                eta_norm = eta.norm()
                if eta_norm > 0.0:
                    dv += dt * vorticity * h * omega_i_norm * (eta / eta_norm).cross(omega_i)
            self.v_next[i] = vi + dv
        for i in range(self.count):
            self.state.v[i] = self.v_next[i]

    def run(self, x, neighbours, dt, vorticity, xsph):
        """Apply confinement (if ε > 0) and XSPH (if c > 0) to the state's velocities."""
        if vorticity > 0.0 or xsph > 0.0:
            self.apply(x, neighbours, dt, vorticity, xsph, vorticity > 0.0)
