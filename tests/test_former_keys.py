"""A scene written for an earlier version is answered with where each of its old keys went, or why it
was removed, the same from a scene file, from ``--set`` and from a dict given to the Python API."""

import pytest
from command_line import refused

from pbf import SceneError, Simulation, load_scene
from pbf.scene import Scene
from pbf.scene.reference import reference
from pbf.scene.schema import MOVED, REMOVED, _schema_keys, echo
from scenes import small_dam_break

HISTORY = {
    # The levers no preset needs went under [solver.expert] when the schema became a package.
    "solver.acceleration": "solver.expert.acceleration",
    "solver.chebyshev_rho": "solver.expert.chebyshev_rho",
    "solver.step_back": "solver.expert.step_back",
    "solver.relaxation": "solver.expert.relaxation",
    "solver.wall_density": "solver.expert.wall_density",
    # Removed at the same time (CHANGELOG.md, "Removed").
    "solver.warm_start": None,
    "solver.clamp_pressure": None,
    "solver.scorr_n": None,
    "solver.scorr_dq": None,
}
"""Every key the schema has lost since its first version, read from the git history of its modules."""

OLD_VALUES = {
    "solver.acceleration": '"none"',
    "solver.chebyshev_rho": "0.8",
    "solver.step_back": "false",
    "solver.relaxation": "0.2",
    "solver.wall_density": "false",
    "solver.warm_start": "1.0",
    "solver.clamp_pressure": "true",
    "solver.scorr_n": "4",
    "solver.scorr_dq": "0.2",
}


def expected(dotted: str) -> str:
    if dotted in MOVED:
        return f"key '{dotted}' moved to '{MOVED[dotted]}'"
    return f"key '{dotted}' was removed: {REMOVED[dotted]}; delete it"


def test_the_tables_hold_the_schemas_history():
    assert MOVED == {old: new for old, new in HISTORY.items() if new is not None}
    assert set(REMOVED) == {old for old, new in HISTORY.items() if new is None}
    current = set(_schema_keys(Scene))
    assert set(MOVED.values()) <= current, "a key moved to a place the schema does not have"
    assert not (set(MOVED) | set(REMOVED)) & current, "a key both current and former"


@pytest.mark.parametrize("dotted", HISTORY)
def test_a_scene_file_with_an_old_key(dotted, tmp_path, capsys):
    table, name = dotted.split(".")
    scene = tmp_path / "old.toml"
    scene.write_text(f'extends = "dam_break"\n\n[{table}]\n{name} = {OLD_VALUES[dotted]}\n')
    line = refused(capsys, [scene, "--stats-only"], str(scene), expected(dotted), cwd=tmp_path)
    assert "did you mean" not in line, line


@pytest.mark.parametrize("dotted", HISTORY)
def test_a_set_of_an_old_key(dotted, tmp_path, capsys):
    assignment = f"{dotted}={OLD_VALUES[dotted]}"
    refused(
        capsys,
        ["--set", assignment, "--stats-only"],
        f"command line --set {echo(assignment)}",
        expected(dotted),
        cwd=tmp_path,
    )


@pytest.mark.parametrize("dotted", HISTORY)
def test_a_dict_with_an_old_key(dotted):
    table = small_dam_break()
    section, name = dotted.split(".")
    table[section][name] = True
    for make in (load_scene, Simulation):
        with pytest.raises(SceneError) as error:
            make(table)
        assert str(error.value).startswith("<dict>: " + expected(dotted)), str(error.value)
        assert error.value.key == dotted


def test_a_moved_key_in_a_file_says_which_table_it_goes_in(tmp_path):
    scene = tmp_path / "old.toml"
    scene.write_text('extends = "dam_break"\n\n[solver]\nchebyshev_rho = 0.8\n')
    with pytest.raises(SceneError, match=r"set chebyshev_rho in the \[solver.expert\] table"):
        load_scene(scene)


def test_the_key_reference_lists_them():
    text = reference()
    section = text[text.index("## Moved and removed keys") :]
    for old, new in MOVED.items():
        assert f"| `{old}` | moved to `{new}` |" in section
    for old, why in REMOVED.items():
        assert f"| `{old}` | removed: {why} |" in section
