"""Time: frames, substeps and the CFL limit, settling before t = 0, and the speeds a frame's
substeps can follow."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pbf.scene.schema import SceneError, _between, _length, _num, key

CFL_FULL_ITERATIONS = 4
"""Jacobi iterations per substep from which a substep may carry particles the whole time.max_cfl;
with fewer, the travel per substep shrinks in proportion (``travel_spacings``).

Why: each substep compresses the water by about the distance the particles travel in it, and each
iteration removes a share of the compression. With too few iterations for the travel, what a
substep leaves piles up from substep to substep: the seed dam break at 64,000 particles, one
iteration and one substep asked (CFL 2 spacings a substep), read a mean density error of 26%, 122%
and 274% at frames 9, 11 and 13 of its impact and then flew apart at 10³-10⁹ m/s. At half a spacing a
substep the same iteration held it under 10% at the impact and 0.2% after; two iterations read 52%
at 2 spacings and 12% at 1 (docs/METHOD.md, "Time steps")."""


@dataclass(frozen=True)
class Time:
    frame_dt_s: float = key(1.0 / 60.0, _between(1e-4, 1.0), "time per rendered frame, s")
    substeps: int = key(2, _between(1, 1000), "PBF steps per frame (Δt = frame_dt_s / substeps)")
    max_cfl: float = key(
        1.2,
        _between(0.01, 4.0),
        "most particle spacings the fastest particle may travel in one "
        "substep at 4 or more solver.iterations (fewer scale it down in proportion: one iteration, a "
        "quarter); a frame takes more substeps when it would go further; at most 1.5 in a scene with "
        "[[obstacles]] or [[bodies]], which a longer step could cross",
    )
    max_substeps: int = key(64, _between(1, 1000), "cap on the substeps one frame may take (a warning when reached)")
    max_speed_m_s: float = key(
        0.0,
        _between(0.0, 1e4),
        "particle speeds capped at this at the end of every substep, so that the splash's fastest "
        "drops do not set every particle's substeps (0: no cap); above the flow's own speeds",
    )
    settle_s: float = key(
        0.0,
        _between(0.0, 60.0),
        "seconds of solver steps, velocities damped after each, that "
        "bring the blocks to the solver's own rest state before t = 0 (not with emitters)",
    )
    settle_substeps: int = key(
        0,
        _between(0, 1000),
        "substeps per frame while settling, but for its last 0.25 s, which runs at time.substeps (the "
        "run's own Δt, so its rest state is the run's): fewer settle a tall column in fewer steps "
        "(0: time.substeps throughout)",
    )


def travel_spacings(max_cfl: float, iterations: int) -> float:
    """The most spacings a particle may travel in one substep of ``iterations`` Jacobi iterations:
    ``max_cfl`` at CFL_FULL_ITERATIONS or more, less in proportion below."""
    return max_cfl * min(1.0, iterations / CFL_FULL_ITERATIONS)


def _check_time(scene, source: str) -> None:
    """Substeps, the CFL limit, initial speeds and gravity must fit what a frame can follow."""
    t = scene.time
    if t.substeps > t.max_substeps:
        raise SceneError(
            f"{source}: key 'time.substeps' = {t.substeps} is more than time.max_substeps = "
            f"{t.max_substeps}, the cap on a frame's substeps; raise time.max_substeps or lower "
            f"time.substeps"
        )
    if not t.max_cfl <= scene.solver.kernel_ratio:
        raise SceneError(
            f"{source}: key 'time.max_cfl' = {_num(t.max_cfl)} would let a particle pass its whole "
            f"neighbourhood (solver.kernel_ratio = {_num(scene.solver.kernel_ratio)} spacings) in one "
            f"substep; allowed: ≤ solver.kernel_ratio"
        )
    # Simulation.substeps_needed takes (fastest speed + |g| · frame_dt) · frame_dt / (max_cfl · s)
    # substeps, capped at max_substeps: beyond the cap particles tunnel from the first frame on.
    followed = scene.fastest_followed_m_s
    fall = _length(scene.gravity_m_s2) * t.frame_dt_s
    limits = "(time.max_substeps × time.max_cfl (less under 4 solver.iterations) × fluid.spacing_m / time.frame_dt_s)"
    if not fall <= followed:
        raise SceneError(
            f"{source}: key 'gravity_m_s2': |g| = {_num(fall / t.frame_dt_s)} m/s² gains "
            f"{_num(fall)} m/s in one frame, more than the {_num(followed)} m/s its substeps can follow "
            f"{limits}; allowed: |g| ≤ {_num(followed / t.frame_dt_s)} m/s², or raise "
            f"time.max_substeps"
        )
    for i, block in enumerate(scene.fluid.blocks):
        speed = _length(block.velocity_m_s)
        if t.max_speed_m_s > 0.0 and speed > t.max_speed_m_s:
            raise SceneError(
                f"{source}: key 'time.max_speed_m_s' = {_num(t.max_speed_m_s)} m/s would slow "
                f"fluid.blocks[{i}] ({_num(speed)} m/s) in the first substep; allowed: 0 (no cap) or ≥ "
                f"{_num(speed)} m/s"
            )
        if not speed + fall <= followed:
            raise SceneError(
                f"{source}: key 'fluid.blocks[{i}].velocity_m_s': {_num(speed)} m/s (plus "
                f"{_num(fall)} m/s of gravity in the first frame) is faster than the {_num(followed)} m/s "
                f"a frame's substeps can follow {limits}; allowed: ≤ {_num(followed - fall)} m/s, or "
                f"raise time.max_substeps"
            )
    cap = t.max_speed_m_s
    for i, emitter in enumerate(scene.emitters):
        if cap > 0.0 and emitter.speed_m_s > cap:
            raise SceneError(
                f"{source}: key 'time.max_speed_m_s' = {_num(cap)} m/s would slow emitters[{i}]'s jet "
                f"({_num(emitter.speed_m_s)} m/s) as it leaves the nozzle; allowed: 0 (no cap) or ≥ "
                f"{_num(emitter.speed_m_s)} m/s"
            )
        if not emitter.speed_m_s + fall <= followed:
            raise SceneError(
                f"{source}: key 'emitters[{i}].speed_m_s' = {_num(emitter.speed_m_s)} m/s (plus "
                f"{_num(fall)} m/s of gravity in a frame) is faster than the {_num(followed)} m/s a "
                f"frame's substeps can follow {limits}; allowed: ≤ {_num(followed - fall)} m/s"
            )
    piston = math.pi * scene.wave_maker.stroke_m / scene.wave_maker.period_s  # the piston's top speed, π S / T
    if cap > 0.0 and piston > cap:
        raise SceneError(
            f"{source}: key 'time.max_speed_m_s' = {_num(cap)} m/s is slower than the wave maker's piston "
            f"(up to π S / T = {_num(piston)} m/s), which the water in front of it must follow; allowed: 0 "
            f"(no cap) or ≥ {_num(piston)} m/s"
        )
    for i, body in enumerate(scene.bodies):
        speed = _length(body.velocity_m_s) + _length(body.angular_velocity_rad_s) * body.bounding_radius()
        if cap > 0.0 and speed > cap:
            raise SceneError(
                f"{source}: key 'time.max_speed_m_s' = {_num(cap)} m/s is slower than bodies[{i}]'s fastest "
                f"point ({_num(speed)} m/s, |v| + |ω| r), which the water must follow; allowed: 0 (no cap) or "
                f"≥ {_num(speed)} m/s"
            )
    if not piston + fall <= followed:
        raise SceneError(
            f"{source}: key 'wave_maker.period_s' = {_num(scene.wave_maker.period_s)} s moves the piston "
            f"at up to π S / T = {_num(piston)} m/s, faster than the {_num(followed)} m/s a frame's "
            f"substeps can follow {limits}; allowed: period_s ≥ "
            f"{_num(math.pi * scene.wave_maker.stroke_m / max(followed - fall, 1e-300))} s"
        )


def _check_settle(scene, source: str) -> None:
    """Settling runs the blocks alone: water that an emitter adds later cannot be settled beforehand; and
    its own Δt means something only where it settles."""
    if scene.time.settle_substeps > 0 and scene.time.settle_s == 0.0:
        raise SceneError(
            f"{source}: key 'time.settle_substeps' = {scene.time.settle_substeps} sets the substeps of settling, "
            f"but 'time.settle_s' is 0: this scene does not settle; allowed: 0 unless time.settle_s > 0 "
            f"(to turn settling off, set both to 0)"
        )
    if scene.time.settle_s > 0.0 and scene.emitters:
        raise SceneError(
            f"{source}: key 'time.settle_s' = {_num(scene.time.settle_s)} settles the blocks before t = 0, "
            f"but this scene has emitters, whose water arrives later; allowed: 0 with emitters"
        )
