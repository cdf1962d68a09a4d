"""restore() takes a Snapshot of this scene only, and whatever Python hands it the emitters cannot
write past the particle budget; emitters that cannot fit the container are refused at load, and a
drowned nozzle pauses instead of pushing."""

import dataclasses
import math

import numpy as np
import pytest

from pbf import SceneError, Simulation
from pbf.scene import from_dict

SPACING = 0.02


def pour(**emitter):
    """A 3 × 3 nozzle over a small box: 21 layers of 9 particles from t = 0.1 s to 0.5 s."""
    return {
        "name": "pour",
        "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.4, 0.3]},
        "fluid": {"spacing_m": SPACING},
        "emitters": [
            {
                "position_m": [0.15, 0.3, 0.15],
                "direction": [0.0, -1.0, 0.0],
                "radius_m": 0.03,
                "speed_m_s": 1.0,
                "start_s": 0.1,
                "end_s": 0.5,
                **emitter,
            }
        ],
    }


@pytest.fixture(scope="module")
def poured():
    """One Simulation for the module (Taichi compiles once): a pour part-way, and its snapshot."""
    sim = Simulation(pour(), quiet=True)
    sim.step(15)
    return sim, sim.snapshot()


def inside(sim) -> bool:
    x = sim.positions()
    lower, upper = np.array(sim.scene.container.min_m), np.array(sim.scene.container.max_m)
    return bool(np.isfinite(x).all() and (x >= lower - 1e-6).all() and (x <= upper + 1e-6).all())


@pytest.mark.parametrize("given", [None, 3, {"positions_m": np.zeros((1, 3))}, np.zeros((4, 3)), "snapshot"])
def test_anything_but_a_snapshot_is_a_type_error(poured, given):
    sim, _ = poured
    with pytest.raises(TypeError, match=f"restore: expected a pbf.solver.Snapshot .*, got {type(given).__name__}$"):
        sim.restore(given)


def changed(snapshot, **changes):
    return dataclasses.replace(snapshot, **changes)


@pytest.mark.parametrize(
    "change, error, words",
    [
        (
            lambda s: changed(s, emitted_layers=(0,)),
            ValueError,
            ("the emitters have still to add (emitted_layers = (0,)) exceed the 147 this scene allocates"),
        ),
        (lambda s: changed(s, emitted_layers=(-5,)), ValueError, "emitted_layers[0] = -5; allowed: 0 to the 21 layers"),
        (lambda s: changed(s, emitted_layers=(22,)), ValueError, "emitted_layers[0] = 22"),
        (
            lambda s: changed(s, emitted_layers=(1, 2)),
            ValueError,
            ("2 emitted layer counts for the 1 emitters of this scene (a snapshot of another scene?)"),
        ),
        (lambda s: changed(s, emitted_layers=(1.5,)), TypeError, "emitted_layers[0]: expected a whole number"),
        (lambda s: changed(s, emitted_layers=None), TypeError, "expected emitted_layers as a tuple"),
        (
            lambda s: changed(s, positions_m=np.full_like(s.positions_m, np.nan)),
            ValueError,
            "positions_m of particle 0 is [nan, nan, nan]; expected finite numbers",
        ),
        (
            lambda s: changed(s, velocities_m_s=np.full_like(s.velocities_m_s, np.inf)),
            ValueError,
            "velocities_m_s of particle 0 is [inf, inf, inf]",
        ),
        (lambda s: changed(s, velocities_m_s=np.full_like(s.velocities_m_s, 1e6)), ValueError, "faster than the"),
        (lambda s: changed(s, positions_m=s.positions_m.astype(np.float64) * 1e300), ValueError, "expected finite"),
        (
            lambda s: changed(s, fields={"multiplier": np.full(len(s.positions_m), np.nan, np.float32)}),
            ValueError,
            "fields['multiplier'] of particle 0 is nan",
        ),
        (lambda s: changed(s, fields=[1, 2]), TypeError, "expected fields as a dict"),
        (
            lambda s: changed(s, time_s=math.nan),
            ValueError,
            "expected time_s as a finite number of seconds ≥ 0, got nan",
        ),
        (lambda s: changed(s, time_s=-1.0), ValueError, "time_s"),
        (lambda s: changed(s, time_s="soon"), TypeError, "time_s as a number of seconds"),
        (lambda s: changed(s, piston_time_s=math.inf), ValueError, "piston_time_s as a finite number"),
        (lambda s: changed(s, frame=-1), ValueError, "frame as a whole number ≥ 0"),
        (lambda s: changed(s, frame=1.5), TypeError, "frame as a whole number"),
        (
            lambda s: changed(s, positions_m=np.array([["a", "b", "c"]] * len(s.positions_m))),
            TypeError,
            "positions_m: expected an array of real numbers",
        ),
        (lambda s: changed(s, positions_m=[[0.1, 0.1], [0.1, 0.1, 0.1]]), TypeError, "positions_m: expected an array"),
        (
            lambda s: changed(s, positions_m=s.positions_m + 5.0),
            ValueError,
            "lies outside this scene's container [0.0, 0.0, 0.0]–[0.3, 0.4, 0.3] m (a snapshot of another scene?)",
        ),
    ],
)
def test_a_snapshot_that_does_not_fit_is_refused_and_changes_nothing(poured, change, error, words):
    sim, snapshot = poured
    sim.restore(snapshot)
    with pytest.raises(error) as refused:
        sim.restore(change(snapshot))
    assert words in str(refused.value) and "\n" not in str(refused.value), str(refused.value)
    assert sim.particle_count == len(snapshot.positions_m) and sim.time_s == snapshot.time_s
    sim.step(1)
    assert inside(sim)


def test_a_snapshot_of_another_scene_is_refused(poured):
    sim, _ = poured
    other = Simulation(
        {
            "container": {"max_m": [2.0, 2.0, 2.0]},
            "fluid": {"spacing_m": 0.05, "blocks": [{"min_m": [1.0, 1.0, 1.0], "max_m": [1.5, 1.5, 1.5]}]},
        },
        quiet=True,
    )
    with pytest.raises(ValueError, match="more than the 147 this scene allocates"):
        sim.restore(other.snapshot())
    few = other.snapshot()
    few = changed(
        few,
        positions_m=few.positions_m[:9],
        velocities_m_s=few.velocities_m_s[:9],
        fields={name: values[:9] for name, values in few.fields.items()},
    )
    with pytest.raises(ValueError, match="outside this scene's container"):
        sim.restore(few)


def test_the_emitters_append_cannot_pass_the_budget(poured):
    # Bounds-safe by construction: even with restore() bypassed, the kernel stops at the allocation.
    sim, snapshot = poured
    sim.restore(snapshot)
    sim.emitters.emitted = [0]  # every layer counted as not yet emitted
    sim.step(40)
    assert sim.particle_count == sim.model.capacity == 147
    assert inside(sim)


def test_restore_of_its_own_snapshot_still_replays(poured):
    sim, snapshot = poured
    sim.restore(snapshot)
    sim.step(10)
    first = sim.positions()
    sim.restore(snapshot)
    sim.step(10)
    assert np.array_equal(sim.positions(), first)


def test_an_emitter_that_cannot_fit_the_container_is_refused_naming_it():
    # 128,000 particles into a box that holds 1,728 at the spacing: refused at load, not run into a blow-up.
    box = {
        "container": {"max_m": [0.4, 0.4, 0.4]},
        "fluid": {"spacing_m": 1 / 30},
        "emitters": [{"position_m": [0.2, 0.25, 0.2], "direction": [0, -1, 0], "radius_m": 0.1, "end_s": 100.0}],
    }
    with pytest.raises(
        SceneError,
        match=r"<dict>: key 'emitters\[0\].end_s' = 100 s adds [\d,]+ particles .* more "
        r"than the 1,728 .* the container holds outside the obstacles .* allowed: "
        r"end_s < [\d.]+ s$",
    ) as refused:
        from_dict(box)
    # The end_s it names fits.
    allowed = float(str(refused.value).rsplit("end_s < ", 1)[1].split(" s")[0]) - 1e-3
    fitted = from_dict({**box, "emitters": [{**box["emitters"][0], "end_s": allowed}]})
    assert fitted.emitted_count <= 1728
    # Obstacles take room too; a second emitter is named when it is the one that overflows.
    two = {
        **box,
        "emitters": [
            {**box["emitters"][0], "end_s": allowed},
            {**box["emitters"][0], "position_m": [0.2, 0.15, 0.2], "end_s": 0.1},
        ],
    }
    with pytest.raises(SceneError, match=r"key 'emitters\[1\].end_s' = 0.1 s .* allowed: no emitter here"):
        from_dict(two)


@pytest.mark.slow
def test_a_drowned_nozzle_pauses_instead_of_pushing():
    # A nozzle 3.5 spacings above the floor of a small box: the water soon reaches it. Its layers
    # then pause; the water stays near rest density and inside the box.
    scene = {
        "name": "flood",
        "container": {"min_m": [0, 0, 0], "max_m": [0.2, 0.3, 0.2]},
        "fluid": {"spacing_m": SPACING},
        "emitters": [
            {"position_m": [0.1, 0.07, 0.1], "direction": [0, -1, 0], "radius_m": 0.03, "speed_m_s": 1.0, "end_s": 1.5}
        ],
    }
    sim = Simulation(scene, quiet=True)
    sim.step(90)
    stats = sim.stats()
    emitted = sim.emitters.emitted[0] * len(sim.emitters.sites[0])
    assert sim.particle_count < 0.8 * emitted  # layers were skipped while the nozzle was under water
    top = sim.positions()[:, 1].max()
    assert top > 0.07 - SPACING  # because the water had reached the nozzle
    assert stats["max_density_error"] < 0.05 and stats["max_speed_m_s"] < 2.0
    assert inside(sim)


def test_arrays_of_two_counts_are_refused_naming_the_count_the_simulation_holds(poured):
    sim, snapshot = poured
    count = len(sim.positions())
    with pytest.raises(ValueError) as refused:
        sim.restore(changed(snapshot, positions_m=snapshot.positions_m[:10]))
    message = str(refused.value)
    assert f"holds {count:,} now" in message and f"got (10, 3) and ({len(snapshot.velocities_m_s)}, 3)" in message
