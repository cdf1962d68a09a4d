"""What a start compiles. The divergence pre-correction's iteration count is data, not unrolled code:
every count in the key's range, [0, 100], runs on the same compiled kernels (the first call runs the
pass's first iterations, calls of their own the rest). The stages' tables and the state are filled in
one launch each (``pbf.solver.constants.array_loader``), not a compiled copy per field, and a scene
without obstacles fills none of theirs."""

import numpy as np
import pytest
import taichi as ti

from benchmarks.instruments import Observer, watching
from pbf import Simulation
from pbf.scene import SceneError, load_scene
from pbf.solver.constants import array_loader
from tests.scenes import small_dam_break


class Compiles(Observer):
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


def test_the_loader_fills_every_kind_of_field_exactly_and_again():
    fields = (
        ti.field(ti.f32, shape=5),
        ti.Vector.field(2, ti.f32, shape=(3, 4)),
        ti.field(ti.i32, shape=(2, 3, 2)),
        ti.Vector.field(3, ti.i32, shape=6),
    )
    rng = np.random.default_rng(1)
    load = array_loader(fields)
    with watching(Compiles()) as watched:
        for _ in range(2):  # a second load replaces the first, on the same compiled kernel
            arrays = (
                rng.standard_normal(5).astype(np.float32),
                rng.standard_normal((3, 4, 2)).astype(np.float32),
                rng.integers(-9, 9, (2, 3, 2)).astype(np.int32),
                rng.integers(-9, 9, (6, 3)).astype(np.int32),
            )
            load(arrays)
            for field, values in zip(fields, arrays):
                np.testing.assert_array_equal(field.to_numpy(), values)
    assert watched.kernels.count("array_loader.<locals>.load") == 1, watched.kernels
    with pytest.raises(ValueError, match=r"expected an array of shape \(5,\), got \(4,\)"):
        load((np.zeros(4), *arrays[1:]))


def loads_compiled(scene) -> list[str]:
    with watching(Compiles()) as watched:
        Simulation(scene)
    return [name for name in watched.kernels if "ext_arr_to" in name or "array_loader" in name]


def test_a_start_fills_its_tables_in_one_launch_each_and_no_obstacles_where_there_are_none():
    # The ghost tables, the state, the iterations' weights; with an obstacle its four arrays too.
    assert len(loads_compiled(small_dam_break())) == 3
    scene = small_dam_break()
    scene["obstacles"] = [{"min_m": [0.5, 0.0, 0.1], "max_m": [0.6, 0.2, 0.3]}]
    assert len(loads_compiled(scene)) == 4
