"""The benchmark scripts under benchmarks/ and the headline table run from a clone, at small sizes and
for a few frames, and print the tables docs/BENCHMARKS.md and the README quote. Their figures are not
checked here (a few frames mean nothing); what is checked is that each runs to its table."""

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pbf.study import headline

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"


def script(name: str):
    """benchmarks/NAME.py imported as a module (the folder is not a package)."""
    spec = importlib.util.spec_from_file_location(f"benchmark_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_surface_measures_the_water_each_mesh_holds(capsys):
    script("surface").main(["--sizes", "8000", "--frames", "10", "--every", "10"])
    out = capsys.readouterr().out
    assert "dam break, 8,000 particles" in out
    header, rest, frame = (line.split() for line in out.splitlines() if line.split()[0] in ("frame", "rest", "10"))
    assert header == ["frame", "defaults"] and len(rest) == len(frame) == 2
    assert all(f"\n{row:>6} " in out for row in ("worst", "ms", "tris", "walls", "drop"))


@pytest.mark.slow
def test_headline_prints_its_table(capsys):
    headline.main(["--quick"])
    out = capsys.readouterr().out
    assert "machine: " in out and "on cpu" in out
    rows = [line for line in out.splitlines() if line.startswith("| ") and not line.startswith("| measure ")]
    assert len(rows) == 6
    assert "8,000 particles" in rows[0] and "s per simulated second" in rows[0]
    assert "nan" not in out.lower(), out
    assert rows[5].endswith("| not measured in --quick (the run ends before the waves reach the gauge) |"), rows[5]


def test_headline_says_why_a_figure_was_not_measured():
    assert headline.wave_value(0.7912, quick=False) == "0.79 of linear theory (Biésel)"
    assert headline.wave_value(float("nan"), quick=True).startswith("not measured in --quick")
    assert "nan" not in headline.wave_value(float("nan"), quick=False)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (apt-get install xvfb)")
def test_window_benchmark_runs_under_a_virtual_display():
    run = subprocess.run(
        [
            "xvfb-run",
            "-a",
            "-s",
            "-screen 0 1920x1080x24",
            sys.executable,
            str(BENCHMARKS / "window.py"),
            "--frames",
            "2",
            "--warmup",
            "1",
            "--rounds",
            "1",
            "--variants",
            "window",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    if "no window:" in run.stderr + run.stdout:
        pytest.skip(f"no Vulkan here: {(run.stderr + run.stdout).strip().splitlines()[-1]}")
    assert run.returncode == 0, run.stderr
    assert "| window | " in run.stdout


@pytest.mark.slow
def test_window_benchmark_runs_offscreen_without_a_display():
    # GGUI's offscreen window (show_window=False) on Mesa's software Vulkan: the window's loop,
    # simulation, drawing and panel, timed with no X server at all.
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    run = subprocess.run(
        [sys.executable, str(BENCHMARKS / "window.py"), "--offscreen", "--arch", "cpu"]
        + ["--frames", "2", "--warmup", "1", "--rounds", "1", "--variants", "window,surface"],
        capture_output=True,
        text=True,
        timeout=300,
        env={**env, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    if "no window:" in run.stderr + run.stdout:
        pytest.skip(f"no Vulkan here: {(run.stderr + run.stdout).strip().splitlines()[-1]}")
    assert run.returncode == 0, run.stderr
    assert "offscreen" in run.stdout and "| window | " in run.stdout and "| surface | " in run.stdout


@pytest.mark.slow
def test_frames_study_prints_its_table(capsys):
    from benchmarks import frames

    argv = ["--at-frame", "1", "--repeats", "2", "--size", "64x36", "--arch", "cpu"]
    assert frames.main(argv) == 0
    out = capsys.readouterr().out
    for stage in ("draw, particles", "draw, surface", "PNG, Sub filter, level 1, surface", "writer, surface"):
        assert f"| {stage} |" in out, stage


@pytest.mark.slow
def test_gallery_draws_a_sheet_of_presets(tmp_path, monkeypatch, capsys):
    gallery = script("gallery")
    monkeypatch.setitem(gallery.MOMENTS, "martin_moyce", 0.05)  # a few frames
    out = tmp_path / "sheet.png"
    gallery.main(["--presets", "martin_moyce", "--out", str(out), "--size", "64x36", "--columns", "1"])
    assert out.stat().st_size > 1000 and "wrote" in capsys.readouterr().out


def test_the_pictures_scripts_write_out_unless_told_docs():
    # The docs' pictures are tracked files: a run of the scripts must not replace them unasked.
    gallery = script("gallery")
    assert gallery.parse([]).out == Path("out/presets.png")
    assert gallery.parse(["--docs"]).out == BENCHMARKS.parent / "docs" / "presets.png"
    with pytest.raises(SystemExit):
        gallery.parse(["--docs", "--out", "x.png"])
    text = (BENCHMARKS / "screenshots.sh").read_text()
    assert "out=${1:-out/window_tour.png}" in text and "--docs) out=docs/window_tour.png" in text


def test_screenshots_says_what_is_missing(tmp_path):
    # Without Xvfb the script used to wait and say only "no window appeared".
    empty = tmp_path / "bin"
    empty.mkdir()
    run = subprocess.run(
        [shutil.which("bash"), str(BENCHMARKS / "screenshots.sh")],
        env={"PATH": str(empty), "HOME": str(tmp_path)},
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert run.returncode == 1
    for tool in ("xvfb", "xdotool", "imagemagick"):
        assert f"apt-get install {tool})" in run.stderr, run.stderr
    assert "pip install -e ." in run.stderr
    assert "no window appeared" not in run.stderr
    assert list(tmp_path.iterdir()) == [empty]


def test_every_preset_has_a_moment_in_the_gallery():
    assert set(script("gallery").MOMENTS) == {p.stem for p in (BENCHMARKS.parent / "scenes").glob("*.toml")}


@pytest.mark.slow
def test_bench_start_counts_the_kernels_a_start_compiles(tmp_path):
    from benchmarks import start

    cold = start.one_start("dam_break", tmp_path, "cpu", [])
    warm = start.one_start("dam_break", tmp_path, "cpu", [])
    assert not cold["error"] and not warm["error"], (cold, warm)
    assert cold["compiled"] > 10, cold  # the solver's kernels, each one file in the cache
    assert warm["compiled"] == 0, warm  # the same start again: everything from the cache
    assert warm["ready_s"] < cold["ready_s"], (cold, warm)


@pytest.mark.slow
def test_bench_presets_writes_its_table(tmp_path):
    """``bench presets``, the table the backends are judged by, runs in a process of its own."""
    table = tmp_path / "cpu.csv"
    argv = ["presets", "--presets", "martin_moyce", "--frames", "2", "--arch", "cpu", "--csv", str(table)]
    run = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench", *argv],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "TQDM_DISABLE": "1"},
    )
    assert run.returncode == 0, run.stderr
    rows = table.read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("martin_moyce,"), rows


@pytest.mark.slow
def test_bench_start_first_calls_names_the_kernels_a_cold_start_compiles(capsys):
    """``--first-calls``: a fresh process with an empty cache builds the preset and steps it once, and
    the table names the solver's kernels with positive times, the longest first."""
    from benchmarks import start

    start.first_calls(["dam_break"], "cpu")
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("dam_break: built and one substep in "), lines
    rows = [line.split() for line in lines[1:]]
    seconds = [float(row[0]) for row in rows]
    names = [row[2] for row in rows]
    assert len(rows) == start.FIRST_CALLS_SHOWN and all(t > 0 for t in seconds), lines
    assert seconds == sorted(seconds, reverse=True), lines
    assert "SubstepKernels._find_neighbours_kernel" in names and "SubstepKernels._iterations_kernel" in names, lines


@pytest.mark.slow
def test_substep_time_prints_its_table_and_a_presets_rate(capsys):
    script("substep_time").main(["--sizes", "1000", "--substeps", "3", "--rounds", "1", "--preset", "pour"])
    out = capsys.readouterr().out
    assert "ms/substep" in out and "host issue ms" in out and "host CPU ms" in out
    assert "pour, cpu:" in out and "frames of simulation a second" in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["HEAD", "--sizes", "300"], "give at least two"),
        (["no-such-revision-or-folder", "HEAD", "--sizes", "300"], "neither a folder nor a git revision"),
        ([str(BENCHMARKS), "HEAD", "--sizes", "300"], "holds no pbf/__init__.py"),
        (["HEAD", "HEAD"], "the following arguments are required: --sizes"),
        (["HEAD", "HEAD", "--sizes", "300", "--rounds", "0"], "--rounds: at least 1"),
        (["HEAD", "HEAD", "--arch", "tpu", "--sizes", "300"], "unknown backend"),
    ],
)
def test_ab_refuses_what_it_cannot_compare_before_running_anything(argv, message, capsys):
    with pytest.raises(SystemExit) as stop:
        script("ab").main(argv)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_ab_alternates_a_revision_and_a_folder(capsys):
    ab = script("ab")
    if ab.revision("HEAD") is None:
        pytest.skip("needs this checkout's git history (a revision is exported with git archive)")
    checkout = str(BENCHMARKS.parent)
    argv = ["HEAD", checkout, "--arch", "cpu", "--sizes", "300", "--rounds", "2", "--inner", "1", "--substeps", "2"]
    assert ab.main(argv) == 0
    out = capsys.readouterr().out
    assert "round 1 of 2: A, B" in out and "round 2 of 2: B, A" in out  # the order rotates
    assert f"B: {checkout}" in out
    rows = [words for words in map(str.split, out.splitlines()) if words and words[0].replace(",", "").isdigit()]
    # A row a version: particles, the version, ms, its range, host CPU ms, the ratio to A and its range.
    assert [row[1] for row in rows] == ["A", "B"] and all(len(row) == 7 for row in rows), out
    assert rows[0][-2:] == ["1.00", "(1.00-1.00)"] and float(rows[1][-2]) > 0


TRACE = """Generating SQLite file substeps.sqlite
"Start (ns)","Duration (ns)","CorrId","GrdX","Name"
1000,500,1,4,"predict"
1600,400,2,4,"visit"
2000,100,3,0,"[CUDA memcpy Host-to-Device]"
2500,1000,4,4,"iterate"
3000,200,5,4,"inside iterate's time"
4000,500,6,4,"predict"
"""


def test_kernel_gaps_adds_up_busy_and_idle_time(tmp_path, capsys):
    gaps = script("kernel_gaps")
    result = gaps.analyse(gaps.operations(TRACE), None)
    # 1,000-4,500 ns; idle 1,500-1,600, 2,100-2,500 and 3,500-4,000; the fifth runs inside the fourth.
    assert (result["window"], result["busy"], result["idle"]) == (3500, 2500, 1000)
    assert result["gaps"][0] == (500, "iterate", "predict")
    assert dict(result["by_name"])["predict"] == [2, 1000]
    assert gaps.analyse(gaps.operations(TRACE), 0.0021)["operations"] == 3  # began from 2,400 ns on
    (tmp_path / "trace.csv").write_text(TRACE)
    assert gaps.main([str(tmp_path / "trace.csv"), "--substeps", "2"]) == 0
    out = capsys.readouterr().out
    assert "nothing ran: 0.5 µs a substep (29% of the window, 3 gaps)" in out
    assert "iterate → predict" in out


def test_kernel_gaps_says_what_is_not_a_trace(tmp_path, capsys):
    (tmp_path / "notes.csv").write_text("a,b\n1,2\n")
    assert script("kernel_gaps").main([str(tmp_path / "notes.csv")]) == 1
    assert "not a cuda_gpu_trace report" in capsys.readouterr().err
    # A window shorter than the last operation, which began 500 ns before the trace's end, holds none.
    (tmp_path / "trace.csv").write_text(TRACE)
    assert script("kernel_gaps").main([str(tmp_path / "trace.csv"), "--last-ms", "0.0001"]) == 1
    assert "no operation began in the last 0.0001 ms" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        script("kernel_gaps").main([str(tmp_path / "missing.nsys-rep")])
    assert stop.value.code == 2


@pytest.mark.skipif(shutil.which("bash") is None, reason="gpu_run.sh is a bash script")
def test_gpu_run_refuses_a_base_without_the_package_before_writing(tmp_path):
    out = tmp_path / "out"
    done = subprocess.run(
        ["bash", str(BENCHMARKS / "gpu_run.sh"), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "OUT": str(out)},
        cwd=BENCHMARKS.parent,
    )
    assert done.returncode == 2
    assert "holds no pbf/__init__.py" in done.stderr
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("bash") is None, reason="gpu_run.sh is a bash script")
def test_gpu_run_runs_its_steps_on_the_cpu_at_small_sizes(tmp_path):
    """The GPU run's plumbing, here: every step at a small size on the CPU backend, from another folder,
    against the checkout itself as the base; each step's status and table land in the summary."""
    out = tmp_path / "out"
    small = {"ARCH": "cpu", "SIZES": "300", "BIG": "400", "LARGE": "pour", "PY": sys.executable, "OUT": "out"}
    small["COUNTS_LIMIT"] = "240"  # the CPU's launch counts take a minute on a loaded 2-core machine
    done = subprocess.run(
        ["bash", str(BENCHMARKS / "gpu_run.sh"), str(BENCHMARKS.parent)],
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, **small},
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    summary = (out / "summary.txt").read_text()
    for step in ("physics", "ab", "large", "ten_million", "counts"):
        assert f"== {step}: rc 0" in summary, summary
    assert "ratio to A (range)" in summary and "pour, cpu:" in summary
    assert (out / "cpu.npz").is_file()


@pytest.mark.skipif(shutil.which("bash") is None, reason="the stand-in nsys is a bash script")
def test_kernel_gaps_reads_a_report_through_nsys_stats(tmp_path, monkeypatch, capsys):
    # A stand-in nsys that knows only the report's older name: the newer one is tried first, then that.
    (tmp_path / "trace.csv").write_text(TRACE)
    nsys = tmp_path / "bin" / "nsys"
    nsys.parent.mkdir()
    nsys.write_text(f'#!/bin/bash\n[[ "$3" == gputrace ]] && cat "{tmp_path / "trace.csv"}" && exit 0\nexit 1\n')
    nsys.chmod(0o755)
    monkeypatch.setenv("PATH", f"{nsys.parent}{os.pathsep}{os.environ['PATH']}")
    report = tmp_path / "substeps.nsys-rep"
    report.write_bytes(b"")
    assert script("kernel_gaps").main([str(report)]) == 0
    assert "6 operations in a window of 3.5 µs" in capsys.readouterr().out
