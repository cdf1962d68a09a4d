"""Emitters: nozzles that add water while the scene runs, and what they must agree on."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pbf.scene.schema import SceneError, Vec3, _between, _length, _num, key

HEX_PITCH = math.sqrt(2.0 / math.sqrt(3.0))
"""Distance between neighbouring sites of a nozzle's hexagonal lattice, in spacings (1.075): a site's
hexagon, (√3/2) pitch², is a spacing squared."""


@dataclass(frozen=True)
class Emitter:
    """A nozzle that shoots water in: a disc of sites in hexagonal packing, perpendicular to the
    direction, emitting a new layer each time the stream has moved one spacing, from start_s to end_s.
    The disc's lattice is hexagonal so that the stream is round (a square lattice in a small nozzle is a
    square rod: 3 × 3 sites in pour's), its pitch such that each site has a spacing squared of the disc
    (``HEX_PITCH``): with the layers a spacing apart the water arrives at the rest density."""

    position_m: Vec3 = key(doc="centre of the nozzle, m")
    direction: Vec3 = key(doc="direction of the stream (any length; normalised)")
    radius_m: float = key(
        check=_between(0.0, 1e7), doc="radius of the nozzle, m (at least half a spacing, and inside the container)"
    )
    end_s: float = key(check=_between(0.0, 1e6), doc="when the stream stops, s")
    speed_m_s: float = key(
        1.0, _between(1e-6, 1e6), "speed of the stream, m/s (at most what a frame's substeps can follow)"
    )
    start_s: float = key(0.0, _between(0.0, 1e6), "when the stream starts, s")

    def unit_direction(self) -> Vec3:
        largest = max(abs(c) for c in self.direction)  # scaled first: any finite length normalises
        scaled = [c / largest for c in self.direction]
        return tuple(c / _length(scaled) for c in scaled)

    def disc_rows(self, spacing: float) -> list[tuple[float, float, int]]:
        """The nozzle's sites, row by row: a hexagonal lattice of pitch ``HEX_PITCH`` spacings, the sites
        within the radius. Each row is (its offset across the rows, m; its first site's offset along it, m;
        its sites, one pitch apart). Counted per row (a nozzle of a thousand spacings in a millisecond)."""
        pitch = HEX_PITCH * spacing
        row_gap = pitch * math.sqrt(3.0) / 2.0
        radius = self.radius_m * (1 + 1e-9)
        rows = []
        for j in range(-int(math.floor(radius / row_gap)), int(math.floor(radius / row_gap)) + 1):
            across = j * row_gap
            half = math.sqrt(max(radius * radius - across * across, 0.0)) / pitch  # in pitches
            if j % 2:  # odd rows sit half a pitch over: sites at (i + ½) pitch
                count = 2 * int(math.floor(half + 0.5))
                first = -(count / 2 - 0.5) * pitch
            else:
                count = 2 * int(math.floor(half)) + 1
                first = -(count // 2) * pitch
            if count:
                rows.append((across, first, count))
        return rows

    def sites_per_layer(self, spacing: float) -> int:
        """Sites of one layer (:meth:`disc_rows`)."""
        return sum(count for _, _, count in self.disc_rows(spacing))

    def layers(self, spacing: float) -> int:
        """Layers emitted over the whole interval: one at start_s, one per spacing the stream moves."""
        return int(math.floor((self.end_s - self.start_s) * self.speed_m_s / spacing + 1e-9)) + 1


def _check_emitters(scene, source: str) -> None:
    """Emitters: a real interval and nozzle, inside the container and out of obstacles, within budget."""
    spacing = scene.fluid.spacing_m
    c_lo, c_hi = scene.container.min_m, scene.container.max_m
    for i, emitter in enumerate(scene.emitters):
        where = f"{source}: key 'emitters[{i}]"
        if not emitter.end_s > emitter.start_s:
            raise SceneError(
                f"{where}.end_s' = {_num(emitter.end_s)} s must be after start_s = {_num(emitter.start_s)} s"
            )
        if not _length(emitter.direction) >= 1e-9:
            raise SceneError(f"{where}.direction': expected a non-zero vector, e.g. [0, -1, 0]")
        if emitter.radius_m < 0.5 * spacing:
            raise SceneError(
                f"{where}.radius_m' = {_num(emitter.radius_m)} m is less than half a spacing "
                f"({_num(0.5 * spacing)} m): the nozzle would hold no particle"
            )
        margin = emitter.radius_m + 0.5 * spacing  # the whole disc, at any orientation, a radius from the walls
        if any(p - margin < lo or p + margin > hi for p, lo, hi in zip(emitter.position_m, c_lo, c_hi)):
            raise SceneError(
                f"{where}.position_m': the nozzle (radius {_num(emitter.radius_m)} m) must lie inside "
                f"the container, at least radius_m + spacing/2 = {_num(margin)} m from every wall"
            )
        for j, obstacle in enumerate(scene.obstacles):
            if all(
                lo - margin < p < hi + margin for p, lo, hi in zip(emitter.position_m, obstacle.min_m, obstacle.max_m)
            ):
                raise SceneError(
                    f"{where}.position_m': the nozzle touches obstacles[{j}]; move it at least {_num(margin)} m away"
                )
    need = scene.particle_count + scene.emitted_count
    if scene.fluid.max_particles and scene.fluid.max_particles < need:
        raise SceneError(
            f"{source}: key 'fluid.max_particles' = {scene.fluid.max_particles:,} is less than the "
            f"{scene.particle_count:,} particles of the blocks and the {scene.emitted_count:,} the "
            f"emitters add (rate × duration); allowed: ≥ {need:,}, or 0 for exactly that"
        )


def _check_emitter_room(scene, source: str) -> None:
    """What the emitters add must fit, with the blocks, into the container's free volume (outside the
    obstacles) at the rest spacing, one particle per s³: more water than the box holds can only be
    compressed, and the solver then pushes it out at any speed. The first emitter that overflows is
    named, with the end_s that would fit."""
    spacing = scene.fluid.spacing_m
    extent = [hi - lo for lo, hi in zip(scene.container.min_m, scene.container.max_m)]
    free_m3 = math.prod(extent) - sum(math.prod(hi - lo for lo, hi in zip(o.min_m, o.max_m)) for o in scene.obstacles)
    room = math.floor(free_m3 / spacing**3 * (1 + 1e-9))  # particles the free volume holds at rest
    used = scene.particle_count
    for i, emitter in enumerate(scene.emitters):
        sites = emitter.sites_per_layer(spacing)
        added = emitter.layers(spacing) * sites
        if used + added > room:
            fits = (room - used) // sites  # whole layers that still fit
            allowed = (
                f"end_s < {_num(emitter.start_s + fits * spacing / emitter.speed_m_s)} s"
                if fits >= 1
                else "no emitter here (the water before it fills the container)"
            )
            raise SceneError(
                f"{source}: key 'emitters[{i}].end_s' = {_num(emitter.end_s)} s adds {added:,} particles "
                f"({_num(added * spacing**3)} m³ of water) to the {used:,} already counted, more than the "
                f"{room:,} ({_num(free_m3)} m³) the container holds outside the obstacles at "
                f"fluid.spacing_m = {_num(spacing)}; allowed: {allowed}"
            )
        used += added
