"""Taichi's private names are read in one module, ``pbf/solver/launch.py``, gated on the Taichi version
it was written for: another Taichi then changes that file's behaviour and nothing else. Everything
else uses Taichi's public API (``ti.cfg``, ``ti.ScalarField``, ``ti.profiler``) or that module's
helpers (``compile_config``, ``current_arch``, ``watching``, ``profiled_tasks``)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
THE_MODULE = "pbf/solver/launch.py"
EXEMPT = {
    THE_MODULE,
    "benchmarks/instruments.py",  # the lab's instruments wrap Taichi's launch and compile to watch them
    "tests/test_launch.py",  # the gate's own tests look at what the fast launch kept
    "tests/test_private_taichi.py",  # this file names what it looks for
}
PRIVATE = re.compile(
    r"taichi\.lang|\bti\.lang\b|taichi\._lib|\bti\._lib|_ti_core|kernel_impl|\._primal\b|_kernel_owner"
    r"|_is_staticmethod|ensure_compiled|compiled_kernels|launch_kernel|template_slot_locations"
    r"|make_launch_context|compile_kernel\b|current_cfg|get_runtime|get_default_kernel_profiler"
    r"|_update_records|_traced_records|profiler\.kernel_profiler"
)
"""Taichi's private packages (``taichi.lang``, ``taichi._lib``), its kernel class's internals, its
program's, and its profiler's records: what another build of Taichi may lay out otherwise."""
SEARCHED = ("pbf", "benchmarks", "tests")
SUFFIXES = {".py", ".sh", ".c", ".toml"}


def references() -> list[str]:
    """``path:line: text`` of each private name outside the exempt files."""
    found = []
    for top in SEARCHED:
        for path in sorted((ROOT / top).rglob("*")):
            relative = path.relative_to(ROOT).as_posix()
            if path.suffix not in SUFFIXES or relative in EXEMPT or "__pycache__" in relative:
                continue
            for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
                if PRIVATE.search(line):
                    found.append(f"{relative}:{number}: {line.strip()}")
    return found


def test_taichis_private_names_are_read_in_one_module_only():
    found = references()
    assert not found, f"Taichi's private names outside {THE_MODULE}:\n" + "\n".join(found)


def test_the_search_finds_what_it_looks_for():
    # The pattern itself, on lines as they were written before the names moved into the one module.
    for line in [
        "config = ti.lang.impl.current_cfg()",
        "from taichi.lang.field import ScalarField",
        "import taichi.lang.kernel_impl as kernel_impl",
        "profiler._update_records()",
        "from taichi.profiler.kernel_profiler import get_default_kernel_profiler",
        "info.field_source == ti._lib.core.FieldSource.HostMappedPtr",
        "compiled = kernel._primal.compiled_kernels",
    ]:
        assert PRIVATE.search(line), line
    for line in ["config = ti.cfg", "isinstance(count, ti.ScalarField)", "def compile_kernels(folder):"]:
        assert not PRIVATE.search(line), line
    assert (ROOT / THE_MODULE).is_file() and PRIVATE.search((ROOT / THE_MODULE).read_text())
