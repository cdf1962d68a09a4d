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
    emitted_layers: tuple[int, ...] = ()
    """Layers each emitter had added (empty: none, as at the start)."""
    piston_time_s: float | None = None
    """How long the wave maker had run (None: as long as the scene, it was never switched off)."""
    divergence_multipliers: np.ndarray | None = None
    """(n,) float32 Λ, the divergence pressure the next substep starts from (None: none, as at rest)."""


@ti.data_oriented
class State:
    """The particles of a simulation. Arrays are allocated once for the scene's capacity (its blocks
    and everything its emitters will add); the first ``active[None]`` slots hold live particles, in
    the current sorted order: the grid re-sorts them by cell every substep, so slot i holds particle
    ``index[i]``. Emitters append particles after the live ones; the rest of the slots are never read.

    * ``x``: (capacity,) vector(3, f32), positions, m
    * ``v``: (capacity,) vector(3, f32), velocities, m/s
    * ``index``: (capacity,) i32, the particle's creation index (its row in :meth:`positions`)
    * ``multiplier``: (capacity,) f32, Λ of ``pbf.solver.divergence``: the last substep's divergence
      pressure, which the next one starts from
    * ``pressure_sum``: (capacity,) f32, Pa, the sum of each substep's pressure since the frame began
      (``Simulation.pressures`` divides it by the count): one substep's alternates under accelerated
      weights, a frame's mean does not
    * ``active``: () i32, the number of live particles
    """

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.x = ti.Vector.field(3, ti.f32, shape=capacity)
        self.v = ti.Vector.field(3, ti.f32, shape=capacity)
        self.index = ti.field(ti.i32, shape=capacity)
        self.active = ti.field(ti.i32, shape=())
        self.multiplier = ti.field(ti.f32, shape=capacity)
        self.pressure_sum = ti.field(ti.f32, shape=capacity)
        self._unsorted = ti.Vector.field(3, ti.f32, shape=capacity)
        self._unsorted_scalar = ti.field(ti.f32, shape=capacity)

    @property
    def count(self) -> int:
        """The number of live particles (one read from the device)."""
        return int(self.active[None])

    def load(self, positions: np.ndarray, velocities: np.ndarray, multipliers: np.ndarray | None = None) -> None:
        """Make the particles of (n, 3) arrays in creation order (m, m/s) the live ones, n ≤ capacity,
        with their (n,) Λ (zero when None)."""
        n = len(positions)
        padded = np.zeros((2, self.capacity, 3), np.float32)
        padded[0, :n], padded[1, :n] = positions, velocities
        self.x.from_numpy(padded[0])
        self.v.from_numpy(padded[1])
        scalars = np.zeros(self.capacity, np.float32)
        if multipliers is not None:
            scalars[:n] = multipliers
        self.multiplier.from_numpy(scalars)
        self.pressure_sum.fill(0.0)
        self.index.from_numpy(np.arange(self.capacity, dtype=np.int32))
        self.active[None] = n

    @ti.kernel
    def _unsort(self, values: ti.template()):
        for i in range(self.active[None]):
            self._unsorted[self.index[i]] = values[i]

    @ti.kernel
    def _unsort_scalar(self, values: ti.template()):
        for i in range(self.active[None]):
            self._unsorted_scalar[self.index[i]] = values[i]

    def in_creation_order(self, values) -> np.ndarray:
        """A per-particle scalar field (in the current sorted order) as a NumPy array in creation order."""
        self._unsort_scalar(values)
        return self._unsorted_scalar.to_numpy()[: self.count]

    def positions(self) -> np.ndarray:
        """(n, 3) float32 positions in metres of the live particles, in the order they were created."""
        self._unsort(self.x)
        return self._unsorted.to_numpy()[: self.count]

    def velocities(self) -> np.ndarray:
        """(n, 3) float32 velocities in m/s of the live particles, in the order they were created."""
        self._unsort(self.v)
        return self._unsorted.to_numpy()[: self.count]
