"""The work of tests/test_vulkan.py on one backend, in a process of its own (Taichi runs one backend per
process): ``python tests/vulkan_run.py OUT.npz ARCH [--fast-compile] [--device-decisions] [--perturb SEED] TASK...``.

Tasks: ``kernel`` (the SPH kernel and its gradient at sample distances), ``scan`` (prefix sums and
compensated sums of random data), ``grid`` (neighbour lists of random points around a pile in one cell,
checked and unchecked), ``seed`` (the seed scene's statistics frame by frame, with reads and launches
per substep), ``rest`` (a pool filling the seed scene's floor, at rest), ``render`` (the headless frames
of the snapshot in RENDER_SNAPSHOT, particles and surface). Everything lands in OUT.npz for the test to
judge. One Simulation serves the last three: on lavapipe each compiles its kernels for 30-40 s.
"""

import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

SCAN_LENGTHS = (1, 33, 1025, 100_003)
SEED_FRAMES = 30
REST_FRAMES = 20
REST_LAYERS = 7
"""The pool at rest: this many lattice layers over the seed scene's whole floor (7,168 particles)."""
RENDER_SIZE = (320, 180)
RENDER_SNAPSHOT = "RENDER_SNAPSHOT"
"""Environment variable: the npz (positions, velocities) of the state the ``render`` task draws."""


def grid_points() -> tuple[np.ndarray, float]:
    """3,000 random points and a pile of 100 in one cell, whose points have more than SLOTS neighbours
    (the compact list and its second visit), and h."""
    rng = np.random.default_rng(7)
    h = 0.07
    return np.concatenate([rng.uniform(0.0, 1.0, size=(3000, 3)), rng.uniform(0.5, 0.5 + h / 3, size=(100, 3))]), h


def pool(spacing: float, lower, upper, layers: int) -> np.ndarray:
    """Lattice sites at lower + (i + ½) s over the whole floor, ``layers`` deep."""
    counts = [round((upper[0] - lower[0]) / spacing), layers, round((upper[2] - lower[2]) / spacing)]
    axes = [lo + (np.arange(n) + 0.5) * spacing for lo, n in zip(lower, counts)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float32)


def kernel_task(out: dict) -> None:
    import taichi as ti

    from pbf.solver.sph import kernel, kernel_and_gradient

    h = 0.1
    r = np.linspace(0.0, 1.2 * h, 97)
    offsets = np.stack([r * 0.6, r * 0.0, r * 0.8], axis=1).astype(np.float32)
    points = ti.Vector.field(3, ti.f32, shape=len(r))
    values = ti.field(ti.f32, shape=len(r))
    gradients = ti.Vector.field(3, ti.f32, shape=len(r))
    points.from_numpy(offsets)

    @ti.kernel
    def evaluate():
        for i in points:
            values[i] = kernel(points[i].norm_sqr(), h)
            _, gradients[i] = kernel_and_gradient(points[i], h)

    evaluate()
    out.update(kernel_r=r, kernel_offsets=offsets, kernel_w=values.to_numpy(), kernel_grad=gradients.to_numpy())


def scan_task(out: dict) -> None:
    import taichi as ti

    from pbf.solver.backend import GPU_ARCHES, choices, running_device
    from pbf.solver.scan import ExclusiveScan, TreeSum

    for length in SCAN_LENGTHS:
        rng = np.random.default_rng(length)
        counts = rng.integers(0, 50, size=length).astype(np.int32)
        values = (rng.random(length) ** 3).astype(np.float32)
        source, starts = ti.field(ti.i32, shape=length), ti.field(ti.i32, shape=length + 1)
        floats = ti.field(ti.f32, shape=length)
        source.from_numpy(counts)
        floats.from_numpy(values)
        chosen = choices()
        scan = ExclusiveScan(length, gpu=chosen.gpu_blocks)
        sums = TreeSum(length, shared=chosen.shared_memory, gpu=chosen.gpu_blocks)
        most = ti.field(ti.f32, shape=())  # the maximum as Diagnostics takes it: atomics, exact in any order

        @ti.kernel
        def prefix():
            scan.scan(source, starts, length)

        @ti.kernel
        def reduce():
            sums.sum(floats, 0, length)
            for k in range(length):
                ti.atomic_max(most[None], floats[k])

        prefix()
        reduce()
        out[f"scan_{length}_counts"], out[f"scan_{length}_starts"] = counts, starts.to_numpy()
        out[f"scan_{length}_values"] = values
        out[f"scan_{length}_sums"] = np.stack([sums.high.to_numpy(), sums.low.to_numpy()])
        out[f"scan_{length}_maximum"] = most.to_numpy()

        # The shared-memory sums (CUDA's): on SPIR-V backends only where one loop holds them (a kernel's
        # second loop with a shared array fails there), so a sum of one block, a kernel of its own each;
        # not on a CPU, which has no shared memory (the CPU's reference runs of the judge take this task).
        arch = running_device().arch
        blocks = TreeSum(length, shared=True) if arch in GPU_ARCHES else None
        if blocks is not None and (blocks.blocks == 1 or arch == "cuda"):

            @ti.kernel
            def add_in_blocks():
                blocks.sum(floats, 0, length)

            add_in_blocks()
            out[f"scan_{length}_block_sums"] = np.stack([blocks.high.to_numpy(), blocks.low.to_numpy()])


def grid_task(out: dict) -> None:
    import taichi as ti

    from pbf.solver.backend import choices
    from pbf.solver.grid import NeighbourGrid
    from pbf.solver.model import NEIGHBOUR_REACH, GridParams

    points, h = grid_points()
    n = len(points)
    active = ti.field(ti.i32, shape=())
    active[None] = n
    # The solver's choices for this backend: a GPU's slot-major lists and loops over the bucket.
    chosen = choices()
    grid = NeighbourGrid(
        GridParams.covering(n, (0, 0, 0), (1, 1, 1), h, NEIGHBOUR_REACH),
        active,
        chosen,
        n if chosen.slot_major else active,
    )
    x = ti.Vector.field(3, ti.f32, shape=n)
    key = ti.field(ti.i32, shape=n)
    x.from_numpy(points.astype(np.float32))
    key.from_numpy(np.arange(n, dtype=np.int32))
    grid.sort(x, key)
    order = grid.sorted_from.to_numpy()
    x.from_numpy(points[order].astype(np.float32))
    out["grid_order"] = order
    for checked in (True, False):  # exact (read and grown), and as a substep builds them
        if checked:
            grid.build_neighbours(x)
        else:
            grid.build(x)
        lists = grid.neighbour_lists()
        name = f"grid_{'checked' if checked else 'unchecked'}"
        out[name + "_counts"] = np.array([len(entries) for entries in lists])
        out[name + "_flat"] = np.concatenate(lists)


def statistics_row(sim) -> list[float]:
    stats = sim.stats()
    return [
        stats["mean_density_error"],
        stats["max_density_error"],
        stats["max_speed_m_s"],
        stats["kinetic_energy_j"],
        stats["mean_neighbours"],
        stats["iterations"],
        stats["substeps"],
    ]


STATISTICS = (
    "mean_density_error",
    "max_density_error",
    "max_speed_m_s",
    "kinetic_energy_j",
    "mean_neighbours",
    "iterations",
    "substeps",
)


SIMULATION = {}
"""The one Simulation of the seed scene that ``seed``, ``rest`` and ``render`` share."""


PERTURBATION_M = 1e-7
"""``--perturb``: the seed scene's positions moved by this much (normal, per coordinate): the size of
float32 rounding at its 0.5 m, so that the run differs from the others as a rounding difference does."""


def seed_simulation(perturb: int | None = None):
    from pbf import Simulation

    if "dam_break" not in SIMULATION:
        sim = SIMULATION["dam_break"] = Simulation("dam_break", quiet=True, choices=SIMULATION["choices"])
        if perturb is not None:
            start = sim.snapshot()
            noise = np.random.default_rng(perturb).normal(0.0, PERTURBATION_M, start.positions_m.shape)
            sim.restore(replace(start, positions_m=(start.positions_m + noise).astype(np.float32)))
    return SIMULATION["dam_break"]


def seed_task(out: dict, perturb: int | None = None) -> None:
    sys.path.append(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # the checkout, for the lab
    from benchmarks.instruments import TransferCounter

    sim = seed_simulation(perturb)
    rows, reads, launches, substeps = [], 0, 0, 0
    for _ in range(SEED_FRAMES):
        with TransferCounter() as counter:
            sim.step()
        reads, launches, substeps = reads + counter.reads, launches + counter.launches, substeps + sim.frame_substeps
        rows.append(statistics_row(sim))
    out["seed_statistics"] = np.array(rows)
    out["seed_transfers"] = np.array([reads / substeps, launches / substeps])


def rest_task(out: dict) -> None:
    from pbf.solver import Snapshot

    sim = seed_simulation()
    container = sim.scene.container
    positions = pool(sim.scene.fluid.spacing_m, container.min_m, container.max_m, REST_LAYERS)
    sim.restore(Snapshot(positions, np.zeros_like(positions), 0.0, 0))
    sim.step(REST_FRAMES)
    out["rest_statistics"] = np.array(statistics_row(sim))
    out["rest_speeds"] = np.linalg.norm(sim.velocities(), axis=1)
    out["rest_depth_m"] = np.array(REST_LAYERS * sim.scene.fluid.spacing_m)


def render_task(out: dict) -> None:
    from pbf.app.render import SceneRenderer
    from pbf.solver import Snapshot

    state = np.load(os.environ[RENDER_SNAPSHOT])
    sim = seed_simulation()
    sim.restore(Snapshot(state["positions"], state["velocities"], 0.0, 0))
    for style in ("particles", "surface"):
        out[f"render_{style}"] = SceneRenderer(sim, *RENDER_SIZE, style=style).frame()
    # White water on this backend's path (a GPU's: per-item sprites, the block tree's prefix sums): it starts at
    # the snapshot's frame and emits over the next; the frame drawn twice.
    renderer = SceneRenderer(sim, *RENDER_SIZE, style="surface")
    renderer.frame()
    sim.step()
    out["render_white"] = renderer.frame()
    out["render_white_again"] = renderer.frame()
    out["white_counts"] = np.array(renderer.white_water.counts())


TASKS = {
    "kernel": kernel_task,
    "scan": scan_task,
    "grid": grid_task,
    "seed": seed_task,
    "rest": rest_task,
    "render": render_task,
}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("arch")
    parser.add_argument("--fast-compile", action="store_true")
    parser.add_argument("--device-decisions", action="store_true")
    parser.add_argument("--perturb", type=int, default=None, help="seed: start from positions moved by rounding noise")
    parser.add_argument("tasks", nargs="+", choices=TASKS)
    args = parser.parse_args()
    from pbf.solver.backend import choices, running_device, start_backend

    start_backend(args.arch, fast_compile=args.fast_compile)
    out = {"device": np.array(running_device().name), "arch": np.array(running_device().arch)}
    SIMULATION["choices"] = choices(decisions_on_device=True if args.device_decisions else None)
    for task in args.tasks:
        start = time.perf_counter()
        TASKS[task](out, args.perturb) if task == "seed" else TASKS[task](out)
        out[f"seconds_{task}"] = np.array(time.perf_counter() - start)
        print(f"{task}: {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    np.savez(args.out, **out)


if __name__ == "__main__":
    main()
