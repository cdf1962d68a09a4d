"""The substep's three kernels, the same on every backend, composed of the stages' ``@ti.func`` loops
(docs/METHOD.md, "One substep on every backend"); on the host's path with solids the first kernel's
denominators are a fourth (``SubstepKernels.prepare_apart``)."""

import taichi as ti

from pbf.solver.grid import NeighbourList, named
from pbf.solver.iterations import calls
from pbf.solver.launch import Launcher


@ti.data_oriented
class SubstepKernels:
    """The kernels that run the stages given, each a ``pbf.solver`` stage object."""

    def __init__(self, state, integrator, grid, divergence, density, iterations, postprocess, prepare_apart=False):
        """``prepare_apart``: the denominators at x* in a call of their own after lines 1-7's, not in the same
        kernel: a shorter cold start where they hold a solid's 27-term ghost, Taichi's whole-kernel analyses
        growing faster than a kernel's length (docs/BENCHMARKS.md, "Start-up: cold and warm"); for the host's
        path, where a call costs little. The same loops either way, the same results bit for bit."""
        self.state, self.integrator, self.grid = state, integrator, grid
        self.density, self.divergence, self.iterations, self.postprocess = density, divergence, iterations, postprocess
        self.prepare_apart = prepare_apart
        self._find_neighbours = Launcher(self._find_neighbours_kernel)
        self._prepare = Launcher(self._prepare_kernel) if prepare_apart else None
        self._iterations = Launcher(self._iterations_kernel)
        self._divergence = Launcher(self._divergence_kernel)

    def find_neighbours(self, dt: float, gravity, features, divergence_iterations: int) -> None:
        """Lines 1-7, the divergence pre-correction's ``divergence_iterations`` (if ``features.divergence``)
        and the denominators of λ (Eq. 10) at x*: one call, more only for the pass's iterations past its
        ``PER_CALL``; with ``dt`` 0, no gravity and no divergence iteration, only the sort, the lists and the
        denominators (a restore)."""
        gx, gy, gz = (float(g) for g in gravity)
        count = divergence_iterations if features.divergence else 0  # 0: a restore runs none
        entries = self.grid.neighbours
        self._find_neighbours(entries=entries, dt=dt, gx=gx, gy=gy, gz=gz, features=features, count=count)
        if self.prepare_apart:
            self._prepare(entries, dt, features.divergence, count)
        per_call = self.divergence.PER_CALL
        calls(lambda it: self._divergence(entries, dt, it, count), per_call, count, per_call)

    def iterate(self, features, control) -> None:
        """The substep's iterations, ``per_call`` a call, while not done and short of the most."""
        iterations, per_call = control.iterations, self.iterations.per_call
        self.iterations.begin(iterations, features.measure)
        call = lambda it: self._call(features, control, it, False)  # noqa: E731
        # The device's decision read where the backend reads it (never on a GPU's choices).
        calls(call, 0, iterations, per_call, self.iterations.done)

    def finish(self, dt: float, features, control, scales, first_of_frame, max_speed) -> None:
        """x* settled, then lines 20-23 with v capped at ``max_speed`` (0: not), and the pressure
        (``scales``: Pa a unit of L and of Λ, ``pbf.solver.density.pressure_scales``; restarted
        ``first_of_frame``). The same kernel as the iterations' with the end compiled in instead of them:
        an iteration's code compiled once, not again in the last call."""
        self._call(features, control, 0, True, dt, scales, first_of_frame, max_speed)

    def _call(self, features, control, start, finish, dt=0.0, scales=(0.0, 0.0), first_of_frame=False, max_speed=0.0):
        self._iterations(
            entries=self.grid.neighbours,
            features=features,
            finish=finish,
            start=start,
            iterations=control.iterations,
            target=control.target_density_error,
            min_iterations=control.min_iterations,
            step_back=int(control.step_back),
            dt=dt,
            epsilon=control.vorticity,
            xsph_c=control.xsph,
            pressure_per_impulse=scales[0],
            pressure_per_multiplier=scales[1],
            first_of_frame=int(first_of_frame),
            max_speed=max_speed,
        )

    @ti.kernel
    def _find_neighbours_kernel(
        self,
        entries: NeighbourList,
        dt: ti.f32,
        gx: ti.f32,
        gy: ti.f32,
        gz: ti.f32,
        features: ti.template(),
        count: ti.i32,
    ):
        state, grid = self.state, self.grid
        x_star = ti.static(self.integrator.predicted.first)
        for i in range(state.live_bound()):
            grid.clear_for_visit(i)  # what the visit gathers
            if i < state.active[None]:
                # g as three numbers: Taichi 1.7.4 sets a vector argument through Python objects, slower.
                gravity = ti.Vector([gx, gy, gz])
                x_i = self.integrator.advance_particle(dt, gravity, i)  # lines 1-4: v += Δt g, x* = x + Δt v
                grid.count_in_cell(x_i, i)  # lines 5-6: a counting sort by the cell of x*,
        grid.order_loops(state.index, ti.static(state.carried))  # the state and x* gathered in sorted order
        grid.find_neighbours(ti.static(state.scratch_of(x_star)), x_star, entries, ti.static(state.carried))  # line 7
        if ti.static(features.divergence):  # ours: v made divergence-free at x, its first iterations,
            self.divergence.start(state.x, entries, dt, count)
            self.divergence.iterate(state.x, entries, dt, 0, count)
        if ti.static(not self.prepare_apart):
            self._predict_and_prepare(entries, dt, features.divergence, 0, count)

    @ti.kernel
    def _prepare_kernel(self, entries: NeighbourList, dt: ti.f32, divergence: ti.template(), count: ti.i32):
        """The end of the first kernel's work as a call of its own (``prepare_apart``)."""
        self._predict_and_prepare(entries, dt, divergence, 0, count)

    @ti.kernel
    def _divergence_kernel(self, entries: NeighbourList, dt: ti.f32, first: ti.i32, count: ti.i32):
        """The divergence pre-correction's iterations past the first call's, ``PER_CALL`` a call."""
        self.divergence.iterate(self.state.x, entries, dt, first, count)
        self._predict_and_prepare(entries, dt, True, first, count)

    @ti.func
    def _predict_and_prepare(
        self,
        entries: ti.template(),
        dt: ti.template(),
        divergence: ti.template(),
        first: ti.template(),
        count: ti.template(),
    ):
        """In the divergence pass's last call (the one that runs iterations ``first`` … up to ``count``):
        x* = x + Δt v again, then the denominators of λ (Eq. 10) at x*. Whether it is the last is read
        inside the loops, and the numbers are templates: a value made outside the loops is a one-thread task."""
        state, per_call = self.state, ti.static(self.divergence.PER_CALL)
        if ti.static(divergence):
            for i in range(state.live_bound()):
                if i < state.active[None] and count > 0 and count <= first + per_call:
                    self.integrator.predict_particle(dt, i)
        for i in range(state.live_bound()):
            if i < state.active[None] and first + per_call >= count:
                self.density.prepare(self.integrator.predicted.first, i, entries)

    @ti.kernel
    def _iterations_kernel(
        self,
        entries: NeighbourList,
        features: ti.template(),
        finish: ti.template(),
        start: ti.i32,
        iterations: ti.i32,
        target: ti.f32,
        min_iterations: ti.i32,
        step_back: ti.i32,
        dt: ti.f32,
        epsilon: ti.f32,
        xsph_c: ti.f32,
        pressure_per_impulse: ti.f32,
        pressure_per_multiplier: ti.f32,
        first_of_frame: ti.i32,
        max_speed: ti.f32,
    ):
        x = self.integrator.predicted
        run = ti.static(
            named(
                measure=features.measure,
                vorticity=features.vorticity,
                start=start,
                iterations=iterations,
                target=target,
                min_iterations=min_iterations,
                step_back=step_back,
                dt=dt,
                epsilon=epsilon,
                xsph_c=xsph_c,
                pressure_per_impulse=pressure_per_impulse,
                pressure_per_multiplier=pressure_per_multiplier,
                first_of_frame=first_of_frame,
                max_speed=max_speed,
            )
        )
        if ti.static(not finish):
            self.iterations.iterate(x.first, x.second, entries, run)  # lines 8-19
        else:  # the substep's last call:
            self.iterations.settle(x.first, x.second, run)  # x* back in the first buffer,
            self.postprocess.finish(x.first, entries, self.density.lam_total, run)  # lines 20-23
