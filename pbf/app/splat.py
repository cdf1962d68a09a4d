"""Splatting particles on a GPU backend: a thread per (particle, pixel) of the particle's footprint.

Both headless renderers project each particle's sphere to a screen rectangle and test its pixels
(``pbf.app.render.SphereRenderer``, ``pbf.app.fluid_render.FluidRenderer``). On the CPU backend a
thread per particle walks its rectangle, column by column, in memory order. On a GPU backend that
leaves threads idle behind the few particles near the camera that cover thousands of pixels, and
Mesa's software Vulkan driver (lavapipe 22.3) loses atomic operations inside a loop whose trip count
differs between threads (a per-particle loop of 40 atomic adds kept 1 in 10 of them): its frames had
holes. Here instead the rectangles' areas are prefix-summed into a list of work items, one per
(particle, pixel); each item finds its particle by a binary search over the sums and does its one
atomic at the top level of the loop. The image does not depend on the order of the items (each
pixel keeps the least key, or sums integers), so it is the same as the per-particle loops'.
"""

import math

import taichi as ti


def per_item() -> bool:
    """Whether the running backend splats per item (every backend but the CPU)."""
    return ti.cfg.arch not in (ti.x64, ti.arm64)


@ti.data_oriented
class Footprints:
    """Screen rectangles of up to ``capacity`` particles and the prefix sum of their areas."""

    def __init__(self, capacity: int):
        self.capacity = max(int(capacity), 1)
        self.corner = ti.Vector.field(2, ti.i32, shape=self.capacity)
        """(first column, first row) of each particle's rectangle."""
        self.width = ti.field(ti.i32, shape=self.capacity)
        self.sums = [ti.field(ti.i32, shape=self.capacity + 1) for _ in range(2)]
        """Ping-pong buffers of the scan: the areas, then their inclusive sums."""
        self.passes = max(1, math.ceil(math.log2(self.capacity)))

    @ti.func
    def set(self, k, c0, c1, r0, r1):
        """Particle k covers columns [c0, c1) and rows [r0, r1) (empty when either is)."""
        width, height = ti.max(c1 - c0, 0), ti.max(r1 - r0, 0)
        self.corner[k] = ti.Vector([c0, r0])
        self.width[k] = width
        self.sums[0][k + 1] = width * height

    @ti.func
    def scan(self, count):
        """starts[k] = Σ_{l<k} area[l] for k ≤ count (Hillis & Steele: log₂ n passes, each parallel);
        called at a kernel's top level after :meth:`set` of particles 0 … count − 1."""
        self.sums[0][0] = 0
        for p in ti.static(range(self.passes)):
            source, target = ti.static(self.sums[p % 2], self.sums[(p + 1) % 2])
            for k in range(count + 1):
                value = source[k]
                if k >= (1 << p):
                    value += source[k - (1 << p)]
                target[k] = value

    @ti.func
    def total(self, count):
        """Work items of particles 0 … count − 1, after :meth:`scan`."""
        return self.sums[self.passes % 2][count]

    @ti.func
    def item(self, w, count):
        """The particle slot k of work item w and its pixel (column, row)."""
        starts = ti.static(self.sums[self.passes % 2])
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
