"""What a substep asks of the device: Python kernel calls and offloaded tasks, counted.

    python -m pbf.study.bench counts [--sizes 8000] [--iterations 4] [--arch cpu]

A Python kernel call is one call of a ``@ti.kernel`` (Taichi's own ``fill`` and copies included).
Taichi splits each kernel into offloaded tasks: every top-level loop is one, and every run of
statements outside loops is one more, a one-thread ``serial`` task. On a GPU each task is a launch
of its own, however little it does, so at 8,000 particles the count, not the work, sets the cost of
a substep. Taichi's kernel profiler lists every task it ran, on the CPU
backend as on CUDA, so the counts measured here are the GPU's.

The tasks are split by where they run: inside the Jacobi iterations (Algorithm 1, lines 8-19: they
repeat with the iteration count) or once per substep, and serial or parallel.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

ITERATION_KERNELS = ("_iterations_kernel",)
"""The kernel whose tasks repeat with the iteration count (``SubstepKernels.iterate``); its last call
of a substep also holds lines 20-23 (``SubstepKernels.iterate_and_finish``), whose few tasks the
column counts too."""


@dataclass(frozen=True)
class SubstepCounts:
    """Per-substep means over the counted substeps."""

    kernel_calls: float
    tasks: float
    serial_tasks: float
    iteration_tasks: float
    serial_iteration_tasks: float
    by_kernel: dict
    """Kernel name → tasks per substep."""


def kernel_of(task: str) -> str:
    """The kernel a profiler record's task belongs to: ``iterate_c100_0_kernel_4_range_for`` → ``iterate``."""
    return task.split("_c", 1)[0] if "_c" in task else task


def count_substeps(sim, substeps: int, dt: float | None = None) -> SubstepCounts:
    """Run ``substeps`` substeps of ``sim`` and count what they launched. Taichi must have been started
    with its kernel profiler (``start_backend(kernel_profiler=True)``)."""
    import taichi as ti

    from pbf.solver.launch import profiled_tasks
    from pbf.study.common import TransferCounter

    ti.sync()
    ti.profiler.clear_kernel_profiler_info()
    with TransferCounter() as counter:
        for _ in range(substeps):
            sim.substep(dt)
    ti.sync()
    tasks = [task for task, _ in profiled_tasks()]  # every task since the clear
    serial = [task for task in tasks if task.endswith("_serial")]
    iteration = [task for task in tasks if kernel_of(task) in ITERATION_KERNELS]
    by_kernel = Counter(kernel_of(task) for task in tasks)
    return SubstepCounts(
        kernel_calls=counter.launches / substeps,
        tasks=len(tasks) / substeps,
        serial_tasks=len(serial) / substeps,
        iteration_tasks=len(iteration) / substeps,
        serial_iteration_tasks=sum(task.endswith("_serial") for task in iteration) / substeps,
        by_kernel={name: count / substeps for name, count in sorted(by_kernel.items(), key=lambda kv: -kv[1])},
    )


def table(rows: list[tuple[str, SubstepCounts]]) -> str:
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
