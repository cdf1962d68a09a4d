"""One substep on every backend; what differs is chosen when the Simulation is built: on a GPU backend
(here the CPU told to act as one, ``pbf.solver.backend.choices(decisions_on_device=True)``) four iterations a call,
loops over the particles' bucket and no decision read by the host; on the CPU an iteration a call and
the error target's decision read after each. The same kernels take the same decisions on the device:
the two give the same bits."""

import hashlib

import numpy as np
import pytest

from benchmarks.instruments import TransferCounter
from pbf import Simulation
from pbf.solver.backend import Choices, choices
from pbf.solver.grid import SLOTS
from scenes import small_dam_break


def frames(sim, count):
    """Iterations of the last substep of each of ``count`` frames, and the reads and launches per substep."""
    used, substeps, reads, launches = [], 0, 0, 0
    for _ in range(count):
        with TransferCounter() as counter:
            sim.step()
        substeps, reads, launches = substeps + sim.frame_substeps, reads + counter.reads, launches + counter.launches
        used.append(sim.iterations_used)  # a read when a target is set, outside the count
    return used, reads / substeps, launches / substeps


@pytest.mark.parametrize("step_back", [True, pytest.param(False, marks=pytest.mark.slow)])
def test_the_gpus_choices_give_the_cpus_bits(step_back):
    scene = small_dam_break(iterations=10)
    scene["solver"].update(target_density_error=0.002, expert={"step_back": step_back})
    cpu = Simulation(scene)
    gpu = Simulation(scene, choices=choices(decisions_on_device=True))
    assert (cpu.iterations.per_call, gpu.iterations.per_call) == (1, 4)
    assert cpu.iterations.reads_decisions and not gpu.iterations.reads_decisions
    cpu_used, cpu_reads, cpu_launches = frames(cpu, 8)
    gpu_used, gpu_reads, gpu_launches = frames(gpu, 8)
    assert gpu_used == cpu_used and 2 < max(cpu_used) < 10  # the target stopped some substep early
    assert np.array_equal(gpu.positions(), cpu.positions())
    assert np.array_equal(gpu.velocities(), cpu.velocities())
    assert gpu_reads <= 1.0 < cpu_reads  # the CPU reads the target's decision after each call
    # lines 1-7, the iterations four a call, lines 20-23, the frame's read of the fastest speed
    assert gpu_launches <= 1 + 3 + 1 + 1
    # No call past the target on the CPU (a read of the decision counts as a launch too): lines 1-7, the
    # iterations used, lines 20-23 and the frame's read, at most.
    assert cpu_launches - cpu_reads <= 2 + np.mean(cpu_used) + 1, (cpu_launches, cpu_reads, cpu_used)


@pytest.mark.slow  # several Simulations compiled twice: the default run's time
def test_a_fixed_iteration_count_reads_nothing_in_the_substep():
    scene = small_dam_break(iterations=3)
    scene["solver"].update(target_density_error=0.0, min_iterations=1)
    for on_device in (False, True):
        sim = Simulation(scene, choices=choices(decisions_on_device=on_device))
        used, reads, _ = frames(sim, 3)
        assert used == [3, 3, 3]
        assert reads == pytest.approx(1.0 / sim.frame_substeps)  # the frame's one read: the CFL limit's speed


@pytest.mark.slow
def test_a_pouring_nozzle_adds_no_read_to_the_substep():
    # A stream into an empty box: every substep appends a layer or more (the drowned check, the slots
    # and the live count on the device), yet the substep still reads the device once at most.
    scene = small_dam_break(iterations=3)
    scene["solver"].update(target_density_error=0.0, min_iterations=1)
    scene["fluid"]["blocks"] = []
    scene["emitters"] = [
        {"position_m": [0.4, 0.6, 0.2], "direction": [0, -1, 0], "radius_m": 0.07, "speed_m_s": 2.0, "end_s": 1.0}
    ]
    sim = Simulation(scene, choices=choices(decisions_on_device=True))
    counts = []
    for _ in range(3):
        with TransferCounter() as counter:
            sim.step()
        counts.append(counter.reads / sim.frame_substeps)
        assert sim.particle_count == sim.emitters.emitted[0] * len(sim.emitters.sites[0])  # none drowned yet
    assert max(counts) <= 1.0 and sim.particle_count > 0


@pytest.mark.slow  # several Simulations compiled twice: the default run's time
def test_the_gpus_list_layout_holds_the_cpus_lists():
    # The GPU's neighbour lists (slot-major, built with a branch) hold the same neighbours in the same
    # order as the CPU's rows, so every sum over them adds the same terms in the same order; the
    # compiler, under fast math, may still group the additions of the two loops differently.
    scene = small_dam_break(iterations=3)
    rows = Simulation(scene)
    slot_major = Simulation(scene, choices=Choices(slot_major=True))
    assert slot_major.grid.slot_major and not rows.grid.slot_major
    for a, b in zip(rows.grid.neighbour_lists(), slot_major.grid.neighbour_lists(), strict=True):
        assert np.array_equal(a, b)
    for _ in range(4):
        rows.step()
        slot_major.step()
    assert np.abs(rows.positions() - slot_major.positions()).max() < 1e-5  # m: rounding, 1e-4 spacings
    assert slot_major.stats()["mean_neighbours"] == pytest.approx(rows.stats()["mean_neighbours"], rel=1e-3)


@pytest.mark.slow  # several Simulations compiled twice: the default run's time
@pytest.mark.parametrize("divergence", [0, 1])
def test_lists_past_their_slots_stay_exact(divergence):
    # At h = 3.6 spacings a particle inside the block has about 190 neighbours, far more than the SLOTS
    # of the one-visit list: every substep takes the compact list's way (its second visit and the
    # starts each thread works out on the device), which must hold every pair within h.
    scene = small_dam_break(iterations=3)
    scene["solver"].update(kernel_ratio=3.6, divergence_iterations=divergence)
    sim = Simulation(scene)
    x = sim.state.x.to_numpy()[: sim.particle_count].astype(np.float64)  # sorted, where the lists were made
    lists = sim.grid.neighbour_lists()
    assert max(map(len, lists)) > 2 * SLOTS and sim.grid.overflow[None] == 1  # not vacuous: overflowed
    h = sim.model.grid.kernel_radius_m
    for i in range(0, len(x), 97):  # a sample of rows against brute force
        d = np.linalg.norm(x - x[i], axis=1)
        expected = set(np.flatnonzero(d < h * (1 - 1e-6)).tolist()) - {i}
        near_edge = set(np.flatnonzero(np.abs(d - h) < 1e-6 * h).tolist())
        assert expected <= set(lists[i].tolist()) <= expected | near_edge
    before = hashlib.sha256(sim.positions().tobytes()).hexdigest()
    device = Simulation(scene, choices=choices(decisions_on_device=True))
    for _ in range(2):
        sim.step()
        device.step()
    assert before != hashlib.sha256(sim.positions().tobytes()).hexdigest()
    assert np.array_equal(device.positions(), sim.positions())
