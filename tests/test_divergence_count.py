"""The divergence pre-correction's iteration count is data, not unrolled code: every count in the key's
range, [0, 100], runs on the same compiled kernels (the first call runs the pass's first iterations,
calls of their own the rest), and more iterations leave the substep less compressed."""

import numpy as np
import pytest

from benchmarks.instruments import Observer, watching
from pbf import Simulation
from pbf.scene import SceneError, load_scene
from scenes import small_dam_break


class Compiles(Observer):
    """The kernels that compiled a new variant while watched."""

    def __init__(self):
        self.kernels: list[str] = []

    def compiled(self, kernel: str, seconds: float) -> None:
        self.kernels.append(kernel)


def test_every_count_in_the_range_runs_on_the_same_kernels_and_the_pass_converges():
    # The upper bound given as the scene's key (checked, then built).
    scene = small_dam_break(iterations=2)
    scene["solver"].update(target_density_error=0.0, divergence_iterations=100)
    with watching(Compiles()) as built:
        sim = Simulation(scene)
        sim.step(12)  # mid-splash: the pass has velocities to correct
    start = sim.snapshot()
    errors, velocities, compiled = {}, {}, {}
    for count in (100, 50, 2, 1, 0):
        sim.restore(start)
        sim.control.divergence_iterations = count
        with watching(Compiles()) as watched:
            sim.substep()
        errors[count] = sim.stats()["mean_density_error"]
        velocities[count] = sim.velocities()
        compiled[count] = [name for name in watched.kernels if "SubstepKernels" in name]
    # 100 compiled lines 1-7 with the pass and the calls of its further iterations; the others but 0
    # (the pass compiled out) run on them.
    assert "SubstepKernels._divergence_kernel" in built.kernels
    assert all(compiled[count] == [] for count in (100, 50, 2, 1)), compiled
    # The pass removes compression before the prediction, whatever its count.
    assert all(errors[count] < 0.95 * errors[0] for count in (100, 50, 2, 1)), errors
    # Every count is run (the last iterations still move v), and the Jacobi iterations converge: the
    # 50 after the 50th move v less than half as far as the second does.
    late, early = (np.abs(velocities[a] - velocities[b]).max() for a, b in ((100, 50), (2, 1)))
    assert 0.0 < late < 0.5 * early, (late, early)


def test_the_count_is_refused_outside_its_range():
    with pytest.raises(SceneError, match=r"solver\.divergence_iterations"):
        load_scene("dam_break", ["solver.divergence_iterations=101"])
