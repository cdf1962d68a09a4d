"""Settled starts kept on disk (``pbf.solver.settled``): a second start of a settling scene restores
the first's settled state instead of settling again, bit for bit, and the file is named by what
determines it."""

import numpy as np
import pytest

from pbf.scene import load_scene
from pbf.solver import settled
from pbf.solver.backend import choices
from pbf.solver.simulation import Simulation
from tests.scenes import small_dam_break

SETTLING = ["time.settle_s=0.1"]


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """The settled starts' folder, in a test's own temporary folder."""
    monkeypatch.setattr(settled, "cache_folder", lambda name: tmp_path)
    return tmp_path


def test_a_second_start_restores_the_first_settled_state_bit_for_bit(folder, monkeypatch):
    first = Simulation(small_dam_break(), overrides=SETTLING)
    assert len(list(folder.glob("*.npz"))) == 1
    start = first.snapshot()
    first.step(3)

    def refused(self, seconds):
        raise AssertionError("settled again")

    monkeypatch.setattr(Simulation, "_settle", refused)
    second = Simulation(small_dam_break(), overrides=SETTLING)
    again = second.snapshot()
    assert np.array_equal(again.positions_m, start.positions_m)
    assert np.array_equal(again.velocities_m_s, start.velocities_m_s)
    assert again.fields.keys() == start.fields.keys()
    assert all(np.array_equal(again.fields[name], start.fields[name]) for name in start.fields)
    second.step(3)
    assert np.array_equal(second.positions(), first.positions())
    assert np.array_equal(second.velocities(), first.velocities())


def test_the_key_follows_the_physics_not_the_view():
    scene = load_scene(small_dam_break(), SETTLING)
    cpu = choices(decisions_on_device=False)
    same = settled.settled_key(scene, cpu)
    assert settled.settled_key(load_scene(small_dam_break(), [*SETTLING, "camera.position_m=[1, 1, 2]"]), cpu) == same
    assert settled.settled_key(load_scene(small_dam_break(), [*SETTLING, "solver.iterations=5"]), cpu) != same
    assert settled.settled_key(load_scene(small_dam_break(), ["time.settle_s=0.2"]), cpu) != same
    # The GPU backends' substep, run on the CPU: another path.
    assert settled.settled_key(scene, choices(decisions_on_device=True)) != same


def test_a_file_cut_short_is_settled_again(folder):
    scene = load_scene(small_dam_break(), SETTLING)
    (folder / f"{settled.settled_key(scene, choices())}.npz").write_bytes(b"PK\x03\x04 cut short")
    assert settled.load(scene, choices()) is None
    sim = Simulation(scene)  # settles, and replaces the file
    assert np.array_equal(settled.load(scene, choices()).positions_m, sim.positions())


def test_nothing_is_kept_without_the_offline_cache(monkeypatch):
    monkeypatch.setattr(settled, "cache_folder", lambda name: None)
    scene = load_scene(small_dam_break(), SETTLING)
    settled.store(scene, Simulation(scene).snapshot(), choices())
    assert settled.load(scene, choices()) is None
