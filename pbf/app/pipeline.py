"""The simulation one frame ahead in a process of its own, so that the window's rendering overlaps it.

In one process the two cannot overlap: a Taichi kernel launch and GGUI's ``window.show()`` each hold
Python's GIL from start to end (measured: docs/BENCHMARKS.md, "The window"), so a worker thread
would only take turns, and Taichi is not made for kernels launched from two threads at once. On a
2-core CPU a frame then costs the step plus the rendering. ``SimulationProcess`` runs the solver (a
``pbf.solver.Simulation``) in a second process: while the window renders frame k, that process
computes frame k + 1. The particles cross the pipe between the two (a few hundred kilobytes a frame
at the seed scene's size, a fraction of a millisecond) into Taichi fields of this process, which
the renderers read as they read an in-process Simulation's.

It offers the part of Simulation's interface the window and the loop use: ``step``, ``reset``,
``control``, ``readout``, ``density_ratios``, ``stats``, ``positions`` and the figures ``frame``,
``time_s``, ``dt_s``, ``particle_count``, ``scene``, ``model``, ``backend``. What the user changes
in ``control`` (sliders, keys, the mouse's push) reaches the solver with the next frame it starts,
so it shows one frame later than in one process; the frames themselves are the same, bit for bit.
"""
from __future__ import annotations

import multiprocessing
import time
import traceback

import numpy as np
import taichi as ti

from pbf.solver import Model, Readout, Simulation, start_backend


class SimulationProcessError(RuntimeError):
    """The simulation's process failed; the message carries its traceback."""


class SimulationProcess:
    """A Simulation stepped in a second process, one frame ahead of what it shows (see the module)."""

    def __init__(self, scene, arch: str | None = None, quiet: bool = False):
        """``scene`` a ``pbf.Scene`` (validated); ``arch`` as ``Simulation``'s. The memory check and the
        backend's start happen here first, so that their errors are raised here, as Simulation raises
        them; the other process starts Taichi as this one runs it (backend, compiler optimisation)."""
        self.model = Model.from_scene(scene)
        self.backend = start_backend(arch, quiet=quiet)
        fast_compile = not ti.lang.impl.current_cfg().advanced_optimization
        capacity = self.model.capacity
        self.positions_field = ti.Vector.field(3, ti.f32, shape=capacity)
        self.velocities_field = ti.Vector.field(3, ti.f32, shape=capacity)
        self.ratios_field = ti.field(ti.f32, shape=capacity)
        self.ratios_wanted = scene.render.colour_by == "density"
        self._stats_wanted = True
        self._host_positions = np.zeros((0, 3), np.float32)
        self._pending = False
        self._closed = False
        context = multiprocessing.get_context("spawn")  # a fresh interpreter: Taichi does not survive fork
        self._connection, child = context.Pipe()
        self.process = context.Process(target=_serve, name="pbf simulation", daemon=True,
                                       args=(scene, self.backend, fast_compile, child))
        self.process.start()
        child.close()
        self.control = None
        """The solver's ``Control``, as the other process started it; changes go with the next step."""
        self.step_ms = None
        """How long the other process took for the last frame, ms (its own clock)."""
        self._receive(self._answer())

    @property
    def scene(self):
        return self.model.scene

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames: take the frame the other process finished (computing it now if
        none is under way) and start it on the next one with the current control."""
        for _ in range(frames):
            if not self._pending:
                self._request()
            self._receive(self._answer())
            self._request()

    def reset(self) -> None:
        """Back to the scene's initial state (the frame under way is dropped) and its control."""
        if self._pending:
            self._answer()
            self._pending = False
        self._send(("reset", self.ratios_wanted))
        self._receive(self._answer())

    def readout(self) -> Readout:
        return Readout(self.particle_count, self.scene.particle_radius_m, self.positions_field, self.velocities_field)

    def density_ratios(self):
        """ρ/ρ0 per particle in the order of :meth:`readout` (sent with every frame once asked for;
        the scene's ``render.colour_by = "density"`` asks from the start)."""
        self.ratios_wanted = True
        return self.ratios_field

    def stats(self) -> dict:
        """The statistics of the frame shown, or of the latest frame they were computed for: they are
        computed in the other process for the frames after one they were asked of."""
        self._stats_wanted = True
        return dict(self._stats)

    def positions(self) -> np.ndarray:
        """(n, 3) positions of the frame shown, m (in the solver's current order, not creation order)."""
        return self._host_positions.copy()

    def close(self) -> None:
        """End the other process."""
        if self._closed:
            return
        self._closed = True
        try:
            self._send(("stop",))
        except (BrokenPipeError, OSError):
            pass
        self.process.join(timeout=10)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join()
        self._connection.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def _send(self, message) -> None:
        self._connection.send(message)

    def _request(self) -> None:
        self._send(("step", self.control, self._stats_wanted, self.ratios_wanted))
        self._stats_wanted = False
        self._pending = True

    def _answer(self) -> dict:
        try:
            kind, payload = self._connection.recv()
        except EOFError:
            raise SimulationProcessError(f"the simulation's process ended (exit code {self.process.exitcode})") from None
        if kind == "error":
            raise SimulationProcessError(f"the simulation's process failed:\n{payload}")
        return payload

    def _receive(self, frame: dict) -> None:
        """Take a finished frame: its figures and particles."""
        self._pending = False
        self.frame, self.time_s, self.dt_s = frame["frame"], frame["time_s"], frame["dt_s"]
        self.particle_count, self.step_ms = frame["particle_count"], frame["step_ms"]
        if frame["control"] is not None:
            self.control = frame["control"]
        if frame["stats"] is not None:
            self._stats = frame["stats"]
        self.positions_field.from_numpy(frame["positions"])
        self.velocities_field.from_numpy(frame["velocities"])
        self._host_positions = frame["positions"][:self.particle_count]
        if frame["ratios"] is not None:
            self.ratios_field.from_numpy(frame["ratios"])


def _serve(scene, backend: str, fast_compile: bool, connection) -> None:
    """The other process: builds the Simulation, then steps a frame, resets or stops as asked, and
    sends each frame's figures and particles."""
    try:
        start_backend(backend, quiet=True, fast_compile=fast_compile)
        sim = Simulation(scene, arch=backend, quiet=True)

        def frame(step_ms: float, with_stats: bool, with_ratios: bool, with_control: bool) -> tuple:
            particles = sim.readout()
            return ("frame", {
                "frame": sim.frame, "time_s": sim.time_s, "dt_s": sim.dt_s, "particle_count": sim.particle_count,
                "step_ms": step_ms, "positions": particles.positions.to_numpy(),
                "velocities": particles.velocities.to_numpy(),
                "ratios": sim.density_ratios().to_numpy() if with_ratios else None,
                "stats": sim.stats() if with_stats else None, "control": sim.control if with_control else None})

        colour_by_density = scene.render.colour_by == "density"
        connection.send(frame(0.0, True, colour_by_density, True))
        while True:
            message = connection.recv()
            if message[0] == "stop":
                break
            if message[0] == "reset":
                sim.reset()
                connection.send(frame(0.0, True, message[1], True))
                continue
            _, control, with_stats, with_ratios = message
            sim.control = control
            started = time.perf_counter()
            sim.step()
            ti.sync()
            connection.send(frame(1e3 * (time.perf_counter() - started), with_stats, with_ratios, False))
    except (EOFError, KeyboardInterrupt, BrokenPipeError):
        pass  # the window's process went away
    except Exception:  # noqa: BLE001 - everything else goes back to the window's process, which raises it
        try:
            connection.send(("error", traceback.format_exc()))
        except (BrokenPipeError, OSError):
            pass
