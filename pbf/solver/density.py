"""The density constraint of PBF (Macklin & Müller 2013, Sec. 3-4), in a dimensionless form.

The paper's λ_i = −C_i / (Σ_k |∇_k C_i|² + ε) (Eq. 10) carries units of length², so ε and s_corr
(Eqs. 11-12) only work at the scale they were tuned for. Lengths are measured in h: with volume
V = m/ρ0 and the dimensionless gradient ĝ_ij = V h ∇W(x_i − x_j),

    C_i  = ρ_i/ρ0 + ψ_i − 1,  ρ_i/ρ0 = V Σ_j W_ij + ρ_wall/ρ0          (clamped to C_i ≥ 0)
    λ̂_i  = −ω C_i / (|Σ_j ĝ_ij + ĝ_wall|² + Σ_j |ĝ_ij|² + ε̂)          (λ = h² λ̂, ε = ε̂ / h²)
    Δx_i = h [Σ_j (λ̂_i + λ̂_j + s_corr) ĝ_ij + λ̂_i ĝ_wall],  s_corr = −k (W_ij / W(Δq))ⁿ

Every constant (ε̂, k, n, Δq/h) is dimensionless. ω = STABLE_GAIN / gain under-relaxes the Jacobi
iterations so that no error mode grows. The denominator (a diagonal preconditioner) and ψ_i, the ghost
fluid beyond the free surface, are computed once a substep at x* (:meth:`DensityConstraint.prepare`).
With ``solver.wall_mirror`` the ghost behind the container's walls is the fluid's mirror image
(:meth:`DensityConstraint.image_sums`). Why each of these: docs/METHOD.md ("A Jacobi step that no mode
outgrows", "Artificial pressure", "Walls and obstacles", "The free surface").
"""

import taichi as ti

from pbf.solver.backend import Choices
from pbf.solver.constants import scene_constants
from pbf.solver.grid import named
from pbf.solver.model import SCORR_N, DensityParams
from pbf.solver.scan import TreeSum
from pbf.solver.sph import kernel_scale, scaled_kernel, scaled_kernel_and_gradient

SURFACE_RAMP = (0.25, 0.75)
"""Where between the smoothed colour gradient of a lattice's second layer (0) and of its top layer (1)
the surface ghost's smoothstep starts and ends."""
SURFACE_SKIP = 0.002
"""ψ is left at 0, without its neighbour loop, where twice the deficit 1 − ρ/ρ0 is below this."""


@ti.func
def pair_terms(r, volume, h, scale):
    """Pair (i, j) at r = x_i − x_j: ĝ_ij = V h ∇W(r), and its terms (V W_ij, ĝ_ij, |ĝ_ij|²) of ρ_i/ρ0, of
    Σ_j ĝ_ij and of Σ_j |∂C_i/∂x_j|² (the density pass's and the divergence pass's)."""
    w, grad_w = scaled_kernel_and_gradient(r, scale)
    g = volume * h * grad_w
    return g, ti.Vector([volume * w, g[0], g[1], g[2], g.norm_sqr()])


@ti.func
def multiplier_denominator(gradient_i, sum_sq, relaxation):
    """The denominator of λ̂_i (Eq. 10): |∂C_i/∂x_i|² + Σ_j |∂C_i/∂x_j|² + ε̂."""
    return gradient_i.norm_sqr() + sum_sq + relaxation


@ti.func
def position(x: ti.template(), j):
    """x_j of the triple (first, second, from_second): the iterations' two buffers, read from the one
    ``from_second`` picks (a field alone is ``(x, x, 0)``), per neighbour, so a kernel holds one copy of
    each walk, not one per buffer."""
    xj = ti.static(x[0])[j]
    if x[2]:
        xj = ti.static(x[1])[j]
    return xj


@ti.data_oriented
class DensityConstraint:
    """The constraint's passes (``@ti.func``, composed into kernels by ``pbf.solver.substep``) and scratch:
    λ̂ per particle, its sum over a substep, the error sum."""

    def __init__(self, params: DensityParams, boundaries, grid, choices: Choices):
        particle_count = params.particle_count
        self.h = params.kernel_radius_m
        self.boundaries = boundaries
        self.grid = grid
        self.wall_mirror = params.wall_mirror  # compiles the images' walk in
        g_below, g_top, psi_top = params.surface_calibration
        self.constants = scene_constants(
            h=params.kernel_radius_m,
            volume=params.particle_volume_m3,
            relaxation=params.relaxation,
            omega=params.omega,
            scorr_k=params.scorr_k,
            inverse_w_dq=params.inverse_w_dq,
            max_correction=params.max_correction,
            surface_density=params.surface_density,
            surface_offset=g_below + SURFACE_RAMP[0] * (g_top - g_below),
            surface_slope=1.0 / ((SURFACE_RAMP[1] - SURFACE_RAMP[0]) * (g_top - g_below)),
            surface_top=psi_top,
        )
        self.surface = ti.field(ti.f32, shape=particle_count)
        """ψ_i/ρ0, the ghost fluid beyond the free surface, from the substep's first iteration."""
        self.colour_gradient = ti.Vector.field(3, ti.f32, shape=particle_count)
        """ĝ_i = Σ_j ĝ_ij + ĝ_wall at x* (:meth:`prepare`), which ψ is smoothed from."""
        self.plain_error = ti.field(ti.f32, shape=particle_count)
        """ρ_i/ρ0 − 1 (walls included, the ghost not) at x* (:meth:`prepare`): the first iteration's C_i."""
        self.lam = ti.field(ti.f32, shape=particle_count)
        """λ̂_i, the dimensionless Lagrange multiplier of each particle's constraint."""
        self.wall_gradient = ti.Vector.field(3, ti.f32, shape=particle_count)
        """The held-still ghost's gradient at x_i (1/m), from the λ pass for the Δx pass (:meth:`walls`)."""
        self.error = ti.field(ti.f32, shape=particle_count)  # max(C_i, 0) of the last λ pass
        self.error_sum = TreeSum(particle_count, shared=choices.shared_memory, gpu=choices.gpu_blocks)
        """Σ_i max(C_i, 0), compensated and summed the same way on any thread count (it decides when to stop)."""
        self.lam_total = ti.field(ti.f32, shape=particle_count)
        """L_i, the multiplier of the substep's whole correction (the pressure impulse, :func:`pressure`):
        it combines as the positions do, L^{k+1} = L^{k−1} + w (L^k + λ̂^k − L^{k−1})."""
        self.lam_before = ti.field(ti.f32, shape=particle_count)  # L^{k−1} of lam_total's recurrence
        self.denominator = ti.field(ti.f32, shape=particle_count)
        """|∂C_i/∂x_i|² + Σ_j |∂C_i/∂x_j|² + ε̂ of λ̂_i (Eq. 10) at x* (:meth:`prepare`), the images' terms
        included with mirrored walls."""

    @ti.func
    def ghost(self, xi, velocity_level: ti.template()):
        """The walls' ghost at xi, density ρ/ρ0 and gradient (1/m), chosen here for every pass (docs/METHOD.md,
        "Walls and obstacles"): the position passes leave out the walls whose ghost is the fluid's mirror
        image (``solver.wall_mirror``; :meth:`pair_sums` walks the images), the divergence pass at velocity
        level (``velocity_level``) takes every wall's table ghost."""
        return self.boundaries.ghost(xi, ti.static(not velocity_level))

    @ti.func
    def walls(self, i, xi):
        """The ghost density ρ/ρ0 of the boundaries held still at xi (:meth:`ghost`); its gradient is kept for
        the Δx pass."""
        wall, gradient = self.ghost(xi, False)
        self.wall_gradient[i] = gradient
        return wall

    @ti.func
    def image_sums(self, xi, xj, near, plane, h, scale, gradients: ti.template()):
        """Σ W(x_i − x') over the mirror images x' of x_j in the container walls ``near`` x_i: one across
        each, each edge and the corner. With ``gradients`` also Σ ∇W(x_i − x') and Σ R∇W(x_i − x'), R the
        image's reflection (∂/∂x_j of W(x_i − x') is −R∇W)."""
        w_sum = 0.0
        g_sum = ti.Vector([0.0, 0.0, 0.0])
        reflected_sum = ti.Vector([0.0, 0.0, 0.0])
        for mask in ti.static(range(1, 8)):
            m = ti.static([float(mask >> a & 1) for a in range(3)])  # 1 on the axes reflected
            flip = ti.Vector([1.0 - 2.0 * m[0], 1.0 - 2.0 * m[1], 1.0 - 2.0 * m[2]])  # −1 there
            reflected = ti.Vector([mask >> a & 1 for a in ti.static(range(3))])
            use = (near * reflected + 1 - reflected).min()  # near every wall the image reflects in
            if use != 0:
                r = xi - (flip * xj + 2.0 * ti.Vector(m) * plane)  # x' = x_j reflected: 2 P_a − x_j,a
                if r.norm_sqr() < h * h:  # most images are out of reach: no square root for them
                    if ti.static(gradients):
                        w, g = scaled_kernel_and_gradient(r, scale)
                        w_sum += w
                        g_sum += g
                        reflected_sum += flip * g
                    else:
                        w_sum += scaled_kernel(r.norm_sqr(), scale)
        return w_sum, g_sum, reflected_sum

    @ti.func
    def particle_constants(self):
        """h, V and the kernel's scale, read once per particle, not per neighbour."""
        h, volume = self.constants[None].h, self.constants[None].volume
        return h, volume, kernel_scale(h)

    @ti.func
    def density_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s V W_ij into ρ_i/ρ0, and with ``p.gradients`` ĝ_ij = V h ∇W_ij into Σ_j ĝ_ij and
        |ĝ_ij|² into Σ_j |∂C_i/∂x_j|²."""
        xj = position(p.x, j)
        if ti.static(p.gradients):
            _g, terms = pair_terms(p.xi - xj, p.volume, p.h, p.scale)
            p.sums += terms
        else:
            p.sums[0] += p.volume * scaled_kernel((p.xi - xj).norm_sqr(), p.scale)

    @ti.func
    def mirrored_density_pair(self, i, j, p: ti.template()):
        """:meth:`density_pair` with x_j's mirror images in the walls near x_i (∂C_i/∂x_j: reflected)."""
        xj = position(p.x, j)
        if ti.static(p.gradients):
            w, grad_w = scaled_kernel_and_gradient(p.xi - xj, p.scale)
            w_images, g_images, reflected = self.image_sums(p.xi, xj, p.near, p.plane, p.h, p.scale, True)
            g = p.volume * p.h * (grad_w + g_images)
            sq = (p.volume * p.h * (grad_w + reflected)).norm_sqr()
            p.sums += ti.Vector([p.volume * (w + w_images), g[0], g[1], g[2], sq])
        else:
            w_images, g_images, reflected = self.image_sums(p.xi, xj, p.near, p.plane, p.h, p.scale, False)
            p.sums[0] += p.volume * (scaled_kernel((p.xi - xj).norm_sqr(), p.scale) + w_images)

    @ti.func
    def pair_sums(self, x: ti.template(), xi, i, neighbours: ti.template(), gradients: ti.template()):
        """(ρ_i/ρ0, Σ_j ĝ_ij, Σ_j |∂C_i/∂x_j|², ĝ_self): the fluid's part of ρ_i/ρ0 at xi, its own term
        and the mirror images included; with ``gradients`` the pairs' part of ∂C_i/∂x_i, the
        denominator's sum and the gradient of the particle's own images (they move with it, so
        ∂C_i/∂x_i counts them twice)."""
        h, volume, scale = self.particle_constants()
        near, plane = ti.Vector([0, 0, 0]), ti.Vector([0.0, 0.0, 0.0])
        g_self = ti.Vector([0.0, 0.0, 0.0])
        sums = ti.Vector([volume * scaled_kernel(0.0, scale), 0.0, 0.0, 0.0, 0.0])
        p = ti.static(
            named(x=x, xi=xi, h=h, volume=volume, scale=scale, near=near, plane=plane, gradients=gradients, sums=sums)
        )
        if ti.static(self.wall_mirror):
            near, plane = self.boundaries.mirror_walls(xi)
            if near.sum() > 0:
                # A walk of its own for the particles at a wall: the images' code in the common walk
                # would slow every particle's pairs, the few at a wall or not.
                w_self, g_self, reflected_self = self.image_sums(xi, xi, near, plane, h, scale, gradients)
                sums[0] = volume * (scaled_kernel(0.0, scale) + w_self)
                self.grid.for_each_neighbour(i, neighbours, self.mirrored_density_pair, p)
            else:
                self.grid.for_each_neighbour(i, neighbours, self.density_pair, p)
        else:
            self.grid.for_each_neighbour(i, neighbours, self.density_pair, p)
        return sums[0], ti.Vector([sums[1], sums[2], sums[3]]), sums[4], volume * h * g_self

    @ti.func
    def density_ratio(self, x: ti.template(), i, neighbours: ti.template()):
        """ρ_i/ρ0 of particle i: the fluid and the ghost fluid behind the walls."""
        xi = x[i]
        ratio, gradient_i, sum_sq, own_images = self.pair_sums((x, x, 0), xi, i, neighbours, False)
        wall, wall_gradient = self.ghost(xi, False)
        return ratio + wall

    @ti.func
    def prepare(self, x: ti.template(), i, neighbours: ti.template()):
        """Particle i's constants of the substep at x*: C_i, the denominator of λ̂_i (Eq. 10), the colour
        gradient the surface ghost is smoothed from and the walls' gradient for the first Δx pass."""
        xi = x[i]
        h, relaxation = self.constants[None].h, self.constants[None].relaxation
        wall = self.walls(i, xi)
        ratio, gradient_i, sum_sq, own_images = self.pair_sums((x, x, 0), xi, i, neighbours, True)
        # The colour gradient, the ghost fluid held still: zero inside a lattice, at a wall too.
        colour = gradient_i + own_images + h * self.wall_gradient[i]
        self.denominator[i] = multiplier_denominator(colour + own_images, sum_sq, relaxation)
        self.colour_gradient[i] = colour
        self.plain_error[i] = ratio + wall - 1.0

    @ti.func
    def colour_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s V W_ij ĝ_j into the smoothed colour gradient."""
        p.smoothed += p.volume * scaled_kernel((p.xi - p.x[j]).norm_sqr(), p.scale) * self.colour_gradient[j]

    @ti.func
    def surface_ghost(self, x: ti.template(), i, neighbours: ti.template()):
        """ψ_i/ρ0, the density of the ghost fluid beyond the free surface, from the smoothed colour
        gradient g = |Σ_j V W_ij ĝ_j|: ψ_top where g reads as in the top layer of a lattice, 0 as in
        the layer below, a smoothstep between (SURFACE_RAMP, ``pbf.solver.sph.surface_ghost_calibration``).
        ψ fills at most twice the particle's deficit 1 − ρ_i/ρ0 (a layer squeezed against a wall lacks
        nothing), and is 0 without a neighbour loop where the deficit is below SURFACE_SKIP."""
        psi = 0.0
        cap = -2.0 * self.plain_error[i]
        if self.constants[None].surface_density and cap > SURFACE_SKIP:
            h, volume, scale = self.particle_constants()
            smoothed = volume * scaled_kernel(0.0, scale) * self.colour_gradient[i]
            p = ti.static(named(x=x, xi=x[i], volume=volume, scale=scale, smoothed=smoothed))
            self.grid.for_each_neighbour(i, neighbours, self.colour_pair, p)
            offset, slope = self.constants[None].surface_offset, self.constants[None].surface_slope
            u = ti.min(ti.max((smoothed.norm() - offset) * slope, 0.0), 1.0)
            psi = ti.min(self.constants[None].surface_top * u * u * (3.0 - 2.0 * u), cap)
        return psi

    @ti.func
    def multiplier_pass(
        self,
        first: ti.template(),
        second: ti.template(),
        from_second,
        i,
        neighbours: ti.template(),
        k,
        weight,
    ):
        """λ̂_i of iteration k (Eq. 10) from C_i in the buffer ``from_second`` picks (the first iteration's
        from :meth:`prepare`, the surface ghost found then), into L with this iteration's ``weight``."""
        c = 0.0
        if k == 0:  # x* in the first buffer, its sums made by prepare()
            self.surface[i] = self.surface_ghost(first, i, neighbours)
            c = self.plain_error[i]
        else:
            x = ti.static((first, second, from_second))
            xi = position(x, i)
            wall = self.walls(i, xi)
            ratio, gradient_i, sum_sq, own_images = self.pair_sums(x, xi, i, neighbours, False)
            c = ratio + wall - 1.0
        self.lagrange_multiplier(i, c + self.surface[i], k == 0, weight)

    @ti.func
    def lagrange_multiplier(self, i, c, first_iteration, weight):
        """λ̂_i (Eq. 10, dimensionless) for the constraint value ``c``, combined into the substep's L with
        this iteration's ``weight`` (lam_total); max(C_i, 0) is kept for error_sum."""
        c = ti.max(c, 0.0)  # only compressed particles push: no attraction at the free surface
        self.error[i] = c
        lam = -self.constants[None].omega * c / self.denominator[i]
        self.lam[i] = lam
        # The multiplier the positions have moved by, combined as the positions are (see lam_total).
        earlier = ti.select(first_iteration, 0.0, self.lam_before[i])
        total = ti.select(first_iteration, 0.0, self.lam_total[i])
        self.lam_before[i] = total
        self.lam_total[i] = earlier + weight * (total + lam - earlier)

    @ti.func
    def correction_term(self, j, p: ti.template()):
        """(λ̂_i + λ̂_j + s_corr) ĝ_ij (Eqs. 11-12) of pair (i, j)."""
        w, grad_w = scaled_kernel_and_gradient(p.xi - position(p.x, j), p.scale)
        s_corr = -p.scorr[0] * (w * p.scorr[1]) ** ti.static(SCORR_N)  # 0 with k = 0
        return (p.lam_i + self.lam[j] + s_corr) * p.volume * p.h * grad_w

    @ti.func
    def correction_pair(self, i, j, p: ti.template()):
        p.dx += self.correction_term(j, p)

    @ti.func
    def mirrored_correction_pair(self, i, j, p: ti.template()):
        """Pair (i, j)'s term and its mirror images' with (λ̂_i + λ̂_j) into Δx_i."""
        w_images, g_images, reflected = self.image_sums(p.xi, position(p.x, j), p.near, p.plane, p.h, p.scale, True)
        p.dx += self.correction_term(j, p) + (p.lam_i + self.lam[j]) * p.volume * p.h * g_images

    @ti.func
    def correction(self, x: ti.template(), xi, i, lam_i, neighbours: ti.template()):
        """Σ_j (λ̂_i + λ̂_j + s_corr) ĝ_ij (Eqs. 11-12) for particle i at xi, with ``solver.wall_mirror``
        also the pairs' mirror images with (λ̂_i + λ̂_j) and the particle's own with 2 λ̂_i (they move
        with it); Jacobi, so x is only read."""
        h, volume, scale = self.particle_constants()
        scorr = ti.Vector([self.constants[None].scorr_k, self.constants[None].inverse_w_dq])
        near, plane = ti.Vector([0, 0, 0]), ti.Vector([0.0, 0.0, 0.0])
        dx = ti.Vector([0.0, 0.0, 0.0])
        p = ti.static(
            named(x=x, xi=xi, h=h, volume=volume, scale=scale, near=near, plane=plane, lam_i=lam_i, scorr=scorr, dx=dx)
        )
        if ti.static(self.wall_mirror):
            near, plane = self.boundaries.mirror_walls(xi)
            if near.sum() > 0:  # a walk of its own, as in pair_sums
                w_self, g_self, reflected_self = self.image_sums(xi, xi, near, plane, h, scale, True)
                dx += 2.0 * lam_i * volume * h * g_self
                self.grid.for_each_neighbour(i, neighbours, self.mirrored_correction_pair, p)
            else:
                self.grid.for_each_neighbour(i, neighbours, self.correction_pair, p)
        else:
            self.grid.for_each_neighbour(i, neighbours, self.correction_pair, p)
        return dx

    @ti.func
    def jacobi_step(
        self, first: ti.template(), second: ti.template(), from_second, i, neighbours: ti.template(), weight
    ):
        """x_i + Δx_i (Eqs. 11-12) from the buffer ``from_second`` picks, weighted against the other's (the
        iteration before), collided (line 15), into the other."""
        h, max_correction = self.constants[None].h, self.constants[None].max_correction
        xi, earlier = first[i], second[i]
        if from_second:
            xi, earlier = second[i], first[i]
        lam_i = self.lam[i]
        dx = self.correction((first, second, from_second), xi, i, lam_i, neighbours)
        dx += lam_i * h * self.wall_gradient[i]  # the ghost's gradient at xi (walls)
        # A bound on one iteration's move (in units of h): particles piled on one point have tiny
        # gradients and huge λ, and their product would throw them out at thousands of m/s.
        dx *= ti.min(1.0, max_correction / (dx.norm() + 1e-12))
        corrected = xi + h * dx
        moved = self.boundaries.project_recorded(
            ti.select(weight == 1.0, corrected, earlier + weight * (corrected - earlier)), i, "iteration", weight
        )
        if from_second:
            first[i] = moved
        else:
            second[i] = moved

    @ti.func
    def between(self, first: ti.template(), second: ti.template(), newer_in_second, fraction, i):
        """x*_i = newer + fraction (older − newer), collided, into the first buffer, and L_i alike: the
        step back by the share of the last iteration the error target did not need, which makes the
        result continuous in the error (``pbf.solver.iterations``; docs/METHOD.md, "Accelerated iterations")."""
        newer, older = first[i], second[i]
        if newer_in_second:
            newer, older = second[i], first[i]
        first[i] = self.boundaries.project_recorded(newer + fraction * (older - newer), i, "between", fraction)
        self.lam_total[i] += fraction * (self.lam_before[i] - self.lam_total[i])


def pressure_scales(rest_density_kg_m3: float, h: float, dt: float) -> tuple[float, float]:
    """Pa a unit of L_i (``lam_total``) and a unit of Λ_i (``State.multiplier``) in :func:`pressure`."""
    scale = -rest_density_kg_m3 * h**2
    return scale / dt**2, scale


@ti.func
def pressure(impulse, multiplier, per_impulse, per_multiplier):
    """p_i = −ρ0 h² (L_i/Δt² + Λ_i) (Pa) with :func:`pressure_scales`: matching Δx_i = h Σ_j (L_i + L_j) ĝ_ij
    with the SPH pressure acceleration −Σ_j V (p_i + p_j)/ρ0 ∇W_ij applied over Δt² (docs/METHOD.md,
    "The pressure read-out"); the pressures read out and the bodies' reaction alike."""
    return per_impulse * impulse + per_multiplier * multiplier
