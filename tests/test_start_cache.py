"""One compile serves every scene: a scene of another size and other constants, started in a fresh
process after another, finds every kernel it runs in Taichi's offline cache (``pbf.solver.constants``,
``pbf.solver.model.allocation``)."""

import json
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest

from pbf.solver import Simulation, buckets
from pbf.solver.backend import choices
from pbf.solver.model import BYTES_PER_CELL, BYTES_PER_PARTICLE, reused_allocation
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
print(json.dumps({"particles": sim.particle_count, "allocated": sim.model.allocated,
                  "seconds": time.perf_counter() - began}))
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


@pytest.mark.slow
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


def larger_scene() -> dict:
    """The small dam break's container filled with 20,000 particles: the bucket of 32,768, one size up
    from the small dam break's 16,384, and the same bucket of cells."""
    scene = small_dam_break()
    scene["fluid"]["spacing_m"] = 0.02
    scene["fluid"]["blocks"][0]["max_m"] = [0.8, 0.5, 0.4]
    return scene


@pytest.mark.slow  # two more processes that compile the solver: the default run's memory peak
def test_a_smaller_scene_takes_the_larger_bucket_a_start_before_compiled(tmp_path):
    first, compiled, _ = start(larger_scene(), tmp_path)
    assert first["allocated"] == 32768
    assert buckets.FILE in {path.name for path in tmp_path.iterdir()}
    second, again, loaded = start(small_dam_break(), tmp_path)
    assert (second["particles"], second["allocated"]) == (1728, 32768)
    assert len(loaded) > 10
    assert again & compiled == set(), f"the smaller scene compiled {sorted(again & compiled)} again"


@pytest.mark.parametrize(
    "on_device", [pytest.param(False, id="cpu path"), pytest.param(True, id="device path", marks=pytest.mark.slow)]
)
def test_a_scene_steps_bit_for_bit_the_same_in_a_larger_bucket(monkeypatch, on_device):
    monkeypatch.setattr(buckets, "record", lambda particles, cells: None)  # the user's cache folder untouched
    path = choices(decisions_on_device=on_device)
    monkeypatch.setattr(buckets, "compiled", lambda: frozenset())
    own = Simulation(small_dam_break(), quiet=True, choices=path)
    monkeypatch.setattr(buckets, "compiled", lambda: frozenset({(32768, 131072)}))
    larger = Simulation(small_dam_break(), quiet=True, choices=path)
    assert (own.model.allocated, own.model.grid.allocated_cells) == (16384, 65536)
    assert (larger.model.allocated, larger.model.grid.allocated_cells) == (32768, 131072)
    start = own.positions()
    own.step(12)
    larger.step(12)
    assert np.abs(own.positions() - start).max() > 0.05  # it moved: the splash began
    np.testing.assert_array_equal(own.positions(), larger.positions())
    np.testing.assert_array_equal(own.velocities(), larger.velocities())


def test_the_bucket_taken_is_the_smallest_compiled_pair_at_most_one_size_up():
    own = (16384, 65536)
    limit = 64 << 20
    assert reused_allocation(own, frozenset(), limit) == own
    assert reused_allocation(own, {own, (32768, 65536)}, limit) == own  # its own, compiled: no more memory
    assert reused_allocation(own, {(32768, 65536), (32768, 131072)}, limit) == (32768, 65536)
    assert reused_allocation(own, {(16384, 131072), (32768, 65536)}, limit) == (16384, 131072)  # 0.8 MB < 10 MB
    assert reused_allocation(own, {(65536, 65536), (8192, 65536)}, limit) == own  # two sizes up; too small
    assert reused_allocation(own, {(32768, 32768)}, limit) == own  # too few cells
    # More memory than the limit allows: its own bucket.
    extra = 16384 * BYTES_PER_PARTICLE + 0 * BYTES_PER_CELL
    assert reused_allocation(own, {(32768, 65536)}, extra - 1) == own
    assert reused_allocation(own, {(32768, 65536)}, extra) == (32768, 65536)


def test_the_record_holds_each_pair_once_and_skips_what_it_cannot_read(monkeypatch, tmp_path):
    path = tmp_path / "cache" / buckets.FILE
    monkeypatch.setattr(buckets, "cache_folder", lambda name: path)
    assert buckets.compiled() == frozenset()  # no record yet
    buckets.record(16384, 65536)
    buckets.record(16384, 65536)
    buckets.record(32768, 65536)
    assert path.read_text().splitlines() == ["16384 65536", "32768 65536"]
    with path.open("a") as file:
        file.write("garbage\n-1 5\n0 65536\n1 2 3\n\u00e9 4\n")
    assert buckets.compiled() == {(16384, 65536), (32768, 65536)}
    monkeypatch.setattr(buckets, "cache_folder", lambda name: None)  # the offline cache off: nothing read or written
    assert buckets.compiled() == frozenset()
    buckets.record(65536, 65536)
