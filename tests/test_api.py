"""The Python API refuses what it cannot use with SceneError, whatever the way in: a dict, overrides,
a Scene built by hand, a wrong type."""

import dataclasses

import pytest

from pbf import Scene, SceneError, Simulation, load_scene
from pbf.scene import Block, Camera, Fluid, Time, from_dict
from scenes import small_dam_break

BLOCK = Block(min_m=(0.0, 0.0, 0.0), max_m=(0.4, 0.4, 0.4))


def test_overrides_apply_to_a_dict_and_to_a_scene():
    table = small_dam_break()
    scene = load_scene(table, ["solver.iterations=7", "time.substeps=3"])
    assert (scene.solver.iterations, scene.time.substeps) == (7, 3)
    assert table == small_dam_break(), "the caller's dict must not change"
    again = load_scene(scene, ["solver.iterations=2"])
    assert again.solver.iterations == 2 and again.time.substeps == 3 and again.source == "<dict>"
    assert load_scene(scene) is scene
    with pytest.raises(SceneError, match=r"overrides solver.iterations=0: key 'solver.iterations'"):
        load_scene(table, ["solver.iterations=0"])


def test_simulation_applies_overrides_to_a_dict():
    with pytest.raises(SceneError, match="key 'solver.iterations'"):
        Simulation(small_dam_break(), overrides=["solver.iterations=0"])


@pytest.mark.parametrize(
    "table, message",
    [
        ({1: "x"}, "<dict>: key 1 is not a string"),
        ({"solver": {(1, 2): 3}}, "<dict>: key 'solver': key [1, 2] is not a string"),
        ({"fluid": {"blocks": [{None: 1}]}}, "key 'fluid.blocks[0]': key None is not a string"),
        ("scene", "<dict>: expected a table ([scene]), got 'scene'"),
        ({"fluid": 5}, "key 'fluid': expected a table ([fluid]), got 5"),
        ({"fluid": {"blocks": {"min_m": [0, 0, 0]}}}, "key 'fluid.blocks': expected a list of tables"),
    ],
)
def test_dicts_that_are_no_scene(table, message):
    with pytest.raises(SceneError) as error:
        from_dict(table)
    assert message in str(error.value)


@pytest.mark.parametrize(
    "build, message",
    [
        (
            lambda: Scene(fluid=Fluid(spacing_m=0.0, blocks=(BLOCK,))),
            "<Scene>: key 'fluid.spacing_m': expected a value in",
        ),
        (
            lambda: Scene(fluid=Fluid(blocks=(BLOCK,)), time=Time(substeps=0)),
            "key 'time.substeps': expected a value in",
        ),
        (
            lambda: Scene(fluid=Fluid(blocks=(BLOCK,)), time=Time(frame_dt_s="fast")),
            "key 'time.frame_dt_s': expected a number",
        ),
        (lambda: Scene(fluid=Fluid(blocks=(BLOCK,), spacing_m=float("nan"))), "expected a finite number, got nan"),
        (lambda: Scene(fluid="water"), "key 'fluid': expected a table ([fluid]), got 'water'"),
        (lambda: Scene(fluid=Fluid(blocks=[{"min_m": [0, 0, 0]}])), "key 'fluid.blocks[0].max_m' is required"),
        (lambda: Scene(fluid=Fluid()), "at least one [[fluid.blocks]] table"),
        (lambda: Scene(source=5), "source: expected a string"),
        (
            lambda: Scene(fluid=Fluid(blocks=(BLOCK,)), camera=Camera(position_m=(1, 2))),
            "key 'camera.position_m': expected",
        ),
        (
            lambda: dataclasses.replace(from_dict(small_dam_break()), name="two\nlines"),
            "key 'name': expected at most 64",
        ),
    ],
)
def test_a_scene_built_by_hand_is_checked_like_a_file(build, message):
    with pytest.raises(SceneError) as error:
        build()
    assert message in str(error.value)


def test_a_scene_built_by_hand_gets_plain_types():
    scene = Scene(fluid=Fluid(blocks=(Block(min_m=[0, 0, 0], max_m=[0.5, 0.5, 0.5]),), spacing_m=1 / 20))
    assert scene.fluid.blocks[0].max_m == (0.5, 0.5, 0.5) and type(scene.fluid.blocks[0].min_m[0]) is float
    assert scene.particle_count == 1000 and scene.source == "<Scene>"


@pytest.mark.parametrize(
    "source, overrides, message",
    [
        (123, (), "123: expected a preset name, a TOML path, a dict or a pbf.Scene"),
        (None, (), "None: expected a preset name"),
        ("dam_break", "solver.iterations=6", "overrides: expected a list of 'KEY=VALUE' strings"),
        ("dam_break", [6], "overrides 6: expected a 'KEY=VALUE' string"),
    ],
)
def test_wrong_types_are_scene_errors(source, overrides, message):
    with pytest.raises(SceneError) as error:
        load_scene(source, overrides)
    assert message in str(error.value)
