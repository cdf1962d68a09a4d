"""The Python API is held to the rules of scene files: every Control assignment is checked against
the bounds of its scene key, and memory refusals name the key that makes the difference."""

import dataclasses
import math

import numpy as np
import pytest

from pbf import SceneError
from pbf.scene import SCENES_DIR, Solver, Time, from_dict, load_scene
from pbf.solver import Control, Model, Push, model
from scenes import small_dam_break

NAN, INF = math.nan, math.inf


@pytest.fixture(scope="module")
def control():
    return Control.from_scene(from_dict(small_dam_break()))


def bounds(table, name):
    return {f.name: f for f in dataclasses.fields(table)}[name].metadata["check"].bounds


@pytest.mark.parametrize(
    "field, value, error, words",
    [
        (
            "iterations",
            -1,
            ValueError,
            ("control.iterations: expected an integer in [1, 100] (the bounds of solver.iterations), got -1"),
        ),
        ("iterations", 0, ValueError, "control.iterations: expected an integer in [1, 100]"),
        ("iterations", 10**9, ValueError, "got 1000000000"),
        (
            "iterations",
            1e9,
            TypeError,
            (
                "control.iterations: expected an integer in [1, 100] (the bounds of "
                "solver.iterations), got 1000000000.0 (float)"
            ),
        ),
        ("iterations", NAN, TypeError, "got nan (float)"),
        ("iterations", "5", TypeError, "got '5' (str)"),
        ("iterations", True, TypeError, "got true (bool)"),
        ("min_iterations", 101, ValueError, "control.min_iterations: expected an integer in [1, 100]"),
        ("substeps", 0, ValueError, "control.substeps: expected an integer in [1, 1000] (the bounds of time.substeps)"),
        ("substeps", -3, ValueError, "control.substeps"),
        (
            "xsph",
            NAN,
            ValueError,
            ("control.xsph: expected a finite number in [0, 1] (the bounds of viscosity.xsph), got nan"),
        ),
        ("xsph", 2.0, ValueError, "control.xsph"),
        (
            "vorticity",
            INF,
            ValueError,
            ("control.vorticity: expected a finite number in [0, 1] (the bounds of vorticity.epsilon), got inf"),
        ),
        ("target_density_error", NAN, ValueError, "control.target_density_error: expected a finite number in [0, 1]"),
        ("target_density_error", "0.01", TypeError, "control.target_density_error"),
        ("divergence_iterations", -1, ValueError, "control.divergence_iterations: expected an integer in [0, 100]"),
        ("step_back", 1, TypeError, "control.step_back: expected True or False, got 1 (int)"),
        ("emitters_on", "yes", TypeError, "control.emitters_on: expected True or False"),
        ("wave_maker_on", None, TypeError, "control.wave_maker_on"),
        ("gravity_m_s2", (0.0, NAN, 0.0), ValueError, "control.gravity_m_s2: expected three finite numbers"),
        ("gravity_m_s2", (0.0, -1e6, 0.0), ValueError, "control.gravity_m_s2: expected |g| ≤"),
        ("gravity_m_s2", 9.81, TypeError, "control.gravity_m_s2: expected three finite numbers"),
        ("gravity_m_s2", "down", TypeError, "control.gravity_m_s2"),
        ("push", 3, TypeError, "control.push: expected a pbf.solver.Push or None, got 3 (int)"),
        ("iteration", 3, AttributeError, "control.iteration: no such setting; did you mean control.iterations?"),
        # Names by meaning (the README's words, the window's sliders) point to the field that holds it.
        ("viscosity", 0.02, AttributeError, "control.viscosity: no such setting; did you mean control.xsph?"),
        ("gravity", (0, -9.81, 0), AttributeError, "did you mean control.gravity_m_s2?"),
    ],
)
def test_a_bad_assignment_is_refused_at_once_naming_the_setting(control, field, value, error, words):
    before = dataclasses.asdict(control)
    with pytest.raises(error) as refused:
        setattr(control, field, value)
    message = str(refused.value).strip("'\"")  # AttributeError's str() is plain, KeyError's would be quoted
    assert words in message and "\n" not in message, message
    assert dataclasses.asdict(control) == before  # nothing changed


def test_the_bounds_are_the_scene_keys(control):
    # Read from the keys' declarations, not copied: the ends are allowed, one step beyond is not.
    for field, (table, name) in {
        "iterations": (Solver, "iterations"),
        "substeps": (Time, "substeps"),
        "divergence_iterations": (Solver, "divergence_iterations"),
    }.items():
        lowest, highest = bounds(table, name)
        for allowed in (lowest, highest):
            setattr(control, field, np.int64(allowed))
            assert getattr(control, field) == allowed and type(getattr(control, field)) is int
        for refused in (lowest - 1, highest + 1):
            with pytest.raises(ValueError, match=f"control.{field}"):
                setattr(control, field, refused)
    lowest, highest = bounds(Solver, "target_density_error")
    control.target_density_error = np.float32(highest)
    assert type(control.target_density_error) is float


def test_good_assignments_keep_working(control):
    control.iterations, control.substeps, control.xsph = 7, 3, 0.0
    control.gravity_m_s2 = [0, -1, 0]
    assert control.gravity_m_s2 == (0.0, -1.0, 0.0)
    control.push = Push(np.array([0.1, 0.2, 0.3]), (0.0, 1.0, 0.0), 0.05)
    assert control.push.point_m == (0.1, 0.2, 0.3)
    control.push = None


@pytest.mark.parametrize(
    "point, velocity, radius, words",
    [
        ((0.0, NAN, 0.0), (0.0, 0.0, 0.0), 0.1, "control.push.point_m: expected three finite numbers"),
        ((0.0, 0.0, 0.0), (INF, 0.0, 0.0), 0.1, "control.push.velocity_m_s"),
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, "control.push.radius_m: expected a finite number in (0,"),
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), NAN, "control.push.radius_m"),
    ],
)
def test_a_bad_push_is_refused(point, velocity, radius, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        Push(point, velocity, radius)


@pytest.fixture
def plenty_of_memory(monkeypatch):
    monkeypatch.setattr(model, "available_memory_bytes", lambda: 8 << 30)


@pytest.mark.parametrize(
    "overrides, words",
    [
        (["fluid.max_particles=1000000000"], "key 'fluid.max_particles': 1,000,000,000 particles"),
        (["fluid.max_particles=2147483647"], "key 'fluid.max_particles': 2,147,483,647 particles"),
    ],
)
def test_a_memory_refusal_names_the_budget_when_it_is_the_budget(plenty_of_memory, overrides, words):
    with pytest.raises(SceneError, match=words) as refused:
        Model.from_scene(load_scene(small_dam_break(), overrides))
    assert "lower fluid.max_particles to 1,728 or 0" in str(refused.value)
    assert refused.value.key == "fluid.max_particles"


def test_a_memory_refusal_names_the_emitter_that_adds_the_most(plenty_of_memory):
    # A tall box so that the water fits its volume; the stream then decides the memory.
    scene = {
        "container": {"max_m": [40.0, 40.0, 40.0]},
        "fluid": {"spacing_m": 0.02},
        "time": {"max_substeps": 1000},
        "emitters": [
            {"position_m": [20.0, 39.0, 20.0], "direction": [0, -1, 0], "radius_m": 0.05, "end_s": 1.0},
            {"position_m": [10.0, 38.0, 10.0], "direction": [0, -1, 0], "radius_m": 1.0, "end_s": 1000.0},
        ],
    }
    with pytest.raises(SceneError, match=r"key 'emitters\[1\].end_s': [\d,]+ particles .* GiB") as refused:
        Model.from_scene(from_dict(scene))
    assert "emitters[1] adds" in str(refused.value)


def test_a_memory_refusal_from_the_command_line_names_it(plenty_of_memory):
    from pbf.app import cli

    args = cli.parse_args(["dam_break", "--stats-only", "--set", "fluid.max_particles=1000000000"])
    scene = cli.load(args)
    with pytest.raises(SceneError) as refused:
        Model.from_scene(scene)
    said = cli.schema.attribute(refused.value, cli.command_line_keys(args))
    assert str(said).startswith("command line --set fluid.max_particles=1000000000: key 'fluid.max_particles'")


def test_a_conflict_with_a_key_the_command_line_set_names_the_command_line():
    # The seed scene's time.max_cfl = 2 is fine without obstacles; --set obstacles=… brings the conflict.
    with pytest.raises(SceneError) as refused:
        load_scene("dam_break", ["obstacles=[{min_m=[0.5,0,0],max_m=[0.6,0.2,0.2]}]"])
    message = str(refused.value)
    assert (
        message.startswith("overrides obstacles=[{min_m=[0.5,0,0],max_m=[0.6,0.2,0.2]}]: does not agree with ")
        and "key 'time.max_cfl' = 2" in message
    )


@pytest.mark.parametrize(
    "key, table", [("obstacles.min_m=[0.1,0.3,0.1]", "obstacles"), ("emitters.rate_m3_s=1", "emitters")]
)
def test_a_list_of_tables_made_a_table_by_set_names_the_set(tmp_path, key, table):
    # A scene without obstacles: --set obstacles.min_m=… makes 'obstacles' a table where a list of tables
    # goes. The file never said 'obstacles', so the error is the command line's, not scene.toml's.
    own = tmp_path / "scene.toml"
    own.write_text((SCENES_DIR / "dam_break.toml").read_text())
    with pytest.raises(SceneError) as refused:
        load_scene(own, [key])
    message = str(refused.value)
    assert message.startswith(f"overrides {key}: key '{table}': expected a list of tables"), message
    assert "scene.toml" not in message


@pytest.fixture(scope="module")
def shared_simulation():
    from pbf.solver import Simulation

    return Simulation(small_dam_break(), quiet=True)


@pytest.mark.parametrize(
    "call, error, message",
    [
        (lambda sim: sim.step(1.5), TypeError, "step: frames: expected a whole number of frames, got 1.5"),
        (lambda sim: sim.step(True), TypeError, "step: frames: expected a whole number"),
        (lambda sim: sim.step(-1), ValueError, "step: frames: expected 0 or more, got -1"),
        (lambda sim: sim.substep(float("nan")), ValueError, r"substep: dt: expected a value in \(0, "),
        (lambda sim: sim.substep(1.0), ValueError, r"substep: dt: expected a value in \(0, 0.0166667\] s"),
        (lambda sim: sim.substep("0.01"), TypeError, "substep: dt: expected a number of seconds"),
    ],
)
def test_step_and_substep_refuse_bad_arguments(shared_simulation, call, error, message):
    sim = shared_simulation
    before = sim.positions()
    with pytest.raises(error, match=message):
        call(sim)
    assert np.array_equal(sim.positions(), before)
