"""Properties of every way in, tried with random input (Hypothesis): a scene dict or --set override
through load_scene, an assignment to sim.control, a Snapshot through restore(). Each ends in a
documented error with a one-line message, or in a run with finite statistics and every particle
inside the container. Examples are few and scenes tiny; one Simulation serves each test where the
scene stays the same (Taichi compiles a scene's kernels once)."""

import copy
import dataclasses
import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pbf import SceneError, Simulation
from pbf.scene import load_scene
from pbf.solver import Control, Push, Snapshot

SPACING = 0.05


def tiny():
    """64 particles in a 0.3 m box, with a nozzle that adds 8 layers of 5: every kind of key has a table."""
    return {
        "name": "tiny",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.4, 0.3]},
        "fluid": {"spacing_m": SPACING, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.2, 0.2, 0.2]}]},
        "emitters": [
            {
                "position_m": [0.2, 0.3, 0.2],
                "direction": [0.0, -1.0, 0.0],
                "radius_m": 0.05,
                "speed_m_s": 1.0,
                "start_s": 0.0,
                "end_s": 0.35,
            }
        ],
        "time": {"substeps": 2},
        "solver": {"iterations": 4},
    }


def one_line(error: BaseException) -> None:
    message = str(error)
    assert message and "\n" not in message and len(message) < 600 and "np.float" not in message, message


def runs_cleanly(sim, frames: int = 1) -> None:
    """Step on: finite statistics, finite read-outs, every particle inside the container."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".* need .* substeps per frame", category=RuntimeWarning)
        sim.step(frames)
    stats = sim.stats()
    assert all(math.isfinite(v) for v in stats.values() if isinstance(v, float)), stats
    x, v = sim.positions(), sim.velocities()
    lower, upper = np.array(sim.scene.container.min_m), np.array(sim.scene.container.max_m)
    assert np.isfinite(v).all()
    assert np.isfinite(x).all() and (x >= lower - 1e-5).all() and (x <= upper + 1e-5).all()
    assert sim.particle_count <= sim.model.capacity


# ----------------------------------------------------------------------------- scenes

KEYS = [
    "gravity_m_s2",
    "fluid.spacing_m",
    "fluid.max_particles",
    "fluid.rest_density_kg_m3",
    "time.substeps",
    "time.frame_dt_s",
    "time.max_cfl",
    "time.max_substeps",
    "solver.iterations",
    "solver.kernel_ratio",
    "solver.target_density_error",
    "solver.divergence_iterations",
    "viscosity.xsph",
    "vorticity.epsilon",
    "emitters[0].end_s",
    "emitters[0].speed_m_s",
    "emitters[0].radius_m",
    "emitters[0].position_m",
    "emitters[0].direction",
    "fluid.blocks[0].max_m",
    "fluid.blocks[0].velocity_m_s",
    "container.max_m",
]
"""Keys that change what runs (the view's keys are tested with the command line)."""
NUMBER = (
    st.floats(allow_nan=True, allow_infinity=True)
    | st.floats(-2.0, 2.0)
    | st.integers(-3, 200)
    | st.integers(-(10**20), 10**20)
)
VALUE = (
    NUMBER
    | st.lists(NUMBER, min_size=0, max_size=4)
    | st.booleans()
    | st.none()
    | st.text(max_size=6)
    | st.lists(st.floats(0.0, 0.4), min_size=3, max_size=3)
)


def set_key(scene: dict, dotted: str, value) -> None:
    *tables, name = dotted.split(".")
    target = scene
    for part in tables:
        table, _, index = part.partition("[")
        target = target.setdefault(table, {})
        if index:
            target = target[int(index.rstrip("]"))]
    target[name] = value


@settings(max_examples=120, deadline=None)
@given(st.dictionaries(st.sampled_from(KEYS), VALUE, max_size=3))
def test_random_scene_dicts_load_or_are_refused_in_one_line(changes):
    scene = tiny()
    for dotted, value in changes.items():
        set_key(scene, dotted, copy.deepcopy(value))
    try:
        loaded = load_scene(scene)
    except SceneError as error:
        one_line(error)
        return
    assert loaded.particle_count + loaded.emitted_count <= loaded.particle_capacity


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(KEYS), st.text(max_size=12) | NUMBER.map(repr))
def test_random_overrides_load_or_are_refused_naming_the_command_line(dotted, text):
    assignment = f"{dotted.replace('[0]', '')}={text}"
    try:
        load_scene(tiny(), [assignment])
    except SceneError as error:
        one_line(error)
        assert str(error).startswith("overrides") or str(error).startswith("<dict>"), str(error)


@pytest.mark.slow  # each new scene compiles its kernels anew: 8-18 s an example on a shared 2-core box
@settings(max_examples=3, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    st.fixed_dictionaries(
        {
            "solver.iterations": st.integers(1, 10),
            "time.substeps": st.integers(1, 4),
            "viscosity.xsph": st.floats(0.0, 1.0),
            "vorticity.epsilon": st.floats(0.0, 1.0),
            "emitters[0].end_s": st.floats(0.01, 0.35),
            "fluid.blocks[0].velocity_m_s": st.lists(st.floats(-5.0, 5.0), min_size=3, max_size=3),
        }
    )
)
def test_a_random_scene_that_loads_runs_cleanly(changes):
    # In the default suite, the scenes that load are run by the snapshot property below (one Simulation);
    # this one builds a Simulation per example.
    scene = tiny()
    for dotted, value in changes.items():
        set_key(scene, dotted, value)
    try:
        sim = Simulation(scene, quiet=True)
    except SceneError as error:
        one_line(error)
        return
    runs_cleanly(sim, 2)


# ----------------------------------------------------------------------------- the control


@pytest.fixture(scope="module")
def sim():
    return Simulation(tiny(), quiet=True)


FIELDS = [f.name for f in dataclasses.fields(Control)]
SETTING = (
    NUMBER
    | st.booleans()
    | st.none()
    | st.text(max_size=4)
    | st.lists(NUMBER, min_size=3, max_size=3)
    | st.builds(
        lambda p, v, r: (p, v, r),
        st.lists(NUMBER, min_size=3, max_size=3),
        st.lists(NUMBER, min_size=3, max_size=3),
        NUMBER,
    )
)


# In the default run: an example that sets control.divergence_iterations runs the kernels compiled for
# any count (the count is data), where an unrolled count compiled anew for each value drawn.
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from(FIELDS + ["iteration"]), SETTING), min_size=1, max_size=4))
def test_random_control_assignments_are_refused_at_once_or_run_cleanly(sim, assignments):
    sim.reset()
    for field, value in assignments:
        if field == "push" and isinstance(value, tuple) and len(value) == 3 and isinstance(value[0], list):
            try:
                value = Push(*value)
            except (TypeError, ValueError) as error:
                one_line(error)
                continue
        before = dataclasses.asdict(sim.control)
        try:
            setattr(sim.control, field, value)
        except (TypeError, ValueError, AttributeError) as error:
            one_line(error)
            assert f"control.{field}" in str(error)
            assert dataclasses.asdict(sim.control) == before
    # A substep, not a frame: the control may ask for 1,000 substeps of 100 iterations each.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".* need .* substeps per frame", category=RuntimeWarning)
        sim.substep()
    sim.control = Control.from_scene(sim.scene)
    runs_cleanly(sim, 1)


# ----------------------------------------------------------------------------- snapshots


def particle_arrays(count: int, elements):
    return st.lists(st.lists(elements, min_size=3, max_size=3), min_size=count, max_size=count).map(
        lambda rows: np.array(rows, dtype=np.float64).reshape(-1, 3)
    )


INSIDE = st.floats(0.0, 0.3)
SPEED = st.floats(-3.0, 3.0)
ANY = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def snapshots(draw):
    """Half plausible (inside the box, moderate speeds, layers that fit), half anything."""
    count = draw(st.integers(0, 110))  # the tiny scene allocates 64 + 40 = 104
    if not draw(st.booleans()):
        return Snapshot(
            draw(particle_arrays(count, INSIDE)),
            draw(particle_arrays(count, SPEED)),
            draw(st.floats(0.0, 1.0)),
            draw(st.integers(0, 100)),
            draw(st.just(()) | st.tuples(st.integers(0, 8))),
            draw(st.none() | st.floats(0.0, 10.0)),
            draw(st.just({}) | st.just({"multiplier": np.zeros(count, np.float32)})),
        )
    positions = draw(particle_arrays(count, ANY | INSIDE))
    velocities = draw(particle_arrays(count, ANY | SPEED))
    layers = draw(
        st.one_of(st.just(()), st.tuples(st.integers(-10, 12)), st.tuples(st.integers(0, 9), st.integers(0, 9)))
    )
    fields = draw(
        st.just({})
        | st.just({"multiplier": np.full(count, np.nan, np.float32)})
        | st.just({"pressure_sum": np.zeros(count, np.float32)})
    )
    return Snapshot(positions, velocities, draw(ANY), draw(st.integers(-2, 100)), layers, draw(st.none() | ANY), fields)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(snapshots() | st.sampled_from([None, 3, "x", {}, np.zeros((2, 3))]))
def test_random_snapshots_are_refused_in_one_line_or_run_cleanly(sim, snapshot):
    sim.reset()
    try:
        sim.restore(snapshot)
    except (TypeError, ValueError) as error:
        one_line(error)
        assert str(error).startswith("restore: ")
        return
    runs_cleanly(sim, 2)
