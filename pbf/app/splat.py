"""Splats of particles: the surface style's ellipsoids (Yu & Turk, :class:`Ellipsoids`), and how either
renderer splats on a GPU backend: a thread per (particle, pixel) of the particle's footprint.

Both headless renderers project each particle to a screen rectangle and test its pixels
(``pbf.app.render.SphereRenderer``, ``pbf.app.surface_render.SurfaceRenderer``). On the CPU backend a
thread per particle walks its rectangle, column by column, in memory order (the surface: a thread per
band of rows walks the splats that reach into it). On a GPU backend that leaves threads idle behind
the few particles near the camera that cover thousands of pixels, and Mesa's software Vulkan driver
(lavapipe 22.3) loses atomic operations inside a loop whose trip count differs between threads (a
per-particle loop of 40 atomic adds kept 1 in 10 of them): its frames had holes. Here instead the
rectangles' areas are prefix-summed into a list of work items, one per (particle, pixel); each item
finds its particle by a binary search over the sums and does its one atomic at the top level of the
loop. The image does not depend on the order of the items (each pixel keeps the least key, or sums
integers), so it is the same as the CPU's loops'.
"""

import math

import taichi as ti

from pbf.solver import ExclusiveScan, NeighbourList, scene_constants


def per_item() -> bool:
    """Whether the running backend splats per item (every backend but the CPU)."""
    return ti.cfg.arch not in (ti.x64, ti.arm64)


@ti.data_oriented
class PrefixSum:
    """Exclusive prefix sums of up to ``capacity`` integers, by the solver's block tree
    (``pbf.solver.ExclusiveScan``: a few parallel passes, however many entries). Integer sums are exact, so
    the result never depends on the order threads run in."""

    def __init__(self, capacity: int):
        self.capacity = max(int(capacity), 1)
        self.values = ti.field(ti.i32, shape=self.capacity)
        self.starts = ti.field(ti.i32, shape=self.capacity + 1)
        self.tree = ExclusiveScan(self.capacity, gpu=per_item())

    @ti.func
    def put(self, k, value):
        """Entry k's value, before :meth:`scan`."""
        self.values[k] = value

    @ti.func
    def scan(self, count):
        """start(k) = Σ_{l<k} value[l] for k ≤ count; called at a kernel's top level after :meth:`put` of
        entries 0 … count − 1."""
        self.tree.scan(self.values, self.starts, count)

    @ti.func
    def start(self, k):
        """The sum of the values before entry k (k ≤ count), after :meth:`scan`."""
        return self.starts[k]


@ti.data_oriented
class Footprints:
    """Screen rectangles of up to ``capacity`` particles and the prefix sum of their areas."""

    def __init__(self, capacity: int):
        self.capacity = max(int(capacity), 1)
        self.corner = ti.Vector.field(2, ti.i32, shape=self.capacity)
        """(first column, first row) of each particle's rectangle."""
        self.width = ti.field(ti.i32, shape=self.capacity)
        self.areas = PrefixSum(self.capacity)

    @ti.func
    def set(self, k, c0, c1, r0, r1):
        """Particle k covers columns [c0, c1) and rows [r0, r1) (empty when either is)."""
        width, height = ti.max(c1 - c0, 0), ti.max(r1 - r0, 0)
        self.corner[k] = ti.Vector([c0, r0])
        self.width[k] = width
        self.areas.put(k, width * height)

    @ti.func
    def scan(self, count):
        """The areas' prefix sums, called at a kernel's top level after :meth:`set` of particles 0 … count − 1."""
        self.areas.scan(count)

    @ti.func
    def total(self, count):
        """Work items of particles 0 … count − 1, after :meth:`scan`."""
        return self.areas.start(count)

    @ti.func
    def item(self, w, count):
        """The particle slot k of work item w and its pixel (column, row)."""
        starts = ti.static(self.areas.starts)
        low, high = 0, count  # the last k with starts[k] ≤ w: its area is not empty
        while high - low > 1:
            middle = (low + high) // 2
            if starts[middle] <= w:
                low = middle
            else:
                high = middle
        local = w - starts[low]
        width = self.width[low]
        corner = self.corner[low]
        return low, corner[0] + local % width, corner[1] + local // width


SMOOTHING = 0.9
"""λ of Yu & Turk's centre smoothing: a splat's centre is (1 − λ) x_i + λ x̄_i, x̄_i the weighted mean of
the particle and its neighbours; the bumps of single particles on a surface go, a sheet keeps its place."""
AXIS_RATIO = 4.0
"""k_r: no axis of a splat is shorter than 1/k_r of its longest (the covariance's eigenvalues clamped)."""
FEW_NEIGHBOURS = 6
"""N_ε: a particle with fewer neighbours within h is a drop, drawn as a sphere of its own volume. Yu &
Turk's 25 count the neighbours within twice their kernel's support; the solver's lists hold those within h
(2 spacings: about 33 in the bulk, 17 at a flat surface, 12 in a sheet one particle thick, 2-4 along a
filament), and a sheet should stay a sheet."""
DROP_RADIUS_SPACINGS = (3.0 / (4.0 * math.pi)) ** (1.0 / 3.0)
"""A drop's sphere, in spacings: the volume of a spacing cubed (0.62)."""
ON_FLOOR_SPACINGS = 1.0
"""A drop whose particle lies within this many spacings of the floor rests on it."""
PUDDLE_HALF_THICKNESS_SPACINGS = 0.07
"""A drop resting on the floor wets it: drawn as a level disc of its volume, this thin (a half-thickness, in
spacings; its radius 1.85). Water spreading over a floor in a layer a particle deep breaks into strands and
lone particles, which as spheres read as beads scattered on the floor; as discs they join into a film."""
PUDDLE_RADIUS_SPACINGS = (DROP_RADIUS_SPACINGS**3 / PUDDLE_HALF_THICKNESS_SPACINGS) ** 0.5


@ti.func
def _unit_normal_to_rows(m, value):
    """A unit vector that (m − value I) maps to zero, for a symmetric m and its eigenvalue ``value`` of
    multiplicity one: the longest of the cross products of the matrix's rows (any unit vector where all
    vanish)."""
    shifted = m - value * ti.Matrix.identity(ti.f32, 3)
    r0, r1, r2 = (
        ti.Vector([shifted[0, 0], shifted[0, 1], shifted[0, 2]]),
        ti.Vector([shifted[1, 0], shifted[1, 1], shifted[1, 2]]),
        ti.Vector([shifted[2, 0], shifted[2, 1], shifted[2, 2]]),
    )
    best = r0.cross(r1)
    c02, c12 = r0.cross(r2), r1.cross(r2)
    if c02.norm_sqr() > best.norm_sqr():
        best = c02
    if c12.norm_sqr() > best.norm_sqr():
        best = c12
    result = ti.Vector([1.0, 0.0, 0.0])
    if best.norm_sqr() > 0.0:
        result = best / ti.sqrt(best.norm_sqr())
    return result


@ti.func
def _second_vector(m, first, value):
    """The unit eigenvector of symmetric m for eigenvalue ``value`` orthogonal to its unit eigenvector
    ``first``: the null vector of m − value I restricted to the plane normal to ``first`` (a 2 × 2
    problem, robust where two eigenvalues are close)."""
    u = ti.Vector([-first[2], 0.0, first[0]])
    if ti.abs(first[0]) <= ti.abs(first[1]):
        u = ti.Vector([0.0, first[2], -first[1]])
    u = u / ti.sqrt(u.norm_sqr())
    v = first.cross(u)
    mu, mv = m @ u, m @ v
    m00, m01, m11 = u.dot(mu) - value, u.dot(mv), v.dot(mv) - value
    result = u
    if ti.abs(m00) >= ti.abs(m11):  # the null vector of the larger row: (m00, m01) or (m01, m11)
        if ti.max(ti.abs(m00), ti.abs(m01)) > 0.0:
            a, b = _unit_pair(m00, m01)
            result = b * u - a * v
    elif ti.max(ti.abs(m11), ti.abs(m01)) > 0.0:
        a, b = _unit_pair(m11, m01)
        result = a * u - b * v
    return result


@ti.func
def _unit_pair(a, b):
    """(a, b) scaled to unit length, dividing by the larger so that nothing overflows (not both zero)."""
    x, y = a, b
    if ti.abs(x) >= ti.abs(y):
        y /= x
        x = 1.0 / ti.sqrt(1.0 + y * y)
        y *= x
    else:
        x /= y
        y = 1.0 / ti.sqrt(1.0 + x * x)
        x *= y
    return x, y


@ti.func
def symmetric_eigen(m):
    """Eigenvalues and unit eigenvectors (the matrix's columns, a rotation) of a symmetric 3 × 3 matrix,
    in closed form (Eberly 2014, "A robust eigensolver for 3 × 3 symmetric matrices",
    Geometric Tools): the eigenvalues from the trigonometric solution of the characteristic cubic, the
    eigenvector of the one farthest from the others from cross products of rows, the second within the
    plane normal to it, the third their cross product. Equal or close eigenvalues (a lattice's
    covariance) need no special case; a diagonal matrix gives its diagonal and the coordinate axes."""
    largest = ti.max(
        ti.abs(m[0, 0]), ti.abs(m[0, 1]), ti.abs(m[0, 2]), ti.abs(m[1, 1]), ti.abs(m[1, 2]), ti.abs(m[2, 2])
    )
    values = ti.Vector([m[0, 0], m[1, 1], m[2, 2]])
    vectors = ti.Matrix.identity(ti.f32, 3)
    if largest > 0.0:
        a = m / largest  # scaled: no overflow in the cubic's terms
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        if off > 0.0:
            q = (a[0, 0] + a[1, 1] + a[2, 2]) / 3.0
            b00, b11, b22 = a[0, 0] - q, a[1, 1] - q, a[2, 2] - q
            p = ti.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * off) / 6.0)
            c00 = b11 * b22 - a[1, 2] * a[1, 2]
            c01 = a[0, 1] * b22 - a[1, 2] * a[0, 2]
            c02 = a[0, 1] * a[1, 2] - b11 * a[0, 2]
            half_det = ti.min(ti.max(0.5 * (b00 * c00 - a[0, 1] * c01 + a[0, 2] * c02) / (p * p * p), -1.0), 1.0)
            angle = ti.acos(half_det) / 3.0
            beta2 = 2.0 * ti.cos(angle)
            beta0 = 2.0 * ti.cos(angle + 2.0 * math.pi / 3.0)
            beta1 = -(beta0 + beta2)
            values = q + p * ti.Vector([beta0, beta1, beta2])
            if half_det >= 0.0:  # the largest eigenvalue lies farthest from the others
                e2 = _unit_normal_to_rows(a, values[2])
                e1 = _second_vector(a, e2, values[1])
                e0 = e1.cross(e2)
                vectors = ti.Matrix.cols([e0, e1, e2])
            else:
                e0 = _unit_normal_to_rows(a, values[0])
                e1 = _second_vector(a, e0, values[1])
                e2 = e0.cross(e1)
                vectors = ti.Matrix.cols([e0, e1, e2])
            values *= largest
    return values, vectors


@ti.data_oriented
class Ellipsoids:
    """A splat per particle: an ellipsoid with the axes of the weighted covariance of its neighbours and
    its centre smoothed toward theirs (Yu & Turk 2013, "Reconstructing surfaces of particle-based fluids
    using anisotropic kernels", ACM TOG 32(1), §3-4), computed on the device from the solver's neighbour
    lists (``Simulation.neighbourhood``) once per drawn frame; or, without lists, spheres.

    With weights w_ij = 1 − (|x_j − x_i| / h)³ (j = i included, w = 1), x̄_i = Σ w x_j / Σ w and
    C_i = Σ w (x_j − x̄_i)(x_j − x̄_i)ᵀ / Σ w = R diag(σ) Rᵀ. The semi-axes are R's columns with lengths
    proportional to max(σ_k, σ_1 / k_r), scaled so that the ellipsoid has the volume of the sphere of
    ``radius_m``: in the bulk, where C is isotropic, the splat is that sphere; at a surface it is a disc
    in the surface's plane, in a sheet a disc in the sheet's, along a filament a rod. Each particle
    keeps ``inverse``, G = diag(1/a) Rᵀ, which maps the ellipsoid to the unit sphere
    (x' = G (x − c)), ``reach``, its longest semi-axis (its screen bound), and ``chord``, its volume's
    share of the sphere's (which scales the thickness its chord adds). A particle with fewer than
    ``FEW_NEIGHBOURS`` is a drop: a sphere of its volume, or on the floor (y = ``floor_y_m``) a level disc.
    """

    def __init__(self, capacity: int, radius_m: float, spacing_m: float, floor_y_m: float = -math.inf):
        self.capacity = max(int(capacity), 1)
        self.point = ti.Vector.field(3, ti.f32, shape=self.capacity)
        """The particles' positions, copied: the neighbour walk reads them from here."""
        self.centre = ti.Vector.field(3, ti.f32, shape=self.capacity)
        self.inverse = ti.Matrix.field(3, 3, ti.f32, shape=self.capacity)
        self.reach = ti.field(ti.f32, shape=self.capacity)
        self.chord = ti.field(ti.f32, shape=self.capacity)
        spacing = float(spacing_m)
        self.constants = scene_constants(
            radius=float(radius_m),
            drop=DROP_RADIUS_SPACINGS * spacing,
            on_floor=max(float(floor_y_m), -1e30) + ON_FLOOR_SPACINGS * spacing,
            puddle=(PUDDLE_RADIUS_SPACINGS * spacing, PUDDLE_HALF_THICKNESS_SPACINGS * spacing),
        )
        """The sphere's radius and a drop's, the height below which a drop rests on the floor, and a puddle's
        radius and half-thickness, m (data: another spacing compiles nothing)."""

    @ti.kernel
    def spheres(self, x: ti.template(), count: ti.i32):
        """Every splat the sphere of ``radius`` at its particle."""
        radius = self.constants[None].radius
        for i in range(count):
            self.centre[i] = x[i]
            self.inverse[i] = ti.Matrix.identity(ti.f32, 3) / radius
            self.reach[i] = radius
            self.chord[i] = 1.0

    @ti.func
    def pair(self, i, j, acc: ti.template()):
        """Neighbour j's weight, weighted offset and weighted outer product (its upper triangle) into
        ``acc``, and a count of the neighbours within h (the lists were built a little earlier)."""
        d = self.point[j] - self.point[i]
        q = d.norm() * acc[10]  # acc[10]: 1/h, set by the caller
        if q < 1.0:
            w = 1.0 - q * q * q
            wd = w * d
            acc += ti.Vector(
                [w, wd.x, wd.y, wd.z, wd.x * d.x, wd.x * d.y, wd.x * d.z, wd.y * d.y, wd.y * d.z, wd.z * d.z, 0.0, 1.0]
            )

    @ti.kernel
    def anisotropic(self, grid: ti.template(), x: ti.template(), entries: NeighbourList, count: ti.i32, h: ti.f32):
        """Every splat from the neighbour lists ``entries`` of ``grid`` (``pbf.solver.Neighbourhood``),
        positions ``x``."""
        for i in range(count):
            self.point[i] = x[i]
        c = self.constants[None]
        radius, drop = c.radius, c.drop
        for i in range(count):
            # The particle itself (w = 1, offset 0), then its neighbours; offsets from x_i keep float32's
            # digits for the covariance (positions are metres, offsets a few centimetres).
            acc = ti.Vector([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0 / h, 0.0])
            grid.for_each_neighbour(i, entries, self.pair, acc)
            total = acc[0]
            mean = ti.Vector([acc[1], acc[2], acc[3]]) / total
            centre = self.point[i] + SMOOTHING * mean
            inverse = ti.Matrix.identity(ti.f32, 3) / drop
            reach, chord = drop, (radius / drop) ** 3
            if acc[11] >= FEW_NEIGHBOURS:
                second = ti.Matrix(
                    [[acc[4], acc[5], acc[6]], [acc[5], acc[7], acc[8]], [acc[6], acc[8], acc[9]]]
                ) / total - mean.outer_product(mean)
                # In closed form: Taichi's iterative ti.sym_eig never returned on a lattice's covariance
                # (equal eigenvalues), and its SVD's Jacobi sweeps took most of this kernel's time.
                sigma, axes = symmetric_eigen(second)
                largest = ti.max(sigma[0], sigma[1], sigma[2])
                if largest > 0.0:
                    floor = largest / AXIS_RATIO
                    s = ti.Vector([ti.max(sigma[0], floor), ti.max(sigma[1], floor), ti.max(sigma[2], floor)])
                    # Semi-axes ∝ σ with the sphere's volume: a_k = r σ_k / (σ_1 σ_2 σ_3)^(1/3).
                    scale = radius / ti.pow(s[0] * s[1] * s[2], 1.0 / 3.0)
                    a = s * scale
                    inverse = ti.Matrix([[1.0 / a[0], 0.0, 0.0], [0.0, 1.0 / a[1], 0.0], [0.0, 0.0, 1.0 / a[2]]])
                    inverse = inverse @ axes.transpose()
                    reach, chord = ti.max(a[0], a[1], a[2]), 1.0
            elif self.point[i].y < c.on_floor:  # a drop on the floor: a puddle of its volume, as thick anywhere
                inverse = ti.Matrix(
                    [[1.0 / c.puddle[0], 0.0, 0.0], [0.0, 1.0 / c.puddle[1], 0.0], [0.0, 0.0, 1.0 / c.puddle[0]]]
                )
                reach = c.puddle[0]
            self.centre[i] = centre
            self.inverse[i] = inverse
            self.reach[i] = reach
            self.chord[i] = chord

    def update(self, positions, count: int, neighbourhood=None, velocities=None, exposure_s: float = 0.0) -> None:
        """The splats of the ``count`` particles at ``positions``: anisotropic from ``neighbourhood``
        (a ``pbf.solver.Neighbourhood`` of these positions), spheres without; with ``velocities``, each
        drop stretched along its velocity over ``exposure_s`` (motion blur)."""
        if not count:
            return
        if neighbourhood is None:
            self.spheres(positions, count)
        else:
            self.anisotropic(
                neighbourhood.grid, positions, neighbourhood.entries, count, float(neighbourhood.support_m)
            )
            if velocities is not None and exposure_s > 0.0:
                self.blurred(velocities, count, exposure_s)

    @ti.kernel
    def blurred(self, v: ti.template(), count: ti.i32, exposure: ti.f32):
        """Each drop (a splat of the drop's radius) an ellipsoid along its velocity: semi-axes the drop's radius
        across and that plus half the distance it moves in the exposure along, its chord scaled so that it
        holds the same volume of water. A camera sees a moving drop as a streak, not a bead."""
        drop = self.constants[None].drop
        for i in range(count):
            travel = 0.5 * exposure * v[i].norm()
            if self.reach[i] == drop and travel > 0.05 * drop:
                along = v[i].normalized()
                length = drop + travel
                projector = along.outer_product(along)
                self.inverse[i] = (ti.Matrix.identity(ti.f32, 3) - projector) / drop + projector / length
                self.reach[i] = length
                self.chord[i] *= drop / length

    @ti.func
    def frame(self, i, eye, right, up, forward):
        """Splat i's view in its own frame x' = G (x − c): G (c − eye) and the images G right, G up and
        G forward of the camera's axes, from which :meth:`row` and :meth:`hit` test a pixel with a few
        products (computed once per splat, not per pixel)."""
        inverse = self.inverse[i]
        return inverse @ (self.centre[i] - eye), inverse @ right, inverse @ up, inverse @ forward

    @ti.func
    def row(self, seen, w):
        """The rays eye + t (u right + w up + forward) of one image row (w fixed) against a splat seen as
        :meth:`frame` gives it, as polynomials in u: in the splat's frame the ray is G (eye − c) + t g(u),
        g(u) = u G right + (w G up + G forward), and the splat the unit sphere, which the ray meets where
        t² |g|² − 2 t g·o + |o|² − 1 = 0 (o = G (c − eye)). Returned: the coefficients of |g|² (quadratic),
        of g·o (linear) and of the discriminant (g·o)² − |g|² (|o|² − 1) = |g|² − |g × o|² (quadratic:
        written with the cross product, which keeps float32's digits where the splat is small against
        its distance, instead of the difference of two terms of about |o|² |g|² each), and the interval
        of u where that is positive: the splat's span on the row (empty, lower > upper, where it misses)."""
        offset, along_right, along_up, along_forward = seen[0], seen[1], seen[2], seen[3]
        p = along_up * w + along_forward
        right_o, p_o = along_right.cross(offset), p.cross(offset)
        a = ti.Vector([along_right.norm_sqr(), 2.0 * along_right.dot(p), p.norm_sqr()])
        b = ti.Vector([along_right.dot(offset), p.dot(offset)])
        d = ti.Vector([a[0] - right_o.norm_sqr(), a[1] - 2.0 * right_o.dot(p_o), a[2] - p_o.norm_sqr()])
        lower, upper = 1.0, -1.0
        # The splat lies wholly in front of the eye (the caller's bound), so its outline is an ellipse and
        # d[0] < 0; the roots by the form without cancellation (q = −(d₁ + sign(d₁) √Δ) / 2: q / d₀, d₂ / q).
        discriminant = d[1] * d[1] - 4.0 * d[0] * d[2]
        if d[0] < 0.0 and discriminant > 0.0:
            q = -0.5 * (d[1] + ti.select(d[1] < 0.0, -1.0, 1.0) * ti.sqrt(discriminant))
            first, second = q / d[0], d[2] / q
            lower, upper = ti.min(first, second), ti.max(first, second)
        return a, b, d, lower, upper

    @ti.func
    def hit(self, a, b, d, u, w):
        """Where the ray of column u on row w (a, b, d: :meth:`row`'s coefficients) first meets the splat:
        (t, the view depth, or -1 where it misses; the chord it cuts, m)."""
        disc = (d[0] * u + d[1]) * u + d[2]
        t, chord = -1.0, 0.0
        if disc > 0.0:
            length = (a[0] * u + a[1]) * u + a[2]
            root = ti.sqrt(disc)
            t = (b[0] * u + b[1] - root) / length
            chord = 2.0 * root / length * ti.sqrt(u * u + w * w + 1.0)
        return t, chord
