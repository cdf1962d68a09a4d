"""Prefix sums and reductions over Taichi fields: parallel, in float32, bit-identical on any thread count.

Both walk a tree of blocks (level 0: blocks of consecutive entries; each level above: blocks of the
results below, up to one block). A block is one thread's loop in index order and a level one parallel
loop in the calling kernel, so the order of every addition depends on the indices alone: no atomic, no
host round trip, no launch of its own. On CUDA float sums add up in shared memory instead
(:meth:`TreeSum._reduce_in_blocks`), in a fixed order all the same.

Float sums are compensated (a float32 pair (high, low), Knuth's TwoSum: as exact as float64 without
it, which Metal and many integrated GPUs lack). Fast math may rewrite (a + b) − a as b, so every
TwoSum step passes through an integer xor with a zero the compiler cannot see (``_opaque``).
"""

import math

import taichi as ti

Template = ti.template()
GPU_BLOCK = 32
"""Entries per block of a prefix sum on a GPU backend, at every level but the top."""
GPU_SCAN_TOP = 512
"""The most entries the top level of a prefix sum's tree holds on a GPU backend, as one block, read
whole by :meth:`ExclusiveScan.start_of` rather than summed by one more pass (a launch)."""
GPU_SUM_THREADS = 256
"""Threads of a GPU block that adds up a float sum in shared memory (any GPU backend takes it)."""
GPU_SUM_ONE_BLOCK = 16_384
"""Up to this many entries one block adds up a sum: one launch."""
GPU_SUM_PER_THREAD = 16
"""Entries a thread adds up first when a sum takes more than one block (more blocks hide latency)."""
GPU_SUM_MOST_BLOCKS = 1024
"""At most this many level-0 blocks: each thread runs one pass, so every thread meets each sync."""
CPU_BLOCKS = 1024
"""On the CPU: about this many level-0 blocks (≥ 64 entries each) and entries a block above: two levels."""
CPU_SCAN_BLOCKS = 256
"""The prefix sum's CPU_BLOCKS: few enough that each block of the pass down adds the sums before its own."""


class Tree:
    """The static shape of a block tree over ``length`` entries (block sizes, each level's length and
    offset in one scratch field): it never depends on the live count, so a result depends on the values."""

    def __init__(self, length: int, block: int | None, cpu_blocks: int, top: int, gpu: bool):
        """``top``: the most entries the top level may hold as one block (:data:`GPU_SCAN_TOP`)."""
        self.length = max(int(length), 1)
        if block is not None or gpu:  # in a GPU's blocks (``Choices.gpu_blocks``): a long one idles threads
            first = above = block or GPU_BLOCK
        else:  # on the CPU few long blocks at level 0 and above it (a level is a task)
            first, above = max(64, math.ceil(self.length / cpu_blocks)), cpu_blocks
        self.blocks = [first]
        self.lengths = [self.length]
        while self.lengths[-1] > (first if len(self.lengths) == 1 else max(above, top)):
            self.lengths.append(math.ceil(self.lengths[-1] / self.blocks[-1]))
            self.blocks.append(above)
        self.blocks[-1] = max(self.blocks[-1], self.lengths[-1])  # the top level is one block
        self.top = len(self.lengths) - 1
        self.block_counts = self.lengths[1:] + [1]
        self.offsets = [0, 0]
        for level_length in self.lengths[1:]:
            self.offsets.append(self.offsets[-1] + level_length)
        self.scratch = max(self.offsets[-1], 1)
        """Entries of levels 1 … top, back to back (level j at ``offsets[j]``)."""


@ti.func
def _live(count, block):
    """Blocks that hold any of the first ``count`` entries."""
    return (count + block - 1) // block


@ti.func
def read_count(count: ti.template(), gate: ti.template()):
    """A count (a 0-D field, an int or a value) read inside the loop that uses it, times ``gate`` (1 or a 0-D field)."""
    return _read(count) * _read(gate)


@ti.func
def _read(value: ti.template()):
    result = 0
    if ti.static(isinstance(value, ti.ScalarField)):
        result = value[None]
    else:
        result = value
    return result


@ti.func
def _opaque(x, zero):
    """x itself, through an integer xor with a runtime zero: fast math cannot see through it."""
    return ti.bit_cast(ti.bit_cast(x, ti.i32) ^ zero, ti.f32)


@ti.func
def _two_sum(a, b, zero):
    """s = fl(a + b) and its rounding error e, a + b = s + e exactly (Knuth's TwoSum)."""
    s = _opaque(a + b, zero)
    b_virtual = _opaque(s - a, zero)
    a_virtual = _opaque(s - b_virtual, zero)
    return s, _opaque(a - a_virtual, zero) + _opaque(b - b_virtual, zero)


@ti.func
def _accumulate(high, low, value_high, value_low, zero):
    """(high, low) with one more value (value_high, value_low) added in, compensated."""
    high, error = _two_sum(high, value_high, zero)
    low += error + value_low
    return high, low


@ti.data_oriented
class ExclusiveScan:
    """starts[k] = Σ_{l<k} values[l] of int32 values (a counting sort's cell starts)."""

    def __init__(self, length: int, block: int | None = None, gpu: bool = False):
        """``gpu``: in a GPU's blocks (``pbf.solver.backend.Choices.gpu_blocks``)."""
        self.length = length
        self.tree = Tree(length, block, CPU_SCAN_BLOCKS, GPU_SCAN_TOP if block is None and gpu else 0, gpu)
        self.sums = ti.field(ti.i32, shape=self.tree.scratch)
        """Block sums of levels 1 … top (``Tree.offsets``)."""

    @ti.func
    def _entry(self, values: ti.template(), level: ti.template(), k):
        value = 0
        if ti.static(level == 0):
            value = values[k]
        else:
            value = self.sums[self.tree.offsets[level] + k]
        return value

    @ti.func
    def add_to_block(self, k, amount):
        """Add ``amount`` to the sum of entry k's level-0 block, for a caller that counts its values itself
        (then ``scan(..., counted=True)`` skips its first pass up)."""
        ti.atomic_add(self.sums[self.tree.offsets[1] + k // self.tree.blocks[0]], amount)

    @ti.func
    def clear_block(self, k):
        """Zero the sum :meth:`add_to_block` gathers for entry k's block, once the scan has read it."""
        self.sums[self.tree.offsets[1] + k // self.tree.blocks[0]] = 0

    @ti.func
    def up(self, values: ti.template(), count: ti.template(), gate: ti.template() = 1, counted: ti.template() = False):
        """The passes up the tree of :meth:`scan` (from level 1 when ``counted``), for :meth:`start_of`."""
        for level in ti.static(range(1 if counted else 0, self.tree.top)):
            block = ti.static(self.tree.blocks[level])
            for b in range(ti.static(self.tree.block_counts[level])):
                live = read_count(count, gate)  # this level's entries that hold any of the first count values
                for j in ti.static(range(level)):
                    live = _live(live, self.tree.blocks[j])
                if b < _live(live, block):
                    total = 0
                    for k in range(b * block, ti.min((b + 1) * block, live)):
                        total += self._entry(values, level, k)
                    self.sums[self.tree.offsets[level + 1] + b] = total

    @ti.func
    def start_of(self, values: ti.template(), k, lowest: ti.template() = 0):
        """Σ_{l<k} values[l] by the calling thread alone, after :meth:`up` (no pass down): the entries before
        k in its block, then before its block a level up, to the top. ``lowest``: k's level."""
        total = 0
        index = k
        for level in ti.static(range(lowest, self.tree.top + 1)):
            block = ti.static(self.tree.blocks[level])
            above = index // block
            for e in range(above * block, index):
                total += self._entry(values, level, e)
            index = above
        return total

    @ti.func
    def scan(self, values: ti.template(), starts: ti.template(), count: ti.template(), counted: ti.template() = False):
        """starts[k] = Σ_{l<k} values[l] for k ≤ count ≤ length (starts[count] is the total), ``count`` a
        0-D field, a Python int or a value. Called at a kernel's top level. After the passes up, one pass
        down: each level-0 block works out its own start (:meth:`start_of`). Every level loops over all
        its blocks and skips those past the live entries (a count read outside the loops would be a
        one-thread task). ``counted``: :meth:`add_to_block` gathered the level-0 sums."""
        self.up(values, count, 1, counted)
        block = ti.static(self.tree.blocks[0])
        for b in range(ti.static(self.tree.block_counts[0])):
            total_count = read_count(count, 1)
            if b < _live(total_count, block):
                running = self.start_of(values, b, 1)
                end = ti.min((b + 1) * block, total_count)
                for k in range(b * block, end):
                    starts[k] = running
                    running += values[k]
                if end == total_count:
                    starts[total_count] = running
            if b == 0 and total_count == 0:  # no block is live: the total is 0
                starts[0] = 0


@ti.data_oriented
class TreeSum:
    """Compensated sums of float32 values: ``sums`` results, each the same bits on any thread
    count, kept on the device (:attr:`high` + :attr:`low`) for kernels to use or the host to read."""

    def __init__(self, length: int, sums: int = 1, block: int | None = None, shared: bool = False, gpu: bool = False):
        """``gpu`` and ``shared``: in a GPU's blocks, added up in shared memory (``pbf.solver.backend.Choices``)."""
        self.length = length
        self.tree = Tree(length, block, CPU_BLOCKS, 0, gpu)
        self.in_shared_memory = block is None and shared
        """Each GPU block adds up in shared memory (:meth:`_reduce_in_blocks`)."""
        self._reduce = self._reduce_in_blocks if self.in_shared_memory else self._reduce_in_tree
        threads = GPU_SUM_THREADS
        if length <= GPU_SUM_ONE_BLOCK:
            self.per_thread = math.ceil(max(length, 1) / threads)
        else:
            self.per_thread = max(GPU_SUM_PER_THREAD, math.ceil(length / (threads * GPU_SUM_MOST_BLOCKS)))
        self.blocks = math.ceil(max(length, 1) / (threads * self.per_thread))
        """Level-0 blocks of the shared-memory sum, each over threads × per_thread consecutive entries."""
        self.top_per_thread = math.ceil(self.blocks / threads)
        scratch = self.blocks if self.in_shared_memory else self.tree.scratch
        self.scratch_high = ti.field(ti.f32, shape=scratch)
        self.scratch_low = ti.field(ti.f32, shape=scratch)
        self.high = ti.field(ti.f32, shape=sums)
        """The results: sum ``slot`` is high[slot] + low[slot]."""
        self.low = ti.field(ti.f32, shape=sums)
        self.zero = ti.field(ti.i32, shape=())
        """Always 0; read in the kernels, so that the compiler cannot fold the TwoSum steps."""

    @ti.func
    def sum(self, values: ti.template(), slot: ti.template(), count: ti.template()):
        """high[slot] + low[slot] = Σ_{k < count} values[k] (``count``: an int or a 0-D field), at a kernel's
        top level."""
        self._reduce(values, slot, count)

    @ti.func
    def total(self, slot: ti.template()):
        """Sum ``slot`` as one float32, for the kernel's statements after :meth:`sum`."""
        return self.high[slot] + self.low[slot]

    @ti.func
    def _reduce_in_blocks(self, values: Template, slot: Template, count: Template):
        # Thread t of block g adds up entries (g·per + j)·threads + t, j < per (a warp reads consecutive
        # entries), then the block halves its partial sums in shared memory: an order fixed by the length.
        threads = ti.static(GPU_SUM_THREADS)
        for level in ti.static(range(2 if self.blocks > 1 else 1)):
            top = ti.static(level == 1 or self.blocks == 1)
            per = ti.static(self.per_thread if level == 0 else self.top_per_thread)
            ti.loop_config(block_dim=threads)
            for i in range(threads * ti.static(self.blocks if level == 0 else 1)):
                t, g = i % threads, i // threads
                shared_high = ti.simt.block.SharedArray((threads,), ti.f32)
                shared_low = ti.simt.block.SharedArray((threads,), ti.f32)
                live = read_count(count, 1)
                if ti.static(level == 1):
                    live = self.blocks
                zero = self.zero[None]
                high, low = 0.0, 0.0
                for j in range(per):
                    k = (g * per + j) * threads + t
                    if k < live:
                        value_high, value_low = 0.0, 0.0
                        if ti.static(level == 0):
                            value_high = values[k]
                        else:
                            value_high, value_low = self.scratch_high[k], self.scratch_low[k]
                        high, low = _accumulate(high, low, value_high, value_low, zero)
                shared_high[t] = high
                shared_low[t] = low
                ti.simt.block.sync()
                for halving in ti.static(range(int(math.log2(threads)))):
                    width = ti.static(threads >> (halving + 1))
                    if t < width:
                        total, error = _two_sum(shared_high[t], shared_high[t + width], zero)
                        shared_high[t] = total
                        shared_low[t] = shared_low[t] + shared_low[t + width] + error
                    ti.simt.block.sync()
                if t == 0:
                    if ti.static(top):
                        self.high[slot] = shared_high[0]
                        self.low[slot] = shared_low[0]
                    else:
                        self.scratch_high[g] = shared_high[0]
                        self.scratch_low[g] = shared_low[0]

    @ti.func
    def _reduce_in_tree(self, values: Template, slot: Template, count: Template):
        # Every level loops over all of its blocks and skips those past the live entries (as in
        # ExclusiveScan.scan); the top block always runs, so that it writes 0 when there is nothing to add.
        for level in ti.static(range(self.tree.top + 1)):
            block = ti.static(self.tree.blocks[level])
            for b in range(ti.static(self.tree.block_counts[level])):
                live = read_count(count, 1)
                for j in ti.static(range(level)):
                    live = _live(live, self.tree.blocks[j])
                if ti.static(level == self.tree.top) or b < _live(live, block):
                    zero = self.zero[None]
                    high, low = 0.0, 0.0
                    for k in range(b * block, ti.min((b + 1) * block, live)):
                        value_high, value_low = 0.0, 0.0
                        if ti.static(level == 0):
                            value_high = values[k]
                        else:
                            value_high = self.scratch_high[self.tree.offsets[level] + k]
                            value_low = self.scratch_low[self.tree.offsets[level] + k]
                        high, low = _accumulate(high, low, value_high, value_low, zero)
                    if ti.static(level == self.tree.top):
                        self.high[slot] = high
                        self.low[slot] = low
                    else:
                        self.scratch_high[self.tree.offsets[level + 1] + b] = high
                        self.scratch_low[self.tree.offsets[level + 1] + b] = low
