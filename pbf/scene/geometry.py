"""The container, the fluid's blocks and the static obstacles: where things are, and what their
positions must agree on (inside the box, no shared volume, thick enough not to be crossed)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pbf.scene.schema import SceneError, Vec3, _box, _num, _vec, key

POSITION_REACH_SPACINGS = 2**16
"""How far from the origin, in spacings, a wall may lie. Positions are float32 (24-bit significand):
at 2¹⁶ spacings one unit in the last place is 2⁻⁷ of a spacing, the finest resolution the neighbour
distances and collisions can still work with. It also keeps every coordinate, and every speed the
box allows (see FLOAT32_SAFE), far inside float32's range."""


@dataclass(frozen=True)
class Container:
    """Axis-aligned box the fluid lives in."""

    min_m: Vec3 = key((0.0, 0.0, 0.0), doc="lower corner of the box, m")
    max_m: Vec3 = key((1.0, 1.0, 1.0), doc="upper corner of the box, m")


@dataclass(frozen=True)
class Block:
    """A box of fluid filled with a simple-cubic lattice at the fluid spacing."""

    min_m: Vec3 = key(doc="lower corner, m")
    max_m: Vec3 = key(doc="upper corner, m")
    velocity_m_s: Vec3 = key((0.0, 0.0, 0.0), doc="initial velocity, m/s")


@dataclass(frozen=True)
class Obstacle:
    """A static box inside the container that the water flows around (collision and wall density,
    like the container's walls)."""

    min_m: Vec3 = key(doc="lower corner, m")
    max_m: Vec3 = key(doc="upper corner, m")


def block_counts(block: Block, spacing: float) -> tuple[int, int, int]:
    """Lattice sites per axis: as many spacings as fit in the block (a rounding tolerance of 1e-6 s)."""
    return tuple(int(math.floor((hi - lo) / spacing + 1e-6)) for lo, hi in zip(block.min_m, block.max_m))


def _check_container(scene, source: str) -> None:
    lo, hi = scene.container.min_m, scene.container.max_m
    spacing = scene.fluid.spacing_m
    reach = POSITION_REACH_SPACINGS * spacing
    for name, corner in (("min_m", lo), ("max_m", hi)):
        farthest = max(abs(c) for c in corner)
        if farthest > reach:
            raise SceneError(
                f"{source}: key 'container.{name}': a wall at {_num(farthest)} m lies {_num(farthest / spacing)} "
                f"spacings from the origin; float32 positions resolve 1/128 spacing only within "
                f"{POSITION_REACH_SPACINGS:,} spacings ({_num(reach)} m at fluid.spacing_m = {_num(spacing)}): "
                f"move the container towards the origin or use a larger spacing"
            )
    if any(h <= l for l, h in zip(lo, hi)):
        raise SceneError(
            f"{source}: key 'container.max_m' must exceed 'container.min_m' on every axis, "
            f"got min {_vec(lo)} and max {_vec(hi)}"
        )
    if any(h - l < 2 * scene.kernel_radius_m for l, h in zip(lo, hi)):
        raise SceneError(
            f"{source}: key 'container.max_m': the box must be at least two smoothing radii "
            f"(2 h = {_num(2 * scene.kernel_radius_m)} m) wide on every axis for fluid.spacing_m = "
            f"{_num(spacing)}"
        )


def _check_blocks(scene, source: str) -> None:
    blocks = scene.fluid.blocks
    if not blocks:
        if scene.emitters:
            return
        raise SceneError(
            f"{source}: key 'fluid.blocks': at least one [[fluid.blocks]] table (or an [[emitters]] table) is required"
        )
    c_lo, c_hi = np.array(scene.container.min_m), np.array(scene.container.max_m)
    spacing = scene.fluid.spacing_m
    tolerance = 1e-9 * (float(np.max(np.abs(np.concatenate([c_lo, c_hi])))) + 1.0)
    lows = np.array([b.min_m for b in blocks])
    highs = np.array([b.max_m for b in blocks])
    for i, block in enumerate(blocks):
        where = f"{source}: key 'fluid.blocks[{i}]"
        b_lo, b_hi = lows[i], highs[i]
        if np.any(b_hi <= b_lo):
            raise SceneError(f"{where}.max_m' must exceed min_m on every axis, got {_vec(b_lo)} and {_vec(b_hi)}")
        if np.any(b_lo < c_lo - tolerance) or np.any(b_hi > c_hi + tolerance):
            raise SceneError(
                f"{where}': block {_box(b_lo, b_hi)} lies outside the container {_box(c_lo, c_hi)}; "
                f"allowed: min_m ≥ container.min_m and max_m ≤ container.max_m"
            )
        if min(block_counts(block, spacing)) < 1:
            raise SceneError(
                f"{where}': block {_box(b_lo, b_hi)} is thinner than one spacing ({_num(spacing)} m) "
                f"on some axis, so it holds no particle"
            )
        # One vectorised comparison against all earlier blocks: a thousand blocks check in milliseconds.
        overlap = np.all(np.minimum(b_hi, highs[:i]) - np.maximum(b_lo, lows[:i]) > tolerance, axis=1)
        if overlap.any():
            raise SceneError(f"{where}' overlaps fluid.blocks[{int(np.argmax(overlap))}]; blocks must not share volume")


MIN_OBSTACLE_SPACINGS = 2
"""An obstacle's least thickness, in spacings. Grown by the particle radius, its half-thickness is
then at least 1.5 spacings, and a particle moves at most time.max_cfl spacings per substep (1.2 by
default, at most OBSTACLE_MAX_CFL with obstacles), so it cannot cross an obstacle's middle in one
substep and be pushed out on the far side."""
OBSTACLE_MAX_CFL = 1.5


def _check_obstacles(scene, source: str) -> None:
    """Obstacles: inside the container, thick enough, sharing no volume with fluid or each other."""
    c_lo, c_hi = scene.container.min_m, scene.container.max_m
    thinnest = MIN_OBSTACLE_SPACINGS * scene.fluid.spacing_m
    tolerance = 1e-9 * (max(abs(c) for c in c_lo + c_hi) + 1.0)

    def overlap(a_lo, a_hi, b_lo, b_hi):
        return all(min(ah, bh) - max(al, bl) > tolerance for al, ah, bl, bh in zip(a_lo, a_hi, b_lo, b_hi))

    if scene.obstacles and scene.time.max_cfl > OBSTACLE_MAX_CFL:
        raise SceneError(
            f"{source}: key 'time.max_cfl' = {_num(scene.time.max_cfl)} lets particles cross an "
            f"obstacle in one substep; with [[obstacles]] it must be ≤ {_num(OBSTACLE_MAX_CFL)}: set time.max_cfl = "
            f"{_num(OBSTACLE_MAX_CFL)} beside them"
        )
    for i, obstacle in enumerate(scene.obstacles):
        lo, hi = obstacle.min_m, obstacle.max_m
        where = f"{source}: key 'obstacles[{i}]"
        if any(h - l < thinnest for l, h in zip(lo, hi)):
            raise SceneError(
                f"{where}.max_m': obstacle {_box(lo, hi)} must be at least {MIN_OBSTACLE_SPACINGS} "
                f"spacings ({_num(thinnest)} m) thick on every axis, or particles could cross it"
            )
        if any(l < cl - tolerance or h > ch + tolerance for l, h, cl, ch in zip(lo, hi, c_lo, c_hi)):
            raise SceneError(
                f"{where}': obstacle {_box(lo, hi)} lies outside the container {_box(c_lo, c_hi)}; "
                f"allowed: min_m ≥ container.min_m and max_m ≤ container.max_m"
            )
        for j, block in enumerate(scene.fluid.blocks):
            if overlap(lo, hi, block.min_m, block.max_m):
                raise SceneError(
                    f"{where}' overlaps fluid.blocks[{j}] ({_box(block.min_m, block.max_m)}); "
                    f"move the block or the obstacle so that they share no volume"
                )
        for j, other in enumerate(scene.obstacles[:i]):
            if overlap(lo, hi, other.min_m, other.max_m):
                raise SceneError(f"{where}' overlaps obstacles[{j}]; obstacles must not share volume")
