"""The key reference is generated from the schema: docs/KEYS.md must be its current output, and every
key of the schema must appear in it with its bounds."""

import dataclasses
import re
from pathlib import Path

import pytest

from pbf.app.cli import main
from pbf.scene import Fluid, Scene, Solver
from pbf.scene.reference import reference
from pbf.scene.schema import _schema_keys

KEYS_MD = Path(__file__).resolve().parent.parent / "docs" / "KEYS.md"


def test_docs_keys_is_current():
    assert KEYS_MD.read_text(encoding="utf-8") == reference(), "docs/KEYS.md is stale: run `pbf --keys > docs/KEYS.md`"


def test_every_key_is_listed_with_its_range():
    text = reference()
    for dotted in _schema_keys(Scene):
        listed = dotted.replace(".blocks.", ".blocks[].").replace("obstacles.", "obstacles[].")
        listed = listed.replace("emitters.", "emitters[].")
        dataclass_table = any(
            dataclasses.is_dataclass(f.default) for f in dataclasses.fields(Scene) if f.name == dotted
        )
        assert dataclass_table or f"`{listed}`" in text or f"[{listed}]" in text, dotted
    assert "| `fluid.spacing_m` | number | `0.025` | [0.0001, 100] |" in text
    assert "[1, 100]" in text.split("`solver.iterations`")[1].split("\n")[0]
    assert Fluid.__dataclass_fields__["spacing_m"].metadata["doc"] in text
    assert '"stable", "chebyshev", "none"' in text.split("`solver.expert.acceleration`")[1].split("\n")[0]
    assert Solver.__dataclass_fields__["expert"]


def test_the_command_line_prints_it(capsys):
    assert main(["--keys"]) == 0
    assert capsys.readouterr().out == reference()


def test_the_documented_command_prints_it(capsys):
    # docs/KEYS.md says how it is made; that command must be one the command line runs.
    documented = re.findall(r"`pbf ([^`]*?) > docs/KEYS.md`", KEYS_MD.read_text(encoding="utf-8"))
    assert documented, "docs/KEYS.md names the command that writes it"
    for command in documented:
        capsys.readouterr()
        assert main(command.split()) == 0, command
        assert capsys.readouterr().out == reference()


@pytest.mark.parametrize("word, option", [("keys", "--keys"), ("list", "--list")])
def test_a_reference_typed_as_a_subcommand_names_its_option(capsys, word, option):
    capsys.readouterr()
    assert main([word]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {word}: no such scene file or preset;"), err
    assert f"printed by {option}" in err[0]


def test_the_max_cfl_rule_with_obstacles_and_bodies_is_in_the_key_reference():
    # A copy of the seed scene (max_cfl 2.0) with an obstacle is refused: the reference says why beforehand.
    from pbf.scene import BODY_MAX_CFL
    from pbf.scene.geometry import OBSTACLE_MAX_CFL

    line = next(line for line in KEYS_MD.read_text(encoding="utf-8").splitlines() if "`time.max_cfl`" in line)
    assert f"at most {OBSTACLE_MAX_CFL:g} in a scene with [[obstacles]] or [[bodies]]" in line, line
    assert BODY_MAX_CFL == OBSTACLE_MAX_CFL


def test_the_seed_with_an_obstacle_is_told_what_to_set():
    from pbf.scene import SceneError, load_scene

    with pytest.raises(SceneError) as refused:
        load_scene("dam_break", ["obstacles=[{min_m=[0.6,0,0],max_m=[0.7,0.2,0.2]}]"])
    assert "set time.max_cfl = 1.5 beside them" in str(refused.value), str(refused.value)
    load_scene("dam_break", ["obstacles=[{min_m=[0.6,0,0],max_m=[0.7,0.2,0.2]}]", "time.max_cfl=1.5"])
