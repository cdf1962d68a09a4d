"""The Simulation: a scene's particles, the PBF step (Macklin & Müller 2013, Algorithm 1) and its readouts."""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass

import numpy as np

from pbf import backend, config
from pbf.boundary import Box
from pbf.density import DensityConstraint
from pbf.diagnostics import Diagnostics
from pbf.grid import NeighbourGrid
from pbf.integrate import Integrator
from pbf.postprocess import VelocityPostprocess
from pbf.state import ParticleState


@dataclass
class LiveSettings:
    """What may change while a simulation runs (the interactive sliders); initialised from the scene."""

    iterations: int
    substeps: int
    target_density_error: float
    xsph: float
    vorticity: float
    gravity_m_s2: tuple[float, float, float]

    @classmethod
    def from_scene(cls, scene: config.Scene) -> LiveSettings:
        return cls(scene.solver.iterations, scene.time.substeps, scene.solver.target_density_error,
                   scene.viscosity.xsph, scene.vorticity.epsilon, scene.gravity_m_s2)


class Simulation:
    """Position Based Fluids in a box.

    >>> sim = Simulation("dam_break")          # a preset name, a TOML path, a dict or a config.Scene
    >>> sim.step()                             # one frame: scene.time.substeps PBF substeps
    >>> sim.positions(), sim.velocities()      # (n, 3) float32 NumPy arrays, m and m/s
    >>> sim.stats()["mean_density_error"]      # dict of diagnostics
    >>> sim.reset()                            # back to the initial state
    """

    def __init__(self, scene: config.Scene | dict | str | os.PathLike, arch: str | None = None,
                 overrides=(), quiet: bool = False):
        if isinstance(scene, dict):
            scene = config.from_dict(scene)
        elif not isinstance(scene, config.Scene):
            scene = config.load(scene, overrides)
        self.scene = scene
        self.backend = backend.start(arch, quiet=quiet)
        self.settings = LiveSettings.from_scene(scene)
        n = config.particle_count(scene)
        self.particle_count = n
        h = scene.kernel_radius_m
        self.particle_mass_kg = config.particle_mass_kg(scene)
        volume = self.particle_mass_kg / scene.fluid.rest_density_kg_m3
        lower, upper = scene.container.min_m, scene.container.max_m
        self.state = ParticleState(n)
        self.box = Box(lower, upper, scene.particle_radius_m, scene.fluid.spacing_m, h, scene.solver.wall_density)
        self.grid = NeighbourGrid(n, lower, upper, h, config.grid_resolution(scene), config.NEIGHBOUR_REACH)
        self.integrator = Integrator(self.state, self.box)
        s = scene.solver
        self.density = DensityConstraint(n, h, scene.fluid.spacing_m, volume, s.relaxation, s.clamp_pressure,
                                         s.scorr_k, s.scorr_n, s.scorr_dq, self.box, self.grid)
        self.postprocess = VelocityPostprocess(self.state, volume, h, self.grid)
        self.diagnostics = Diagnostics(self.state, self.density, self.grid, self.particle_mass_kg)
        self.reset()

    def reset(self) -> None:
        """Restore the scene's initial particles, time and live settings."""
        self.settings = LiveSettings.from_scene(self.scene)
        self.restore({"positions": None, "velocities": None, "time_s": 0.0, "frame": 0})

    def snapshot(self) -> dict:
        """Positions, velocities (NumPy, creation order), time and frame: what :meth:`restore` takes."""
        return {"positions": self.positions(), "velocities": self.velocities(), "time_s": self.time_s,
                "frame": self.frame}

    def restore(self, snapshot: dict) -> None:
        """Return to a :meth:`snapshot` (positions None means the scene's initial particles)."""
        if snapshot["positions"] is None:
            self.state.load(*config.initial_positions(self.scene))
        else:
            self.state.load(snapshot["positions"], snapshot["velocities"])
        self.time_s = snapshot["time_s"]
        self.frame = snapshot["frame"]
        self.frame_substeps = self.settings.substeps
        self.last_dt_s = self.scene.time.frame_dt_s / self.settings.substeps
        self.iterations_used = 0
        self.integrator.x_pred.copy_from(self.state.x)
        self._find_neighbours(self.state.x)

    @property
    def dt_s(self) -> float:
        """Δt of the last substep, s (less than frame_dt_s / substeps when the CFL limit added some)."""
        return self.last_dt_s

    def substeps_needed(self) -> int:
        """Substeps for the next frame: the scene's, or more so that no particle travels more than
        time.max_cfl spacings in one substep (no tunnelling into the pile at a wall, no blow-up)."""
        t = self.scene.time
        speed = self.diagnostics.max_speed() + float(np.linalg.norm(self.settings.gravity_m_s2)) * t.frame_dt_s
        needed = max(self.settings.substeps, math.ceil(speed * t.frame_dt_s / (t.max_cfl * self.scene.fluid.spacing_m)))
        if needed > t.max_substeps:
            warnings.warn(f"{self.scene.name}: particles at {speed:.3g} m/s need {needed} substeps per frame for "
                          f"time.max_cfl = {t.max_cfl}; capped at time.max_substeps = {t.max_substeps}",
                          RuntimeWarning, stacklevel=3)
        return min(needed, t.max_substeps)

    def _find_neighbours(self, x) -> None:
        self.grid.sort(x)
        self.integrator.reorder(self.grid.sorted_from)
        self.grid.build_neighbours(x)

    def substep(self, dt: float | None = None) -> None:
        """One PBF step of Δt (Algorithm 1); Δt defaults to frame_dt_s / settings.substeps."""
        settings = self.settings
        dt = dt or self.scene.time.frame_dt_s / settings.substeps
        target = settings.target_density_error
        x_pred, spare = self.integrator.x_pred, self.density.x_spare
        self.integrator.predict(dt, settings.gravity_m_s2)         # lines 1-4: v += Δt g, x* = x + Δt v
        self._find_neighbours(x_pred)                              # lines 5-7: sorted grid, neighbour lists
        for k in range(settings.iterations):                       # lines 8-19: λ, Δx, collision, x* += Δx
            error = self.density.project(x_pred, spare, self.grid.neighbours, measure=target > 0.0, first=k == 0)
            x_pred, spare = spare, x_pred                          # Jacobi: x* + Δx went into the other buffer
            self.iterations_used = k + 1
            if target > 0.0 and error < target:                    # the error this iteration started from
                break
        self.postprocess.run(x_pred, self.grid.neighbours, dt,     # lines 20-23: v = (x* − x) / Δt, vorticity
                             settings.vorticity, settings.xsph)    # confinement, XSPH, x = x*
        self.time_s += dt
        self.last_dt_s = dt

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames of ``scene.time.frame_dt_s`` each (substeps_needed() substeps per frame)."""
        for _ in range(frames):
            self.frame_substeps = self.substeps_needed()
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
        """(n,) float32 pressure in Pa from the last substep's Lagrange multipliers, in creation order."""
        scale = self.density.pressure_scale(self.dt_s) * self.scene.fluid.rest_density_kg_m3
        return self.state.in_creation_order(self.density.lam_total) * np.float32(scale)

    def neighbour_counts(self) -> np.ndarray:
        """(n,) neighbours within h of each particle at the last neighbour search, in creation order."""
        return self.state.in_creation_order(self.grid.neighbour_count).astype(np.int32)

    def stats(self) -> dict:
        """Diagnostics of the current state (see Diagnostics.compute), with time and counts."""
        figures = self.diagnostics.compute(self.grid.neighbours)
        figures.update(time_s=self.time_s, frame=self.frame, particles=self.particle_count,
                       backend=self.backend, iterations=self.iterations_used, substeps=self.frame_substeps)
        return figures
