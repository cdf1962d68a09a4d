"""Particle state, what persists between substeps: each per-particle quantity declared once, in
:data:`PARTICLE_FIELDS`; a stage's own array that must follow the sort is attached with :meth:`State.carry`.
"""

from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from pbf.solver.constants import array_loader
from pbf.solver.scan import read_count


@dataclass(frozen=True)
class ParticleField:
    """One per-particle quantity of :class:`State`."""

    name: str
    """The attribute of State that holds it."""
    dtype: object
    components: int
    """1 (a scalar) or 3 (a vector)."""
    unit: str
    doc: str
    kept: bool
    """Whether a :class:`Snapshot` keeps it (if not, a restore starts it at its initial value)."""
    initial: str = "zero"
    """A new particle's value: "zero", or "creation" (the creation index)."""


PARTICLE_FIELDS = (
    ParticleField("x", ti.f32, 3, "m", "position", kept=True),
    ParticleField("v", ti.f32, 3, "m/s", "velocity", kept=True),
    ParticleField(
        "index", ti.i32, 1, "", "the particle's creation index (its row in positions())", kept=False, initial="creation"
    ),
    ParticleField(
        "multiplier",
        ti.f32,
        1,
        "1/s²",
        "Λ/Δt² of pbf.solver.divergence: the last substep's divergence pressure, which the next one starts from",
        kept=True,
    ),
    ParticleField(
        "pressure_sum",
        ti.f32,
        1,
        "Pa",
        "the sum of each substep's pressure since the frame began "
        "(Simulation.pressures divides it by the count): one substep's alternates under accelerated "
        "weights, a frame's mean does not",
        kept=False,
    ),
)
"""The particles' quantities, in the order the sort carries them."""


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
    fields: dict = field(default_factory=dict)
    """The other kept per-particle fields by name, (n,) or (n, 3) float32; one left out starts at zero."""
    bodies: np.ndarray | None = None
    """(bodies, 19) float32 (``pbf.solver.bodies.STATE_LAYOUT``); None: as the scene sets them."""


@ti.data_oriented
class State:
    """A (capacity,) field per :data:`PARTICLE_FIELDS` entry; slots below ``active[None]`` hold the live ones."""

    def __init__(self, capacity: int, on_device: bool):
        self.capacity = capacity
        self.fields = PARTICLE_FIELDS
        self.active = ti.field(ti.i32, shape=())
        self.loop_bound = capacity if on_device else self.active
        """What loops over the live particles run to: on a GPU's path (``on_device``,
        ``pbf.solver.backend.Choices.decisions_on_device``) the capacity (a bound read at run time is a
        one-thread task), on the CPU's the live count."""
        self._carried = []
        """(field, scratch) of every per-particle array the sort carries, the state's own first."""
        for spec in self.fields:
            setattr(self, spec.name, self._allocate(spec.dtype, spec.components))
            self._carried.append((getattr(self, spec.name), self._allocate(spec.dtype, spec.components)))
        self._unsorted = ti.Vector.field(3, ti.f32, shape=capacity)
        self._unsorted_scalar = ti.field(ti.f32, shape=capacity)
        self._loader = None  # made at the first load (pbf.solver.constants.array_loader)

    def _allocate(self, dtype, components: int):
        if components == 1:
            return ti.field(dtype, shape=self.capacity)
        return ti.Vector.field(components, dtype, shape=self.capacity)

    def carry(self, values) -> None:
        """Have the sort carry ``values``, a stage's own (capacity,) field (before the first substep)."""
        self._carried.append((values, self._allocate(values.dtype, values.n if hasattr(values, "n") else 1)))

    @property
    def count(self) -> int:
        """The number of live particles (one read from the device)."""
        return int(self.active[None])

    def load(self, values: dict) -> None:
        """Make ``values`` (name → array in creation order; x required) the live particles, the rest initial."""
        n = len(values["x"])
        arrays = []
        for spec in self.fields:
            shape = (self.capacity,) if spec.components == 1 else (self.capacity, spec.components)
            if spec.initial == "creation":
                padded = np.arange(self.capacity, dtype=np.int32)
            else:
                padded = np.zeros(shape, np.float32 if spec.dtype == ti.f32 else np.int32)
            if spec.name in values and values[spec.name] is not None:
                padded[:n] = values[spec.name]
            arrays.append(padded)
        if self._loader is None:
            self._loader = array_loader(getattr(self, spec.name) for spec in self.fields)
        self._loader(arrays)
        self.active[None] = n

    @ti.func
    def live_bound(self):
        """The bound of a loop over the live particles (:attr:`loop_bound`); the loop still skips ``i ≥ active``."""
        return read_count(self.loop_bound, 1)

    @property
    def carried(self) -> tuple:
        """(field, scratch) of every array the sort carries (``NeighbourGrid.order_loops``), the state's first."""
        return tuple(self._carried)

    def scratch_of(self, values):
        return next(scratch for field, scratch in self._carried if field is values)

    @ti.func
    def reset_new(self, slot):
        """A new particle's fields, except position and velocity, at their initial values (the emitters)."""
        for k in ti.static([k for k, spec in enumerate(self.fields) if spec.name not in ("x", "v")]):
            # The creation index for "creation", else zero, without a branch.
            creation = ti.static(int(self.fields[k].initial == "creation"))
            self._carried[k][0][slot] = ti.cast(slot * creation, self.fields[k].dtype)

    @ti.kernel
    def _unsort(self, values: ti.template(), unsorted: ti.template()):
        for i in range(self.active[None]):
            unsorted[self.index[i]] = values[i]

    def in_creation_order(self, values) -> np.ndarray:
        """A per-particle field as a NumPy array in creation order, (n,) or (n, 3)."""
        unsorted = self._unsorted if hasattr(values, "n") else self._unsorted_scalar
        self._unsort(values, unsorted)
        return unsorted.to_numpy()[: self.count]

    @property
    def _kept(self) -> tuple:
        """The kept float32 fields (a snapshot's): (name, field, components, first column) each."""
        kept, column = [], 0
        for spec in self.fields:
            if spec.kept and spec.dtype == ti.f32:
                kept.append((spec.name, getattr(self, spec.name), spec.components, column))
                column += spec.components
        return tuple(kept)

    @ti.kernel
    def _unsort_kept(self, out: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        for i in range(self.active[None]):
            for k in ti.static(range(len(self._kept))):
                _, values, components, column = ti.static(self._kept[k])
                if ti.static(components == 1):
                    out[self.index[i], column] = values[i]
                else:
                    for c in ti.static(range(components)):
                        out[self.index[i], column + c] = values[i][c]

    def kept_in_creation_order(self) -> dict:
        """Every kept field by name, in creation order, (n,) or (n, 3), read in one launch: a kernel a
        field (and a copy out for each shape) would each compile on a cold start."""
        kept = self._kept
        out = np.zeros((self.count, kept[-1][3] + kept[-1][2]), np.float32)
        self._unsort_kept(out)
        return {
            name: np.ascontiguousarray(out[:, column : column + components] if components > 1 else out[:, column])
            for name, _, components, column in kept
        }

    def positions(self) -> np.ndarray:
        return self.kept_in_creation_order()["x"]

    def velocities(self) -> np.ndarray:
        return self.kept_in_creation_order()["v"]
