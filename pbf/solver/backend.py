"""Choosing and starting Taichi's backend once per process, and what the host knows of its device.
``auto`` never takes a software Vulkan driver (the CPU backend is faster); ``gpu`` takes the best GPU
backend that starts; one asked for by name that cannot start is a BackendError (docs/BENCHMARKS.md,
"Backends: the CPU's path and the GPU's")."""

import contextlib
import ctypes
import ctypes.util
import os
import struct
import sys
from dataclasses import dataclass

import taichi as ti

from pbf.solver.launch import compile_config, current_arch, start_taichi

ARCHES = ("auto", "cpu", "gpu", "cuda", "vulkan", "metal")
GPU_ARCHES = ("cuda", "vulkan", "metal")
ENV_VAR = "PBF_ARCH"


class BackendError(RuntimeError):
    """The requested backend cannot be started."""


@dataclass(frozen=True)
class Device:
    arch: str
    """One of "cpu", "cuda", "vulkan", "metal"."""
    name: str
    software: bool = False
    """A CPU posing as a GPU (Mesa's lavapipe/llvmpipe)."""
    memory_bytes: int | None = None
    """The device's own memory where the host can tell; None where the kernels use the host's."""


_started: Device | None = None
_options: dict = {}
"""The ``ti.init`` options of the running backend, for ``restart_backend``."""

CPU_DEVICE = Device("cpu", "")
SOFTWARE_VULKAN = ("llvmpipe", "lavapipe", "swiftshader")
"""Names of software Vulkan devices (Mesa's lavapipe reports "llvmpipe (LLVM …)")."""


def taichi_version() -> str:
    return ".".join(map(str, ti.__version__))


def _cuda_device() -> Device | None:
    """The first CUDA device (Taichi's), from NVIDIA's driver library, once Taichi has started on it; or None."""
    if ctypes.util.find_library("cuda") is None and not os.path.exists("/proc/driver/nvidia"):
        return None
    name, memory = "CUDA GPU", None
    with contextlib.suppress(OSError, AttributeError):
        cuda = ctypes.CDLL(ctypes.util.find_library("cuda") or "libcuda.so.1")
        device, total = ctypes.c_int(), ctypes.c_size_t()
        buffer = ctypes.create_string_buffer(256)
        if cuda.cuInit(0) == 0 and cuda.cuDeviceGet(ctypes.byref(device), 0) == 0:
            if cuda.cuDeviceGetName(buffer, 256, device) == 0:
                name = buffer.value.decode(errors="replace")
            if cuda.cuDeviceTotalMem_v2(ctypes.byref(total), device) == 0:
                memory = total.value
    try:
        start_taichi(arch=ti.cuda, log_level=ti.ERROR)
        found = current_arch() == ti.cuda
    except Exception:  # Taichi raises several types when the driver is missing
        found = False
    ti.reset()
    return Device("cuda", name, False, memory) if found else None


class _VkApplicationInfo(ctypes.Structure):
    _fields_ = [
        ("sType", ctypes.c_int),
        ("pNext", ctypes.c_void_p),
        ("pApplicationName", ctypes.c_char_p),
        ("applicationVersion", ctypes.c_uint32),
        ("pEngineName", ctypes.c_char_p),
        ("engineVersion", ctypes.c_uint32),
        ("apiVersion", ctypes.c_uint32),
    ]


class _VkInstanceCreateInfo(ctypes.Structure):
    _fields_ = [
        ("sType", ctypes.c_int),
        ("pNext", ctypes.c_void_p),
        ("flags", ctypes.c_uint32),
        ("pApplicationInfo", ctypes.POINTER(_VkApplicationInfo)),
        ("enabledLayerCount", ctypes.c_uint32),
        ("ppEnabledLayerNames", ctypes.c_void_p),
        ("enabledExtensionCount", ctypes.c_uint32),
        ("ppEnabledExtensionNames", ctypes.c_void_p),
    ]


VK_PHYSICAL_DEVICE_TYPE = {1: "integrated", 2: "discrete", 3: "virtual", 4: "cpu"}
"""VkPhysicalDeviceType values; 0 is "other"."""


def vulkan_devices() -> list[dict]:
    """Every Vulkan device (name, type, API minor version, largest local heap in bytes), read from libvulkan."""
    try:
        vulkan = ctypes.CDLL(ctypes.util.find_library("vulkan") or "libvulkan.so.1")
    except OSError:
        return []
    application = _VkApplicationInfo(0, None, b"pbf", 1, b"pbf", 1, 1 << 22)  # Vulkan 1.0 asks the least
    create = _VkInstanceCreateInfo(1, None, 0, ctypes.pointer(application), 0, None, 0, None)
    instance = ctypes.c_void_p()
    vulkan.vkCreateInstance.restype = ctypes.c_int
    if vulkan.vkCreateInstance(ctypes.byref(create), None, ctypes.byref(instance)) != 0:
        return []
    devices = []
    try:
        count = ctypes.c_uint32()
        vulkan.vkEnumeratePhysicalDevices(instance, ctypes.byref(count), None)
        handles = (ctypes.c_void_p * count.value)()
        vulkan.vkEnumeratePhysicalDevices(instance, ctypes.byref(count), handles)
        for handle in handles:
            # VkPhysicalDeviceProperties: five uint32 (apiVersion … deviceType), deviceName[256], < 1 kB of limits.
            properties = ctypes.create_string_buffer(4096)
            vulkan.vkGetPhysicalDeviceProperties(ctypes.c_void_p(handle), properties)
            api, _, _, _, code = struct.unpack_from("<5I", properties.raw, 0)
            name = properties.raw[20:276].split(b"\0")[0].decode(errors="replace")
            # VkPhysicalDeviceMemoryProperties: memoryHeapCount at 260, 16-byte heaps (size, flags) from 264.
            memory = ctypes.create_string_buffer(1024)
            vulkan.vkGetPhysicalDeviceMemoryProperties(ctypes.c_void_p(handle), memory)
            heaps = [
                struct.unpack_from("<QI", memory.raw, 264 + 16 * k)
                for k in range(min(struct.unpack_from("<I", memory.raw, 260)[0], 16))
            ]
            local = max((size for size, flags in heaps if flags & 1), default=0)  # VK_MEMORY_HEAP_DEVICE_LOCAL_BIT
            kind = VK_PHYSICAL_DEVICE_TYPE.get(code, "other")
            devices.append({"name": name, "type": kind, "api_minor": (api >> 12) & 0x3FF, "memory_bytes": local})
    finally:
        vulkan.vkDestroyInstance(instance, None)
    return devices


def _is_software(device: dict) -> bool:
    return device["type"] == "cpu" or any(word in device["name"].lower() for word in SOFTWARE_VULKAN)


def _taichi_vulkan_choice(devices: list[dict]) -> dict | None:
    """The device Taichi 1.7's Vulkan backend picks (``VulkanDeviceCreator::pick_physical_device``)."""
    if not devices:
        return None
    visible = os.environ.get("TI_VISIBLE_DEVICE", "")
    if visible.isdigit() and int(visible) < len(devices):
        return devices[int(visible)]
    return max(devices, key=lambda d: {"discrete": 1000, "integrated": 500}.get(d["type"], 0) + 100 * d["api_minor"])


def _vulkan_device() -> Device | None:
    choice = _taichi_vulkan_choice(vulkan_devices())
    if choice is None:
        return None
    software = _is_software(choice)
    return Device("vulkan", choice["name"], software, None if software else choice["memory_bytes"] or None)


def _metal_device() -> Device | None:
    return Device("metal", "Apple GPU") if sys.platform == "darwin" else None


UNAVAILABLE = {
    "cuda": "no CUDA GPU is available",
    "vulkan": "no Vulkan device is available (no Vulkan loader or driver; on Debian/Ubuntu 'apt-get install "
    "mesa-vulkan-drivers libvulkan1' gives a software one)",
    "metal": "Metal exists only on macOS",
    "gpu": "no GPU backend can start here (no CUDA GPU, no Metal, no Vulkan device)",
}
"""Why a backend asked for by name cannot start, for its BackendError."""


def _choose(requested: str) -> tuple[Device, str]:
    """The device to start for ``requested`` and why; BackendError when a named backend has none."""
    if requested == "cpu":
        return CPU_DEVICE, "requested"
    finders = {"cuda": _cuda_device, "vulkan": _vulkan_device, "metal": _metal_device}
    if requested in finders:
        device, reason = finders[requested](), "requested"
    else:  # auto or gpu: CUDA first
        device = _cuda_device()
        if device is not None:
            return device, "CUDA GPU found" if requested == "auto" else "the best GPU backend found"
        device, reason = _metal_device() or _vulkan_device(), "the best GPU backend found"
        if requested == "auto":
            if device is None:
                return CPU_DEVICE, "no GPU found"
            if device.software:
                return CPU_DEVICE, (
                    f"no GPU found; the Vulkan device {device.name!r} is a software driver, slower than the CPU backend"
                )
            return device, f"no CUDA GPU, a {device.arch} device found"
    if device is None:
        raise BackendError(f"arch={requested!r} was requested but {UNAVAILABLE[requested]}; use arch='cpu' or 'auto'")
    return device, reason


def start_backend(
    arch: str | None = None,
    quiet: bool = False,
    cpu_threads: int | None = None,
    fast_compile: bool = False,
    kernel_profiler: bool = False,
) -> str:
    """Start Taichi on ``arch`` (else $PBF_ARCH, else "auto") and return the backend's name; ``fast_compile``
    skips the advanced IR optimisation (shorter compile, slower step, other rounding). One backend a
    process: asking for another later raises BackendError."""
    global _started
    requested = (arch or os.environ.get(ENV_VAR) or "auto").lower()
    if requested not in ARCHES:
        source = "arch" if arch else ENV_VAR
        raise BackendError(f"{source}={requested!r}: unknown backend; allowed: {', '.join(ARCHES)}")
    if _started is not None:
        if requested not in ("auto", _started.arch) and not (requested == "gpu" and _started.arch in GPU_ARCHES):
            raise BackendError(f"Taichi already runs on {_started.arch} in this process; cannot switch to {requested}")
        return _started.arch
    device, reason = _choose(requested)
    threads = {"cpu_max_num_threads": cpu_threads} if cpu_threads else {}
    profiler = {"kernel_profiler": True} if kernel_profiler else {}
    _options.clear()
    _options.update(arch=getattr(ti, device.arch), default_fp=ti.f32, log_level=ti.WARN)
    _options.update(advanced_optimization=not fast_compile, **threads, **profiler)
    try:
        start_taichi(**_options)
        running = current_arch()
    except Exception as error:  # Taichi raises RuntimeError and its own types when a driver fails
        raise BackendError(f"arch={requested!r}: Taichi could not start {device.arch}: {error}") from None
    if device.arch != "cpu" and running != getattr(ti, device.arch):  # Taichi's own fallback to the CPU
        ti.reset()
        raise BackendError(
            f"arch={requested!r}: Taichi could not start {device.arch} on {device.name!r} (it fell "
            f"back to the CPU); use arch='cpu' or 'auto'"
        )
    _started = device
    if not quiet:
        print(
            f"[pbf] Starting on {device.arch} ({describe(device, running.name)}, {reason}), Taichi {taichi_version()}",
            flush=True,
        )
    return device.arch


def describe(device: Device, arch_name: str | None = None) -> str:
    """The start line's device: the CPU backend's arch (x64, arm64), else the device's name."""
    if device.arch == "cpu":
        return arch_name or current_arch().name
    memory = f", {device.memory_bytes / 2**30:.1f} GiB" if device.memory_bytes else ""
    return f"{device.name}{memory}{', a software Vulkan driver' if device.software else ''}"


def running_device() -> Device:
    if _started is None:
        raise BackendError("no backend has been started in this process")
    return _started


def on_gpu() -> bool:
    """Whether the running backend is a GPU one (CUDA, Vulkan, Metal), lavapipe included."""
    return _started is not None and _started.arch in GPU_ARCHES


@dataclass(frozen=True)
class Choices:
    """What differs by backend, one value made when a Simulation starts (:func:`choices`) and handed to the
    stages that build on it (docs/METHOD.md, "One substep on every backend")."""

    decisions_on_device: bool = False
    """A GPU's path: four iterations a call, no decision read by the host, loops over the capacity bucket."""
    gpu_blocks: bool = False
    """Prefix sums and tree sums laid out in a GPU's blocks of 32 (``pbf.solver.scan``)."""
    shared_memory: bool = False
    """Float sums added up in each GPU block's shared memory: CUDA only (SPIR-V fails on a second loop with
    a shared array)."""
    slot_major: bool = False
    """Neighbour lists slot-major (``NeighbourGrid.slot_major``)."""


def choices(decisions_on_device: bool | None = None, gpu_blocks: bool | None = None) -> Choices:
    """The running backend's choices; ``decisions_on_device`` and ``gpu_blocks`` ask for a GPU's on any
    backend (the same results: tests, and a GPU's launches counted on the CPU)."""
    gpu = on_gpu()
    return Choices(
        gpu if decisions_on_device is None else decisions_on_device,
        gpu if gpu_blocks is None else gpu_blocks,
        _started is not None and _started.arch == "cuda",
        gpu,
    )


@contextlib.contextmanager
def light_compile():
    """Kernels first called inside skip the advanced IR optimisation: for those whose compile is most of what
    they cost (a measurement decides: the same time a call, and the bits checked)."""
    config = compile_config()
    before = config.advanced_optimization
    config.advanced_optimization = False
    try:
        yield
    finally:
        config.advanced_optimization = before


def host_available_bytes() -> int:
    """Physical memory that is free now (Linux/macOS), falling back to 8 GiB where it cannot be read."""
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def _cuda_free_bytes() -> int | None:
    """Free memory of the CUDA device in the calling thread's context (Taichi's, once started)."""
    with contextlib.suppress(OSError, AttributeError):
        cuda = ctypes.CDLL(ctypes.util.find_library("cuda") or "libcuda.so.1")
        context, free, total = ctypes.c_void_p(), ctypes.c_size_t(), ctypes.c_size_t()
        if cuda.cuCtxGetCurrent(ctypes.byref(context)) == 0 and context.value:
            if cuda.cuMemGetInfo_v2(ctypes.byref(free), ctypes.byref(total)) == 0:
                return free.value
    return None


def device_memory_bytes() -> int:
    """Memory the backend can still give the fields, bytes: the GPU's where it can tell, else the host's."""
    device = _started or CPU_DEVICE
    if device.arch == "cuda":
        return _cuda_free_bytes() or device.memory_bytes or host_available_bytes()
    return device.memory_bytes or host_available_bytes()


def memory_place() -> str:
    """Where :func:`device_memory_bytes` looks, in words for a message."""
    if _started is None or _started.arch not in GPU_ARCHES:
        return "free on this computer"
    if _started.arch == "cuda" or _started.memory_bytes:
        return f"of {_started.name}'s memory"
    return "free on this computer, which the device shares"


def restart_backend() -> None:
    """Free every Taichi field and kernel and start the same backend again; earlier Simulations cannot be used."""
    if _started is None:
        raise BackendError("restart_backend(): no backend has been started in this process")
    start_taichi(**_options)  # ti.init begins with ti.reset(), which frees the runtime
