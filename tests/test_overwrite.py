"""Nothing of the user's is deleted unless asked (--overwrite), a mistyped option is never read as
another, output paths that cannot be written are refused before the run, and an option that would do
nothing in its combination is refused."""

from pathlib import Path

import pytest
from command_line import files_under, refused

from pbf.app import cli, outputs

COARSE = ["--set", "fluid.spacing_m=0.1", "--size", "32x32"]
"""The seed scene at 125 particles and thumbnail frames."""


@pytest.fixture
def here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def a_mesh_export(folder: Path, count: int) -> set[Path]:
    folder.mkdir(parents=True)
    for k in range(count):
        (folder / outputs.surface_name(k, "ply")).write_bytes(b"mesh")
    return files_under(folder)


def test_a_mistyped_option_is_not_read_as_another_and_deletes_nothing(here, capsys):
    # argparse's prefix matching read --frame as --frames; the run then cleared the folder.
    kept = a_mesh_export(here / "out" / "dam_break", 12)
    refused(capsys, ["--headless", "--frame", "10"], "unknown option --frame; did you mean --frames?", cwd=here)
    refused(capsys, ["--headless", "--over"], "unknown option --over", cwd=here)
    assert files_under(here / "out" / "dam_break") == kept


@pytest.mark.parametrize(
    "name", [outputs.frame_name(3), outputs.particles_name(0, "npz"), outputs.surface_name(7, "obj")]
)
def test_a_folder_with_an_earlier_runs_files_is_refused_without_overwrite(here, capsys, name):
    (here / "frames").mkdir()
    (here / "frames" / name).write_bytes(b"theirs")
    line = refused(
        capsys,
        ["--headless", "--out", "frames", *COARSE],
        f"--out 'frames': holds 1 files of an earlier run ({name} …); add --overwrite",
        cwd=here,
    )
    assert "choose another folder" in line


def test_another_style_after_a_run_keeps_its_frames(here, capsys):
    # A particles run, then a surface run into the same folder: the second is refused, nothing wiped.
    assert cli.main(["--headless", "--frames", "1", "--out", "frames", *COARSE]) == 0
    first = {p: p.read_bytes() for p in files_under(here / "frames")}
    refused(
        capsys,
        ["--headless", "--frames", "1", "--out", "frames", "--style", "surface", *COARSE],
        "holds 2 files of an earlier run",
        cwd=here,
    )
    assert {p: p.read_bytes() for p in files_under(here / "frames")} == first


def test_an_existing_video_is_replaced_only_with_overwrite(here, capsys):
    (here / "v.mp4").write_bytes(b"a film of mine")
    refused(
        capsys,
        ["--headless", "--frames", "1", "--out", "frames", "--video", "v.mp4", *COARSE],
        "--video 'v.mp4': exists; add --overwrite",
        cwd=here,
    )
    assert (here / "v.mp4").read_bytes() == b"a film of mine"


PROC = "/proc is the kernel's proc filesystem, which holds only the kernel's own files"


@pytest.mark.parametrize(
    "argv, names",
    [
        (["--headless", "--out", "/proc/x"], ["--out '/proc/x': the folder cannot be created in /proc: ", PROC]),
        (
            ["--headless", "--out", "/proc/pbf/frames"],
            ["--out '/proc/pbf/frames': the folder cannot be created in /proc"],
        ),
        (["--headless", "--out", "/proc"], ["--out '/proc': cannot write in /proc: ", PROC]),
        (
            ["--headless", "--video", "/proc/x.mp4", "--out", "frames"],
            ["--video '/proc/x.mp4': the video file cannot be created in /proc: ", PROC],
        ),
    ],
)
def test_a_place_that_refuses_writes_is_refused_before_the_run(here, capsys, argv, names):
    if not Path("/proc/self").exists():
        pytest.skip("no /proc here")
    refused(capsys, argv, *names, cwd=here)


@pytest.mark.parametrize(
    "argv, names",
    [
        (
            ["--headless", "--style", "surface", "--colour-map", "viridis"],
            ["--colour-map: --style surface draws the water's surface"],
        ),
        (["--headless", "--style", "surface", "--colour-by", "density"], ["--colour-by: --style surface"]),
        (
            ["--headless", "--colour-map", "viridis", "--set", 'render.style="surface"'],
            ['--colour-map: the scene\'s render.style = "surface"'],
        ),
        (["--stats-only", "--overwrite"], ["--overwrite: --stats-only writes nothing"]),
    ],
)
def test_an_option_that_would_do_nothing_is_refused(here, capsys, argv, names):
    refused(capsys, argv, *names, cwd=here)


def test_overwrite_removes_only_the_programs_own_files(here):
    folder = here / "frames"
    folder.mkdir()
    for name in (
        outputs.frame_name(0),
        outputs.frame_name(9),
        outputs.surface_name(2, "obj"),
        "frame_1.png",
        "notes.txt",
        "particles_00001.csv",
    ):
        (folder / name).write_bytes(b"x")
    with pytest.raises(outputs.OutputError, match="holds 3 files of an earlier run"):
        outputs.check_folder("frames", "--out")
    assert outputs.check_folder("frames", "--out", overwrite=True) == Path("frames")
    assert [p.name for p in outputs.clear_earlier(folder)] == [
        "frame_00000.png",
        "frame_00009.png",
        "surface_00002.obj",
    ]
    assert sorted(p.name for p in folder.iterdir()) == ["frame_1.png", "notes.txt", "particles_00001.csv"]
