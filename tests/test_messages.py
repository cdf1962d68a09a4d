"""An error is one short message: no traceback, no NumPy reprs, values echoed cut short, command-line
values blamed on the command line, and the closest valid name suggested."""

import os
import re

import numpy as np
import pytest
from command_line import assert_one_error, refused, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from pbf import SceneError, Simulation, load_scene
from pbf.app import cli, window
from pbf.scene import from_dict
from scenes import small_dam_break


def message_of(scene, source="test.toml"):
    with pytest.raises(SceneError) as error:
        from_dict(scene, source)
    return str(error.value)


@pytest.mark.parametrize(
    "path, value",
    [
        (("fluid", "blocks", 0, "min_m"), np.array([-0.5, 0.0, 0.0])),
        (("fluid", "blocks", 0, "max_m"), [np.float64(0.4), np.float64(0.4), np.float64(0.9)]),
        (("container", "max_m"), np.array([0.8, -1.0, 0.4])),
        (("fluid", "spacing_m"), np.float64(-0.5)),
        (("solver", "iterations"), np.int64(0)),
        (("render", "colour_by"), np.str_("pressure")),
    ],
)
def test_no_numpy_reprs(path, value):
    scene = small_dam_break()
    target = scene
    for part in path[:-1]:
        target = target.setdefault(part, {}) if isinstance(part, str) else target[part]
    target[path[-1]] = value
    message = message_of(scene)
    assert "np." not in message and "array(" not in message and "dtype" not in message, message


@settings(max_examples=60, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False, width=64).filter(lambda x: not 0.0001 <= x <= 100))
def test_numpy_scalars_print_as_plain_numbers(x):
    scene = small_dam_break()
    scene["fluid"]["spacing_m"] = np.float64(x)
    message = message_of(scene)
    assert f"got {float(x)!r}" in message and "np." not in message


@pytest.mark.parametrize(
    "value",
    [list(range(1_000_000)), "x" * 5_000_000, {"k" + str(i): i for i in range(10_000)}, [[[[[[[[1]]]]]]]], 10**4000],
)
def test_values_are_echoed_cut_short(value):
    scene = small_dam_break()
    scene["fluid"]["spacing_m"] = value
    assert len(message_of(scene)) < 300


def test_a_python_callers_overrides_are_not_called_the_command_line(tmp_path):
    # Simulation(file, overrides=[...]) from Python: the list it was given, not a --set it never typed.
    scene = tmp_path / "my_scene.toml"
    scene.write_text('extends = "dam_break"\n')
    with pytest.raises(SceneError) as error:
        Simulation(str(scene), overrides=["solver.iteratons=3"])
    message = str(error.value)
    assert message.startswith("overrides solver.iteratons=3: unknown key 'solver.iteratons'"), message
    assert "command line" not in message


def test_an_override_error_names_the_override_not_the_file():
    with pytest.raises(SceneError) as error:
        load_scene("dam_break", ["solver.iterations=0"])
    assert str(error.value).startswith("overrides solver.iterations=0: key 'solver.iterations'")
    with pytest.raises(SceneError) as error:
        load_scene("dam_break", ["fluid.blocks=[{min_m = [0, 0, 0], max_m = [2, 2, 2]}]"])
    message = str(error.value)
    assert message.startswith("overrides 'fluid.blocks=[{min_m") and "lies outside the container" in message
    with pytest.raises(SceneError) as error:  # the file's own mistakes still name the file
        load_scene("dam_break", ["solver.iterations=0x"])
    assert "got '0x'" in str(error.value)


@pytest.mark.parametrize(
    "change, hint",
    [
        ({"solver": {"iteratons": 4}}, "did you mean 'solver.iterations'?"),
        ({"iterations": 4}, "did you mean 'solver.iterations'?"),
        ({"solvr": {}}, "did you mean 'solver'?"),
        ({"render": {"colour_map": "virdis"}}, "did you mean 'viridis'?"),
        ({"render": {"colour_by": "sped"}}, "did you mean 'speed'?"),
    ],
)
def test_unknown_names_suggest_the_closest(change, hint):
    scene = small_dam_break()
    for table, values in change.items():
        scene[table] = {**scene.get(table, {}), **values} if isinstance(values, dict) and values else values
    assert hint in message_of(scene)


def test_unknown_presets_and_options_suggest_the_closest(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    refused(capsys, ["dam_brake"], "dam_brake: no such scene file; did you mean dam_break?", cwd=tmp_path)
    refused(capsys, ["dam_break", "--vidoe", "v.mp4"], "unknown option --vidoe; did you mean --video?", cwd=tmp_path)
    refused(
        capsys,
        ["dam_break", "--set", "solver.iteratons=3"],
        "command line --set solver.iteratons=3: unknown key 'solver.iteratons'; did you mean 'solver.iterations'?",
        cwd=tmp_path,
    )


def test_a_bad_value_is_one_line_without_traceback(tmp_path):
    result = run_cli("dam_break", "--set", "fluid.spacing_m=1e999", "--headless", cwd=tmp_path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert_one_error(
        result.stderr,
        "command line --set fluid.spacing_m=1e999: key 'fluid.spacing_m'",
        "expected a finite number, got inf",
    )


# ------------------------------------------------------------------------------------ a run's own lines


def pbf_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("[pbf]")]


def test_without_a_display_the_window_is_given_up_in_one_line(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    args = cli.parse_args(["dam_break"])
    assert cli.try_window(cli.load(args), args, cli.COMPILING) is None
    assert capsys.readouterr().out == "[pbf] no window: DISPLAY is not set; rendering headless instead\n"


def test_a_display_that_cannot_be_opened_is_given_up_in_one_line(monkeypatch, capsys):
    # GGUI's GLFW would print "cannot initialize GLFW" and end the process.
    monkeypatch.setenv("DISPLAY", ":4242")
    args = cli.parse_args(["dam_break"])
    if window.unreachable_display() is None:
        pytest.skip("no Xlib here to ask, or an X server answers on :4242")
    capsys.readouterr()
    assert cli.try_window(cli.load(args), args, cli.COMPILING) is None
    assert capsys.readouterr().out == (
        "[pbf] no window: the display DISPLAY=:4242 cannot be opened; rendering headless instead\n"
    )


@pytest.mark.slow
def test_a_run_without_vulkan_says_why_once_and_counts_its_frames_alike(tmp_path):
    """The lines of a window run that falls back to files, as the user reads them, in a process of its own
    (GGUI, once started in a process, does not survive a second window without a driver). Where Vulkan
    cannot start, GGUI's C++ side writes "RHI Error: Can not create Vulkan instance" to file descriptor 2
    before the program says why there is no window: only the program's line shows (a loader pointed at no
    driver, VK_ICD_FILENAMES, makes any machine one without Vulkan; a Wayland display, named, takes the run
    past the X display's check to GGUI). Every number of frames said is the
    number written, and the pour, empty at the start, says how many particles its nozzle will add."""
    env = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
    env |= {"WAYLAND_DISPLAY": "wayland-4242", "VK_ICD_FILENAMES": str(tmp_path / "no_driver.json")}
    out = tmp_path / "frames"
    result = run_cli("pour", "--arch", "cpu", "--frames", "2", "--out", out, "--size", "64x48", cwd=tmp_path, env=env)
    assert result.returncode == 0, result.stderr
    assert "RHI" not in result.stderr and "RHI" not in result.stdout, result.stderr
    lines = pbf_lines(result.stdout)
    assert lines[0].startswith("[pbf] Starting on cpu ("), result.stdout
    assert lines[2] in (cli.COMPILING, cli.LOADING), result.stdout  # the cache held kernels or not
    assert lines[1:5] == [
        "[pbf] no window: no Vulkan driver for the window (on Debian/Ubuntu 'apt-get install mesa-vulkan-drivers "
        "libvulkan1' gives a software one); rendering headless instead",
        lines[2],
        "[pbf] pour: 0 particles now, up to 9,772 from its emitters; Δt = 8.33 ms, 10 iterations",
        f"[pbf] rendering 3 frames (the start and 2 steps) into {out}/",
    ], result.stdout
    assert re.fullmatch(r"\[pbf\] kernels ready and the first frame drawn in \d+\.\d s", lines[5]), result.stdout
    size = cli._size(sum(path.stat().st_size for path in out.glob("frame_*.png")))
    assert lines[6:] == [
        f"[pbf] wrote 3 frames in {out}/: {size} (PNG frames at 64×48); a video instead: "
        f"--headless --video {out}.mp4 --no-png; "
        f"fewer or smaller frames: --frames N, --size WxH"
    ], result.stdout
    assert len(list(out.glob("frame_*.png"))) == 3
    assert "((" not in result.stdout and "))" not in result.stdout


def test_the_kernels_line_says_whether_they_compile_or_load(tmp_path):
    cache = tmp_path / "ticache"
    assert cli.kernels_line(True, cache) == cli.COMPILING  # no cache folder yet: a first run
    cache.mkdir()
    (cache / "ticache.tcb").write_bytes(b"")  # Taichi's index alone holds no kernel
    assert cli.kernels_line(True, cache) == cli.COMPILING
    (cache / "T0123abcd.tic").write_bytes(b"")
    assert cli.kernels_line(True, cache) == cli.LOADING
    assert cli.kernels_line(False, cache) == cli.UNCACHED
    assert "first run only" not in cli.LOADING + cli.COMPILING


@pytest.mark.slow
def test_a_first_start_says_it_compiles_and_the_next_that_it_loads(tmp_path):
    # Every start used to say "compiling kernels (first run only ...)"; with an empty cache folder of its
    # own, the first run compiles and fills it, and the second loads from it, faster.
    env = os.environ | {"TI_OFFLINE_CACHE_FILE_PATH": str(tmp_path / "cache")}
    argv = ["dam_break", "--stats-only", "--frames", "1", "--set", "fluid.spacing_m=0.1"]
    said, took = [], []
    for _ in range(2):
        result = run_cli(*argv, cwd=tmp_path, env=env)
        assert result.returncode == 0, result.stderr
        lines = pbf_lines(result.stdout)
        said.append(lines[1])
        took.append(float(re.fullmatch(r"\[pbf\] kernels ready in (\d+\.\d) s", lines[3]).group(1)))
    assert said == [cli.COMPILING, cli.LOADING]
    assert took[1] < took[0], took
