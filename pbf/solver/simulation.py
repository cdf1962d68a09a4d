"""The Simulation: a scene's particles, the PBF step (Macklin & Müller 2013, Algorithm 1) and its read-outs."""

from __future__ import annotations

import contextlib
import math
import numbers
import os
import warnings
from contextlib import AbstractContextManager as ContextManager
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from pbf import scene as schema
from pbf.scene.schema import _show
from pbf.solver import buckets, settled
from pbf.solver.backend import Choices, start_backend
from pbf.solver.backend import choices as backend_choices
from pbf.solver.bodies import STATE_WIDTH
from pbf.solver.boundary import Boundaries
from pbf.solver.density import DensityConstraint, pressure_scales
from pbf.solver.diagnostics import Diagnostics
from pbf.solver.divergence import DivergenceCorrection
from pbf.solver.emit import Emitters
from pbf.solver.grid import NeighbourGrid
from pbf.solver.integrate import Integrator
from pbf.solver.iterations import JacobiIterations
from pbf.solver.model import Control, Features, Model
from pbf.solver.postprocess import VelocityPostprocess
from pbf.solver.state import Snapshot, State
from pbf.solver.substep import SubstepKernels

STAGES = ("predict, sort by cell, neighbour lists", "solver iterations", "velocity, vorticity, XSPH, x = x*")
"""The stages :meth:`Simulation.substep` reports to its :class:`StageHook`, in order."""


SETTLE_DAMPING = 0.9
"""Velocities are multiplied by this after each substep of settling (``time.settle_s``)."""
SETTLE_FINISH_S = 0.25
"""Settling's last seconds, at the run's own Δt under ``time.settle_substeps`` (docs/METHOD.md, "Rest")."""


class StageHook(Protocol):
    """Told about each stage of a substep as it runs (a profiler, say)."""

    def stage(self, name: str) -> ContextManager:
        """A context that encloses the stage ``name`` (one of STAGES)."""


class NoHook:
    _null = contextlib.nullcontext()

    def stage(self, name: str) -> ContextManager:
        return self._null


@dataclass(frozen=True)
class Readout:
    """Per-particle fields for renderers on the device, in sorted order, read-only, valid until the next step."""

    count: int
    radius_m: float
    positions: object
    """(n,) vector(3, f32) field, m."""
    velocities: object
    """(n,) vector(3, f32) field, m/s."""


@dataclass(frozen=True)
class Neighbourhood:
    """The last neighbour search's lists for renderers on the device, in the order of :class:`Readout`,
    valid until the next step (a kernel that walks them: docs/ARCHITECTURE.md, "The data each stage owns")."""

    count: int
    """Particles the lists cover (the first ``count`` of the readout's fields)."""
    support_m: float
    """h, the radius the lists were searched within, m."""
    positions: object
    grid: object
    """The grid, a ``ti.template()``: ``for_each_neighbour(i, entries, task, acc)`` calls ``task(i, j, acc)``."""
    entries: object
    """The lists, for a ``pbf.solver.NeighbourList`` argument (it may be replaced between steps: pass it each call)."""


@dataclass(frozen=True)
class Solids:
    """The rigid bodies' shapes and poses for renderers on the device, valid until the next step."""

    count: int
    sphere: object
    """(slots,) i32 field: 1 for a sphere, 0 for a box."""
    half: object
    """(slots,) vector(3, f32) field: half extents (a sphere: its radius on each), m."""
    position: object
    """(slots,) vector(3, f32) field: centres, m."""
    rotation: object
    """(slots,) matrix(3, 3, f32) field: body to world."""


def _particle_array(name: str, values, shape: tuple | None = None, whence: str = "") -> np.ndarray:
    """A snapshot's array as float32, or a TypeError for what holds no real numbers; with ``shape``, a
    ValueError for another (``whence``: where that shape comes from, for the message)."""
    try:
        array = np.asarray(values)
    except (ValueError, TypeError) as error:  # ragged lists
        raise TypeError(
            f"restore: {name}: expected an array of numbers, got {type(values).__name__} ({error})"
        ) from None
    if array.dtype.kind not in "fiu" or array.dtype == np.float16:
        raise TypeError(f"restore: {name}: expected an array of real numbers, got dtype {array.dtype}")
    if shape is not None and array.shape != shape:
        raise ValueError(f"restore: expected {name} of shape {shape}{whence}, got {array.shape}")
    with np.errstate(over="ignore"):  # beyond float32: inf, refused as not finite
        return array.astype(np.float32, copy=False)


def _clock(name: str, value) -> float:
    """A snapshot's time: a finite number of seconds ≥ 0."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"restore: expected {name} as a number of seconds, got {_show(value)}")
    if not (math.isfinite(float(value)) and value >= 0.0):
        raise ValueError(f"restore: expected {name} as a finite number of seconds ≥ 0, got {float(value)!r}")
    return float(value)


class Simulation:
    """Position Based Fluids in a container, around obstacles.

    >>> sim = Simulation("dam_break")          # a preset name, a TOML path, a dict or a Scene
    >>> sim.step()                             # one frame: control.substeps PBF substeps (or more, CFL)
    >>> sim.positions(), sim.velocities()      # (n, 3) float32 NumPy arrays, m and m/s
    >>> sim.stats()["mean_density_error"]      # dict of diagnostics
    >>> sim.reset()                            # back to the initial state
    """

    def __init__(
        self,
        scene: schema.Scene | dict | str | os.PathLike,
        arch: str | None = None,
        overrides=(),
        quiet: bool = False,
        hook: StageHook | None = None,
        choices: Choices | None = None,
    ):
        """``choices``: the backend's (``pbf.solver.backend.choices()``, made here by default), or a GPU's
        asked for on the CPU (the same results: tests, launch counts)."""
        scene = schema.load_scene(scene, overrides)
        self.backend = start_backend(arch, quiet=quiet)  # first: the memory check reads the device's memory
        self.choices = choices or backend_choices()
        """What differs by backend, chosen once (docs/METHOD.md, "One substep on every backend")."""
        self.model = Model.from_scene(scene, buckets.compiled(), buckets.REUSE_LIMIT_BYTES)
        buckets.record(self.model.allocated, self.model.grid.allocated_cells)
        self.hook = hook or NoHook()
        """Told about every stage of every substep (see StageHook); assign one to profile."""
        model = self.model
        # The arrays every scene has first, in one order, then those of features a scene may lack: the
        # offline cache keys a kernel by its fields' shapes and places (docs/ARCHITECTURE.md).
        on_device = self.choices.decisions_on_device
        self.state = State(model.allocated, on_device)
        self.boundaries = Boundaries(model.boundary, solids=False)
        self.grid = NeighbourGrid(model.grid, self.state.active, self.choices, self.state.loop_bound)
        self.integrator = Integrator(self.state, self.boundaries)
        self.density = DensityConstraint(model.density, self.boundaries, self.grid, self.choices)
        self.divergence = DivergenceCorrection(model.density, self.state, self.boundaries, self.grid, self.density)
        self.postprocess = VelocityPostprocess(model.velocity, self.state, self.grid)
        self.diagnostics = Diagnostics(self.state, self.density, self.grid, model.particle_mass_kg, self.choices)
        self.iterations = JacobiIterations(
            self.density,
            weights=model.iteration_weights,
            state=self.state,
            # A GPU's host never waits inside a substep: at 4 iterations lines 1-7, the iterations and
            # the end are 3 calls. The CPU reads the decision after each iteration.
            per_call=4 if on_device else 1,
            reads_decisions=not on_device,
        )
        self.boundaries.allocate_solids(model.allocated)
        self.bodies = self.boundaries.bodies
        """The rigid bodies (``pbf.solver.bodies``), None in a scene without them."""
        if self.bodies is not None:  # the collision's record, made before the sort (Bodies.record_start)
            self.state.carry(self.bodies.shift)
            self.state.carry(self.bodies.pusher)
        self.kernels = SubstepKernels(  # the stages composed into three kernels
            self.state,
            self.integrator,
            self.grid,
            self.divergence,
            self.density,
            self.iterations,
            self.postprocess,
            # With solids their 27-term ghost is most of the denominators' compile: apart where calls are cheap.
            prepare_apart=not on_device and (self.boundaries.with_bodies or self.boundaries.obstacles.count > 0),
        )
        self.emitters = Emitters(scene.emitters, scene.fluid.spacing_m, self.state, self.grid, model.capacity)
        self._start: Snapshot | None = None
        """The state reset() returns to, taken the first time (later resets restore it, not settle again)."""
        self.restarts = -1
        """Restores so far (a reset is one; the start is the first): post-processes that follow the particles
        from frame to frame, such as the renderer's white water, start again when it changes."""
        self.reset()

    @property
    def scene(self) -> schema.Scene:
        return self.model.scene

    @property
    def particle_count(self) -> int:
        """Live particles (emitters add to them up to ``model.capacity``)."""
        return self.state.count

    def reset(self) -> None:
        """Restore the scene's initial particles, time and control (settled, with time.settle_s)."""
        self.control = Control.from_scene(self.scene)
        if self._start is not None:
            self.restore(self._start)
            return
        settled_start = settled.load(self.scene, self.choices) if self.scene.time.settle_s > 0.0 else None
        if settled_start is not None:  # settled by a start before: the same bits (pbf.solver.settled)
            self.restore(settled_start)
        else:
            self.restore(Snapshot(*self.model.initial_particles(), 0.0, 0))
            if self.scene.time.settle_s > 0.0:
                self._settle(self.scene.time.settle_s)
                settled.store(self.scene, self.snapshot(), self.choices)
        self._start = self.snapshot()

    def _settle(self, seconds: float) -> None:
        """Step ``seconds`` with damped velocities, the wave maker still (all but SETTLE_FINISH_S at the
        coarser Δt of ``time.settle_substeps``), then start the clock at t = 0 there."""
        t = self.scene.time
        fine = t.frame_dt_s / self.control.substeps
        finish = min(seconds, SETTLE_FINISH_S) if t.settle_substeps else seconds
        phases = [(fine, finish)]
        if seconds > finish:
            phases.insert(0, (t.frame_dt_s / t.settle_substeps, seconds - finish))
        self.control.wave_maker_on = False
        if self.bodies is not None:
            self.bodies.held = True  # the water settles around the bodies where the scene puts them
        for dt, span in phases:
            for _ in range(math.ceil(span / dt - 1e-9)):
                self.substep(dt)
                self.integrator.damp(SETTLE_DAMPING)
        if self.bodies is not None:
            self.bodies.held = False
        self.control.wave_maker_on = True
        self.restore(replace(self.snapshot(), time_s=0.0, frame=0, piston_time_s=None))

    def snapshot(self) -> Snapshot:
        """What :meth:`restore` takes: the particles' kept fields (creation order), clocks, emitters, bodies."""
        kept = self.state.kept_in_creation_order()  # x, v and the other kept fields in one read
        return Snapshot(
            kept.pop("x"),
            kept.pop("v"),
            self.time_s,
            self.frame,
            tuple(self.emitters.emitted),
            self.piston_time_s,
            kept,
            None if self.bodies is None else self.bodies.state(),
        )

    def restore(self, snapshot: Snapshot) -> None:
        """Return to a :meth:`snapshot`; the next steps replay exactly those that followed it. Anything
        else is refused before the state changes: a TypeError, or a ValueError naming the part."""
        positions, velocities, fields, emitted = self._checked_snapshot(snapshot)
        bodies = self._checked_bodies(snapshot)
        self.state.load({**fields, "x": positions, "v": velocities})
        if bodies is not None:
            self.bodies.load(bodies)
        self.emitters.emitted = emitted
        self.time_s = float(snapshot.time_s)
        self.frame = int(snapshot.frame)
        # The wave maker's own clock: it stops while control.wave_maker_on is off.
        self.piston_time_s = self.time_s if snapshot.piston_time_s is None else float(snapshot.piston_time_s)
        self._after_restore()

    def _checked_snapshot(self, snapshot) -> tuple[np.ndarray, np.ndarray, dict, list[int]]:
        """The snapshot's arrays (float32) and emitted layers, each checked against this scene."""
        if not isinstance(snapshot, Snapshot):
            raise TypeError(
                f"restore: expected a pbf.solver.Snapshot (from Simulation.snapshot(), or "
                f"Snapshot(positions_m, velocities_m_s, time_s, frame)), got {type(snapshot).__name__}"
            )
        positions = _particle_array("positions_m", snapshot.positions_m)
        velocities = _particle_array("velocities_m_s", snapshot.velocities_m_s)
        if positions.ndim != 2 or positions.shape[1:] != (3,) or velocities.shape != positions.shape:
            raise ValueError(
                f"restore: expected positions_m and velocities_m_s both of shape (n, 3), n the snapshot's "
                f"particles (this simulation holds {self.state.count:,} now, at most {self.model.capacity:,}), "
                f"got {positions.shape} and {velocities.shape}"
            )
        if not isinstance(snapshot.fields, dict):
            raise TypeError(f"restore: expected fields as a dict of name → array, got {type(snapshot.fields).__name__}")
        kept = {spec.name: spec for spec in self.state.fields if spec.kept and spec.name not in ("x", "v")}
        fields = {}
        for name, values in snapshot.fields.items():
            spec = kept.get(name)
            if spec is None:
                raise ValueError(
                    f"restore: unknown particle field {name!r} in the snapshot; kept fields: {', '.join(kept)}"
                )
            shape = positions.shape[:1] + (() if spec.components == 1 else (spec.components,))
            fields[name] = _particle_array(f"fields[{name!r}]", values, shape)
        count = len(positions)
        if count > self.model.capacity:
            raise ValueError(
                f"restore: {count:,} particles, more than the {self.model.capacity:,} this "
                f"scene allocates (its blocks and emitters)"
            )
        for name, values in (
            ("positions_m", positions),
            ("velocities_m_s", velocities),
            *((f"fields[{name!r}]", values) for name, values in fields.items()),
        ):
            bad = ~np.isfinite(values)
            if bad.any():
                row = int(np.argwhere(bad)[0][0])
                raise ValueError(
                    f"restore: {name} of particle {row} is {values[row].tolist()}; expected finite numbers"
                )
        self._check_inside(positions, velocities)
        _clock("time_s", snapshot.time_s)
        if snapshot.piston_time_s is not None:
            _clock("piston_time_s", snapshot.piston_time_s)
        frame = snapshot.frame
        if isinstance(frame, (bool, np.bool_)) or not isinstance(frame, numbers.Integral) or frame < 0:
            raise (ValueError if isinstance(frame, numbers.Integral) else TypeError)(
                f"restore: expected frame as a whole number ≥ 0, got {_show(frame)}"
            )
        return positions, velocities, fields, self._checked_layers(snapshot.emitted_layers, count)

    def _checked_bodies(self, snapshot) -> np.ndarray | None:
        """The snapshot's bodies (their start when it holds none), checked."""
        if self.bodies is None:
            if snapshot.bodies is not None and len(snapshot.bodies):
                raise ValueError(f"restore: the snapshot holds {len(snapshot.bodies)} bodies; this scene has none")
            return None
        if snapshot.bodies is None:
            return self.bodies.initial_state()
        shape = (self.bodies.count, STATE_WIDTH)
        bodies = _particle_array("bodies", snapshot.bodies, shape, " (pbf.solver.bodies.STATE_LAYOUT)")
        if not np.isfinite(bodies).all():
            raise ValueError("restore: the bodies' states hold a value that is not finite")
        return bodies

    def _check_inside(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Every particle inside this scene's container, and no faster than its frames can follow."""
        lower, upper = (np.array(c, np.float64) for c in (self.scene.container.min_m, self.scene.container.max_m))
        slack = 1e-6 * (np.abs(lower) + np.abs(upper) + 1.0)  # float32 rounding of a particle at the wall
        outside = np.any((positions < lower - slack) | (positions > upper + slack), axis=1)
        if outside.any():
            row = int(np.argmax(outside))
            raise ValueError(
                f"restore: particle {row} at {positions[row].tolist()} m lies outside this scene's "
                f"container {lower.tolist()}–{upper.tolist()} m (a snapshot of another scene?)"
            )
        fastest = self.scene.fastest_followed_m_s
        speeds = np.sqrt(np.sum(velocities.astype(np.float64) ** 2, axis=1))
        if len(speeds) and speeds.max() > fastest:
            row = int(np.argmax(speeds))
            raise ValueError(
                f"restore: particle {row} moves at {float(speeds[row]):.6g} m/s, faster than the "
                f"{fastest:.6g} m/s this scene's frames can follow (time.max_substeps × time.max_cfl (less "
                f"under 4 solver.iterations) × fluid.spacing_m / time.frame_dt_s)"
            )

    def _checked_layers(self, layers, count: int) -> list[int]:
        """Emitted layers: a whole number per emitter, 0 to its total, the particles to come within budget."""
        emitters, spacing = self.scene.emitters, self.scene.fluid.spacing_m
        if not isinstance(layers, (tuple, list, np.ndarray)):
            raise TypeError(
                f"restore: expected emitted_layers as a tuple of whole numbers, one per emitter, got "
                f"{type(layers).__name__}"
            )
        layers = list(layers) if len(layers) else [0] * len(emitters)
        if len(layers) != len(emitters):
            raise ValueError(
                f"restore: {len(layers)} emitted layer counts for the {len(emitters)} emitters of this "
                f"scene (a snapshot of another scene?)"
            )
        for k, (done, emitter) in enumerate(zip(layers, emitters)):
            if isinstance(done, (bool, np.bool_)) or not isinstance(done, numbers.Integral):
                raise TypeError(f"restore: emitted_layers[{k}]: expected a whole number, got {_show(done)}")
            if not 0 <= done <= emitter.layers(spacing):
                raise ValueError(
                    f"restore: emitted_layers[{k}] = {int(done)}; allowed: 0 to the "
                    f"{emitter.layers(spacing):,} layers emitters[{k}] adds in all"
                )
        layers = [int(done) for done in layers]
        sites = [e.sites_per_layer(spacing) for e in emitters]
        to_come = sum((e.layers(spacing) - done) * n for e, done, n in zip(emitters, layers, sites))
        if count + to_come > self.model.capacity:
            raise ValueError(
                f"restore: {count:,} particles and the {to_come:,} the emitters have still to add "
                f"(emitted_layers = {tuple(layers)}) exceed the {self.model.capacity:,} this scene "
                f"allocates"
            )
        return layers

    def _after_restore(self) -> None:
        """What a restore resets besides the particles: the piston, the frame's counters, the lists."""
        self.restarts += 1
        self.boundaries.move(self.piston_time_s)
        self.frame_substeps = self.control.substeps
        self.last_dt_s = self.scene.time.frame_dt_s / self.control.substeps
        self.iterations.begin(0, False)
        self.pressure_substeps = 0  # summed in State.pressure_sum since the frame began
        self._find_neighbours_in_place()

    def _find_neighbours_in_place(self) -> None:
        """The sort and the lists where the particles stand (Δt = 0), by the substep's kernel (one compile for
        both); the frames' record of the lists starts here."""
        features = Features.of(self.model, self.control)
        self.grid.build_fitting(lambda: self.kernels.find_neighbours(0.0, (0.0, 0.0, 0.0), features, 0))

    @property
    def iterations_used(self) -> int:
        """Jacobi iterations the last substep ran (read from the device)."""
        return self.iterations.used

    @property
    def dt_s(self) -> float:
        """Δt of the last substep, s (less than frame_dt_s / substeps when the CFL limit added some)."""
        return self.last_dt_s

    def substeps_needed(self, speeds: tuple[float, float] | None = None) -> int:
        """Substeps for the next frame: the control's, or more so that no particle travels more than
        ``Scene.travel_per_substep_m`` in one (docs/METHOD.md, "Time steps"). ``speeds``: the fastest
        particle's and body point's (``Diagnostics.frame_read``), else read here."""
        t = self.scene.time
        fastest, bodies = speeds or self.diagnostics.frame_read(self.bodies)[:2]
        if t.max_speed_m_s > 0.0:  # capped at the end of every substep
            fastest = min(fastest, t.max_speed_m_s)
        walls = self.boundaries.speed_limit_m_s(bodies)
        speed = max(fastest, walls) + float(np.linalg.norm(self.control.gravity_m_s2)) * t.frame_dt_s
        travel = self.scene.travel_per_substep_m(self.control.iterations)
        needed = max(self.control.substeps, math.ceil(speed * t.frame_dt_s / travel))
        if needed > t.max_substeps:
            message = (
                f"{self.scene.name}: particles at {speed:.3g} m/s need {needed} substeps per frame for "
                f"{travel / self.scene.fluid.spacing_m:.3g} spacings a substep (time.max_cfl = {t.max_cfl} at "
                f"{self.control.iterations} iterations); capped at time.max_substeps = {t.max_substeps}"
            )
            warnings.warn(message, RuntimeWarning, stacklevel=3)
        return min(needed, t.max_substeps)

    def _outside_inputs(self, dt: float) -> None:
        """What acts from outside Algorithm 1: nozzles, the hand, the bodies' rigid step, moving walls placed
        where they stand at the substep's end."""
        control = self.control
        self.emitters.emit(self.time_s, control.emitters_on)
        if control.push is not None:
            hand = control.push.capped(self.scene.travel_per_substep_m(control.iterations) / dt)
            self.integrator.push(hand)
            if self.bodies is not None:
                self.bodies.grab(hand)
        self.piston_time_s += dt if control.wave_maker_on else 0.0
        if self.bodies is not None:  # the rigid step, with the water's last reaction
            self.bodies.advance(dt, control.gravity_m_s2)
        self.boundaries.move(self.piston_time_s, dt)

    def substep(self, dt: float | None = None) -> None:
        """One PBF step (Algorithm 1) of Δt ≤ frame_dt_s, by default frame_dt_s / control.substeps."""
        control, hook, kernels = self.control, self.hook, self.kernels
        dt = self._checked_dt(dt)
        features = Features.of(self.model, control)  # what the kernels compile in
        self._outside_inputs(dt)  # emitters, the mouse, the bodies, moving walls
        with hook.stage("predict, sort by cell, neighbour lists"):
            # Lines 1-7: v += Δt g, x* = x + Δt v; the particles sorted by the cell of x* and their
            # neighbours; ours: v made divergence-free, x* again; the denominators of λ (Eq. 10) at x*.
            kernels.find_neighbours(dt, control.gravity_m_s2, features, control.divergence_iterations)
        with hook.stage("solver iterations"):
            # Lines 8-19 until the error target: λ (Eq. 10), Δx with s_corr (Eqs. 11-12), collisions,
            # x* += Δx.
            kernels.iterate(features, control)
        with hook.stage("velocity, vorticity, XSPH, x = x*"):
            # x* settled, then lines 20-23: v = (x* − x)/Δt, confinement (Eqs. 13-14), XSPH (Eq. 15),
            # x = x*; and the pressure, summed for pressures().
            scales = pressure_scales(self.scene.fluid.rest_density_kg_m3, self.model.grid.kernel_radius_m, dt)
            first, cap = self.pressure_substeps == 0, self.scene.time.max_speed_m_s
            kernels.finish(dt, features, control, scales, first, cap)
        if self.bodies is not None:  # the water's reaction on the bodies
            self.bodies.gather(self.state.x, self.density.lam_total, self.state.multiplier, self.state.active, dt)
        self.pressure_substeps += 1
        self.time_s += dt
        self.last_dt_s = dt

    def _checked_dt(self, dt) -> float:
        frame_dt = self.scene.time.frame_dt_s
        if dt is None:
            return frame_dt / self.control.substeps
        if isinstance(dt, bool) or not isinstance(dt, numbers.Real):
            raise TypeError(f"substep: dt: expected a number of seconds, got {_show(dt)}")
        if not 0.0 < dt <= frame_dt:
            raise ValueError(f"substep: dt: expected a value in (0, {frame_dt:g}] s (time.frame_dt_s), got {_show(dt)}")
        return float(dt)

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames of ``scene.time.frame_dt_s`` each (substeps_needed() substeps per frame)."""
        if isinstance(frames, bool) or not isinstance(frames, numbers.Integral):
            raise TypeError(f"step: frames: expected a whole number of frames, got {_show(frames)}")
        if frames < 0:
            raise ValueError(f"step: frames: expected 0 or more, got {_show(frames)}")
        for _ in range(frames):
            fastest, bodies, most_entries, truncated = self.diagnostics.frame_read(self.bodies)  # one read
            self.grid.settle_frame(most_entries, truncated)  # the lists grown ahead of need
            self.frame_substeps = self.substeps_needed((fastest, bodies))
            self.pressure_substeps = 0  # pressures(): this frame's mean
            dt = self.scene.time.frame_dt_s / self.frame_substeps
            for _ in range(self.frame_substeps):
                self.substep(dt)
            self.frame += 1

    def positions(self) -> np.ndarray:
        """(n, 3) float32 particle positions in metres, in creation order."""
        return self.state.positions()

    def velocities(self) -> np.ndarray:
        """(n, 3) float32 particle velocities in m/s, in creation order."""
        return self.state.velocities()

    def pressures(self) -> np.ndarray:
        """(n,) float32 pressure in Pa, in creation order: p = −ρ0 h² (L/Δt² + Λ) averaged over the last frame's
        substeps (docs/METHOD.md, "The pressure read-out"); zero before the first substep. Noisy per
        particle: average over frames for a field."""
        total = self.state.in_creation_order(self.state.pressure_sum)
        return total / np.float32(max(self.pressure_substeps, 1))

    def neighbour_counts(self) -> np.ndarray:
        """(n,) neighbours within h of each particle at the last neighbour search, in creation order."""
        return self.state.in_creation_order(self.grid.neighbour_count).astype(np.int32)

    def body_states(self) -> np.ndarray:
        """(bodies, 19) float32 copy of the rigid bodies' state (``pbf.solver.bodies.STATE_LAYOUT``)."""
        return np.zeros((0, STATE_WIDTH), np.float32) if self.bodies is None else self.bodies.state()

    def solids(self) -> Solids | None:
        """The rigid bodies' device fields, for renderers (no copy to the host); None without bodies."""
        bodies = self.bodies
        if bodies is None:
            return None
        return Solids(bodies.count, bodies.sphere, bodies.half, bodies.position, bodies.rotation)

    def readout(self) -> Readout:
        """The particles' device fields, for renderers (no copy to the host)."""
        return Readout(self.particle_count, self.scene.particle_radius_m, self.state.x, self.state.v)

    def neighbourhood(self) -> Neighbourhood:
        """The last neighbour search's lists, for renderers on the device (no copy to the host)."""
        h, x, grid = self.model.grid.kernel_radius_m, self.state.x, self.grid
        return Neighbourhood(count=self.particle_count, support_m=h, positions=x, grid=grid, entries=grid.neighbours)

    def density_ratios(self):
        """ρ/ρ0 of every particle as a device field in the order of :meth:`readout`."""
        return self.diagnostics.density_ratios(self.grid.neighbours)

    def stats(self) -> dict:
        """Diagnostics of the current state (see Diagnostics.compute), with time and counts."""
        figures = self.diagnostics.compute(self.grid.neighbours)
        figures.update(time_s=self.time_s, frame=self.frame, particles=self.particle_count, backend=self.backend)
        figures.update(iterations=self.iterations_used, substeps=self.frame_substeps)
        return figures
