"""The substep of the GPU backends, whose decisions stay on the device (the iterations' stopping test, the
neighbour lists' overflow), run here on the CPU (``pbf.solver.backend.decisions_on_device``): it takes
the host path's decisions and reads the device at most once per substep."""

import contextlib

import numpy as np
import pytest

from pbf import Simulation
from pbf.solver.backend import decisions_on_device
from pbf.solver.grid import SLOTS
from pbf.study.common import TransferCounter
from scenes import small_dam_break


def frames(sim, count):
    """Iterations of the last substep of each of ``count`` frames, and the reads and launches per substep."""
    used, substeps, reads, launches = [], 0, 0, 0
    for _ in range(count):
        with TransferCounter() as counter:
            sim.step()
        substeps, reads, launches = substeps + sim.frame_substeps, reads + counter.reads, launches + counter.launches
        used.append(sim.iterations_used)  # on the device path a read, outside the count
    return used, reads / substeps, launches / substeps


@pytest.mark.slow
@pytest.mark.parametrize("step_back", [True, False])
def test_the_device_takes_the_hosts_decisions(step_back):
    scene = small_dam_break(iterations=10)
    scene["solver"].update(target_density_error=0.002, expert={"step_back": step_back})
    host = Simulation(scene)
    with decisions_on_device():
        device = Simulation(scene)
    assert device.iterations.on_device and device.grid.on_device and not host.iterations.on_device
    host_used, host_reads, _ = frames(host, 6)
    device_used, device_reads, device_launches = frames(device, 6)
    # Positions differ only by rounding (the device path's sums run in other kernels, whose fused
    # multiply-adds round apart), which the splash then amplifies (5-7e-6 m after 6 frames, up to 1.1e-4
    # after 12): compared in the fall, before it does.
    assert np.abs(device.positions() - host.positions()).max() < 3e-5
    more_host, host_reads_later, _ = frames(host, 6)
    more_device, device_reads_later, device_launches_later = frames(device, 6)
    # The same mean errors, formed in float32 on the device and float64 on the host, stop the same
    # iterations through the impact.
    host_used, device_used = host_used + more_host, device_used + more_device
    host_reads, device_reads = min(host_reads, host_reads_later), max(device_reads, device_reads_later)
    device_launches = max(device_launches, device_launches_later)
    assert device_used == host_used and max(host_used) > 2  # the target stopped some substep early
    assert device.stats()["mean_density_error"] == pytest.approx(host.stats()["mean_density_error"], rel=0.02)
    assert device_reads <= 1.0 < host_reads
    assert device_launches <= 10 + 8  # every iteration is launched (past the target over no particles)


def test_a_fixed_iteration_count_reads_nothing_in_the_substep():
    scene = small_dam_break(iterations=3)
    scene["solver"].update(target_density_error=0.0, min_iterations=1)
    with decisions_on_device():
        sim = Simulation(scene)
    used, reads, _ = frames(sim, 3)
    assert used == [3, 3, 3]
    assert reads == pytest.approx(1.0 / sim.frame_substeps)  # the frame's one read: the CFL limit's speed


def test_a_pouring_nozzle_adds_no_read_to_the_substep():
    # A stream into an empty box: every substep appends a layer or more (the drowned check, the slots
    # and the live count on the device), yet the substep still reads the device once at most.
    scene = small_dam_break(iterations=3)
    scene["solver"].update(target_density_error=0.0, min_iterations=1)
    scene["fluid"]["blocks"] = []
    scene["emitters"] = [
        {"position_m": [0.4, 0.6, 0.2], "direction": [0, -1, 0], "radius_m": 0.07, "speed_m_s": 2.0, "end_s": 1.0}
    ]
    with decisions_on_device():
        sim = Simulation(scene)
    counts = []
    for _ in range(3):
        with TransferCounter() as counter:
            sim.step()
        counts.append(counter.reads / sim.frame_substeps)
        assert sim.particle_count == sim.emitters.emitted[0] * len(sim.emitters.sites[0])  # none drowned yet
    assert max(counts) <= 1.0 and sim.particle_count > 0


def test_the_gpus_list_layout_holds_the_cpus_lists(monkeypatch):
    # The GPU's neighbour lists (slot-major, built with a branch) hold the same neighbours in the same
    # order as the CPU's rows, so every sum over them adds the same terms in the same order; the
    # compiler, under fast math, may still group the additions of the two loops differently.
    scene = small_dam_break(iterations=3)
    rows = Simulation(scene)
    monkeypatch.setattr("pbf.solver.grid.on_gpu", lambda: True)
    slot_major = Simulation(scene)
    assert slot_major.grid.slot_major and not rows.grid.slot_major
    for a, b in zip(rows.grid.neighbour_lists(), slot_major.grid.neighbour_lists(), strict=True):
        assert np.array_equal(a, b)
    for _ in range(4):
        rows.step()
        slot_major.step()
    assert np.abs(rows.positions() - slot_major.positions()).max() < 1e-5  # m: rounding, 1e-4 spacings
    assert slot_major.stats()["mean_neighbours"] == pytest.approx(rows.stats()["mean_neighbours"], rel=1e-3)


@pytest.mark.parametrize("divergence", [0, 1])
def test_the_device_paths_substep_keeps_exact_lists_past_their_slots(divergence):
    # At h = 3.6 spacings a particle inside the block has about 190 neighbours, far more than the SLOTS
    # of the one-visit list: every substep of the device path takes the compact list's way (its
    # second visit and the starts it works out on the device), and must give the host path's lists
    # exactly (its own overflow read and compact build) and the same motion up to rounding. Without
    # the divergence pass the second visit runs in the first λ pass; with it, in lines 1-7's call.
    scene = small_dam_break(iterations=3)
    scene["solver"].update(kernel_ratio=3.6, divergence_iterations=divergence)
    host = Simulation(scene)
    with decisions_on_device():
        device = Simulation(scene)
    # The first substep's lists, of the same x* on both paths (later ones are of positions that rounded apart).
    host.substep()
    device.substep()
    assert max(map(len, host.grid.neighbour_lists())) > 2 * SLOTS  # not vacuous: the lists overflowed
    assert device.grid.overflow[None] == 1
    assert device.grid.on_device and not device.grid.checking  # the device's unchecked build, both visits in one call
    for a, b in zip(host.grid.neighbour_lists(), device.grid.neighbour_lists(), strict=True):
        assert np.array_equal(a, b)
    for _ in range(2):
        host.step()
        device.step()
    assert np.abs(device.positions() - host.positions()).max() < 1e-5  # m: rounding, 3e-4 spacings


class WallsChecked:
    """A stage hook that, as the iterations start and as they hand over to the substep's last call, checks
    that the walls' ghost the device path's λ and Δx passes read is the ghost at x*: the lookup the sort,
    each Δx pass and a divergence pass's re-prediction made (``DensityConstraint.walls_where_written``)
    against one made afresh there."""

    def __init__(self):
        self.sim, self.checked, self.worst = None, 0, 0.0

    @contextlib.contextmanager
    def stage(self, name):
        if name in ("solver iterations", "velocity, vorticity, XSPH, x = x*") and self.sim is not None:
            density, n = self.sim.density, self.sim.particle_count
            read = density.wall_density.to_numpy()[:n], density.wall_gradient.to_numpy()[:n]
            density._look_up_walls(self.sim.integrator.predicted.first)  # x* is in the first buffer here
            fresh = density.wall_density.to_numpy()[:n], density.wall_gradient.to_numpy()[:n]
            assert np.count_nonzero(fresh[0]) > n // 10  # not vacuous: many particles near a wall
            # Relative to the value: each lookup is inlined in another kernel, whose fused multiply-adds
            # may round it an ulp or two apart.
            self.worst = max(
                self.worst, *(float((np.abs(a - b) / (1.0 + np.abs(b))).max()) for a, b in zip(read, fresh))
            )
            self.checked += 1
        yield


@pytest.mark.slow  # it compiles the device path's kernels with an obstacle: 30-50 MB more in the worker
@pytest.mark.parametrize("divergence", [0, 1])
def test_the_device_path_reads_the_walls_ghost_at_the_positions_it_iterates(divergence):
    scene = small_dam_break(iterations=4)  # two calls: the first's 2 iterations end with x* in the first buffer
    scene["solver"].update(divergence_iterations=divergence)
    scene["obstacles"] = [{"min_m": [0.5, 0.0, 0.1], "max_m": [0.6, 0.1, 0.3]}]  # its ghost too
    hook = WallsChecked()
    with decisions_on_device():
        sim = Simulation(scene, hook=hook)
    sim.step(8)  # the water spreads along the floor into the obstacle
    hook.sim = sim
    sim.step(2)
    assert sim.density.walls_where_written and hook.checked >= 8
    # The same lookup of the same positions, up to rounding; one a substep old would be off by the ghost's
    # change over a substep's travel, percents.
    assert hook.worst < 1e-6


def first_pass_from_the_visit_and_from_the_lists(scene, checking):
    """On the device path, a substep's lines 1-7 whose visit also does the first λ pass
    (``DensityConstraint.first_in_visit``), then that pass over the lists as the host path runs it: the
    denominators and, with the surface ghost, C_i and the colour gradients, else λ̂_i, of each.
    ``checking``: lines 1-7 as when the compact list runs full (the host reads the overflow flag)."""
    with decisions_on_device():
        sim = Simulation(scene)
    sim.step(6)  # the block in its fall onto the floor: every particle compressed or at a wall
    density, grid, x_star = sim.density, sim.grid, sim.integrator.predicted
    assert sim.launches.first_in_visit(True)  # not vacuous: the visit takes the pass
    grid.checking = checking
    ghost = scene["solver"].get("surface_density", False)
    names = ("denominator", "plain_error", "colour_gradient") if ghost else ("denominator", "lam")
    sim.launches.predict_and_find_neighbours(sim.dt_s, sim.control.gravity_m_s2, True)
    visited = [getattr(density, name).to_numpy()[: sim.particle_count] for name in names]
    if grid.deferred[None]:  # the lists' second visit, which the iterations' first pass would make
        grid.build_compact(x_star.first)
    density.iterate(x_star.first, x_star.second, 0, grid.neighbours, False, 1, 1.0)  # the host path's λ pass
    walked = [getattr(density, name).to_numpy()[: sim.particle_count] for name in names]
    return sim, names, visited, walked


@pytest.mark.slow  # three more compiles of the device path in a worker: the default run's memory
@pytest.mark.parametrize(
    "solver, checking",
    [({"surface_density": True}, False), ({"kernel_ratio": 3.6}, False), ({"kernel_ratio": 3.6}, True)],
    ids=["surface ghost", "lists past their slots", "past their slots, checked"],
)
def test_the_device_paths_visit_does_the_first_lambda_pass(solver, checking):
    # The visit meets every pair within h in the order the lists hold them, so its sums are the first λ
    # pass's up to rounding: each is inlined in another kernel, whose fused multiply-adds round each
    # term apart, a few ulps of ρ/ρ0 = 1 over 190 neighbours (C_i and λ̂_i then differ by 1e-5 of their
    # largest). With h = 3.6 spacings every list overflows its slots, and the sums must still count every
    # pair: one pair's term is 1e-3 to 1e-1 of ρ/ρ0.
    scene = small_dam_break(iterations=3)
    scene["solver"].update(solver)
    sim, names, visited, walked = first_pass_from_the_visit_and_from_the_lists(scene, checking)
    if "kernel_ratio" in solver:
        assert max(map(len, sim.grid.neighbour_lists())) > 2 * SLOTS  # not vacuous: the lists overflowed
    for name, a, b in zip(names, visited, walked, strict=True):
        assert np.count_nonzero(b) > b.size // 2  # not vacuous
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-4 * np.abs(b).max(), err_msg=name)
