"""The Simulation: a scene's particles, the PBF step (Macklin & Müller 2013, Algorithm 1) and its read-outs."""
from __future__ import annotations

import contextlib
import math
import os
import warnings
from dataclasses import dataclass, replace
from typing import ContextManager, Protocol

import numpy as np

from pbf import scene as schema
from pbf.solver.backend import start_backend
from pbf.solver.bodies import STATE_WIDTH
from pbf.solver.boundary import Boundaries
from pbf.solver.acceleration import Weights
from pbf.solver.density import DensityConstraint
from pbf.solver.divergence import DivergenceCorrection
from pbf.solver.diagnostics import Diagnostics
from pbf.solver.emit import Emitters
from pbf.solver.grid import NeighbourGrid
from pbf.solver.integrate import Integrator
from pbf.solver.model import Control, Model
from pbf.solver.postprocess import VelocityPostprocess
from pbf.solver.state import Snapshot, State

STAGES = ("predict", "sort by cell", "neighbour lists", "divergence pre-correction", "solver iterations",
          "velocity, vorticity, XSPH, x = x*")
"""The stages :meth:`Simulation.substep` reports to its :class:`StageHook`, in order."""


SETTLE_DAMPING = 0.9
"""Velocities are multiplied by this after each substep of settling (``time.settle_s``): zeroing them
left only the iterations' creep, and settled too slowly; 0.9 comes to rest within a second."""


class StageHook(Protocol):
    """Told about each stage of a substep as it runs (a profiler, say; ``pbf.study.common.StageTimer``)."""

    def stage(self, name: str) -> ContextManager:
        """A context that encloses the stage ``name`` (one of STAGES)."""


class NoHook:
    """The default hook: does nothing, at the cost of entering a null context per stage."""

    _null = contextlib.nullcontext()

    def stage(self, name: str) -> ContextManager:
        return self._null


@dataclass(frozen=True)
class Readout:
    """Per-particle Taichi fields for code on the same device (renderers), in the solver's current
    sorted order, valid until the next step. Read them; never write them."""

    count: int
    radius_m: float
    positions: object
    """(n,) vector(3, f32) field, m."""
    velocities: object
    """(n,) vector(3, f32) field, m/s."""


class Simulation:
    """Position Based Fluids in a container, around obstacles.

    >>> sim = Simulation("dam_break")          # a preset name, a TOML path, a dict or a Scene
    >>> sim.step()                             # one frame: control.substeps PBF substeps (or more, CFL)
    >>> sim.positions(), sim.velocities()      # (n, 3) float32 NumPy arrays, m and m/s
    >>> sim.stats()["mean_density_error"]      # dict of diagnostics
    >>> sim.reset()                            # back to the initial state
    """

    def __init__(self, scene: schema.Scene | dict | str | os.PathLike, arch: str | None = None,
                 overrides=(), quiet: bool = False, hook: StageHook | None = None):
        scene = schema.load_scene(scene, overrides)  # any kind of scene, checked, with the overrides
        self.model = Model.from_scene(scene)  # validates memory before Taichi allocates anything
        self.backend = start_backend(arch, quiet=quiet)
        self.hook = hook or NoHook()
        """Told about every stage of every substep (see StageHook); assign one to profile."""
        model = self.model
        self.state = State(model.capacity)
        self.boundaries = Boundaries(model.boundary, model.capacity)
        """The container, its piston, the obstacles and the rigid bodies (``pbf.solver.boundary``)."""
        self.bodies = self.boundaries.bodies
        """The rigid bodies (``pbf.solver.bodies``), None in a scene without them."""
        self.emitters = Emitters(scene.emitters, scene.fluid.spacing_m, self.state)
        self.grid = NeighbourGrid(model.grid, self.state.active)
        self.integrator = Integrator(self.state, self.boundaries)
        self.density = DensityConstraint(model.density, self.boundaries, self.grid)
        self.divergence = DivergenceCorrection(model.density, self.state, self.boundaries, self.grid, self.density)
        self.postprocess = VelocityPostprocess(model.velocity, self.state, self.grid)
        self.diagnostics = Diagnostics(self.state, self.density, self.grid, model.particle_mass_kg)
        self.weights = Weights(model.iteration_weights)
        """The iterations' weights (solver.expert.acceleration), restarted at each substep."""
        self._start: Snapshot | None = None
        """The state reset() returns to, taken the first time (settling is deterministic, so later
        resets restore it instead of settling again: 2 s of substeps at 64,000 particles)."""
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
        positions, velocities = self.model.initial_particles()
        self.restore(Snapshot(positions, velocities, 0.0, 0))
        if self.scene.time.settle_s > 0.0:
            self._settle(self.scene.time.settle_s)
        self._start = self.snapshot()

    def _settle(self, seconds: float) -> None:
        """Step ``seconds`` with the velocities damped by SETTLE_DAMPING after each substep (the wave
        maker standing still), then start the clock at t = 0 from there: the blocks come close to the
        positions and the pressure the solver itself holds at rest, so a tank at rest starts near rest
        instead of sagging into it (docs/VALIDATION.md)."""
        dt = self.scene.time.frame_dt_s / self.control.substeps
        self.control.wave_maker_on = False
        if self.bodies is not None:
            self.bodies.held = True  # the water settles around the bodies where the scene puts them
        for _ in range(math.ceil(seconds / dt - 1e-9)):
            self.substep(dt)
            self.integrator.damp(SETTLE_DAMPING)
        if self.bodies is not None:
            self.bodies.held = False
        self.control.wave_maker_on = True
        settled = self.snapshot()
        self.restore(replace(settled, time_s=0.0, frame=0, piston_time_s=None))

    def snapshot(self) -> Snapshot:
        """Positions, velocities, the divergence pressure (creation order), time and frame, the bodies:
        what :meth:`restore` takes."""
        return Snapshot(self.positions(), self.velocities(), self.time_s, self.frame, tuple(self.emitters.emitted),
                        self.piston_time_s, self.state.kept_fields(),
                        None if self.bodies is None else self.bodies.state())

    def restore(self, snapshot: Snapshot) -> None:
        """Return to a :meth:`snapshot`; the next steps replay exactly those that followed it."""
        positions, velocities = np.asarray(snapshot.positions_m), np.asarray(snapshot.velocities_m_s)
        if positions.ndim != 2 or positions.shape[1:] != (3,) or velocities.shape != positions.shape:
            raise ValueError(f"restore: expected positions_m and velocities_m_s of shape (n, 3), got "
                             f"{positions.shape} and {velocities.shape}")
        kept = {spec.name: spec for spec in self.state.fields if spec.kept and spec.name not in ("x", "v")}
        for name, values in snapshot.fields.items():
            spec = kept.get(name)
            if spec is None:
                raise ValueError(f"restore: unknown particle field {name!r} in the snapshot; kept fields: "
                                 f"{', '.join(kept)}")
            shape = positions.shape[:1] + (() if spec.components == 1 else (spec.components,))
            if np.shape(values) != shape:
                raise ValueError(f"restore: expected fields[{name!r}] of shape {shape}, got {np.shape(values)}")
        if len(positions) > self.model.capacity:
            raise ValueError(f"restore: {len(positions):,} particles, more than the {self.model.capacity:,} this "
                             f"scene allocates (its blocks and emitters)")
        bodies = None
        if self.bodies is not None:
            bodies = self.bodies.initial_state() if snapshot.bodies is None else np.asarray(snapshot.bodies)
            if bodies.shape != (self.bodies.count, STATE_WIDTH):
                raise ValueError(f"restore: expected bodies of shape ({self.bodies.count}, {STATE_WIDTH}) "
                                 f"(pbf.solver.bodies.STATE_LAYOUT), got {bodies.shape}")
        elif snapshot.bodies is not None and len(snapshot.bodies):
            raise ValueError(f"restore: the snapshot holds {len(snapshot.bodies)} bodies; this scene has none")
        self.state.load({**snapshot.fields, "x": positions, "v": velocities})
        if bodies is not None:
            self.bodies.load(bodies)
        self.emitters.emitted = list(snapshot.emitted_layers or [0] * len(self.scene.emitters))
        self.time_s = snapshot.time_s
        self.frame = snapshot.frame
        # The wave maker's own clock: it stops while control.wave_maker_on is off.
        self.piston_time_s = self.time_s if snapshot.piston_time_s is None else snapshot.piston_time_s
        self.boundaries.move(self.piston_time_s)
        self.frame_substeps = self.control.substeps
        self.last_dt_s = self.scene.time.frame_dt_s / self.control.substeps
        self.iterations_used = 0
        self.pressure_substeps = 0
        """Substeps summed in ``State.pressure_sum`` since the frame began (pressures())."""
        self._sort_by_cell(self.state.x)  # neighbour lists for stats() before the first step
        self.grid.build_neighbours(self.state.x)

    @property
    def dt_s(self) -> float:
        """Δt of the last substep, s (less than frame_dt_s / substeps when the CFL limit added some)."""
        return self.last_dt_s

    def substeps_needed(self) -> int:
        """Substeps for the next frame: the control's, or more so that no particle travels more than
        time.max_cfl spacings in one substep (no tunnelling into the pile at a wall, no blow-up)."""
        t = self.scene.time
        speed = (max(self.diagnostics.max_speed(), self.boundaries.speed_limit_m_s())
                 + float(np.linalg.norm(self.control.gravity_m_s2)) * t.frame_dt_s)
        needed = max(self.control.substeps, math.ceil(speed * t.frame_dt_s / (t.max_cfl * self.scene.fluid.spacing_m)))
        if needed > t.max_substeps:
            warnings.warn(f"{self.scene.name}: particles at {speed:.3g} m/s need {needed} substeps per frame for "
                          f"time.max_cfl = {t.max_cfl}; capped at time.max_substeps = {t.max_substeps}",
                          RuntimeWarning, stacklevel=3)
        return min(needed, t.max_substeps)

    def _sort_by_cell(self, x) -> None:
        """Counting-sort the particles by the cell of ``x``, and reorder the state and x* alike."""
        self.grid.sort_and_permute(x, self.state.index, self.state)

    def _outside_inputs(self, dt: float) -> None:
        """What acts on the water from outside Algorithm 1, before its prediction: new water from the
        nozzles, the user's hand (velocities, capped so the CFL limit holds), and moving walls placed
        where they stand at the end of the substep, where x* is projected."""
        control = self.control
        self.emitters.emit(self.time_s, control.emitters_on)
        if control.push is not None:
            self.integrator.push(control.push, self.scene.time.max_cfl * self.scene.fluid.spacing_m / dt)
            if self.bodies is not None:                          # and the bodies it touches
                self.bodies.grab(control.push, self.scene.time.max_cfl * self.scene.fluid.spacing_m / dt)
        self.piston_time_s += dt if control.wave_maker_on else 0.0
        if self.bodies is not None:                              # the rigid step, with the water's last reaction
            self.bodies.advance(dt, control.gravity_m_s2)
        self.boundaries.move(self.piston_time_s, dt)

    def substep(self, dt: float | None = None) -> None:
        """One PBF step of Δt (Algorithm 1); Δt defaults to frame_dt_s / control.substeps."""
        control, hook = self.control, self.hook
        dt = dt or self.scene.time.frame_dt_s / control.substeps
        target = control.target_density_error
        x_star = self.integrator.predicted
        self._outside_inputs(dt)                                 # emitters, the mouse, moving walls
        with hook.stage("predict"):
            self.integrator.advance(dt, control.gravity_m_s2)    # lines 1-4: v += Δt g, x* = x + Δt v
        with hook.stage("sort by cell"):                         # lines 5-7: find neighbouring particles
            self._sort_by_cell(x_star.first)
        with hook.stage("neighbour lists"):
            self.grid.build_neighbours(x_star.first)
        with hook.stage("divergence pre-correction"):            # ours: v made divergence-free (at x,
            if control.divergence_iterations > 0:                # warm-started), then x* = x + Δt v again
                self.divergence.run(self.grid.neighbours, dt, control.divergence_iterations)
                self.integrator.predict(dt)
        with hook.stage("solver iterations"):
            weights, last_error = self.weights, math.inf
            weights.restart()
            for k in range(control.iterations):                  # lines 8-19: λ, Δx, collision, x* += Δx
                error = self.density.project(x_star, self.grid.neighbours,  # Jacobi, into the other buffer
                                             measure=target > 0.0, first=k == 0, weight=weights.next())
                self.iterations_used = k + 1
                if target > 0.0 and error < target and k + 1 >= control.min_iterations:
                    if control.step_back and k + 1 > control.min_iterations and last_error >= target:
                        # The target fell between the last two errors: take back the share of the last
                        # iteration it did not need, a count in between (DensityConstraint.step_back).
                        self.density.step_back(x_star, (target - error) / (last_error - error))
                    break                                        # the error this iteration started from
                if target > 0.0 and error > last_error:          # the acceleration overshot: plain again
                    weights.restart()
                last_error = error
            x_star.gather()                                      # x* back in the first buffer
        with hook.stage("velocity, vorticity, XSPH, x = x*"):
            self.postprocess.run(x_star.first, self.grid.neighbours, dt,  # lines 20-23: v = (x* − x)/Δt,
                                 control.vorticity, control.xsph,           # confinement, XSPH, x = x*;
                                 self.density.lam_total,                    # and the pressure, summed
                                 self.density.pressure_scale(dt) * self.scene.fluid.rest_density_kg_m3,
                                 self.pressure_substeps == 0)
        if self.bodies is not None:                              # the water's reaction on the bodies
            self.bodies.gather(self.state.x, self.density.lam_total, self.state.multiplier, self.state.active, dt)
        self.pressure_substeps += 1
        self.time_s += dt
        self.last_dt_s = dt

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames of ``scene.time.frame_dt_s`` each (substeps_needed() substeps per frame)."""
        for _ in range(frames):
            self.frame_substeps = self.substeps_needed()
            self.pressure_substeps = 0                           # pressures(): this frame's mean
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
        """(n,) float32 pressure in Pa, in creation order: the mean over the last frame's substeps (or
        over those run since, with :meth:`substep`) of p = −ρ0 h² (L/Δt² + Λ), L the multiplier the
        position iterations moved the particle by and Λ the divergence pre-correction's
        (``DensityConstraint.lam_total``). Under accelerated weights one substep's pressure alternates
        from substep to substep; a frame's mean holds still (docs/VALIDATION.md, the hydrostatic
        tank). Zero before the first substep after a restore. Each particle's value is still noisy (a
        few per cent of ρ0 g H): average over frames for a field."""
        total = self.state.in_creation_order(self.state.pressure_sum)
        return total / np.float32(max(self.pressure_substeps, 1))

    def neighbour_counts(self) -> np.ndarray:
        """(n,) neighbours within h of each particle at the last neighbour search, in creation order."""
        return self.state.in_creation_order(self.grid.neighbour_count).astype(np.int32)

    def body_states(self) -> np.ndarray:
        """(bodies, 19) float32 copy of the rigid bodies' state, in the scene's order
        (``pbf.solver.bodies.STATE_LAYOUT``: position, quaternion (w, x, y, z), velocity, angular
        velocity, the water's last force and torque on each); (0, 19) without bodies."""
        return np.zeros((0, STATE_WIDTH), np.float32) if self.bodies is None else self.bodies.state()

    def readout(self) -> Readout:
        """The particles' device fields, for renderers (no copy to the host)."""
        return Readout(self.particle_count, self.scene.particle_radius_m, self.state.x, self.state.v)

    def density_ratios(self):
        """ρ/ρ0 of every particle as a device field in the order of :meth:`readout`."""
        return self.diagnostics.density_ratios(self.grid.neighbours)

    def stats(self) -> dict:
        """Diagnostics of the current state (see Diagnostics.compute), with time and counts."""
        figures = self.diagnostics.compute(self.grid.neighbours)
        figures.update(time_s=self.time_s, frame=self.frame, particles=self.particle_count,
                       backend=self.backend, iterations=self.iterations_used, substeps=self.frame_substeps)
        return figures
