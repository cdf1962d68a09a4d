"""The Jacobi iterations of a substep (Algorithm 1, lines 8-19) as loops for ``pbf.solver.substep``'s kernels,
and the stopping rule, decided on the device after each error sum (docs/METHOD.md, "One substep on every
backend"); the host's loop over a pass's calls, :func:`calls` (the density's and the divergence's).
"""

import numpy as np
import taichi as ti

DONE, WEIGHT_INDEX, USED, IN_SECOND, STEPPING_BACK = range(5)
"""Entries of ``JacobiIterations.flags``."""
LAST_ERROR, FRACTION = range(2)
"""Entries of ``JacobiIterations.values``."""


def calls(call, first: int, end: int, per_call: int, done=None) -> int:
    """The host's loop over a pass's kernel calls: ``call(it)`` runs iterations it … it + per_call − 1
    (the kernel skips those past the pass's count), while not ``done()`` (read after each call) and it
    is short of ``end``; returns the first iteration no call ran. The count is data, so every count
    runs the same compiled kernels."""
    it, finished = first, False
    while not finished and it < end:
        call(it)
        it += per_call
        finished = done is not None and done()
    return it


@ti.data_oriented
class JacobiIterations:
    """A substep's iterations as loops for ``pbf.solver.substep``'s kernels, steered on the device."""

    def __init__(self, density, weights: tuple[float, ...], state, per_call: int, reads_decisions: bool):
        self.density = density
        self.state = state  # its live particles: the loops' bound, the count
        self.per_call = per_call  # iterations a kernel call runs (each a copy of an iteration's code)
        self.reads_decisions = reads_decisions  # the host reads after each call whether the target was met
        # The first iteration weighs its λ by 1 (DensityConstraint.multiplier_pass starts L afresh there).
        assert weights[0] == 1.0, f"the first iteration's weight is 1 in every table, not {weights[0]}"
        self.table = ti.field(ti.f32, shape=len(weights))
        self.table.from_numpy(np.asarray(weights, np.float32))
        """The iterations' weights (``pbf.solver.acceleration``)."""
        self.flags = ti.field(ti.i32, shape=5)
        self.values = ti.field(ti.f32, shape=2)
        self._count = 0
        self._measured = False

    @property
    def used(self) -> int:
        """Iterations the last substep ran (with a target one read, so only when asked)."""
        return int(self.flags[USED]) if self._measured else self._count

    def begin(self, iterations: int, measure: bool) -> None:
        """A substep's iterations begin (none after a restore): ``iterations``, fewer by :meth:`decide` when
        ``measure``."""
        self._count, self._measured = iterations, measure

    def done(self) -> bool:
        """The device's decision to stop (:meth:`decide`), read by the host where the backend reads it."""
        return self._measured and self.reads_decisions and bool(self.flags[DONE])

    @ti.func
    def _loop_state(self, measure: ti.template(), k):
        """(running, the buffer x* is in, the weight's index) before iteration ``k``, as iteration k − 1 decided."""
        running, from_second, index = 1, k % 2, k
        if ti.static(measure):
            if k > 0:
                running = 1 - self.flags[DONE]
                from_second = self.flags[IN_SECOND]
                index = self.flags[WEIGHT_INDEX]
        return running, from_second, index

    @ti.func
    def _weight(self, index):
        return self.table[ti.min(index, self.table.shape[0] - 1)]

    @ti.func
    def iterate(self, first: ti.template(), second: ti.template(), neighbours: ti.template(), run: ti.template()):
        """Iterations ``run.start`` … ``run.start + per_call − 1`` (over no particles once the target was
        met), for the top level of a kernel: λ̂_i (Eqs. 1, 10, lines 9-11); Δx_i (Eqs. 11-12), collided,
        x*_i += Δx_i (lines 12-17); with a target Σ max(C_i, 0), then the rules (:meth:`decide`)."""
        density = self.density
        for u in ti.static(range(self.per_call)):
            for i in range(self.state.live_bound()):
                k = run.start + u
                running, from_second, index = self._loop_state(run.measure, k)
                if k < run.iterations and i < self.state.active[None] * running:
                    density.multiplier_pass(first, second, from_second, i, neighbours, k, self._weight(index))
            for i in range(self.state.live_bound()):
                k = run.start + u
                running, from_second, index = self._loop_state(run.measure, k)
                if k < run.iterations and i < self.state.active[None] * running:
                    density.jacobi_step(first, second, from_second, i, neighbours, self._weight(index))
            if ti.static(run.measure):
                density.error_sum.sum(density.error, 0, self.state.active)
                for _ in range(1):  # one thread
                    self.decide(run.start + u, density.error_sum.total(0), run)

    @ti.func
    def decide(self, k, total, run: ti.template()):
        """The stopping rule after iteration k, from the error's sum ``total``, into the flags the next
        iteration and the host read: the target met (after the least iterations) stops, stepping back the
        share it did not need; a rising error restarts the weights."""
        iterations, target, min_iterations, step_back = run.iterations, run.target, run.min_iterations, run.step_back
        running, from_second, index = self._loop_state(True, k)
        if running and k < iterations:
            error = total / ti.cast(ti.max(self.state.active[None], 1), ti.f32)
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
    def settle(self, first: ti.template(), second: ti.template(), run: ti.template()):
        """x* into the first buffer after the iterations (stepped back, or copied from the second)."""
        for i in range(self.state.live_bound()):
            in_second, stepping_back, fraction = run.iterations % 2, 0, 0.0
            if ti.static(run.measure):
                in_second, stepping_back = self.flags[IN_SECOND], self.flags[STEPPING_BACK]
                fraction = self.values[FRACTION]
            if i < self.state.active[None] and (in_second or stepping_back):
                if stepping_back:
                    self.density.between(first, second, in_second, fraction, i)
                else:
                    first[i] = second[i]
