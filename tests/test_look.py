"""How the surface style reads (``python -m pbf.study.frames look``): each particle's splat is an
ellipsoid from its neighbours (flat at a surface, a sphere in the bulk, a drop alone), a settled pool is
one flat surface and a splash is not speckled. The figures are the study's own measures, on small
scenes; the renderer of spheres before the anisotropic splats failed both (docs/RENDERING.md)."""

import numpy as np
import pytest

from pbf.app.fluid_render import SPLAT_RADIUS_SPACINGS
from pbf.app.render import SceneRenderer
from pbf.app.splat import DROP_RADIUS_SPACINGS, Ellipsoids
from pbf.solver import Simulation
from pbf.study.frames import particles_top, speckle, top_face
from scenes import column_scene, small_dam_break

SIZE = (480, 270)


def semi_axes(inverse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The semi-axes' lengths (ascending) and unit directions (columns) of the ellipsoid |G x| ≤ 1."""
    lengths, directions = np.linalg.eigh(np.linalg.inv(inverse.T @ inverse))
    return np.sqrt(lengths), directions


def test_splats_are_flat_at_the_surface_round_in_the_bulk_and_drops_alone():
    sim = Simulation(column_scene(), quiet=True)  # a lattice at rest, its neighbour lists built
    s = sim.scene.fluid.spacing_m
    hood = sim.neighbourhood()
    splats = Ellipsoids(hood.positions.shape[0], SPLAT_RADIUS_SPACINGS * s, s)
    splats.update(hood.positions, hood.count, hood)
    x = sim.positions()
    inverse, centre = splats.inverse.to_numpy()[: hood.count], splats.centre.to_numpy()[: hood.count]
    reach = splats.reach.to_numpy()[: hood.count]
    top, middle = x[:, 1].max(), np.median(np.unique(x[:, 1]))
    lower, upper = np.asarray(sim.scene.container.min_m), np.asarray(sim.scene.container.max_m)
    away = np.all((x[:, [0, 2]] > lower[[0, 2]] + 3 * s) & (x[:, [0, 2]] < upper[[0, 2]] - 3 * s), axis=1)
    for i in np.nonzero(away & np.isclose(x[:, 1], top))[0][:20]:
        lengths, directions = semi_axes(inverse[i])
        assert lengths[0] < 0.5 * lengths[2]  # a disc ...
        assert abs(directions[1, 0]) > 0.99  # ... whose short axis is vertical
        assert np.prod(lengths) == pytest.approx((SPLAT_RADIUS_SPACINGS * s) ** 3, rel=1e-3)  # the sphere's volume
        assert centre[i, 1] < x[i, 1]  # smoothed toward the water below
    for i in np.nonzero(away & np.isclose(x[:, 1], middle))[0][:20]:
        lengths, _ = semi_axes(inverse[i])
        assert lengths == pytest.approx(np.full(3, SPLAT_RADIUS_SPACINGS * s), rel=1e-3)
        assert reach[i] == pytest.approx(SPLAT_RADIUS_SPACINGS * s, rel=1e-3)
        assert centre[i] == pytest.approx(x[i], abs=1e-6)
    # Without neighbours (lists of particles far apart), every splat is a drop of a particle's volume.
    lone = Simulation(
        {
            "name": "drops",
            "container": {"max_m": [1.0, 1.0, 1.0]},
            "fluid": {"spacing_m": s, "blocks": [{"min_m": [0.4, 0.4, 0.4], "max_m": [0.4 + s, 0.4 + s, 0.4 + s]}]},
        },
        quiet=True,
    )
    hood = lone.neighbourhood()
    splats.update(hood.positions, hood.count, hood)
    lengths, _ = semi_axes(splats.inverse.to_numpy()[0])
    assert lengths == pytest.approx(np.full(3, DROP_RADIUS_SPACINGS * s), rel=1e-4)


@pytest.mark.slow  # a column settled, then drawn: among the default run's longest
def test_a_settled_column_reads_as_one_flat_surface():
    sim = Simulation(column_scene(), quiet=True)
    sim.step(60)
    renderer = SceneRenderer(sim, *SIZE, style="surface")
    renderer.frame()
    face = top_face(*renderer.fluid.surface(), renderer.view, sim.scene)
    assert face["pixels"] > 250
    assert face["flat"] >= 0.9 and face["median_deg"] <= 2.0
    # Not flatter than the water: the particles' own top has waves of about that tilt.
    assert particles_top(sim.positions(), sim.scene)["median_deg"] > 1.0


@pytest.mark.slow
def test_a_splash_is_not_speckled():
    sim = Simulation(small_dam_break(), quiet=True)
    renderer = SceneRenderer(sim, *SIZE, style="surface")
    shares = []
    for frame in (15, 20, 25):
        sim.step(frame - sim.frame)
        renderer.frame()
        normals, water, depth = renderer.fluid.surface()
        assert water.sum() > 2000  # a tenth of the frame
        shares.append(speckle(normals, water, depth, 2 * sim.scene.fluid.spacing_m))
    assert np.mean(shares) <= 0.04
