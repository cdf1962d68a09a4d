"""What the studies share: scaled scenes, timing (a stage hook and a synchronised timer) and
measurements of the free surface. Benchmarks, the sweep, the validation and the tests import it;
it imports no study module."""

from __future__ import annotations

import contextlib
import os
import statistics
import sys
import time
from collections import defaultdict

import numpy as np
import taichi as ti

from pbf.scene import Scene, load_scene
from pbf.solver import STAGES, Simulation
from pbf.solver.launch import Observer, watching
from pbf.solver.sph import kernel_np


def scaled(preset: str, particles: int, reference: int, overrides=()) -> Scene:
    """``preset`` (which holds ``reference`` particles) with its spacing scaled to hold about ``particles``.

    The spacing is chosen so that the first block stays a whole number of spacings wide: a block that
    fills its container wall to wall then still does, and starts at rest.
    """
    base = load_scene(preset)
    block = base.fluid.blocks[0]
    across = round((block.max_m[0] - block.min_m[0]) / base.fluid.spacing_m)
    spacing = base.fluid.spacing_m * across / round(across * (particles / reference) ** (1 / 3))
    return load_scene(preset, [f"fluid.spacing_m={spacing!r}", *overrides])


def dam_break(particles: int, iterations: int, overrides=()) -> Scene:
    """The dam break scaled to ``particles``, Δt with the spacing (Δt ∝ spacing keeps the distance a
    particle moves per substep, in spacings, the same: the scene stays equally hard)."""
    base = load_scene("dam_break")
    substeps = max(1, round(base.time.substeps * (particles / 8000) ** (1 / 3)))
    return scaled(
        "dam_break", particles, 8000, [f"solver.iterations={iterations}", f"time.substeps={substeps}", *overrides]
    )


def run_command(main) -> None:
    """Run a study's ``main()`` as its command and exit with its status (an int; anything else, such as
    the rows a study returns to its Python callers, is success); a reader that stops early
    (``python -m pbf.study.bench --help | head -1``) ends it quietly, with 0. The same recipe as
    ``pbf.app.cli``'s, kept here because a study imports the application only where it studies it."""
    try:
        status = main()
        sys.stdout.flush()  # here, where a closed pipe is caught, not in Python's flush at exit
    except BrokenPipeError:
        # Python flushes stdout again at exit, which would fail the same way: what is left goes to devnull.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        status = 0
    raise SystemExit(status if isinstance(status, int) else 0)


def timed(function, *args):
    """Seconds ``function(*args)`` takes, with the device synchronised before and after."""
    ti.sync()
    start = time.perf_counter()
    function(*args)
    ti.sync()
    return time.perf_counter() - start


class TransferCounter(Observer):
    """Counts Taichi's kernel launches and device-to-host reads while active (a context manager).

    A device-to-host read is anything that makes the host wait for a result from the device:
    - a kernel launch that returns a value (``-> ti.i32``, a tuple, ...);
    - a kernel launch given a NumPy array (Taichi copies the array to the device and, on GPU backends,
      the whole of it back after the launch; ``to_numpy`` and ``from_numpy`` are such launches);
    - reading an element of a field or ndarray from Python (``field[None]``, ``field[i]``).
    A launch is every call of a ``@ti.kernel``, Taichi's own (``to_numpy``, ``fill``...) included;
    writing an element from Python (``field[None] = v``) launches a small writer kernel and is counted
    with the launches, not with the reads. ``ti.sync()`` is neither. What Taichi does is seen through
    ``pbf.solver.launch.watching``, the one place that reads Taichi's internals."""

    def __init__(self):
        self.launches = 0
        self.reads = 0
        self._watching = None

    def launched(self, kernel: str, waits: bool) -> None:
        self.launches += 1
        self.reads += waits

    def accessed(self, read: bool) -> None:
        self.launches += 1
        self.reads += read

    def __enter__(self):
        self._watching = watching(self)
        self._watching.__enter__()
        return self

    def __exit__(self, *exc):
        self._watching.__exit__(*exc)
        self._watching = None
        return False


class StageTimer:
    """A stage hook for ``Simulation.hook``: times every stage of every substep it sees, with the device
    synchronised around each (so stages add up to a little more than an untimed substep)."""

    def __init__(self):
        self.ms: dict[str, list[float]] = defaultdict(list)
        """Milliseconds of each call, by stage name."""

    @contextlib.contextmanager
    def stage(self, name: str):
        ti.sync()
        start = time.perf_counter()
        yield
        ti.sync()
        self.ms[name].append((time.perf_counter() - start) * 1e3)

    def medians(self) -> dict[str, float]:
        """Median ms of each stage, in the order of the substep."""
        return {name: statistics.median(self.ms[name]) for name in STAGES if self.ms[name]}


def stage_breakdown(sim: Simulation, substeps: int) -> dict[str, float]:
    """Median ms of each stage over ``substeps`` substeps of the running simulation, at its last Δt."""
    timer, previous = StageTimer(), sim.hook
    sim.hook = timer
    try:
        for _ in range(substeps):
            sim.substep(sim.dt_s)
    finally:
        sim.hook = previous
    return timer.medians()


def fill_height_m(sim: Simulation) -> float:
    """The analytic fill height: the water's mass at ρ0 spread over the container floor, N V / A (m).

    V = m/ρ0 is 0.43% less than s³ at h = 2.2 s (the mass comes from the kernel's lattice sum, so that
    the lattice is at ρ0), so this lies a little below the top of the initial lattice.
    """
    lower, upper = sim.scene.container.min_m, sim.scene.container.max_m
    return sim.particle_count * sim.model.particle_volume_m3 / ((upper[0] - lower[0]) * (upper[2] - lower[2]))


def colour_surface_height(positions, volume_m3, h, xs, zs, y_range) -> float:
    """Height where the SPH colour field Σ_j V W(x − x_j) falls to ½: the free surface, averaged over
    vertical probes at every (x, z) of ``xs`` × ``zs``. Each probe samples 400 heights over
    ``y_range`` and interpolates linearly between the two around the crossing (the samples alone put
    every height on a 2-mm grid, as coarse as the wave heights and surface sags it measures)."""
    ys = np.linspace(*y_range, 400)
    heights = []
    for x in xs:
        for z in zs:
            probes = np.stack([np.full_like(ys, x), ys, np.full_like(ys, z)], axis=1)
            near = positions[(np.abs(positions[:, 0] - x) < h) & (np.abs(positions[:, 2] - z) < h)]
            distances = np.linalg.norm(probes[:, None, :] - near[None, :, :], axis=2)
            colour = volume_m3 * kernel_np(distances, h).sum(axis=1)
            k = int(np.argmax(colour < 0.5))  # the first sample below ½; 0 when the first is, or none is
            if k == 0:
                heights.append(ys[0])
            else:
                heights.append(ys[k - 1] + (colour[k - 1] - 0.5) / (colour[k - 1] - colour[k]) * (ys[k] - ys[k - 1]))
    return float(np.mean(heights))
