"""Fields with baked constants against ndarrays with constants as data: the compile cache and the speed.

    python benchmarks/kernel_arguments.py [--particles 64000] [--rounds 15] [--arch cpu]

The solver's stages keep their arrays in Taichi fields sized by the scene and read the scene's
constants (h, the particle volume) as Python floats, which Taichi bakes into the kernels. Taichi's
offline cache names a compiled kernel by a hash of its IR (the baked constants in it), its argument
types and the whole tree of every field it touches, shapes included: another particle count or
spacing compiles every kernel again. An ndarray argument enters that hash by its element type and
dimension count only, and a struct argument by its member types, so a kernel that takes its arrays
as ndarrays (grouped in a ``ti.types.argpack``, which a ``@ti.func`` takes as a template) and its
constants as a struct compiles once for every scene.

This script measures the two on the same work, the density sum of the constraint (ρ_i/ρ0 = V Σ_j W_ij
over neighbour lists, a lattice at the seed scene's h = 2 spacings):

1. the cache: a fresh process runs each variant at one size and constants, a second fresh process
   at another size and other constants, sharing one empty cache folder; the second's new cache
   files are the kernels it had to compile (0: served from the cache);
2. the speed: both variants on the same particles in one process, alternating, median ms per call,
   and whether they give the same bits;
3. the launch: the host's time to launch a kernel that does next to nothing, reading fields, and
   taking an argpack of 1, 8 or 32 ndarrays (the solver's fused kernels would take 30 or more):
   Taichi sets every ndarray of a pack anew at each launch, in Python.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import taichi as ti

KERNEL_RATIO = 2.0
"""h in spacings, as the seed scene's ``solver.kernel_ratio``."""


def lattice(particles: int, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A cubic lattice of about ``particles`` points, jittered, and its exact neighbour lists within h
    (positions, per-particle list starts, the flat list), built with NumPy on a cell grid."""
    side = round(particles ** (1 / 3))
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(1)
    x = (grid + rng.uniform(-0.1, 0.1, grid.shape)) * spacing
    h = KERNEL_RATIO * spacing
    reach = int(np.ceil(h / spacing + 0.2))
    index = {tuple(c): k for k, c in enumerate(grid)}
    offsets = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    lists = []
    for k, c in enumerate(grid):
        candidates = [index.get(tuple(c + o)) for o in offsets]
        candidates = np.array([j for j in candidates if j is not None and j != k])
        near = candidates[np.sum((x[candidates] - x[k]) ** 2, axis=1) < h * h]
        lists.append(near)
    starts = np.concatenate([[0], np.cumsum([len(n) for n in lists])]).astype(np.int32)
    return x.astype(np.float32), starts, np.concatenate(lists).astype(np.int32)


def derived(h: float, volume: float) -> tuple[float, float]:
    """1/h and V σ, σ = 8/(π h³) the cubic spline's normalisation: computed once on the host for both
    variants, as the solver's Model does, so that neither divides per pair."""
    return 1.0 / h, volume * 8.0 / (np.pi * h**3)


@ti.func
def cubic(r2, inverse_h, sigma):
    """The cubic spline kernel W(r, h) of the solver (``pbf.solver.sph``), from r², times V."""
    q = ti.sqrt(r2) * inverse_h
    w = 0.0
    if q <= 0.5:
        w = sigma * (6.0 * (q * q * q - q * q) + 1.0)
    elif q <= 1.0:
        w = sigma * 2.0 * (1.0 - q) ** 3
    return w


@ti.data_oriented
class FieldVariant:
    """Today's style: fields sized by the scene, constants baked into the kernel."""

    def __init__(self, x, starts, neighbours, h, volume):
        n = len(x)
        self.inverse_h, self.sigma = derived(h, volume)
        self.x = ti.Vector.field(3, ti.f32, shape=n)
        self.start = ti.field(ti.i32, shape=n + 1)
        self.neighbours = ti.field(ti.i32, shape=len(neighbours))
        self.density = ti.field(ti.f32, shape=n)
        self.count = ti.field(ti.i32, shape=())
        self.x.from_numpy(x)
        self.start.from_numpy(starts)
        self.neighbours.from_numpy(neighbours)
        self.count[None] = n

    @ti.kernel
    def run(self):
        for i in range(self.count[None]):
            xi = self.x[i]
            rho = cubic(0.0, self.inverse_h, self.sigma)
            for k in range(self.start[i], self.start[i + 1]):
                rho += cubic((xi - self.x[self.neighbours[k]]).norm_sqr(), self.inverse_h, self.sigma)
            self.density[i] = rho

    def result(self) -> np.ndarray:
        return self.density.to_numpy()


Constants = ti.types.struct(inverse_h=ti.f32, sigma=ti.f32, count=ti.i32)


@ti.data_oriented
class ConstantsVariant(FieldVariant):
    """Fields as today, the constants as a struct argument: what constants as data cost alone."""

    def __init__(self, x, starts, neighbours, h, volume):
        super().__init__(x, starts, neighbours, h, volume)
        self.constants = Constants(inverse_h=self.inverse_h, sigma=self.sigma, count=len(x))

    @ti.kernel
    def _run(self, c: Constants):
        for i in range(c.count):
            xi = self.x[i]
            rho = cubic(0.0, c.inverse_h, c.sigma)
            for k in range(self.start[i], self.start[i + 1]):
                rho += cubic((xi - self.x[self.neighbours[k]]).norm_sqr(), c.inverse_h, c.sigma)
            self.density[i] = rho

    def run(self):
        self._run(self.constants)


vec3_array = ti.types.ndarray(dtype=ti.math.vec3, ndim=1)
f32_array = ti.types.ndarray(dtype=ti.f32, ndim=1)
i32_array = ti.types.ndarray(dtype=ti.i32, ndim=1)
Arrays = ti.types.argpack(x=vec3_array, start=i32_array, neighbours=i32_array, density=f32_array)


@ti.func
def density_of(a: ti.template(), c, i):
    """ρ_i/ρ0 of particle i: the same arithmetic as FieldVariant.run, the arrays from the pack."""
    xi = a.x[i]
    rho = cubic(0.0, c.inverse_h, c.sigma)
    for k in range(a.start[i], a.start[i + 1]):
        rho += cubic((xi - a.x[a.neighbours[k]]).norm_sqr(), c.inverse_h, c.sigma)
    return rho


@ti.kernel
def ndarray_density(a: Arrays, c: Constants):
    for i in range(c.count):
        a.density[i] = density_of(a, c, i)


@ti.kernel
def plain_density(
    x: vec3_array, start: i32_array, neighbours: i32_array, density: f32_array, inverse_h: ti.f32, sigma: ti.f32
):
    for i in range(x.shape[0]):
        xi = x[i]
        rho = cubic(0.0, inverse_h, sigma)
        for k in range(start[i], start[i + 1]):
            rho += cubic((xi - x[neighbours[k]]).norm_sqr(), inverse_h, sigma)
        density[i] = rho


class NdarrayVariant:
    """Sizes and constants as data: one compiled kernel for every scene."""

    def __init__(self, x, starts, neighbours, h, volume):
        arrays = {}
        for name, values, dtype in (
            ("x", x, ti.math.vec3),
            ("start", starts, ti.i32),
            ("neighbours", neighbours, ti.i32),
        ):
            arrays[name] = ti.ndarray(dtype, shape=len(values))
            arrays[name].from_numpy(values)
        arrays["density"] = ti.ndarray(ti.f32, shape=len(x))
        self.arrays = Arrays(**arrays)
        self.density = arrays["density"]
        inverse_h, sigma = derived(h, volume)
        self.constants = Constants(inverse_h=inverse_h, sigma=sigma, count=len(x))

    def run(self):
        ndarray_density(self.arrays, self.constants)

    def result(self) -> np.ndarray:
        return self.density.to_numpy()


class PlainArgumentsVariant(NdarrayVariant):
    """The same ndarrays and constants as loose kernel arguments, without the pack."""

    def run(self):
        a, c = self.arrays, self.constants
        plain_density(a.x, a.start, a.neighbours, a.density, c.inverse_h, c.sigma)


VARIANTS = {
    "fields": FieldVariant,
    "constants": ConstantsVariant,
    "ndarrays": NdarrayVariant,
    "arguments": PlainArgumentsVariant,
}
"""Today's fields with baked constants; the same fields with the constants as a struct argument; the
arrays as ndarrays in an argpack with the constants as a struct; the same as loose arguments."""


def build(variant: str, particles: int, spacing: float):
    x, starts, neighbours = lattice(particles, spacing)
    h = KERNEL_RATIO * spacing
    return VARIANTS[variant](x, starts, neighbours, h, 0.9 * spacing**3)


def compile_once(variant: str, particles: int, spacing: float, arch: str) -> None:
    """In a process of its own (``--compile-once``): build and run one variant once."""
    ti.init(arch=getattr(ti, arch), default_fp=ti.f32, log_level=ti.WARN)
    build(variant, particles, spacing).run()
    ti.sync()


def cache_check(arch: str) -> dict:
    """Kernels the second process compiled, per variant (another size and spacing than the first)."""
    compiled = {}
    for variant in VARIANTS:
        with tempfile.TemporaryDirectory() as folder:
            env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=folder)
            counts = []
            for particles, spacing in ((8000, 0.025), (12167, 0.02)):
                before = set(Path(folder).rglob("*.tic"))
                command = [sys.executable, __file__, "--compile-once", variant, "--particles", str(particles)]
                command += ["--spacing", str(spacing), "--arch", arch]
                subprocess.run(command, check=True, env=env, capture_output=True)
                counts.append(len(set(Path(folder).rglob("*.tic")) - before))
            compiled[variant] = counts
    return compiled


LAUNCH_PACKS = (1, 8, 32)
"""Ndarrays per argpack in the launch measurement."""


def launch_costs(rounds: int, calls: int = 500) -> dict:
    """µs per launch of a kernel over one element: reading two fields, taking a 3-vector or three values
    (gravity, as the substep's first kernel takes it), and taking argpacks of LAUNCH_PACKS ndarrays (it
    reads two of them); medians of ``rounds`` alternating rounds."""
    a, b = ti.field(ti.f32, shape=1), ti.field(ti.f32, shape=1)

    @ti.kernel
    def on_fields():
        for i in range(1):
            a[i] = b[i] + 1.0

    @ti.kernel
    def with_vector(g: ti.types.vector(3, ti.f32)):
        for i in range(1):
            a[i] = b[i] + g[1]

    @ti.kernel
    def with_values(gx: ti.f32, gy: ti.f32, gz: ti.f32):
        for i in range(1):
            a[i] = b[i] + ti.Vector([gx, gy, gz])[1]

    gravity = (0.0, -9.81, 0.0)
    launches = {
        "fields": on_fields,
        "a vector arg.": lambda: with_vector(gravity),
        "three values": lambda: with_values(*gravity),
    }
    for members in LAUNCH_PACKS:
        pack_type = ti.types.argpack(**{f"a{k}": f32_array for k in range(members)})
        pack = pack_type(**{f"a{k}": ti.ndarray(ti.f32, shape=1) for k in range(members)})

        @ti.kernel
        def on_pack(p: pack_type):
            for i in range(1):
                p.a0[i] = p.a0[i] + 1.0

        launches[f"argpack of {members}"] = lambda kernel=on_pack, pack=pack: kernel(pack)
    for launch in launches.values():
        launch()
    ti.sync()
    times = {name: [] for name in launches}
    for _ in range(rounds):
        for name, launch in launches.items():
            began = time.perf_counter()
            for _ in range(calls):
                launch()
            ti.sync()
            times[name].append((time.perf_counter() - began) * 1e6 / calls)
    return {name: statistics.median(values) for name, values in times.items()}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=64000)
    parser.add_argument("--spacing", type=float, default=0.025)
    parser.add_argument("--rounds", type=int, default=15, help="alternating timing rounds")
    parser.add_argument("--calls", type=int, default=10, help="calls per variant and round")
    parser.add_argument("--arch", default="cpu", choices=("cpu", "cuda", "vulkan"))
    parser.add_argument("--compile-once", choices=tuple(VARIANTS), default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.compile_once:
        return compile_once(args.compile_once, args.particles, args.spacing, args.arch)
    compiled = cache_check(args.arch)
    print("kernels compiled by a fresh process at 8,000 particles, then by one at 12,167 (another spacing):")
    for variant, (first, second) in compiled.items():
        print(f"  {variant:<9} {first} then {second}")
    ti.init(arch=getattr(ti, args.arch), default_fp=ti.f32, log_level=ti.WARN)
    built = {name: build(name, args.particles, args.spacing) for name in VARIANTS}
    for variant in built.values():  # compile before timing
        variant.run()
    ti.sync()
    times = {name: [] for name in built}
    for _ in range(args.rounds):
        for name, variant in built.items():
            began = time.perf_counter()
            for _ in range(args.calls):
                variant.run()
            ti.sync()
            times[name].append((time.perf_counter() - began) * 1e3 / args.calls)
    base = statistics.median(times["fields"])
    reference = built["fields"].result()
    same = ", ".join(f"{name} {'yes' if np.array_equal(reference, v.result()) else 'no'}" for name, v in built.items())
    print(
        f"density sum over neighbour lists, {args.particles:,} particles, {args.arch}, medians of {args.rounds} rounds:"
    )
    for name, values in times.items():
        print(f"  {name:<9} {statistics.median(values):8.3f} ms  ({statistics.median(values) / base:.2f}x fields)")
    print(f"  the same bits as fields: {same}")
    print(f"host time per launch of a kernel over one element, {args.arch}, medians of {args.rounds} rounds:")
    for name, micros in launch_costs(args.rounds).items():
        print(f"  {name:<15} {micros:7.1f} µs")


if __name__ == "__main__":
    main()
