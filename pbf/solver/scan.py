"""Exclusive prefix sum for Taichi fields on any backend.

Taichi's ``PrefixSumExecutor`` refuses the CPU (x64) backend, so we scan in blocks: each block sums
its slice in parallel, a serial pass turns the block sums into block offsets, and each block then
writes its running sum in parallel. Work is O(n); the serial part is O(n / block).
"""
import math

import taichi as ti


@ti.data_oriented
class ExclusiveScan:
    def __init__(self, length: int):
        self.length = length
        # About a thousand blocks: enough parallel work for a GPU, a short serial middle pass.
        self.block = max(64, math.ceil(length / 1024))
        self.blocks = math.ceil(length / self.block)
        self.block_offset = ti.field(ti.i32, shape=self.blocks + 1)

    @ti.func
    def scan(self, values: ti.template(), starts: ti.template()):
        """starts[k] = Σ_{l<k} values[l] for k ≤ length; returns the total. Called at a kernel's top
        level, so that its loops run in parallel and the scan adds no launch of its own."""
        for b in range(self.blocks):
            total = 0
            for k in range(b * self.block, ti.min((b + 1) * self.block, self.length)):
                total += values[k]
            self.block_offset[b + 1] = total
        ti.loop_config(serialize=True)
        for b in range(1, self.blocks + 1):
            self.block_offset[b] += self.block_offset[b - 1]
        for b in range(self.blocks):
            running = self.block_offset[b]
            for k in range(b * self.block, ti.min((b + 1) * self.block, self.length)):
                starts[k] = running
                running += values[k]
        starts[self.length] = self.block_offset[self.blocks]
        return self.block_offset[self.blocks]

    @ti.kernel
    def run(self, values: ti.template(), starts: ti.template()) -> ti.i32:
        """:meth:`scan` as a kernel of its own."""
        return self.scan(values, starts)


@ti.data_oriented
class BlockSum:
    """Sums of per-particle values in float64 that come out the same, bit for bit, on any thread count.

    A float atomic add into one address sums in whatever order the threads arrive, so the last bits
    change from run to run (and when such a sum decides when the solver stops iterating, the whole
    run changes); on a GPU, a million atomics into one address also serialise. Here fixed blocks are
    summed in parallel, each in index order, then the block sums in order.
    """

    def __init__(self, length: int, sums: int = 1):
        self.length = length
        self.block = max(64, math.ceil(length / 1024))
        self.blocks = math.ceil(length / self.block)
        self.partial = ti.field(ti.f64, shape=self.blocks)
        self.total = ti.field(ti.f64, shape=sums)
        """The results: ``total[slot]`` of each :meth:`sum`."""

    @ti.func
    def sum(self, values: ti.template(), slot: ti.template(), count):
        """total[slot] = Σ_{k < count} values[k], count ≤ length. Called at a kernel's top level, like
        ExclusiveScan.scan. The blocks are the same whatever the count, so the result depends only on
        the values."""
        for b in range(self.blocks):
            partial = ti.cast(0.0, ti.f64)
            for k in range(b * self.block, ti.min((b + 1) * self.block, count)):
                partial += ti.cast(values[k], ti.f64)
            self.partial[b] = partial
        self.total[slot] = 0.0
        ti.loop_config(serialize=True)
        for b in range(self.blocks):
            self.total[slot] += self.partial[b]
