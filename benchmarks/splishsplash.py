"""Our PBF against SPlisHSPlasH 2.19's DFSPH and PBF on the seed dam break, 1 s: cost and density error.

    python benchmarks/splishsplash.py --splash /tmp/sphvenv/bin/splash                    # the default rows
    python benchmarks/splishsplash.py --splash /tmp/sphvenv/bin/splash --sloshing         # the standing wave's decay
    python benchmarks/splishsplash.py --splash /tmp/sphvenv/bin/splash --methods dfsph \\
        --ours "substeps=4,iterations=4" "substeps=4,target=0.001,max_iterations=30"

SPlisHSPlasH needs NumPy 1, so it is installed apart and run as its own process: ``python3 -m venv
/tmp/sphvenv && /tmp/sphvenv/bin/pip install pysplishsplash==2.19.0 "numpy<2"``. A row a run: its
step, steps, iterations a step, ms a step (SPlisHSPlasH's own "SimStep", ours ``step()`` alone),
compute seconds a simulated second, and the density error's mean and max over the frames (its from
the density it exports). An ``--ours`` spec is overrides of the preset (short names in OUR_SHORT_KEYS;
``preset``: as shipped). ``--sloshing``: the decay a period of ``pbf.study.damping``'s standing wave
in each. The setups' differences: docs/BENCHMARKS.md, "Against SPlisHSPlasH's DFSPH".
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from pbf.scene import SceneError, load_scene
from pbf.solver import Simulation, start_backend
from pbf.study import damping
from pbf.study.common import timed

# Preloaded into SPlisHSPlasH's process: the libGLdispatch its wheel bundles clashes with the system's.
SYSTEM_GLDISPATCH = "/lib/x86_64-linux-gnu/libGLdispatch.so.0"
PRESET = "dam_break"
SECONDS = 1.0  # simulated, every run
DT_S = 1 / 240  # SPlisHSPlasH's fixed step: four a frame, our preset's substeps
MAX_ERRORS = (0.01, 0.1)  # SPlisHSPlasH's variants: its maxError, percent (its default, and ten times looser)
SPLASH_METHODS = {  # name: (simulationMethod, its scene block and log prefix, its shipped stopping rules)
    "dfsph": (4, "DFSPH", dict(minIterations=2, maxIterations=100, maxError=0.01, enableDivergenceSolver=True,
                               maxIterationsV=100, maxErrorV=0.1)),
    "pbf": (2, "PBF", dict(minIterations=2, maxIterations=100, maxError=0.01, velocityUpdateMethod=0)),
}  # fmt: skip
OUR_SHORT_KEYS = {
    "substeps": "time.substeps", "iterations": "solver.iterations", "max_iterations": "solver.iterations",
    "target": "solver.target_density_error", "kernel_ratio": "solver.kernel_ratio", "xsph": "viscosity.xsph",
    "divergence": "solver.divergence_iterations",
}  # fmt: skip

# Run in SPlisHSPlasH's environment: the sloshing tank settled, the mode imposed, its amplitude written
# every frame (argv: scene file, output folder, result .npy, settle steps, steps a frame, the mode's JSON).
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
    divergence_iterations: float | None = None


def splash_config(splash: Path, method: str, params: dict, dt_s: float, stop_s: float, scene, box, block) -> dict:
    """A SPlisHSPlasH scene: ``scene``'s fluid and gravity, walls on the box ``box`` (lower, upper), the
    fluid block ``block`` (start, end: its first particle one spacing inside ``start``)."""
    number, name, _ = SPLASH_METHODS[method]
    (lower, upper), spacing = np.asarray(box), scene.fluid.spacing_m
    return {
        "Configuration": {
            "particleRadius": spacing / 2, "simulationMethod": number, "gravitation": list(scene.gravity_m_s2),
            "timeStepSize": dt_s, "cflMethod": 0, "boundaryHandlingMethod": 0, "stopAt": stop_s,
            "enableVTKExport": True, "dataExportFPS": round(1 / scene.time.frame_dt_s),
            "particleAttributes": "density", name: params,
        },
        "Materials": [{"id": "Fluid", "density0": scene.fluid.rest_density_kg_m3, "viscosityMethod": 0,
                       "vorticityMethod": 0, "XSPH": {"xsph": scene.viscosity.xsph, "xsphBoundary": 0.0}}],
        "RigidBodies": [{"geometryFile": str(splash.parent / "data" / "models" / "UnitBox.obj"),
                         "translation": list((lower + upper) / 2), "scale": list(upper - lower), "isDynamic": False,
                         "isWall": True, "mapInvert": True, "mapThickness": 0.0,
                         "mapResolution": [20, 20, 20]}],
        "FluidBlocks": [{"denseMode": 0, "start": list(block[0]), "end": list(block[1])}],
    }  # fmt: skip


def run_splash_python(splash: Path, code: str, args: list, threads: int) -> subprocess.CompletedProcess:
    """``code`` in SPlisHSPlasH's own Python (the splash script's interpreter), or the script itself."""
    first = splash.read_text(errors="replace").splitlines()[0]
    command = [first[2:].strip() if first.startswith("#!") else str(splash.parent / "python"), "-c", code]
    env = dict(os.environ, LD_PRELOAD=SYSTEM_GLDISPATCH, OMP_NUM_THREADS=str(threads))
    done = subprocess.run((command if code else [str(splash)]) + list(map(str, args)), env=env, capture_output=True,
                          text=True)  # fmt: skip
    if done.returncode:
        sys.exit(f"SPlisHSPlasH failed ({done.returncode}):\n{done.stdout[-2000:]}{done.stderr[-2000:]}")
    return done


def read_density(path: Path) -> np.ndarray:
    """The ``density`` field (n,) of a legacy binary VTK file from SPlisHSPlasH."""
    data = path.read_bytes()
    points, density = re.search(rb"POINTS (\d+) float\n", data), re.search(rb"\ndensity 1 (\d+) float\n", data)
    if not (points and density):
        raise ValueError(f"{path}: expected float POINTS and a density field")
    return np.frombuffer(data, ">f4", int(points.group(1)), density.end()).astype(np.float64)


def run_splishsplash(splash: Path, method: str, params: dict, threads: int) -> Row:
    scene, name = load_scene(PRESET), SPLASH_METHODS[method][1]
    box = np.array(scene.container.min_m), np.array(scene.container.max_m)
    block = scene.fluid.blocks[0].min_m, np.array(scene.fluid.blocks[0].max_m) + scene.fluid.spacing_m
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        config = splash_config(splash, method, params, DT_S, SECONDS, scene, box, block)
        (tmp / "scene.json").write_text(json.dumps(config, indent=1))
        log = run_splash_python(splash, "", ["--no-gui", "--no-initial-pause", "--output-dir", tmp / "out",
                                             tmp / "scene.json"], threads).stdout  # fmt: skip

        def number(pattern):
            found = re.search(pattern + r": ([-+\d.eE]+)", log)
            return float(found.group(1)) if found else None

        step_ms, sum_ms = number(r"Average time: SimStep"), number(r"Time sum: SimStep")
        mean_dt, total_time = number(r"Average number: Time step size"), number(r"Total number: Time step size")
        iterations = number(rf"Average number: {name} - iterations")
        frames = sorted(
            (tmp / "out" / "vtk").glob("ParticleData_Fluid_*.vtk"), key=lambda p: int(p.stem.split("_")[-1])
        )
        if len(frames) < 2 or None in (step_ms, sum_ms, mean_dt, total_time, iterations):
            sys.exit(f"{splash}: {len(frames)} frames, or its log lacks SimStep, step or iterations:\n{log[-2000:]}")
        # Its first export follows its first step: no error counted. Its AVX build (the wheel) exports the
        # cubic spline's density whatever the kernel, so its PBF, which converges on Poly6's, reads high.
        rho0 = scene.fluid.rest_density_kg_m3
        errors = [np.maximum(read_density(path) / rho0 - 1.0, 0.0) for path in frames[1:]]
    return Row(
        f"SPlisHSPlasH {name} maxError={params['maxError']}", DT_S * 1e3, round(total_time / mean_dt), iterations,
        step_ms, sum_ms / 1e3 / total_time, float(np.mean([e.mean() for e in errors])),
        float(max(e.max() for e in errors)), number(rf"Average number: {name} - iterationsV"),
    )  # fmt: skip


class IterationCount:
    """A stage hook that adds up the solver iterations of every substep (one Python call per stage)."""

    def __init__(self):
        self.sim, self.iterations, self.substeps = None, 0, 0

    @contextlib.contextmanager
    def stage(self, name: str):
        yield
        if name == "velocity, vorticity, XSPH, x = x*":  # the substep's last stage: its iterations are known
            self.iterations += self.sim.iterations_used
            self.substeps += 1


def our_scene(spec: str):
    """The preset with the spec's overrides, vorticity off and the CFL limit at its most. A spec runs
    fixed iterations unless it sets a target; ``preset`` keeps the preset's solver settings."""
    preset = spec.strip() == "preset"
    overrides = ["vorticity.epsilon=0"] + ([] if preset else ["solver.target_density_error=0"])
    for item in filter(None, (part.strip() for part in ("" if preset else spec).split(","))):
        key, sep, value = item.partition("=")
        if not sep:
            raise SceneError(f"--ours {spec!r}: expected KEY=VALUE, got {item!r}")
        overrides.append(f"{OUR_SHORT_KEYS.get(key.strip(), key.strip())}={value.strip()}")
    if not any(o.startswith("time.max_cfl=") for o in overrides):
        overrides.append(f"time.max_cfl={min(load_scene(PRESET, overrides).solver.kernel_ratio, 4.0)!r}")
    return load_scene(PRESET, overrides)


def run_ours(spec: str) -> Row:
    scene, counter = our_scene(spec), IterationCount()
    sim = counter.sim = Simulation(scene, quiet=True, hook=counter)
    sim.step(2)  # compiles every kernel (both position buffers' orders); the run starts again from rest
    sim.reset()
    counter.iterations = counter.substeps = 0
    frame_s, means, maxima = [], [], []
    for _ in range(round(SECONDS / scene.time.frame_dt_s)):
        frame_s.append(timed(sim.step))  # the step alone, as SPlisHSPlasH's SimStep leaves out its exports
        stats = sim.stats()
        means.append(stats["mean_density_error"])
        maxima.append(stats["max_density_error"])
    steps = max(counter.substeps, 1)
    return Row(
        f"pbf {spec} (h {scene.solver.kernel_ratio:g} s)", scene.time.frame_dt_s / scene.time.substeps * 1e3,
        counter.substeps, counter.iterations / steps, sum(frame_s) / steps * 1e3,
        sum(frame_s) / (len(frame_s) * scene.time.frame_dt_s), statistics.fmean(means), max(maxima),
        scene.solver.divergence_iterations or None,
    )  # fmt: skip


def medians(runs: list[Row]) -> Row:
    """One row from repeated runs: median time and mean error, the largest max error."""
    first = runs[0]
    if len(runs) > 1:
        first.ms_per_step = statistics.median(r.ms_per_step for r in runs)
        first.compute_s_per_s = statistics.median(r.compute_s_per_s for r in runs)
        first.mean_error = statistics.median(r.mean_error for r in runs)
        first.max_error = max(r.max_error for r in runs)
        first.label += f" (median of {len(runs)})"
    return first


def splash_sloshing(splash: Path, method: str, periods: float, threads: int) -> tuple[np.ndarray, np.ndarray]:
    """The standing wave in SPlisHSPlasH: (times, the mode's amplitude). Its container is one spacing
    wider in x and z, so that its wall particles stand one spacing from the water as in its dam break."""
    scene = load_scene(damping.PRESET)
    spacing, frame_dt, per_frame = scene.fluid.spacing_m, scene.time.frame_dt_s, scene.time.substeps
    dt, block = frame_dt / per_frame, scene.fluid.blocks[0]
    size = np.array(block.max_m) - np.array(block.min_m)
    k, omega = damping.sloshing_mode(size[0], size[1], float(np.linalg.norm(scene.gravity_m_s2)))
    settle = round(1.0 / dt)
    stop = (settle + math.ceil(periods * 2 * math.pi / omega / dt) + 1) * dt
    water_lower = np.full(3, spacing)
    box = (np.zeros(3), np.array(scene.container.max_m) + [spacing, 0.0, spacing])
    block = (np.zeros(3), water_lower + size)
    config = splash_config(splash, method, SPLASH_METHODS[method][2], dt, stop, scene, box, block)
    config["Configuration"]["enableVTKExport"] = False
    config["RigidBodies"][0]["mapResolution"] = [40, 30, 20]
    mode = dict(k=k, omega=omega, depth=float(size[1]), lower=list(water_lower - spacing / 2), amplitude=0.01)
    with tempfile.TemporaryDirectory() as tmp:
        path, result = Path(tmp) / "sloshing.json", Path(tmp) / "amplitudes.npy"
        path.write_text(json.dumps(config))
        run_splash_python(splash, SPLASH_SLOSHING, [path, Path(tmp) / "out", result, settle, per_frame,
                                                    json.dumps(mode)], threads)  # fmt: skip
        amplitudes = np.load(result)
    return np.arange(len(amplitudes)) * frame_dt, amplitudes


def sloshing_comparison(splash: Path, methods: list[str], threads: int, periods: float = 3.0) -> None:
    """The standing wave's decay per period in SPlisHSPlasH's methods and in ours (``--sloshing``)."""
    theory = 2 * math.pi / damping.sloshing_mode(0.45, 0.195, 9.81)[1]
    print(f"{'run':<34} {'decay per period':>16} {'period':>8}   (linear theory: period {theory:.3f} s)")
    for method in methods:
        decay, _, period = damping.decay_per_period(*splash_sloshing(splash, method, periods, threads))
        print(f"{'SPlisHSPlasH ' + SPLASH_METHODS[method][1]:<34} {decay:>16.1%} {period:>7.3f}s")
    ours = damping.sloshing(periods=periods)
    print(f"{'ours (the sloshing preset)':<34} {ours.decay_per_period:>16.1%} {ours.period_s:>7.3f}s")


def line(r: Row) -> str:
    divergence = "-" if r.divergence_iterations is None else f"{r.divergence_iterations:.2f}"
    return (
        f"{r.label:<58.58} {r.dt_ms:>5.2f} {r.steps:>5} {r.iterations:>9.2f} {divergence:>8} {r.ms_per_step:>8.2f} "
        f"{r.compute_s_per_s:>7.2f} {r.mean_error:>8.3%} {r.max_error:>7.2%}"
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--splash", type=Path, required=True, help="the splash script of a pysplishsplash 2.19 install")
    parser.add_argument("--methods", nargs="+", choices=sorted(SPLASH_METHODS), default=["dfsph", "pbf"])
    ours = ["substeps=4,iterations=4", "substeps=2,iterations=4", "preset"]
    parser.add_argument("--ours", nargs="*", default=ours, help="our settings: comma-separated overrides, or 'preset'")
    parser.add_argument("--threads", type=int, default=2, help="CPU threads for both simulators (default 2)")
    parser.add_argument("--repeats", type=int, default=1, help="runs of each row, alternating; medians")
    parser.add_argument("--sloshing", action="store_true", help="instead: the standing wave's decay a period")
    args = parser.parse_args(argv)
    sys.stdout.reconfigure(line_buffering=True)
    if not args.splash.exists():
        parser.error(f"--splash: {args.splash} does not exist; install SPlisHSPlasH apart (see --help's module doc)")
    if args.threads < 1 or args.repeats < 1:
        parser.error("--threads and --repeats: at least 1")
    try:
        for spec in args.ours:
            our_scene(spec)
    except SceneError as error:
        parser.error(str(error))
    start_backend("cpu", cpu_threads=args.threads)
    if args.sloshing:
        return sloshing_comparison(args.splash, args.methods, args.threads)
    started = time.perf_counter()
    print(f"SPlisHSPlasH: {args.splash}; {args.threads} threads; {SECONDS:g} simulated s; Δt {DT_S * 1e3:.4g} ms")
    variants = [(method, {**SPLASH_METHODS[method][2], "maxError": e}) for method in args.methods for e in MAX_ERRORS]
    jobs = [partial(run_splishsplash, args.splash, method, params, args.threads) for method, params in variants]
    jobs += [partial(run_ours, spec) for spec in args.ours]  # in this order, alternating over repeats
    results = [[] for _ in jobs]
    for _ in range(args.repeats):
        for runs, job in zip(results, jobs):
            began, load = time.perf_counter(), os.getloadavg()[0]
            runs.append(job())
            print(f"  ran {runs[-1].label} ({time.perf_counter() - began:.0f} s; load {load:.1f} before)")
    rows = [medians(runs) for runs in results]
    print(
        f"\n{'run':<58} {'Δt ms':>5} {'steps':>5} {'iter/step':>9} {'div/step':>8} {'ms/step':>8} "
        f"{'s/sim s':>7} {'mean err':>8} {'max err':>7}"
    )
    print("\n".join(map(line, rows)))
    print("(s/sim s: compute a simulated second)")
    print(
        "\nNot equal in the comparison (docs/BENCHMARKS.md): kernels and support, walls (Akinci particles against "
        f"our ghost), rest state, XSPH, stopping rules, timers.\n(wall time {time.perf_counter() - started:.0f} s)"
    )
    return rows


if __name__ == "__main__":
    main()
