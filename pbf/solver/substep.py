"""The substep's launches: the stages of Algorithm 1, each in a module of its own, composed into few kernels.

Each stage is a set of loops (``@ti.func``) in its module: the prediction in ``pbf.solver.integrate``,
the counting sort and the neighbour visit in ``pbf.solver.grid``, the Jacobi iterations in
``pbf.solver.iterations`` and ``pbf.solver.density``, the velocity update in ``pbf.solver.postprocess``.
On a GPU every kernel call costs the host tens of microseconds and every top-level loop a launch of a
few, so at 8,000 particles the calls, not the work, set the cost of a substep. The kernels here run
consecutive stages in one call:

* lines 1-7, :meth:`SubstepLaunches.predict_and_find_neighbours`: v += Δt g and x* = x + Δt v, the
  counting sort by cell with the state reordered alike, and the neighbour lists (both visits on a
  device that keeps its decisions; the first, and its overflow flag back to the host, on the CPU);
* lines 8-19, the iterations: on the CPU one call each, steered by the host; on the device path
  PER_LAUNCH a call (``pbf.solver.iterations``), the last call's in the call that ends the substep;
* lines 20-23, :meth:`SubstepLaunches.finish` on the device path: the last iterations, x* settled
  into the first buffer (copied back or stepped back between the two), then the velocity, vorticity
  and XSPH passes and x = x*, in one call. At 4 iterations a substep is 3 calls.
"""

import taichi as ti

from pbf.solver.grid import NeighbourList
from pbf.solver.launch import Launcher

MOST_DIVERGENCE_IN_CALL = 2
"""The divergence pre-correction's iterations the device path runs in the call of lines 1-7 at most (each
is a copy of its two loops there); more run a call each, as on the host's path."""


@ti.data_oriented
class SubstepLaunches:
    """The kernels that run consecutive stages of a substep in one call (the module docstring); the
    stages themselves are the objects given, each from its module."""

    def __init__(self, state, integrator, grid, iterations, postprocess, divergence):
        self.state = state
        self.integrator = integrator
        self.grid = grid
        self.iterations = iterations
        self.postprocess = postprocess
        self.divergence = divergence
        # The calls, launched past Taichi's per-call Python once compiled (pbf.solver.launch).
        self._launch_on_device = Launcher(self._predict_and_find_neighbours_on_device)
        self._launch_visit = Launcher(self._predict_and_visit)
        self._launch_finish = Launcher(self._finish)

    def predict_and_find_neighbours(
        self, dt: float, gravity, defer: bool = False, divergence: int = 0, piston=None
    ) -> bool:
        """Algorithm 1, lines 1-7, in one call: v += Δt g, x* = x + Δt v (kept inside the boundaries),
        the particles and x* sorted by the cell of x*, and their exact neighbour lists. On the CPU the
        call returns whether a particle has more than SLOTS neighbours, and only then a second visit
        fills a compact list (``NeighbourGrid.build_compact``). On the device path ``defer`` leaves an
        overflow's second visit to the first pass of the iterations (``NeighbourGrid.finish_compact``),
        for a substep in which nothing else reads the lists before it, and ``divergence`` iterations of
        the divergence pre-correction (up to MOST_DIVERGENCE_IN_CALL) run in the same call, then x* is
        predicted again and the walls' ghost looked up there. ``piston``: the wave maker's place and
        velocity for this substep (``Boundaries.move``'s, not yet set), set first in the same call.
        Returns whether the pre-correction ran."""
        grid, x = self.grid, self.integrator.predicted.first
        place = piston is not None and self.integrator.boundaries.container.wave_maker
        piston_x, piston_v = piston if place else (0.0, 0.0)
        if grid.on_device and not grid.checking:
            in_call = divergence if divergence <= MOST_DIVERGENCE_IN_CALL else 0
            self._launch_on_device(grid.neighbours, dt, *gravity, defer, in_call, place, piston_x, piston_v)
            return in_call > 0
        if self._launch_visit(grid.neighbours, dt, *gravity, defer, place, piston_x, piston_v):
            grid.build_compact(x)
        return False

    def predict_again(self, dt: float) -> None:
        """x* = x + Δt v again after the divergence pre-correction changed v (a call), with the walls'
        ghost looked up at the new x* on the device path (another: ``DensityConstraint.look_up_walls``)."""
        self.integrator.predict(dt)
        self.iterations.density.look_up_walls(self.integrator.predicted.first)

    def first_in_visit(self, defer: bool) -> bool:
        """Whether the visit of lines 1-7 also does the first iteration's λ pass (``defer``: nothing between
        the visit and the iterations moves x*; ``DensityConstraint.first_in_visit``): the iterations are
        told the same (``JacobiIterations.iterate_loops``' ``finish_lists``)."""
        return defer and self.iterations.density.first_in_visit

    @ti.func
    def _predict_and_sort(self, dt: ti.template(), gravity: ti.template()):
        for i in range(self.state.live_bound()):
            self.grid.clear_for_visit(i)  # for this substep's visit
            if i < self.state.active[None]:
                x_star = self.integrator.advance_particle(dt, gravity, i)  # lines 1-4: v = v + Δt g, x* = x + Δt v
                self.grid.count_in_cell(x_star, i)  # lines 5-7: a counting sort by the cell of x*,
        self.grid.order_loops(self.state.index, self)  # the state and x* gathered in sorted order (gather)

    @ti.func
    def gather(self, slot, i):
        """The sort's gather of particle i into ``slot`` (``NeighbourGrid.order_loops``): the state and x*
        into their scratch, and on the device path the walls' ghost at x*, looked up here once for the
        first λ and Δx passes (``DensityConstraint.walls_where_written``)."""
        self.state.gather(slot, i)
        self.iterations.density.wall_ghost_at(slot, self.integrator.predicted.first[i])

    @ti.kernel
    def _predict_and_find_neighbours_on_device(
        self,
        neighbours: NeighbourList,
        dt: ti.f32,
        gx: ti.f32,
        gy: ti.f32,
        gz: ti.f32,
        defer: ti.template(),
        divergence: ti.template(),
        place: ti.template(),
        piston_x: ti.f32,
        piston_v: ti.f32,
    ):
        if ti.static(place):  # the wave maker where the substep ends (Container.move): a task, not a call
            self.integrator.boundaries.container.set_piston(piston_x, piston_v)
        # g as three numbers: Taichi 1.7.4 sets a vector argument through Python objects, about 15 µs more
        # a call than three values (benchmarks/kernel_arguments.py).
        self._predict_and_sort(dt, ti.Vector([gx, gy, gz]))
        x = ti.static(self.integrator.predicted.first)
        gathered = ti.static(self.state.scratch_of(x))
        if ti.static(self.first_in_visit(defer)):  # the lists, and the first λ pass (DensityConstraint.first_in_visit)
            self.grid.visit_on_device(x, neighbours, self.state, gathered, defer, self.iterations.density)
        else:
            self.grid.visit_on_device(x, neighbours, self.state, gathered, defer)
        if ti.static(divergence > 0):  # ours: v made divergence-free at x (it reads the lists, so no defer),
            self.divergence.run_loops(self.state.x, neighbours, dt, divergence)
            for i in range(self.state.live_bound()):  # then x* = x + Δt v again, and the walls' ghost there
                if i < self.state.active[None]:
                    self.iterations.density.wall_ghost_at(i, self.integrator.predict_particle(dt, i))

    @ti.kernel
    def _predict_and_visit(
        self,
        neighbours: NeighbourList,
        dt: ti.f32,
        gx: ti.f32,
        gy: ti.f32,
        gz: ti.f32,
        defer: ti.template(),
        place: ti.template(),
        piston_x: ti.f32,
        piston_v: ti.f32,
    ) -> ti.i32:
        self.grid.overflow[None] = 0  # the sort clears it in its first thread, which an empty box lacks
        if ti.static(place):  # and the wave maker where the substep ends, in the same one-thread task
            self.integrator.boundaries.container.set_piston(piston_x, piston_v)
        self._predict_and_sort(dt, ti.Vector([gx, gy, gz]))
        x = ti.static(self.integrator.predicted.first)
        gathered = ti.static(self.state.scratch_of(x))
        if ti.static(self.first_in_visit(defer)):  # the lists' first visit, and the first λ pass
            self.grid.visit_first(gathered, neighbours, self.state, False, False, self.iterations.density)
        else:
            self.grid.visit_first(gathered, neighbours, self.state)
        return self.grid.overflow[None]

    def finish(self, neighbours, control, defer: bool, *finish) -> None:
        """The device path's end of a substep in one call (:meth:`_finish`): the iterations of the last call,
        x* settled into the first buffer, then lines 20-23 (``finish``: the arguments of
        ``VelocityPostprocess.finish`` after the neighbours). Loops that would run over no particle are
        left out at compile time, each a launch saved: the surface pass unless the last call holds the
        substep's first iteration, and the settling when x* surely ends in the first buffer (no target,
        an even count: the last iteration reads the second and writes the first). ``defer``: as in
        :meth:`predict_and_find_neighbours`."""
        iterations, measure = control.iterations, control.target_density_error > 0.0
        start = self.iterations.last_start(iterations)
        self._launch_finish(
            neighbours,
            measure,
            self.iterations.per_launch,
            start == 0,
            defer and start == 0,
            measure or iterations % 2 == 1,
            start,
            iterations,
            control.target_density_error,
            control.min_iterations,
            int(control.step_back),
            *finish,
        )

    @ti.kernel
    def _finish(
        self,
        neighbours: NeighbourList,
        measure: ti.template(),
        per_launch: ti.template(),
        may_start: ti.template(),
        finish_lists: ti.template(),
        settle: ti.template(),
        start: ti.i32,
        iterations: ti.i32,
        target: ti.f32,
        min_iterations: ti.i32,
        step_back: ti.i32,
        dt: ti.f32,
        vorticity: ti.f32,
        xsph: ti.f32,
        with_vorticity: ti.template(),
        with_xsph: ti.template(),
        impulse: ti.template(),
        pressure_per_impulse: ti.f32,
        first_of_frame: ti.i32,
        max_speed: ti.f32,
    ):
        """:meth:`finish`'s launch: the iterations from ``start`` (``JacobiIterations.iterate_loops``, the
        surface pass and the first iteration's λ pass only with ``may_start``, a deferred second visit
        only with ``finish_lists``), x* settled into the first buffer (``JacobiIterations.settle_loop``,
        only with ``settle``), then lines 20-23 (``VelocityPostprocess.finish``)."""
        self.iterations.iterate_loops(
            self.integrator.predicted.first,
            self.integrator.predicted.second,
            neighbours,
            measure,
            per_launch,
            may_start,
            finish_lists,
            start,
            iterations,
            target,
            min_iterations,
            step_back,
        )
        if ti.static(settle):
            self.iterations.settle_loop(
                self.integrator.predicted.first, self.integrator.predicted.second, measure, iterations
            )
        self.postprocess.finish_loops(
            self.integrator.predicted.first,
            neighbours,
            dt,
            vorticity,
            xsph,
            with_vorticity,
            with_xsph,
            impulse,
            pressure_per_impulse,
            first_of_frame,
            max_speed,
        )
