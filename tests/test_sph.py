"""Kernel maths: normalisation, zero gradient sum, and the Taichi kernels against their NumPy twins."""

import numpy as np
import pytest
import taichi as ti

from pbf.solver import sph


@pytest.mark.parametrize("ratio", [2.0, 2.2, 3.0])
def test_kernel_integrates_to_one(ratio):
    # A fine lattice is a good quadrature of ∫ W dV; at s = h/20 it must give 1 to 0.1%.
    h = 1.0
    s = h / 20
    assert sph.lattice_density_sum(s, h) * s**3 == pytest.approx(1.0, abs=1e-3)
    # At the simulation's spacing the sum is off by a few per cent, which is why mass comes from it.
    coarse = sph.lattice_density_sum(h / ratio, h) * (h / ratio) ** 3
    assert 0.9 < coarse < 1.1


def test_kernel_radial_integral_is_one():
    # Independent of lattices: ∫0^h 4π r² W(r) dr = 1 by the trapezoid rule.
    r = np.linspace(0.0, 1.0, 200001)
    assert np.trapezoid(4 * np.pi * r**2 * sph.kernel_np(r, 1.0), r) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("ratio", [2.0, 2.2, 3.0])
def test_gradients_sum_to_zero_on_a_lattice(ratio):
    h = 0.05
    offsets = sph.lattice_offsets(h / ratio, h)
    gradients = sph.kernel_gradient_np(offsets, h)
    scale = np.abs(gradients).sum()
    assert scale > 0
    assert np.abs(gradients.sum(axis=0)).max() < 1e-12 * scale


def test_gradient_is_derivative_of_kernel():
    h = 0.1
    r = np.linspace(0.001, 0.099, 50)
    step = 1e-7
    numeric = (sph.kernel_np(r + step, h) - sph.kernel_np(r - step, h)) / (2 * step)
    offsets = np.stack([r, np.zeros_like(r), np.zeros_like(r)], axis=1)
    assert np.allclose(sph.kernel_gradient_np(offsets, h)[:, 0], numeric, rtol=1e-5, atol=1e-3)


def test_taichi_kernels_match_numpy():
    h = 0.07
    rng = np.random.default_rng(1)
    offsets = rng.uniform(-h, h, size=(500, 3)).astype(np.float32)
    r = ti.Vector.field(3, ti.f32, shape=500)
    w = ti.field(ti.f32, shape=500)
    g = ti.Vector.field(3, ti.f32, shape=500)
    r.from_numpy(offsets)

    @ti.kernel
    def evaluate():
        for i in r:
            w[i] = sph.kernel(r[i].norm_sqr(), h)
            g[i] = sph.kernel_gradient(r[i], h)

    evaluate()
    distances = np.linalg.norm(offsets.astype(np.float64), axis=1)
    peak = sph.kernel_np(0.0, h)
    assert np.allclose(w.to_numpy(), sph.kernel_np(distances, h), atol=1e-5 * peak)
    reference = sph.kernel_gradient_np(offsets, h)
    assert np.allclose(g.to_numpy(), reference, atol=1e-5 * np.abs(reference).max())


def test_wall_table_restores_lattice_density():
    # A lattice half-space next to a wall at distance s/2 plus the ghost table gives the full lattice sum.
    s, h = 0.02, 0.044
    density, slope = sph.wall_density_table(s, h, 2001)
    offsets = sph.lattice_offsets(s, h)
    half = offsets[offsets[:, 1] > -s / 2 - 1e-12]  # neighbours of a particle s/2 above the wall
    fluid = sph.kernel_np(np.linalg.norm(half, axis=1), h).sum() / sph.lattice_density_sum(s, h)
    ghost = np.interp(s / 2, np.linspace(0, h, 2001), density)
    assert fluid + ghost == pytest.approx(1.0, abs=2e-4)
    assert np.all(slope <= 1e-9)  # closer to the wall means more ghost density: the wall repels


@pytest.mark.parametrize("ratio", [2.0, 2.2])
def test_jacobi_gain_matches_the_projection_matrix(ratio):
    # Build the linearised projection of a periodic 8³ lattice as a matrix and take its spectrum: the
    # Fourier formula must find the same largest gain, and plain Jacobi (gain > 2) must be unstable.
    period, relaxation = 8, 0.1
    offsets = sph.lattice_offsets(1.0, ratio)
    offsets = offsets[np.linalg.norm(offsets, axis=1) > 0.0]
    gradients = ratio * sph.kernel_gradient_np(offsets, ratio) / sph.lattice_density_sum(1.0, ratio)
    sites = np.stack(np.meshgrid(*[np.arange(period)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    n = len(sites)
    jacobian = np.zeros((n, 3 * n))  # ∂C_i/∂x_j, dimensionless: row i holds ĝ_ij at j and −Σ_j ĝ_ij at i
    for i, site in enumerate(sites):
        for offset, g in zip(offsets, gradients):
            j = np.ravel_multi_index(tuple((site + offset.astype(int)) % period), (period,) * 3)
            jacobian[i, 3 * j : 3 * j + 3] += g
            jacobian[i, 3 * i : 3 * i + 3] -= g
    system = jacobian @ jacobian.T
    gain = np.linalg.eigvalsh(system).max() / (np.diag(system)[0] + relaxation)
    # The periodic lattice holds the wave vectors k = 2πm/8: sample the formula at exactly those.
    assert gain == pytest.approx(sph.jacobi_gain(ratio, relaxation, samples=period // 2 + 1), rel=1e-9)
    assert gain > 2.0
    assert sph.jacobi_gain(ratio, relaxation) >= gain
