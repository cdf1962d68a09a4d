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
