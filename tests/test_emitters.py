"""Emitters: water enters at the rest spacing, within the budget allocated at the start, and a
restored snapshot replays the pour exactly."""

import dataclasses

import numpy as np
import pytest

from pbf import SceneError, Simulation
from pbf.scene import from_dict

SPACING = 0.02


def pour(**fluid):
    return {
        "name": "pour",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.4, 0.3]},
        "fluid": {"spacing_m": SPACING, **fluid},
        "emitters": [
            {
                "position_m": [0.15, 0.3, 0.15],
                "direction": [0.0, -1.0, 0.0],
                "radius_m": 0.03,
                "speed_m_s": 1.0,
                "start_s": 0.1,
                "end_s": 0.5,
            }
        ],
    }


def test_a_pour_fills_the_budget_at_the_rest_spacing_and_replays():
    sim = Simulation(pour())
    emitter = sim.scene.emitters[0]
    per_layer, layers = emitter.sites_per_layer(SPACING), emitter.layers(SPACING)
    assert (per_layer, layers) == (7, 21)  # a hexagon and its centre within 1.5 spacings; 0.4 s at 1 m/s: 20 spacings
    assert sim.model.capacity == per_layer * layers
    sim.step(5)  # to t = 0.083 s: before the start, an empty box with finite statistics
    assert sim.particle_count == 0 and np.isfinite(sim.stats()["mean_density_error"])
    sim.step(4)  # t = 0.15 s: 0.05 s of stream, layers 0-2 and the one due at the last substep's start
    count = sim.particle_count
    assert count % per_layer == 0 and 3 <= count // per_layer <= 4
    x = sim.positions()
    # The stream in the air: every particle's nearest neighbour a spacing away along the stream or the
    # nozzle's pitch across it (no overlap, no gap inside the nozzle's lattice).
    from pbf.scene.emitters import HEX_PITCH

    gaps = np.linalg.norm(x[:, None] - x[None], axis=2) + np.eye(count)
    assert (gaps.min(axis=1) > 0.98 * SPACING).all() and (gaps.min(axis=1) < 1.02 * HEX_PITCH * SPACING).all()
    snapshot = sim.snapshot()
    sim.step(30)
    assert sim.particle_count == sim.model.capacity  # all of it, and never more
    first = sim.positions()
    sim.restore(snapshot)
    sim.step(30)
    assert np.array_equal(sim.positions(), first)
    assert np.isfinite(first).all() and first[:, 1].min() > 0.0


@pytest.mark.parametrize(
    "change, message",
    [
        ({"max_particles": 100}, "'fluid.max_particles' = 100 is less than"),
    ],
)
def test_a_budget_too_small_is_refused(change, message):
    with pytest.raises(SceneError, match=message):
        from_dict(pour(**change))


@pytest.mark.parametrize(
    "emitter, message",
    [
        ({"end_s": 0.05}, "must be after start_s"),
        ({"direction": [0.0, 0.0, 0.0]}, "non-zero vector"),
        ({"radius_m": 0.005}, "less than half a spacing"),
        ({"position_m": [0.01, 0.3, 0.15]}, "must lie inside the container"),
    ],
)
def test_bad_emitters_are_refused(emitter, message):
    scene = pour()
    scene["emitters"][0].update(emitter)
    with pytest.raises(SceneError, match=message):
        from_dict(scene, "test.toml")


@pytest.mark.slow
def test_the_pour_stays_one_stream_down_to_the_pool():
    # Consecutive nozzle layers (creation order) that are still falling whole (every particle within
    # the nozzle's radius and a spacing of the layer's centre, above the pool) stand at most 1.5
    # spacings apart: the stream has no gap from the nozzle to the pool.
    sim = Simulation("pour", quiet=True)
    s, emitter = sim.scene.fluid.spacing_m, sim.scene.emitters[0]
    sites = emitter.sites_per_layer(s)
    for _ in range(2):
        sim.step(30)
        x = sim.positions()
        layers = x[: len(x) // sites * sites].reshape(-1, sites, 3)
        centre = layers.mean(axis=1)
        whole = np.linalg.norm(layers - centre[:, None], axis=2).max(axis=1) < emitter.radius_m + s
        falling = np.nonzero(whole & (centre[:, 1] > 5 * s))[0]
        assert len(falling) >= 10  # the stream is there
        pairs = [(a, b) for a, b in zip(falling[:-1], falling[1:]) if b == a + 1]
        distances = [np.linalg.norm(centre[b] - centre[a]) / s for a, b in pairs]
        assert len(pairs) >= len(falling) - 2 and max(distances) <= 1.5, max(distances)


@pytest.mark.parametrize("radius_spacings", [0.5, 1.5, 1.75, 3.0, 7.3])
def test_a_nozzles_sites_fill_a_disc_in_hexagonal_packing(radius_spacings):
    # A square lattice in a small nozzle is a square rod (pour's 3 × 3); hexagonal packing is the
    # roundest. Every site lies in the disc, in the plane across the stream; every site's nearest
    # neighbours are one pitch away, six of them inside the disc; a site stands for a spacing squared
    # of it, so the stream arrives at the rest density; and the count is the one the budget uses.
    from pbf.scene import load_scene
    from pbf.scene.emitters import HEX_PITCH
    from pbf.solver.emit import nozzle_sites

    s = 0.02
    scene = load_scene(pour())
    emitter = dataclasses.replace(scene.emitters[0], radius_m=radius_spacings * s, direction=(0.3, -1.0, 0.2))
    sites = nozzle_sites(emitter, s)
    assert len(sites) == emitter.sites_per_layer(s)
    direction = np.asarray(emitter.unit_direction())
    assert np.abs(sites @ direction).max() < 1e-9
    assert np.linalg.norm(sites, axis=1).max() <= emitter.radius_m * (1 + 1e-6)
    assert HEX_PITCH**2 * np.sqrt(3) / 2 == pytest.approx(1.0)  # a site's hexagon is s²
    if len(sites) > 1:
        gaps = np.linalg.norm(sites[:, None] - sites[None], axis=2) + np.eye(len(sites))
        assert gaps.min(axis=1) == pytest.approx(np.full(len(sites), HEX_PITCH * s))
        inner = np.linalg.norm(sites, axis=1) < emitter.radius_m - HEX_PITCH * s
        assert (np.sum(np.abs(gaps - HEX_PITCH * s) < 1e-9, axis=1)[inner] == 6).all()
    if radius_spacings > 3:  # a wide disc: its sites cover its area, a spacing squared each
        assert len(sites) == pytest.approx(np.pi * radius_spacings**2, rel=0.1)
    # Round: the sites' spread is the same in every direction across the stream.
    if len(sites) >= 7:
        spread = np.linalg.eigvalsh(sites.T @ sites)[1:]
        assert spread[1] == pytest.approx(spread[0], rel=1e-6)
