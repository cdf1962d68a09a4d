"""One loop for every way of running a scene: the window, headless frames and statistics only.

The loop steps the simulation and hands each frame to a viewer (as Newton's examples take a viewer,
with a null one for headless runs). A viewer decides when to step (the window pauses), shows each
frame (draws it, writes it to files, or prints statistics) and says when to stop.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol


class Viewer(Protocol):
    def running(self) -> bool:
        """False once the viewer is done (the window was closed)."""

    def advance(self) -> bool:
        """Handle input since the last frame; whether the simulation steps one frame now."""

    def show(self) -> None:
        """Present the simulation's current frame."""

    def close(self) -> None:
        """Release what the viewer holds (files, progress bars); called however the loop ends."""


def run(sim, viewer: Viewer, frames: int | None = None, first_shown: Callable[[], None] | None = None) -> None:
    """Show the current state, then step and show until the viewer stops or ``frames`` frames were
    stepped (None: until the viewer stops). ``first_shown`` is called once the first frame is shown
    (the command line says then how long the start took)."""
    stepped = 0
    try:
        viewer.show()
        if first_shown is not None:
            first_shown()
        while viewer.running() and (frames is None or stepped < frames):
            if viewer.advance():
                sim.step()
                stepped += 1
            viewer.show()
    finally:
        viewer.close()


def warm_up(sim) -> float:
    """Run the first frame's first substep and return to the start, so that the step's kernels are
    compiled (or loaded from Taichi's offline cache) before the first picture rather than after it;
    ``reset`` restores the start exactly, so the run is the one it would have been. One substep, not
    a frame: a frame's substeps run the same kernels, and a whole frame of a million particles took
    5 s of every start on a CPU. Returns the seconds it took."""
    started = time.perf_counter()
    sim.substep(sim.scene.time.frame_dt_s / sim.substeps_needed())
    sim.reset()
    return time.perf_counter() - started


def stats_line(sim) -> str:
    s = sim.stats()
    return (
        f"t = {s['time_s']:6.2f} s  density error mean {s['mean_density_error']:.3%} "
        f"max {s['max_density_error']:.2%}  max speed {s['max_speed_m_s']:.2f} m/s  "
        f"KE {s['kinetic_energy_j']:.3g} J  neighbours {s['mean_neighbours']:.1f} (max {s['max_neighbours']})"
    )


class StatsViewer:
    """The null viewer (``--stats-only``): renders nothing, prints statistics once a simulated second
    and after the last frame, and the frame rate at the end."""

    def __init__(self, sim, frames: int):
        self.sim = sim
        self.frames = frames
        self.frames_per_report = max(1, round(1.0 / sim.scene.time.frame_dt_s))
        self.started: float | None = None
        """When the first frame was shown: the kernels are ready by then (``warm_up``), so the rate at the end
        is the stepping's own."""

    def running(self) -> bool:
        return True

    def advance(self) -> bool:
        return True

    def show(self) -> None:
        frame = self.sim.frame
        if self.started is None:
            self.started = time.perf_counter()
        if frame and (frame % self.frames_per_report == 0 or frame == self.frames):
            print(stats_line(self.sim))

    def close(self) -> None:
        if self.started is None:
            return
        elapsed = max(time.perf_counter() - self.started, 1e-9)
        frames = f"{self.sim.frame} frame{'' if self.sim.frame == 1 else 's'}"
        print(f"[pbf] {frames} in {elapsed:.1f} s ({self.sim.frame / elapsed:.1f} frames/s)")
