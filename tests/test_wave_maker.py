"""The piston wave maker: where the wall stands, that water never gets behind it, and its checks."""

import math

import numpy as np
import pytest

from pbf import SceneError, Simulation
from pbf.scene import from_dict

STROKE, PERIOD = 0.04, 0.6


def tank(**extra):
    return {
        "name": "piston",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.6, 0.3, 0.1]},
        "fluid": {"spacing_m": 0.02, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.6, 0.12, 0.1]}]},
        "wave_maker": {"stroke_m": STROKE, "period_s": PERIOD},
        **extra,
    }


@pytest.mark.slow
def test_the_piston_pushes_the_water_and_nothing_gets_behind_it():
    sim = Simulation(tank())
    box = sim.boundaries.container
    assert box.piston_position_m(0.0) == 0.0
    assert box.piston_position_m(PERIOD / 2) == pytest.approx(STROKE)
    assert box.piston_position_m(PERIOD) == pytest.approx(0.0, abs=1e-12)
    radius = sim.scene.particle_radius_m
    for _ in range(9):  # 0.9 s: the piston goes in, back and in again
        sim.step(6)
        x, v = sim.positions(), sim.velocities()
        wall = box.piston_position_m(sim.time_s)
        assert x[:, 0].min() >= wall + 0.999 * radius
        assert np.isfinite(v).all()
    # While the piston moves in at its fastest (t = 0.75 T), the water next to it keeps up with it.
    sim.reset()
    sim.step(round(0.75 * PERIOD * 60))
    x, v = sim.positions(), sim.velocities()
    against = x[:, 0] < box.piston_position_m(sim.time_s) + 0.6 * 0.02
    piston_speed = math.pi * STROKE / PERIOD * math.sin(2 * math.pi * sim.time_s / PERIOD)
    assert against.sum() > 10
    assert np.median(v[against, 0]) == pytest.approx(piston_speed, rel=0.35)


def test_a_piston_that_cannot_work_is_refused():
    with pytest.raises(SceneError, match="'wave_maker.stroke_m' = 0.2 m is more than a quarter"):
        from_dict(tank(wave_maker={"stroke_m": 0.2, "period_s": 1.0}))
    in_the_way = tank(obstacles=[{"min_m": [0.05, 0.0, 0.0], "max_m": [0.1, 0.05, 0.05]}])
    in_the_way["fluid"]["blocks"][0]["min_m"] = [0.0, 0.06, 0.0]  # above the obstacle
    with pytest.raises(SceneError, match=r"'obstacles\[0\].min_m': the piston sweeps"):
        from_dict(in_the_way)
