"""Choosing the backend (auto, gpu, a named one), naming its device, its memory; and the solver's source
free of what GPUs lack or serialise (float64, serialised loops)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pbf.scene import SceneError, load_scene
from pbf.solver import backend
from pbf.solver.backend import BackendError, Device
from pbf.solver.model import Model

SOLVER = Path(backend.__file__).parent
CUDA = Device("cuda", "NVIDIA Test GPU", False, 8 << 30)
HARDWARE_VULKAN = Device("vulkan", "Test Radeon", False, 4 << 30)
LAVAPIPE = Device("vulkan", "llvmpipe (LLVM 15.0.6, 256 bits)", True)
METAL = Device("metal", "Apple GPU")


@pytest.fixture
def found(monkeypatch):
    """Stand-ins for the device probes: ``found(cuda=..., vulkan=..., metal=...)``."""

    def install(cuda=None, vulkan=None, metal=None):
        monkeypatch.setattr(backend, "_cuda_device", lambda: cuda)
        monkeypatch.setattr(backend, "_vulkan_device", lambda: vulkan)
        monkeypatch.setattr(backend, "_metal_device", lambda: metal)

    return install


@pytest.mark.parametrize(
    "devices, chosen",
    [
        ({"cuda": CUDA, "vulkan": HARDWARE_VULKAN}, "cuda"),
        ({"vulkan": HARDWARE_VULKAN}, "vulkan"),
        ({"metal": METAL, "vulkan": LAVAPIPE}, "metal"),
        ({"vulkan": LAVAPIPE}, "cpu"),  # never a software rasterizer over the CPU backend
        ({}, "cpu"),
    ],
)
def test_auto_prefers_cuda_then_a_hardware_gpu_then_the_cpu(found, devices, chosen):
    found(**devices)
    device, reason = backend._choose("auto")
    assert device.arch == chosen
    if devices.get("vulkan") is LAVAPIPE and chosen == "cpu":
        assert "llvmpipe" in reason and "software" in reason


@pytest.mark.parametrize(
    "devices, chosen",
    [
        ({"cuda": CUDA, "vulkan": LAVAPIPE}, "cuda"),
        ({"metal": METAL, "vulkan": HARDWARE_VULKAN}, "metal"),
        ({"vulkan": LAVAPIPE}, "vulkan"),  # asked for a GPU backend: the software one is the one there is
    ],
)
def test_gpu_takes_the_best_gpu_backend(found, devices, chosen):
    found(**devices)
    assert backend._choose("gpu")[0].arch == chosen


@pytest.mark.parametrize("requested", ["gpu", "cuda", "vulkan", "metal"])
def test_a_gpu_backend_that_cannot_start_is_an_error(found, requested):
    found()
    with pytest.raises(BackendError, match=f"arch='{requested}' was requested but"):
        backend._choose(requested)


def test_a_named_backend_is_taken_when_present(found):
    found(cuda=CUDA, vulkan=LAVAPIPE, metal=METAL)
    assert [backend._choose(name)[0] for name in ("cuda", "vulkan", "metal")] == [CUDA, LAVAPIPE, METAL]
    assert backend._choose("cpu")[0].arch == "cpu"


def test_taichi_picks_the_discrete_gpu_over_lavapipe_unless_told(monkeypatch):
    devices = [
        {"name": "llvmpipe (LLVM 15.0.6, 256 bits)", "type": "cpu", "api_minor": 3, "memory_bytes": 2 << 30},
        {"name": "Test Radeon", "type": "discrete", "api_minor": 2, "memory_bytes": 8 << 30},
    ]
    monkeypatch.delenv("TI_VISIBLE_DEVICE", raising=False)
    assert backend._taichi_vulkan_choice(devices)["name"] == "Test Radeon"
    monkeypatch.setenv("TI_VISIBLE_DEVICE", "0")
    assert backend._taichi_vulkan_choice(devices)["name"].startswith("llvmpipe")
    assert backend._is_software(devices[0]) and not backend._is_software(devices[1])


def test_the_start_line_names_the_device():
    assert backend.describe(CUDA) == "NVIDIA Test GPU, 8.0 GiB"
    assert backend.describe(LAVAPIPE) == "llvmpipe (LLVM 15.0.6, 256 bits), a software Vulkan driver"
    assert backend.describe(Device("cpu", ""), "x64") == "x64"


def test_vulkan_devices_lists_this_machines():
    devices = backend.vulkan_devices()
    if not devices:
        pytest.skip("no Vulkan loader or driver here")
    assert all(d["name"] and d["type"] in ("integrated", "discrete", "virtual", "cpu", "other") for d in devices)
    assert all(d["memory_bytes"] > 0 for d in devices)


def test_device_memory_on_the_cpu_is_the_hosts_free_memory():
    assert backend.running_device().arch == "cpu"  # the suite runs on the CPU backend (conftest.py)
    assert backend.device_memory_bytes() == pytest.approx(backend.host_available_bytes(), rel=0.2)


def test_device_memory_of_a_gpu_is_its_own(monkeypatch):
    monkeypatch.setattr(backend, "_started", HARDWARE_VULKAN)
    assert backend.device_memory_bytes() == 4 << 30
    monkeypatch.setattr(backend, "_started", LAVAPIPE)  # a CPU posing as a GPU: the host's memory
    assert backend.device_memory_bytes() == pytest.approx(backend.host_available_bytes(), rel=0.2)
    monkeypatch.setattr(backend, "_started", CUDA)
    monkeypatch.setattr(backend, "_cuda_free_bytes", lambda: 3 << 30)
    assert backend.device_memory_bytes() == 3 << 30


def test_the_memory_check_before_allocation_reads_the_gpus_memory(monkeypatch):
    # The seed scene needs a few MB: refused on a GPU with 1 MB free, named as the device's memory,
    # before anything is allocated; the host's memory plays no part.
    monkeypatch.setattr(backend, "_started", CUDA)
    monkeypatch.setattr(backend, "_cuda_free_bytes", lambda: 1 << 20)
    monkeypatch.setattr(backend, "host_available_bytes", lambda: 1 << 40)
    with pytest.raises(SceneError, match=r"key 'fluid.spacing_m': 8,000 particles .* GiB of .*'s memory"):
        Model.from_scene(load_scene("dam_break"))
    monkeypatch.setattr(backend, "_cuda_free_bytes", lambda: 8 << 30)
    monkeypatch.setattr(backend, "host_available_bytes", lambda: 1 << 20)
    assert Model.from_scene(load_scene("dam_break")).capacity == 8000


@pytest.mark.parametrize(
    "arch, expected",
    [
        ("auto", r"\[pbf\] Starting on cpu \((x64|arm64), no GPU found.*\), Taichi .+"),
        ("vulkan", r"\[pbf\] Starting on vulkan \(.+, requested\), Taichi .+"),
    ],
)
def test_a_fresh_process_starts_and_says_on_what(arch, expected):
    devices = backend.vulkan_devices()
    if arch == "vulkan" and not devices:
        pytest.skip("no Vulkan loader or driver here")
    if arch == "auto" and any(not backend._is_software(d) for d in devices):
        pytest.skip("a hardware Vulkan device is present here")
    code = f"from pbf.solver import start_backend; print(start_backend({arch!r}))"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env={**os.environ, "PBF_ARCH": ""}
    )
    if arch == "auto" and "Starting on cuda" in result.stdout:
        pytest.skip("a CUDA GPU is present here")
    assert result.returncode == 0, result.stderr
    starting = [line for line in result.stdout.splitlines() if "Starting on" in line]
    assert len(starting) == 1 and re.fullmatch(expected, starting[0]), result.stdout


def test_the_solver_uses_no_float64_and_no_serialised_loop():
    # Metal and many integrated GPUs have no float64; a serialised loop runs on one GPU thread.
    for path in sorted(SOLVER.glob("*.py")):
        name, text = path.name, path.read_text()
        code = "\n".join(line.split("#")[0] for line in text.splitlines())
        assert "serialize=True" not in code, name
        assert not re.search(r"\bti\.f64\b|\bti\.float64\b", code), name
