"""The README is the front door: its Python examples run as written, and its presets table is the
presets that exist, each with the particle count and description `run.py --list` prints."""

import re
from pathlib import Path

import pytest

from pbf.app import cli

README = Path(__file__).resolve().parent.parent / "README.md"


def python_blocks() -> list[str]:
    """Every ```python block of the README, in order."""
    return re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), flags=re.DOTALL | re.MULTILINE)


def test_the_readme_has_python_examples():
    assert len(python_blocks()) >= 2


@pytest.mark.parametrize("number", range(len(python_blocks())))
def test_each_python_example_runs_as_written(number, tmp_path, monkeypatch, capsys):
    # In an empty folder of its own, as a reader would paste it: nothing it needs may come from here.
    monkeypatch.chdir(tmp_path)
    code = python_blocks()[number]
    exec(compile(code, f"README.md, python block {number + 1}", "exec"), {"__name__": "__main__"})
    assert capsys.readouterr().out.strip(), "each example prints what it shows"
    assert list(tmp_path.iterdir()) == [], "an example writes no files"


def presets_table() -> dict[str, tuple[str, str]]:
    """The README's presets table: name → (particles, what it shows)."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Presets") :]
    section = section[: section.index("\n## ", 1)]
    return {
        match[0]: (match[1], match[2])
        for match in re.findall(r"^\| `(\w+)` \| ([^|]+?) \| ([^|]+?) \|$", section, flags=re.MULTILINE)
    }


def test_the_presets_table_is_the_presets(capsys):
    capsys.readouterr()
    assert cli.main(["--list"]) in (0, None)
    listed = {}
    for line in capsys.readouterr().out.splitlines():
        name, particles, description = re.fullmatch(r"(\w+)\s+(.+?) particles  (.+)", line).groups()
        listed[name] = (particles, description)
    assert presets_table() == listed


def test_the_readme_is_a_front_door():
    """Short, and usage before measurements: no benchmark figure ahead of the first usage section
    (the figures live in docs/BENCHMARKS.md, each with its command)."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 220
    before_usage = text[: text.index("## Three ways to use it")]
    figures = re.findall(r"\d[\d,.]*\s?(?:ms|µs|fps|frames a second)\b|H200|H100", before_usage)
    assert not figures, f"benchmark figures before the usage sections: {figures}"


def test_the_control_fields_the_readme_names_exist():
    # The comment that lists the live settings names fields a user will type: each must be one.
    from pbf.solver.model import CONTROL_CHECKS

    line = next(line for line in README.read_text(encoding="utf-8").splitlines() if "sim.control.iterations =" in line)
    names = [re.sub(r"\s*\(.*\)", "", name).strip() for name in line.split("live:", 1)[1].split(",")]
    assert len(names) >= 5, line
    assert all(name in CONTROL_CHECKS for name in names), names
