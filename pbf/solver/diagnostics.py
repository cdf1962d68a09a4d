"""Statistics of the current state, reduced inside a kernel (no Python loop over particles)."""
import taichi as ti

from pbf.solver.grid import NeighbourList
from pbf.solver.scan import BlockSum


@ti.data_oriented
class Diagnostics:
    """Reductions over the state, and the per-particle density ratio renderers colour by."""

    def __init__(self, state, density, grid, particle_mass_kg: float):
        self.state = state
        self.density = density
        self.grid = grid
        self.mass = particle_mass_kg
        self.terms = [ti.field(ti.f32, shape=state.capacity) for _ in range(3)]
        """max(ρ/ρ0 − 1, 0), |v|² and the neighbour count of each particle."""
        self.sums = BlockSum(state.capacity, 3)
        """Σ max(ρ/ρ0 − 1, 0), Σ |v|², Σ neighbours, the same bits on any thread count."""
        self.maxima = ti.field(ti.f32, shape=3)
        """max max(ρ/ρ0 − 1, 0), max |v|, max neighbours."""
        self.density_ratio = ti.field(ti.f32, shape=state.capacity)
        """ρ_i/ρ0 (wall density included) from :meth:`density_ratios`, in the state's sorted order."""

    @ti.kernel
    def _reduce(self, neighbours: NeighbourList):
        for k in ti.static(range(3)):
            self.maxima[k] = 0.0
        for i in range(self.state.active[None]):
            ratio = self.density.density_ratio(self.state.x, i, neighbours)
            error = ti.max(ratio - 1.0, 0.0)
            speed2 = self.state.v[i].norm_sqr()
            count = ti.cast(self.grid.neighbour_end[i] - self.grid.neighbour_start[i], ti.f32)
            self.terms[0][i], self.terms[1][i], self.terms[2][i] = error, speed2, count
            ti.atomic_max(self.maxima[0], error)  # a maximum is the same in any order
            ti.atomic_max(self.maxima[1], ti.sqrt(speed2))
            ti.atomic_max(self.maxima[2], count)
        for k in ti.static(range(3)):
            self.sums.sum(self.terms[k], k, self.state.active[None])

    @ti.kernel
    def _density_ratios(self, neighbours: NeighbourList):
        for i in range(self.state.active[None]):
            ratio = self.density.density_ratio(self.state.x, i, neighbours)
            self.density_ratio[i] = ratio

    def density_ratios(self, neighbours):
        """ρ/ρ0 of every particle at the current positions, with the last substep's neighbour lists;
        returns the field."""
        self._density_ratios(neighbours)
        return self.density_ratio

    @ti.kernel
    def _max_speed(self) -> ti.f32:
        fastest = 0.0
        for i in range(self.state.active[None]):
            ti.atomic_max(fastest, self.state.v[i].norm())
        return fastest

    def max_speed(self) -> float:
        """The largest particle speed, m/s (one reduction, no neighbour pass)."""
        return float(self._max_speed())

    def compute(self, neighbours) -> dict:
        """Density error (max(ρ/ρ0 − 1, 0), mean and max), speed, kinetic energy and neighbour counts.

        Densities use the neighbour lists of the last substep with the current positions, as the
        solver's final iteration did.
        """
        self._reduce(neighbours)
        sums, maxima = self.sums.total.to_numpy(), self.maxima.to_numpy()
        n = max(self.state.count, 1)  # an empty box (before an emitter starts) has zero means
        return {
            "mean_density_error": float(sums[0] / n),
            "max_density_error": float(maxima[0]),
            "max_speed_m_s": float(maxima[1]),
            "kinetic_energy_j": float(0.5 * self.mass * sums[1]),
            "mean_neighbours": float(sums[2] / n),
            "max_neighbours": int(maxima[2]),
        }
