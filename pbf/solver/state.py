"""Particle state: what persists from one substep to the next, kept apart from the stages' scratch."""

from dataclasses import dataclass

import numpy as np
import taichi as ti


@dataclass(frozen=True)
class Snapshot:
    """A state to return to with ``Simulation.restore``: NumPy copies in creation order."""

    positions_m: np.ndarray
    """(n, 3) float32, m."""
    velocities_m_s: np.ndarray
    """(n, 3) float32, m/s."""
    time_s: float
    frame: int


@ti.data_oriented
class State:
    """The particles of a simulation. Every array has one entry per particle, in the current sorted
    order: the grid re-sorts them by cell every substep, so slot i holds particle ``index[i]``.

    * ``x``: (n,) vector(3, f32), positions, m
    * ``v``: (n,) vector(3, f32), velocities, m/s
    * ``index``: (n,) i32, the particle's creation index (its row in :meth:`positions`)
    """

    def __init__(self, particle_count: int):
        self.count = particle_count
        self.x = ti.Vector.field(3, ti.f32, shape=particle_count)
        self.v = ti.Vector.field(3, ti.f32, shape=particle_count)
        self.index = ti.field(ti.i32, shape=particle_count)
        self._unsorted = ti.Vector.field(3, ti.f32, shape=particle_count)
        self._unsorted_scalar = ti.field(ti.f32, shape=particle_count)

    def load(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Set every particle from (n, 3) arrays in creation order (m, m/s)."""
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
