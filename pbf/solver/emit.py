"""Emitters: nozzles, discs of sites in hexagonal packing (a site to each s²). Layer j leaves at
t_j = start + j s / u and has travelled u (t − t_j) by t: the water arrives at rest density.
"""

import itertools
import math

import numpy as np
import taichi as ti

from pbf.scene import Emitter
from pbf.scene.emitters import HEX_PITCH
from pbf.solver.constants import scene_constants
from pbf.solver.model import allocation


def nozzle_sites(emitter: Emitter, spacing: float) -> np.ndarray:
    """(k, 3) offsets (m) of the nozzle's sites from its centre, in its plane (``Emitter.disc_rows``)."""
    direction = np.array(emitter.unit_direction())
    helper = np.eye(3)[int(np.argmin(np.abs(direction)))]  # the axis least along the stream
    u = np.cross(direction, helper)
    u /= np.linalg.norm(u)
    w = np.cross(direction, u)
    pitch = HEX_PITCH * spacing
    sites = [
        (first + i * pitch) * u + across * w
        for across, first, count in emitter.disc_rows(spacing)
        for i in range(count)
    ]
    return np.array(sites).reshape(-1, 3)


LAYERS_PER_LAUNCH = 16
"""Layers one launch appends at most; more due at once take more launches."""


@ti.data_oriented
class Emitters:
    """Appends the layers due on the device; a drowned one (water within s/2 of a site) is skipped."""

    def __init__(self, emitters, spacing_m: float, state, grid, capacity: int):
        self.emitters = emitters
        self.spacing = spacing_m
        self.state = state
        self.capacity = min(int(capacity), state.capacity)  # the budget
        self.grid = grid  # the last sort's grid, to find water at a nozzle
        self.sites = [nozzle_sites(e, spacing_m) for e in emitters]
        self.emitted = [0] * len(emitters)  # layers each emitter has added so far
        self.offsets = [0, *itertools.accumulate(len(sites) for sites in self.sites)]  # into site_offsets
        if self.offsets[-1]:
            # Sized by buckets, constants as data: one compile for every scene with emitters.
            self.constants = scene_constants(spacing=spacing_m, capacity=self.capacity)
            padded = np.zeros((allocation(self.offsets[-1], 64), 3), np.float32)
            padded[: self.offsets[-1]] = np.concatenate(self.sites)
            self.site_offsets = ti.Vector.field(3, ti.f32, len(padded))  # every nozzle's sites from its centre, m
            self.site_offsets.from_numpy(padded)
            # Per (layer, site) of a launch: 1 where water lies within half a spacing; per layer: any of them.
            self.taken = ti.field(ti.i32, allocation(LAYERS_PER_LAUNCH * max(len(sites) for sites in self.sites), 64))
            self.layer_taken = ti.field(ti.i32, LAYERS_PER_LAUNCH)

    def layers_due(self, emitter: Emitter, time_s: float) -> int:
        """Layers emitted by ``time_s``: those with t_j ≤ time_s, at most the emitter's total."""
        if time_s < emitter.start_s:
            return 0
        moved = (min(time_s, emitter.end_s) - emitter.start_s) * emitter.speed_m_s / self.spacing
        return min(int(math.floor(moved + 1e-9)) + 1, emitter.layers(self.spacing))

    @ti.func
    def _water_within(self, p, radius):
        """1 where a live particle lies within ``radius`` (< h − max_cfl s) of p, from the last sort's cells."""
        grid = self.grid
        c = grid.cell_of(p)
        found = 0
        for dx, dy, dz in ti.ndrange(
            (-grid.reach, grid.reach + 1), (-grid.reach, grid.reach + 1), (-grid.reach, grid.reach + 1)
        ):
            cell = c + ti.Vector([dx, dy, dz])
            if all(cell >= 0) and all(cell < grid.constants[None].resolution):
                linear = grid.linear(cell)
                for slot in range(grid.cell_start[linear], grid.cell_start[linear + 1]):
                    if slot < self.state.active[None] and (self.state.x[slot] - p).norm_sqr() < radius * radius:
                        found = 1
        return found

    @ti.kernel
    def _append_layers(
        self,
        first_site: ti.i32,
        sites: ti.i32,
        layers: ti.i32,
        centre: ti.math.vec3,
        direction: ti.math.vec3,
        travelled: ti.f32,
        velocity: ti.math.vec3,
    ):
        """Append ``layers`` layers of one nozzle, layer j at centre + (travelled − j s) direction."""
        for j, k in ti.ndrange(layers, sites):
            spacing = self.constants[None].spacing
            radius = 0.5 * spacing
            p = centre + (travelled - j * spacing) * direction + self.site_offsets[first_site + k]
            self.taken[j * sites + k] = self._water_within(p, radius)
        for j in range(layers):
            found = 0
            for k in range(sites):
                found |= self.taken[j * sites + k]
            self.layer_taken[j] = found
        # The slots written are clamped to the allocation, whatever the scene.
        for j, k in ti.ndrange(layers, sites):
            spacing, capacity = self.constants[None].spacing, self.constants[None].capacity
            if self.layer_taken[j] == 0:
                before = 0  # layers kept ahead of this one
                for i in range(j):
                    before += 1 - self.layer_taken[i]
                slot = ti.min(ti.max(self.state.active[None], 0), capacity) + before * sites + k
                if slot < capacity:
                    p = centre + (travelled - j * spacing) * direction + self.site_offsets[first_site + k]
                    self.state.x[slot] = p
                    self.state.v[slot] = velocity
                    self.state.reset_new(slot)  # every other field at its initial value, the index in creation order
        for _ in range(1):  # after every append has read the old count
            capacity = self.constants[None].capacity
            kept = 0
            for j in range(layers):
                kept += 1 - self.layer_taken[j]
            first = ti.min(ti.max(self.state.active[None], 0), capacity)
            self.state.active[None] = ti.min(first + kept * sites, capacity)

    def emit(self, now_s: float, pouring: bool = True) -> None:
        """Add the layers due by ``now_s`` (skipped when not ``pouring``: a nozzle resumes, never bursts)."""
        for k, emitter in enumerate(self.emitters):
            due = self.layers_due(emitter, now_s)
            if not pouring:
                self.emitted[k] = max(self.emitted[k], due)
            direction = emitter.unit_direction()
            velocity = tuple(emitter.speed_m_s * d for d in direction)
            for first in range(self.emitted[k], due, LAYERS_PER_LAUNCH):
                travelled = emitter.speed_m_s * (now_s - emitter.start_s) - first * self.spacing
                self._append_layers(
                    self.offsets[k],
                    len(self.sites[k]),
                    min(LAYERS_PER_LAUNCH, due - first),
                    emitter.position_m,
                    direction,
                    travelled,
                    velocity,
                )
            self.emitted[k] = max(self.emitted[k], due)
