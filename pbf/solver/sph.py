"""The cubic B-spline kernel (Monaghan 1992), as Taichi functions and NumPy twins (for constants and
tests): density and gradient from one function (docs/METHOD.md, "The kernel"). W = 0 for r ≥ h.
"""

import math

import numpy as np
import taichi as ti

SIGMA_3D = 8.0 / math.pi


@ti.func
def kernel_scale(h):
    """(1/h, σ, σ/h²) at support radius h, σ = 8/(π h³): worked out once per particle, not per pair."""
    inverse_h = 1.0 / h
    sigma = SIGMA_3D * inverse_h * inverse_h * inverse_h
    return ti.Vector([inverse_h, sigma, sigma * inverse_h * inverse_h])


@ti.func
def scaled_kernel(r2, k):
    """W(r, h) from r² and k = kernel_scale(h), with q = r/h: σ(6q³ − 6q² + 1) for q ≤ ½, 2σ(1 − q)³ for q < 1."""
    q = ti.sqrt(r2) * k[0]
    t = ti.max(1.0 - q, 0.0)
    return k[1] * ti.select(q <= 0.5, 6.0 * q * q * (q - 1.0) + 1.0, 2.0 * t * t * t)


@ti.func
def scaled_kernel_and_gradient(r: ti.template(), k):
    """(W, ∇W) at offset r, k = kernel_scale(h): ∇W = W'(|r|) r/|r|, W'/|r| = σ/h⁵ · 6(3q − 2) for q ≤ ½
    (zero at r = 0) and −σ/h⁵ · 6(1 − q)²/q beyond; both computed, one selected (no branch)."""
    q = r.norm() * k[0]
    t = ti.max(1.0 - q, 0.0)
    inner = q <= 0.5
    w = k[1] * ti.select(inner, 6.0 * q * q * (q - 1.0) + 1.0, 2.0 * t * t * t)
    slope_over_r = k[2] * ti.select(inner, 6.0 * (3.0 * q - 2.0), -6.0 * t * t / ti.max(q, 0.5))
    return w, slope_over_r * r


@ti.func
def kernel(r2: ti.f32, h: ti.f32) -> ti.f32:
    return scaled_kernel(r2, kernel_scale(h))


@ti.func
def kernel_and_gradient(r: ti.template(), h: ti.f32):
    return scaled_kernel_and_gradient(r, kernel_scale(h))


@ti.func
def scaled_kernel_gradient(r: ti.template(), k):
    """∇W at offset r, k = kernel_scale(h); zero at r = 0 (no self-force)."""
    _, gradient = scaled_kernel_and_gradient(r, k)
    return gradient


@ti.func
def kernel_gradient(r: ti.template(), h: ti.f32):
    """∇W(r, h) = W'(|r|) r/|r|; zero at r = 0 (no self-force)."""
    return scaled_kernel_gradient(r, kernel_scale(h))


def kernel_np(r, h):
    """NumPy twin of :func:`kernel`, taking distances (not squared)."""
    q = np.asarray(r, dtype=np.float64) / h
    inner = 6.0 * q * q * (q - 1.0) + 1.0
    outer = 2.0 * np.clip(1.0 - q, 0.0, None) ** 3
    return SIGMA_3D / h**3 * np.where(q <= 0.5, inner, np.where(q < 1.0, outer, 0.0))


def kernel_gradient_np(r_vec, h):
    """NumPy twin of :func:`kernel_gradient` for an (n, 3) array of offsets."""
    r_vec = np.asarray(r_vec, dtype=np.float64)
    norm = np.linalg.norm(r_vec, axis=-1, keepdims=True)
    q = norm / h
    slope = SIGMA_3D / h**4 * np.where(q <= 0.5, 6.0 * q * (3.0 * q - 2.0), -6.0 * np.clip(1.0 - q, 0.0, None) ** 2)
    inside = (norm > 0.0) & (norm < h)
    return np.where(inside, slope / np.where(inside, norm, 1.0) * r_vec, 0.0)


def lattice_offsets(spacing, h):
    """Offsets of all simple-cubic lattice sites (spacing s) within distance h of the origin, origin included."""
    n = int(math.ceil(h / spacing))
    axis = np.arange(-n, n + 1) * spacing
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[np.linalg.norm(grid, axis=1) < h]


def lattice_density_sum(spacing, h):
    """Σ_j W(x_j) over a full lattice (1/m³), not 1/s³: the mass derived from it puts the lattice at ρ0."""
    return float(kernel_np(np.linalg.norm(lattice_offsets(spacing, h), axis=1), h).sum())


def wall_density_table(spacing, h, samples):
    """Missing density ρ_wall(d)/ρ0 at distance d in [0, h] from a flat wall and its derivative: ghost
    lattice planes at d + s/2 + k s behind it, so a lattice touching the wall reads the interior's."""
    d = np.linspace(0.0, h, samples)
    density = ghost_lattice_density(d, spacing, h)
    return density, np.gradient(density, d)


def ghost_lattice_density(d, spacing, h):
    """ρ/ρ0 that the lattice planes at d + s/2 + k s (k = 0, 1, ...) give a particle, for an array d."""
    n = int(math.ceil(h / spacing))
    lateral = np.arange(-n, n + 1) * spacing
    la, lb = np.meshgrid(lateral, lateral, indexing="ij")
    lateral_r2 = (la * la + lb * lb).ravel()
    density = np.zeros(len(d))
    for k in range(n + 1):
        plane = d + 0.5 * spacing + k * spacing
        density += kernel_np(np.sqrt(plane[:, None] ** 2 + lateral_r2[None, :]), h).sum(axis=1)
    return density / lattice_density_sum(spacing, h)


def surface_ghost_calibration(spacing, h):
    """(g_below, g_top, ψ_top) of the free-surface ghost on a half-space lattice (units of s): the smoothed
    colour gradient |Σ_j V W_ij ĝ_j| of the layer below the top and of the top, and what the top misses."""
    s = 1.0
    h = h / spacing
    n = int(math.ceil(h)) + 1
    lateral = np.arange(-n, n + 1) * s
    layers = np.arange(0, 2 * n + 3)
    sites = np.array([(a, -k * s, b) for k in layers for a in lateral for b in lateral])
    volume = 1.0 / lattice_density_sum(s, h)

    def colour_gradient_y(layer):
        r = np.array([0.0, -layer * s, 0.0]) - sites
        return h * volume * kernel_gradient_np(r, h)[:, 1].sum()

    raw = np.array([colour_gradient_y(k) for k in layers])

    def smoothed(layer):
        weights = volume * kernel_np(np.linalg.norm(np.array([0.0, -layer * s, 0.0]) - sites, axis=1), h)
        return float(abs(weights @ raw[np.rint(-sites[:, 1] / s).astype(int)]))

    return smoothed(1), smoothed(0), float(ghost_lattice_density(np.array([0.5 * s]), s, h)[0])


def wall_overlap_tables(spacing, h, samples):
    """For inclusion–exclusion (density = Σ walls − Σ edges + corner): the quadrant table Q[i, k] and the
    octant table O[i, j, k] on d = linspace(0, h, samples) per axis, and their gradient tables."""
    n = int(math.ceil(h / spacing))
    behind = 0.5 * spacing + np.arange(n + 1) * spacing  # ghost planes beyond the wall, from d
    lateral = np.arange(-n, n + 1) * spacing
    d = np.linspace(0.0, h, samples)
    a = d[:, None] + behind[None, :]  # (samples, planes): distances to ghost planes along one axis
    quadrant = np.zeros((samples, samples))
    octant = np.zeros((samples, samples, samples))
    for y in lateral:
        r2 = a[:, None, :, None] ** 2 + a[None, :, None, :] ** 2 + y * y
        quadrant += kernel_np(np.sqrt(r2), h).sum(axis=(2, 3))
    for k in range(n + 1):
        r2 = (
            a[:, None, None, :, None] ** 2
            + a[None, :, None, None, :] ** 2
            + (d[None, None, :, None, None] + behind[k]) ** 2
        )
        octant += kernel_np(np.sqrt(r2), h).sum(axis=(3, 4))
    total = lattice_density_sum(spacing, h)
    quadrant /= total
    octant /= total
    return (
        quadrant,
        np.stack(np.gradient(quadrant, d, d), axis=-1),
        octant,
        np.stack(np.gradient(octant, d, d, d), axis=-1),
    )


def jacobi_gain(kernel_ratio, relaxation, samples=24):
    """Largest gain μ(k) = |Σ_j e^{ik·r_j} ĝ_j|² / (Σ_j |ĝ_j|² + ε̂) of one Jacobi density projection over
    an interior lattice's wave vectors, in units of s (docs/METHOD.md, "A Jacobi step that no mode outgrows")."""
    h = float(kernel_ratio)
    offsets = lattice_offsets(1.0, h)
    offsets = offsets[np.linalg.norm(offsets, axis=1) > 0.0]
    gradients = lattice_density_sum(1.0, h) ** -1 * h * kernel_gradient_np(offsets, h)
    axis = np.linspace(0.0, math.pi, samples)
    waves = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    symbols = np.exp(1j * waves @ offsets.T) @ gradients
    return float((np.abs(symbols) ** 2).sum(axis=1).max() / ((gradients**2).sum() + relaxation))
