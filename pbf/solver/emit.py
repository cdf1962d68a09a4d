"""Emitters: water added while the scene runs, before each substep's prediction.

A nozzle is a disc of lattice sites at the spacing s, perpendicular to its direction. The stream is a
pile of such layers one spacing apart: layer j leaves the nozzle at t_j = start + j s / u and, at
time t, has travelled u (t − t_j), so the new water arrives at the rest spacing (no explosion where
it appears). The layers emitted so far are part of a snapshot, so a restored one replays exactly.
Slots for every particle the emitters will add are allocated at the start
(``Scene.particle_capacity``); new particles take the slots after the live ones.

A drowned nozzle pauses: a layer whose sites the water already occupies (a live particle within
half a spacing of a site, where the density constraint would push the pair apart at once) is
skipped, as while the emitters are switched off, and the stream resumes once the water has gone.
"""

import itertools
import math

import numpy as np
import taichi as ti

from pbf.scene import Emitter


def nozzle_sites(emitter: Emitter, spacing: float) -> np.ndarray:
    """(k, 3) offsets (m) of the nozzle's lattice sites from its centre, in its plane."""
    direction = np.array(emitter.unit_direction())
    helper = np.eye(3)[int(np.argmin(np.abs(direction)))]  # the axis least along the stream
    u = np.cross(direction, helper)
    u /= np.linalg.norm(u)
    w = np.cross(direction, u)
    reach = int(math.floor(emitter.radius_m / spacing + 1e-9))
    limit = (emitter.radius_m / spacing) ** 2 + 1e-9
    grid = [(i, j) for i in range(-reach, reach + 1) for j in range(-reach, reach + 1) if i * i + j * j <= limit]
    return np.array([spacing * (i * u + j * w) for i, j in grid]).reshape(-1, 3)


@ti.data_oriented
class Emitters:
    """Appends each emitter's due layers to the state."""

    def __init__(self, emitters, spacing_m: float, state, grid=None):
        self.emitters = emitters
        self.spacing = spacing_m
        self.state = state
        self.capacity = state.capacity
        """Slots allocated: no append writes past them."""
        self.grid = grid
        """The neighbour grid (``pbf.solver.grid``) of the last sort, to find water at a nozzle; None: no check."""
        self.sites = [nozzle_sites(e, spacing_m) for e in emitters]
        self.emitted = [0] * len(emitters)
        """Layers each emitter has added so far."""

    def layers_due(self, emitter: Emitter, time_s: float) -> int:
        """Layers emitted by ``time_s``: those with t_j ≤ time_s, at most the emitter's total."""
        if time_s < emitter.start_s:
            return 0
        moved = (min(time_s, emitter.end_s) - emitter.start_s) * emitter.speed_m_s / self.spacing
        return min(int(math.floor(moved + 1e-9)) + 1, emitter.layers(self.spacing))

    @ti.kernel
    def _append(
        self,
        positions: ti.types.ndarray(dtype=ti.math.vec3, ndim=1),
        velocities: ti.types.ndarray(dtype=ti.math.vec3, ndim=1),
    ):
        # Bounds-safe by construction: the slots written are clamped to the allocation, whatever the
        # caller hands in (restore() also refuses emitted layers that could overflow the budget).
        first = ti.min(ti.max(self.state.active[None], 0), self.capacity)
        added = ti.min(positions.shape[0], self.capacity - first)
        for k in range(added):
            slot = first + k
            self.state.x[slot] = positions[k]
            self.state.v[slot] = velocities[k]
            self.state.reset_new(slot)  # every other field at its initial value, the index in creation order
        self.state.active[None] = first + added

    @ti.kernel
    def _occupied(
        self,
        sites: ti.types.ndarray(dtype=ti.math.vec3, ndim=1),
        occupied: ti.types.ndarray(dtype=ti.i32, ndim=1),
        radius: ti.f32,
    ):
        """occupied[k] = 1 where a live particle lies within ``radius`` of sites[k]. The cells within
        the grid's reach (h) of the site's hold every particle that was within h at the last sort, and
        none has moved a spacing since (time.max_cfl), so none within radius < h − max_cfl s is missed."""
        grid = self.grid
        for k in range(sites.shape[0]):
            p = sites[k]
            c = grid.cell_of(p)
            found = 0
            for dx, dy, dz in ti.ndrange(
                (-grid.reach, grid.reach + 1), (-grid.reach, grid.reach + 1), (-grid.reach, grid.reach + 1)
            ):
                cell = c + ti.Vector([dx, dy, dz])
                if all(cell >= 0) and all(cell < grid.resolution):
                    linear = grid.linear(cell)
                    for slot in range(grid.cell_start[linear], grid.cell_start[linear + 1]):
                        if slot < self.state.active[None] and (self.state.x[slot] - p).norm_sqr() < radius * radius:
                            found = 1
            occupied[k] = found

    def drowned(self, layers: list[np.ndarray]) -> list[bool]:
        """Whether each layer's sites are taken by water already (one small read from the device)."""
        if self.grid is None or not layers:
            return [False] * len(layers)
        sites = np.concatenate(layers).astype(np.float32)
        occupied = np.zeros(len(sites), np.int32)
        self._occupied(sites, occupied, 0.5 * self.spacing)
        bounds = np.cumsum([0] + [len(layer) for layer in layers])
        return [bool(occupied[a:b].any()) for a, b in itertools.pairwise(bounds)]

    def emit(self, now_s: float, pouring: bool = True) -> None:
        """Add the layers due by ``now_s`` (the start of a substep) that are not in yet, each where its
        time since leaving the nozzle has carried it; the substep moves them on with everything else.
        When not ``pouring``, the layers due are skipped instead: turned back on, a nozzle resumes its
        stream rather than releasing everything it held back at once."""
        positions, velocities = [], []
        for k, (emitter, sites) in enumerate(zip(self.emitters, self.sites)):
            due = self.layers_due(emitter, now_s)
            if not pouring:
                self.emitted[k] = max(self.emitted[k], due)
            direction = np.array(emitter.unit_direction())
            for j in range(self.emitted[k], due):
                travelled = emitter.speed_m_s * (now_s - emitter.start_s) - j * self.spacing
                positions.append(np.array(emitter.position_m) + travelled * direction + sites)
                velocities.append(np.broadcast_to(emitter.speed_m_s * direction, sites.shape))
            self.emitted[k] = max(self.emitted[k], due)
        if positions:
            kept = [k for k, drowned in enumerate(self.drowned(positions)) if not drowned]
            if kept:
                # Only the new layers cross to the device (kernel arguments of their own size).
                self._append(
                    np.concatenate([positions[k] for k in kept]).astype(np.float32),
                    np.concatenate([velocities[k] for k in kept]).astype(np.float32),
                )
