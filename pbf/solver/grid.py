"""Uniform grid and exact neighbour lists, rebuilt every substep by counting sorts (Algorithm 1, lines 5-7).

1. count the particles in each cell (cells ≥ h / reach wide), each with a rank inside its cell;
2. exclusive prefix sum of the counts → the first slot of every cell;
3. the permutation that sorts particles by cell, ties inside a cell broken by a key (the creation
   index), which the caller applies to its arrays (gathered in the same loop);
4. visit the cells within ``reach`` of each particle's own, writing its neighbours within h into its
   SLOTS entries and counting them all. If some particle has more, the counts are prefix-summed into a
   compact list, filled by a second visit in the same launch. Nothing is dropped: the host learns once
   a frame how full the compact list got (``settle_frame``) and grows it ahead of need.

docs/METHOD.md, "Grid and neighbour lists", says why.
"""

import collections
import functools
import math
import warnings

import numpy as np
import taichi as ti

from pbf.solver.backend import Choices
from pbf.solver.constants import scene_constants
from pbf.solver.model import GridParams
from pbf.solver.scan import ExclusiveScan, read_count

SLOTS = 64
"""Neighbours stored per particle by the first visit: about twice the typical count at h = 2.2 s."""
MOST_ENTRIES, TRUNCATED = range(2)
"""Entries of ``NeighbourGrid.status``."""
GROW_ABOVE = 0.75
"""The compact list is grown by half once a frame's longest need passed this share of it (``settle_frame``)."""
NeighbourList = ti.types.ndarray(dtype=ti.i32, ndim=1)
"""The kernel argument type of :attr:`NeighbourGrid.neighbours` (an ndarray, so that growing it after
an overflow recompiles nothing)."""


def named(**values):
    """Taichi values by name, for a walk's task (:meth:`NeighbourGrid.for_each_neighbour`) or a kernel's
    arguments handed to its stages. Made inside ``ti.static`` (``p = ti.static(named(xi=xi, sums=sums))``)
    the variables stay themselves, not copies: a task's ``p.sums += …`` adds to the caller's ``sums``."""
    return _named_type(tuple(values))(**values)


@functools.cache
def _named_type(names: tuple[str, ...]):
    return collections.namedtuple("Named", names)


@ti.data_oriented
class NeighbourGrid:
    """The uniform grid and exact neighbour lists of the module docstring; ``choices`` (``slot_major``,
    ``gpu_blocks``) and ``loop_bound`` are the backend's, chosen by the Simulation."""

    def __init__(self, params: GridParams, active, choices: Choices, loop_bound):
        particle_count, resolution, reach = params.particle_count, params.resolution, params.reach
        allocated = params.allocated_particles or particle_count
        self.particle_count = particle_count
        self.active = active
        extent = np.asarray(params.upper_m, dtype=np.float64) - np.asarray(params.lower_m, dtype=np.float64)
        self.reach = reach
        """Cells per h: every neighbour within h lies within ``reach`` cells of a particle's own."""
        # Cells are at least h / reach wide (a 1e-4 margin keeps float32 rounding from making them
        # narrower), so every neighbour within h lies within reach cells along each axis.
        assert all(e / r * reach >= params.kernel_radius_m * (1 + 1e-5) or r == 1 for e, r in zip(extent, resolution))
        self.constants = scene_constants(
            kernel_radius=params.kernel_radius_m,
            lower=tuple(params.lower_m),
            resolution=tuple(int(r) for r in resolution),
            inverse_cell_size=tuple(float(r / e) for r, e in zip(resolution, extent)),
        )
        cell_count = params.allocated_cells
        particle_count = allocated
        self.cell_particles = ti.field(ti.i32, shape=cell_count)
        self.cell_start = ti.field(ti.i32, shape=cell_count + 1)
        self.cell_scan = ExclusiveScan(cell_count, gpu=choices.gpu_blocks)
        self.particle_cell = ti.field(ti.i32, shape=particle_count)
        self.rank_in_cell = ti.field(ti.i32, shape=particle_count)
        self.cell_members = ti.field(ti.i32, shape=particle_count)
        """The particles by cell in the atomic counter's order, which changes from run to run (step 3)."""
        self.sorted_from = ti.field(ti.i32, shape=particle_count)
        """sorted_from[slot] = index, before sorting, of the particle that moves to ``slot``."""
        self.neighbour_count = ti.field(ti.i32, shape=particle_count)
        self.neighbour_start = ti.field(ti.i32, shape=particle_count + 1)
        self.neighbour_listed = ti.field(ti.i32, shape=particle_count)
        """Entries of particle i's neighbours in the list (``neighbour_count`` unless cut at the list's end)."""
        self.overflow = ti.field(ti.i32, shape=())
        """1 when the last visit found a particle with more than SLOTS neighbours."""
        self.status = ti.field(ti.i32, shape=2)
        """What the builds saw since the list last grew (:meth:`settle_frame`)."""
        self.loop_bound = loop_bound
        """What loops over the live particles run to (``State.loop_bound``); the first ``active[None]`` are live."""
        self.slot_major = choices.slot_major
        """The one-visit list's layout: on a GPU slot-major (entry i + k·n: a warp walking its lists in step
        reads one contiguous run per k), on the CPU particle-major (entry i·SLOTS + k: one stretch a thread)."""
        self.neighbour_scan = ExclusiveScan(particle_count, gpu=choices.gpu_blocks)
        self.neighbours = ti.ndarray(ti.i32, shape=SLOTS * self.particle_count)
        """Flat neighbour list: the neighbours of sorted particle i, itself excluded, are the
        ``neighbour_listed[i]`` entries of :meth:`listed` and :meth:`neighbour`."""

    @ti.func
    def cell_of(self, p):
        """Integer cell coordinates of position p, clamped to the grid (monotone, so exactness holds)."""
        c = ti.cast(ti.floor((p - self.constants[None].lower) * self.constants[None].inverse_cell_size), ti.i32)
        return ti.max(0, ti.min(c, self.constants[None].resolution - 1))

    @ti.func
    def linear(self, c):
        # z fastest: the three cells (x, y, z-1..z+1) are one contiguous slot range after sorting.
        resolution = self.constants[None].resolution
        return (c[0] * resolution[1] + c[1]) * resolution[2] + c[2]

    @ti.kernel
    def sort(self, x: ti.template(), key: ti.template()):
        """Counting sort by cell of positions ``x`` (steps 1-3), ties by ``key``, into :attr:`sorted_from`;
        the caller reorders (for the grid's tests; the substep sorts inside its first kernel)."""
        for i in range(read_count(self.loop_bound, 1)):
            self.clear_for_visit(i)
            if i < self.active[None]:
                self.count_in_cell(x[i], i)
        self.order_loops(key, ())  # nothing carried: the caller reorders its own arrays

    @ti.func
    def clear_for_visit(self, i):
        """Thread i of the loop before a visit clears what the visit gathers: the overflow flag and i's
        block sum of the overflow's prefix sum (no task of its own)."""
        if i == 0:
            self.overflow[None] = 0
        self.neighbour_scan.clear_block(i)

    @ti.func
    def count_in_cell(self, p, i):
        """Step 1 for particle i at position p: its cell, and a rank among the cell's particles counted so far."""
        cell = self.linear(self.cell_of(p))
        self.particle_cell[i] = cell
        self.rank_in_cell[i] = ti.atomic_add(self.cell_particles[cell], 1)
        self.cell_scan.add_to_block(cell, 1)  # the scan's first pass up, done here

    @ti.func
    def order_loops(self, key: ti.template(), carried: ti.template()):
        """Steps 2-3 once every particle is counted (:meth:`count_in_cell`), for the top level of a kernel:
        :attr:`sorted_from`, and each (field, scratch) pair of ``carried`` (``State.carried``) copied from
        particle i into its sorted slot of the scratch. The atomic
        counter's ranks change from run to run, so a particle's place in its cell is its rank by ``key``
        (its slot before the sort breaks a tie): runs replay bit for bit."""
        # Over the allocated cells (their bucket, a count the kernel knows); those past the grid's are empty.
        self.cell_scan.scan(self.cell_particles, self.cell_start, self.cell_scan.length, True)
        for i in range(read_count(self.loop_bound, 1)):
            if i < self.active[None]:
                cell = self.particle_cell[i]
                self.cell_members[self.cell_start[cell] + self.rank_in_cell[i]] = i
                # Cleared for the next sort here, once the scan has read them: a loop of its own is a launch.
                self.cell_particles[cell] = 0
                self.cell_scan.clear_block(cell)
        for slot in range(read_count(self.loop_bound, 1)):
            if slot < self.active[None]:
                i = self.cell_members[slot]
                cell = self.particle_cell[i]
                begin, end = self.cell_start[cell], self.cell_start[cell + 1]
                key_i = key[i]
                place = begin
                for m in range(begin, end):
                    other = self.cell_members[m]
                    key_other = key[other]
                    place += ti.select(key_other < key_i or (key_other == key_i and other < i), 1, 0)
                self.sorted_from[place] = i
                for k in ti.static(range(len(carried))):
                    carried[k][1][place] = carried[k][0][i]

    @ti.func
    def column_range(self, c, resolution, dx, dy):
        """Slots of the cells (c.x+dx, c.y+dy, c.z-reach..c.z+reach): contiguous, as z varies fastest."""
        begin, end = 0, 0
        cx, cy = c[0] + dx, c[1] + dy
        if 0 <= cx < resolution[0] and 0 <= cy < resolution[1]:
            z0 = ti.max(c[2] - self.reach, 0)
            z1 = ti.min(c[2] + self.reach, resolution[2] - 1)
            row = (cx * resolution[1] + cy) * resolution[2]
            begin = self.cell_start[row + z0]
            end = self.cell_start[row + z1 + 1]
        return begin, end

    @ti.func
    def listed(self, i, neighbours: ti.template()):
        """(first, last, stride) of particle i's neighbours in ``neighbours``: slot-major after a one-visit
        build on a GPU (:attr:`slot_major`), in a row after an overflow's compact build and on the CPU."""
        first = self.neighbour_start[i]
        _start, slot_stride = self.slots_of(i, neighbours.shape[0])
        stride = ti.select(self.overflow[None] > 0, 1, slot_stride)
        return first, first + self.neighbour_listed[i], stride

    @ti.func
    def slots_of(self, i, capacity):
        """(first entry, stride) of particle i's SLOTS entries in a one-visit list of ``capacity`` entries:
        entry i + k·(capacity / SLOTS) slot-major, i·SLOTS + k in a row (:attr:`slot_major`)."""
        start, stride = i * SLOTS, 1
        if ti.static(self.slot_major):
            start, stride = i, capacity // SLOTS
        return start, stride

    @ti.func
    def for_each_neighbour(self, i, entries: ti.template(), task: ti.template(), acc: ti.template()):
        """``task(i, j, acc)`` for every neighbour j of sorted particle i in ``entries`` (:attr:`neighbours`,
        a ``NeighbourList`` argument), in the list's order; ``acc`` (a vector or :func:`named` values) is
        passed by reference. The one walk of the lists: every pass of the solver and the renderers' sums.
        Slot-major (a GPU) it reads the next entry before the task gathers x_j, so the dependent load is
        in flight meanwhile; in a row (the CPU) the cores read ahead themselves."""
        first, last, stride = self.listed(i, entries)
        if ti.static(self.slot_major):
            upcoming = 0
            if first < last:
                upcoming = entries[first]
            for k in range(first, last):
                j = upcoming
                if k + 1 < last:
                    upcoming = entries[first + (k + 1 - first) * stride]
                task(i, j, acc)
        else:
            for k in range(first, last):
                task(i, entries[k], acc)

    @ti.func
    def _visit_particle(self, x: ti.template(), neighbours: ti.template(), compact: ti.template(), i):
        """Find the neighbours of particle i: into its SLOTS entries (first visit) or, when ``compact``,
        into the prefix-summed row neighbour_start[i] (second visit, only after an overflow), never past
        the list's end. A particle with more than SLOTS sets ``overflow`` (a plain store of 1)."""
        capacity = neighbours.shape[0]
        kernel_radius, resolution = self.constants[None].kernel_radius, self.constants[None].resolution
        h2 = kernel_radius * kernel_radius
        xi = x[i]
        c = self.cell_of(xi)
        start, stride = self.slots_of(i, capacity)
        room = SLOTS
        if ti.static(compact):
            start = ti.min(self.neighbour_start[i], capacity)
            stride = 1
            room = ti.min(self.neighbour_start[i] + self.neighbour_count[i], capacity) - start
        found = 0
        # Runtime loops over the columns, not unrolled: the unrolled copies of the walk took seconds to
        # compile in every kernel that visits, and ran slower on the CPU.
        for dx in range(-self.reach, self.reach + 1):
            for dy in range(-self.reach, self.reach + 1):
                first, last = self.column_range(c, resolution, dx, dy)
                for j in range(first, last):
                    xj = x[j]
                    if ti.static(self.slot_major):
                        # A GPU thread stores only neighbours: each store skipped is a scattered write
                        # saved (the candidates are 3-6 times the neighbours).
                        if j != i and (xj - xi).norm_sqr() < h2:
                            if found < room:
                                neighbours[start + found * stride] = j
                            found += 1
                    else:
                        # Branch-free on the CPU (a branch on the distance mispredicts): write every
                        # candidate to the next free entry, advance only past neighbours.
                        if found < room:
                            neighbours[start + found] = j
                        found += ti.select(j != i and (xj - xi).norm_sqr() < h2, 1, 0)
        if ti.static(not compact):  # the second visit finds the same count, which others may be reading
            self.neighbour_count[i] = found
            self.neighbour_start[i] = start
            if found > SLOTS:
                self.overflow[None] = 1
        self.neighbour_listed[i] = ti.min(found, room)

    @ti.func
    def find_neighbours(
        self, gathered: ti.template(), x: ti.template(), neighbours: ti.template(), carried: ti.template()
    ):
        """Step 4 over the live particles, both visits, for the top level of a kernel whose loop before
        cleared what they gather (:meth:`clear_for_visit`). The first visit takes every field of ``carried``
        back from its scratch (:meth:`order_loops`); ``gathered``: x's scratch there, or ``x``. The second
        visit runs only after an overflow, each thread finding its start itself (``ExclusiveScan.start_of``);
        a compact list longer than the array is cut at its end and ``status`` says so, for :meth:`settle_frame`."""
        for i in range(read_count(self.loop_bound, 1)):
            if i < self.active[None]:
                for k in ti.static(range(len(carried))):
                    carried[k][0][i] = carried[k][1][i]
                self._visit_particle(gathered, neighbours, False, i)
                self.neighbour_scan.add_to_block(i, self.neighbour_count[i])
        self.neighbour_scan.up(self.neighbour_count, self.active, self.overflow, True)
        for i in range(ti.static(self.particle_cell.shape[0])):
            count = self.active[None]
            if i < count * self.overflow[None]:
                start = self.neighbour_scan.start_of(self.neighbour_count, i)
                self.neighbour_start[i] = start
                self._visit_particle(x, neighbours, True, i)
                if i == count - 1:  # the last particle's list ends where the compact list does
                    total = start + self.neighbour_count[i]
                    self.status[MOST_ENTRIES] = ti.max(self.status[MOST_ENTRIES], total)
                    if total > neighbours.shape[0]:
                        self.status[TRUNCATED] = 1

    @ti.kernel
    def _build(self, x: ti.template(), neighbours: NeighbourList):
        for i in range(read_count(self.loop_bound, 1)):
            self.clear_for_visit(i)
        self.find_neighbours(x, x, neighbours, ())

    def build(self, x) -> None:
        """Neighbour lists (|x_i − x_j| < h, i ≠ j) of positions ``x`` sorted by cell (:meth:`sort`), as the
        substep builds them: exact unless the compact list outgrew its array (:attr:`status` says)."""
        self._build(x, self.neighbours)

    def build_neighbours(self, x) -> None:
        """:meth:`build`, made again in a longer array if the compact list did not fit (tests and tools)."""
        self.build_fitting(lambda: self.build(x))

    def build_fitting(self, build) -> None:
        """``build()``, a build of the lists, made again in a longer array if the compact list did not fit;
        the record of :attr:`status` starts afresh."""
        build()
        most_entries, truncated = (int(v) for v in self.status.to_numpy())
        if truncated:
            self.settle_frame(most_entries, False)
            build()
        self.status.fill(0)

    def settle_frame(self, most_entries: int, truncated: bool) -> None:
        """Act on the record of :attr:`status` (``Diagnostics.frame_read``): a compact list over GROW_ABOVE of
        the array is grown by half, and the record starts again; one cut short too, with a warning (that
        substep missed pairs)."""
        most_entries = int(most_entries)
        if truncated or most_entries > GROW_ABOVE * self.neighbours.shape[0]:
            self.neighbours = ti.ndarray(ti.i32, shape=int(math.ceil(max(most_entries, 1) * 1.5)))
            self.status.fill(0)
        if truncated:
            warnings.warn(
                f"the neighbour list needed {most_entries:,} entries, more than the {SLOTS} per particle "
                f"it held; a substep of the last frame missed neighbours. Grown: exact from here on",
                RuntimeWarning,
                stacklevel=3,
            )

    def neighbour_lists(self):
        """Neighbour lists as a list of NumPy arrays of sorted indices (for tests and inspection)."""
        start, listed = self.neighbour_start.to_numpy(), self.neighbour_listed.to_numpy()
        flat = self.neighbours.to_numpy()
        stride = len(flat) // SLOTS if self.slot_major and not self.overflow[None] else 1
        return [flat[start[i] + stride * np.arange(listed[i])] for i in range(int(self.active[None]))]
