"""What a cold start compiles: the stages' tables and the state are filled in one launch each
(``pbf.solver.constants.array_loader``), not a compiled copy per field, and a scene without obstacles
fills none of theirs."""

import numpy as np
import pytest
import taichi as ti

from benchmarks.instruments import Observer, watching
from pbf import Simulation
from pbf.solver.constants import array_loader
from tests.scenes import small_dam_break


class Compiles(Observer):
    def __init__(self):
        self.kernels: list[str] = []

    def compiled(self, kernel: str, seconds: float) -> None:
        self.kernels.append(kernel)


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
