"""A built wheel ships the package, not the lab (``benchmarks/``), and the presets (the checkout's
top-level ``scenes/``, inside the package as ``pbf/scenes/``): it installs into a fresh virtual
environment, and from a folder outside the source tree its ``pbf`` command runs a preset by name,
finding the scene inside the installed package rather than in this checkout."""

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def run(command, **kwargs) -> subprocess.CompletedProcess:
    done = subprocess.run(command, capture_output=True, text=True, **kwargs)
    assert done.returncode == 0, f"{' '.join(map(str, command))} failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    return done


@pytest.mark.slow
def test_a_wheel_ships_the_presets_and_runs_one_by_name(tmp_path):
    # Built from a copy of what the distribution is made of: setuptools builds in the source folder,
    # and would leave build/ in the checkout.
    source = tmp_path / "source"
    shutil.copytree(ROOT / "pbf", source / "pbf", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "scenes", source / "scenes")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    wheels = tmp_path / "wheels"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(source)])
    (wheel,) = wheels.glob("pbf_fluids-*.whl")
    presets = sorted(path.stem for path in (ROOT / "scenes").glob("*.toml"))
    with zipfile.ZipFile(wheel) as archive:  # the top-level scenes/ inside the package, as package data
        shipped = sorted(Path(name).stem for name in archive.namelist() if name.startswith("pbf/scenes/"))
        study = sorted(Path(name).stem for name in archive.namelist() if name.startswith("pbf/study/"))
        tops = {name.split("/")[0] for name in archive.namelist() if not name.startswith("pbf_fluids-")}
    assert shipped == presets, (shipped, presets)
    # Of the studies, what a user runs to report speed against error and to validate; the lab stays out.
    assert study == ["__init__", "common", "damping", "headline", "spheric", "sweep", "validate"], study
    assert tops == {"pbf"}, tops

    # The fresh environment borrows this one's dependencies (Taichi is 80 MB) through a path file: a
    # folder added that way is not a site folder, so the editable install's own path file there is not
    # read, and only the wheel can provide ``pbf``.
    environment = tmp_path / "env"
    venv.EnvBuilder(with_pip=False).create(environment)
    python = environment / "bin" / "python"
    site = Path(run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    (site / "borrowed.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q", str(wheel)])

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PBF_ARCH")}
    where = run(
        [python, "-c", "import pbf, pbf.scene; print(pbf.__file__); print(pbf.scene.SCENES_DIR)"],
        cwd=elsewhere,
        env=clean,
    ).stdout.split()
    assert all(Path(p).is_relative_to(environment) for p in where), where
    assert (Path(where[1]) / "dam_break.toml").is_file()
    # Every preset of the checkout is found by name in the installed package and loads there (each
    # `extends` included); running one shows the rest would run the same way.
    load_each = "import sys; from pbf.scene import load_scene; print(*[load_scene(n).name for n in sys.argv[1:]])"
    loaded = run(
        [python, "-c", load_each, *presets],
        cwd=elsewhere,
        env=clean,
    ).stdout.split()
    assert loaded == presets, (loaded, presets)

    command = [environment / "bin" / "pbf", "martin_moyce", "--headless", "--frames", "2", "--size", "64x36"]
    done = run(
        command + ["--arch", "cpu"],
        cwd=elsewhere,
        env=clean,
    )
    assert "wrote 3 frames" in done.stdout, done.stdout
    assert sorted(p.name for p in (elsewhere / "out" / "martin_moyce").iterdir()) == [
        "frame_00000.png",
        "frame_00001.png",
        "frame_00002.png",
    ]
