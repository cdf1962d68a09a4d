"""Choosing and starting Taichi's backend, once per process.

``arch="auto"`` takes CUDA when an NVIDIA GPU answers and Taichi's CPU backend otherwise. The choice
can also come from the ``PBF_ARCH`` environment variable. Asking for CUDA where there is none is an
error, never a silent fallback. The chosen backend is printed once, in one line that names the
Taichi version: ``[pbf] Starting on cpu (x64, no CUDA GPU found), Taichi 1.7.4``. Taichi's own
lines stay silent: its banner (``[Taichi] version …``, printed when Taichi is imported) is switched
off by ``pbf/__init__.py``, and the ``[Taichi] Starting on arch=…`` that ``ti.init`` prints is
caught here (``_init``).
"""
import contextlib
import ctypes.util
import io
import os
import sys

import taichi as ti

ARCHES = ("auto", "cpu", "cuda")
ENV_VAR = "PBF_ARCH"


class BackendError(RuntimeError):
    """The requested backend cannot be started."""


_started: str | None = None
_options: dict = {}
"""The ``ti.init`` options of the running backend, for ``restart_backend``."""

TAICHI_START_LINE = "[Taichi] Starting on arch="
"""The line ``ti.init`` prints (``taichi/lang/misc.py``, a plain ``print``) on every start."""


def taichi_version() -> str:
    return ".".join(map(str, ti.__version__))


def _init(**options) -> None:
    """``ti.init(**options)`` without Taichi's "Starting on" line; anything else it prints passes."""
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            ti.init(**options)
    finally:
        rest = [line for line in printed.getvalue().splitlines(keepends=True) if not line.startswith(TAICHI_START_LINE)]
        sys.stdout.write("".join(rest))


def _cuda_present() -> bool:
    """Whether Taichi can start CUDA here. Without NVIDIA's driver library there is nothing to try;
    with it, Taichi initialises CUDA once to find out (and, where that fails, says it started on the
    CPU: a second such line next to the real start)."""
    if ctypes.util.find_library("cuda") is None and not os.path.exists("/proc/driver/nvidia"):
        return False
    try:
        _init(arch=ti.cuda, log_level=ti.ERROR)
        found = ti.lang.impl.current_cfg().arch == ti.cuda
    except Exception:  # Taichi raises several types when the driver is missing
        found = False
    ti.reset()
    return found


def start_backend(arch: str | None = None, quiet: bool = False, cpu_threads: int | None = None,
                  fast_compile: bool = False) -> str:
    """Start Taichi on ``arch`` (argument, else $PBF_ARCH, else "auto") and return "cpu" or "cuda".
    ``cpu_threads`` caps the CPU backend's threads (default: one per core). ``fast_compile`` turns
    off Taichi's advanced IR optimisation: a Simulation compiles in 1.6 s instead of 6.2 s on 2 cores
    but may step a few per cent slower; the test suite, which builds many short-lived Simulations,
    uses it. The arithmetic is the same up to rounding, not bit for bit: the seed scene's positions
    differ by 3e-8 m after one frame and, the splash being chaotic, by up to 0.8 m after 60. Each
    mode is deterministic by itself.

    Taichi can only run one backend per process: a second call with a different explicit request
    raises BackendError; a matching or "auto" request returns the backend already running.
    """
    global _started
    requested = (arch or os.environ.get(ENV_VAR) or "auto").lower()
    if requested not in ARCHES:
        source = "arch" if arch else ENV_VAR
        raise BackendError(f"{source}={requested!r}: unknown backend; allowed: {', '.join(ARCHES)}")
    if _started is not None:
        if requested not in ("auto", _started):
            raise BackendError(f"Taichi already runs on {_started} in this process; cannot switch to {requested}")
        return _started
    if requested == "cpu":
        chosen = "cpu"
    elif _cuda_present():
        chosen = "cuda"
    elif requested == "cuda":
        raise BackendError("arch='cuda' was requested but no CUDA GPU is available; use arch='cpu' or 'auto'")
    else:
        chosen = "cpu"
    threads = {"cpu_max_num_threads": cpu_threads} if cpu_threads else {}
    _options.clear()
    _options.update(arch=ti.cuda if chosen == "cuda" else ti.cpu, default_fp=ti.f32, log_level=ti.WARN,
                    advanced_optimization=not fast_compile, **threads)
    _init(**_options)
    _started = chosen
    if not quiet:
        reason = "CUDA GPU found" if chosen == "cuda" else ("requested" if requested == "cpu" else "no CUDA GPU found")
        arch_name = ti.lang.impl.current_cfg().arch.name  # x64, arm64 or cuda
        print(f"[pbf] Starting on {chosen} ({arch_name}, {reason}), Taichi {taichi_version()}", flush=True)
    return chosen


def restart_backend() -> None:
    """Free every Taichi field and compiled kernel of this process and start the same backend again.

    Taichi keeps each Simulation's kernels (and the memory they were compiled into) until the
    runtime is reset, so a process that builds hundreds of Simulations, like the test suite, grows by
    a few MB with each. Simulations made before the restart cannot be used after it.
    """
    if _started is None:
        raise BackendError("restart_backend(): no backend has been started in this process")
    _init(**_options)  # ti.init begins with ti.reset(), which frees the runtime
