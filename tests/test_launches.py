"""The launches of a substep, counted by Taichi's kernel profiler (``python -m pbf.study.bench counts``).

On a GPU every offloaded task is a launch of its own, so at small particle counts the count sets the
cost of a substep; a change that adds kernels or one-thread tasks fails here. The ceilings are the
counts of today's solver (docs/BENCHMARKS.md, "Launches per substep"): lower them as the substep is
fused, never raise them without a measurement that says why.
"""

import re
import subprocess
import sys

import pytest

CEILINGS = {
    # case: (Python kernel calls, offloaded tasks, serial tasks, tasks inside the iterations)
    "8,000, 4 iterations": (6, 34, 15, 24),
    "8,000, 4 its., device decisions": (3, 15, 0, 4),
}
"""At 4 fixed iterations: the host's decisions (the CPU path) and the device's (GPU backends). On the
device path no task is a one-thread task (``pbf.solver.substep``); on the CPU one costs next to nothing,
and the host's iterations return their error through some."""


def bench_counts(*options) -> dict:
    """The table of ``bench counts`` by case, from a process of its own (the profiler is chosen at
    ``ti.init``, and this suite's runtime runs without it)."""
    done = subprocess.run(
        [sys.executable, "-m", "pbf.study.bench", "counts", "--arch", "cpu", "--threads", "1", *options],
        capture_output=True,
        text=True,
        timeout=600,
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
    """The count inside the iterations is per iteration: 4 iterations launch 4 times one iteration's
    tasks (a miscount of the profiler's records would break this first)."""
    _, _, _, iteration, serial_there = counts["8,000, 4 iterations"]
    assert iteration % 4 == 0 and serial_there % 4 == 0, (iteration, serial_there)


@pytest.mark.slow
def test_the_counts_see_every_kernel_call(counts):
    """The calls a substep makes at 4 iterations, counted through Taichi's call and the Launcher's direct
    launches alike (``pbf.study.common.TransferCounter``): on the host's decisions lines 1-7, one call an
    iteration and lines 20-23; on the device's lines 1-7, iterations 1-2, and iterations 3-4 with lines
    20-23. A count that missed the direct launches read 5 and 0."""
    assert counts["8,000, 4 iterations"][0] == 6
    assert counts["8,000, 4 its., device decisions"][0] == 3


@pytest.mark.slow
def test_a_gpus_blocks_add_few_launches():
    """With a GPU's blocks of 32 the prefix sums have more levels, each a pass up and a launch (the pass
    down is one whatever the levels, and the top level holds up to 512 block sums): 16 tasks a substep
    at 4 iterations on the device path, one more than the CPU's blocks, and still no one-thread task."""
    calls, tasks, serial, iteration, _ = bench_counts("--gpu-blocks")["8,000, 4 its., device decisions"]
    assert (calls, serial, iteration) == (3, 0, 4)
    assert tasks <= 16, f"{tasks} offloaded tasks per substep in a GPU's blocks, at most 16"


@pytest.mark.slow
def test_the_divergence_pass_adds_no_call_on_the_device_path():
    """The divergence pre-correction runs in the call of lines 1-7 on the device path, its loops over the
    particles' bucket: still 3 calls and no one-thread task (it took 4 calls more and 3 such tasks)."""
    calls, tasks, serial, _, _ = bench_counts("--set", "solver.divergence_iterations=1")[
        "8,000, 4 its., device decisions"
    ]
    assert (calls, serial) == (3, 0)
    assert tasks <= 22, f"{tasks} offloaded tasks per substep with the divergence pass, at most 22"


@pytest.mark.slow
def test_moving_boundaries_add_few_calls_and_no_one_thread_task():
    """On the device path a scene with rigid bodies adds two calls a substep, the rigid step (one thread
    over the few bodies: their motion, contacts and collision distances) and the water's reaction, and
    no one-thread task that reads a count for a loop's bound: ``floating_boxes`` makes the 6 calls of its
    10 iterations' substep and these 2 (the rigid step alone took 3 calls and 5 tasks, 2 of them such).
    The wave maker adds no call: the substep's first launch places the piston (``wave_tank``: 6 calls,
    one one-thread task, where a call of its own made 7)."""
    rows = bench_counts("--presets", "floating_boxes", "wave_tank")
    calls, tasks, serial, _, _ = rows["floating_boxes, device decisions"]
    assert (calls, serial) == (8, 0), (calls, serial)
    assert tasks <= 51, f"{tasks} offloaded tasks per substep, at most 51"
    assert rows["floating_boxes"][0] <= 15, rows["floating_boxes"]
    calls, tasks, serial, _, _ = rows["wave_tank, device decisions"]
    assert (calls, serial) == (6, 1), (calls, serial)
    assert rows["wave_tank"][0] <= 14, rows["wave_tank"]
