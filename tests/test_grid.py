"""Neighbour lists from the counting-sort grid equal brute force, including the hard layouts."""

import numpy as np
import pytest
import taichi as ti

from pbf.solver import scan
from pbf.solver.backend import Choices
from pbf.solver.grid import SLOTS, NeighbourGrid
from pbf.solver.model import GridParams
from pbf.solver.scan import GPU_SCAN_TOP, ExclusiveScan, TreeSum


def brute_force(points, h):
    d2 = ((points[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    return [set(np.nonzero(row < h * h)[0]) for row in d2]


def make_grid(n, lower, upper, h, reach, slot_major=False, bucket=False):
    """A grid for n live particles (the solver's State owns the count; here a field of its own);
    ``slot_major``: the GPU's layout; ``bucket``: loops over the particles' bucket, as on a GPU."""
    active = ti.field(ti.i32, shape=())
    active[None] = n
    params = GridParams.covering(n, lower, upper, h, reach)
    return NeighbourGrid(params, active, Choices(slot_major=slot_major), n if bucket else active)


def grid_neighbours(points, lower, upper, h, reach=1, checked=True, slot_major=False):
    n = len(points)
    grid = make_grid(n, lower, upper, h, reach, slot_major, bucket=not checked)
    x = ti.Vector.field(3, ti.f32, shape=n)
    x.from_numpy(points.astype(np.float32))
    keys = np.random.default_rng(n).permutation(n).astype(np.int32)
    key = ti.field(ti.i32, shape=n)
    key.from_numpy(keys)
    grid.sort(x, key)
    order = grid.sorted_from.to_numpy()
    assert sorted(order) == list(range(n)), "the sort must be a permutation"
    sorted_points = points[order]
    x.from_numpy(sorted_points.astype(np.float32))
    if checked:
        grid.build_neighbours(x)
    else:
        grid.build(x)
    lists = grid.neighbour_lists()
    assert np.array_equal([len(l) for l in lists], grid.neighbour_count.to_numpy())
    check_walk(grid, lists)
    # Back to original indices; also check the sort put cells in ascending order.
    cells = grid.particle_cell.to_numpy()[order]
    assert np.all(np.diff(cells) >= 0)
    same_cell = np.diff(cells) == 0
    assert np.all(np.diff(keys[order])[same_cell] > 0), "within a cell, particles follow their keys"
    return [set(order[l].tolist()) for l in lists], order


SIGNATURE_MODULUS = 1_000_003


@ti.func
def _sign(i, j, acc: ti.template()):
    acc[0] += 1
    acc[1] = (acc[1] + acc[0] * (j + 1)) % SIGNATURE_MODULUS


@ti.kernel
def _walk(grid: ti.template(), neighbours: ti.types.ndarray(dtype=ti.i32, ndim=1), signature: ti.template()):
    for i in range(grid.active[None]):
        acc = ti.Vector([0, 0])  # (entries met, signature)
        grid.for_each_neighbour(i, neighbours, _sign, acc)
        signature[i] = acc[1]


def check_walk(grid, lists):
    """The solver's walk of a list (``for_each_neighbour``: one entry ahead on a GPU) meets every entry of
    ``neighbour_lists`` in its order: a signature Σ (k + 1)(j + 1) per particle (modulo a prime, so that a
    pile's long lists stay inside int32)."""
    signature = ti.field(ti.i32, shape=max(len(lists), 1))
    _walk(grid, grid.neighbours, signature)
    expected = [int(((np.arange(len(l)) + 1) * (l.astype(np.int64) + 1)).sum() % SIGNATURE_MODULUS) for l in lists]
    assert np.array_equal(signature.to_numpy()[: len(lists)].astype(np.int64), np.array(expected, np.int64))


def float32_brute_force(points, h):
    # The grid compares float32 distances; brute force on the same float32 values.
    return brute_force(points.astype(np.float32), np.float32(h))


def check(points, lower, upper, h, reach=1, checked=True, slot_major=None):
    got, order = grid_neighbours(points, lower, upper, h, reach, checked, slot_major)
    expected = float32_brute_force(points, h)
    by_original = [None] * len(points)
    for slot, original in enumerate(order):
        by_original[original] = got[slot]
    mismatches = [i for i in range(len(points)) if by_original[i] != expected[i]]
    assert not mismatches, f"{len(mismatches)} particles with wrong neighbours, e.g. {mismatches[:5]}"
    return expected


REACHES = pytest.mark.parametrize("reach", [1, 2])  # cells h wide (3×3×3 visited) or h/2 (5×5×5)
# Reach 2 slow where it repeats reach 1's case: its cells are walked in the default run by the random and
# cell-border points, the slot-major lists and the unchecked builds, each at reach 2 as well.
REACH_1_AND_SLOW_2 = pytest.mark.parametrize("reach", [1, pytest.param(2, marks=pytest.mark.slow)])


@REACHES
def test_random_points(reach):
    rng = np.random.default_rng(0)
    points = rng.uniform(0.0, 1.0, size=(3000, 3))
    expected = check(points, (0, 0, 0), (1, 1, 1), 0.07, reach)
    assert sum(map(len, expected)) > 3000  # the test is not vacuous


@REACHES
def test_points_on_cell_borders(reach):
    # Every point has one, two or three coordinates exactly on a cell face (so it sits on a face, an
    # edge or a corner); the others are random, so no pair sits at exactly h (a float32 tie).
    h = 0.1
    cell = 1.0 / int(np.floor(reach / (h * (1 + 1e-4))))
    rng = np.random.default_rng(4)
    points = rng.uniform(0.0, 1.0, size=(3000, 3))
    snap = rng.random((3000, 3)) < 0.6
    snap[np.arange(3000), rng.integers(0, 3, 3000)] = True
    points = np.where(snap, np.round(points / cell) * cell, points)
    expected = check(points, (0, 0, 0), (1.0, 1.0, 1.0), h, reach)
    assert sum(map(len, expected)) > 3000


@REACH_1_AND_SLOW_2
def test_all_points_in_one_cell(reach):
    # 4,000 particles in one cell: 15,996,000 pairs, far more than any fixed capacity would hold.
    # Checked with NumPy in blocks of rows (Python sets of 64 million indices, at 8,000, took 7 GB).
    rng = np.random.default_rng(2)
    h, n = 0.1, 4000
    points = rng.uniform(0.45, 0.45 + h / 3, size=(n, 3))
    grid = make_grid(n, (0, 0, 0), (1, 1, 1), h, reach)
    x = ti.Vector.field(3, ti.f32, shape=n)
    x.from_numpy(points.astype(np.float32))
    key = ti.field(ti.i32, shape=n)
    grid.sort(x, key)
    grid.build_neighbours(x)  # every particle is in the one cell, so the sort's order does not matter
    start, listed = grid.neighbour_start.to_numpy()[:n], grid.neighbour_listed.to_numpy()[:n]
    assert np.array_equal(listed, np.full(n, n - 1))
    assert np.array_equal(start, np.arange(n) * (n - 1))  # the compact list, rows back to back
    lists = grid.neighbours.to_numpy()[: n * (n - 1)].reshape(n, n - 1)
    column = np.arange(n - 1)[None, :]
    for first in range(0, n, 500):
        rows = np.arange(first, min(first + 500, n))[:, None]
        # Row i, sorted, must be every index but i: k for k < i, k + 1 beyond.
        assert np.array_equal(np.sort(lists[rows[:, 0]], axis=1), column + (column >= rows))


@REACH_1_AND_SLOW_2
def test_points_outside_grid_are_clamped_not_lost(reach):
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.2, 1.2, size=(1500, 3))
    check(points, (0, 0, 0), (1, 1, 1), 0.15, reach)


@pytest.mark.parametrize("length", [1, 63, 64, 65, 5000, 100_003])
def test_exclusive_scan(length):
    rng = np.random.default_rng(length)
    values = rng.integers(0, 50, size=length).astype(np.int32)
    source = ti.field(ti.i32, shape=length)
    starts = ti.field(ti.i32, shape=length + 1)
    source.from_numpy(values)
    scan = ExclusiveScan(length)

    @ti.kernel
    def run():
        scan.scan(source, starts, length)

    run()
    total = starts[length]
    expected = np.concatenate([[0], np.cumsum(values)])
    assert total == expected[-1]
    assert np.array_equal(starts.to_numpy(), expected)


@pytest.mark.parametrize("length", [1, 33, 1025, 40_000])
@pytest.mark.parametrize("count", ["all", "some", "none"])
def test_exclusive_scan_in_gpu_blocks_of_some_entries(length, count):
    # The GPU backends' block of 32 entries (several levels of blocks) over the first `count` entries.
    live = {"all": length, "some": length * 2 // 3, "none": 0}[count]
    values = np.random.default_rng(length).integers(0, 50, size=length).astype(np.int32)
    source = ti.field(ti.i32, shape=length)
    starts = ti.field(ti.i32, shape=length + 1)
    source.from_numpy(values)
    scan = ExclusiveScan(length, block=32)

    @ti.kernel
    def run(count: ti.i32):
        scan.scan(source, starts, count)

    run(live)
    assert len(scan.tree.lengths) >= min(3, 1 + (length > 32) + (length > 1024))
    assert np.array_equal(starts.to_numpy()[: live + 1], np.concatenate([[0], np.cumsum(values[:live])]))


@pytest.mark.parametrize("block", [None, 4, 32, "gpu"])
@pytest.mark.parametrize("length", [1, 33, 1025, 40_000])
def test_a_scan_whose_caller_counted_the_blocks(block, length):
    # The sort's way: each value added to its level-0 block's sum by atomics where it is counted
    # (add_to_block), the first pass up skipped (counted=True), the block sums cleared after
    # (clear_block); twice, so that a sum left over from the first count would show in the second.
    # "gpu": a GPU backend's tree, blocks of 32 under a top level of up to GPU_SCAN_TOP entries.
    scan = ExclusiveScan(length, block=None if block == "gpu" else block, gpu=block == "gpu")
    source = ti.field(ti.i32, shape=length)
    starts = ti.field(ti.i32, shape=length + 1)

    @ti.kernel
    def count_and_scan():
        for k in range(length):
            scan.add_to_block(k, source[k])
        scan.scan(source, starts, length, True)
        for k in range(length):
            scan.clear_block(k)

    @ti.kernel
    def count_and_start_each():  # the compact list's way: the passes up, then each thread its own start
        for k in range(length):
            scan.add_to_block(k, source[k])
        scan.up(source, length, 1, True)
        for k in range(length):
            starts[k] = scan.start_of(source, k)
        for k in range(length):
            scan.clear_block(k)

    for seed in (1, 2):
        values = np.random.default_rng(seed * length).integers(0, 50, size=length).astype(np.int32)
        source.from_numpy(values)
        count_and_scan()
        assert np.array_equal(starts.to_numpy(), np.concatenate([[0], np.cumsum(values)]))
        starts.fill(-1)
        count_and_start_each()
        assert np.array_equal(starts.to_numpy()[:length], np.concatenate([[0], np.cumsum(values)])[:length])


@pytest.mark.parametrize(
    ("length", "lengths"),
    [
        (500, [500, 16]),  # level 0 keeps its blocks of 32 however short
        (16_384, [16_384, 512]),  # the seed's neighbour counts: 512 block sums are the top
        (65_536, [65_536, 2_048, 64]),  # the seed's cells
        (4_194_304, [4_194_304, 131_072, 4_096, 128]),  # a million particles' cells
    ],
)
def test_a_gpus_prefix_sum_stops_at_a_top_level_of_a_few_hundred(length, lengths):
    # On a GPU each level above the first is a pass up, a launch: the tree stops at the first level of
    # at most GPU_SCAN_TOP block sums, which start_of reads whole. The float sums keep their blocks.
    tree = ExclusiveScan(length, gpu=True).tree
    assert TreeSum(length, gpu=True).tree.lengths[-1] <= 32  # a float sum keeps its tree of 32s
    assert tree.lengths == lengths
    assert tree.blocks[:-1] == [32] * (len(lengths) - 1) and tree.blocks[-1] >= lengths[-1]
    assert lengths[-1] <= GPU_SCAN_TOP


@pytest.mark.parametrize("block", [None, 32])
def test_tree_sums_are_compensated_and_independent_of_the_count_of_blocks(block):
    # 100,003 values spanning eight decades: a float32 running sum loses ~1e-4 of it, the pair keeps it
    # to float64's accuracy.
    n = 100_003
    values = (np.random.default_rng(5).random(n) ** 8).astype(np.float32)
    values[17] = 3.0e4
    field = ti.field(ti.f32, shape=n)
    field.from_numpy(values)
    sums = TreeSum(n, block=block)

    @ti.kernel
    def run():
        sums.sum(field, 0, n)

    run()
    high, low = sums.high.to_numpy(), sums.low.to_numpy()
    assert float(high[0]) + float(low[0]) == pytest.approx(values.astype(np.float64).sum(), rel=1e-11)


@pytest.mark.parametrize("length", [1, 255, 16_384, 16_385, 1_000_000, 4_194_305, 100_000_000])
def test_cuda_sums_cover_every_entry_in_one_or_two_launches(length):
    # The shared-memory sums' shape (their arithmetic runs on CUDA and, one block a kernel, in the Vulkan
    # subset): one block up to GPU_SUM_ONE_BLOCK entries, else at most GPU_SUM_MOST_BLOCKS blocks, so that
    # every thread of the loop makes one pass and meets every sync; the blocks cover every entry.
    sums = TreeSum(length, shared=True)
    threads = scan.GPU_SUM_THREADS
    assert sums.in_shared_memory and not TreeSum(length).in_shared_memory  # on the CPU: the tree
    assert sums.blocks * threads * sums.per_thread >= length > (sums.blocks - 1) * threads * sums.per_thread
    assert (sums.blocks == 1) == (length <= scan.GPU_SUM_ONE_BLOCK)
    assert sums.blocks <= scan.GPU_SUM_MOST_BLOCKS and sums.top_per_thread * threads >= sums.blocks
    if length > scan.GPU_SUM_ONE_BLOCK:
        assert sums.per_thread >= scan.GPU_SUM_PER_THREAD


@pytest.mark.parametrize("checked", [True, False])
@pytest.mark.parametrize("pile", [False, True])
def test_the_gpus_slot_major_lists_match_brute_force(checked, pile):
    # The GPU's layout (entry i + k·n) and its branchy build, on the CPU: random points, and with a
    # pile of 200 in one cell, whose lists overflow SLOTS and go to the compact rows.
    rng = np.random.default_rng(7)
    points = rng.uniform(0.0, 1.0, size=(2000, 3))
    if pile:
        points[:200] = rng.uniform(0.5, 0.52, size=(200, 3))
    expected = check(points, (0, 0, 0), (1, 1, 1), 0.08, 2, checked, slot_major=True)
    assert max(map(len, expected)) > SLOTS if pile else max(map(len, expected)) < SLOTS


@REACHES
def test_unchecked_builds_on_the_device_match_brute_force(reach):
    # Random points and a pile of 100 in one cell: the pile's particles have more than SLOTS neighbours,
    # so the device runs the prefix sum and the second visit itself (the compact list fits).
    rng = np.random.default_rng(6)
    points = np.concatenate([rng.uniform(0.0, 1.0, size=(3000, 3)), rng.uniform(0.5, 0.5 + 0.07 / 3, size=(100, 3))])
    expected = check(points, (0, 0, 0), (1, 1, 1), 0.07, reach, checked=False)
    assert max(map(len, expected)) > SLOTS


def test_a_list_cut_short_is_reported_grown_and_exact_after():
    # 300 particles in one cell: 89,700 entries, more than the SLOTS per particle (19,200) an
    # unchecked build can hold. The frame's record says so; the list grows and the next build is exact.
    rng = np.random.default_rng(8)
    n, h = 300, 0.1
    points = rng.uniform(0.45, 0.45 + h / 3, size=(n, 3)).astype(np.float32)
    grid = make_grid(n, (0, 0, 0), (1, 1, 1), h, 1, bucket=True)
    x = ti.Vector.field(3, ti.f32, shape=n)
    x.from_numpy(points)
    grid.sort(x, ti.field(ti.i32, shape=n))

    def take():
        return tuple(int(v) for v in grid.status.to_numpy())

    grid.build(x)
    most_entries, truncated = take()
    assert (most_entries, truncated) == (n * (n - 1), 1)
    with pytest.warns(RuntimeWarning, match="needed 89,700 entries"):
        grid.settle_frame(most_entries, bool(truncated))
    assert grid.neighbours.shape[0] == n * (n - 1) * 3 // 2
    assert take() == (0, 0)  # grown: the record starts again
    grid.build(x)
    assert np.array_equal(grid.neighbour_count.to_numpy(), np.full(n, n - 1))
    assert all(len(set(entries.tolist())) == n - 1 for entries in grid.neighbour_lists())
    most_entries, truncated = take()
    assert (most_entries, truncated) == (n * (n - 1), 0)
    grid.settle_frame(most_entries, False)  # two thirds full: the array stays
    assert grid.neighbours.shape[0] == n * (n - 1) * 3 // 2
    grid.settle_frame(int(0.8 * grid.neighbours.shape[0]), False)  # over GROW_ABOVE: grown ahead of need
    assert grid.neighbours.shape[0] > n * (n - 1) * 3 // 2


def test_the_gpu_checks_scan_task_runs_on_a_cpu_for_the_judges_references(tmp_path):
    """tests/vulkan_run.py's prefix sums and float sums on the CPU backend, as ../shared/gpu/judge.py runs
    them for its references: the shared-memory sums, a GPU's alone, are left out there, not failed."""
    import subprocess
    import sys
    from pathlib import Path

    worker = Path(__file__).resolve().parent / "vulkan_run.py"
    out = tmp_path / "cpu.npz"
    done = subprocess.run(
        [sys.executable, str(worker), str(out), "cpu", "--fast-compile", "scan"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    runs = np.load(out)
    for length in (1, 33, 1025, 100_003):
        counts = runs[f"scan_{length}_counts"]
        assert np.array_equal(runs[f"scan_{length}_starts"], np.concatenate([[0], np.cumsum(counts)]))
        assert f"scan_{length}_block_sums" not in runs.files
