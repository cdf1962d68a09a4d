"""``benchmarks/registers.py`` without its tools: the occupancy sm_90's limits allow, the reading of
``ptxas -v``'s report (lines copied from ptxas 12.9 on the seed scene's PTX), the launch log's, and
the refusals that come before anything is built. Nothing here needs a C compiler, ptxas or CUDA."""

import importlib.util
import types
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"


@pytest.fixture(scope="module")
def registers():
    """benchmarks/registers.py imported as a module (the folder is not a package)."""
    spec = importlib.util.spec_from_file_location("benchmark_registers", BENCHMARKS / "registers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    "registers_used, block, shared, warps",
    [
        (72, 128, 0, 28),  # 2304 registers a warp: 28 warps' worth, 7 blocks of 4 warps
        (64, 128, 0, 32),  # 2048 a warp: 8 blocks
        (56, 128, 0, 36),  # 1792 a warp: 36 warps, 9 blocks
        (34, 128, 0, 48),  # 1088 rounds up to 1280 a warp: 51 warps' worth, 12 whole blocks
        (32, 128, 0, 64),  # the most: 64 warps
        (255, 128, 0, 8),  # 8160 rounds up to 8192: 8 warps, 2 blocks
        (25, 256, 2048, 64),  # Taichi's reductions: 2 kB a block, not a limit
        (32, 128, 48 * 1024, 16),  # 49 kB a block with the runtime's 1 kB: 4 blocks in 228 kB
        (32, 128, 100 * 1024, 8),  # 101 kB: 2 blocks
        (10, 1, 0, 32),  # a serial task: 32 blocks of one warp at most
        (20, 100, 0, 64),  # 100 threads take 4 warps
        (32, 1024, 0, 64),  # 2 blocks of 32 warps
        (33, 1024, 0, 32),  # 1280 a warp: 51 warps' worth, one whole block
        (65, 1024, 0, 0),  # 2304 a warp: 28 warps' worth, not one block of 32
    ],
)
def test_occupancy_on_sm_90(registers, registers_used, block, shared, warps):
    assert registers.occupancy(registers_used, block, shared) == warps / 64


def test_occupancy_of_the_briefs_examples(registers):
    assert registers.occupancy(72, 128) == 0.4375
    assert registers.occupancy(34, 128) == 0.75
    assert registers.occupancy(64, 128) == 0.5
    assert registers.occupancy(255, 128) == 0.125


@pytest.mark.parametrize("arguments", [(32, 0), (32, 1025), (256, 128), (-1, 128), (32, 128, -1)])
def test_occupancy_refuses_what_no_launch_has(registers, arguments):
    with pytest.raises(ValueError):
        registers.occupancy(*arguments)


ITERATE = """\
ptxas warning : Unresolved extern variable 'shared_array_17' in whole program compilation, ignoring extern qualifier
ptxas info    : 0 bytes gmem
ptxas info    : Compiling entry function '_iterate_c142_0_kernel_6_range_for' for 'sm_90'
ptxas info    : Function properties for _iterate_c142_0_kernel_6_range_for
    0 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads
ptxas info    : Used 25 registers, used 1 barriers, 2048 bytes smem
ptxas info    : Compile time = 10.346 ms
ptxas info    : Compiling entry function '_iterate_c142_0_kernel_5_range_for' for 'sm_90'
ptxas info    : Function properties for _iterate_c142_0_kernel_5_range_for
    40 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads
ptxas info    : Used 64 registers, used 0 barriers, 40 bytes cumulative stack size
ptxas info    : Compile time = 23.590 ms
ptxas info    : Function properties for function_body_$_5
    0 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads
ptxas info    : Compiling entry function '_iterate_c142_0_kernel_4_range_for' for 'sm_90'
ptxas info    : Function properties for _iterate_c142_0_kernel_4_range_for
    0 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads
ptxas info    : Used 34 registers, used 0 barriers
ptxas info    : Compile time = 7.896 ms
"""

# The same module with its .maxntid taken out and -maxrregcount=32: the task and the function it calls spill.
SPILLING = """\
ptxas info    : Overriding maximum register limit 256 for '_iterate_c142_0_kernel_5_range_for' with  32 of maxrregcount option
ptxas info    : 0 bytes gmem
ptxas info    : Compiling entry function '_iterate_c142_0_kernel_5_range_for' for 'sm_90'
ptxas info    : Function properties for _iterate_c142_0_kernel_5_range_for
    160 bytes stack frame, 20 bytes spill stores, 4 bytes spill loads
ptxas info    : Used 32 registers, used 0 barriers, 160 bytes cumulative stack size
ptxas info    : Compile time = 26.099 ms
ptxas info    : Function properties for function_body_$_5
    0 bytes stack frame, 164 bytes spill stores, 216 bytes spill loads
ptxas info    : Compiling entry function '_iterate_c142_0_kernel_4_range_for' for 'sm_90'
ptxas info    : Function properties for _iterate_c142_0_kernel_4_range_for
    0 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads
ptxas info    : Used 32 registers, used 0 barriers
ptxas info    : Compile time = 7.798 ms
"""  # noqa: E501


def test_ptxas_report_per_entry(registers):
    entries = registers.parse_ptxas(ITERATE)
    Compiled = registers.Compiled
    assert entries == {
        "_iterate_c142_0_kernel_6_range_for": Compiled(registers=25, shared=2048),
        "_iterate_c142_0_kernel_5_range_for": Compiled(registers=64, stack=40, calls=["function_body_$_5"]),
        "_iterate_c142_0_kernel_4_range_for": Compiled(registers=34),
    }


def test_ptxas_report_counts_the_called_functions_spills(registers):
    entries = registers.parse_ptxas(SPILLING)
    spilling = entries["_iterate_c142_0_kernel_5_range_for"]
    assert (spilling.registers, spilling.stack) == (32, 160)
    assert (spilling.spill_stores, spilling.spill_loads) == (20 + 164, 4 + 216)
    assert entries["_iterate_c142_0_kernel_4_range_for"] == registers.Compiled(registers=32)


def test_launch_log_gives_each_tasks_block(registers, tmp_path):
    log = tmp_path / "launches.log"
    log.write_text(
        "module 0000 runtime_initialize grid=1,1,1 block=1,1,1 shmem=0\n"
        "module 0032 _iterate_c142_0_kernel_3_range_for grid=1,1,1 block=256,1,1 shmem=0\n"
        "module 0032 _iterate_c142_0_kernel_0_range_for grid=128,1,1 block=128,1,1 shmem=0\n"
        "module 0032 _iterate_c142_0_kernel_0_range_for grid=128,1,1 block=128,1,1 shmem=0\n"
        "module 0032 _iterate_c142_0_kernel_0_range_for grid=8,1,1 block=64,1,1 shmem=0\n"
    )
    blocks = registers.launched_blocks(log)
    assert blocks[32, "_iterate_c142_0_kernel_3_range_for"] == [256]
    assert blocks[32, "_iterate_c142_0_kernel_0_range_for"] == [128, 64]  # the most launched first
    assert (33, "_iterate_c142_0_kernel_3_range_for") not in blocks


def test_kernel_names_drop_the_compile_counter_where_unambiguous(registers):
    def task(kernel):
        return registers.Task(1, f"{kernel}_kernel_0_serial", kernel, 0, "serial", registers.Compiled(), [])

    names = registers.display_names([task(k) for k in ("_iterate_c142_0", "_unsort_c102_0", "_unsort_c102_1")])
    assert names["_iterate_c142_0"] == "_iterate"
    assert (names["_unsort_c102_0"], names["_unsort_c102_1"]) == ("_unsort_c102_0", "_unsort_c102_1")


@pytest.fixture
def nothing_builds(registers, monkeypatch):
    """The stub's build and the simulation replaced by failures: a refusal must come before them."""

    def built(*args, **kwargs):
        raise AssertionError("built before the options were checked")

    monkeypatch.setattr(registers, "build_stub", built)
    monkeypatch.setattr(registers, "compile_kernels", built)


def refusal(registers, argv, capsys) -> str:
    with pytest.raises(SystemExit) as stop:
        registers.main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2, err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0] == err.strip().splitlines()[-1], err  # one line, argparse's last
    return errors[0]


def test_an_unknown_preset_is_refused_before_anything_is_built(registers, nothing_builds, tmp_path, capsys):
    kept = tmp_path / "kept"
    line = refusal(registers, ["--preset", "no_such_preset", "--keep", str(kept)], capsys)
    assert "no_such_preset: no such scene file" in line
    assert not kept.exists()


def test_a_bad_override_is_refused(registers, nothing_builds, capsys):
    assert "unknown key 'solver.nonsense'" in refusal(registers, ["--set", "solver.nonsense=1"], capsys)


def test_a_folder_with_files_is_never_kept_into(registers, nothing_builds, tmp_path, capsys):
    (tmp_path / "mine.txt").write_text("the user's")
    assert "exists and is not an empty folder" in refusal(registers, ["--keep", str(tmp_path)], capsys)
    assert [path.name for path in tmp_path.iterdir()] == ["mine.txt"]


def test_missing_tools_say_what_to_install(registers, nothing_builds, monkeypatch, capsys):
    monkeypatch.setattr(registers, "shutil", types.SimpleNamespace(which=lambda name: None))
    monkeypatch.setattr(registers, "pip_ptxas", lambda: None)
    assert "apt-get install gcc" in refusal(registers, [], capsys)
    only_cc = types.SimpleNamespace(which=lambda name: "/bin/cc" if name == "cc" else None)
    monkeypatch.setattr(registers, "shutil", only_cc)
    assert "pip install nvidia-cuda-nvcc-cu12" in refusal(registers, [], capsys)
