"""What a newcomer meets before the first run: the Pythons named alike in pyproject.toml, the README
and the first import; what a bare run writes, said in the quick start; the source tree left clean."""

import re
import subprocess
import sys
from pathlib import Path

import pbf
from pbf.app import cli
from pbf.scene import SCENES_DIR
from pbf.scene.files import tomllib  # the standard library's, or tomli before Python 3.11

ROOT = Path(__file__).resolve().parent.parent
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_the_pythons_are_named_alike_everywhere():
    assert pbf.PYTHONS == "3.10-3.13" and pbf.NEWEST_PYTHON == (3, 13)
    assert PROJECT["requires-python"] == ">=3.10,<3.14"
    named = [c.rsplit(" :: ", 1)[1] for c in PROJECT["classifiers"] if re.fullmatch(r".* :: Python :: 3\.\d+", c)]
    assert named == ["3.10", "3.11", "3.12", "3.13"]
    quick_start = README[README.index("## Quick start") :].split("```", 1)[0]
    assert "Python 3.10-3.13" in quick_start and "no wheel for 3.14" in quick_start, quick_start
    assert "Python 3.10-3.13" in (ROOT / "CONTRIBUTING.md").read_text(encoding="utf-8")


def test_a_python_without_a_taichi_wheel_is_told_so():
    message = pbf.python_problem((3, 14), taichi_installed=False)
    assert message == (
        "pbf runs on Python 3.10-3.13, not 3.14: Taichi 1.7.4 has no wheel for Python 3.14; use 3.10-3.13 "
        "(python3.13 -m venv .venv)"
    )
    assert pbf.python_problem((3, 13), taichi_installed=False) is None
    assert pbf.python_problem((3, 10), taichi_installed=True) is None
    assert pbf.python_problem((3, 15), taichi_installed=True) is None  # built from source: Taichi has its say


def test_the_first_import_on_python_3_14_says_why_it_cannot_run():
    # A fresh interpreter that reports 3.14 and finds no Taichi, as a 3.14 install would.
    child = (
        "import sys, importlib.util; sys.version_info = (3, 14, 0, 'final', 0); real = importlib.util.find_spec; "
        "importlib.util.find_spec = lambda name, *a: None if name == 'taichi' else real(name, *a); import pbf"
    )
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1] == f"ImportError: {pbf.python_problem((3, 14), False)}"


def test_the_quick_start_says_what_a_bare_run_writes():
    scene = pbf.load_scene("dam_break")
    quick_start = README[README.index("## Quick start") :].split("```", 1)[0]
    frames = f"{cli.HEADLESS_FRAMES + 1} PNG files at {scene.render.width_px}×{scene.render.height_px}"
    assert frames in quick_start, quick_start
    assert re.search(r"\b\d+ MB\b", quick_start), quick_start


def test_build_output_is_ignored_by_git():
    for path in ("build/lib/pbf/__init__.py", "build/bdist.linux-x86_64/wheel", "pbf_fluids.egg-info/PKG-INFO"):
        done = subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT, timeout=60)
        assert done.returncode == 0, f"{path} is not ignored by git"


def test_the_presets_live_in_the_top_level_scenes_folder():
    assert sorted(p.name for p in (ROOT / "scenes").glob("*.toml")), "no preset in scenes/"
    assert not (ROOT / "pbf" / "scenes").exists()
    assert SCENES_DIR.resolve() == (ROOT / "scenes").resolve()  # a checkout's (editable) install finds them there
    # and a wheel ships them inside the package (tests/test_wheel.py builds one)
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"pbf.scenes": "scenes"} and "pbf.scenes" in setuptools["packages"]
