"""Same scene, same backend, same thread count: the same bits, run after run and after a restore."""

import numpy as np
import pytest

from pbf import Simulation
from pbf.solver import Snapshot
from scenes import small_dam_break


def test_runs_and_restored_snapshots_replay_bit_for_bit():
    # The dam break through its impact (frames 10-25), where particles pile up and cells hold the
    # most: before the cells were put in key order, two runs of the seed scene ended 0.46 m apart.
    # A target error makes the solver's stopping decision part of what must replay, and the divergence
    # pass's warm start the pressure Λ carried from substep to substep (which snapshots hold).
    sim = Simulation(small_dam_break(), overrides=["solver.divergence_iterations=1"])
    sim.control.target_density_error = 0.002
    sim.step(12)
    snapshot = sim.snapshot()
    sim.step(14)
    first, first_stats = sim.positions(), sim.stats()
    sim.restore(snapshot)
    sim.step(14)
    assert np.array_equal(sim.positions(), first)
    assert sim.stats() == first_stats
    sim.reset()
    at_rest = sim.stats()  # the maxima are this state's: none left over from the stats before (atomics)
    assert at_rest["max_speed_m_s"] == pytest.approx(np.linalg.norm(sim.velocities(), axis=1).max(), rel=1e-6)
    assert at_rest["max_speed_m_s"] < 0.1 * first_stats["max_speed_m_s"]
    sim.control.target_density_error = 0.002
    sim.step(26)
    assert np.array_equal(sim.positions(), first)
    assert sim.stats() == first_stats
    assert 1 <= first_stats["iterations"] <= 4  # the target was in play, not always all iterations


def test_a_snapshot_that_does_not_fit_is_refused_clearly():
    sim = Simulation(small_dam_break())
    snapshot = sim.snapshot()
    too_many = np.concatenate([snapshot.positions_m, snapshot.positions_m])
    with pytest.raises(ValueError, match="more than the 1,728 this scene allocates"):
        sim.restore(Snapshot(too_many, too_many, 0.0, 0))
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        sim.restore(Snapshot(snapshot.positions_m[:, :2], snapshot.velocities_m_s, 0.0, 0))


def test_reset_returns_to_the_settled_start_without_settling_again():
    # reset() settles once (time.settle_s) and restores that state afterwards: the same bits as a
    # fresh Simulation, and the next frames replay.
    overrides = ["time.settle_s=0.1"]
    sim = Simulation(small_dam_break(), overrides=overrides)
    start = sim.positions()
    sim.step(5)
    after_five = sim.positions()
    substeps = []
    sim.substep = lambda dt=None, _run=sim.substep: (substeps.append(dt), _run(dt))[1]
    sim.reset()
    assert substeps == []  # restored, not settled again
    assert np.array_equal(sim.positions(), start)
    assert np.array_equal(Simulation(small_dam_break(), overrides=overrides).positions(), start)
    sim.step(5)
    assert np.array_equal(sim.positions(), after_five)


@pytest.mark.parametrize("iterations", [3, 4])
def test_predicted_positions_end_every_substep_in_the_first_buffer(iterations):
    # Every kernel but the iterations reads x* from the first buffer (and so compiles once, not again
    # at the first substep with an iteration count of the other parity); the positions are x* there.
    sim = Simulation(small_dam_break(iterations=iterations))
    sim.step(3)
    x_star = sim.integrator.predicted
    n = sim.particle_count
    assert np.array_equal(x_star.first.to_numpy()[:n], sim.state.x.to_numpy()[:n])


@pytest.mark.slow
def test_the_start_warm_up_leaves_the_run_as_it_would_have_been():
    # What a user's start runs before the first picture (a substep, then back to the start): the
    # frames after it are those of a run that never had it, settled start and divergence pass included.
    from pbf.app import loop

    scene = small_dam_break()
    overrides = ["solver.divergence_iterations=1", "time.settle_s=0.05"]
    warmed = Simulation(scene, overrides=overrides)
    assert loop.warm_up(warmed) > 0.0
    warmed.step(6)
    plain = Simulation(scene, overrides=overrides)
    plain.step(6)
    assert np.array_equal(warmed.positions(), plain.positions())
    assert np.array_equal(warmed.velocities(), plain.velocities())
    assert warmed.time_s == plain.time_s and warmed.stats() == plain.stats()
