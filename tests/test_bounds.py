"""Every number has a lower and an upper bound, derived quantities are checked in exact arithmetic
before anything is allocated, and what is allowed runs without NaN, inf or overflow warnings."""

import copy
import dataclasses
import math
import sys
import typing
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pbf import Scene, SceneError, Simulation
from pbf.scene import FLOAT32_SAFE, MAX_TABLES, POSITION_REACH_SPACINGS, Fluid, Solver, Time, Vec3, from_dict
from pbf.solver import Model, grid, model
from scenes import small_dam_break

FIELDS = {}
"""Every key of the schema: dotted name → (annotation, its check)."""


def _collect(cls, prefix=""):
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):
            continue
        if dataclasses.is_dataclass(hints[f.name]):
            _collect(hints[f.name], f"{prefix}{f.name}.")
        elif typing.get_origin(hints[f.name]) is tuple and dataclasses.is_dataclass(typing.get_args(hints[f.name])[0]):
            _collect(typing.get_args(hints[f.name])[0], f"{prefix}{f.name}[0].")
        else:
            FIELDS[prefix + f.name] = (hints[f.name], f.metadata["check"])


_collect(Scene)
NUMBERS = {k: v for k, v in FIELDS.items() if v[0] in (int, float)}
DERIVED = {
    "gravity_m_s2",
    "container.min_m",
    "container.max_m",
    "fluid.blocks[0].min_m",
    "fluid.blocks[0].max_m",
    "fluid.blocks[0].velocity_m_s",
    "obstacles[0].min_m",
    "obstacles[0].max_m",
    "emitters[0].position_m",
    "emitters[0].direction",
    "camera.position_m",
    "camera.look_at_m",
    "bodies[0].size_m",
    "bodies[0].position_m",
    "bodies[0].velocity_m_s",
}
"""The three-number keys bounded by what they must agree with (container and spacing, the substeps
a frame can take, the camera's distance from the box; a direction is normalised whatever its length)
rather than by a fixed range."""


NOZZLE = {"position_m": [0.6, 0.6, 0.2], "direction": [0.0, -1.0, 0.0], "radius_m": 0.05, "end_s": 0.5}
BODY = {"size_m": [0.05, 0.05, 0.05], "density_kg_m3": 500.0, "position_m": [0.6, 0.2, 0.2]}


def base_scene():
    """The small dam break with a nozzle pouring in and a floating box, so that every kind of key has a table to go
    in."""
    scene = small_dam_break()
    scene["emitters"] = [dict(NOZZLE)]
    scene["bodies"] = [dict(BODY)]
    return scene


def set_key(dotted, value, scene=None):
    """``scene`` (a copy of :func:`base_scene` by default) with ``dotted`` set, e.g.
    ``fluid.blocks[0].velocity_m_s``."""
    scene = copy.deepcopy(base_scene()) if scene is None else scene
    *tables, name = dotted.split(".")
    target = scene
    for part in tables:
        table, _, index = part.partition("[")
        target = target.setdefault(table, {})
        if index:
            target = target[int(index.rstrip("]"))]
    target[name] = value
    return scene


def test_every_number_has_both_bounds():
    unbounded = [k for k, (_, check) in NUMBERS.items() if not hasattr(check, "bounds")]
    assert not unbounded, f"numeric keys without a lower and an upper bound: {unbounded}"
    vectors = {
        k
        for k, (annotation, check) in FIELDS.items()
        if annotation in (Vec3, Vec3 | None) and not hasattr(check, "bounds")
    }
    assert vectors == DERIVED


@pytest.mark.parametrize("dotted", sorted(NUMBERS))
@settings(max_examples=20, deadline=None)
@given(value=st.floats() | st.integers(-(10**40), 10**40) | st.integers(-10, 10))
def test_each_number_is_refused_outside_its_bounds_only(dotted, value):
    annotation, check = NUMBERS[dotted]
    lowest, highest = check.bounds
    typed = isinstance(value, int) or annotation is float
    inside = typed and math.isfinite(value) and lowest <= value <= highest and check(annotation(value)) is None
    try:
        from_dict(set_key(dotted, value), "fuzz.toml")
    except SceneError as error:
        message = str(error)
        assert message.startswith("fuzz.toml: ") and len(message) < 500
        if not inside:
            assert error.key == dotted and "expected" in message
        else:  # only what the key must agree with may refuse it
            assert not (error.key == dotted and "expected a" in message), message
    else:
        assert inside


def test_derived_float32_figures_stay_in_range():
    # The figures of the bounds comment in pbf/scene/schema.py, from the bounds themselves.
    s_min, s_max = Fluid.__dataclass_fields__["spacing_m"].metadata["check"].bounds
    r_min, r_max = Solver.__dataclass_fields__["kernel_ratio"].metadata["check"].bounds
    dt_frame_min = Time.__dataclass_fields__["frame_dt_s"].metadata["check"].bounds[0]
    most_substeps = Time.__dataclass_fields__["max_substeps"].metadata["check"].bounds[1]
    rho_max = Fluid.__dataclass_fields__["rest_density_kg_m3"].metadata["check"].bounds[1]
    h_min, h_max = r_min * s_min, r_max * s_max
    sigma = 8 / math.pi
    assert sigma / h_min**5 < FLOAT32_SAFE and h_max**5 < FLOAT32_SAFE
    dt_min = dt_frame_min / most_substeps
    box_speed = 2 * math.sqrt(3) * POSITION_REACH_SPACINGS * s_max / dt_min
    assert box_speed**2 < FLOAT32_SAFE
    assert rho_max * h_max**2 / dt_min**2 < FLOAT32_SAFE
    assert FLOAT32_SAFE < float(np.finfo(np.float32).max) / 1e6


@pytest.mark.parametrize(
    "dotted, value, message",
    [
        ("container.max_m", [1e6, 1e6, 1e6], "key 'container.max_m': a wall at 1e+06 m lies 3.00003e+07 spacings"),
        ("container.min_m", [-1e308, 0.0, 0.0], "key 'container.min_m': a wall at 1e+308 m"),
        ("fluid.spacing_m", 1e-300, "key 'fluid.spacing_m': expected a value in [0.0001, 100]"),
        ("gravity_m_s2", [0.0, -1e300, 0.0], "key 'gravity_m_s2': |g| = 1e+300 m/s²"),
        ("gravity_m_s2", [1e308, 1e308, 1e308], "key 'gravity_m_s2': |g| = 1.73205e+308 m/s²"),
        ("fluid.blocks[0].velocity_m_s", [1e308, 0.0, 0.0], "key 'fluid.blocks[0].velocity_m_s': 1e+308 m/s"),
        ("time.frame_dt_s", 1e-300, "key 'time.frame_dt_s': expected a value in [0.0001, 1]"),
        ("solver.iterations", 10**9, "key 'solver.iterations': expected a value in [1, 100]"),
        ("time.substeps", 10**9, "key 'time.substeps': expected a value in [1, 1000]"),
        ("time.max_substeps", 10**9, "key 'time.max_substeps': expected a value in [1, 1000]"),
        ("fluid.rest_density_kg_m3", 10**400, "expected a finite number, got ~1e400"),
    ],
)
def test_values_past_what_the_machine_holds(dotted, value, message):
    with pytest.raises(SceneError) as error:
        from_dict(set_key(dotted, value), "test.toml")
    assert message in str(error.value), str(error.value)


def test_initial_speed_is_bounded_by_what_a_frame_can_follow():
    scene = from_dict(small_dam_break())
    fall = 9.81 * scene.time.frame_dt_s
    limit = scene.fastest_followed_m_s - fall
    at_limit = set_key(
        "fluid.blocks", [{"min_m": [0, 0, 0], "max_m": [0.4, 0.4, 0.4], "velocity_m_s": [0.999 * limit, 0, 0]}]
    )
    from_dict(at_limit)
    at_limit["fluid"]["blocks"][0]["velocity_m_s"] = [1e308, 0, 0]
    with pytest.raises(SceneError, match=r"'fluid.blocks\[0\].velocity_m_s': 1e\+308 m/s .* raise time.max_substeps"):
        from_dict(at_limit)


def calls_made(work) -> int:
    """How many Python and C functions ``work()`` calls: a count of work that a busy machine cannot change,
    where a clock would."""
    count = 0

    def tally(frame, event, arg):
        nonlocal count
        count += event in ("call", "c_call")

    sys.setprofile(tally)
    try:
        work()
    finally:
        sys.setprofile(None)
    return count


def test_many_blocks_are_checked_in_linear_work_and_too_many_refused():
    def blocks(count):
        return [{"min_m": [0.001 * i, 0.0, 0.0], "max_m": [0.001 * i + 0.001, 0.01, 0.01]} for i in range(count)]

    scene = {"container": {"max_m": [10.0, 1.0, 1.0]}, "fluid": {"spacing_m": 0.001}}

    def check(count):
        return from_dict({**scene, "fluid": {**scene["fluid"], "blocks": blocks(count)}})

    assert check(MAX_TABLES).particle_count == 100_000
    # The overlap check compares each block with all earlier ones in one vectorised call, so each block
    # adds the same work: the second 450 blocks cost what the first 450 did (a pair-by-pair loop in
    # Python would cost more than twice as much). Calls are counted, not timed: a clock fails on a busy
    # machine, and the speed itself is a benchmark's to show.
    first, middle, last = (calls_made(lambda count=count: check(count)) for count in (100, 550, MAX_TABLES))
    assert last - middle <= 1.01 * (middle - first), (first, middle, last)
    with pytest.raises(SceneError, match=f"key 'fluid.blocks': expected at most {MAX_TABLES} tables .* got 10,000"):
        check(10_000)


@pytest.fixture
def plenty_of_memory(monkeypatch):
    """A machine with memory to spare, so that the index checks behind the memory check are reached."""
    monkeypatch.setattr(model, "available_memory_bytes", lambda: 1 << 62)


def test_particles_times_neighbour_slots_must_fit_int32(plenty_of_memory):
    most = model.INT32_MAX // grid.SLOTS
    scene = from_dict(small_dam_break())
    model._check_indices(scene, most, 1000)
    with pytest.raises(SceneError, match=f"{most + 1:,} particles × {grid.SLOTS} neighbour slots .* at most {most:,}"):
        model._check_indices(scene, most + 1, 1000)
    # 2²⁵ particles (a 256 × 256 × 512 lattice) through the Model, which allocates nothing.
    big = {
        "container": {"max_m": [3.0, 3.0, 6.0]},
        "fluid": {"spacing_m": 0.01, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [2.56, 2.56, 5.12]}]},
    }
    assert from_dict(big).particle_count == 2**25
    with pytest.raises(SceneError, match="key 'fluid.spacing_m': 33,554,432 particles"):
        Model.from_scene(from_dict(big))


def test_a_container_of_a_million_metres_is_refused_for_its_cell_count(plenty_of_memory):
    # At 100 m spacing the walls are within float32's reach; the grid of h/2 cells is not int32's.
    scene = {
        "container": {"max_m": [1e6, 1e6, 1e6]},
        "fluid": {"spacing_m": 100.0, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [1000.0, 1000.0, 1000.0]}]},
        "time": {"frame_dt_s": 1.0},
    }
    with pytest.raises(SceneError, match=r"key 'container.max_m': the neighbour grid .* has [\d,]+ cells, more than"):
        Model.from_scene(from_dict(scene))


def assert_runs_cleanly(scene, frames):
    """Build and step ``scene``: finite statistics, read-outs and pressures, particles in the box,
    and no NumPy floating-point warning on the way."""
    with np.errstate(all="raise"), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".* need .* substeps per frame", category=RuntimeWarning)
        sim = Simulation(scene, quiet=True)
        sim.step(frames)
        stats = sim.stats()
        x, v, p = sim.positions(), sim.velocities(), sim.pressures()
    assert all(math.isfinite(value) for value in stats.values() if isinstance(value, float)), stats
    assert np.isfinite(x).all() and np.isfinite(v).all() and np.isfinite(p).all()
    lower, upper = np.array(sim.scene.container.min_m), np.array(sim.scene.container.max_m)
    assert (x >= lower).all() and (x <= upper).all()


def test_the_fastest_allowed_start_runs_cleanly():
    # The shortest frame, the strongest gravity and the fastest block the substep cap allows.
    scene = small_dam_break()
    scene["time"] = {"frame_dt_s": 1e-4, "substeps": 1, "max_substeps": 20}
    followed = from_dict(scene).fastest_followed_m_s
    scene["gravity_m_s2"] = [0.0, -0.5 * followed / 1e-4, 0.0]
    scene["fluid"]["blocks"][0]["velocity_m_s"] = [0.499 * followed, 0.0, 0.0]
    assert_runs_cleanly(scene, frames=2)


@pytest.mark.slow
@pytest.mark.parametrize(
    "scene",
    [
        # The finest spacing at the edge of float32's reach, with the softest λ and the strongest terms.
        {
            "container": {"min_m": [6.5512] * 3, "max_m": [6.5536] * 3},
            "fluid": {"spacing_m": 1e-4, "blocks": [{"min_m": [6.5512] * 3, "max_m": [6.552] * 3}]},
            "solver": {"scorr_k": 1.0, "kernel_ratio": 4.0, "expert": {"relaxation": 1e-6}},
            "vorticity": {"epsilon": 1.0},
            "viscosity": {"xsph": 1.0},
        },
        # The coarsest spacing, far from the origin, densest and stiffest.
        {
            "container": {"min_m": [-6553600.0] * 3, "max_m": [-6551600.0] * 3},
            "fluid": {
                "spacing_m": 100.0,
                "rest_density_kg_m3": 1e5,
                "blocks": [{"min_m": [-6553600.0] * 3, "max_m": [-6552600.0] * 3}],
            },
            "solver": {"kernel_ratio": 1.5, "scorr_k": 1.0, "expert": {"relaxation": 100.0}},
            "time": {"frame_dt_s": 1.0, "max_substeps": 1000},
        },
    ],
)
def test_extreme_allowed_scales_run_cleanly(scene):
    assert_runs_cleanly(scene, frames=1)


@settings(max_examples=200, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(sorted(k for k in FIELDS if not k.startswith("obstacles"))),
        st.none()
        | st.booleans()
        | st.integers()
        | st.floats()
        | st.text(max_size=8)
        | st.lists(st.floats() | st.integers(), max_size=4),
        max_size=4,
    )
)
def test_any_values_give_a_scene_or_a_scene_error(changes):
    scene = base_scene()
    for dotted, value in changes.items():
        set_key(dotted, value, scene)
    try:
        Model.from_scene(from_dict(scene))
    except SceneError as error:
        assert len(str(error)) < 500 and "np." not in str(error)
