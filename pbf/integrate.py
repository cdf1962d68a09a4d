"""Time integration: prediction and reordering by cell (Algorithm 1, lines 1-4); lines 20-23 are
``pbf.postprocess``."""
import taichi as ti


@ti.data_oriented
class Integrator:
    def __init__(self, state, box):
        self.state = state
        self.box = box
        self.count = state.count
        self.x_pred = ti.Vector.field(3, ti.f32, shape=state.count)
        """Predicted positions x* (m). The solver iterations alternate between this and
        ``DensityConstraint.x_spare``, so after an odd number of them x* is in the other buffer."""
        self._vec = ti.Vector.field(3, ti.f32, shape=(3, state.count))
        self._int = ti.field(ti.i32, shape=state.count)

    @ti.kernel
    def predict(self, dt: ti.f32, gravity: ti.types.vector(3, ti.f32)):
        """v ← v + Δt g;  x* ← x + Δt v, kept inside the box so the grid never sees a lost particle."""
        for i in range(self.count):
            v = self.state.v[i] + dt * gravity
            self.state.v[i] = v
            self.x_pred[i] = self.box.clamp(self.state.x[i] + dt * v)

    @ti.kernel
    def reorder(self, sorted_from: ti.template()):
        """Apply the grid's counting-sort permutation to every per-particle array that persists."""
        for slot in range(self.count):
            i = sorted_from[slot]
            self._vec[0, slot] = self.state.x[i]
            self._vec[1, slot] = self.state.v[i]
            self._vec[2, slot] = self.x_pred[i]
            self._int[slot] = self.state.index[i]
        for slot in range(self.count):
            self.state.x[slot] = self._vec[0, slot]
            self.state.v[slot] = self._vec[1, slot]
            self.x_pred[slot] = self._vec[2, slot]
            self.state.index[slot] = self._int[slot]
