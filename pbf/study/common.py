"""What the studies share: scaled scenes, a synchronised timer, the command's exit, and measurements
of the free surface. The sweep, the validation, the lab's benchmarks and the tests import it; it
imports no study module."""

from __future__ import annotations

import os
import sys
import time

import numpy as np
import taichi as ti

from pbf.scene import Scene, load_scene
from pbf.solver import Simulation
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
    (``python -m pbf.study.sweep --help | head -1``) ends it quietly, with 0. The same recipe as
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
