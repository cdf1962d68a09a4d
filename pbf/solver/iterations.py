"""The Jacobi iterations of a substep (Algorithm 1, lines 8-19) and the rules that steer them: the error
target that stops them (after ``min_iterations``), the accelerated weights that restart when the error
rises, and the step back that takes back the part of the last iteration the target did not need
(``DensityConstraint.step_back``).

On the CPU backend the host steers: each iteration returns its mean error and the loop stops at the
target, so no launch is wasted (a launch costs 30-100 µs on two cores, reading its result nothing
more). On a GPU backend that would make the host wait for the device after every iteration, so the
rules run on the device instead, in the one thread that finishes each iteration's error sum
(``TreeSum.sum_then``, :meth:`JacobiIterations.received`): it writes the state of the loop (the buffer
that holds x*, the weight's index, the last error, whether the target was met) to a few device
entries that the next iteration's threads read, and once the target is met the remaining iterations
loop over no particles. Without a target the state is a function of the iteration's index and
nothing is written. The host launches ``solver.iterations`` of them, PER_LAUNCH to a call, and reads
nothing; the end (the step back, or x* copied back into the first buffer) runs in the call that ends
the substep (``pbf.solver.substep``), and the iteration count comes back only when asked (``used``,
for ``stats()``). The two paths take the same decisions from the same mean errors, which the device
forms in float32 and the host in float64 from the same compensated sum.
"""

import math

import numpy as np
import taichi as ti

from pbf.solver.grid import NeighbourList
from pbf.solver.launch import Launcher

DONE, WEIGHT_INDEX, USED, IN_SECOND, STEPPING_BACK = range(5)
"""Entries of ``JacobiIterations.flags``."""
LAST_ERROR, FRACTION = range(2)
"""Entries of ``JacobiIterations.values``."""
PER_LAUNCH = 2
"""Iterations per kernel call on the device path. A call costs the host 60-130 µs on a GPU machine
(Taichi's Python side sets every argument); at 2 a call a substep of 4 iterations is 3 calls with the
last call's iterations run in the substep's last launch (``pbf.solver.substep``), 6 at the presets'
10. Each iteration in a call is a copy of its code: +1.5 s of compile at 2 and +5 s at 4 against 1
(8,000 particles, the CPU backend; docs/BENCHMARKS.md, "Launches per substep")."""


@ti.data_oriented
class JacobiIterations:
    """Runs a substep's iterations on the host's or on the device's decisions (``on_device``)."""

    def __init__(self, density, weights, active, on_device: bool, per_launch: int = PER_LAUNCH):
        self.density = density
        self.weights = weights
        """``pbf.solver.acceleration.Weights``: the host path's weights, and the table the device copies."""
        self.active = active
        self.on_device = on_device
        self.per_launch = per_launch
        """Iterations per kernel call on the device path: more save host time per substep (tens of µs a
        call on a GPU) and cost compile time (each is a copy of an iteration's code)."""
        self._used = 0
        self._measured = False
        """Whether the last substep on the device path had a target (else it ran every iteration)."""
        self._launch_iterate = Launcher(self._iterate)  # past Taichi's per-call Python (pbf.solver.launch)
        if on_device:
            # The visit that may do the first λ pass weighs it by 1 (DensityConstraint.sums_in_visit_end).
            assert weights.table[0] == 1.0, f"the first iteration's weight is 1 in every table, not {weights.table[0]}"
            self.table = ti.field(ti.f32, shape=len(weights.table))
            self.table.from_numpy(np.asarray(weights.table, np.float32))
            self.flags = ti.field(ti.i32, shape=5)
            self.values = ti.field(ti.f32, shape=2)

    @property
    def used(self) -> int:
        """Iterations the last substep ran (on the device path with a target one read, so only when asked)."""
        return int(self.flags[USED]) if self.on_device and self._measured else self._used

    @used.setter
    def used(self, count: int) -> None:
        if self.on_device:
            self.flags[USED] = count
        self._used = count

    def run(self, predicted, neighbours, control, defer: bool = False) -> None:
        """``control.iterations`` Jacobi iterations of x* (a ``PredictedPositions``) at most, stopped by
        ``control.target_density_error`` (0: never) after ``control.min_iterations``; x* may end in
        either buffer (``predicted.gather()`` brings it back). On the device path all calls but the
        last: the caller runs the last call's iterations (from :meth:`last_start`,
        :meth:`iterate_loops`) and :meth:`settle_loop` in the launch that ends the substep
        (``pbf.solver.substep.SubstepLaunches.finish``). ``defer``: the lists' second visit after an
        overflow was left to the first λ pass (``NeighbourGrid.finish_compact``; the device path only)."""
        if self.on_device:
            self._run_on_device(predicted, neighbours, control, defer)
        else:
            self._run_on_host(predicted, neighbours, control)

    def _run_on_host(self, predicted, neighbours, control) -> None:
        target = control.target_density_error
        weights, last_error = self.weights, math.inf
        weights.restart()
        for k in range(control.iterations):  # lines 8-19: λ, Δx, collision, x* += Δx
            error = self.density.project(
                predicted,
                neighbours,  # Jacobi, into the other buffer
                measure=target > 0.0,
                first=k == 0,
                weight=weights.next(),
            )
            self._used = k + 1
            if target > 0.0 and error < target and k + 1 >= control.min_iterations:
                if control.step_back and k + 1 > control.min_iterations and last_error >= target:
                    # The target fell between the last two errors: take back the share of the last
                    # iteration it did not need, a count in between (DensityConstraint.step_back).
                    self.density.step_back(predicted, (target - error) / (last_error - error))
                break  # the error this iteration started from
            if target > 0.0 and error > last_error:  # the acceleration overshot: plain again
                weights.restart()
            last_error = error

    def _run_on_device(self, predicted, neighbours, control, defer: bool) -> None:
        assert not predicted.in_second, "a substep's x* starts in the first buffer"
        target = control.target_density_error
        measure = target > 0.0
        for k in range(0, self.last_start(control.iterations), self.per_launch):  # the last call: the caller's
            self._launch_iterate(
                predicted.first,
                predicted.second,
                neighbours,
                measure,
                self.per_launch,
                defer,
                k,
                control.iterations,
                target,
                control.min_iterations,
                int(control.step_back),
            )
        self._used, self._measured = control.iterations, measure

    def last_start(self, iterations: int) -> int:
        """The first iteration of the last call of ``iterations`` on the device path, which :meth:`run`
        leaves to the launch that ends the substep."""
        return (iterations - 1) // self.per_launch * self.per_launch

    @ti.func
    def _loop_state(self, measure: ti.template(), k):
        """(running, the buffer x* is in, the weight's index) before iteration ``k``: without a target a
        function of k; with one, what the sum of iteration k − 1 decided (:meth:`received`)."""
        running, from_second, index = 1, k % 2, k
        if ti.static(measure):
            if k > 0:
                running = 1 - self.flags[DONE]
                from_second = self.flags[IN_SECOND]
                index = self.flags[WEIGHT_INDEX]
        return running, from_second, index

    @ti.kernel
    def _iterate(
        self,
        first: ti.template(),
        second: ti.template(),
        neighbours: NeighbourList,
        measure: ti.template(),
        per_launch: ti.template(),
        finish_lists: ti.template(),
        start: ti.i32,
        iterations: ti.i32,
        target: ti.f32,
        min_iterations: ti.i32,
        step_back: ti.i32,
    ):
        """Iterations ``start`` … ``start + per_launch − 1`` of the substep's ``iterations`` (:attr:`per_launch`),
        each over no particles once the target was met; with a target, after each the rules of
        :meth:`_run_on_host` decided by the thread that holds the error's sum.

        Every loop runs over the particles' bucket, a count the kernel knows, and every thread reads the
        loop's state and the live count itself: read once outside the loops they would be one-thread
        tasks of their own, a launch each on a GPU."""
        self.iterate_loops(
            first,
            second,
            neighbours,
            measure,
            per_launch,
            True,
            finish_lists,
            start,
            iterations,
            target,
            min_iterations,
            step_back,
        )

    @ti.func
    def iterate_loops(
        self,
        first: ti.template(),
        second: ti.template(),
        neighbours: ti.template(),
        measure: ti.template(),
        per_launch: ti.template(),
        may_start: ti.template(),
        finish_lists: ti.template(),
        start: ti.template(),
        iterations: ti.template(),
        target: ti.template(),
        min_iterations: ti.template(),
        step_back: ti.template(),
    ):
        """The loops of :meth:`_iterate`, for the top level of a kernel (``pbf.solver.substep`` runs the
        substep's last call of them in the launch that ends it); every argument a template, so that no
        value is copied outside the loops (a one-thread task). ``may_start``: whether the call may hold the
        substep's first iteration (``start`` 0): only then are the surface ghost's pass and the first
        iteration's λ pass (the one that also finds the gradients, ``DensityConstraint.constraint``)
        compiled in. Elsewhere, and in every iteration of a call but its first, the later iterations' λ
        pass is compiled alone: on a GPU the two in one task kept the registers of the larger
        (``benchmarks/registers.py``);
        ``finish_lists``: whether the substep's visit left an overflow's second visit to the first pass
        here (``NeighbourGrid.finish_compact``: each thread its own particle's list, the only one its pass
        reads), and did the first iteration's λ pass itself where the density constraint allows it
        (``DensityConstraint.first_in_visit``): then the loop of a call's first λ pass runs, in the
        substep's first iteration, the surface ghost's pass (the colour gradients are the visit's) or,
        without the ghost, only the lists' second visit, and in a later iteration its λ pass."""
        for u in ti.static(range(per_launch)):
            in_visit = ti.static(u == 0 and may_start and finish_lists and self.density.first_in_visit)
            for i in range(ti.static(self.density.error.shape[0])):
                if ti.static(u == 0 and finish_lists):
                    if start == 0:
                        self.density.grid.finish_compact(first, neighbours, i, self.density.grid.deferred)
                k = start + u
                running, from_second, index = self._loop_state(measure, k)
                if k < iterations and i < self.active[None] * running:
                    weight = self._weight(index)
                    if ti.static(in_visit):
                        if k == 0:  # λ̂ of the substep's first iteration waits for the ghost, or is done
                            if i < self.density.surface_count(1):
                                self.density.surface_pass(first, i, neighbours, measure, 1, weight)
                        else:
                            self.density.multiplier_pass(first, second, from_second, i, neighbours, measure, 0, weight)
                    else:
                        first_iteration = 0
                        if ti.static(u == 0 and may_start):
                            first_iteration = ti.select(k == 0, 1, 0)
                        self.density.multiplier_pass(
                            first, second, from_second, i, neighbours, measure, first_iteration, weight
                        )
            if ti.static(u == 0 and may_start and not in_visit):  # the surface ghost, in a first iteration
                for i in range(ti.static(self.density.error.shape[0])):
                    running, _, index = self._loop_state(measure, start)
                    if start == 0 and i < self.density.surface_count(1):
                        self.density.surface_pass(first, i, neighbours, measure, 1, self._weight(index))
            for i in range(ti.static(self.density.error.shape[0])):
                k = start + u
                running, from_second, index = self._loop_state(measure, k)
                if k < iterations and i < self.active[None] * running:
                    self.density.jacobi_step(first, second, from_second, i, neighbours, self._weight(index))
            if ti.static(measure):
                # The arguments as they are (a tuple of templates), read where they are used.
                self.density.error_sum.sum_then(
                    self.density.error, 0, self.active, self, (start + u, iterations, target, min_iterations, step_back)
                )

    @ti.func
    def _weight(self, index):
        return self.table[ti.min(index, self.table.shape[0] - 1)]

    @ti.func
    def received(self, total, count, context: ti.template()):
        """The rules of :meth:`_run_on_host` after iteration k of ``context`` (k, the substep's iterations,
        the target, the least iterations, whether to step back: the kernel's arguments), on the mean error ``total`` /
        ``count``: run by the one thread that summed it (``TreeSum.sum_then``), into the flags the next
        iteration reads."""
        k, iterations, target, min_iterations, step_back = context
        running, from_second, index = self._loop_state(True, k)
        if running and k < iterations:
            error = total / ti.cast(ti.max(count, 1), ti.f32)
            last = ti.math.inf
            if k > 0:
                last = self.values[LAST_ERROR]
            self.flags[USED] = k + 1
            self.flags[IN_SECOND] = 1 - from_second
            self.flags[WEIGHT_INDEX] = index + 1
            self.flags[DONE] = 0
            self.flags[STEPPING_BACK] = 0
            if error < target and k + 1 >= min_iterations:
                if step_back and k + 1 > min_iterations and last >= target:
                    self.values[FRACTION] = (target - error) / (last - error)
                    self.flags[STEPPING_BACK] = 1
                self.flags[DONE] = 1
            else:
                if error > last:  # the acceleration overshot: plain again
                    self.flags[WEIGHT_INDEX] = 0
                self.values[LAST_ERROR] = error

    @ti.func
    def settle_loop(
        self, first: ti.template(), second: ti.template(), measure: ti.template(), iterations: ti.template()
    ):
        """x* into the first buffer after ``iterations`` iterations on the device's decisions: stepped back
        between the buffers, or copied when it is in the second. For the top level of a kernel
        (``pbf.solver.substep`` runs it in the launch that ends the substep)."""
        for i in range(ti.static(self.density.error.shape[0])):
            in_second, stepping_back, fraction = iterations % 2, 0, 0.0
            if ti.static(measure):
                in_second, stepping_back = self.flags[IN_SECOND], self.flags[STEPPING_BACK]
                fraction = self.values[FRACTION]
            if i < self.active[None] and (in_second or stepping_back):
                if stepping_back:
                    self.density.between(first, second, in_second, fraction, i)
                else:
                    first[i] = second[i]
