"""The Jacobi iterations of a substep (Algorithm 1, lines 8-19) and the rules that steer them: the error
target that stops them (after ``min_iterations``), the accelerated weights that restart when the error
rises, and the step back that takes back the part of the last iteration the target did not need
(``DensityConstraint.step_back``).

On the CPU backend the host steers: each iteration returns its mean error and the loop stops at the
target, so no launch is wasted (a launch costs 30-100 µs on two cores, reading its result nothing
more). On a GPU backend that would make the host wait for the device after every iteration, so the
rules run on the device instead: each iteration's kernel reads the state of the loop (the buffer
that holds x*, the weight's index, the last error, whether the target was met) from a few device
entries and updates them at its end, and once the target is met the remaining launches loop over no
particles. The host launches ``solver.iterations`` of them and one to finish (the step back, or x*
copied back into the first buffer) and reads nothing; the iteration count comes back only when asked
(``used``, for ``stats()``). The two paths take the same decisions from the same mean errors, which
the device forms in float32 and the host in float64 from the same compensated sum.
"""

import math

import numpy as np
import taichi as ti

from pbf.solver.grid import NeighbourList

DONE, WEIGHT_INDEX, USED, IN_SECOND, STEPPING_BACK = range(5)
"""Entries of ``JacobiIterations.flags``."""
LAST_ERROR, FRACTION = range(2)
"""Entries of ``JacobiIterations.values``."""


@ti.data_oriented
class JacobiIterations:
    """Runs a substep's iterations on the host's or on the device's decisions (``on_device``)."""

    def __init__(self, density, weights, active, on_device: bool):
        self.density = density
        self.weights = weights
        """``pbf.solver.acceleration.Weights``: the host path's weights, and the table the device copies."""
        self.active = active
        self.on_device = on_device
        self._used = 0
        if on_device:
            self.table = ti.field(ti.f32, shape=len(weights.table))
            self.table.from_numpy(np.asarray(weights.table, np.float32))
            self.flags = ti.field(ti.i32, shape=5)
            self.values = ti.field(ti.f32, shape=2)

    @property
    def used(self) -> int:
        """Iterations the last substep ran (on the device path one read, so only when asked)."""
        return int(self.flags[USED]) if self.on_device else self._used

    @used.setter
    def used(self, count: int) -> None:
        if self.on_device:
            self.flags[USED] = count
        else:
            self._used = count

    def run(self, predicted, neighbours, control) -> None:
        """``control.iterations`` Jacobi iterations of x* (a ``PredictedPositions``) at most, stopped by
        ``control.target_density_error`` (0: never) after ``control.min_iterations``; x* may end in
        either buffer (``predicted.gather()`` brings it back)."""
        if self.on_device:
            self._run_on_device(predicted, neighbours, control)
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

    def _run_on_device(self, predicted, neighbours, control) -> None:
        assert not predicted.in_second, "a substep's x* starts in the first buffer"
        target = control.target_density_error
        for k in range(control.iterations):
            self._iterate(
                predicted.first,
                predicted.second,
                neighbours,
                target > 0.0,
                k,
                target,
                control.min_iterations,
                int(control.step_back),
            )
        self._finish(predicted.first, predicted.second)
        predicted.in_second = False

    @ti.kernel
    def _iterate(
        self,
        first: ti.template(),
        second: ti.template(),
        neighbours: NeighbourList,
        measure: ti.template(),
        k: ti.i32,
        target: ti.f32,
        min_iterations: ti.i32,
        step_back: ti.i32,
    ):
        """Iteration ``k`` of the substep, over no particles once the target was met; then the rules of
        :meth:`_run_on_host` on the device's entries."""
        if k == 0:
            self.flags[DONE] = 0
            self.flags[WEIGHT_INDEX] = 0
            self.flags[IN_SECOND] = 0
            self.flags[STEPPING_BACK] = 0
            self.values[LAST_ERROR] = ti.math.inf
        running = 1 - self.flags[DONE]
        count = self.active[None] * running
        from_second = self.flags[IN_SECOND]
        weight = self.table[ti.min(self.flags[WEIGHT_INDEX], self.table.shape[0] - 1)]
        first_iteration = ti.select(k == 0, 1, 0)
        # The passes of DensityConstraint.iterate, over no particles once done.
        for i in range(count):
            self.density.multiplier_pass(first, second, from_second, i, neighbours, measure, first_iteration, weight)
        for i in range(self.density.surface_count(first_iteration) * running):
            self.density.surface_pass(first, i, neighbours, measure, first_iteration, weight)
        for i in range(count):
            self.density.jacobi_step(first, second, from_second, i, neighbours, weight)
        if ti.static(measure):
            self.density.error_sum.sum(self.density.error, 0, count)
        if running:
            self.flags[USED] = k + 1
            self.flags[IN_SECOND] = 1 - from_second
            self.flags[WEIGHT_INDEX] += 1
            if ti.static(measure):
                error = self.density.error_sum.total(0) / ti.cast(ti.max(count, 1), ti.f32)
                last = self.values[LAST_ERROR]
                if error < target and k + 1 >= min_iterations:
                    if step_back and k + 1 > min_iterations and last >= target:
                        self.values[FRACTION] = (target - error) / (last - error)
                        self.flags[STEPPING_BACK] = 1
                    self.flags[DONE] = 1
                else:
                    if error > last:  # the acceleration overshot: plain again
                        self.flags[WEIGHT_INDEX] = 0
                    self.values[LAST_ERROR] = error

    @ti.kernel
    def _finish(self, first: ti.template(), second: ti.template()):
        """x* into the first buffer: stepped back between the buffers, or copied when it is in the second."""
        in_second, stepping_back = self.flags[IN_SECOND], self.flags[STEPPING_BACK]
        fraction = self.values[FRACTION]
        for i in range(self.active[None] * ti.max(in_second, stepping_back)):
            if stepping_back:
                self.density.between(first, second, in_second, fraction, i)
            else:
                first[i] = second[i]
