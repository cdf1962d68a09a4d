"""Settings that cannot hold together are refused with what to change."""

import pytest
from command_line import refused

from pbf import SceneError
from pbf.app.render import View
from pbf.scene import default_look_at_m, from_dict
from pbf.solver.model import Control
from scenes import small_dam_break

NOZZLE = {"position_m": [0.6, 0.6, 0.2], "direction": [0.0, -1.0, 0.0], "radius_m": 0.05, "end_s": 0.5}


def scene_with(**tables):
    scene = small_dam_break()
    for name, table in tables.items():
        scene[name] = {**scene.get(name, {}), **table} if isinstance(table, dict) else table
    return scene


@pytest.mark.parametrize(
    "changes, message",
    [
        (
            {"time": {"substeps": 100}},
            "key 'time.substeps' = 100 is more than time.max_substeps = 64, the cap on a "
            "frame's substeps; raise time.max_substeps or lower time.substeps",
        ),
        (
            {"time": {"settle_substeps": 2}},
            "key 'time.settle_substeps' = 2 sets the substeps of settling, but 'time.settle_s' is 0",
        ),
        (
            {"time": {"max_cfl": 3.0}, "solver": {"kernel_ratio": 2.0}},
            "key 'time.max_cfl' = 3 would let a particle pass its whole neighbourhood",
        ),
        (
            {"camera": {"position_m": [0.3, 0.2, 0.1], "look_at_m": [0.3, 0.2, 0.1]}},
            "key 'camera.position_m': the eye [0.3, 0.2, 0.1] m is at camera.look_at_m [0.3, 0.2, 0.1] m, so it looks "
            "nowhere; move camera.position_m or set camera.look_at_m elsewhere",
        ),
        ({"camera": {"position_m": [0.4, 0.336, 0.2]}}, "is at the default look-at point [0.4, 0.336, 0.2] m"),
        ({"camera": {"position_m": [1e6, 0.0, 0.0]}}, "key 'camera.position_m': [1e+06, 0, 0] m is"),
        (
            {"emitters": [{**NOZZLE, "start_s": 1.0, "end_s": 0.5}]},
            "key 'emitters[0].end_s' = 0.5 s must be after start_s",
        ),
        ({"emitters": [{**NOZZLE, "speed_m_s": 1000.0}]}, "key 'emitters[0].speed_m_s' = 1000 m/s"),
        ({"wave_maker": {"stroke_m": 0.1, "period_s": 0.001}}, "key 'wave_maker.period_s' = 0.001 s moves the piston"),
        ({"wave_maker": {"stroke_m": 0.5}}, "key 'wave_maker.stroke_m' = 0.5 m is more than a quarter"),
        (
            {"obstacles": [{"min_m": [0.5, 0.0, 0.1], "max_m": [0.7, 0.2, 0.3]}], "time": {"max_cfl": 2.0}},
            "key 'time.max_cfl' = 2 lets particles cross an obstacle",
        ),
        ({"fluid": {"max_particles": 10}}, "key 'fluid.max_particles' = 10 is less than the 1,728 particles"),
        (
            {"solver": {"wall_mirror": True, "expert": {"wall_density": False}}},
            "key 'solver.wall_mirror' = true mirrors the ghost fluid behind the walls, but "
            "solver.expert.wall_density = false leaves none; allowed: false, or solver.expert.wall_density = true",
        ),
        (
            {"solver": {"expert": {"chebyshev_rho": 0.95}}},
            "key 'solver.expert.chebyshev_rho' = 0.95 sets the ρ of Chebyshev weights, but "
            'solver.expert.acceleration = "stable" does not use them',
        ),
        (
            {"solver": {"expert": {"acceleration": "none", "chebyshev_rho": 0.0}}},
            "key 'solver.expert.chebyshev_rho' = 0",
        ),
        ({"solver": {"iterations": 3, "min_iterations": 4}}, "key 'solver.min_iterations' = 4 is more than"),
        (
            {"solver": {"expert": {"step_back": False}, "target_density_error": 0.0}},
            "key 'solver.expert.step_back' = false changes where the error target stops the iterations, but "
            "solver.target_density_error = 0 runs them all",
        ),
    ],
)
def test_settings_that_cannot_both_hold(changes, message):
    with pytest.raises(SceneError) as error:
        from_dict(scene_with(**changes), "test.toml")
    assert str(error.value).startswith("test.toml: ") and message in str(error.value), str(error.value)


def test_the_default_least_iterations_yield_to_fewer_most():
    # solver.min_iterations defaults to 2; a scene that asks for 1 iteration at most runs 1, unrefused.
    scene = from_dict(scene_with(solver={"iterations": 1}))
    assert scene.solver.iterations == 1 and Control.from_scene(scene).min_iterations == 1


def test_the_default_look_at_point_is_the_renderers():
    scene = from_dict(small_dam_break())
    assert tuple(View.of_scene(scene).target) == pytest.approx(default_look_at_m(scene))


@pytest.mark.parametrize(
    "argv, names",
    [
        (["--headless", "--stats-only"], ["--stats-only: not allowed with argument --headless"]),
        (["--list", "dam_break"], ["--list lists the presets and takes no other option; drop the scene"]),
        (["--list", "--frames", "3"], ["drop --frames"]),
        (
            ["dam_break", "--set", "time.substeps=100", "--headless"],
            ["command line --set time.substeps=100: key 'time.substeps' = 100 is more than time.max_substeps"],
        ),
        (
            ["dam_break", "--camera", "0.4,0.3,0.4", "--look-at", "0.4,0.3,0.4", "--headless"],
            ["command line --camera 0.4,0.3,0.4: key 'camera.position_m'", "so it looks nowhere"],
        ),
    ],
)
def test_command_line_contradictions(tmp_path, monkeypatch, capsys, argv, names):
    monkeypatch.chdir(tmp_path)
    refused(capsys, argv, *names, cwd=tmp_path)
