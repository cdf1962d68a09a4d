"""Time integration: external forces and prediction (Algorithm 1, lines 1-4); lines 20-23 are
``pbf.solver.postprocess``."""

import taichi as ti


@ti.data_oriented
class PredictedPositions:
    """x* (m) in two buffers: each iteration reads one and writes the other; x* ends in the first.
    Which holds x* is data, so the kernels compile once."""

    def __init__(self, particle_count: int):
        self.first = ti.Vector.field(3, ti.f32, shape=particle_count)
        self.second = ti.Vector.field(3, ti.f32, shape=particle_count)


@ti.data_oriented
class Integrator:
    """Owns x* (:class:`PredictedPositions`), which the grid's sort carries with the state."""

    def __init__(self, state, boundaries):
        self.state = state
        self.boundaries = boundaries
        self.predicted = PredictedPositions(state.capacity)
        state.carry(self.predicted.first)

    @ti.func
    def advance_particle(self, dt, gravity, i):
        self.state.v[i] = self.state.v[i] + dt * gravity
        return self.predict_particle(dt, i)

    @ti.kernel
    def damp(self, factor: ti.f32):
        """v ← factor · v (settling before t = 0, ``Simulation.reset``)."""
        for i in range(self.state.active[None]):
            self.state.v[i] *= factor

    @ti.func
    def predict_particle(self, dt, i):
        """x*_i ← x_i + Δt v_i, kept inside the boundaries; returns x*_i."""
        x_star = self.boundaries.project_recorded(self.state.x[i] + dt * self.state.v[i], i, "start", 1.0)
        self.predicted.first[i] = x_star
        return x_star

    @ti.kernel
    def _push(self, point: ti.types.vector(3, ti.f32), velocity: ti.types.vector(3, ti.f32), radius: ti.f32):
        for i in range(self.state.active[None]):
            q2 = (self.state.x[i] - point).norm_sqr() / (radius * radius)
            if q2 < 1.0:
                w = (1.0 - q2) ** 3
                self.state.v[i] += w * (velocity - self.state.v[i])

    def push(self, push) -> None:
        """Blend the velocities near the hand toward its velocity (``model.Push``, capped by the caller)."""
        self._push(push.point_m, push.velocity_m_s, push.radius_m)
