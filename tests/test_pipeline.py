"""The window's simulation in a process of its own (pbf.app.pipeline): the same frames, bit for bit,
as in one process; the user's changes one frame later; reset; its failures and its end."""
import numpy as np
import pytest
from scenes import small_dam_break

from pbf import Simulation, load_scene
from pbf.app import cli
from pbf.app.pipeline import SimulationProcess, SimulationProcessError


def same_particles(a, b) -> bool:
    ra, rb = a.readout(), b.readout()
    return (ra.count == rb.count and np.array_equal(ra.positions.to_numpy(), rb.positions.to_numpy())
            and np.array_equal(ra.velocities.to_numpy(), rb.velocities.to_numpy()))


def test_the_simulation_in_its_own_process_gives_the_same_frames():
    scene = load_scene(small_dam_break())
    reference = Simulation(scene)
    sim = cli.make_simulation(scene, "cpu", window=object())  # what the command line makes for a window
    assert isinstance(sim, SimulationProcess)
    with sim:
        assert sim.frame == 0 and sim.particle_count == reference.particle_count and same_particles(sim, reference)
        assert sim.control == reference.control and sim.dt_s == reference.dt_s
        for _ in range(3):
            sim.step()
            reference.step()
            assert sim.frame == reference.frame and sim.time_s == reference.time_s and same_particles(sim, reference)
        # A change reaches the solver with the next frame it starts: the one under way keeps the old.
        sim.control.iterations = 1
        sim.step()
        reference.step()
        assert same_particles(sim, reference)
        reference.control.iterations = 1
        sim.step()
        reference.step()
        assert same_particles(sim, reference) and sim.step_ms > 0.0
        assert sim.stats()["frame"] <= sim.frame  # computed in the other process, for a recent frame
        sim.reset()
        reference.reset()
        assert sim.frame == 0 and sim.control == reference.control and same_particles(sim, reference)
        assert sim.stats() == reference.stats()
        process = sim.process
    assert not process.is_alive()


def test_a_failure_in_the_other_process_is_raised_here():
    with SimulationProcess(load_scene(small_dam_break()), arch="cpu") as sim:
        sim.control = None  # the solver cannot step with this
        with pytest.raises(SimulationProcessError, match="Traceback"):
            sim.step()
        process = sim.process
    assert not process.is_alive()
