"""Every output path is checked before the simulation starts; a scene's name never steers where
files go; a rerun never mixes its frames with an earlier run's, and deletes nothing unless asked."""

import errno
import os
from pathlib import Path

import pytest
from command_line import assert_one_error, files_under, refused, run_cli

from pbf.app import cli, outputs

COARSE = ["--set", "fluid.spacing_m=0.1", "--size", "32x32"]
"""The seed scene at 125 particles and thumbnail frames: a run of a frame or two in seconds."""


@pytest.fixture
def here(tmp_path, monkeypatch):
    """A fresh working folder with a file and a folder in it to misuse."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a_file").write_text("not a folder")
    (tmp_path / "a_folder.mp4").mkdir()
    return tmp_path


@pytest.mark.parametrize(
    "argv, names",
    [
        (["--out", "a_file"], ["--out 'a_file': is a file; expected a folder"]),
        (["--out", "a_file/frames"], ["--out 'a_file/frames':", "a_file is a file, not a folder"]),
        (["--out", "a_file/deeper/frames"], ["a_file is a file, not a folder"]),
        (["--out", "/"], ["--out '/': is the filesystem root"]),
        (["--out", ""], ["--out '': expected the path of a folder"]),
        (["--out", "frames\nfolder"], ["expected the path of a folder"]),
        (["--video", "a_folder.mp4"], ["--video 'a_folder.mp4': is a folder; expected a video file"]),
        (["--video", "a_file/v.mp4"], ["a_file is a file, not a folder"]),
        (["--video", ""], ["--video '': expected the path of a video file"]),
        (["--video", "v.gif"], ["--video 'v.gif': expected a file ending in .mp4"]),
        (["--out", "x" * 300], ["File name too long"]),
    ],
)
def test_bad_output_paths_are_refused_before_the_run(here, capsys, argv, names):
    refused(capsys, ["dam_break", "--headless", "--frames", "1", *argv], *names, cwd=here)


def test_a_folder_that_cannot_be_written(here, capsys, monkeypatch):
    (here / "locked").mkdir()
    # Root may write anywhere, so the kernel's refusal for a read-only folder is simulated.
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: real_access(path, mode) and Path(path).name != "locked")
    refused(capsys, ["dam_break", "--headless", "--out", "locked"], "--out 'locked': cannot write into it", cwd=here)
    refused(capsys, ["dam_break", "--headless", "--out", "locked/sub"], "no permission to write in", cwd=here)
    refused(capsys, ["dam_break", "--headless", "--video", "locked/v.mp4"], "no permission to write in", cwd=here)


@pytest.mark.parametrize(
    "error, filesystem, why",
    [
        (errno.EROFS, "ext4", "{folder} is on a read-only filesystem (Read-only file system)"),
        (errno.EACCES, "nfs", "no permission to write in {folder} (Permission denied)"),
        (
            errno.ENOENT,
            "sysfs",
            "{folder} is the kernel's sysfs filesystem, which holds only the kernel's own files "
            "(No such file or directory)",
        ),
        (errno.EIO, "ext4", "{folder} refuses new files (Input/output error)"),
    ],
)
def test_a_folder_that_cannot_be_created_says_why(here, capsys, monkeypatch, error, filesystem, why):
    # A mount that refuses new files, simulated: the probe's file cannot be made, for the reason given.
    def refuse(*args, **kwargs):
        raise OSError(error, os.strerror(error))

    monkeypatch.setattr(outputs.tempfile, "mkstemp", refuse)
    monkeypatch.setattr(outputs, "_filesystem", lambda folder: filesystem)
    line = refused(capsys, ["dam_break", "--headless", "--out", "frames"], cwd=here)
    assert line == f"error: --out 'frames': the folder cannot be created in {here}: {why.format(folder=here)}"


def test_a_folder_where_a_frame_goes(here, capsys):
    (here / "frames" / "frame_00001.png").mkdir(parents=True)
    refused(
        capsys,
        ["dam_break", "--headless", "--out", "frames"],
        "frame_00001.png is a folder where a frame file goes",
        cwd=here,
    )


def test_the_default_folder_is_the_scene_files_name_inside_out():
    assert outputs.default_folder("scenes/dam_break.toml") == Path("out/dam_break")
    assert outputs.default_folder("/tmp/../x/my scene!.toml") == Path("out/my_scene_")
    assert outputs.default_folder("..toml") == Path("out/scene")
    assert outputs.default_folder("/a/.hidden.toml") == Path("out/hidden")


def test_a_rerun_takes_the_next_default_folder_and_overwrite_replaces_only_the_runs_files(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    scene = (
        (Path(cli.schema.SCENES_DIR) / "dam_break.toml")
        .read_text()
        .replace('name = "dam_break"', 'name = "../../escape"')
    )
    (tmp_path / "evil.toml").write_text(scene)
    earlier = tmp_path / "out" / "evil"
    earlier.mkdir(parents=True)
    for k in range(6):
        (earlier / outputs.frame_name(k)).write_bytes(b"old")
    (earlier / outputs.particles_name(3, "ply")).write_bytes(b"old")
    (earlier / "notes.txt").write_text("mine")
    before = files_under(earlier)
    # The same folder named with --out: refused in one line naming the folder and the option.
    refused(
        capsys,
        ["evil.toml", "--headless", "--frames", "1", "--out", "out/evil", *COARSE],
        "--out 'out/evil': holds 7 files of an earlier run (frame_00000.png …); add --overwrite",
        cwd=tmp_path,
    )
    # Without --out the run takes the next free name (the README's commands, run in order by a slow test,
    # show the line that says so) and leaves the first alone.
    args = cli.parse_args(["evil.toml", "--headless", "--frames", "1", *COARSE])
    assert cli.plan_outputs(cli.load(args), args) == (Path("out/evil-2"), None)
    assert args.taken_default == Path("out/evil")
    assert files_under(earlier) == before
    # --overwrite without --out replaces the first folder's run, and only its files.
    assert cli.main(["evil.toml", "--headless", "--frames", "1", "--overwrite", *COARSE]) == 0
    assert "removed 7 files of an earlier run from out/evil/" in capsys.readouterr().out
    assert sorted(p.name for p in earlier.iterdir()) == ["frame_00000.png", "frame_00001.png", "notes.txt"]
    assert (earlier / "frame_00000.png").read_bytes() != b"old"
    assert {p.relative_to(tmp_path) for p in files_under(tmp_path)} == {
        Path("evil.toml"),
        Path("out"),
        Path("out/evil"),
        Path("out/evil/frame_00000.png"),
        Path("out/evil/frame_00001.png"),
        Path("out/evil/notes.txt"),
    }


def test_the_next_free_default_folder(tmp_path):
    base = tmp_path / "out" / "dam_break"
    assert outputs.free_default_folder(base) == base  # not there yet
    base.mkdir(parents=True)
    (base / "notes.txt").write_text("mine")
    assert outputs.free_default_folder(base) == base  # no run's files in it
    (base / outputs.frame_name(0)).write_bytes(b"")
    second = tmp_path / "out" / "dam_break-2"
    assert outputs.free_default_folder(base) == second
    second.mkdir()
    (second / outputs.surface_name(4, "obj")).write_bytes(b"")
    assert outputs.free_default_folder(base) == tmp_path / "out" / "dam_break-3"


def test_a_window_run_checks_the_folder_it_falls_back_to_before_taichi_starts(tmp_path):
    # No display here: the window falls back to frames in --out, which holds a run. The refusal must come
    # before the backend starts (its start line), as it does with --headless, not seconds later.
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / outputs.frame_name(0)).write_bytes(b"theirs")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    result = run_cli("dam_break", "--frames", "1", "--out", "frames", cwd=tmp_path, env=env)
    assert result.returncode == 2
    assert_one_error(result.stderr, "--out 'frames': holds 1 files of an earlier run", "add --overwrite")
    assert "[pbf] Starting on" not in result.stdout, result.stdout


def test_command_line_refuses_a_file_as_the_frame_folder(tmp_path):
    (tmp_path / "taken").write_text("")
    before = files_under(tmp_path)
    result = run_cli("dam_break", "--headless", "--out", "taken", cwd=tmp_path)
    assert result.returncode == 2
    assert_one_error(result.stderr, "--out 'taken': is a file")
    assert files_under(tmp_path) == before
