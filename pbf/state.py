"""Particle state: what persists between substeps, kept apart from the solver's scratch arrays."""
import numpy as np
import taichi as ti


@ti.data_oriented
class ParticleState:
    """Positions x (m), velocities v (m/s) and each particle's original index, all of length n.

    The arrays are re-sorted by grid cell every substep, so slot i holds particle ``index[i]``;
    :meth:`positions` and :meth:`velocities` return them in the original order.
    """

    def __init__(self, particle_count: int):
        self.count = particle_count
        self.x = ti.Vector.field(3, ti.f32, shape=particle_count)
        self.v = ti.Vector.field(3, ti.f32, shape=particle_count)
        self.index = ti.field(ti.i32, shape=particle_count)
        self._unsorted = ti.Vector.field(3, ti.f32, shape=particle_count)
        self._unsorted_scalar = ti.field(ti.f32, shape=particle_count)

    def load(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        self.x.from_numpy(positions.astype(np.float32))
        self.v.from_numpy(velocities.astype(np.float32))
        self.index.from_numpy(np.arange(self.count, dtype=np.int32))

    @ti.kernel
    def _unsort(self, values: ti.template()):
        for i in range(self.count):
            self._unsorted[self.index[i]] = values[i]

    @ti.kernel
    def _unsort_scalar(self, values: ti.template()):
        for i in range(self.count):
            self._unsorted_scalar[self.index[i]] = values[i]

    def in_creation_order(self, values) -> np.ndarray:
        """A per-particle scalar field (in the current sorted order) as a NumPy array in creation order."""
        self._unsort_scalar(values)
        return self._unsorted_scalar.to_numpy()

    def positions(self) -> np.ndarray:
        """(n, 3) float32 positions in metres, in the order the particles were created."""
        self._unsort(self.x)
        return self._unsorted.to_numpy()

    def velocities(self) -> np.ndarray:
        """(n, 3) float32 velocities in m/s, in the order the particles were created."""
        self._unsort(self.v)
        return self._unsorted.to_numpy()
