"""Static box obstacles: exact ghost density at faces, edges and corners; no particle ever inside."""

import numpy as np
import pytest

from pbf import SceneError, Simulation, load_scene
from pbf.scene import from_dict

SPACING = 0.025


def block_on_obstacle(**extra):
    """A block of water resting on top of an obstacle of the same footprint, gravity off."""
    return {
        "name": "block_on_obstacle",
        "gravity_m_s2": [0.0, 0.0, 0.0],
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.4, 0.6, 0.4]},
        "fluid": {"spacing_m": SPACING, "blocks": [{"min_m": [0.1, 0.2, 0.1], "max_m": [0.3, 0.4, 0.3]}]},
        "obstacles": [{"min_m": [0.1, 0.0, 0.1], "max_m": [0.3, 0.2, 0.3]}],
        **extra,
    }


def test_water_on_an_obstacle_sees_the_ghost_lattice_at_faces_edges_and_corners():
    # The bottom layer rests on the obstacle's top face, its outer rows on the obstacle's convex edges
    # and corners. With the ghost lattice inside the obstacle, each bottom particle must see the same
    # density as the particle four layers up (which has full neighbourhoods above and below); without
    # it, the bottom layer reads 46% light and would be pulled into the obstacle.
    sim = Simulation(block_on_obstacle())
    ratio = sim.density_ratios().to_numpy()
    x = sim.readout().positions.to_numpy()
    column = {(round(p[0] / SPACING), round(p[2] / SPACING)): [] for p in x}
    for p, r in zip(x, ratio):
        column[round(p[0] / SPACING), round(p[2] / SPACING)].append((p[1], r))
    for layers in column.values():
        layers.sort()
        assert layers[0][1] == pytest.approx(layers[4][1], abs=2e-4)
    assert sim.stats()["max_density_error"] < 1e-3


def test_dam_break_around_an_obstacle_stays_out_of_it():
    # The preset at double spacing (fewer particles, the same geometry): the surge hits the box,
    # climbs it and wraps around its edges; no particle may ever be inside the box grown by a radius.
    scene = load_scene("dam_break_obstacle", ["fluid.spacing_m=0.02"])
    sim = Simulation(scene)
    lower = np.array(scene.obstacles[0].min_m) - 0.999 * scene.particle_radius_m
    upper = np.array(scene.obstacles[0].max_m) + 0.999 * scene.particle_radius_m
    c_lo, c_hi = np.array(scene.container.min_m), np.array(scene.container.max_m)
    reached = 0.0
    for _ in range(12):  # 1.2 s: the surge reaches the box at about 0.35 s and runs up the far wall
        sim.step(6)
        x = sim.positions()
        assert np.isfinite(x).all()
        inside = np.all((x > lower) & (x < upper), axis=1)
        assert not inside.any(), f"{inside.sum()} particles inside the obstacle at t = {sim.time_s:.2f} s"
        assert (x >= c_lo).all() and (x <= c_hi).all()
        reached = max(reached, x[:, 0].max())
    assert reached > upper[0]  # the water did get past the obstacle
    assert sim.stats()["max_speed_m_s"] < 5.0


@pytest.mark.parametrize(
    "obstacle, message",
    [
        ({"min_m": [0.1, 0.0, 0.1], "max_m": [0.3, 0.04, 0.3]}, "at least 2 spacings"),
        ({"min_m": [0.1, 0.0, 0.1], "max_m": [0.3, 0.2, 0.5]}, "lies outside the container"),
        ({"min_m": [0.1, 0.0, 0.1], "max_m": [0.3, 0.25, 0.3]}, "overlaps fluid.blocks[0]"),
    ],
)
def test_bad_obstacles_are_refused(obstacle, message):
    with pytest.raises(SceneError) as error:
        from_dict(block_on_obstacle(obstacles=[obstacle]), "test.toml")
    assert str(error.value).startswith("test.toml: key 'obstacles[0]")
    assert message in str(error.value)


def test_obstacles_need_a_small_cfl():
    with pytest.raises(SceneError, match="time.max_cfl"):
        from_dict(block_on_obstacle(time={"max_cfl": 3.0}))
