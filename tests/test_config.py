"""Bad scenes fail at load with one clear error naming the file, the key and what is allowed."""

import copy
import math
import subprocess
import sys

import pytest

from pbf import SceneError, Simulation, load_scene
from pbf.scene import from_dict
from pbf.solver import ENV_VAR, BackendError, start_backend
from scenes import small_dam_break


def with_change(path, value):
    scene = copy.deepcopy(small_dam_break())
    target = scene
    for part in path[:-1]:
        target = target.setdefault(part, {}) if not isinstance(part, int) else target[part]
    target[path[-1]] = value
    return scene


@pytest.mark.parametrize(
    "path, value, expected",
    [
        (("fluid", "spacing_m"), -0.02, "key 'fluid.spacing_m': expected a value in [0.0001, 100]"),
        (("fluid", "spacing_m"), 0.0, "key 'fluid.spacing_m': expected a value in [0.0001, 100]"),
        (("fluid", "spacing_m"), math.nan, "key 'fluid.spacing_m': expected a finite number"),
        (("fluid", "spacing_m"), "fine", "key 'fluid.spacing_m': expected a number"),
        (("solver", "iterations"), 0, "key 'solver.iterations': expected a value in [1, 100]"),
        (("solver", "iterations"), 2.5, "key 'solver.iterations': expected an integer"),
        (("solver", "wall_mirror"), 1, "key 'solver.wall_mirror': expected true or false"),
        (("solver", "expert", "step_back"), 1, "key 'solver.expert.step_back': expected true or false"),
        (("time", "frame_dt_s"), math.inf, "key 'time.frame_dt_s': expected a finite number"),
        (("viscosity", "xsph"), 1.5, "key 'viscosity.xsph': expected a value in [0, 1]"),
        (("gravity_m_s2",), [0, -9.81], "key 'gravity_m_s2': expected three numbers"),
        (
            ("solver", "iteratons"),
            4,
            "unknown key 'solver.iteratons'; did you mean 'solver.iterations'? allowed keys here:",
        ),
        (("colour",), "blue", "unknown key 'colour'"),
        (("fluid", "blocks", 0, "max_m"), [0.4, 0.4, 0.9], "'fluid.blocks[0]': block"),
        (("fluid", "blocks"), [], "at least one [[fluid.blocks]]"),
        (("container", "max_m"), [0.8, -1.0, 0.4], "container.max_m' must exceed"),
        (("render", "colour_by"), "pressure", "key 'render.colour_by': expected one of 'speed', 'density'"),
        (("render", "colour_map"), "rainbowz", "key 'render.colour_map': expected a Matplotlib colour map"),
        (("render", "width_px"), 641, "key 'render.width_px': expected an even number of pixels"),
        (("render", "background_rgb"), [0, 0, 2], "key 'render.background_rgb': expected three values in [0, 1]"),
        (("camera", "position_m"), "front", "key 'camera.position_m': expected three numbers"),
        (("camera", "fov_deg"), 0, "key 'camera.fov_deg': expected a value in [5, 150]"),
    ],
)
def test_bad_values_name_the_key(path, value, expected):
    with pytest.raises(SceneError) as error:
        from_dict(with_change(path, value), "test.toml")
    assert str(error.value).startswith("test.toml")
    assert expected in str(error.value)


def test_block_outside_box_names_the_allowed_range():
    with pytest.raises(SceneError, match="lies outside the container.*allowed: min_m ≥ container.min_m"):
        from_dict(with_change(("fluid", "blocks", 0, "min_m"), [-0.1, 0.0, 0.0]))


def test_overlapping_blocks():
    scene = small_dam_break()
    scene["fluid"]["blocks"].append({"min_m": [0.3, 0.3, 0.0], "max_m": [0.5, 0.5, 0.2]})
    with pytest.raises(SceneError, match=r"fluid.blocks\[1\]' overlaps fluid.blocks\[0\]"):
        from_dict(scene)


def test_too_many_particles_for_memory():
    scene = small_dam_break()
    scene["container"]["max_m"] = [100.0, 100.0, 100.0]
    scene["fluid"]["blocks"][0]["max_m"] = [100.0, 100.0, 100.0]
    scene["fluid"]["spacing_m"] = 0.01
    # The Model checks memory before Taichi allocates anything; the scene itself is valid.
    with pytest.raises(SceneError, match="<dict>: key 'fluid.spacing_m': .* particles .* GiB"):
        Simulation(from_dict(scene))


def test_missing_scene_lists_presets():
    with pytest.raises(SceneError, match="no_such_scene: no such scene file; presets: .*dam_break"):
        load_scene("no_such_scene")


def test_override_and_preset_load(tmp_path):
    scene = load_scene("dam_break", ["solver.iterations=6", "fluid.spacing_m=0.05"])
    assert scene.solver.iterations == 6 and scene.fluid.spacing_m == 0.05
    assert load_scene("dam_break").particle_count == 8000
    with pytest.raises(
        SceneError,
        match=r"overrides solver.iterations=0: key 'solver.iterations': "
        r"expected a value in \[1, 100\]",
    ):
        load_scene("dam_break", ["solver.iterations=0"])
    broken = tmp_path / "broken.toml"
    broken.write_text("[solver\niterations = 3")
    with pytest.raises(SceneError, match="broken.toml: not valid TOML"):
        load_scene(broken)


def test_unknown_backend(monkeypatch):
    with pytest.raises(BackendError, match="unknown backend; allowed: auto, cpu, gpu, cuda, vulkan, metal"):
        start_backend("opengl")
    monkeypatch.setenv(ENV_VAR, "tpu")
    with pytest.raises(BackendError, match="PBF_ARCH='tpu'"):
        start_backend()


def test_cuda_without_gpu_is_a_clear_error():
    # A fresh process: this one already runs Taichi on the CPU.
    code = "from pbf.solver import start_backend; start_backend('cuda')"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    if result.returncode == 0:
        pytest.skip("a CUDA GPU is present here")
    assert "BackendError: arch='cuda' was requested but no CUDA GPU is available" in result.stderr


def test_restart_frees_the_runtime_and_keeps_the_backend():
    # A fresh process: restarting before any start is an error; after a start, a restart gives back
    # the memory of what was built (a 200 MB field here) and runs the same backend again.
    code = (
        "from pbf.solver.backend import BackendError, restart_backend, start_backend\n"
        "import taichi as ti\n"
        "def rss_mb():\n"
        "    return int(next(l for l in open('/proc/self/status') if l.startswith('VmRSS')).split()[1]) // 1024\n"
        "try:\n    restart_backend()\nexcept BackendError as error:\n    print('refused:', error)\n"
        "start_backend('cpu', quiet=True)\n"
        "big = ti.field(ti.f32, shape=50_000_000)\n"
        "big.fill(1.0)\n"
        "held = rss_mb()\n"
        "restart_backend()\n"
        "after = ti.field(ti.f32, shape=4)\n"
        "after.fill(2.0)\n"
        "print('arch', ti.cfg.arch.name, 'sum', after.to_numpy().sum(), 'freed', held - rss_mb())\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "refused: restart_backend(): no backend has been started in this process" in result.stdout
    words = result.stdout.split()
    assert words[words.index("arch") + 1] in ("x64", "arm64") and words[words.index("sum") + 1] == "8.0"
    assert int(words[words.index("freed") + 1]) > 150  # of the field's 200 MB


def test_bad_scene_allocates_nothing():
    with pytest.raises(SceneError):
        Simulation(with_change(("solver", "iterations"), -1))
