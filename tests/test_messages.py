"""An error is one short message: no traceback, no NumPy reprs, values echoed cut short, command-line
values blamed on the command line, and the closest valid name suggested."""

import numpy as np
import pytest
from command_line import assert_one_error, refused, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from pbf import SceneError, load_scene
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


def test_an_override_error_names_the_command_line_not_the_file():
    with pytest.raises(SceneError) as error:
        load_scene("dam_break", ["solver.iterations=0"])
    assert str(error.value).startswith("command line --set solver.iterations=0: key 'solver.iterations'")
    with pytest.raises(SceneError) as error:
        load_scene("dam_break", ["fluid.blocks=[{min_m = [0, 0, 0], max_m = [2, 2, 2]}]"])
    assert str(error.value).startswith(
        "command line --set 'fluid.blocks=[{min_m"
    ) and "lies outside the container" in str(error.value)
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
