"""Statistics of the current state: sums by tree reductions (``pbf.solver.scan``), maxima by atomics, the same
bits on any thread count."""

import taichi as ti

from pbf.solver import backend
from pbf.solver.backend import Choices
from pbf.solver.grid import MOST_ENTRIES, TRUNCATED, NeighbourList
from pbf.solver.scan import TreeSum


@ti.data_oriented
class Diagnostics:
    """Reductions over the state, and the per-particle density ratio renderers colour by."""

    def __init__(self, state, density, grid, particle_mass_kg: float, choices: Choices):
        self.state = state
        self.density = density
        self.grid = grid
        self.mass = particle_mass_kg
        self.terms = [ti.field(ti.f32, shape=state.capacity) for _ in range(3)]  # max(ρ/ρ0 − 1, 0), |v|², neighbours
        self.sums = TreeSum(state.capacity, 3, shared=choices.shared_memory, gpu=choices.gpu_blocks)
        self.maxima = ti.field(ti.f32, shape=3)
        """The terms' maxima (|v| for |v|²) by atomic max: exact in any order, so the same bits on any thread
        count without a tree (whose code would double the reduction's compile). 0 between kernels: each
        kernel that takes them clears them as it reads them, in its last, one-thread statements."""
        self.density_ratio = ti.field(ti.f32, shape=state.capacity)
        """ρ_i/ρ0 (wall density included) from :meth:`density_ratios`, in the state's sorted order."""

    @ti.kernel
    def _reduce(self, neighbours: NeighbourList) -> ti.types.vector(9, ti.f32):
        for i in range(self.state.live_bound()):  # the bucket on a GPU: no one-thread task for a bound
            if i < self.state.active[None]:
                ratio = self.density.density_ratio(self.state.x, i, neighbours)
                speed2 = self.state.v[i].norm_sqr()
                error, listed = ti.max(ratio - 1.0, 0.0), ti.cast(self.grid.neighbour_listed[i], ti.f32)
                self.terms[0][i], self.terms[1][i], self.terms[2][i] = error, speed2, listed
                ti.atomic_max(self.maxima[0], error)
                ti.atomic_max(self.maxima[1], ti.sqrt(speed2))
                ti.atomic_max(self.maxima[2], listed)
        for k in ti.static(range(3)):
            self.sums.sum(self.terms[k], k, self.state.active)
        # Returned, not read with to_numpy: a copy out compiles a kernel of its own for each field.
        sums = [self.sums.high[k] for k in ti.static(range(3))] + [self.sums.low[k] for k in ti.static(range(3))]
        values = ti.Vector(sums + [self._take_maximum(k) for k in ti.static(range(3))])
        return values

    @ti.kernel
    def _density_ratios(self, neighbours: NeighbourList):
        for i in range(self.state.live_bound()):
            if i < self.state.active[None]:
                self.density_ratio[i] = self.density.density_ratio(self.state.x, i, neighbours)

    def density_ratios(self, neighbours):
        """The field of ρ/ρ0 at the current positions, with the last substep's neighbour lists."""
        with backend.light_compile():  # as in compute
            self._density_ratios(neighbours)
        return self.density_ratio

    @ti.kernel
    def _frame_read(self, bodies: ti.template()) -> tuple[ti.f32, ti.i32, ti.i32, ti.f32]:
        for i in range(self.state.live_bound()):
            if i < self.state.active[None]:
                ti.atomic_max(self.maxima[1], self.state.v[i].norm())
        solids = 0.0
        if ti.static(hasattr(bodies, "fastest")):  # None when the scene has no bodies
            solids = bodies.fastest[None]
        fastest = self._take_maximum(1)
        return fastest, self.grid.status[MOST_ENTRIES], self.grid.status[TRUNCATED], solids

    @ti.func
    def _take_maximum(self, k: ti.template()):
        """Maximum k, cleared for the next kernel's atomics (:attr:`maxima`)."""
        value = self.maxima[k]
        self.maxima[k] = 0.0
        return value

    def frame_read(self, bodies=None) -> tuple[float, float, int, bool]:
        """A frame's one read: the fastest particle and body point (m/s) for the CFL limit, and the grid's
        record since its lists last grew (``NeighbourGrid.settle_frame``'s arguments)."""
        speed, most_entries, truncated, solids = self._frame_read(bodies)
        return float(speed), float(solids), int(most_entries), bool(truncated)

    def compute(self, neighbours) -> dict:
        """Density error (max(ρ/ρ0 − 1, 0), mean and max), speed, kinetic energy and neighbour counts."""
        # Without Taichi's advanced IR optimisation: a density sum with every boundary's ghost inlined
        # compiles much faster, and runs once a frame in the same time with the same bits (measured:
        # docs/BENCHMARKS.md, "Start-up: cold and warm").
        with backend.light_compile():
            values = self._reduce(neighbours)
        sums = [float(values[k]) + float(values[3 + k]) for k in range(3)]
        n = max(self.state.count, 1)  # an empty box (before an emitter starts) has zero means
        return {
            "mean_density_error": sums[0] / n,
            "max_density_error": float(values[6]),
            "max_speed_m_s": float(values[7]),
            "kinetic_energy_j": 0.5 * self.mass * sums[1],
            "mean_neighbours": sums[2] / n,
            "max_neighbours": int(values[8]),
        }
