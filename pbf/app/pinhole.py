"""The pinhole projection both headless renderers share: an eye-relative point to its pixel."""

import taichi as ti


@ti.func
def to_pixel(p, right, up, forward, focal, width, height):
    """Row and column of eye-relative point ``p`` (row 0 at the top), its depth along ``forward``,
    and whether it lies in front of the eye and inside the image."""
    depth = p.dot(forward)
    row, col, inside = -1, -1, False
    if depth > 1e-6:
        col = ti.cast(0.5 * width + focal * p.dot(right) / depth, ti.i32)
        row = ti.cast(0.5 * height - focal * p.dot(up) / depth, ti.i32)
        inside = 0 <= row < height and 0 <= col < width
    return row, col, depth, inside
