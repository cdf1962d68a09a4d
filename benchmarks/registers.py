"""Registers, spills, stack, shared memory and occupancy of the simulator's CUDA tasks on sm_90, without a GPU.

    python benchmarks/registers.py
    python benchmarks/registers.py --preset dam_break_large --set solver.iterations=4
    python benchmarks/registers.py --ptxas ~/nvcc/bin/ptxas --keep registers-run --all

A fake CUDA driver (``benchmarks/cuda_stub.c``, built here with the C compiler) stands in for
libcuda in a child Python: Taichi's CUDA backend starts on it as on an NVIDIA H200, the preset's
Simulation is built and steps 2 frames, so that every kernel of a substep compiles. The stub keeps
each PTX module Taichi loads and logs each launch (launches run nothing). Each module then goes
through NVIDIA's ``ptxas -arch=sm_90 -v``: Taichi 1.7.4 emits PTX for sm_86 at most (its
``.target``), and the driver JIT-compiles that PTX for the card it runs on, which is what ptxas for
sm_90 reproduces here (Taichi passes the driver no JIT options, so both compile with ptxas's
defaults). The driver's JIT is the ptxas of the driver's CUDA release; another release may allocate
a few registers more or fewer, so compare tables made with the same ptxas.

Per task (Taichi's offloaded loop, one CUDA kernel each), in the order the kernels were loaded:

* registers: ptxas compiles the whole module, so the count of a task that calls a non-inlined
  function (Taichi's ``function_body`` of some loops) covers the function too: it is the count the
  cubin records (EIATTR_REGCOUNT) and every launch allocates;
* spill stores and loads (bytes a thread), the task's and its called functions';
* stack: the task's frame and the deepest chain of the functions it calls (bytes a thread);
* shared memory a block (Taichi's reductions use 2 kB);
* block: the threads a block of its launches had ("-": not launched in those frames; a serial
  task's block is 1 thread, a warp of its own);
* occupancy: the warps resident on an SM as a share of the 64 it holds, as the registers, the block
  and the shared memory allow (``occupancy()``; sm_90's limits, so only for sm_90 and sm_90a).

Taichi's runtime module and the one-element field readers and writers (``snode_reader_N``,
``snode_writer_N``) are left out unless ``--all``.

Needs a C compiler (``cc`` or ``gcc``) and ptxas: ``--ptxas PATH``, else ``ptxas`` on PATH, else the
one of the ``nvidia-cuda-nvcc-cu12`` package where this Python has it (the package installs anywhere
with pip, no GPU needed). Nothing is written outside a temporary folder, removed at the end, or
``--keep DIR`` (a new or empty folder, kept: the stub, ``ptx/``, ``launches.log``, ptxas's reports):
Taichi's offline cache is a fresh folder in it, so every kernel compiles and the user's cache is
neither read nor written.
"""

import argparse
import collections
import dataclasses
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from pbf.scene import SceneError, load_scene

ROOT = Path(__file__).resolve().parent.parent
STUB = Path(__file__).resolve().parent / "cuda_stub.c"
FRAMES = 2
"""Frames the child steps: every kernel they run compiles (kernels that only some frames run may not)."""
CHILD_TIMEOUT_S = 1800
NOT_ON_CUDA = 3
"""The child's exit status where Taichi did not start on the stub driver."""

WARP = 32
REGISTERS_PER_SM = 65536
"""sm_90 (H100, H200): 64 Ki 32-bit registers an SM, the most a block may hold too."""
REGISTER_UNIT = 256
"""Registers are allocated to a warp in units of 256 (8 a thread)."""
WARPS_PER_SM = 64
"""2048 threads resident an SM at most."""
BLOCKS_PER_SM = 32
"""Blocks resident an SM at most, however small."""
SHARED_PER_SM = 228 * 1024
"""Shared memory an SM (bytes), the whole of the L1/shared carve-out."""
SHARED_RESERVED_PER_BLOCK = 1024
"""Shared memory the CUDA runtime reserves to each block on sm_80 and later (bytes)."""
SHARED_UNIT = 128
"""Shared memory is allocated to a block in units of 128 bytes."""
MAX_BLOCK = 1024
"""Threads a block at most."""
OCCUPANCY_ARCHES = ("sm_90", "sm_90a")
"""The targets whose limits the constants above are."""

CHILD = f"""
import sys

import taichi as ti

from pbf import Simulation
from pbf.scene import load_scene
from pbf.solver import BackendError, start_backend

try:
    start_backend("cuda", quiet=True)
except BackendError as error:
    print(f"Taichi did not start on the fake CUDA driver (it was not loaded): {{error}}", file=sys.stderr)
    sys.exit({NOT_ON_CUDA})
if ti.cfg.arch != ti.cuda:
    print("Taichi runs on the CPU, not on the fake CUDA driver: it was not loaded", file=sys.stderr)
    sys.exit({NOT_ON_CUDA})
Simulation(load_scene(sys.argv[1], sys.argv[2:]), quiet=True).step({FRAMES})
ti.sync()
"""

PTX_ENTRY = re.compile(r"^\s*(?:\.visible\s+|\.weak\s+)?\.entry\s+([\w$.]+)\s*\(", re.M)
PTX_VERSION = re.compile(r"^\s*\.version\s+(\S+)", re.M)
PTX_TARGET = re.compile(r"^\s*\.target\s+([^\s,]+)", re.M)
TASK = re.compile(r"^(?P<kernel>.+)_kernel_(?P<index>\d+)_(?P<type>[a-z_]+)$")
"""Taichi's name of an offloaded task: its kernel's name, the task's index in it, the task's type."""
COUNTER = re.compile(r"_c\d+_\d+$")
"""Taichi's suffix to a kernel's Python name: its compile counter and instantiation."""
ACCESSOR = re.compile(r"^snode_(?:reader|writer)_\d+$")
LAUNCH = re.compile(r"^module (\d+) (\S+) grid=\d+,\d+,\d+ block=(\d+),(\d+),(\d+)")

ENTRY = re.compile(r"Compiling entry function '([^']+)'")
PROPERTIES = re.compile(r"Function properties for (\S+)")
FRAME = re.compile(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads")
USED = re.compile(r"Used (\d+) registers")
SMEM = re.compile(r"(\d+) bytes smem")
CUMULATIVE = re.compile(r"(\d+) bytes cumulative stack size")


def occupancy(registers: int, block: int, shared_bytes: int = 0) -> float:
    """The share of an sm_90 SM's 64 warps resident when each thread of a ``block``-thread block uses
    ``registers`` registers and each block ``shared_bytes`` of shared memory: whole blocks, as many as
    the registers (allocated a warp at a time in units of REGISTER_UNIT), the shared memory (with the
    runtime's reserve, in units of SHARED_UNIT), the warps and the blocks an SM holds allow. 0 where
    one block does not fit."""
    if not 1 <= block <= MAX_BLOCK:
        raise ValueError(f"block: {block} threads; 1 to {MAX_BLOCK}")
    if not 0 <= registers <= 255 or shared_bytes < 0:
        raise ValueError(f"registers {registers}, shared memory {shared_bytes} B: 0 to 255, 0 or more")
    warps = -(-block // WARP)
    per_warp = -(-registers * WARP // REGISTER_UNIT) * REGISTER_UNIT
    by_registers = REGISTERS_PER_SM // per_warp // warps if per_warp else BLOCKS_PER_SM
    per_block = -(-(shared_bytes + SHARED_RESERVED_PER_BLOCK) // SHARED_UNIT) * SHARED_UNIT
    blocks = min(BLOCKS_PER_SM, WARPS_PER_SM // warps, by_registers, SHARED_PER_SM // per_block)
    return blocks * warps / WARPS_PER_SM


@dataclasses.dataclass
class Compiled:
    """What ptxas reports of one entry function (a task), with the functions it calls."""

    registers: int = 0
    spill_stores: int = 0
    spill_loads: int = 0
    stack: int = 0
    shared: int = 0
    calls: list[str] = dataclasses.field(default_factory=list)


def parse_ptxas(text: str) -> dict[str, Compiled]:
    """``ptxas -v``'s report of one module, by entry function. The properties of a function an entry
    calls follow the entry's own; its spills count to the entry's, its frame is in the entry's
    cumulative stack size, and its registers in the entry's count (whole-module compilation)."""
    entries: dict[str, Compiled] = {}
    entry, described = None, None
    for line in text.splitlines():
        if found := ENTRY.search(line):
            entry = found.group(1)
            entries[entry] = Compiled()
            described = None
        elif entry is None:
            continue
        elif found := PROPERTIES.search(line):
            described = found.group(1)
            if described != entry:
                entries[entry].calls.append(described)
        elif found := FRAME.search(line):
            compiled = entries[entry]
            stack, stores, loads = map(int, found.groups())
            compiled.spill_stores += stores
            compiled.spill_loads += loads
            if described == entry:
                compiled.stack = max(compiled.stack, stack)
        elif found := USED.search(line):
            compiled = entries[entry]
            compiled.registers = int(found.group(1))
            if shared := SMEM.search(line):
                compiled.shared = int(shared.group(1))
            if cumulative := CUMULATIVE.search(line):
                compiled.stack = max(compiled.stack, int(cumulative.group(1)))
    return entries


@dataclasses.dataclass
class Task:
    module: int
    entry: str
    kernel: str
    index: int | None  # None: an entry of Taichi's runtime module
    type: str
    compiled: Compiled
    blocks: list[int]  # the block sizes of its launches, the most launched first


def launched_blocks(log: Path) -> dict[tuple[int, str], list[int]]:
    """The stub's launch log: (module, entry) -> the threads a block of its launches, most launched first."""
    counts: dict[tuple[int, str], collections.Counter] = collections.defaultdict(collections.Counter)
    if log.exists():
        for line in log.read_text().splitlines():
            if found := LAUNCH.match(line):
                x, y, z = (int(found.group(k)) for k in (3, 4, 5))
                counts[int(found.group(1)), found.group(2)][x * y * z] += 1
    return {key: [block for block, _ in counter.most_common()] for key, counter in counts.items()}


def pip_ptxas() -> Path | None:
    """The ptxas of the nvidia-cuda-nvcc-cu12 package, where this Python has it."""
    try:
        spec = importlib.util.find_spec("nvidia.cuda_nvcc")
    except (ImportError, ValueError):
        return None
    for folder in (spec.submodule_search_locations or []) if spec else []:
        candidate = Path(folder) / "bin" / "ptxas"
        if candidate.is_file():
            return candidate
    return None


def find_ptxas(given: str | None) -> Path | None:
    """``given``, else ptxas on PATH, else :func:`pip_ptxas`."""
    if given:
        return Path(given)
    on_path = shutil.which("ptxas")
    return Path(on_path) if on_path else pip_ptxas()


def ptxas_version(ptxas: Path) -> str:
    done = subprocess.run([str(ptxas), "--version"], capture_output=True, text=True)
    found = re.search(r"release (\S+), (V\S+)", done.stdout)
    if done.returncode or not found:
        raise RuntimeError(f"{ptxas} --version: {(done.stdout + done.stderr).strip() or 'no output'}")
    return f"{found.group(1)} ({found.group(2)})"


def build_stub(compiler: str, folder: Path) -> Path:
    """The stub built into ``folder``/driver as libcuda.so.1 and libcuda.so (the name Taichi opens)."""
    driver = folder / "driver"
    driver.mkdir()
    library = driver / "libcuda.so.1"
    command = [compiler, "-O2", "-shared", "-fPIC", "-Wl,-soname,libcuda.so.1", "-o", str(library), str(STUB)]
    env = dict(os.environ, TMPDIR=str(folder / "tmp"))  # the compiler's temporary files
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    if done.returncode:
        errors = [line for line in done.stderr.splitlines() if "error" in line] or done.stderr.splitlines()
        raise RuntimeError(f"{compiler} could not build {STUB.name}: {(errors or ['no output'])[0]}")
    (driver / "libcuda.so").symlink_to("libcuda.so.1")
    return driver


def compile_kernels(folder: Path, driver: Path, preset: str, overrides: list[str]) -> None:
    """The child Python on the stub: every kernel of the preset's first frames compiled to PTX in ``folder``/ptx."""
    env = dict(os.environ)
    env.pop("TI_ENABLE_CUDA", None)
    env.update(
        CUDASTUB_DIR=str(folder),
        LD_LIBRARY_PATH=os.pathsep.join(filter(None, [str(driver), os.environ.get("LD_LIBRARY_PATH")])),
        PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        PYTHONDONTWRITEBYTECODE="1",
        TI_OFFLINE_CACHE_FILE_PATH=str(folder / "ticache"),
        TI_SKIP_VERSION_CHECK="ON",  # Taichi's check writes ~/.cache/taichi/version_info
        TMPDIR=str(folder / "tmp"),
    )
    command = [sys.executable, "-c", CHILD, preset, *overrides]
    try:
        done = subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True, timeout=CHILD_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"the simulation on the fake CUDA driver ran over {CHILD_TIMEOUT_S} s") from None
    (folder / "simulation.log").write_text(done.stdout + done.stderr)
    last = (done.stderr.strip().splitlines() or ["no output"])[-1]
    if done.returncode == NOT_ON_CUDA:
        raise RuntimeError(last)
    if done.returncode:
        sys.stderr.write(done.stderr[-4000:])
        raise RuntimeError(f"the simulation failed on the fake CUDA driver (exit status {done.returncode}): {last}")


def compile_ptx(ptxas: Path, arch: str, folder: Path, everything: bool) -> tuple[list[Task], dict]:
    """ptxas on each captured module (the runtime's only with ``everything``): its tasks, and what was read."""
    modules = sorted((folder / "ptx").glob("module_*.ptx"))
    if not modules:
        raise RuntimeError("no PTX captured: Taichi did not load its kernels through the fake CUDA driver")
    blocks = launched_blocks(folder / "launches.log")
    (folder / "ptxas").mkdir()
    tasks, seen = [], {"modules": len(modules), "versions": set(), "targets": set(), "runtime": 0, "accessors": 0}
    for path in modules:
        module = int(path.stem.split("_")[1])
        source = path.read_text()
        seen["versions"].update(PTX_VERSION.findall(source))
        seen["targets"].update(PTX_TARGET.findall(source))
        tasks_named = [TASK.match(name) for name in PTX_ENTRY.findall(source)]
        runtime = not any(tasks_named)
        accessor = not runtime and all(task and ACCESSOR.match(task["kernel"]) for task in tasks_named)
        seen["runtime"] += runtime
        seen["accessors"] += accessor
        if not everything and (runtime or accessor):
            continue
        done = subprocess.run(
            [str(ptxas), f"-arch={arch}", "-v", "-o", os.devnull, path.name],
            cwd=path.parent,
            capture_output=True,
            text=True,
        )
        (folder / "ptxas" / f"{path.stem}.txt").write_text(done.stdout + done.stderr)
        if done.returncode:
            errors = [line for line in done.stderr.splitlines() if "error" in line] or done.stderr.splitlines()
            raise RuntimeError(f"ptxas -arch={arch} failed on {path.name}: {(errors or ['no output'])[0]}")
        for name, compiled in parse_ptxas(done.stdout + done.stderr).items():
            launched = blocks.get((module, name), [])
            if task := TASK.match(name):
                tasks.append(Task(module, name, task["kernel"], int(task["index"]), task["type"], compiled, launched))
            else:
                tasks.append(Task(module, name, name, None, "runtime", compiled, launched))
    tasks.sort(key=lambda t: (t.module, -1 if t.index is None else t.index, t.entry))
    return tasks, seen


def display_names(tasks: list[Task]) -> dict[str, str]:
    """Each kernel's name without Taichi's ``_cNNN_N`` suffix, where no other kernel listed shares it."""
    full = collections.defaultdict(set)
    for task in tasks:
        full[COUNTER.sub("", task.kernel)].add(task.kernel)
    return {kernel: short if len(kernels) == 1 else kernel for short, kernels in full.items() for kernel in kernels}


def table(tasks: list[Task], with_occupancy: bool) -> list[str]:
    names = display_names(tasks)
    header = ["kernel", "task", "type", "registers", "spill st/ld B", "stack B", "smem B", "block"]
    header += ["warps/SM", "occupancy"] if with_occupancy else []
    rows = []
    for task in tasks:
        c = task.compiled
        row = [names[task.kernel], "-" if task.index is None else str(task.index), task.type, str(c.registers)]
        row += [f"{c.spill_stores}/{c.spill_loads}", str(c.stack), str(c.shared)]
        row.append("/".join(map(str, task.blocks)) or "-")
        if with_occupancy:
            shares = [occupancy(c.registers, block, c.shared) for block in task.blocks]
            row.append("/".join(str(round(share * WARPS_PER_SM)) for share in shares) or "-")
            row.append("/".join(f"{share * 100:.2f}%" for share in shares) or "-")
        rows.append(row)
    widths = [max(len(row[k]) for row in [header, *rows]) for k in range(len(header))]
    lines = []
    for row in [header, *rows]:
        cells = [row[0].ljust(widths[0]), *(cell.rjust(width) for cell, width in zip(row[1:], widths[1:]))]
        lines.append("  ".join(cells).rstrip())
    return lines


def run(args, compiler: str, ptxas: Path, folder: Path) -> None:
    version = ptxas_version(ptxas)
    (folder / "tmp").mkdir()  # TMPDIR of the compiler and the child
    driver = build_stub(compiler, folder)
    compile_kernels(folder, driver, args.preset, args.set)
    tasks, seen = compile_ptx(ptxas, args.arch, folder, args.all)
    named = args.preset + "".join(f" --set {item}" for item in args.set)
    kernels = len({task.kernel for task in tasks if task.index is not None})
    print(f"{named}: {len(tasks)} tasks of {kernels} kernels, compiled by Taichi on the fake driver in {FRAMES} frames")
    print(
        f"PTX .version {', '.join(sorted(seen['versions']))}, .target {', '.join(sorted(seen['targets']))} "
        f"({seen['modules']} modules), compiled by ptxas {version} -arch={args.arch} as the driver's JIT would"
    )
    with_occupancy = args.arch in OCCUPANCY_ARCHES
    if with_occupancy:
        print(
            f"occupancy: warps resident an SM of its {WARPS_PER_SM}, as the registers ({REGISTERS_PER_SM:,} an SM), "
            f"the block and the shared memory ({SHARED_PER_SM // 1024} kB an SM) allow"
        )
    else:
        print(f"occupancy: not shown; its limits are those of {' and '.join(OCCUPANCY_ARCHES)}")
    print()
    print("\n".join(table(tasks, with_occupancy)))
    if not args.all and (seen["runtime"] or seen["accessors"]):
        print(
            f"\nnot listed (--all lists them): Taichi's runtime module (loaded {seen['runtime']} times) and "
            f"{seen['accessors']} snode reader/writer kernels"
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="dam_break", help="the scene whose kernels to compile (default: dam_break)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a key of the preset, as run.py's --set (repeatable)",
    )
    parser.add_argument("--ptxas", default=None, metavar="PATH", help="NVIDIA's ptxas (default: on PATH, else pip's)")
    parser.add_argument("--arch", default="sm_90", help="ptxas's target (default: sm_90, the H100's and H200's)")
    parser.add_argument("--keep", default=None, metavar="DIR", help="work in DIR (new or empty) and keep it")
    parser.add_argument("--all", action="store_true", help="list the runtime module's and the field accessors' too")
    args = parser.parse_args(argv)
    if not re.fullmatch(r"sm_\d+[a-z]?", args.arch):
        parser.error(f"--arch {args.arch}: expected a ptxas target such as sm_90")
    keep = Path(args.keep) if args.keep else None
    if keep is not None and keep.exists() and not (keep.is_dir() and not any(keep.iterdir())):
        parser.error(f"--keep {keep}: exists and is not an empty folder; give a new or empty one")
    try:  # before anything is built
        load_scene(args.preset, args.set)
    except SceneError as error:
        parser.error(str(error))
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        parser.error("no C compiler (cc or gcc) on PATH to build the fake CUDA driver: apt-get install gcc")
    ptxas = find_ptxas(args.ptxas)
    if ptxas is None:
        parser.error(
            "no ptxas on PATH nor in this Python: pip install nvidia-cuda-nvcc-cu12 (in any environment), then "
            "--ptxas <its site-packages>/nvidia/cuda_nvcc/bin/ptxas"
        )
    if not (ptxas.is_file() and os.access(ptxas, os.X_OK)):
        parser.error(f"--ptxas {ptxas}: not an executable file")
    try:
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            run(args, compiler, ptxas, keep.resolve())
        else:
            with tempfile.TemporaryDirectory(prefix="pbf-registers-") as folder:
                run(args, compiler, ptxas, Path(folder))
    except RuntimeError as error:
        parser.exit(1, f"{parser.prog}: error: {error}\n")


if __name__ == "__main__":
    main()
