"""``python -m pbf.study.bench``: no option silently does nothing. Each mode refuses, before anything
starts, an option it does not read (``bench.OPTION_MODES``), and takes every option it does read.
Nothing here starts a backend or a process: where a refusal were missing, the mode would run into the
stand-ins below and fail at once instead of benchmarking."""

import csv

import pytest

from pbf.study import bench
from pbf.study import start as start_study


class Started(Exception):
    """Raised where the mode would have started its work: the options were all taken."""


def started(*args, **kwargs):
    raise Started


@pytest.fixture
def nothing_runs(monkeypatch):
    """Every way out of ``bench.main`` into real work replaced by ``started``: the backend of the modes
    that start one, compare's judging, and start's processes."""
    monkeypatch.setattr(bench, "start_backend", started)
    monkeypatch.setattr(bench, "compare", started)
    monkeypatch.setattr(start_study, "run", started)
    monkeypatch.setattr(start_study, "first_calls", started)


@pytest.fixture
def table(tmp_path):
    """A presets table with the columns compare checks for, one CPU run and one other."""
    path = tmp_path / "presets.csv"
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["preset", "backend", *bench.PRESET_STATISTICS])
        writer.writerow(["dam_break", "cpu", *[1.0] * len(bench.PRESET_STATISTICS)])
        writer.writerow(["dam_break", "vulkan", *[1.0] * len(bench.PRESET_STATISTICS)])
    return path


def arguments(option: str, tmp_path, table) -> list[str]:
    """``option`` as a command line gives it, with a value it takes."""
    values = {
        "tables": [str(table)],
        "--presets": ["--presets", "dam_break"],
        "--perturb": ["--perturb", "1"],
        "--sizes": ["--sizes", "1000"],
        "--iterations": ["--iterations", "4"],
        "--substeps": ["--substeps", "2"],
        "--target": ["--target", "0.01"],
        "--frames": ["--frames", "3"],
        "--particles": ["--particles", "1000"],
        "--warmup": ["--warmup", "1"],
        "--rest-settle": ["--rest-settle", "1"],
        "--rest-frames": ["--rest-frames", "1"],
        "--rounds": ["--rounds", "2"],
        "--set": ["--set", "solver.iterations=3"],
        "--arch": ["--arch", "cpu"],
        "--csv": ["--csv", str(tmp_path / "out.csv")],
        "--threads": ["--threads", "1"],
        "--from-csv": ["--from-csv", str(tmp_path / "sweep.csv")],
        "--plot": ["--plot", str(tmp_path / "sweep.png")],
    }
    return values.get(option, [option])  # the flags take no value


def parser_options() -> set[str]:
    """The parser's options (``tables`` for its positional tables), read without running anything."""
    options = {"tables"}
    for action in bench.build_parser()._actions:
        options.update(string for string in action.option_strings if string.startswith("--"))
    return options - {"--help"}


def test_every_option_of_the_parser_is_in_the_table():
    # A new option must say which modes read it, or main could not refuse it elsewhere.
    assert set(bench.OPTION_MODES) == parser_options()
    for option, modes in bench.OPTION_MODES.items():
        assert modes and set(modes) <= set(bench.MODES), option
    choices = next(action.choices for action in bench.build_parser()._actions if action.dest == "mode")
    assert tuple(choices) == bench.MODES


@pytest.mark.parametrize(
    "argv, message",
    [
        (["start", "--sizes", "8000"], "--sizes: applies to the sizes, sweep, terms, counts and traffic modes only"),
        (["compare", "--frames", "3"], "--frames: applies to the sizes, sweep and presets modes only, not to compare"),
        (["counts", "--plot", "x.png"], "--plot: applies to the sweep mode only, not to counts"),
        (["compare", "--arch", "cpu"], "not to compare"),
        (["start", "--threads", "2"], "--threads: applies to the sizes, sweep, terms, presets, counts and traffic"),
        (["start", "--fast-compile"], "--fast-compile: applies to the sizes, sweep, terms, presets, counts and"),
        (["start", "--set", "solver.iterations=3"], "--set: applies to the sizes, sweep, terms, presets, counts"),
        (["terms", "--device-decisions"], "--device-decisions: applies to the sizes, presets and counts modes only"),
        (["traffic", "--csv", "t.csv"], "--csv: applies to the sizes, sweep, presets and start modes only"),
        (["terms", "--frames", "3"], "--frames: applies to the sizes, sweep and presets modes only, not to terms"),
        (["presets", "--iterations", "4"], "--iterations: applies to the sizes, sweep, terms, counts and traffic"),
        (["sizes", "--rounds", "5"], "--rounds: applies to the terms mode only, not to sizes"),
        (["sweep", "--warmup", "5"], "--warmup: applies to the sizes, terms and traffic modes only, not to sweep"),
        (["sizes", "--perturb-each-frame"], "--perturb-each-frame: applies to the presets mode only, not to sizes"),
        (["sizes", "--gpu-blocks"], "--gpu-blocks: applies to the counts mode only, not to sizes"),
        (["counts", "--presets", "pour", "--sizes", "8000"], "--sizes: counts the seed scene scaled; with --presets"),
        (["counts", "--presets", "pour", "--iterations", "3"], "--iterations: counts the seed scene scaled"),
        # Given at the default's value, abbreviated, or with "=": given all the same.
        (["start", "--frames", "60"], "--frames: applies to the sizes, sweep and presets modes only, not to start"),
        (["compare", "--rou=25"], "--rounds: applies to the terms mode only, not to compare"),
    ],
)
def test_an_option_the_mode_does_not_read_is_refused(argv, message, nothing_runs, capsys):
    with pytest.raises(SystemExit) as exit_:
        bench.main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2, err
    assert message in err.strip().splitlines()[-1], err  # one line, argparse's error line


@pytest.mark.parametrize("mode", bench.MODES)
@pytest.mark.parametrize("option", list(bench.OPTION_MODES))
def test_each_mode_takes_the_options_it_reads_and_refuses_the_others(
    option, mode, nothing_runs, tmp_path, table, capsys
):
    argv = [mode, *arguments(option, tmp_path, table)]
    if option == "--perturb-each-frame" and mode == "presets":
        argv += ["--perturb", "1"]  # which it needs (elsewhere --perturb would be the one refused)
    if mode in bench.OPTION_MODES[option]:
        with pytest.raises(Started):  # past every refusal, into the mode's own work
            bench.main(argv)
    else:
        with pytest.raises(SystemExit) as exit_:
            bench.main(argv)
        line = capsys.readouterr().err.strip().splitlines()[-1]
        assert exit_.value.code == 2 and f"{option}: applies to the " in line and line.endswith(f"not to {mode}")


def test_compare_judges_the_tables_it_is_given(table, capsys):
    # compare runs no backend: the real one, on a table of one CPU run and one other.
    verdicts = bench.main(["compare", str(table)])
    assert len(verdicts) == len(bench.PRESET_STATISTICS) and all(v["inside"] for v in verdicts)
    assert "inside the CPU's own spread" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, given",
    [
        ([], set()),
        (["start"], set()),
        (["start", "--frames", "60", "--target", "0.005"], {"--frames", "--target"}),  # the defaults' values
        (["sizes", "--fram=3", "--set", "a=1", "--set", "b=2"], {"--frames", "--set"}),
        (["compare", "a.csv", "b.csv", "--no-shared"], {"tables", "--no-shared"}),
    ],
)
def test_given_options_are_those_on_the_command_line(argv, given):
    parser = bench.build_parser()
    assert bench.given_options(parser, argv) == given


@pytest.mark.parametrize("option", bench.SWEEP_RUN_OPTIONS)
def test_a_sweep_replotted_from_its_csv_refuses_the_options_of_a_run(option, nothing_runs, tmp_path, table, capsys):
    with pytest.raises(SystemExit) as exit_:
        bench.main(["sweep", "--from-csv", str(tmp_path / "points.csv"), *arguments(option, tmp_path, table)])
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert exit_.value.code == 2 and line.endswith(
        f"{option}: applies to a sweep that runs, not to one re-plotted --from-csv"
    )


def test_a_sweep_replotted_from_its_csv_takes_its_plot_and_frames(nothing_runs, tmp_path):
    with pytest.raises(Started):  # past every refusal (the backend starts before the CSV is read)
        bench.main(
            ["sweep", "--from-csv", str(tmp_path / "points.csv"), "--plot", str(tmp_path / "p.png"), "--frames", "9"]
        )


def test_a_sweep_replotted_from_its_csv_names_the_csv_not_this_machine(monkeypatch, tmp_path, capsys):
    # The points were measured wherever the CSV was written: the title must not claim this backend.
    titles = []
    monkeypatch.setattr(bench.speed_error, "read_csv", lambda path: [])
    monkeypatch.setattr(bench.speed_error, "plot", lambda points, path, title: titles.append(title))
    args = bench.build_parser().parse_args(
        ["sweep", "--from-csv", str(tmp_path / "h200.csv"), "--plot", str(tmp_path / "p.png"), "--frames", "9"]
    )
    args.backend = "a backend of this machine"
    bench.sweep(args)
    assert titles == ["PBF dam break, 9 frames from rest (the points of h200.csv)"]
