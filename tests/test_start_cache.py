"""One compile serves every scene: a scene of another size and other constants, started in a fresh
process after another, finds every kernel it runs in Taichi's offline cache (``pbf.solver.constants``,
``pbf.solver.model.allocation``)."""

import json
import os
import re
import subprocess
import sys
import time

from tests.scenes import small_dam_break

CHILD = r"""
import json, sys, time
began = time.perf_counter()
import taichi as ti
from pbf.solver.backend import start_backend
start_backend("cpu", quiet=True)
ti.set_logging_level(ti.DEBUG)  # names each kernel compiled ("Cache kernel") or loaded ("from cache")
from pbf.solver.simulation import Simulation
sim = Simulation(json.loads(sys.argv[1]), quiet=True)
sim.step(3)
sim.stats()
sim.snapshot()
print(json.dumps({"particles": sim.particle_count, "seconds": time.perf_counter() - began}))
"""


def other_scene() -> dict:
    """The small dam break with every size and constant changed: another spacing (so particle count,
    h and the particle volume), container (so grid), rest density, gravity and s_corr strength."""
    scene = small_dam_break()
    scene["container"]["max_m"] = [0.9, 0.7, 0.45]
    scene["fluid"]["spacing_m"] = 0.04
    scene["fluid"]["rest_density_kg_m3"] = 998.0
    scene["fluid"]["blocks"][0]["max_m"] = [0.44, 0.36, 0.44]
    scene["solver"]["scorr_k"] = 0.05
    scene["gravity_m_s2"] = [0.0, -9.7, 0.0]
    return scene


def start(scene: dict, folder) -> tuple[dict, set, set]:
    """Run ``scene`` for three frames in a fresh process whose offline cache is ``folder``: its report,
    the kernels it compiled and those it loaded from the cache, by name (Taichi's debug log)."""
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(folder), TI_OFFLINE_CACHE="1")
    done = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(scene)], capture_output=True, text=True, env=env, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    log = done.stdout + done.stderr
    report = json.loads([line for line in done.stdout.splitlines() if line.startswith("{")][-1])
    compiled = set(re.findall(r"Cache kernel '([^']+)'", log))
    loaded = set(re.findall(r"Create kernel '([^']+)' from cache", log))
    return report, compiled, loaded


def test_a_scene_of_another_size_and_other_constants_compiles_nothing(tmp_path):
    first, compiled, _ = start(small_dam_break(), tmp_path)
    assert len(compiled) > 10  # the first start compiled the solver's kernels into the empty folder
    began = time.perf_counter()
    second, again, loaded = start(other_scene(), tmp_path)
    wall = time.perf_counter() - began
    assert second["particles"] != first["particles"]
    assert len(loaded) > 10
    # A kernel the first start never ran (the step back, say, which only some substeps take) may be
    # new; none that it ran may be compiled again.
    assert again & compiled == set(), f"the second scene compiled {sorted(again & compiled)} again ({wall:.1f} s)"
