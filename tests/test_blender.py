"""Exports for Blender (``[export]``, ``pbf.app.export``, ``pbf.app.blender_load``): the axis
conversion, the attributes in the files, run.json, and, where Blender is installed, the shipped
script loading a short run (marked slow)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from plyfile import PlyData

from pbf.app import blender_load
from pbf.app.export import Z_UP, to_export_axes, write_particles
from pbf.app.mesh import Mesh, write_mesh
from pbf.scene import SceneError, load_scene


def test_z_up_is_a_rotation_that_stands_the_simulations_up_axis_on_z():
    points = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], np.float32)
    assert np.allclose(to_export_axes(points, "z"), [[0, 0, 1], [1, 0, 0], [0, -1, 0]])
    assert np.allclose(to_export_axes(points, "y"), points)
    # determinant 1: a rotation, so a mesh's winding (outward normals) survives the conversion
    assert np.linalg.det(Z_UP) == pytest.approx(1.0)


def test_particles_carry_velocity_and_speed_in_the_chosen_axes(tmp_path):
    positions = np.array([[0.1, 0.2, 0.3]], np.float32)
    velocities = np.array([[0.0, -3.0, 4.0]], np.float32)
    vertex = PlyData.read(str(write_particles(tmp_path / "p.ply", positions, velocities, 0.5, "z")))["vertex"]
    assert [p.name for p in vertex.properties] == ["x", "y", "z", "vx", "vy", "vz", "speed"]
    assert (vertex["x"][0], vertex["y"][0], vertex["z"][0]) == pytest.approx((0.1, -0.3, 0.2))
    assert (vertex["vx"][0], vertex["vy"][0], vertex["vz"][0]) == pytest.approx((0.0, -4.0, -3.0))
    assert vertex["speed"][0] == pytest.approx(5.0)
    saved = np.load(write_particles(tmp_path / "p.npz", positions, velocities, 0.5, "y"))
    assert str(saved["up_axis"]) == "y" and saved["speeds_m_s"][0] == pytest.approx(5.0)


def test_a_mesh_ply_carries_its_vertex_velocities_and_the_blender_reader_reads_them(tmp_path):
    mesh = Mesh(
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
        np.array([[0, 1, 2]], np.int32),
        np.array([[1, 0, 0], [0, 2, 0], [0, 0, 3]], np.float32),
    )
    ply = blender_load.read_ply(write_mesh(tmp_path / "m.ply", mesh, 0.0, "z"))
    assert ply["properties"] == ["x", "y", "z", "vx", "vy", "vz", "speed"]
    assert list(ply["faces"]) == [0, 1, 2]
    assert list(blender_load.columns(ply, ("x", "y", "z"))) == pytest.approx([0, 0, 0, 1, 0, 0, 0, 0, 1])
    assert list(blender_load.columns(ply, ("speed",))) == pytest.approx([1, 2, 3])


def test_bad_export_keys_are_refused_naming_the_key():
    with pytest.raises(SceneError, match=r"key 'export.up_axis'.*one of 'z', 'y'"):
        load_scene("dam_break", overrides=["export.up_axis=x"])


def test_the_blender_script_refuses_a_folder_without_a_run(tmp_path):
    with pytest.raises(blender_load.LoadError, match="run.json: missing"):
        blender_load.Run(tmp_path)
    with pytest.raises(blender_load.LoadError, match="no such folder"):
        blender_load.Run(tmp_path / "nowhere")


def test_the_blender_script_loads_the_frames_whose_files_are_there(tmp_path):
    (tmp_path / "run.json").write_text("[1]")
    with pytest.raises(blender_load.LoadError, match="lacks frames, frame_rate_hz, camera, container"):
        blender_load.Run(tmp_path)
    info = {"frames": 5, "frame_rate_hz": 60.0, "camera": {}, "container": {}, "surface": "ply", "particles": None}
    (tmp_path / "run.json").write_text(json.dumps(info))
    mesh = Mesh(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.int32))
    for frame in range(2):  # a run cut short after two of its five frames
        write_mesh(tmp_path / f"surface_{frame:05d}.ply", mesh, 0.0)
    run = blender_load.Run(tmp_path)
    assert (run.frames, run.surface, run.particles) == (2, True, False)


def test_outside_blender_the_script_prints_its_path():
    done = subprocess.run([sys.executable, "-m", "pbf.app.blender_load"], capture_output=True, text=True, check=True)
    assert Path(done.stdout.strip()) == Path(blender_load.__file__).resolve()


@pytest.mark.slow
def test_blender_loads_a_short_run_z_up_with_its_attributes(tmp_path):
    if shutil.which("blender") is None:
        pytest.skip("blender is not installed (apt-get install blender); the exports' own tests ran without it")
    out = tmp_path / "run"
    run = [sys.executable, "run.py", "dam_break", "--headless", "--frames", "2", "--size", "64x36"]
    run += ["--export", "ply", "--export", "mesh", "--out", str(out), "--set", "fluid.spacing_m=0.05"]
    subprocess.run(run, cwd=Path(__file__).parent.parent, check=True, capture_output=True)
    info = json.loads((out / "run.json").read_text())
    report = tmp_path / "report.json"
    script = [
        "blender", "-b", "--factory-startup", "-P", blender_load.__file__, "--",
        str(out), "--report", str(report), "--frame", "0", "--frame", "2",
    ]  # fmt: skip
    subprocess.run(script, check=True, capture_output=True, timeout=300)
    loaded = json.loads(report.read_text())
    first, last = loaded["surface 0"], loaded["surface 2"]
    count = len(PlyData.read(str(out / "particles_00000.ply"))["vertex"])
    assert loaded["particles 0"]["vertices"] == count
    for entry in (first, last, loaded["particles 2"]):
        assert {"velocity", "speed"} <= set(entry["attributes"])
    # z up: the block of water (0.5 m, its bottom 0.1 m off the floor) stands 0.1-0.6 m on Blender's z
    assert first["min"][2] == pytest.approx(0.1, abs=0.01) and first["max"][2] == pytest.approx(0.6, abs=0.01)
    assert first["recalculate_outside_flips"] == 0
    # one surface object whose mesh is replaced frame by frame: no object or mesh per frame
    assert first["objects"] == last["objects"] and first["meshes"] == last["meshes"]
    assert last["vertices"] != first["vertices"] and last["speed_max"] > 0
    assert info["frames"] == 3 and info["up_axis"] == "z"
