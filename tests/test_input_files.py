"""A scene file that cannot be read is one SceneError naming the file and what is wrong, never a
traceback (PermissionError, UnicodeDecodeError, RecursionError, ValueError)."""

import tempfile
from pathlib import Path

import pytest
from command_line import assert_one_error, files_under, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from pbf import SceneError, load_scene
from pbf.scene import MAX_SCENE_BYTES

VALID = Path(__file__).resolve().parent.parent / "scenes" / "dam_break.toml"


@pytest.mark.parametrize(
    "content, message",
    [
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "not UTF-8 text (byte 0x89 at offset 0)"),
        ('name = "café"\n'.encode("latin-1"), "not UTF-8 text (byte 0xe9 at offset 11)"),
        ("name = 'x'\n".encode("utf-16"), "not UTF-8 text"),
        (b"name = 'x'\x00\n", "not valid TOML"),
        (b"a = " + b"[" * 5000 + b"]" * 5000, "nested deeper than Python can read"),
        (b"a = " + b"{b = " * 3000 + b"1" + b"}" * 3000, "nested deeper than Python can read"),
        (b"[time]\nsubsteps = " + b"9" * 5000, "an integer of more than 4,300 digits"),
        (b"[time]\nsubsteps = " + b"9" * 4000, "key 'time.substeps': expected a value in [1, 1000]"),
        (b"[time]\nframe_dt_s = 1e999", "key 'time.frame_dt_s': expected a finite number, got inf"),
        (b".".join([b"a"] * 3000) + b" = 1", "unknown key 'a'"),
        (b"", "key 'fluid.blocks': at least one [[fluid.blocks]] table"),
        (b"# " + b"x" * MAX_SCENE_BYTES, f"a scene file is at most {MAX_SCENE_BYTES:,} bytes"),
    ],
)
def test_unreadable_content_is_one_error_naming_the_file(tmp_path, content, message):
    path = tmp_path / "scene.toml"
    path.write_bytes(content)
    with pytest.raises(SceneError) as error:
        load_scene(path)
    assert str(error.value).startswith(str(path)) and message in str(error.value)
    assert len(str(error.value)) < 400


def test_a_byte_order_mark_is_read_as_utf8(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + VALID.read_bytes())
    assert load_scene(path).particle_count == 8000


def test_a_file_without_read_permission(tmp_path, monkeypatch):
    path = tmp_path / "locked.toml"
    path.write_bytes(VALID.read_bytes())

    # Root reads any file whatever its mode, so the refusal the kernel would give is simulated.
    def refuse(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "open", refuse)
    with pytest.raises(SceneError, match=r"locked.toml: cannot be read \(Permission denied\)"):
        load_scene(path)


@pytest.mark.parametrize(
    "name, message",
    [
        ("", "expected a preset name or the path of a TOML file"),
        ("dam\x00break", "expected a preset name or the path of a TOML file"),
        ("x" * 5000 + ".toml", "cannot be read (File name too long)"),
        ("dam_brake", "no such scene file; did you mean dam_break?"),
        ("../pyproject", "no such scene file"),
        ("/etc/passwd", "not valid TOML"),
    ],
)
def test_names_that_are_no_scene_file(name, message):
    with pytest.raises(SceneError) as error:
        load_scene(name)
    assert message in str(error.value) and len(str(error.value)) < 400


def test_a_folder_is_no_scene_file(tmp_path):
    (tmp_path / "folder.toml").mkdir()
    with pytest.raises(SceneError, match="folder.toml: is a folder; expected a TOML scene file"):
        load_scene(tmp_path / "folder.toml")


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_any_bytes_load_or_raise_scene_error(content):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "fuzz.toml"
        path.write_bytes(content)
        try:
            load_scene(path)
        except SceneError as error:
            assert str(error).startswith(str(path))


@pytest.mark.parametrize(
    "content, message",
    [
        (b"\x89PNG\r\n\x1a\n", "not UTF-8 text"),
        (b"[time]\nsubsteps = " + b"9" * 5000, "more than 4,300 digits"),
    ],
)
def test_command_line_refuses_an_unreadable_file_and_writes_nothing(tmp_path, content, message):
    (tmp_path / "bad.toml").write_bytes(content)
    before = files_under(tmp_path)
    result = run_cli("bad.toml", "--headless", "--frames", "1", cwd=tmp_path)
    assert result.returncode == 2
    assert_one_error(result.stderr, "bad.toml", message)
    assert files_under(tmp_path) == before
