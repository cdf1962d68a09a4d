"""The density constraint of PBF (Macklin & Müller 2013, Sec. 3-4), in a dimensionless form.

The paper's λ_i = −C_i / (Σ_k |∇_k C_i|² + ε) (Eq. 10) carries units of length², so ε and the s_corr
term added to λ (Eqs. 11-12) only work at the scale they were tuned for. We measure lengths in h:
with volume V = m/ρ0 and the dimensionless gradient ĝ_ij = V h ∇W(x_i − x_j),

    C_i  = ρ_i/ρ0 − 1,  ρ_i/ρ0 = V Σ_j W_ij + ρ_wall/ρ0            (clamped to C_i ≥ 0 by default)
    λ̂_i  = −ω C_i / (|Σ_j ĝ_ij + ĝ_wall|² + Σ_j |ĝ_ij|² + ε̂)      (λ = h² λ̂, ε = ε̂ / h²)
    Δx_i = h [Σ_j (λ̂_i + λ̂_j + s_corr) ĝ_ij + λ̂_i ĝ_wall],  s_corr = −k (W_ij / W(Δq))ⁿ

Every constant (ε̂, k, n, Δq/h) is dimensionless, so one set behaves the same at any particle spacing.

s_corr is a repulsion added in every iteration, not a constraint that converges. The paper's n = 4
still pushes at the lattice spacing (0.45 h), so water at rest kept jostling: single particles of a
resting 0.4 m column flickered at up to 0.32 m/s. With n = 8 and k = 0.03 it is negligible beyond
about 0.3 h, it still parts pairs that come closer (its job in spray), and the fastest particle of
the same column stays under 0.11 m/s.

Iterations are Jacobi: all λ from the same positions, then all Δx, then all positions move at once
(into a second buffer: the iterations alternate between two, ``PredictedPositions``),
accelerated by the weights of ``pbf.solver.acceleration``.
The denominator of λ̂_i is computed in a substep's first iteration and kept for the rest: it only
scales each particle's step (a diagonal preconditioner: the iterations still stop where C_i = 0,
and Δx still follows the current gradients), and the positions move by a few per cent of h within
a substep, so it changes by little. Later λ passes then sum the density alone, without the
gradients, so a later iteration costs less than the first (docs/METHOD.md, "Speed on a CPU"). The
price: a deep tank at 1-2 substeps with a fixed iteration count, already at the edge of stability,
sloshes (every preset holds still as before).

The free surface (``solver.surface_density``). A particle in the top layer of a pool has half a
neighbourhood, reads about 0.82 ρ0 and is left free by the clamp; gravity then settles the layer into
the hollows of the one below, 0.73 s above it instead of a spacing, and the settled seed pool stood
1.5% below its fill height (docs/VALIDATION.md). As the wall term supplies the ghost fluid behind a
wall, ψ_i supplies the ghost fluid beyond the free surface, C_i = ρ_i/ρ0 + ψ_i − 1, so that the top
layer pushes back at a lattice layer's height. Where the surface lies is read from the colour
gradient: a particle's own |ĝ_i| is 0.1-0.2 of noise in a disordered interior against 0.7-1.1 in the
top layer, and ψ read from it made the surface jitter at 0.2 m/s, so it is smoothed over the
neighbourhood first, which needs every ĝ_j: in the substep's first iteration the λ pass stores ĝ_i,
a second loop smooths it into ψ_i and only then forms λ̂_i. ψ is a constant of the substep (like the
denominator): with its own gradient the top layer stopped pushing itself up and the tank boiled.

The walls (``solver.wall_mirror``). By default the ghost fluid behind the container's walls is a fixed
lattice, its density and gradient looked up in tables (``Container.ghost``). A particle at a wall
then has half a neighbourhood that moves: to hold its density it takes twice its neighbours'
multiplier, and that doubled pressure held the layer at the back wall of the Martin & Moyce
collapse 0.57 s above its neighbours (docs/VALIDATION.md). With ``solver.wall_mirror`` the ghost is the
mirror image of the fluid in every wall within reach, one image across each wall, edge and corner
(R_S reflects in the walls S), and it moves with the water:

    ρ_i/ρ0 = V Σ_{j ∈ N_i ∪ {i}} Σ_S W(x_i − R_S x_j)                   (S = ∅: the fluid itself)
    Δx_i   = h [Σ_j (λ̂_i + λ̂_j) Σ_S ĝ(x_i − R_S x_j) + 2 λ̂_i Σ_{S≠∅} ĝ(x_i − R_S x_i)]

A pair's images act like the pair; a particle's own image moves with it, so it counts twice in
∂C_i/∂x_i, and ∂C_i/∂x_j = −Σ_S R_S ĝ(x_i − R_S x_j). On a lattice the images are the tables' ghost
lattice; at a free surface they end where the water does. Obstacles keep their tables, and so does
the divergence pre-correction (``pbf.solver.divergence``).

Plain Jacobi (ω = 1) overshoots: some short-wavelength modes of the error grow every iteration
(``pbf.solver.sph.jacobi_gain``), which blew up a 64,000-particle dam break at its first impact. We
under-relax by ω = STABLE_GAIN / gain (``pbf.solver.model``), so that no mode is amplified; long
waves, which carry most of the density error, still converge.
"""

import taichi as ti

from pbf.solver.constants import scene_constants
from pbf.solver.grid import NeighbourList
from pbf.solver.launch import Launcher
from pbf.solver.model import SCORR_N, DensityParams
from pbf.solver.scan import TreeSum, read_count
from pbf.solver.sph import kernel_scale, scaled_kernel, scaled_kernel_and_gradient

SURFACE_RAMP = (0.25, 0.75)
"""Where between the smoothed colour gradient of a lattice's second layer (0) and of its top layer (1)
the surface ghost's smoothstep starts and ends: a disordered surface spreads both by about ±0.1 of
their gap, and ψ_top is reached (and held) before the top layer's value."""
SURFACE_SKIP = 0.002
"""ψ is left at 0, without its neighbour loop, where twice the deficit 1 − ρ/ρ0 is below this."""


@ti.func
def position(x: ti.template(), j):
    """x_j of ``x``: a field, or the triple (first, second, from_second) of the iterations' two buffers,
    read from the one ``from_second`` picks. The choice is made per neighbour, inside the walk, so that a
    kernel holds one copy of each walk, not one per buffer: a branch every thread takes the same way,
    which costs nothing measurable, where the copies doubled the compile of the density iteration."""
    xj = ti.Vector([0.0, 0.0, 0.0])
    if ti.static(isinstance(x, tuple)):
        if x[2]:
            xj = ti.static(x[1])[j]
        else:
            xj = ti.static(x[0])[j]
    else:
        xj = x[j]
    return xj


@ti.data_oriented
class DensityConstraint:
    """The constraint's kernels and scratch: λ̂ per particle, its sum over a substep, the error sum."""

    def __init__(self, params: DensityParams, boundaries, grid):
        particle_count = params.particle_count
        self.h = params.kernel_radius_m
        """h on the host (``pressure_scale``); the kernels read it from :attr:`constants`."""
        self.boundaries = boundaries
        self.grid = grid
        self.wall_mirror = params.wall_mirror
        """Whether the container's walls mirror the fluid: a switch that compiles the images' code in."""
        self.with_scorr = params.scorr_k > 0.0
        """Whether s_corr is added: a switch that compiles its term in (its strength k is data)."""
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
        """The scene's constants as data (``pbf.solver.constants``): h (m), V (m³), ε̂, ω, k, 1/W(Δq),
        the largest correction (in h), whether the surface ghost is on (a flag, not a switch: its pass
        runs over no particles when off, so a scene with it and one without share the kernels) and its
        smoothstep's offset, slope and ψ_top."""
        scratch = particle_count
        self.surface = ti.field(ti.f32, shape=scratch)
        """ψ_i/ρ0, the density of the ghost fluid beyond the free surface, from the substep's first
        iteration."""
        self.colour_gradient = ti.Vector.field(3, ti.f32, shape=scratch)
        """ĝ_i = Σ_j ĝ_ij + ĝ_wall of the substep's first iteration, which ψ is smoothed from."""
        self.plain_error = ti.field(ti.f32, shape=scratch)
        """ρ_i/ρ0 − 1 (walls included, the ghost not) of the substep's first iteration."""
        self.lam = ti.field(ti.f32, shape=particle_count)
        """λ̂_i, the dimensionless Lagrange multiplier of each particle's constraint."""
        self.walls_where_written = grid.on_device
        """Where the walls' ghost at x_i is looked up: on the device path (the GPU backends') where x_i is
        written (:meth:`wall_ghost_at`: the sort's gather, each Δx pass, :meth:`look_up_walls`), for
        the λ and Δx passes that read x_i next; on the host path in the λ pass, for its Δx pass. The
        ghost of the container's edges and corners is trilinear tables, and that of obstacles and bodies
        long code: in the λ pass it set the registers of the whole neighbour walk on a GPU (72 where the
        walk alone needs 34, ptxas for sm_90: ``benchmarks/registers.py``), while looked up there the
        kernels inline one copy of it fewer, which the CPU's compile of a scene with bodies feels (its
        cold start 1.3-2.5 s longer with the lookups where written)."""
        self.first_in_visit = self.walls_where_written and not self.wall_mirror
        """Whether, on the device path, the neighbour visit may also do the substep's first λ pass
        (:meth:`sums_in_visit_begin`, ``NeighbourGrid.visit_first``): it meets every pair the pass would
        walk, in the list's order, at the positions the pass reads, so the pass's walk of the lists, one of
        the substep's neighbour passes, is saved where nothing between the visit and the iterations
        moves x* (``Simulation.substep``'s ``defer``). Mirrored walls keep the pass (their images' sums)."""
        self.wall_density = ti.field(ti.f32, shape=particle_count if self.walls_where_written else 1)
        """The held-still ghost's ρ/ρ0 behind the walls (:meth:`fixed_walls`) at x_i, on the device path
        (:attr:`walls_where_written`; one unused entry on the host's)."""
        self.wall_gradient = ti.Vector.field(3, ti.f32, shape=particle_count)
        """Its gradient at x_i (1/m), for the λ pass and the Δx pass, which read the same positions."""
        self.error = ti.field(ti.f32, shape=particle_count)
        """max(C_i, 0) of the last λ pass that measured it."""
        self.error_sum = TreeSum(particle_count)
        """Σ_i max(C_i, 0), compensated and summed the same way on any thread count (it decides when to stop)."""
        self._launch_iterate = Launcher(self.iterate)  # past Taichi's per-call Python (pbf.solver.launch)
        self.lam_total = ti.field(ti.f32, shape=particle_count)
        """L_i, the multiplier of the whole correction this substep's iterations made: the pressure
        impulse (see pressure_scale). Δx^k is linear in λ̂^k, and the positions combine as
        x^{k+1} = x^{k−1} + w (x^k + Δx^k − x^{k−1}) (``pbf.solver.acceleration``), so the multiplier
        they have moved by combines alike: L^{k+1} = L^{k−1} + w (L^k + λ̂^k − L^{k−1}), Σ_k λ̂^k for
        plain Jacobi (w = 1). The plain sum under accelerated (Chebyshev) weights read the `hydrostatic`
        tank's gradient 35% low; this reads it within 2% once averaged over a frame's substeps
        (docs/VALIDATION.md)."""
        self.lam_before = ti.field(ti.f32, shape=particle_count)
        """L^{k−1} of lam_total's recurrence."""
        self.denominator = ti.field(ti.f32, shape=particle_count)
        """|∂C_i/∂x_i|² + Σ_j |∂C_i/∂x_j|² + ε̂ of λ̂_i (Eq. 10), from the substep's first iteration: with the
        ghost tables |Σ_j ĝ_ij + ĝ_wall|² + Σ_j |ĝ_ij|² + ε̂; with mirrored walls the images' terms too
        (:meth:`pair_sums`)."""

    @ti.func
    def fixed_walls(self, xi):
        """The ghost density ρ/ρ0 behind the walls that is held still, and its gradient (1/m): the ghost
        tables of the container and the obstacles, or with ``solver.wall_mirror`` the obstacles' only."""
        return self.boundaries.ghost(xi, True)

    @ti.func
    def image_sums(self, xi, xj, near, plane, h, scale, gradients: ti.template()):
        """Σ W(x_i − x') over the mirror images x' of x_j in the container walls ``near`` x_i: one across
        each, one across each edge, one across the corner (with the fluid they fill the space around a
        lattice in a corner). With ``gradients`` also Σ ∇W(x_i − x') and Σ R∇W(x_i − x'), R the image's
        reflection (∂/∂x_j of W(x_i − x') is −R∇W). ``h`` and its ``scale = kernel_scale(h)`` come from the
        caller, read once per particle: read here, once per neighbour, h cost the `hydrostatic` tank 14%
        of its time."""
        w_sum = 0.0
        g_sum = ti.Vector([0.0, 0.0, 0.0])
        reflected_sum = ti.Vector([0.0, 0.0, 0.0])
        for mask in ti.static(range(1, 8)):
            m = ti.static([float(mask >> a & 1) for a in range(3)])  # 1 on the axes reflected
            flip = ti.Vector([1.0 - 2.0 * m[0], 1.0 - 2.0 * m[1], 1.0 - 2.0 * m[2]])  # −1 there
            use = 1
            for a in ti.static(range(3)):
                if ti.static(m[a] > 0.0):
                    use *= near[a]
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
    def pair_sums(self, x: ti.template(), xi, i, neighbours: ti.template(), gradients: ti.template()):
        """The fluid's part of ρ_i/ρ0 for particle i at xi (its own term included, and with
        ``solver.wall_mirror`` the mirror images in the container's walls); with ``gradients`` also
        Σ_j ĝ_ij (the pairs' part of ∂C_i/∂x_i), Σ_j |∂C_i/∂x_j|² and ĝ_self, the gradient of the
        particle's own images held still (they move with it, so ∂C_i/∂x_i counts them twice)."""
        ratio, gradient_i, sum_sq = 0.0, ti.Vector([0.0, 0.0, 0.0]), 0.0
        own_images = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.wall_mirror):
            near, plane = self.boundaries.container.mirror_walls(xi)
            # A loop of its own for the particles at a wall: with the images' code in the common loop,
            # every particle's pairs took 2.5 times as long, the few at a wall or not.
            if near.sum() > 0:
                ratio, gradient_i, sum_sq, own_images = self.mirrored_pair_sums(
                    x, xi, i, neighbours, near, plane, gradients
                )
            else:
                ratio, gradient_i, sum_sq = self.plain_pair_sums(x, xi, i, neighbours, gradients)
        else:
            ratio, gradient_i, sum_sq = self.plain_pair_sums(x, xi, i, neighbours, gradients)
        return ratio, gradient_i, sum_sq, own_images

    @ti.func
    def plain_pair_sums(self, x: ti.template(), xi, i, neighbours: ti.template(), gradients: ti.template()):
        """:meth:`pair_sums` without mirror images."""
        h, volume = self.constants[None].h, self.constants[None].volume
        scale = kernel_scale(h)  # once per particle, for the neighbour loop
        ratio = volume * scaled_kernel(0.0, scale)
        gradient_i = ti.Vector([0.0, 0.0, 0.0])
        sum_sq = 0.0
        first, last, stride = self.grid.listed(i, neighbours)
        upcoming = self.grid.upcoming(neighbours, first, last)
        for k in range(first, last):
            j = self.grid.neighbour(neighbours, k, upcoming)
            upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
            if ti.static(gradients):
                w, g = self.pair_density_and_gradient(xi, position(x, j), scale, volume, h)
                ratio += w
                gradient_i += g
                sum_sq += g.norm_sqr()
            else:
                ratio += volume * scaled_kernel((xi - position(x, j)).norm_sqr(), scale)
        return ratio, gradient_i, sum_sq

    @ti.func
    def pair_density_and_gradient(self, xi, xj, scale, volume, h):
        """V W_ij and ĝ_ij = V h ∇W_ij of one pair (h, V and ``scale = kernel_scale(h)`` from the caller,
        read once per particle): a term of the first iteration's sums (:meth:`plain_pair_sums`)."""
        w, grad_w = scaled_kernel_and_gradient(xi - xj, scale)
        return volume * w, volume * h * grad_w

    @ti.func
    def sums_in_visit_begin(self):
        """The first iteration's sums of :meth:`plain_pair_sums` as the neighbour visit finds the pairs
        (:attr:`first_in_visit`): (the sums, the particle's own term in; what their pairs need), each a
        vector the visit carries without reading it."""
        h, volume = self.constants[None].h, self.constants[None].volume
        scale = kernel_scale(h)  # once per particle, for the neighbour loop
        sums = ti.Vector([volume * scaled_kernel(0.0, scale), 0.0, 0.0, 0.0, 0.0])  # ratio, Σ ĝ_ij, Σ |ĝ_ij|²
        return sums, ti.Vector([scale[0], scale[1], scale[2], volume, h])

    @ti.func
    def sums_in_visit_add(self, sums, xi, xj, given):
        """:meth:`sums_in_visit_begin`'s sums with the pair (x_i, x_j) added, in the visit's order, which is
        the list's: the same sums as the first λ pass's."""
        scale = ti.Vector([given[0], given[1], given[2]])
        w, g = self.pair_density_and_gradient(xi, xj, scale, given[3], given[4])
        return sums + ti.Vector([w, g[0], g[1], g[2], g.norm_sqr()])

    @ti.func
    def sums_in_visit_end(self, i, sums):
        """The first iteration's λ pass for particle i from the visit's sums (:attr:`first_in_visit`):
        C_i, the denominator and the colour gradient kept for the substep, and λ̂_i, or with the surface
        ghost C_i alone (λ̂_i waits for the ghost: :meth:`surface_pass`). Its weight is w_1 = 1, the
        first of every table (``pbf.solver.acceleration``); its error is kept whether measured or not."""
        c = self.first_constraint(
            i,
            sums[0],
            ti.Vector([sums[1], sums[2], sums[3]]),
            sums[4],
            ti.Vector([0.0, 0.0, 0.0]),
            self.wall_density[i],
            self.wall_gradient[i],
        )
        if self.constants[None].surface_density:
            self.plain_error[i] = c
        else:
            self.lagrange_multiplier(i, c, True, 1, 1.0)

    @ti.func
    def mirrored_pair_sums(
        self, x: ti.template(), xi, i, neighbours: ti.template(), near, plane, gradients: ti.template()
    ):
        """:meth:`pair_sums` with the mirror images in the walls ``near`` xi."""
        h, volume = self.constants[None].h, self.constants[None].volume
        scale = kernel_scale(h)  # once per particle, for the neighbour loop
        w_self, g_self, _ = self.image_sums(xi, xi, near, plane, h, scale, gradients)
        ratio = volume * (scaled_kernel(0.0, scale) + w_self)
        own_images = volume * h * g_self
        gradient_i = ti.Vector([0.0, 0.0, 0.0])
        sum_sq = 0.0
        first, last, stride = self.grid.listed(i, neighbours)
        upcoming = self.grid.upcoming(neighbours, first, last)
        for k in range(first, last):
            j = self.grid.neighbour(neighbours, k, upcoming)
            upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
            xj = position(x, j)
            if ti.static(gradients):
                w, grad_w = scaled_kernel_and_gradient(xi - xj, scale)
                w_images, g_images, reflected = self.image_sums(xi, xj, near, plane, h, scale, True)
                ratio += volume * (w + w_images)
                gradient_i += volume * h * (grad_w + g_images)
                sum_sq += (volume * h * (grad_w + reflected)).norm_sqr()
            else:
                w_images, _, _ = self.image_sums(xi, xj, near, plane, h, scale, False)
                ratio += volume * (scaled_kernel((xi - xj).norm_sqr(), scale) + w_images)
        return ratio, gradient_i, sum_sq, own_images

    @ti.func
    def density_ratio(self, x: ti.template(), i, neighbours: ti.template()):
        """ρ_i/ρ0 of particle i: the fluid and the ghost fluid behind the walls."""
        xi = x[i]
        ratio, _, _, _ = self.pair_sums(x, xi, i, neighbours, False)
        wall, _ = self.fixed_walls(xi)
        return ratio + wall

    @ti.func
    def own_position(self, first: ti.template(), second: ti.template(), from_second, i):
        """x_i from the buffer ``from_second`` picks."""
        xi = first[i]
        if from_second:
            xi = second[i]
        return xi

    @ti.func
    def constraint(
        self, first: ti.template(), second: ti.template(), from_second, i, neighbours: ti.template(), first_iteration
    ):
        """C_i = ρ_i/ρ0 − 1 (walls included, the surface ghost not) at the positions in the buffer
        ``from_second`` picks; in the ``first_iteration`` also the denominator of λ̂_i, kept for the
        substep (module docstring), and the colour gradient the surface ghost is smoothed from."""
        xi = self.own_position(first, second, from_second, i)
        wall, wall_gradient = 0.0, ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.walls_where_written):
            wall, wall_gradient = self.wall_density[i], self.wall_gradient[i]  # at xi (wall_ghost_at)
        else:
            wall, wall_gradient = self.fixed_walls(xi)
            self.wall_gradient[i] = wall_gradient  # for this iteration's Δx pass (jacobi_step)
        c = 0.0
        if first_iteration:  # always from the first buffer (x* starts a substep there)
            ratio, gradient_i, sum_sq, own_images = self.pair_sums(first, xi, i, neighbours, True)
            c = self.first_constraint(i, ratio, gradient_i, sum_sq, own_images, wall, wall_gradient)
        else:
            ratio, _, _, _ = self.pair_sums((first, second, from_second), xi, i, neighbours, False)
            c = ratio + wall - 1.0
        return c

    @ti.func
    def first_constraint(self, i, ratio, gradient_i, sum_sq, own_images, wall, wall_gradient):
        """C_i of the substep's first iteration from its sums (:meth:`pair_sums` with gradients), with the
        denominator of λ̂_i and the colour gradient kept for the substep."""
        # The colour gradient, the ghost fluid held still: zero inside a lattice, at a wall too.
        (h, relaxation, surface_density) = (
            self.constants[None].h,
            self.constants[None].relaxation,
            self.constants[None].surface_density,
        )
        colour = gradient_i + own_images + h * wall_gradient
        self.denominator[i] = (colour + own_images).norm_sqr() + sum_sq + relaxation
        if surface_density:
            self.colour_gradient[i] = colour
        return ratio + wall - 1.0

    @ti.func
    def surface_ghost(self, x: ti.template(), i, neighbours: ti.template()):
        """ψ_i/ρ0, the density of the ghost fluid beyond the free surface (module docstring), from the
        colour gradients smoothed over the neighbourhood, g = |Σ_j V W_ij ĝ_j| (self included): ψ_top
        where g reads as in the top layer of a lattice under a flat surface, 0 where it reads as in the
        layer below, a smoothstep between (SURFACE_RAMP; ``pbf.solver.sph.surface_ghost_calibration``).
        ψ fills at most twice the particle's deficit 1 − ρ_i/ρ0: a layer squeezed against a wall at an
        impact, whose colour gradient the wall term turns outward, lacks nothing; a particle above
        0.999 ρ0 (most of a pool) is left at 0 without the neighbour loop (SURFACE_SKIP)."""
        psi = 0.0
        cap = -2.0 * self.plain_error[i]
        if cap > SURFACE_SKIP:
            (h, volume, surface_offset, surface_slope, surface_top) = (
                self.constants[None].h,
                self.constants[None].volume,
                self.constants[None].surface_offset,
                self.constants[None].surface_slope,
                self.constants[None].surface_top,
            )
            scale = kernel_scale(h)  # once per particle, for the neighbour loop
            xi = x[i]
            smoothed = volume * scaled_kernel(0.0, scale) * self.colour_gradient[i]
            first, last, stride = self.grid.listed(i, neighbours)
            upcoming = self.grid.upcoming(neighbours, first, last)
            for k in range(first, last):
                j = self.grid.neighbour(neighbours, k, upcoming)
                upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
                smoothed += volume * scaled_kernel((xi - x[j]).norm_sqr(), scale) * self.colour_gradient[j]
            u = ti.min(ti.max((smoothed.norm() - surface_offset) * surface_slope, 0.0), 1.0)
            psi = ti.min(surface_top * u * u * (3.0 - 2.0 * u), cap)
        return psi

    @ti.func
    def lagrange_multiplier(self, i, c, measure: ti.template(), first_iteration, weight):
        """λ̂_i (Eq. 10, dimensionless) for the constraint value ``c``, combined into the substep's L with
        this iteration's ``weight`` (lam_total). With ``measure``, max(C_i, 0) is kept for
        error_sum."""
        if ti.static(measure):
            self.error[i] = ti.max(c, 0.0)
        c = ti.max(c, 0.0)  # only compressed particles push: no attraction at the free surface
        lam = -self.constants[None].omega * c / self.denominator[i]
        self.lam[i] = lam
        # The multiplier the positions have moved by, combined as the positions are (see lam_total).
        earlier = ti.select(first_iteration, 0.0, self.lam_before[i])
        total = ti.select(first_iteration, 0.0, self.lam_total[i])
        self.lam_before[i] = total
        self.lam_total[i] = earlier + weight * (total + lam - earlier)

    @ti.func
    def pair_correction(self, x: ti.template(), xi, i, lam_i, neighbours: ti.template()):
        """Σ_j (λ̂_i + λ̂_j + s_corr) ĝ_ij (Eqs. 11-12) for particle i at xi, with ``solver.wall_mirror``
        also the pairs' mirror images with (λ̂_i + λ̂_j) and the particle's own with 2 λ̂_i (they move
        with it); Jacobi, so x is only read."""
        h, volume = self.constants[None].h, self.constants[None].volume
        scale = kernel_scale(h)  # once per particle, for the neighbour loop
        scorr = ti.Vector([self.constants[None].scorr_k, self.constants[None].inverse_w_dq])
        dx = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(self.wall_mirror):
            near, plane = self.boundaries.container.mirror_walls(xi)
            if near.sum() > 0:  # a loop of its own, as in pair_sums
                # Unused results named, not "_": Taichi gives one "_" a single type, and a second "_"
                # of another type (a float, then a vector) broke its compile without optimisation.
                w_self, g_self, reflected_self = self.image_sums(xi, xi, near, plane, h, scale, True)
                dx = 2.0 * lam_i * volume * h * g_self
                first, last, stride = self.grid.listed(i, neighbours)
                upcoming = self.grid.upcoming(neighbours, first, last)
                for k in range(first, last):
                    j = self.grid.neighbour(neighbours, k, upcoming)
                    upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
                    w_images, g_images, reflected = self.image_sums(xi, position(x, j), near, plane, h, scale, True)
                    images = (lam_i + self.lam[j]) * volume * h * g_images
                    dx += self.pair_term(x, xi, lam_i, j, h, scale, volume, scorr) + images
            else:
                dx = self.plain_pair_correction(x, xi, i, lam_i, neighbours, h, scale, volume, scorr)
        else:
            dx = self.plain_pair_correction(x, xi, i, lam_i, neighbours, h, scale, volume, scorr)
        return dx

    @ti.func
    def plain_pair_correction(self, x: ti.template(), xi, i, lam_i, neighbours: ti.template(), h, scale, volume, scorr):
        """:meth:`pair_correction` without mirror images."""
        dx = ti.Vector([0.0, 0.0, 0.0])
        first, last, stride = self.grid.listed(i, neighbours)
        upcoming = self.grid.upcoming(neighbours, first, last)
        for k in range(first, last):
            j = self.grid.neighbour(neighbours, k, upcoming)
            upcoming = self.grid.read_ahead(neighbours, first, last, stride, k, upcoming)
            dx += self.pair_term(x, xi, lam_i, j, h, scale, volume, scorr)
        return dx

    @ti.func
    def pair_term(self, x: ti.template(), xi, lam_i, j, h, scale, volume, scorr):
        """(λ̂_i + λ̂_j + s_corr) ĝ_ij (Eqs. 11-12); h, V and (k, 1/W(Δq)) of s_corr from the caller, which
        reads them once per particle."""
        w, grad_w = scaled_kernel_and_gradient(xi - position(x, j), scale)
        s_corr = 0.0
        if ti.static(self.with_scorr):
            s_corr = -scorr[0] * (w * scorr[1]) ** ti.static(SCORR_N)
        return (lam_i + self.lam[j] + s_corr) * volume * h * grad_w

    @ti.func
    def jacobi_step(
        self, first: ti.template(), second: ti.template(), from_second, i, neighbours: ti.template(), weight
    ):
        """x_i + Δx_i (Eqs. 11-12) from the buffer ``from_second`` picks, weighted against the
        other buffer's x_i (the iteration before) and collided with the boundaries (line 15), into that buffer."""
        h, max_correction = self.constants[None].h, self.constants[None].max_correction
        xi = self.own_position(first, second, from_second, i)
        lam_i = self.lam[i]
        dx = self.pair_correction((first, second, from_second), xi, i, lam_i, neighbours)
        earlier = second[i]
        if from_second:
            earlier = first[i]
        dx += lam_i * h * self.wall_gradient[i]  # the ghost's gradient at xi (walls_where_written)
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
        if ti.static(self.walls_where_written):
            self.wall_ghost_at(i, moved)  # for the next λ pass

    @ti.func
    def wall_ghost_at(self, i, xi):
        """On the device path (:attr:`walls_where_written`) the held-still ghost behind the walls at
        particle i's new position xi, for the λ and Δx passes that read it next; nothing on the host's."""
        if ti.static(self.walls_where_written):
            wall, wall_gradient = self.fixed_walls(xi)
            self.wall_density[i] = wall
            self.wall_gradient[i] = wall_gradient

    @ti.kernel
    def _look_up_walls(self, x: ti.template()):
        for i in range(read_count(self.grid.loop_bound, 1)):  # the bucket: no one-thread task for the bound
            if i < self.grid.active[None]:
                self.wall_ghost_at(i, x[i])

    def look_up_walls(self, x) -> None:
        """:meth:`wall_ghost_at` every live particle's position in ``x`` on the device path: after a pass
        that wrote x* anew outside the sort (the divergence pre-correction's prediction)."""
        if self.walls_where_written:
            self._look_up_walls(x)

    @ti.func
    def multiplier_pass(
        self,
        first: ti.template(),
        second: ti.template(),
        from_second,
        i,
        neighbours: ti.template(),
        measure: ti.template(),
        first_iteration,
        weight,
    ):
        """C_i and λ̂_i of particle i; with the surface ghost, in the first iteration only C_i (λ̂ waits
        for the ghost, which needs every ĝ_j: :meth:`surface_pass`)."""
        c = self.constraint(first, second, from_second, i, neighbours, first_iteration)
        if self.constants[None].surface_density:
            if first_iteration:
                self.plain_error[i] = c
            else:
                self.lagrange_multiplier(i, c + self.surface[i], measure, first_iteration, weight)
        else:
            self.lagrange_multiplier(i, c, measure, first_iteration, weight)

    @ti.func
    def surface_pass(
        self, first: ti.template(), i, neighbours: ti.template(), measure: ti.template(), first_iteration, weight
    ):
        """ψ_i and λ̂_i in a substep's first iteration, which always starts from the first buffer."""
        self.surface[i] = self.surface_ghost(first, i, neighbours)
        self.lagrange_multiplier(i, self.plain_error[i] + self.surface[i], measure, first_iteration, weight)

    @ti.kernel
    def iterate(
        self,
        first: ti.template(),
        second: ti.template(),
        from_second: ti.i32,
        neighbours: NeighbourList,
        measure: ti.template(),
        first_iteration: ti.i32,
        weight: ti.f32,
    ) -> tuple[ti.f32, ti.f32, ti.i32]:
        """One Jacobi iteration as one kernel: all λ from x, then all corrected positions, weighted
        against the other buffer (which holds the positions of the iteration before) and collided with
        the boundaries (Algorithm 1, line 15), into that buffer; x is ``second`` when ``from_second``, else
        ``first``. With ``measure`` returns Σ max(C_i, 0) as a float32 pair (high, low) and the particle
        count, from which the host forms the mean (:meth:`project`); else zeros. On a GPU backend
        ``pbf.solver.iterations`` runs the same passes in a kernel of its own.

        The buffers come in a fixed order and the direction as a flag, branched on around the neighbour
        sums only (the same way for every particle, so predicted), so that the kernel compiles once
        (``PredictedPositions``), and the wall and collision code, which obstacles make long, once in
        it. One launch, and the error comes back as its return value: a launch costs 30-100 µs on a
        2-core CPU, and reading a field from Python after a launch 40 µs more."""
        for i in range(self.grid.active[None]):
            self.multiplier_pass(first, second, from_second, i, neighbours, measure, first_iteration, weight)
        for i in range(self.surface_count(first_iteration)):  # an empty loop after the first, or without it
            self.surface_pass(first, i, neighbours, measure, first_iteration, weight)
        for i in range(self.grid.active[None]):
            self.jacobi_step(first, second, from_second, i, neighbours, weight)
        high, low = 0.0, 0.0
        if ti.static(measure):
            self.error_sum.sum(self.error, 0, self.grid.active)
            high, low = self.error_sum.high[0], self.error_sum.low[0]
        return high, low, self.grid.active[None]

    @ti.func
    def surface_count(self, first_iteration):
        """The particles the surface pass loops over: all in a substep's first iteration with the surface
        ghost on, else none."""
        return self.grid.active[None] * first_iteration * self.constants[None].surface_density

    @ti.func
    def between(self, first: ti.template(), second: ti.template(), newer_in_second, fraction, i):
        """x*_i = newer + fraction (older − newer), collided, into the first buffer, and L_i alike
        (:meth:`step_back`)."""
        newer, older = first[i], second[i]
        if newer_in_second:
            newer, older = second[i], first[i]
        first[i] = self.boundaries.project_recorded(newer + fraction * (older - newer), i, "between", fraction)
        self.lam_total[i] += fraction * (self.lam_before[i] - self.lam_total[i])

    @ti.kernel
    def _between(self, first: ti.template(), second: ti.template(), newer_in_second: ti.i32, fraction: ti.f32):
        for i in range(self.grid.active[None]):
            self.between(first, second, newer_in_second, fraction, i)

    def step_back(self, predicted, fraction: float) -> None:
        """Take back ``fraction`` of the last iteration: x* = x^{k+1} + fraction (x^k − x^{k+1}), and L
        alike, into the first buffer (the iteration before is still in the other; the collision again,
        as a point between two outside an obstacle may lie in it).

        Why (``Simulation.substep``): with an error target the count of iterations jumps by a whole one
        as the error crosses the target, and in a pool at rest, whose error hovers at the target, the
        count flips from substep to substep, a relay that kept a small tank moving at 0.6% of sqrt(g H)
        (median over six tanks; docs/VALIDATION.md). Stepping back by the fraction of the last step the
        target did not need, (target − e_k) / (e_{k−1} − e_k), makes the result continuous in the error:
        0.2%. One launch, only in substeps the target stopped after more than the least iterations."""
        self._between(predicted.first, predicted.second, predicted.in_second, fraction)
        predicted.in_second = False

    def pressure_scale(self, dt: float) -> float:
        """p_i = −ρ0 h² L_i / Δt² (Pa per unit ρ0, L_i = lam_total): matching Δx_i = h Σ_j (L_i + L_j) ĝ_ij
        with the SPH pressure acceleration −Σ_j V (p_i + p_j)/ρ0 ∇W_ij applied over Δt²."""
        return -(self.h**2) / dt**2

    def project(self, predicted, neighbours, measure: bool = False, first: bool = False, weight: float = 1.0):
        """One Jacobi iteration of the density constraint (Algorithm 1, lines 9-19) on the x* of
        ``predicted`` (a ``PredictedPositions``): reads the buffer that holds x*, writes the corrected
        positions into the other (which holds the positions of the iteration before) as
        x_prev + weight (x + Δx − x_prev), the accelerated step (``pbf.solver.acceleration``), plain
        Jacobi at weight 1, and swaps them.

        ``first`` starts the substep's sum of multipliers afresh. With ``measure``, returns the mean
        density error max(ρ/ρ0 − 1, 0) the iteration started from.
        """
        assert not (first and predicted.in_second), "a substep's x* starts in the first buffer"
        high, low, count = self._launch_iterate(
            predicted.first, predicted.second, predicted.in_second, neighbours, bool(measure), first, weight
        )
        predicted.swap()
        # The pair's sum in float64 on the host: the same mean as a float64 sum of the errors to ~1e-13.
        return (float(high) + float(low)) / max(count, 1) if measure else None
