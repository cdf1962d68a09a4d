"""The launches of a substep, counted by Taichi's kernel profiler (``python -m benchmarks.bench counts``).

On a GPU every offloaded task is a launch of its own, so at small particle counts the count sets the
cost of a substep; a change that adds kernels or one-thread tasks fails here. The ceilings are the
counts of today's solver (docs/BENCHMARKS.md, "Launches per substep"): lower them as the substep is
fused, never raise them without a measurement that says why.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

CEILINGS = {
    # case: (Python kernel calls, offloaded tasks, serial tasks, tasks in the iterations' kernel)
    "8,000, 4 iterations": (6, 24, 6, 16),
    "8,000, 4 its., device decisions": (3, 18, 0, 11),
}
"""At 4 fixed iterations: the CPU's choices (an iteration a call) and a GPU's (four a call, every loop
over the bucket). With a GPU's choices no task is a one-thread task; on the CPU one costs next to
nothing (a loop's bound read at run time). The iterations' kernel holds the end too, compiled in
instead of the iterations for a call of its own (so that an iteration's code compiles once: the CPU's
choices went from 5 calls to 6 for a shorter cold start)."""


def bench_counts(*options) -> dict:
    """The table of ``bench counts`` by case, from a process of its own (the profiler is chosen at
    ``ti.init``, and this suite's runtime runs without it)."""
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench", "counts", "--arch", "cpu", "--threads", "1", *options],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=Path(__file__).resolve().parent.parent,  # the checkout: the lab runs from it
    )
    assert done.returncode == 0, done.stderr
    rows = {}
    for line in done.stdout.splitlines():
        match = re.match(r"(\S.*?)\s{2,}([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)$", line)
        if match:
            rows[match.group(1)] = tuple(float(value) for value in match.groups()[1:])
    return rows


@pytest.fixture(scope="module")
def counts() -> dict:
    return bench_counts()


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CEILINGS))
def test_substep_launches_stay_within_todays_counts(counts, case):
    calls, tasks, serial, iteration, _ = counts[case]
    most_calls, most_tasks, most_serial, most_iteration = CEILINGS[case]
    assert calls <= most_calls, f"{case}: {calls} kernel calls per substep, at most {most_calls}"
    assert tasks <= most_tasks, f"{case}: {tasks} offloaded tasks per substep, at most {most_tasks}"
    assert serial <= most_serial, f"{case}: {serial} serial tasks per substep, at most {most_serial}"
    assert iteration <= most_iteration, f"{case}: {iteration} tasks in the iterations, at most {most_iteration}"


@pytest.mark.slow
def test_the_device_path_launches_no_one_thread_task(counts):
    """On a GPU a one-thread task is a launch that does next to nothing: none in a substep, none in the
    iterations, on the path the GPU backends take."""
    calls, tasks, serial, iteration, serial_there = counts["8,000, 4 its., device decisions"]
    assert serial == 0 and serial_there == 0, (serial, serial_there)


@pytest.mark.slow
def test_the_iterations_repeat_per_iteration(counts):
    """The tasks of the iterations' kernel grow by one iteration's with each iteration: 8 iterations launch
    4 times one iteration's tasks more than 4 (a miscount of the profiler's records would break this)."""
    _, _, _, four, _ = counts["8,000, 4 iterations"]
    _, _, _, eight, _ = bench_counts("--iterations", "8")["8,000, 8 iterations"]
    assert eight > four and (eight - four) % 4 == 0, (four, eight)


@pytest.mark.slow
def test_the_counts_see_every_kernel_call(counts):
    """The calls a substep makes at 4 iterations, counted through Taichi's call and the Launcher's direct
    launches alike (``benchmarks.instruments.TransferCounter``): with the CPU's choices lines 1-7, one call an
    iteration, then lines 20-23; with a GPU's lines 1-7, iterations 1-4, then lines 20-23."""
    assert counts["8,000, 4 iterations"][0] == 6
    assert counts["8,000, 4 its., device decisions"][0] == 3


@pytest.mark.slow
def test_a_gpus_blocks_add_few_launches():
    """With a GPU's blocks of 32 the prefix sums have more levels, each a pass up and a launch (the pass
    down is one whatever the levels, and the top level holds up to 512 block sums): 19 tasks a substep
    at 4 iterations with a GPU's choices, one more than the CPU's blocks, and still no one-thread task."""
    calls, tasks, serial, iteration, _ = bench_counts("--gpu-blocks")["8,000, 4 its., device decisions"]
    assert (calls, serial, iteration) == (3, 0, 11)
    assert tasks <= 19, f"{tasks} offloaded tasks per substep in a GPU's blocks, at most 19"


@pytest.mark.slow
def test_the_divergence_pass_adds_no_call():
    """The divergence pre-correction runs in the call of lines 1-7, its loops over the particles' bucket:
    still 3 calls and no one-thread task with a GPU's choices."""
    calls, tasks, serial, _, _ = bench_counts("--set", "solver.divergence_iterations=1")[
        "8,000, 4 its., device decisions"
    ]
    assert (calls, serial) == (3, 0)
    assert tasks <= 23, f"{tasks} offloaded tasks per substep with the divergence pass, at most 23"


@pytest.mark.slow
def test_moving_boundaries_add_few_calls_and_no_one_thread_task():
    """With a GPU's choices a scene with rigid bodies adds two calls a substep, the rigid step (one thread
    over the few bodies: their motion, contacts and collision distances) and the water's reaction, and
    no one-thread task that reads a count for a loop's bound: ``floating_boxes`` makes the 5 calls of its
    10 iterations' substep and these 2, its tasks with the stopping rule's after each iteration's error sum
    (``JacobiIterations.decide``). Its iterations, four a call, launch 12, the last two over no particles
    (10 tasks more than at two a call, one call fewer). The wave maker's piston is placed by a call of
    its own, one thread (``wave_tank``: 6 calls)."""
    rows = bench_counts("--presets", "floating_boxes", "wave_tank")
    calls, tasks, serial, _, _ = rows["floating_boxes, device decisions"]
    assert (calls, serial) == (7, 0), (calls, serial)
    assert tasks <= 73, f"{tasks} offloaded tasks per substep, at most 73"
    calls, tasks, serial, _, _ = rows["wave_tank, device decisions"]
    assert (calls, serial) == (6, 1), (calls, serial)
