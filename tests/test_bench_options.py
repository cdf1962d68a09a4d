"""The sweep's command line (``python -m pbf.study.sweep``) and the lab's bench
(``python -m benchmarks.bench``): an option that would do nothing is refused before anything starts."""

import csv

import pytest

from benchmarks import bench
from pbf.study import sweep


@pytest.mark.parametrize("option", [["--sizes", "1000"], ["--iterations", "4"], ["--flow"], ["--set", "a=1"]])
def test_a_sweep_replotted_from_its_csv_refuses_the_options_of_a_run(option, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        sweep.main(["--from-csv", str(tmp_path / "points.csv"), *option])
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert exit_.value.code == 2 and line.endswith(
        f"{option[0]}: applies to a sweep that runs, not to one re-plotted --from-csv"
    )


def test_a_sweep_replotted_from_its_csv_names_the_csv_not_this_machine(monkeypatch, tmp_path, capsys):
    # The points were measured wherever the CSV was written: the title must not claim this backend.
    titles = []
    monkeypatch.setattr(sweep, "read_csv", lambda path: [])
    monkeypatch.setattr(sweep, "plot", lambda points, path, title: titles.append(title))
    sweep.main(["--from-csv", str(tmp_path / "h200.csv"), "--plot", str(tmp_path / "p.png"), "--frames", "9"])
    assert titles == ["PBF dam break, 9 frames from rest (the points of h200.csv)"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["counts", "--threads", "0"], "--threads: expected a whole number of threads from 1 to 256, got '0'"),
        (["counts", "--perturb", "1"], "unrecognized arguments: --perturb 1"),
        (["presets", "--perturb-each-frame"], "--perturb-each-frame: needs --perturb SEED"),
        (["start", "--presets", "dam_brake"], "--presets: dam_brake: no such scene file; did you mean dam_break?"),
    ],
)
def test_bench_refuses_what_its_mode_would_ignore(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        bench.main(argv)
    assert exit_.value.code == 2 and message in capsys.readouterr().err


def test_compare_judges_the_tables_it_is_given(tmp_path, capsys):
    table = tmp_path / "presets.csv"
    with table.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["preset", "backend", *bench.PRESET_STATISTICS])
        writer.writerow(["dam_break", "cpu", *[1.0] * len(bench.PRESET_STATISTICS)])
        writer.writerow(["dam_break", "vulkan", *[1.0] * len(bench.PRESET_STATISTICS)])
    verdicts = bench.main(["compare", str(table)])
    assert len(verdicts) == len(bench.PRESET_STATISTICS) and all(v["inside"] for v in verdicts)
    assert "inside the CPU's own spread" in capsys.readouterr().out
