"""White water: spray, foam and air bubbles as diffuse particles, a post-process of the fluid's particles.

A dam break of 8,000 particles cannot resolve its splash: a drop of that water is 2.5 cm across. As
real-time fluids do (NVIDIA FleX's diffuse particles), the renderer supplies the detail the simulation
cannot, after Ihmsen, Akinci, Akinci & Teschner 2012 ("Unified spray, foam and air bubbles for
particle-based fluids", The Visual Computer 28). Once per drawn frame, on the device:

1. *Potentials* of every fluid particle i, from the solver's neighbour lists (``Simulation.neighbourhood``),
   with w(r) = 1 − r/h:
   - trapped air, I_ta = Σ_j |v_ij| (1 − v̂_ij · x̂_ij) w(x_ij) (Eq. 2 of the paper): water moving into water;
   - wave crests, I_wc = Σ_j (1 − n̂_i · n̂_j) w(x_ij) over the neighbours behind a surface particle's normal
     n̂_i (a convex surface), where the particle moves along its normal (v̂_i · n̂_i ≥ 0.6; Eqs. 4-6);
   - kinetic energy, E_k = ½ |v_i|² per unit mass (Eq. 7).
   Each is clamped to [0, 1] between two thresholds, Φ(I) = (min(I, τ_max) − min(I, τ_min)) / (τ_max − τ_min)
   (Eq. 1), with the thresholds in units of the scene's own scales: speeds in √(g h), energies in g h. A
   particle emits Φ_k (k_ta Φ_ta + k_wc Φ_wc) Δt diffuse particles (Eq. 8), rates in units of √(g / h):
   whole ones, and the fraction with that probability, drawn from a hash of the frame and the particle.
   Water at rest has no kinetic energy to give, so it makes no white water.
2. *Emission* into a fixed budget: the particles' counts are prefix-summed (exactly: integers) and the new
   diffuse particles placed in that order in a cylinder around their emitter along its velocity (§4.2);
   what does not fit waits (it is counted in ``waiting``, nothing is overwritten).
3. *Classification and motion* by how much water surrounds a diffuse particle (§5): the fluid's count and
   momentum are splatted to a grid of cells at least h wide, with integer atomics (order-free, so the
   same on every run), and read back trilinearly. Little water around it: *spray*, ballistic under
   gravity with air drag. Some: *foam*, carried by the water's velocity, and the only kind that ages (it
   dies after about ``white_water.lifetime_s``). Deep in it: *bubbles*, rising by buoyancy and dragged
   towards the water's velocity. A diffuse particle that leaves the container dies.

The renderer (``pbf.app.surface_render``) draws them as soft white sprites stretched along their velocity
over the frame's exposure. Nothing here changes the simulation; the same scene on the same backend gives
the same white water, bit for bit.
"""

import math
import numbers

import numpy as np
import taichi as ti

from pbf.app.splat import Footprints, PrefixSum
from pbf.solver import NeighbourList, scene_constants
from pbf.solver import allocation as bucket

SPRAY, FOAM, BUBBLE = 0, 1, 2
"""The kinds of diffuse particle (``kind``)."""
TRAPPED_AIR = (1.0, 4.0)
"""τ_min, τ_max of the trapped-air potential, in √(g h)."""
WAVE_CREST = (0.6, 2.0)
"""τ_min, τ_max of the wave-crest potential (a sum of weights, without units)."""
KINETIC = (1.0, 8.0)
"""τ_min, τ_max of the kinetic energy per unit mass, in g h."""
RATE_TRAPPED_AIR = 2.0
RATE_WAVE_CREST = 2.0
"""k_ta and k_wc: diffuse particles a fluid particle emits per √(h / g) at full potential."""
MOST_PER_FRAME = 8
"""The most diffuse particles one fluid particle emits in a frame."""
CREST_ALIGNMENT = 0.6
"""A crest emits only where the particle moves along its normal: v̂ · n̂ at least this."""
SURFACE_NORMAL = 1.0
"""A fluid particle is at the surface where |Σ_j x̂_ij w(x_ij)| (its neighbours lopsided) is at least this."""
SPRAY_BELOW, BUBBLE_ABOVE = 0.15, 0.6
"""The classes, by the water around a diffuse particle as a share of the bulk's: spray below the first
(Ihmsen et al.'s 6 of about 35 neighbours), bubbles above the second (their 20)."""
TERMINAL_SPEED = 12.0
"""Spray's air drag: its terminal speed, in √(g h)."""
BUOYANCY = 2.0
"""A bubble's upward acceleration, in g (against the water's drag)."""
BUBBLE_DRAG = 1.5
"""How fast a bubble takes the water's velocity, per √(h / g)."""
FOAM_DRAG = 8.0
"""How fast foam takes the water's velocity, per √(h / g): fast enough to ride the surface."""
SPRAY_AGEING, BUBBLE_AGEING = 0.25, 0.25
"""Spray and bubbles age slower than foam (Ihmsen et al.: not at all), so that none lives for ever."""
SPREAD = 0.5
"""A new diffuse particle's velocity differs from its emitter's by up to this, in √(g h)."""
CELL_FLOOR = 2**12
"""The fewest grid cells allocated (a bucket: other scenes find the kernels compiled)."""
MOST_CELLS_PER_PARTICLE = 8
"""The grid's cells grow past h where the container would otherwise need more than this many per fluid particle."""
WEIGHT_STEPS = 256
"""Fixed-point steps of a fluid particle's weight in the grid (its 8 cells' weights sum to 256)."""
SPEED_STEPS = 1000
"""Fixed-point steps per √(g h) of the grid's momentum; speeds are clamped to ±SPEED_LIMIT of these."""
SPEED_LIMIT = 2**16
BYTES_PER_PARTICLE = 4 * (3 + 3 + 1 + 1 + 1) * 2 + 4 * 3
"""Device memory per diffuse particle: position, velocity, age, life and kind, twice (compaction), and
the alive flags' prefix sums."""


@ti.func
def _hash(value):
    """A 32-bit integer hash (PCG's output permutation of one LCG step)."""
    state = value * ti.u32(747796405) + ti.u32(2891336453)
    word = ((state >> ((state >> ti.u32(28)) + ti.u32(4))) ^ state) * ti.u32(277803737)
    return (word >> ti.u32(22)) ^ word


@ti.func
def _uniform(frame, i, k, salt):
    """A number in [0, 1) from the frame, the fluid particle, the draw and a salt: the same on every run."""
    h = _hash(ti.cast(frame, ti.u32) ^ _hash(ti.cast(i, ti.u32) ^ _hash(ti.cast(k * 8 + salt, ti.u32))))
    return ti.cast(h >> ti.u32(8), ti.f32) * (1.0 / 16777216.0)


@ti.func
def _clamped(value, low, high):
    """Eq. (1): the potential's share between its thresholds, in [0, 1]."""
    return (ti.min(value, high) - ti.min(value, low)) / (high - low)


def budget_of(scene) -> int:
    """The most diffuse particles at once: ``white_water.budget``, or twice the fluid's particle capacity."""
    return scene.white_water.budget or 2 * scene.particle_capacity


@ti.data_oriented
class WhiteWater:
    """The diffuse particles of one Simulation, advanced once per frame the simulation advanced (:meth:`sync`)."""

    def __init__(self, sim, budget: int | None = None):
        """``budget``: the most diffuse particles at once (default ``budget_of(sim.scene)``)."""
        scene = sim.scene
        self.sim = sim
        if budget is not None and (isinstance(budget, bool) or not isinstance(budget, numbers.Integral) or budget < 1):
            raise ValueError(f"WhiteWater: budget: expected a whole number of particles ≥ 1, got {budget!r}")
        self.budget = budget_of(scene) if budget is None else int(budget)
        slots = bucket(self.budget, 2**10)
        self.position = ti.Vector.field(3, ti.f32, shape=slots)
        self.velocity = ti.Vector.field(3, ti.f32, shape=slots)
        self.age = ti.field(ti.f32, shape=slots)
        self.life = ti.field(ti.f32, shape=slots)
        """Seconds lived (foam at full rate, spray and bubbles slower) and the age it dies at."""
        self.kind = ti.field(ti.i32, shape=slots)
        """SPRAY, FOAM or BUBBLE, as classified at the last advance."""
        self.scratch = ti.field(ti.f32, shape=(slots, 9))
        """Compaction's scratch: position, velocity, age, life and kind of each survivor and newcomer."""
        self.alive = PrefixSum(slots)
        fluid = sim.model.allocated
        self.emitted = PrefixSum(fluid)
        self.sorted_x = ti.Vector.field(3, ti.f32, shape=fluid)
        self.sorted_v = ti.Vector.field(3, ti.f32, shape=fluid)
        """The fluid's positions and velocities, copied: the neighbour walk's tasks read them from here."""
        self.normal = ti.Vector.field(4, ti.f32, shape=fluid)
        """Per fluid particle: Σ_j x̂_ij w(x_ij) (its outward normal, unnormalised) and |that|."""
        self.near_fast = ti.field(ti.i32, shape=fluid)
        """1 for a fluid particle fast enough to emit and for its neighbours: the particles whose normals
        the wave crests read (the rest of the water is not walked for them)."""
        self.live = ti.field(ti.i32, shape=())
        self.waiting = ti.field(ti.i32, shape=())
        """Diffuse particles alive, and those the last emission could not place (the budget full)."""
        lower = np.array(scene.container.min_m, np.float64)
        upper = np.array(scene.container.max_m, np.float64)
        h = scene.kernel_radius_m
        extent = upper - lower
        cell = max(h, float(np.prod(extent) / (MOST_CELLS_PER_PARTICLE * scene.particle_capacity)) ** (1 / 3))
        resolution = np.maximum(np.ceil(extent / cell).astype(int) + 1, 2)  # nodes on cell corners
        self.nodes = int(np.prod(resolution))
        cells = bucket(self.nodes, CELL_FLOOR)
        self.weight = ti.field(ti.i32, shape=cells)
        self.momentum = ti.Vector.field(3, ti.i32, shape=cells)
        """The grid: the fluid's weight and momentum at each node, fixed-point (``WEIGHT_STEPS``, ``SPEED_STEPS``)."""
        g = float(np.linalg.norm(scene.gravity_m_s2))
        speed = max(math.sqrt(g * h), 0.1 * h / scene.time.frame_dt_s)  # √(g h); without gravity, from h and Δt
        rate = speed / h  # 1 / the time scale √(h / g)
        spacing = scene.fluid.spacing_m
        self.constants = scene_constants(
            lower=tuple(float(c) for c in lower),
            upper=tuple(float(c) for c in upper),
            resolution=tuple(int(c) for c in resolution),
            nodes=self.nodes,
            inverse_cell=1.0 / cell,
            # What a node of the grid holds in the bulk, in WEIGHT_STEPS: (cell / spacing)³ particles.
            inverse_bulk=1.0 / (WEIGHT_STEPS * (cell / spacing) ** 3),
            h=float(h),
            spacing=float(spacing),
            speed=float(speed),
            inverse_speed=1.0 / speed,
            rate=float(rate * scene.white_water.amount),
            drag=float(g / (TERMINAL_SPEED * speed)),
            drag_rate=float(rate),
            gravity=tuple(float(c) for c in scene.gravity_m_s2),
            lifetime=float(scene.white_water.lifetime_s),
            budget=self.budget,
        )
        """The scene's scales and sizes, as data (``pbf.solver.scene_constants``)."""
        self.frame = None
        self.restarts = None
        """The simulation's frame and restart count the white water stands at (None: not started)."""

    def clear(self) -> None:
        self.live[None] = 0
        self.waiting[None] = 0

    def sync(self) -> None:
        """Advance to the simulation's frame: one frame of emission and motion per frame it advanced since
        the last call; after a reset or a restore, start again without white water."""
        sim = self.sim
        if self.restarts != sim.restarts or self.frame is None or sim.frame < self.frame:
            self.clear()
            self.frame, self.restarts = sim.frame, sim.restarts
            return
        if sim.frame == self.frame:
            return
        dt = sim.scene.time.frame_dt_s
        particles = sim.readout()
        neighbourhood = sim.neighbourhood()
        for _ in range(sim.frame - self.frame - 1):  # frames stepped without a draw: motion only
            self._advance(particles.positions, particles.velocities, particles.count, dt)
        self._advance(particles.positions, particles.velocities, particles.count, dt)
        self._emit(
            neighbourhood.grid,
            particles.positions,
            particles.velocities,
            neighbourhood.entries,
            particles.count,
            dt,
            sim.frame,
        )
        self.frame = sim.frame

    def counts(self) -> tuple[int, int]:
        """(diffuse particles alive, emissions waiting for room), read from the device."""
        return int(self.live[None]), int(self.waiting[None])

    def arrays(self) -> dict[str, np.ndarray]:
        """The live diffuse particles on the host: positions (m), velocities (m/s), kind (0 spray, 1 foam,
        2 bubble) and age (s)."""
        n = int(self.live[None])
        return {
            "positions": self.position.to_numpy()[:n],
            "velocities": self.velocity.to_numpy()[:n],
            "kind": self.kind.to_numpy()[:n],
            "age": self.age.to_numpy()[:n],
        }

    # ------------------------------------------------------------------ the grid of the fluid

    @ti.func
    def _corner(self, x):
        """The grid node below x and x's offset from it in cells, the node clamped into the grid."""
        c = self.constants[None]
        g = (x - c.lower) * c.inverse_cell
        base = ti.cast(ti.floor(g), ti.i32)
        base = ti.max(0, ti.min(base, c.resolution - 2))
        return base, ti.min(ti.max(g - base, 0.0), 1.0)

    @ti.func
    def _node(self, n):
        resolution = self.constants[None].resolution
        return (n[0] * resolution[1] + n[1]) * resolution[2] + n[2]

    @ti.func
    def _splat_fluid(self, x: ti.template(), v: ti.template(), count):
        """The fluid's weight and momentum onto the grid's nodes, trilinearly, with integer atomics."""
        for n in range(self.constants[None].nodes):
            self.weight[n] = 0
            self.momentum[n] = ti.Vector([0, 0, 0])
        for i in range(count):
            base, f = self._corner(x[i])
            scaled = ti.max(
                ti.min(v[i] * (SPEED_STEPS * self.constants[None].inverse_speed), SPEED_LIMIT), -SPEED_LIMIT
            )
            steps = ti.cast(ti.round(scaled), ti.i32)
            for dx, dy, dz in ti.static(ti.ndrange(2, 2, 2)):
                w = (f.x if dx else 1.0 - f.x) * (f.y if dy else 1.0 - f.y) * (f.z if dz else 1.0 - f.z)
                q = ti.cast(ti.round(w * WEIGHT_STEPS), ti.i32)
                if q > 0:
                    node = self._node(base + ti.Vector([dx, dy, dz]))
                    ti.atomic_add(self.weight[node], q)
                    ti.atomic_add(self.momentum[node], q * steps)

    @ti.func
    def _water_at(self, x):
        """(The water around x as a share of the bulk's, the water's velocity there in m/s)."""
        c = self.constants[None]
        base, f = self._corner(x)
        weight, momentum = 0.0, ti.Vector([0.0, 0.0, 0.0])
        for dx, dy, dz in ti.static(ti.ndrange(2, 2, 2)):
            w = (f.x if dx else 1.0 - f.x) * (f.y if dy else 1.0 - f.y) * (f.z if dz else 1.0 - f.z)
            node = self._node(base + ti.Vector([dx, dy, dz]))
            weight += w * ti.cast(self.weight[node], ti.f32)
            momentum += w * ti.cast(self.momentum[node], ti.f32)
        velocity = ti.Vector([0.0, 0.0, 0.0])
        if weight > 0.0:
            velocity = momentum / weight * (c.speed / SPEED_STEPS)
        return weight * c.inverse_bulk, velocity

    # ------------------------------------------------------------------ motion

    @ti.kernel
    def _advance(self, x: ti.template(), v: ti.template(), count: ti.i32, dt: ti.f32):
        """Each diffuse particle classified by the water around it and moved by its kind's rule (step 3)."""
        self._splat_fluid(x, v, count)
        c = self.constants[None]
        g = c.gravity
        for p in range(self.live[None]):
            water, flow = self._water_at(self.position[p])
            kind = FOAM
            if water < SPRAY_BELOW:
                kind = SPRAY
            elif water > BUBBLE_ABOVE:
                kind = BUBBLE
            u = self.velocity[p]
            ageing = 1.0
            if kind == SPRAY:  # ballistic, with air drag
                u = (u + dt * g) / (1.0 + dt * c.drag * u.norm())
                ageing = SPRAY_AGEING
            elif kind == FOAM:  # carried by the water
                u = flow + (u - flow) * ti.exp(-FOAM_DRAG * c.drag_rate * dt)
            else:  # rising through the water, dragged towards its velocity
                u = u - BUOYANCY * dt * g
                u = flow + (u - flow) * ti.exp(-BUBBLE_DRAG * c.drag_rate * dt)
                ageing = BUBBLE_AGEING
            self.velocity[p] = u
            self.position[p] += dt * u
            self.kind[p] = kind
            self.age[p] += ageing * dt

    # ------------------------------------------------------------------ emission

    @ti.func
    def _fast(self, i):
        """Whether fluid particle i is above the kinetic energy's lowest threshold: without it a particle
        emits nothing (Eq. 8), and its potentials are not needed."""
        c = self.constants[None]
        speed = self.sorted_v[i].norm()
        return 0.5 * speed * speed * c.inverse_speed * c.inverse_speed > KINETIC[0]

    @ti.func
    def _mark(self, i, j, acc: ti.template()):
        self.near_fast[j] = 1

    @ti.func
    def _lopsided(self, i, j, acc: ti.template()):
        """Neighbour j's unit offset, weighted by w = 1 − r/h, into ``acc`` (the normal's sum)."""
        d = self.sorted_x[i] - self.sorted_x[j]
        r = d.norm()
        if 0.0 < r < self.constants[None].h:
            acc += d / r * (1.0 - r / self.constants[None].h)

    @ti.func
    def _potential_pair(self, i, j, acc: ti.template()):
        """Neighbour j's share of particle i's trapped-air (acc[0]) and wave-crest (acc[1]) potentials."""
        h = self.constants[None].h
        d = self.sorted_x[i] - self.sorted_x[j]
        r = d.norm()
        if 0.0 < r < h:
            w = 1.0 - r / h
            dv = self.sorted_v[i] - self.sorted_v[j]
            speed = dv.norm()
            if speed > 0.0:
                acc[0] += speed * (1.0 - dv.dot(d) / (speed * r)) * w  # Eq. (2)
            n_i, n_j = self.normal[i], self.normal[j]
            a = ti.Vector([n_i[0], n_i[1], n_i[2]])
            b = ti.Vector([n_j[0], n_j[1], n_j[2]])
            # Eqs. (4)-(5): a convex surface, neighbours behind the normal (x̂_ji · n̂_i < 0).
            if n_i[3] >= SURFACE_NORMAL and n_j[3] > 0.0 and d.dot(a) > 0.0:
                acc[1] += (1.0 - a.dot(b) / (n_i[3] * n_j[3])) * w

    @ti.kernel
    def _emit(
        self,
        grid: ti.template(),
        x: ti.template(),
        v: ti.template(),
        entries: NeighbourList,
        count: ti.i32,
        dt: ti.f32,
        frame: ti.i32,
    ):
        """Steps 1 and 2: the survivors compacted in order, then each fluid particle's new diffuse particles
        after them, as many as the budget has room for."""
        c = self.constants[None]
        for i in range(count):
            self.sorted_x[i] = x[i]
            self.sorted_v[i] = v[i]
            self.near_fast[i] = 0
        for i in range(count):
            if self._fast(i):
                self.near_fast[i] = 1
                grid.for_each_neighbour(i, entries, self._mark, 0)
        for i in range(count):
            acc = ti.Vector([0.0, 0.0, 0.0])
            if self.near_fast[i]:
                grid.for_each_neighbour(i, entries, self._lopsided, acc)
            self.normal[i] = ti.Vector([acc.x, acc.y, acc.z, acc.norm()])
        for i in range(count):
            u = self.sorted_v[i]
            speed = u.norm()
            acc = ti.Vector([0.0, 0.0])
            if self._fast(i):
                grid.for_each_neighbour(i, entries, self._potential_pair, acc)
            normal = self.normal[i]
            crest = 0.0
            outward = ti.Vector([normal[0], normal[1], normal[2]])
            if normal[3] >= SURFACE_NORMAL and speed > 0.0 and u.dot(outward) >= CREST_ALIGNMENT * speed * normal[3]:
                crest = acc[1]  # Eq. (6)
            energy = 0.5 * speed * speed * c.inverse_speed * c.inverse_speed  # Eq. (7), in g h
            wanted = (
                _clamped(energy, KINETIC[0], KINETIC[1])
                * (
                    RATE_TRAPPED_AIR * _clamped(acc[0] * c.inverse_speed, TRAPPED_AIR[0], TRAPPED_AIR[1])
                    + RATE_WAVE_CREST * _clamped(crest, WAVE_CREST[0], WAVE_CREST[1])
                )
                * (c.rate * dt)
            )  # Eq. (8)
            n = ti.cast(ti.floor(wanted + _uniform(frame, i, 0, 0)), ti.i32)
            self.emitted.put(i, ti.min(n, MOST_PER_FRAME))
        live = self.live[None]
        for p in range(live):
            survives = self.age[p] < self.life[p]
            for a in ti.static(range(3)):
                survives = survives and c.lower[a] <= self.position[p][a] <= c.upper[a]
            self.alive.put(p, ti.select(survives, 1, 0))
        self.alive.scan(live)
        self.emitted.scan(count)
        kept = self.alive.start(live)
        room = c.budget - kept
        for p in range(live):
            if self.alive.start(p + 1) > self.alive.start(p):
                self._keep(
                    self.alive.start(p), self.position[p], self.velocity[p], self.age[p], self.life[p], self.kind[p]
                )
        for i in range(count):
            first = self.emitted.start(i)
            n = self.emitted.start(i + 1) - first
            u = self.sorted_v[i]
            speed = u.norm()
            along = ti.Vector([0.0, 1.0, 0.0])
            if speed > 0.0:
                along = u / speed
            side = along.cross(ti.Vector([1.0, 0.0, 0.0]))
            if side.norm() < 0.1:
                side = along.cross(ti.Vector([0.0, 0.0, 1.0]))
            side = side.normalized()
            other = along.cross(side)
            for k in range(n):
                if first + k < room:
                    # Uniformly in a cylinder of radius spacing/2 along the velocity, as far as a frame moves it.
                    radius = ti.sqrt(_uniform(frame, i, k, 1))
                    angle = 2.0 * math.pi * _uniform(frame, i, k, 2)
                    across = ti.cos(angle) * side + ti.sin(angle) * other
                    place = self.sorted_x[i] + 0.5 * c.spacing * radius * across + _uniform(frame, i, k, 3) * dt * u
                    place = ti.min(ti.max(place, c.lower), c.upper)
                    velocity = u + SPREAD * c.speed * radius * across
                    life = c.lifetime * (0.5 + _uniform(frame, i, k, 4))
                    self._keep(kept + first + k, place, velocity, 0.0, life, FOAM)
        wanted = self.emitted.start(count)
        placed = ti.min(wanted, room)
        self.waiting[None] = wanted - placed
        total = kept + placed
        self.live[None] = total
        row = ti.static(self.scratch)
        for p in range(total):
            self.position[p] = ti.Vector([row[p, 0], row[p, 1], row[p, 2]])
            self.velocity[p] = ti.Vector([row[p, 3], row[p, 4], row[p, 5]])
            self.age[p] = row[p, 6]
            self.life[p] = row[p, 7]
            self.kind[p] = ti.cast(row[p, 8], ti.i32)

    @ti.func
    def _keep(self, slot, position, velocity, age, life, kind):
        row = ti.static(self.scratch)
        for a in ti.static(range(3)):
            row[slot, a] = position[a]
            row[slot, 3 + a] = velocity[a]
        row[slot, 6] = age
        row[slot, 7] = life
        row[slot, 8] = ti.cast(kind, ti.f32)


SPRITE_RADIUS_SPACINGS = (0.15, 0.2, 0.12)
"""A sprite's radius (its Gaussian's σ) for spray, foam and bubbles, in spacings: white water is finer
than the fluid's particles."""
BRIGHTNESS = (1.2, 0.8, 0.45)
"""A sprite's peak opacity (before overlap) for spray, foam and bubbles: foam gathers into sheets, bubbles
are seen through water."""
MIN_SIGMA_PX = 0.7
"""No sprite is narrower than this on screen (pixels): a smaller one keeps its total brightness, spread."""
SEEN_THROUGH_SPACINGS = 3.0
"""Behind the water's surface a sprite fades by e every this many spacings of water in front of it."""
REACH_SIGMAS = 2.0
"""A sprite reaches this many σ from its streak (its bump (1 − d²/R²)² has about σ's width)."""
HIDDEN_SEEN_THROUGH = 5.0
"""A sprite whose centre lies deeper behind the surface than this many SEEN_THROUGH_SPACINGS (it would show
at under e⁻⁵ of its brightness) is not drawn."""
OPACITY_STEPS = 4096
"""Fixed-point steps of opacity in the sprites' sum (integer atomics: the same image on every run)."""
WHITE_RGB = (0.96, 0.98, 1.0)
FAINTEST = 8
"""The least opacity sum (in OPACITY_STEPS) one of the four coarse pixels around a frame's pixel needs for it
to be whitened at all: below it on all four, 1 − exp(−Σ) is under half a level of an 8-bit channel."""


@ti.func
def _within(low, high, reach, size):
    """The pixels [first, end) of a row or column of ``size`` whose centres (k + ½) lie less than ``reach``
    from [low, high]: the only ones a sprite's bump, which is 0 at its reach, adds to."""
    first = ti.max(ti.cast(ti.floor(low - reach - 0.5), ti.i32) + 1, 0)
    end = ti.min(ti.cast(ti.floor(high + reach - 0.5), ti.i32) + 1, size)
    return first, end


@ti.data_oriented
class Sprites:
    """White water drawn into a surface frame: each diffuse particle a soft white sprite (a Gaussian of its
    kind's radius) stretched along its screen velocity over the exposure (motion blur: a streak keeps the
    sprite's total brightness), depth-tested against the water's surface and seen through it dimmed by
    the water in front. The opacities add up as integers per pixel of the surface renderer's coarse image
    (half the frame's width and height: the sprites are soft, and a quarter of the pixels costs a quarter).
    The surface renderer's compose then whitens each pixel of the frame by 1 − exp(−Σ) (:meth:`share`), Σ
    interpolated bilinearly, so dense foam saturates to white and a lone drop stays faint."""

    def __init__(self, width_px: int, height_px: int, spacing_m: float, per_item: bool):
        """``width_px`` × ``height_px``: the sums' size, the surface renderer's coarse image."""
        self.width, self.height = int(width_px), int(height_px)
        self.opacity = ti.field(ti.i32, shape=(self.height, self.width))
        self.row_used = ti.field(ti.i32, shape=self.height)
        """1 where a row of the sums holds any opacity: a frame's pixel between two other rows costs two reads."""
        self.per_item = per_item
        self.footprints = None
        self.seen = None
        """Per sprite on a GPU's path: its streak's ends on screen, σ and peak (``_sprite``'s), worked out once
        for all the pixels of its rectangle (a body in front costs a ray cast)."""
        self.constants = scene_constants(spacing=float(spacing_m))

    @ti.func
    def _project(self, p, eye, right, up, forward, focal):
        """(column, row, view depth) of world point p; depth ≤ 0 behind the eye."""
        c = p - eye
        depth = c.dot(forward)
        safe = ti.max(depth, 1e-6)
        return ti.Vector(
            [0.5 * self.width + focal * c.dot(right) / safe, 0.5 * self.height - focal * c.dot(up) / safe, depth]
        )

    @ti.func
    def _sprite(self, ww: ti.template(), front: ti.template(), p, eye, right, up, forward, focal, exposure):
        """Diffuse particle p on screen: its streak's ends (column, row, depth), σ in pixels and peak opacity,
        dimmed by the water in front of its centre (``front.front_depth`` there, the nearest water or body:
        a sprite spans a pixel or two, over which the surface's depth hardly changes); σ = 0 where it is
        not drawn (behind the eye, or so deep behind the water's surface that it would add nothing)."""
        kind = ww.kind[p]
        half = 0.5 * exposure * ww.velocity[p]
        a = self._project(ww.position[p] - half, eye, right, up, forward, focal)
        b = self._project(ww.position[p] + half, eye, right, up, forward, focal)
        sigma, peak = 0.0, 0.0
        if a[2] > 1e-3 and b[2] > 1e-3:
            radius = ti.select(
                kind == SPRAY,
                SPRITE_RADIUS_SPACINGS[0],
                ti.select(kind == FOAM, SPRITE_RADIUS_SPACINGS[1], SPRITE_RADIUS_SPACINGS[2]),
            )
            brightness = ti.select(kind == SPRAY, BRIGHTNESS[0], ti.select(kind == FOAM, BRIGHTNESS[1], BRIGHTNESS[2]))
            true_px = focal * radius * self.constants[None].spacing / (0.5 * (a[2] + b[2]))
            sigma = ti.max(true_px, MIN_SIGMA_PX)
            length = (ti.Vector([b[0] - a[0], b[1] - a[1]])).norm()
            # The same total over the sprite's area however it is stretched or widened.
            peak = brightness * (true_px / sigma) ** 2 / (1.0 + length / (2.5 * sigma))
            col = ti.min(ti.max(ti.cast(0.5 * (a[0] + b[0]), ti.i32), 0), self.width - 1)
            row = ti.min(ti.max(ti.cast(0.5 * (a[1] + b[1]), ti.i32), 0), self.height - 1)
            seen_through = SEEN_THROUGH_SPACINGS * self.constants[None].spacing
            surface = front.front_depth(row, col, eye, right, up, forward, focal)
            behind = 0.5 * (a[2] + b[2]) - surface
            if ti.min(a[2], b[2]) > surface + HIDDEN_SEEN_THROUGH * seen_through:
                sigma = 0.0
            elif behind > 0.0:
                peak *= ti.exp(-behind / seen_through)
        return a, b, sigma, peak

    @ti.func
    def _bounds(self, a, b, sigma):
        reach = REACH_SIGMAS * sigma
        c0, c1 = _within(ti.min(a[0], b[0]), ti.max(a[0], b[0]), reach, self.width)
        r0, r1 = _within(ti.min(a[1], b[1]), ti.max(a[1], b[1]), reach, self.height)
        return c0, c1, r0, r1

    @ti.func
    def _add(self, a, b, sigma, peak, row, col):
        """The sprite's opacity at pixel (row, col), added to the pixel's sum: a bump (1 − d²/R²)² of the
        distance d to the streak, R = REACH_SIGMAS σ (close to a Gaussian of σ, without an exponential)."""
        centre = ti.Vector([col + 0.5, row + 0.5])
        start, along = ti.Vector([a[0], a[1]]), ti.Vector([b[0] - a[0], b[1] - a[1]])
        t = 0.0
        if along.norm_sqr() > 0.0:
            t = ti.min(ti.max((centre - start).dot(along) / along.norm_sqr(), 0.0), 1.0)
        falloff = 1.0 - (start + t * along - centre).norm_sqr() / (REACH_SIGMAS * REACH_SIGMAS * sigma * sigma)
        if falloff > 0.0:
            steps = ti.cast(peak * falloff * falloff * OPACITY_STEPS + 0.5, ti.i32)
            if steps > 0:
                ti.atomic_add(self.opacity[row, col], steps)
                if not self.row_used[row]:  # a read, not a write, once set: threads do not fight over the line
                    self.row_used[row] = 1

    @ti.kernel
    def _splat(self, ww: ti.template(), front: ti.template(), exposure: ti.f32):
        """Every sprite's opacity into the sums. On the CPU a thread per sprite walks its rows, each over the
        columns its streak can reach there (a diagonal streak's rectangle is mostly empty); on a GPU a thread
        per (sprite, pixel) of the sprites' rectangles (``pbf.app.splat.Footprints``)."""
        live = ww.live[None]
        if ti.static(self.per_item):
            for p in range(live):
                eye, right, up, forward, focal = front.view()
                a, b, sigma, peak = self._sprite(ww, front, p, eye, right, up, forward, focal, exposure)
                c0, c1, r0, r1 = 0, 0, 0, 0
                if sigma > 0.0:
                    c0, c1, r0, r1 = self._bounds(a, b, sigma)
                self.footprints.set(p, c0, c1, r0, r1)
                self.seen[p] = ti.Vector([a[0], a[1], b[0], b[1], sigma, peak])
            self.footprints.scan(live)
            for w in range(self.footprints.total(live)):
                p, col, row = self.footprints.item(w, live)
                s = self.seen[p]
                self._add(ti.Vector([s[0], s[1]]), ti.Vector([s[2], s[3]]), s[4], s[5], row, col)
        else:
            for p in range(live):
                eye, right, up, forward, focal = front.view()
                a, b, sigma, peak = self._sprite(ww, front, p, eye, right, up, forward, focal, exposure)
                if sigma > 0.0:
                    c0, c1, r0, r1 = self._bounds(a, b, sigma)
                    reach = REACH_SIGMAS * sigma
                    for row in range(r0, r1):
                        # The streak's points within reach of this row: t in [low, high], their columns ± reach.
                        low, high = 0.0, 1.0
                        rise = b[1] - a[1]
                        if ti.abs(rise) > 1e-6:
                            t0 = (row + 0.5 - reach - a[1]) / rise
                            t1 = (row + 0.5 + reach - a[1]) / rise
                            low, high = ti.max(ti.min(t0, t1), 0.0), ti.min(ti.max(t0, t1), 1.0)
                        x0, x1 = a[0] + low * (b[0] - a[0]), a[0] + high * (b[0] - a[0])
                        first, end = _within(ti.min(x0, x1), ti.max(x0, x1), reach, self.width)
                        for col in range(first, end):
                            self._add(a, b, sigma, peak, row, col)

    @ti.func
    def share(self, r0, c0, fy, fx):
        """The white a frame's pixel takes, 1 − exp(−Σ), Σ interpolated bilinearly (weights fy, fx) from the
        coarse sums (r0, c0) … (r0 + 1, c0 + 1); 0 where no corner holds ``FAINTEST``: most pixels have no
        white water near and cost a read of two rows' flags."""
        white = 0.0
        if self.row_used[r0] or self.row_used[r0 + 1]:
            corners = ti.Vector(
                [self.opacity[r0, c0], self.opacity[r0, c0 + 1], self.opacity[r0 + 1, c0], self.opacity[r0 + 1, c0 + 1]]
            )
            if corners.max() >= FAINTEST:
                steps = (1.0 - fy) * ((1.0 - fx) * corners[0] + fx * corners[1]) + fy * (
                    (1.0 - fx) * corners[2] + fx * corners[3]
                )
                white = 1.0 - ti.exp(-steps / OPACITY_STEPS)
        return white

    @ti.func
    def visible(self, row, col):
        """Whether coarse pixel (row, col) holds enough white for a frame's pixel next to it to show any."""
        return self.row_used[row] != 0 and self.opacity[row, col] >= FAINTEST

    @ti.func
    def whiten(self, colour, white):
        """``colour`` (RGB in [0, 1]) whitened by the share ``white`` (:meth:`share`)."""
        return colour + white * (ti.Vector(WHITE_RGB) - colour)

    @ti.func
    def clear(self):
        """The sums cleared once the frame has read them, for the next one; at a kernel's top level. A thread
        per row: most rows hold none."""
        for row in self.row_used:
            if self.row_used[row]:
                for col in range(self.width):
                    self.opacity[row, col] = 0
                self.row_used[row] = 0

    def splat(self, white_water: WhiteWater, front, exposure_s: float) -> None:
        """The live diffuse particles of ``white_water`` into the sums, seen through the view of ``front``'s
        draw, in front of or behind the nearest water or body there (``front``: a renderer whose ``view``
        function gives its draw's eye, axes and the coarse image's focal length, and whose ``front_depth``
        the depth at a coarse pixel, ``pbf.app.surface_render.SurfaceRenderer``)."""
        if self.per_item and (self.footprints is None or self.footprints.capacity < white_water.position.shape[0]):
            self.footprints = Footprints(white_water.position.shape[0])
            self.seen = ti.Vector.field(6, ti.f32, shape=white_water.position.shape[0])
        self._splat(white_water, front, exposure_s)
