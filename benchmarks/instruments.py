"""The lab's instruments, which nothing in ``pbf`` imports: what Taichi launches, reads and compiles
(:func:`watching`, :class:`TransferCounter`), and the tasks Taichi's kernel profiler timed.

Watching wraps Taichi's own classes and ``pbf.solver.launch.Launcher._launch`` (Taichi's internals:
the Taichi ``pbf.solver.launch`` was written for only). A kernel call is one call of a ``@ti.kernel``;
Taichi splits it into offloaded tasks (each top-level loop, and each run of statements outside
loops, a one-thread ``serial`` task), each a launch on a GPU.
"""

from __future__ import annotations

import contextlib
import io
import re
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np
import taichi as ti

from pbf.solver import launch


class Observer:
    """What an instrument is told while it watches; only the methods a subclass overrides are watched for."""

    def launched(self, kernel: str, waits: bool) -> None:
        """A kernel launch (Taichi's own included); ``waits``: the host waits for a result."""

    def accessed(self, read: bool) -> None:
        """An element of a field or ndarray read (``read``) or written from Python (``field[None]``)."""

    def compiled(self, kernel: str, seconds: float) -> None:
        """A kernel call that compiled a new variant: its wall time (front end, compile, one synchronised run)."""


class _Watch:
    """The observers now watching and Taichi's own attributes that the wrappers replace."""

    observers: list[Observer] = []
    wrapped: list[tuple[type, str, object]] = []
    depth = 0  # element accesses under way (what one launches inside is part of it)

    @classmethod
    def tell(cls, name: str, *args) -> None:
        for observer in list(cls.observers):
            getattr(observer, name)(*args)

    @classmethod
    def wants(cls, name: str) -> bool:
        return any(getattr(type(o), name) is not getattr(Observer, name) for o in cls.observers)


def _wrap_launch(original):
    def launch_kernel(kernel, compiled, *args):
        waits = _Watch.depth == 0 and (kernel.return_type is not None or any(isinstance(a, np.ndarray) for a in args))
        _Watch.tell("launched", kernel.func.__qualname__, waits)
        return original(kernel, compiled, *args)

    return launch_kernel


def _wrap_direct(original):
    def direct(launcher, data, context):
        _Watch.tell("launched", launcher._name, False)
        return original(launcher, data, context)

    return direct


def _wrap_access(original, read: bool):
    def access(obj, *args):
        if _Watch.depth == 0:
            _Watch.tell("accessed", read)
        _Watch.depth += 1
        try:
            return original(obj, *args)
        finally:
            _Watch.depth -= 1

    return access


def _wrap_call(original):
    def call(kernel, *args, **kwargs):
        variants = len(kernel.compiled_kernels)
        began = time.perf_counter()
        result = original(kernel, *args, **kwargs)
        if len(kernel.compiled_kernels) > variants:
            ti.sync()
            _Watch.tell("compiled", kernel.func.__qualname__, time.perf_counter() - began)
        return result

    return call


def _rewrap() -> None:
    """Taichi's classes wrapped for what the observers now watching want, and only for that."""
    for cls, name, original in reversed(_Watch.wrapped):
        setattr(cls, name, original)
    _Watch.wrapped.clear()
    targets = []
    if _Watch.wants("launched"):
        targets += [(launch.Kernel, "launch_kernel", _wrap_launch), (launch.Launcher, "_launch", _wrap_direct)]
    if _Watch.wants("accessed"):
        for cls in (ti.ScalarField, ti.MatrixField, ti.ScalarNdarray, ti.VectorNdarray, ti.MatrixNdarray):
            targets.append((cls, "__getitem__", lambda f: _wrap_access(f, True)))
            targets.append((cls, "__setitem__", lambda f: _wrap_access(f, False)))
    if _Watch.wants("compiled"):
        targets.append((launch.Kernel, "__call__", _wrap_call))
    for cls, name, wrap in targets:
        original = cls.__dict__[name]
        _Watch.wrapped.append((cls, name, original))
        setattr(cls, name, wrap(original))


@contextlib.contextmanager
def watching(observer: Observer):
    """``observer`` told of what Taichi does while inside; observers nest. RuntimeError on another Taichi."""
    if not launch.knows_taichi():
        raise RuntimeError(
            f"watching Taichi's launches reads Taichi {'.'.join(map(str, launch.WRITTEN_FOR))}'s internals; "
            f"this is Taichi {'.'.join(map(str, ti.__version__))}"
        )
    _Watch.observers.append(observer)
    _rewrap()
    try:
        yield observer
    finally:
        _Watch.observers.remove(observer)
        _rewrap()


def watching_nothing() -> bool:
    """Whether Taichi's classes are as Taichi made them (no observer, no wrapper)."""
    return not _Watch.observers and not _Watch.wrapped


class TransferCounter(Observer):
    """Counts Taichi's kernel launches and device-to-host reads while active (a context manager).

    A device-to-host read is anything that makes the host wait for a result from the device: a kernel
    launch that returns a value or is given a NumPy array (``to_numpy``, ``from_numpy``), or an element
    of a field or ndarray read from Python (``field[None]``). A launch is every call of a ``@ti.kernel``,
    Taichi's own included; an element written from Python launches a small writer and counts as a
    launch. ``ti.sync()`` is neither."""

    def __init__(self):
        self.launches = 0
        self.reads = 0

    def launched(self, kernel: str, waits: bool) -> None:
        self.launches += 1
        self.reads += waits

    def accessed(self, read: bool) -> None:
        self.launches += 1
        self.reads += read

    def __enter__(self):
        self._watch = watching(self)
        return self._watch.__enter__()

    def __exit__(self, *exc):
        return self._watch.__exit__(*exc)


_COUNT_ROW = re.compile(r"^\[\s*[\d.]+%\s+[\d.]+ s\s+(\d+)x \|\s*[\d.]+\s+([\d.]+)\s+[\d.]+ ms\] (\S+)$")


def profiled_tasks() -> dict[str, tuple[int, float]]:
    """Task → (runs, total milliseconds) since the profiler was last cleared, from Taichi's public
    ``print_kernel_profiler_info("count")`` (read once per clear: the table adds up again each time)."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        ti.profiler.print_kernel_profiler_info("count")
    rows = filter(None, (_COUNT_ROW.match(line.strip()) for line in printed.getvalue().splitlines()))
    return {row.group(3): (int(row.group(1)), int(row.group(1)) * float(row.group(2))) for row in rows}


ITERATION_KERNELS = ("_iterations_kernel",)
"""The kernel whose tasks repeat with the iteration count (``SubstepKernels.iterate``); its last call of
a substep also holds lines 20-23, whose few tasks the column counts too."""


@dataclass(frozen=True)
class SubstepCounts:
    """Per-substep means over the counted substeps."""

    kernel_calls: float
    tasks: float
    serial_tasks: float
    iteration_tasks: float
    serial_iteration_tasks: float
    by_kernel: dict


def kernel_of(task: str) -> str:
    """The kernel a profiler record's task belongs to: ``iterate_c100_0_kernel_4_range_for`` → ``iterate``."""
    return task.split("_c", 1)[0] if "_c" in task else task


def count_substeps(sim, substeps: int, dt: float | None = None) -> SubstepCounts:
    """Run ``substeps`` substeps of ``sim`` and count what they launched (Taichi started with its kernel
    profiler on: ``start_backend(..., kernel_profiler=True)``, chosen at ``ti.init``)."""
    ti.sync()
    ti.profiler.clear_kernel_profiler_info()
    with TransferCounter() as counter:
        for _ in range(substeps):
            sim.substep(dt)
    ti.sync()
    runs = {task: count for task, (count, _) in profiled_tasks().items()}
    by_kernel = Counter()
    for task, count in runs.items():
        by_kernel[kernel_of(task)] += count
    iteration = {task: count for task, count in runs.items() if kernel_of(task) in ITERATION_KERNELS}
    return SubstepCounts(
        kernel_calls=counter.launches / substeps,
        tasks=sum(runs.values()) / substeps,
        serial_tasks=sum(c for t, c in runs.items() if t.endswith("_serial")) / substeps,
        iteration_tasks=sum(iteration.values()) / substeps,
        serial_iteration_tasks=sum(c for t, c in iteration.items() if t.endswith("_serial")) / substeps,
        by_kernel={name: count / substeps for name, count in sorted(by_kernel.items(), key=lambda kv: -kv[1])},
    )


def counts_table(rows: list[tuple[str, SubstepCounts]]) -> str:
    """The counts as a table, one row per case, then each case's tasks by kernel."""
    lines = [f"{'case':<34} {'kernel calls':>12} {'tasks':>7} {'serial':>7} {'in iterations':>14} {'serial there':>13}"]
    for name, c in rows:
        lines.append(
            f"{name:<34} {c.kernel_calls:>12.1f} {c.tasks:>7.1f} {c.serial_tasks:>7.1f} "
            f"{c.iteration_tasks:>14.1f} {c.serial_iteration_tasks:>13.1f}"
        )
    for name, c in rows:
        kernels = ", ".join(f"{kernel} {count:g}" for kernel, count in c.by_kernel.items())
        lines.append(f"  {name}: {kernels}")
    return "\n".join(lines)
