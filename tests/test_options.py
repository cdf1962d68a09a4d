"""No option is silently ignored: each takes effect or is refused, before anything starts."""

import os

import pytest
from command_line import assert_one_error, refused, run_cli

from pbf.app import cli
from pbf.solver import ARCHES, ENV_VAR


@pytest.fixture
def here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(ENV_VAR, raising=False)
    return tmp_path


@pytest.mark.parametrize(
    "argv, names",
    [
        (["--video", "v.mp4"], ["--video writes files, which the window does not; add --headless"]),
        (["--export", "ply"], ["--export writes files, which the window does not; add --headless"]),
        (["--stats-only", "--video", "v.mp4"], ["--video: --stats-only renders and writes nothing"]),
        (["--stats-only", "--export", "npz"], ["--export: --stats-only renders and writes nothing"]),
        (["--stats-only", "--out", "frames"], ["--out: --stats-only renders and writes nothing"]),
        (
            ["--headless", "--no-png"],
            ["--no-png writes a video instead of the PNG frames: add --video FILE.mp4, or drop --no-png"],
        ),
        (["--no-png"], ["--no-png writes a video instead of the PNG frames: add --video"]),
        (["--no-png", "--video", "v.mp4"], ["--video writes files, which the window does not; add --headless"]),
        (["--stats-only", "--no-png"], ["--no-png: --stats-only renders and writes nothing"]),
        (
            ["--headless", "--video", "v.mp4", "--no-png", "--out", "frames"],
            ["--out: with --no-png only --export files go there; drop --out, or add --export"],
        ),
        (["--stats-only", "--size", "64x48"], ["--size: --stats-only renders and writes nothing"]),
        (["--stats-only", "--colour-map", "viridis"], ["--colour-map: --stats-only"]),
        (["--headless", "--size", ""], ["--size '': expected WIDTHxHEIGHT in pixels"]),
        (["--headless", "--size", "64x"], ["--size 64x: expected WIDTHxHEIGHT"]),
        (["--headless", "--fov", ""], ["--fov '': expected degrees"]),
        (["--headless", "--camera", ""], ["--camera '': expected X,Y,Z in metres"]),
        (["--headless", "--look-at", "1,2"], ["--look-at 1,2: expected X,Y,Z in metres"]),
        (["--headless", "--colour-map", ""], ["command line --colour-map '': key 'render.colour_map'"]),
        (["--headless", "--camera", "1,2,3]\n[solver]\niterations=100\n#"], ["--camera", "expected X,Y,Z in metres"]),
        (["--headless", "--colour-map", 'viridis"\n[solver]\niterations = 100\n#'], ["key 'render.colour_map'"]),
        (
            ["--headless", "--set", "render.width_px=64\n[solver]\niterations = 100"],
            [
                "command line --set",
                "expected one line of printable text (a newline would start a second TOML statement)",
            ],
        ),
        (["--headless", "--set", "solver.iterations=4 # x\n[time]\nsubsteps=999"], ["expected one line of printable"]),
        (["--headless", "--set", "solver..iterations=4"], ["'solver..iterations' is not a dotted key"]),
        (["--headless", "--set", "iterations"], ["expected KEY=VALUE"]),
        (["--frames", "0"], ["argument --frames: expected a whole number of frames in [1, 99,999]"]),
        (["--frames", "100000"], ["got 100000"]),
        (["--frames", "9" * 5000], ["expected a whole number of frames", "…"]),
        (["--arch", "opengl"], ["argument --arch: invalid choice: 'opengl'"]),
    ],
)
def test_options_that_would_do_nothing_are_refused(here, capsys, argv, names):
    refused(capsys, ["dam_break", *argv], *names, cwd=here)


def test_a_bad_backend_variable_is_refused_before_the_scene_loads(here, capsys, monkeypatch):
    monkeypatch.setenv(ENV_VAR, "tpu")
    refused(
        capsys,
        ["no_such_scene"],
        "PBF_ARCH=tpu: unknown backend; allowed: auto, cpu, gpu, cuda, vulkan, metal",
        cwd=here,
    )


@pytest.mark.parametrize(
    "text, option, variable, said",
    [
        (
            "arch='cuda' was requested but no CUDA GPU is available; use arch='cpu' or 'auto'",
            "cuda",
            None,
            "--arch cuda was requested but no CUDA GPU is available; use --arch cpu or --arch auto",
        ),
        (
            "arch='cuda' was requested but no CUDA GPU is available; use arch='cpu' or 'auto'",
            None,
            "CUDA",
            "PBF_ARCH=CUDA was requested but no CUDA GPU is available; use --arch cpu or --arch auto",
        ),
        (
            "arch='metal' was requested but Metal exists only on macOS; use arch='cpu' or 'auto'",
            "metal",
            "cuda",
            "--arch metal was requested but Metal exists only on macOS; use --arch cpu or --arch auto",
        ),
        (
            "arch='vulkan': Taichi could not start vulkan: boom",
            "vulkan",
            None,
            "--arch vulkan: Taichi could not start vulkan: boom",
        ),
    ],
)
def test_a_backend_refusal_names_the_option_or_variable_it_came_from(text, option, variable, said):
    assert cli.backend_message(text, option, variable) == said


@pytest.mark.parametrize("given", [["--arch", "cuda"], [f"{ENV_VAR}=cuda"]])
def test_a_cuda_request_without_a_gpu_is_refused_in_the_command_lines_words(tmp_path, given):
    env = {k: v for k, v in os.environ.items() if k != ENV_VAR}
    argv = ["dam_break", "--stats-only", "--frames", "1", "--set", "fluid.spacing_m=0.1"]
    if given[0].startswith(ENV_VAR):
        env[ENV_VAR] = "cuda"
    else:
        argv += given
    result = run_cli(*argv, cwd=tmp_path, env=env)
    if result.returncode == 0:
        pytest.skip("a CUDA GPU is here")
    line = assert_one_error(result.stderr, f"{given[0] if len(given) == 1 else '--arch cuda'} was requested")
    assert "arch='" not in line and "use --arch cpu or --arch auto" in line, line


def test_the_command_line_names_the_solvers_backends():
    assert cli.ARCHES == ARCHES and cli.ARCH_VARIABLE == ENV_VAR


def test_view_options_reach_the_scene(here):
    # No --headless: the window starts in the surface style, and key v shows the particles' colours.
    args = cli.parse_args(
        [
            "dam_break",
            "--size",
            "64x48",
            "--camera",
            "1,2,3",
            "--look-at",
            "0,0.1,0",
            "--fov",
            "35",
            "--colour-by",
            "density",
            "--colour-map",
            "viridis",
            "--style",
            "surface",
            "--set",
            "render.height_px=32",
        ]
    )
    scene = cli.load(args)
    assert (scene.render.width_px, scene.render.height_px) == (64, 32)  # --set after the shortcut wins
    assert scene.camera.position_m == (1.0, 2.0, 3.0) and scene.camera.look_at_m == (0.0, 0.1, 0.0)
    assert (scene.camera.fov_deg, scene.render.colour_by, scene.render.colour_map, scene.render.style) == (
        35.0,
        "density",
        "viridis",
        "surface",
    )


def test_help_and_refusals_need_no_solver(tmp_path):
    # Neither --help nor a refused command line imports the solver (Taichi prints a banner when it does).
    result = run_cli("--help", cwd=tmp_path)
    assert result.returncode == 0 and "--stats-only" in result.stdout and "[Taichi]" not in result.stdout
    result = run_cli("dam_break", "--video", "v.mp4", cwd=tmp_path)
    assert result.returncode == 2 and "[Taichi]" not in result.stdout
    assert_one_error(result.stderr, "--video writes files")
    assert not list(tmp_path.iterdir())


def test_a_legend_asked_for_with_the_surface_style_is_refused_in_one_line(tmp_path, capsys):
    # The surface's colours are the water's own: a legend the user asked for is refused, not dropped.
    refused(
        capsys,
        ["dam_break", "--headless", "--frames", "1", "--style", "surface", "--set", "render.legend=true"],
        "command line --set render.legend=true: key 'render.legend' = true",
        'render.style = "surface" does not draw',
        cwd=tmp_path,
    )
    scene = tmp_path / "surface_legend.toml"
    scene.write_text('extends = "dam_break"\n[render]\nstyle = "surface"\nlegend = true\n')
    refused(capsys, [str(scene), "--stats-only"], f"{scene}: key 'render.legend' = true", cwd=tmp_path)
    # The default follows the style: the surface without a legend asked for starts.
    assert cli.load(cli.parse_args(["dam_break", "--style", "surface"])).render.style == "surface"
