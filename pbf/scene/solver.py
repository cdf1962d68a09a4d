"""The solver's keys: iterations and their stopping, the model's features, the expert levers, XSPH
and vorticity confinement."""

from __future__ import annotations

from dataclasses import dataclass

from pbf.scene.schema import SceneError, _between, _num, _one_of, key

MAX_ITERATIONS = 100
"""Most Jacobi iterations a substep may run (solver.iterations): with substeps ≤ 1000, a bound on a
frame's cost."""
MIN_ITERATIONS = 2
"""solver.min_iterations's default; a scene with fewer solver.iterations runs them all (any other value
above solver.iterations is refused)."""
CHEBYSHEV_RHO = 0.9
"""solver.expert.chebyshev_rho's default, which only acceleration = "chebyshev" reads: any other value with
another acceleration is refused (it would do nothing)."""


@dataclass(frozen=True)
class Expert:
    """Levers of the method that no preset needs to set: each default won its A/B (docs/METHOD.md says
    why); they stay for studies that measure the alternatives (docs/BENCHMARKS.md)."""

    acceleration: str = key(
        "stable",
        _one_of("stable", "chebyshev", "none"),
        "weights of the Jacobi iterations' "
        "two-step acceleration: stable (none reverses an error mode enough to pump it), chebyshev "
        "(Wang 2015, with chebyshev_rho) or none (plain Jacobi); pbf.solver.acceleration",
    )
    chebyshev_rho: float = key(
        CHEBYSHEV_RHO, _between(0.0, 0.99), 'spectral radius ρ assumed by acceleration = "chebyshev"; 0: plain Jacobi'
    )
    step_back: bool = key(
        True,
        doc="when the target stops the iterations, take back the share of the last one it did "
        "not need (a count between two: a pool at rest holds still); false stops after whole "
        "iterations, below the target (cheaper error in a splash); only with a target",
    )
    relaxation: float = key(
        0.1,
        _between(1e-6, 100.0),
        "ε of Eq. (10) in the dimensionless form; it keeps λ finite for a particle with no neighbour (float32: ≥ 1e-6)",
    )
    wall_density: bool = key(
        True,
        doc="add the density of the ghost fluid behind walls; false lets particles "
        "stack against them (for comparison only)",
    )


@dataclass(frozen=True)
class Solver:
    iterations: int = key(
        10,
        _between(1, MAX_ITERATIONS),
        "Jacobi iterations of the density constraint per substep (the most, with target_density_error)",
    )
    min_iterations: int = key(
        MIN_ITERATIONS,
        _between(1, MAX_ITERATIONS),
        "Jacobi iterations every substep "
        "runs, whatever the error (one plain iteration alone leaves the shortest waves "
        "reversed: pbf.solver.acceleration)",
    )
    target_density_error: float = key(
        0.001,
        _between(0.0, 1.0),
        "stop iterating once the mean of max(ρ/ρ0 − 1, 0) "
        "is below this (and min_iterations ran); 0 always runs all iterations",
    )
    divergence_iterations: int = key(
        0,
        _between(0, 100),
        "Jacobi iterations of the divergence pre-correction "
        "(velocity level, before the prediction, warm-started from the last "
        "substep's) per substep; 0 switches it off",
    )
    kernel_ratio: float = key(2.2, _between(1.5, 4.0), "smoothing radius over spacing, h/s")
    scorr_k: float = key(
        0.03,
        _between(0.0, 1.0),
        "s_corr strength k (Eq. 11, with n = 8 and Δq = 0.2 h), dimensionless form, beside λ of order 1; 0 disables",
    )
    wall_mirror: bool = key(
        False,
        doc="the ghost fluid behind the container's walls is the mirror image of the "
        "fluid, moving with it, instead of a fixed lattice: particles at a wall carry the pressure "
        "of their neighbours, not twice it",
    )
    surface_density: bool = key(
        False,
        doc="add the density of ghost fluid beyond the free surface, placed by "
        "each particle's colour gradient (the surface layer sits a spacing high)",
    )
    expert: Expert = key(Expert())


@dataclass(frozen=True)
class Viscosity:
    xsph: float = key(0.01, _between(0.0, 1.0), "XSPH coefficient c (Eq. 15), dimensionless; 0 disables")


@dataclass(frozen=True)
class Vorticity:
    epsilon: float = key(
        0.0,
        _between(0.0, 1.0),
        "vorticity confinement ε (Eqs. 13-14), dimensionless, an "
        "acceleration ε h |ω|² that beyond 1 outgrows the vortex it restores; 0 disables",
    )


def _check_solver(scene, source: str) -> None:
    """The iteration counts must leave room between the least and the most; ρ only goes with Chebyshev
    weights and the step back with a target; a mirrored wall needs a wall."""
    s, expert = scene.solver, scene.solver.expert
    if s.min_iterations > s.iterations and s.min_iterations != MIN_ITERATIONS:
        raise SceneError(
            f"{source}: key 'solver.min_iterations' = {s.min_iterations} is more than solver.iterations = "
            f"{s.iterations}, the most a substep runs; allowed: 1 to {s.iterations}"
        )
    if expert.acceleration != "chebyshev" and expert.chebyshev_rho != CHEBYSHEV_RHO:
        raise SceneError(
            f"{source}: key 'solver.expert.chebyshev_rho' = {_num(expert.chebyshev_rho)} sets the ρ of "
            f'Chebyshev weights, but solver.expert.acceleration = "{expert.acceleration}" does not use '
            f'them; allowed: solver.expert.acceleration = "chebyshev", or no solver.expert.chebyshev_rho'
        )
    if not expert.step_back and s.target_density_error == 0.0:
        raise SceneError(
            f"{source}: key 'solver.expert.step_back' = false changes where the error target stops the "
            f"iterations, but solver.target_density_error = 0 runs them all; allowed: true, or a "
            f"target above 0"
        )
    if s.wall_mirror and not expert.wall_density:
        raise SceneError(
            f"{source}: key 'solver.wall_mirror' = true mirrors the ghost fluid behind the walls, but "
            f"solver.expert.wall_density = false leaves none; allowed: false, or "
            f"solver.expert.wall_density = true"
        )
