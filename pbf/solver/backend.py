"""Choosing and starting Taichi's backend, once per process.

``arch="auto"`` takes CUDA when an NVIDIA GPU answers and Taichi's CPU backend otherwise. The choice
can also come from the ``PBF_ARCH`` environment variable. Asking for CUDA where there is none is an
error, never a silent fallback. The chosen backend is printed once.
"""
import ctypes.util
import os

import taichi as ti

ARCHES = ("auto", "cpu", "cuda")
ENV_VAR = "PBF_ARCH"


class BackendError(RuntimeError):
    """The requested backend cannot be started."""


_started: str | None = None


def _cuda_present() -> bool:
    """Whether Taichi can start CUDA here. Without NVIDIA's driver library there is nothing to try;
    with it, Taichi initialises CUDA once to find out (and, where that fails, says it started on the
    CPU: a second such line next to the real start)."""
    if ctypes.util.find_library("cuda") is None and not os.path.exists("/proc/driver/nvidia"):
        return False
    try:
        ti.init(arch=ti.cuda, log_level=ti.ERROR)
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
    and gives the same bits (the seed scene's positions after 60 frames), but may step a few per
    cent slower; the test suite, which builds many short-lived Simulations, uses it.

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
    ti.init(arch=ti.cuda if chosen == "cuda" else ti.cpu, default_fp=ti.f32, log_level=ti.WARN,
            advanced_optimization=not fast_compile, **threads)
    _started = chosen
    if not quiet:
        reason = "CUDA GPU found" if chosen == "cuda" else ("requested" if requested == "cpu" else "no CUDA GPU found")
        print(f"[pbf] backend: {chosen} ({reason})", flush=True)
    return chosen
