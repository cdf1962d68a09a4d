"""White water (``pbf.app.white_water``): spray, foam and bubbles where the water splashes and none where it
rests, within its budget, the same on every run, drawn in the surface style and written by ``--export``,
and never a change to the simulation. The seed scene's splash is watched by one Simulation, and a second
replays it."""

import numpy as np
import pytest
from plyfile import PlyData

from pbf import Simulation
from pbf.app import cli
from pbf.app.export import to_export_axes
from pbf.app.render import SceneRenderer
from pbf.app.white_water import BUBBLE, FOAM, SPRAY, WhiteWater, budget_of
from pbf.scene import SceneError, from_dict
from scenes import column_scene, small_dam_break

SIZE = (160, 90)
SPLASH_FRAMES = 25
"""The seed's front has hit the far wall and climbs it then (t = 0.42 s)."""


def seed(*overrides):
    return Simulation("dam_break", quiet=True, overrides=["render.style=surface", *overrides])


@pytest.fixture(scope="module")
def splashing():
    """The seed scene at SPLASH_FRAMES with its white water, the counts per frame and a snapshot of its
    start."""
    sim = seed()
    start = sim.snapshot()
    water = WhiteWater(sim)
    water.sync()
    counts = []
    for _ in range(SPLASH_FRAMES):
        sim.step()
        water.sync()
        counts.append(water.counts())
    return sim, water, counts, start


@pytest.fixture(scope="module")
def replay(splashing):
    """The splash replayed from its start by a second Simulation: first without white water (its
    positions), then with it (its diffuse particles, and a snapshot at the end). Kernels compile per
    object, so the tests that need a second run share this one."""
    _sim, _water, _counts, start = splashing
    again = seed()
    again.restore(start)
    again.step(SPLASH_FRAMES)
    positions = again.positions()
    again.restore(start)
    water = WhiteWater(again)
    water.sync()
    for _ in range(SPLASH_FRAMES):
        again.step()
        water.sync()
    return again, water, positions, water.arrays(), again.snapshot()


def test_a_splash_makes_white_water_of_every_kind(splashing):
    _sim, water, counts, _start = splashing
    alive = [live for live, _waiting in counts]
    assert alive[0] == 0  # the block has not landed yet: free fall traps no air
    assert alive[-1] > 1000
    diffuse = water.arrays()
    kinds = np.bincount(diffuse["kind"], minlength=3)
    assert kinds[SPRAY] > 0 and kinds[FOAM] > 0 and kinds[BUBBLE] > 0, kinds
    assert np.isfinite(diffuse["positions"]).all() and np.isfinite(diffuse["velocities"]).all()


def test_spray_flies_and_foam_rides_the_water(splashing):
    sim, water, _counts, _start = splashing
    diffuse = water.arrays()
    container = sim.scene.container
    assert (diffuse["positions"] >= np.array(container.min_m) - 1e-6).all()
    assert (diffuse["positions"] <= np.array(container.max_m) + 1e-6).all()
    # Spray is where the water is not: farther from the nearest fluid particle than foam is.
    fluid = sim.positions()
    nearest = [np.min(np.linalg.norm(fluid - p, axis=1)) for p in diffuse["positions"]]
    nearest = np.array(nearest)
    kind = diffuse["kind"]
    assert np.median(nearest[kind == SPRAY]) > np.median(nearest[kind == BUBBLE])


def test_white_water_never_changes_the_simulation(splashing, replay):
    sim, _water, _counts, _start = splashing
    _again, _other, positions_without, _arrays, _end = replay
    assert np.array_equal(positions_without, sim.positions())


def test_the_same_splash_gives_the_same_white_water_bit_for_bit(splashing, replay):
    _sim, water, _counts, _start = splashing
    _again, _other, _positions, arrays, _end = replay
    first = water.arrays()
    assert first["positions"].shape[0] > 1000
    for name in first:
        assert first[name].tobytes() == arrays[name].tobytes(), name


def test_a_tank_at_rest_has_no_white_water():
    sim = Simulation({**column_scene(height_m=0.2), "time": {"settle_s": 0.5}}, quiet=True)
    water = WhiteWater(sim)
    water.sync()
    for _ in range(20):
        sim.step()
        water.sync()
        assert water.counts() == (0, 0)


def test_the_budget_is_never_exceeded_and_emission_waits_when_it_is_full(splashing, replay):
    _sim, _water, _counts, start = splashing
    again = replay[0]
    budget = 40
    again.restore(start)
    water = WhiteWater(again, budget=budget)
    assert water.budget == budget
    water.sync()
    waited = False
    for _ in range(SPLASH_FRAMES):
        again.step()
        water.sync()
        live, waiting = water.counts()
        assert live <= budget
        waited = waited or waiting > 0
    assert waited
    assert budget_of(from_dict({**small_dam_break(), "white_water": {"budget": budget}})) == budget  # the key's


@pytest.mark.parametrize("budget", [0, -3, 2.5, True, "40"])
def test_a_bad_budget_is_refused_naming_it(replay, budget):
    with pytest.raises(ValueError, match="WhiteWater: budget: expected a whole number"):
        WhiteWater(replay[0], budget=budget)


def test_the_default_budget_is_twice_the_fluid():
    scene = from_dict(small_dam_break())
    assert budget_of(scene) == 2 * scene.particle_capacity


def test_a_restore_starts_the_white_water_again(splashing, replay):
    _sim, _water, _counts, start = splashing
    again, water, _positions, _arrays, end = replay
    again.restore(end)
    water.sync()
    assert water.counts() == (0, 0)  # a restore clears it, even to the frame it stood at
    again.step()
    water.sync()
    assert water.counts()[0] > 0  # and the splash makes it again
    again.restore(start)
    water.sync()
    assert water.counts() == (0, 0)


def test_white_water_whitens_the_surface_frame_the_same_every_draw(replay):
    again, _water, _positions, _arrays, end = replay
    again.restore(end)
    renderer = SceneRenderer(again, *SIZE, style="surface")
    renderer.frame()  # the white water starts at the simulation's frame
    again.step()
    image = renderer.frame()
    assert renderer.white_water.counts()[0] > 0
    # The same state drawn again: the sprites' sums are integers, so any order of the threads gives these bits.
    assert np.array_equal(renderer.frame(), image)
    renderer.white_water, renderer.with_white_water = None, False
    plain = renderer.frame().astype(int)  # the same state, the same renderer, without white water
    image = image.astype(int)
    whiter = (image.sum(axis=2) > plain.sum(axis=2)).mean()
    darker = (image.sum(axis=2) < plain.sum(axis=2)).mean()
    assert whiter > 0.005 and darker == 0.0  # sprites only add white


@pytest.mark.parametrize(
    "assignment, key",
    [
        ("white_water.budget=-1", "white_water.budget"),
        ("white_water.lifetime_s=0", "white_water.lifetime_s"),
        ("white_water.amount=1000", "white_water.amount"),
        ("surface.shutter_frames=3", "surface.shutter_frames"),
    ],
)
def test_bad_white_water_keys_are_refused_in_one_line(tmp_path, capsys, assignment, key):
    out = tmp_path / "out"
    assert cli.main(["dam_break", "--headless", "--style", "surface", "--out", str(out), "--set", assignment]) == 2
    error = capsys.readouterr().err
    assert key in error and "Traceback" not in error
    assert not out.exists()
    with pytest.raises(SceneError, match=key.replace(".", r"\.")):
        from_dict({**small_dam_break(), key.split(".")[0]: {key.split(".")[1]: assignment.split("=")[1]}})


def test_export_writes_the_diffuse_particles_beside_the_frames(tmp_path):
    out = tmp_path / "run"
    scene = tmp_path / "splash.toml"
    scene.write_text(
        'name = "splash"\n[container]\nmin_m = [0.0, 0.0, 0.0]\nmax_m = [0.8, 0.8, 0.4]\n'
        "[fluid]\nspacing_m = 0.033333\n[[fluid.blocks]]\nmin_m = [0.0, 0.0, 0.0]\nmax_m = [0.4, 0.4, 0.4]\n"
        '[solver]\niterations = 4\n[render]\nstyle = "surface"\nwidth_px = 160\nheight_px = 90\n'
    )
    frames = 16
    assert cli.main([str(scene), "--headless", "--frames", str(frames), "--export", "ply", "--out", str(out)]) == 0
    names = sorted(p.name for p in out.glob("diffuse_*.ply"))
    assert names == [f"diffuse_{k:05d}.ply" for k in range(frames + 1)]
    last = PlyData.read(str(out / names[-1]))["vertex"]
    assert {p.name for p in last.properties} == {"x", "y", "z", "vx", "vy", "vz", "speed", "kind", "age_s"}
    assert last.count > 0
    positions = np.stack([last["x"], last["y"], last["z"]], axis=1)
    assert np.isfinite(positions).all()
    corners = to_export_axes(np.array([[0.0, 0.0, 0.0], [0.8, 0.8, 0.4]]), "z")  # export.up_axis's default
    low, high = corners.min(axis=0), corners.max(axis=0)
    assert (positions >= low - 1e-6).all() and (positions <= high + 1e-6).all()
    assert set(np.unique(last["kind"])) <= {SPRAY, FOAM, BUBBLE} and (np.asarray(last["age_s"]) >= 0).all()
