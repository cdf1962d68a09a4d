"""How the surface style reads (``python -m benchmarks.frames look``): each particle's splat is an
ellipsoid from its neighbours (flat at a surface, a sphere in the bulk, a drop alone), a settled pool is
one flat surface and a splash is not speckled. The figures are the study's own measures, on small
scenes; the renderer of spheres before the anisotropic splats failed both (docs/RENDERING.md)."""

import numpy as np
import pytest
import taichi as ti

from benchmarks.frames import particles_top, speckle, top_face
from pbf.app.render import SceneRenderer
from pbf.app.splat import DROP_RADIUS_SPACINGS, PUDDLE_HALF_THICKNESS_SPACINGS, Ellipsoids, symmetric_eigen
from pbf.app.surface_render import SPLAT_RADIUS_SPACINGS
from pbf.solver import Simulation
from scenes import column_scene, small_dam_break

SIZE = (480, 270)


def semi_axes(inverse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The semi-axes' lengths (ascending) and unit directions (columns) of the ellipsoid |G x| ≤ 1."""
    lengths, directions = np.linalg.eigh(np.linalg.inv(inverse.T @ inverse))
    return np.sqrt(lengths), directions


def test_the_closed_form_eigen_decomposition_holds_for_equal_and_close_eigenvalues():
    # Covariances of a spacing squared (1e-4 m²): random ones, and those of a lattice (three equal
    # eigenvalues), a flat surface (two equal), a sheet, a filament, one with a zero eigenvalue, a
    # diagonal one and zero. Taichi's SVD, which the splats used before, loses its accuracy at this
    # scale (its error grows as the matrix shrinks; docs/RENDERING.md).
    rng = np.random.default_rng(3)
    spectra = [rng.uniform(0.0, 1.0, 3) for _ in range(200)]
    spectra += [np.ones(3), [0.25, 1.0, 1.0], [0.25, 0.25, 1.0], [0.0, 0.3, 1.0], [1.0, 1.0 + 1e-6, 1.0 - 1e-6]] * 20
    matrices = []
    for spectrum in spectra:
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        matrices.append((rotation * spectrum) @ rotation.T * 1e-4)
    matrices += [np.diag([1e-4, 3e-4, 2e-4]), np.eye(3) * 1e-4, np.zeros((3, 3))]
    given = np.array(matrices, np.float32)
    n = len(given)
    source = ti.Matrix.field(3, 3, ti.f32, n)
    values, vectors = ti.Vector.field(3, ti.f32, n), ti.Matrix.field(3, 3, ti.f32, n)
    source.from_numpy(given)

    @ti.kernel
    def decompose():
        for i in range(n):
            values[i], vectors[i] = symmetric_eigen(source[i])

    decompose()
    a, lam, v = given.astype(np.float64), values.to_numpy().astype(np.float64), vectors.to_numpy().astype(np.float64)
    scale = np.maximum(np.abs(a).max(axis=(1, 2)), 1e-30)
    residual = np.linalg.norm(a @ v - v * lam[:, None, :], axis=1).max(axis=1) / scale
    assert residual.max() < 1e-3
    assert np.abs(np.einsum("nji,njk->nik", v, v) - np.eye(3)).max() < 1e-5  # orthonormal axes
    assert (np.abs(np.sort(lam, axis=1) - np.linalg.eigvalsh(a)).max(axis=1) / scale).max() < 1e-3


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
    # Without neighbours (lists of particles far apart), every splat is a drop of a particle's volume: a
    # sphere in the air, and on the floor a level disc (a puddle), flat where water wets it.
    blocks = [{"min_m": [0.4, y, 0.4], "max_m": [0.4 + s, y + s, 0.4 + s]} for y in (0.4, 0.0)]
    lone = Simulation(
        {"name": "drops", "container": {"max_m": [1.0, 1.0, 1.0]}, "fluid": {"spacing_m": s, "blocks": blocks}},
        quiet=True,
    )
    hood = lone.neighbourhood()
    splats = Ellipsoids(hood.positions.shape[0], SPLAT_RADIUS_SPACINGS * s, s, floor_y_m=0.0)
    splats.update(hood.positions, hood.count, hood)
    heights = hood.positions.to_numpy()[: hood.count, 1]  # in the lists' order
    assert hood.count == 2 and heights.max() > 0.4 and heights.min() < s
    for i in range(2):
        lengths, directions = semi_axes(splats.inverse.to_numpy()[i])
        assert np.prod(lengths) == pytest.approx(DROP_RADIUS_SPACINGS**3 * s**3, rel=1e-4)  # a drop's volume
        if heights[i] > 0.4:
            assert lengths == pytest.approx(np.full(3, DROP_RADIUS_SPACINGS * s), rel=1e-4)
        else:
            assert lengths[0] == pytest.approx(PUDDLE_HALF_THICKNESS_SPACINGS * s, rel=1e-4)
            assert lengths[1] == pytest.approx(lengths[2], rel=1e-4) and lengths[2] > 2 * DROP_RADIUS_SPACINGS * s
            assert abs(directions[1, 0]) > 0.999  # its short axis vertical


@pytest.mark.slow  # a column settled, then drawn: among the default run's longest
def test_a_settled_column_reads_as_one_flat_surface():
    sim = Simulation(column_scene(), quiet=True)
    sim.step(60)
    renderer = SceneRenderer(sim, *SIZE, style="surface")
    renderer.frame()
    face = top_face(*renderer.renderer.surface(), renderer.view, sim.scene)
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
        normals, water, depth = renderer.renderer.surface()
        assert water.sum() > 2000  # a tenth of the frame
        shares.append(speckle(normals, water, depth, 2 * sim.scene.fluid.spacing_m))
    assert np.mean(shares) <= 0.04
