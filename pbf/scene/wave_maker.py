"""The piston wave maker at the container's lower-x wall."""

from __future__ import annotations

from dataclasses import dataclass

from pbf.scene.schema import SceneError, _between, _num, key


@dataclass(frozen=True)
class WaveMaker:
    """A piston wave maker: the container's lower-x wall swings along x between min_m and
    min_m + stroke_m, x = min + S/2 (1 − cos 2πt/T), starting at rest."""

    stroke_m: float = key(
        0.0, _between(0.0, 1e7), "piston stroke S, m, at most a quarter of the container's length; 0: no wave maker"
    )
    period_s: float = key(
        1.0,
        _between(1e-3, 1e6),
        "wave period T, s (the piston's top speed π S / T at most what a frame's substeps can follow)",
    )


def _check_wave_maker(scene, source: str) -> None:
    """The piston must leave room behind it for the water and in front of it for the obstacles."""
    stroke = scene.wave_maker.stroke_m
    if stroke == 0.0:
        return
    length = scene.container.max_m[0] - scene.container.min_m[0]
    if not stroke <= 0.25 * length:
        raise SceneError(
            f"{source}: key 'wave_maker.stroke_m' = {_num(stroke)} m is more than a quarter of the "
            f"container's length along x ({_num(length)} m); allowed: ≤ {_num(0.25 * length)} m"
        )
    reach = scene.container.min_m[0] + stroke + 2 * scene.kernel_radius_m
    for i, obstacle in enumerate(scene.obstacles):
        if obstacle.min_m[0] < reach:
            raise SceneError(
                f"{source}: key 'obstacles[{i}].min_m': the piston sweeps x up to "
                f"{_num(scene.container.min_m[0] + stroke)} m; an obstacle must start at least 2 h "
                f"further, at x ≥ {_num(reach)} m"
            )
