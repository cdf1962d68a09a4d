"""Our PBF against SPlisHSPlasH 2.19's DFSPH and PBF on the seed dam break: cost and density error.

    python benchmarks/splishsplash.py --splash /tmp/sphvenv/bin/splash                    # the default rows
    python benchmarks/splishsplash.py --splash /tmp/sphvenv/bin/splash --sloshing         # the standing wave's decay
    python benchmarks/splishsplash.py --splash /tmp/sphvenv/bin/splash --methods dfsph \\
        --param maxError=0.01 --param "maxError=0.1,maxIterations=50" \\
        --ours "substeps=4,iterations=4" "substeps=4,target=0.001,max_iterations=30" --seconds 0.25

Install SPlisHSPlasH apart from this project (it needs NumPy 1, and its bundled libGLdispatch clashes
with the system one, so it runs as its own process, ``splash --no-gui``, with the system library
preloaded): ``python3 -m venv /tmp/sphvenv && /tmp/sphvenv/bin/pip install pysplishsplash==2.19.0
"numpy<2"``.

Every simulator runs the ``dam_break`` preset (8,000 particles at 25 mm in a 0.8 m box, the block
0.1 m above the floor) for ``--seconds`` (1 s) and is measured at the same 60 frames per second.

* SPlisHSPlasH: for each ``--methods`` (``dfsph``: simulationMethod 4, its flagship, which its own
  DamBreakModel scene uses; ``pbf``: simulationMethod 2) and each ``--param`` set (by default its
  shipped stopping rules, minIterations 2, maxIterations 100, with maxError 0.01 and 0.1; its maxError
  is in percent; DFSPH keeps its divergence solver at its defaults, enableDivergenceSolver true,
  maxIterationsV 100, maxErrorV 0.1), one run at a fixed step (``cflMethod`` 0, ``--dt-ms``),
  ``--threads`` OpenMP threads, Akinci boundary particles for the box, XSPH 0.01 as ours (its
  ``XSPH`` block; no viscosity method, no vorticity). The parameters go into the scene file's block of
  the method ("DFSPH", "PBF"), where 2.19 reads them; the values it applied are read back from it
  and printed. Its time is its own mean "SimStep" (which leaves out its exports), its iterations its
  own "Average number" counters.
* Placement: SPlisHSPlasH puts a block's first particle one diameter (2r = one spacing) inside the
  block's ``start``, and its boundary particles sit on the box's surface, so ``start`` is the preset
  block's corner and ``end`` one spacing past the far corner (20 × 20 × 20 particles). Its first layer
  is then one spacing from the wall particles, as its fluid-fluid spacing; at half a spacing the block
  explodes out of the box. The script prints the initial placement, the nearest particle to each wall
  plane in the first exported frame (after one step) and how many particles ever leave the box.
* Density error, the same for every simulator: the mean over the exported frames (60 per second, the
  initial state left out) of the mean over particles of max(ρ/ρ0 − 1, 0), and the max over frames of
  the max. For SPlisHSPlasH from the ``density`` it exports (VTK); the script also recomputes ρ from
  the exported positions with its own kernel (its ``Simulation.W``, sampled and checked), fluid volumes
  and boundary particles with their volumes, read from SPlisHSPlasH itself through its Python module,
  and prints both. For ours ``Simulation.stats()`` after each frame: the density of the positions we
  output. The rows compare the exported figures; the recomputed ones are printed beside them.
* Ours: each ``--ours`` spec is a comma-separated list of ``--set`` overrides of the ``dam_break``
  preset, with short names ``substeps`` (time.substeps), ``iterations`` and ``max_iterations``
  (solver.iterations: the most, with a target), ``target`` (solver.target_density_error, a fraction:
  0.001 = 0.1%), ``kernel_ratio`` (solver.kernel_ratio), ``xsph`` (viscosity.xsph), ``divergence``
  (solver.divergence_iterations, our divergence pre-correction) or any dotted key; a spec without a
  target runs a fixed count (the preset's target is set to 0), and ``preset`` keeps the preset's own
  solver settings (its target included). Vorticity confinement is off (``vorticity.epsilon`` = 0), as in
  SPlisHSPlasH, and ``time.max_cfl``
  is raised to the most the scene allows (solver.kernel_ratio) so that the CFL limit does not add
  substeps to the steps asked (at substeps = 4 both simulators take the same 240 steps); the steps
  actually taken are printed. Time is ``step()`` alone per frame, synchronised, the statistics taken
  outside the timer.
* ``--sloshing``: instead of the dam break, the standing wave of ``pbf.study.damping`` in each
  ``--methods`` and in ours: the ``sloshing`` preset's tank and water (1,950 particles), settled for
  a second (velocities × 0.9 after each step, as ours settles), then given its first sloshing mode's
  linear velocity field at 10 mm amplitude, and followed three periods at SPlisHSPlasH's fixed step
  of a quarter of our frame (ours: the preset's four substeps). Its container is one spacing wider
  in x and z, so that its boundary particles, on the walls, stand one spacing from the water as in
  its dam break; the mode is placed on the water's own extent. Both are measured alike: the mode's
  amplitude in the particles' velocities every frame, and its decay per period fitted to the extrema
  (``pbf.study.damping.decay_per_period``).
* Times on a shared machine swing several-fold (SPlisHSPlasH's most: DFSPH at maxError 0.01 took
  26 to 264 ms per step in runs of the same day); the errors hardly do (ours repeat to the bit;
  SPlisHSPlasH's mean errors to 1%, its max errors to a fifth, and its PBF loses 5 to 13 particles
  out of the box, as its OpenMP sums fall). Take timings on a quiet machine.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pbf.scene import SceneError, load_scene
from pbf.solver import Simulation, start_backend
from pbf.study.common import timed

SYSTEM_GLDISPATCH = "/lib/x86_64-linux-gnu/libGLdispatch.so.0"
PRESET = "dam_break"

SPLASH_METHODS = {
    # name: (simulationMethod, the scene file's block and log counter prefix, its defaults as shipped)
    "dfsph": (
        4,
        "DFSPH",
        {
            "minIterations": 2,
            "maxIterations": 100,
            "maxError": 0.01,
            "enableDivergenceSolver": True,
            "maxIterationsV": 100,
            "maxErrorV": 0.1,
        },
    ),
    "pbf": (2, "PBF", {"minIterations": 2, "maxIterations": 100, "maxError": 0.01, "velocityUpdateMethod": 0}),
}
SPLASH_PARAMETER_IDS = {  # the static parameter ids of its TimeStep classes, and their getters
    "minIterations": ("MIN_ITERATIONS", "UInt"),
    "maxIterations": ("MAX_ITERATIONS", "UInt"),
    "maxError": ("MAX_ERROR", "Float"),
    "maxIterationsV": ("MAX_ITERATIONS_V", "UInt"),
    "maxErrorV": ("MAX_ERROR_V", "Float"),
    "enableDivergenceSolver": ("USE_DIVERGENCE_SOLVER", "Bool"),
    "velocityUpdateMethod": ("VELOCITY_UPDATE_METHOD", "Int"),
}
SPLASH_KERNELS = {0: "cubic spline", 2: "Poly6 (gradients: Spiky)", 4: "cubic spline, tabulated"}

OUR_SHORT_KEYS = {
    "substeps": "time.substeps",
    "iterations": "solver.iterations",
    "max_iterations": "solver.iterations",
    "target": "solver.target_density_error",
    "kernel_ratio": "solver.kernel_ratio",
    "xsph": "viscosity.xsph",
    "divergence": "solver.divergence_iterations",
}

# Run inside SPlisHSPlasH's own environment on the run's scene file: builds the scene (and its
# boundary particles) with one step, and writes what the density check needs and the parameters it
# applied. Nothing of it is timed.
SPLASH_PROBE = r"""
import json, sys
import numpy as np
import pysplishsplash as sph
scene, out, npz, ids = sys.argv[1], sys.argv[2], sys.argv[3], json.loads(sys.argv[4])
base = sph.Exec.SimulatorBase()
base.init(["splash", "--no-gui", "--no-initial-pause", "--stopAt", "1e-9", "--output-dir", out, scene], "probe")
base.initSimulation()
sim = sph.Simulation.getCurrent()
fluid = sim.getFluidModel(0)
x0 = np.array([fluid.getPosition(i) for i in range(fluid.numActiveParticles())])
base.runSimulation()  # one step: the boundary particles and their volumes exist from here on
walls = sim.getBoundaryModel(0)
boundary = np.array([walls.getPosition(i) for i in range(walls.numberOfParticles())])
volumes = np.array([walls.getVolume(i) for i in range(walls.numberOfParticles())])
h = sim.getSupportRadius()
r = np.linspace(0.0, 1.02 * h, 2041)
w = np.array([sim.W(np.array([ri, 0.0, 0.0])) for ri in r])
step = sim.getTimeStep()
applied = {name: getattr(step, "getValue" + getter)(getattr(type(step), attr))
           for name, (attr, getter) in ids.items() if hasattr(type(step), attr)}
xsph = fluid.getXSPH()
applied.update(
    timeStepSize=sph.TimeManager.getCurrent().getTimeStepSize(), cflMethod=sim.getValueInt(sim.CFL_METHOD),
    boundaryHandlingMethod=int(getattr(sim.getBoundaryHandlingMethod(), "value", sim.getBoundaryHandlingMethod())),
    simulationMethod=int(getattr(sim.getSimulationMethod(), "value", sim.getSimulationMethod())),
    kernel=sim.getKernel(), gradKernel=sim.getGradKernel(),
    xsph=xsph.getValueFloat(sph.XSPH.FLUID_COEFFICIENT), xsphBoundary=xsph.getValueFloat(sph.XSPH.BOUNDARY_COEFFICIENT),
    viscosityMethod=fluid.getValueInt(sph.FluidModel.VISCOSITY_METHOD),
    vorticityMethod=fluid.getValueInt(sph.FluidModel.VORTICITY_METHOD))
np.savez(npz, x0=x0, boundary=boundary, boundary_volume=volumes, fluid_volume=fluid.getVolume(0),
         density0=fluid.getDensity0(), support=h, r=r, w=w, applied=json.dumps(applied))
"""


# ----------------------------------------------------------------------------- SPlisHSPlasH


def splash_scene(method: str, params: dict, dt_s: float, seconds: float, box_obj: Path) -> dict:
    """SPlisHSPlasH's scene file for the preset (see the module docstring for each choice)."""
    scene = load_scene(PRESET)
    block, spacing = scene.fluid.blocks[0], scene.fluid.spacing_m
    lower, upper = np.array(scene.container.min_m), np.array(scene.container.max_m)
    simulation_method, block_name, _ = SPLASH_METHODS[method]
    return {
        "Configuration": {
            "particleRadius": spacing / 2,
            "simulationMethod": simulation_method,
            "gravitation": list(scene.gravity_m_s2),
            "timeStepSize": dt_s,
            "cflMethod": 0,
            "boundaryHandlingMethod": 0,
            "stopAt": seconds,
            "enableVTKExport": True,
            "dataExportFPS": round(1 / scene.time.frame_dt_s),
            "particleAttributes": "density",
            block_name: params,
        },
        "Materials": [
            {
                "id": "Fluid",
                "density0": scene.fluid.rest_density_kg_m3,
                "viscosityMethod": 0,
                "vorticityMethod": 0,
                "XSPH": {"xsph": scene.viscosity.xsph, "xsphBoundary": 0.0},
            }
        ],
        "RigidBodies": [
            {
                "geometryFile": str(box_obj),
                "translation": list((lower + upper) / 2),
                "scale": list(upper - lower),
                "isDynamic": False,
                "isWall": True,
                "mapInvert": True,
                "mapThickness": 0.0,
                "mapResolution": [20, 20, 20],
            }
        ],
        # Its particles start one diameter (one spacing) inside `start` and fill round((end − start)/s) − 1
        # per axis: `end` one spacing past the block gives the preset's 20 per axis.
        "FluidBlocks": [{"denseMode": 0, "start": list(block.min_m), "end": list(np.array(block.max_m) + spacing)}],
    }


def read_vtk(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (n, 3), ids (n,) and ``density`` (n,) of a legacy binary VTK file from SPlisHSPlasH."""
    data = path.read_bytes()
    points = re.search(rb"POINTS (\d+) float\n", data)
    ids = re.search(rb"LOOKUP_TABLE id_table\n", data)
    density = re.search(rb"\ndensity 1 (\d+) float\n", data)
    if not (points and ids and density):
        raise ValueError(f"{path}: expected float POINTS, ids and a density field")
    n = int(points.group(1))
    return (
        np.frombuffer(data, ">f4", 3 * n, points.end()).reshape(n, 3).astype(np.float64),
        np.frombuffer(data, ">u4", n, ids.end()).astype(np.int64),
        np.frombuffer(data, ">f4", n, density.end()).astype(np.float64),
    )


def splash_kernel(kernel: int, support: float):
    """SPlisHSPlasH's W(r) for its kernel id (3D), in NumPy, float64."""
    h = support
    if kernel in (0, 4):  # CubicKernel (4: the same, tabulated at 10,000 points)
        k = 8.0 / (math.pi * h**3)

        def cubic(r):
            q = r / h
            return np.where(q <= 0.5, k * (6 * q**3 - 6 * q**2 + 1), np.where(q <= 1.0, 2 * k * (1 - q) ** 3, 0.0))

        return cubic
    if kernel == 2:  # Poly6Kernel
        k = 315.0 / (64.0 * math.pi * h**9)
        return lambda r: np.where(r <= h, k * np.clip(h * h - r * r, 0.0, None) ** 3, 0.0)
    raise ValueError(f"SPlisHSPlasH kernel {kernel} is not implemented here")


def neighbour_pairs(points: np.ndarray, sources: np.ndarray, h: float) -> tuple[np.ndarray, ...]:
    """Every pair (i of points, j of sources) within h, with its distance, by a grid of h-wide cells."""
    lower = np.minimum(points.min(0), sources.min(0)) - 2 * h
    source_cells = np.floor((sources - lower) / h).astype(np.int64)
    point_cells = np.floor((points - lower) / h).astype(np.int64)
    dims = np.maximum(source_cells.max(0), point_cells.max(0)) + 3

    def key(cells):
        return (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]

    source_keys = key(source_cells)
    order = np.argsort(source_keys, kind="stable")
    source_keys = source_keys[order]
    found = []
    for offset in itertools.product((-1, 0, 1), repeat=3):
        wanted = key(point_cells + np.array(offset))
        first = np.searchsorted(source_keys, wanted, "left")
        count = np.searchsorted(source_keys, wanted, "right") - first
        i = np.repeat(np.arange(len(points)), count)
        j = order[np.repeat(first, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)]
        r = np.linalg.norm(points[i] - sources[j], axis=1)
        near = r <= h
        found.append((i[near], j[near], r[near]))
    return tuple(np.concatenate(parts) for parts in zip(*found))


def kernel_sum(pairs: tuple[np.ndarray, ...], weights: np.ndarray, kernel, n: int) -> np.ndarray:
    """Σ_j weights_j W(r_ij) for each of n points over ``neighbour_pairs``."""
    i, j, r = pairs
    return np.bincount(i, weights=kernel(r) * weights[j], minlength=n)


def splash_density(
    x: np.ndarray, fluid_volume: float, boundary: np.ndarray, boundary_volume: np.ndarray, h: float, kernels: list
) -> list[np.ndarray]:
    """ρ/ρ0 of every particle at positions x for each of ``kernels``, as SPlisHSPlasH sums it with
    Akinci boundary particles: V_f Σ_fluid W (itself included) + Σ_boundary V_b W."""
    fluid_pairs, wall_pairs = neighbour_pairs(x, x, h), neighbour_pairs(x, boundary, h)
    volumes = np.full(len(x), fluid_volume)
    return [
        kernel_sum(fluid_pairs, volumes, kernel, len(x)) + kernel_sum(wall_pairs, boundary_volume, kernel, len(x))
        for kernel in kernels
    ]


@dataclass
class Row:
    """One run's figures."""

    label: str
    dt_ms: float
    steps: int
    iterations: float
    ms_per_step: float
    compute_s_per_s: float
    mean_error: float
    max_error: float
    frames: int
    divergence_iterations: float | None = None
    recomputed_mean: float | None = None
    recomputed_max: float | None = None
    left_box: int | None = None
    settings: str = ""
    spec: str = ""
    """Ours: the --ours spec the row ran."""
    notes: list[str] = field(default_factory=list)


def splash_interpreter(splash: Path) -> str:
    """The Python of SPlisHSPlasH's environment: the splash script's own interpreter."""
    first = splash.read_text(errors="replace").splitlines()[0]
    return first[2:].strip() if first.startswith("#!") else str(splash.parent / "python")


def run_splishsplash(splash: Path, method: str, params: dict, dt_s: float, seconds: float, threads: int) -> Row:
    scene = load_scene(PRESET)
    frame_dt, spacing = scene.time.frame_dt_s, scene.fluid.spacing_m
    lower, upper = np.array(scene.container.min_m), np.array(scene.container.max_m)
    box_obj = splash.parent / "data" / "models" / "UnitBox.obj"
    _, block_name, _ = SPLASH_METHODS[method]
    env = dict(os.environ, LD_PRELOAD=SYSTEM_GLDISPATCH, OMP_NUM_THREADS=str(threads))
    with tempfile.TemporaryDirectory() as tmp:
        scene_path = Path(tmp) / "dam_break.json"
        scene_path.write_text(json.dumps(splash_scene(method, params, dt_s, seconds, box_obj), indent=1))
        probe = subprocess.run(
            [
                splash_interpreter(splash),
                "-c",
                SPLASH_PROBE,
                str(scene_path),
                str(Path(tmp) / "probe"),
                str(Path(tmp) / "probe.npz"),
                json.dumps(SPLASH_PARAMETER_IDS),
            ],
            env=env,
            capture_output=True,
            text=True,
        )
        if probe.returncode:
            sys.exit(f"SPlisHSPlasH probe failed ({probe.returncode}):\n{probe.stdout[-2000:]}{probe.stderr[-2000:]}")
        meta = np.load(Path(tmp) / "probe.npz")
        out = Path(tmp) / "out"
        result = subprocess.run(
            [str(splash), "--no-gui", "--no-initial-pause", "--output-dir", str(out), str(scene_path)],
            env=env,
            capture_output=True,
            text=True,
        )
        if result.returncode:
            sys.exit(f"{splash} failed ({result.returncode}):\n{result.stdout[-2000:]}{result.stderr[-2000:]}")
        log = result.stdout

        def number(pattern):
            found = re.search(pattern + r": ([-+\d.eE]+)", log)
            return float(found.group(1)) if found else None

        step_ms, sum_ms = number(r"Average time: SimStep"), number(r"Time sum: SimStep")
        mean_dt, total_time = number(r"Average number: Time step size"), number(r"Total number: Time step size")
        iterations = number(rf"Average number: {block_name} - iterations")
        divergence = number(rf"Average number: {block_name} - iterationsV")
        frames = sorted((out / "vtk").glob("ParticleData_Fluid_*.vtk"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
        if len(frames) < 2 or None in (step_ms, sum_ms, mean_dt, total_time, iterations):
            sys.exit(
                f"{splash}: {len(frames)} exported frames, or its log lacks SimStep, time step or iteration "
                f"figures:\n{log[-2000:]}"
            )

        # Its own kernel, checked against its Simulation.W; its fluid volume; its boundary particles.
        applied = json.loads(str(meta["applied"]))
        h, rho0, fluid_volume = float(meta["support"]), float(meta["density0"]), float(meta["fluid_volume"])
        kernel = splash_kernel(applied["kernel"], h)
        cubic = splash_kernel(0, h)  # TimeStep::computeDensities, which writes the exported density in
        # its AVX build (the wheel's), sums the cubic spline whatever the kernel setting; its PBF's own is Poly6
        kernels = [kernel] if applied["kernel"] in (0, 4) else [kernel, cubic]
        kernel_gap = float(np.abs(meta["w"] - kernel(meta["r"])).max() / kernel(np.zeros(1))[0])
        boundary, boundary_volume = meta["boundary"], meta["boundary_volume"]
        x0 = meta["x0"]
        initial = splash_density(x0, fluid_volume, boundary, boundary_volume, h, [kernel])[0]

        means, maxima, re_means, re_maxima, gaps, cubic_gaps = [], [], [], [], [], []
        left, first_left = set(), None
        for k, path in enumerate(frames):
            x, ids, rho = read_vtk(path)
            outside = np.any((x < lower) | (x > upper), axis=1)
            if outside.any() and first_left is None:
                first_left = k
            left.update(ids[outside].tolist())
            if k == 0:  # after its first step (it exports once time ≥ 0): the placement check, no error
                first_x = x
                continue
            error = np.maximum(rho / rho0 - 1.0, 0.0)
            ratios = splash_density(x, fluid_volume, boundary, boundary_volume, h, kernels)
            error_again = np.maximum(ratios[0] - 1.0, 0.0)
            means.append(error.mean())
            maxima.append(error.max())
            re_means.append(error_again.mean())
            re_maxima.append(error_again.max())
            gaps.append(np.abs(ratios[0] * rho0 - rho).max() / rho0)
            if len(ratios) > 1:
                cubic_gaps.append(np.abs(ratios[1] * rho0 - rho).max() / rho0)

    wanted = round(seconds / frame_dt)
    if len(means) != wanted:
        print(f"warning: SPlisHSPlasH exported {len(means)} frames after the first step, not {wanted}")
    defaults = SPLASH_METHODS[method][2]
    shown = ",".join(f"{k}={_num(v)}" for k, v in params.items() if k == "maxError" or v != defaults[k])
    row = Row(
        f"SPlisHSPlasH {block_name} {shown}",
        dt_s * 1e3,
        round(total_time / mean_dt),
        iterations,
        step_ms,
        sum_ms / 1e3 / total_time,
        float(np.mean(means)),
        float(max(maxima)),
        len(means),
        divergence,
        float(np.mean(re_means)),
        float(max(re_maxima)),
        len(left),
    )
    mm = 1e3
    names = ("x = min", "y = min (floor)", "z = min", "x = max", "y = max", "z = max")
    distances = lambda x: np.concatenate([x.min(0) - lower, upper - x.max(0)]) * mm  # noqa: E731
    timers = re.findall(r"Average time: ([^:\n]+): ([\d.eE+-]+) ms", log)
    row.notes += [
        "its timers, mean ms per call: "
        + ", ".join(f"{name} {float(ms):.2f}" for name, ms in timers if "sampling" not in name),
        "applied by SPlisHSPlasH: " + ", ".join(f"{k} {_num(v)}" for k, v in applied.items()),
        f"kernel: {SPLASH_KERNELS.get(applied['kernel'], applied['kernel'])}, support {h * mm:.1f} mm "
        f"= {h / spacing:.1f} spacings; largest gap to its Simulation.W {kernel_gap:.1e} of W(0); fluid volume "
        f"{fluid_volume / spacing**3:.3f} s³; {len(boundary):,} boundary particles",
        f"placement: {len(x0):,} particles; nearest to each wall at the start, mm: "
        + ", ".join(f"{n} {d:.1f}" for n, d in zip(names, distances(x0)))
        + (
            "; first layer one spacing from the wall particles: yes"
            if distances(x0).min() >= 0.75 * spacing * mm
            else f"; WARNING: closer than one spacing ({spacing * mm:.1f} mm) to its wall particles"
        ),
        "  in exported frame 1 (after its first step): "
        + ", ".join(f"{n} {d:.1f}" for n, d in zip(names, distances(first_x)))
        + f"; nearest boundary particle {_nearest(first_x, boundary, h) * mm:.1f} mm",
        f"  initial density ρ/ρ0 by its kernel: bulk {np.median(initial):.4f}, largest {initial.max():.4f} "
        f"(the layer against its wall particles)",
        f"particles that left the box: {len(left)}" + (f" (first in exported frame {first_left + 1})" if left else ""),
        f"exported density vs recomputed from the exported positions: mean error {row.mean_error:.3%} vs "
        f"{row.recomputed_mean:.3%}, max {row.max_error:.2%} vs {row.recomputed_max:.2%}, largest particle "
        f"difference {max(gaps):.2%} of ρ0"
        + (
            f"; its exported density is the cubic spline's (with the boundary volumes of its kernel): recomputed "
            f"so, the largest particle difference is {max(cubic_gaps):.2%} of ρ0"
            if cubic_gaps
            else ""
        ),
    ]
    return row


def _nearest(points: np.ndarray, others: np.ndarray, reach: float) -> float:
    """The smallest distance between any of ``points`` within ``reach`` of the bounding box's faces of
    ``others`` and any of ``others`` (the wall particles lie on those faces)."""
    near = points[np.any((points < others.min(0) + reach) | (points > others.max(0) - reach), axis=1)]
    best = np.inf
    for start in range(0, len(near), 100):
        chunk = near[start : start + 100]
        best = min(best, float(np.sqrt(((chunk[:, None, :] - others[None, :, :]) ** 2).sum(-1)).min()))
    return best


def _num(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


# ----------------------------------------------------------------------------- ours


class IterationCount:
    """A stage hook that adds up the solver iterations of every substep (one Python call per stage)."""

    _null = contextlib.nullcontext()

    def __init__(self):
        self.sim: Simulation | None = None
        self.iterations = 0
        self.substeps = 0

    def stage(self, name: str):
        return self if name == "velocity, vorticity, XSPH, x = x*" else self._null  # the last call's too

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.iterations += self.sim.iterations_used
        self.substeps += 1


def our_overrides(spec: str) -> list[str]:
    """``"substeps=4,target=0.001"`` → ``--set`` overrides, the short names expanded."""
    overrides = []
    for item in filter(None, (part.strip() for part in spec.split(","))):
        key, sep, value = item.partition("=")
        if not sep:
            raise SceneError(f"--ours {spec!r}: expected KEY=VALUE, got {item!r}")
        overrides.append(f"{OUR_SHORT_KEYS.get(key.strip(), key.strip())}={value.strip()}")
    return overrides


def our_scene(spec: str):
    """The preset with the spec's overrides, vorticity off and the CFL limit at its most. A spec runs
    fixed iterations unless it sets a target; ``preset`` keeps the preset's solver settings."""
    pinned = [] if spec.strip() == "preset" else ["solver.target_density_error=0"]
    overrides = ["vorticity.epsilon=0", *pinned, *our_overrides("" if spec.strip() == "preset" else spec)]
    ratio = load_scene(PRESET, overrides).solver.kernel_ratio
    if not any(o.startswith("time.max_cfl=") for o in overrides):
        overrides.append(f"time.max_cfl={min(ratio, 4.0)!r}")
    return load_scene(PRESET, overrides)


def run_ours(spec: str, seconds: float, label: str | None = None) -> Row:
    scene = our_scene(spec)
    counter = IterationCount()
    sim = Simulation(scene, quiet=True, hook=counter)
    counter.sim = sim
    # Compiles the kernels; the run below starts again from rest. Two frames: the kernels that take the
    # two position buffers compile once per order, and with 1 substep of 1 iteration (the free fall)
    # the second order first comes in the second frame (0.7 s that were counted in the timed run).
    sim.step(2)
    sim.reset()
    counter.iterations = counter.substeps = 0
    frame_s, means, maxima = [], [], []
    for _ in range(round(seconds / scene.time.frame_dt_s)):
        # The step alone, synchronised, as SPlisHSPlasH's SimStep timer leaves out its exports.
        frame_s.append(timed(sim.step))
        stats = sim.stats()
        means.append(stats["mean_density_error"])
        maxima.append(stats["max_density_error"])
    simulated = len(frame_s) * scene.time.frame_dt_s
    settings = (
        f"substeps={scene.time.substeps},iterations={scene.solver.iterations}"
        + (f",target={scene.solver.target_density_error:g}" if scene.solver.target_density_error else "")
        + (f",divergence={scene.solver.divergence_iterations}" if scene.solver.divergence_iterations else "")
    )
    divergence = scene.solver.divergence_iterations or None  # fixed per substep when on
    return Row(
        label or f"pbf {spec} (h {scene.solver.kernel_ratio:g} s)",
        scene.time.frame_dt_s / scene.time.substeps * 1e3,
        counter.substeps,
        counter.iterations / max(counter.substeps, 1),
        sum(frame_s) / max(counter.substeps, 1) * 1e3,
        sum(frame_s) / simulated,
        statistics.fmean(means),
        max(maxima),
        len(means),
        divergence,
        settings=f"{settings} (h {scene.solver.kernel_ratio:g} s)",
        spec=spec,
    )


def medians(runs: list[Row]) -> Row:
    """One row from repeated runs: median time and mean error, the largest max error."""
    first = runs[0]
    if len(runs) == 1:
        return first
    first.ms_per_step = statistics.median(r.ms_per_step for r in runs)
    first.compute_s_per_s = statistics.median(r.compute_s_per_s for r in runs)
    first.mean_error = statistics.median(r.mean_error for r in runs)
    first.max_error = max(r.max_error for r in runs)
    first.label += f" (median of {len(runs)})"
    return first


# ----------------------------------------------------------------------------- the standing wave

# Run inside SPlisHSPlasH's own environment: the sloshing tank settled, the mode imposed, its amplitude
# written every frame (argv: scene file, output folder, result .npy, settle steps, steps per frame,
# JSON of the mode: k, omega, depth, the water's lower corner, amplitude).
SPLASH_SLOSHING = r"""
import json, math, sys
import numpy as np
import pysplishsplash as sph
scene, out, result = sys.argv[1], sys.argv[2], sys.argv[3]
settle, per_frame, mode = int(sys.argv[4]), int(sys.argv[5]), json.loads(sys.argv[6])
base = sph.Exec.SimulatorBase()
base.init(["splash", "--no-gui", "--no-initial-pause", "--output-dir", out, scene], "sloshing")
base.initSimulation()
fluid = sph.Simulation.getCurrent().getFluidModel(0)
n = fluid.numActiveParticles()
k, omega, depth, lower, amplitude = mode["k"], mode["omega"], mode["depth"], np.array(mode["lower"]), mode["amplitude"]
def field(x, a):
    y = np.clip(x[:, 1] - lower[1], 0.0, None)
    c = a * omega / math.sinh(k * depth)
    u = np.zeros_like(x)
    u[:, 0] = -c * np.cosh(k * y) * np.sin(k * (x[:, 0] - lower[0]))
    u[:, 1] = c * np.sinh(k * y) * np.cos(k * (x[:, 0] - lower[0]))
    return u
state = {"step": 0, "amplitudes": []}
def step():
    s = state["step"]; state["step"] += 1
    if s < settle:
        for i in range(n):
            fluid.setVelocity(i, 0.9 * np.array(fluid.getVelocity(i)))
        return
    x = np.array([fluid.getPosition(i) for i in range(n)])
    if s == settle:
        for i, u in enumerate(field(x, amplitude)):
            fluid.setVelocity(i, u)
    if (s - settle) % per_frame == 0:
        v = np.array([fluid.getVelocity(i) for i in range(n)])
        u = field(x, 1.0)
        state["amplitudes"].append(float((v * u).sum() / (u * u).sum()))
        np.save(result, np.array(state["amplitudes"]))
base.setTimeStepCB(step)
base.runSimulation()
base.cleanup()
"""


def splash_sloshing(splash: Path, method: str, periods: float, threads: int) -> tuple[np.ndarray, np.ndarray]:
    """The standing wave in SPlisHSPlasH (module docstring, --sloshing): (times, the mode's amplitude)."""
    from pbf.study import damping

    scene = load_scene(damping.PRESET)
    spacing, frame_dt = scene.fluid.spacing_m, scene.time.frame_dt_s
    per_frame = scene.time.substeps
    dt = frame_dt / per_frame
    block = scene.fluid.blocks[0]
    lower, upper = np.array(block.min_m), np.array(block.max_m)
    container_upper = np.array(scene.container.max_m) + np.array([spacing, 0.0, spacing])
    length, depth, width = upper - lower
    k, omega = damping.sloshing_mode(length, depth, float(np.linalg.norm(scene.gravity_m_s2)))
    settle = round(1.0 / dt)
    stop = (settle + math.ceil(periods * 2 * math.pi / omega / dt) + 1) * dt
    simulation_method, block_name, defaults = SPLASH_METHODS[method]
    # The water one spacing inside the boundary particles in x and z (its dam break's placement);
    # its first layer stands one spacing above the floor's.
    water_lower = np.array([spacing, spacing, spacing])
    config = {
        "Configuration": {
            "particleRadius": spacing / 2,
            "simulationMethod": simulation_method,
            "gravitation": list(scene.gravity_m_s2),
            "timeStepSize": dt,
            "cflMethod": 0,
            "boundaryHandlingMethod": 0,
            "stopAt": stop,
            "enableVTKExport": False,
            block_name: defaults,
        },
        "Materials": [
            {
                "id": "Fluid",
                "density0": scene.fluid.rest_density_kg_m3,
                "viscosityMethod": 0,
                "vorticityMethod": 0,
                "XSPH": {"xsph": scene.viscosity.xsph, "xsphBoundary": 0.0},
            }
        ],
        "RigidBodies": [
            {
                "geometryFile": str(splash.parent / "data" / "models" / "UnitBox.obj"),
                "translation": list(container_upper / 2),
                "scale": list(container_upper),
                "isDynamic": False,
                "isWall": True,
                "mapInvert": True,
                "mapThickness": 0.0,
                "mapResolution": [40, 30, 20],
            }
        ],
        "FluidBlocks": [{"denseMode": 0, "start": [0.0, 0.0, 0.0], "end": list(water_lower + upper - lower)}],
    }
    mode = {"k": k, "omega": omega, "depth": float(depth), "lower": list(water_lower - spacing / 2), "amplitude": 0.01}
    env = dict(os.environ, LD_PRELOAD=SYSTEM_GLDISPATCH, OMP_NUM_THREADS=str(threads))
    with tempfile.TemporaryDirectory() as tmp:
        path, result = Path(tmp) / "sloshing.json", Path(tmp) / "amplitudes.npy"
        path.write_text(json.dumps(config))
        run = subprocess.run(
            [
                splash_interpreter(splash),
                "-c",
                SPLASH_SLOSHING,
                str(path),
                str(Path(tmp) / "out"),
                str(result),
                str(settle),
                str(per_frame),
                json.dumps(mode),
            ],
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        if run.returncode or not result.exists():
            sys.exit(
                f"SPlisHSPlasH's standing wave failed ({run.returncode}):\n{run.stdout[-2000:]}{run.stderr[-2000:]}"
            )
        amplitudes = np.load(result)
    return np.arange(len(amplitudes)) * frame_dt, amplitudes


def sloshing_comparison(splash: Path, methods: list[str], threads: int, periods: float = 3.0) -> None:
    """The standing wave's decay per period in SPlisHSPlasH's methods and in ours (``--sloshing``)."""
    from pbf.study import damping

    print(
        f"{'run':<34} {'decay per period':>16} {'period':>8}   (linear theory: period "
        f"{2 * math.pi / damping.sloshing_mode(0.45, 0.195, 9.81)[1]:.3f} s)"
    )
    for method in methods:
        times, amplitudes = splash_sloshing(splash, method, periods, threads)
        decay, _, period = damping.decay_per_period(times, amplitudes)
        print(f"{'SPlisHSPlasH ' + SPLASH_METHODS[method][1]:<34} {decay:>16.1%} {period:>7.3f}s")
    ours = damping.sloshing(periods=periods)
    print(f"{'ours (the sloshing preset)':<34} {ours.decay_per_period:>16.1%} {ours.period_s:>7.3f}s")


# ----------------------------------------------------------------------------- output

HEADER = (
    f"{'run':<58} {'Δt ms':>5} {'steps':>5} {'iter/step':>9} {'div/step':>8} {'ms/step':>8} "
    f"{'s/sim s':>7} {'mean err':>8} {'max err':>7}  {'recomputed':>16} {'left box':>8}"
)


def line(r: Row) -> str:
    divergence = f"{r.divergence_iterations:.2f}" if r.divergence_iterations is not None else "-"
    again = f"{r.recomputed_mean:.3%} / {r.recomputed_max:.1%}" if r.recomputed_mean is not None else "-"
    left = str(r.left_box) if r.left_box is not None else "-"
    return (
        f"{r.label:<58.58} {r.dt_ms:>5.2f} {r.steps:>5} {r.iterations:>9.2f} {divergence:>8} {r.ms_per_step:>8.2f} "
        f"{r.compute_s_per_s:>7.2f} {r.mean_error:>8.3%} {r.max_error:>7.2%}  {again:>16} {left:>8}"
    )


CANNOT_BE_EQUAL = """\
What the comparison cannot make equal:
* Kernels and support. SPlisHSPlasH's support radius is 4 particle radii, 2.0 spacings; its DFSPH uses
  the cubic spline (tabulated), and its PBF Poly6 for the density and Spiky for the gradient (it sets
  these whenever simulationMethod is 2, whatever the scene says): its PBF solves and stops on the Poly6
  density, yet the density it exports is the cubic spline's (the lines above). Ours is the cubic spline
  at 2.2 spacings by default (solver.kernel_ratio; ``kernel_ratio=2.0`` in an --ours spec runs it at
  SPlisHSPlasH's support).
* Walls. SPlisHSPlasH: Akinci et al. 2012 boundary particles, one layer on the box's surface (the
  count is printed above); its fluid keeps about one spacing from them, so the water has about half a
  spacing less room at each wall, and at the start the layer next to the wall particles stands above
  rest density (the 'initial density' line), which pushes the block in the first step. Ours: the wall
  density of ghost planes, the first layer half a spacing from the wall at exactly ρ0.
* Rest state. SPlisHSPlasH's particle volume is s³ (its lattice at 2.0 spacings sums to 1.0000 with
  the cubic spline, 1.0098 with Poly6); ours scales the mass so that the lattice is exactly at ρ0.
* XSPH and viscosity. Both XSPH c = 0.01 and no vorticity confinement, but SPlisHSPlasH applies XSPH
  as an acceleration (before its pressure solve in DFSPH, after the position solve in PBF), ours as the
  velocity filter after the solve (Macklin & Müller, Eq. 17). Its shipped DamBreakModel scene uses its
  'Standard' viscosity 0.01 instead; here viscosityMethod is 0 in both methods to match ours.
* Solvers and their stopping rules. DFSPH stops on the mean predicted density deviation (and the
  divergence solver on the mean divergence); its PBF on the mean of max(ρ/ρ0 − 1, 0) of the current
  positions, both in percent, with 2 iterations at least; ours runs a fixed count or stops on the same
  mean as a fraction (target). Its PBF is plain Jacobi (no relaxation); ours is under-relaxed (ω ≈ 0.58).
* What is exported. DFSPH's exported density is the one it computed at the start of its last step
  (one step before the exported positions); PBF's is computed after the position solve with the step's
  neighbour lists; ours is the density of the positions we output. The recomputed column shows what
  this changes.
* Time. SPlisHSPlasH's SimStep timer is C++ around its step; ours is the wall time of step() with
  Python's launches in it. Both use --threads threads."""


def parse_param_sets(values: list[str] | None, methods: list[str]) -> list[dict]:
    """Each ``--param`` is one SPlisHSPlasH variant: comma-separated KEY=VALUE of the methods' blocks."""
    known = set().union(*(SPLASH_METHODS[m][2] for m in SPLASH_METHODS))
    sets = []
    for text in values or ["maxError=0.01", "maxError=0.1"]:
        variant = {}
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, value = item.partition("=")
            key = key.strip()
            if not sep or key not in known:
                raise ValueError(
                    f"--param {text!r}: {item!r}; expected KEY=VALUE with KEY one of {', '.join(sorted(known))}"
                )
            variant[key] = (
                json.loads(value.strip().lower())
                if value.strip().lower() in ("true", "false")
                else (int(value) if re.fullmatch(r"[-+]?\d+", value.strip()) else float(value))
            )
        sets.append(variant)
    return sets


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="\n".join(__doc__.splitlines()[1:6]),
    )
    parser.add_argument("--splash", type=Path, required=True, help="the splash script of a pysplishsplash 2.19 install")
    parser.add_argument(
        "--methods",
        nargs="+",
        choices=sorted(SPLASH_METHODS),
        default=["dfsph", "pbf"],
        help="SPlisHSPlasH's solvers to run (default: dfsph pbf)",
    )
    parser.add_argument(
        "--param",
        action="append",
        metavar="KEY=VALUE[,KEY=VALUE]",
        help="one SPlisHSPlasH variant per --param, set in its method's block over the shipped "
        "defaults (default: --param maxError=0.01 --param maxError=0.1; maxError is in percent)",
    )
    parser.add_argument(
        "--ours",
        nargs="*",
        default=["substeps=4,iterations=4", "substeps=2,iterations=4", "preset"],
        help="our settings, each a comma-separated list of overrides of the preset (fixed "
        "iterations unless a target is given), or 'preset' for the preset's own solver settings",
    )
    parser.add_argument("--dt-ms", type=float, default=4.1667, help="SPlisHSPlasH's fixed step (default 4.1667)")
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time of every run (default 1)")
    parser.add_argument("--threads", type=int, default=2, help="CPU threads for both simulators (default 2)")
    parser.add_argument(
        "--repeats",
        type=int,
        default=1,
        help="runs of each SPlisHSPlasH and --ours row, alternating; medians are reported (default 1)",
    )
    parser.add_argument(
        "--sloshing",
        action="store_true",
        help="instead: the standing wave's decay per period in --methods and ours (pbf.study.damping)",
    )
    args = parser.parse_args(argv)
    sys.stdout.reconfigure(line_buffering=True)  # progress shows as it comes when written to a file
    if not args.splash.exists():
        parser.error(
            f"--splash: {args.splash} does not exist; SPlisHSPlasH is installed apart from this project: "
            f"python3 -m venv /tmp/sphvenv && /tmp/sphvenv/bin/pip install pysplishsplash==2.19.0 'numpy<2', "
            f"then --splash /tmp/sphvenv/bin/splash"
        )
    if args.threads < 1 or args.repeats < 1 or args.seconds <= 0:
        parser.error("--threads and --repeats must be positive integers, --seconds positive")
    try:
        param_sets = parse_param_sets(args.param, args.methods)
        for spec in args.ours:
            our_scene(spec)
    except (ValueError, SceneError) as error:
        parser.error(str(error))
    start_backend("cpu", cpu_threads=args.threads)
    if args.sloshing:
        return sloshing_comparison(args.splash, args.methods, args.threads)
    started = time.perf_counter()
    print(f"SPlisHSPlasH: {args.splash}; {args.threads} threads; {args.seconds:g} simulated s; Δt {args.dt_ms:g} ms")

    jobs = []  # (label, callable) in the order they run, alternating over repeats
    for method in args.methods:
        block_defaults = SPLASH_METHODS[method][2]
        for variant in param_sets:
            params = {**block_defaults, **{k: v for k, v in variant.items() if k in block_defaults}}
            ignored = [k for k in variant if k not in block_defaults]
            if ignored:
                print(f"note: {SPLASH_METHODS[method][1]} has no {', '.join(ignored)}; left out of its runs")
            jobs.append(
                (
                    "theirs",
                    lambda m=method, p=params: run_splishsplash(
                        args.splash, m, p, args.dt_ms / 1e3, args.seconds, args.threads
                    ),
                )
            )
    for spec in args.ours:
        jobs.append(("ours", lambda s=spec: run_ours(s, args.seconds)))
    results = [[] for _ in jobs]
    for _ in range(args.repeats):
        for k, (_, job) in enumerate(jobs):
            began, load = time.perf_counter(), os.getloadavg()[0]
            results[k].append(job())
            print(
                f"  ran {results[k][-1].label} ({time.perf_counter() - began:.0f} s; load average "
                f"{load:.1f} before, {os.getloadavg()[0]:.1f} after)"
            )
    rows = [medians(runs) for runs in results]
    theirs = [r for (kind, _), r in zip(jobs, rows) if kind == "theirs"]

    print()
    print(HEADER)
    for r in rows:
        print(line(r))
    print(
        "(s/sim s: seconds of compute per simulated second; recomputed: SPlisHSPlasH's density recomputed from its "
        "exported positions, mean / max error; left box: its particles that ever left the box)"
    )
    for r in theirs:
        print(f"\n{r.label}:")
        for note in r.notes:
            print(f"  {note}")

    print()
    print(CANNOT_BE_EQUAL)
    print(f"\n(total wall time {time.perf_counter() - started:.0f} s)")
    return rows


if __name__ == "__main__":
    main()
