"""Where a frame of the window as ``python run.py`` opens it goes (the seed from rest, 1280 × 720, no
input): the step, our draw, the panel and GGUI's show, wall and CPU ms (docs/BENCHMARKS.md, "The window").

    xvfb-run -a -s "-screen 0 1920x1080x24" python benchmarks/window.py [--frames 150] [--rounds 3]
        [--variants window,paused,surface] [--warmup 30]
    python benchmarks/window.py --offscreen --arch cuda --variants window,surface,paused   # no display

Each variant runs in a fresh process, alternated round by round; a figure is the median over the
rounds of a round's median over its frames; ``cpu`` is the process's (every thread), ``X`` the X
server's. ``--offscreen``: GGUI's ``show_window=False``, ``show`` drawing and reading the image back.
Needs Vulkan and, but offscreen, a display: ``apt-get install xvfb mesa-vulkan-drivers libvulkan1``.
"""

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the checkout on the path, for benchmarks.lab
    sys.path.append(str(Path(__file__).resolve().parent.parent))
from benchmarks.lab import Clock, RunFailed, at_least, fresh, markdown, medians  # noqa: E402
from pbf.app import window  # noqa: E402
from pbf.solver import Simulation, start_backend  # noqa: E402

# What each variant changes against "window" (the window as python run.py opens it). The levers tried
# on it (the driver's and Taichi's threads, vsync, the statistics' rate, GGUI's own particles, ...) are
# in docs/HISTORY_BENCHMARKS.md, "The window: the levers".
VARIANTS = {"window": {}, "paused": {"paused": True}, "surface": {"surface": True}}
SCENE = "dam_break"  # the seed, as python run.py opens it
WARMUP_FRAMES = 30
"""Frames before the measured ones by default: the kernels compile and the block reaches the floor."""
PHASES = ("frame", "sim", "draw", "panel", "show")


def x_server_cpu_s() -> float | None:
    """CPU seconds the X server of $DISPLAY has used (all its threads), if it is an Xvfb or Xorg process
    we can read."""
    display = os.environ.get("DISPLAY", "").encode()
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            argv = (proc / "cmdline").read_bytes().split(b"\0")
            if Path(argv[0].decode()).name in ("Xvfb", "Xorg") and display in argv:
                fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()  # user and system time
                return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, IndexError, UnicodeDecodeError):
            continue
    return None


def make_offscreen(gui_window) -> None:
    """A window without a display as the viewer uses one: its ``show`` draws the frame (GGUI draws it
    when its image is read), and its input, which GGUI refuses without a display, is none: no key, no
    button, the cursor in the middle (the benchmark gives no input either)."""
    gui_window.show = lambda: gui_window.get_image_buffer_as_numpy()
    gui_window.get_events = lambda *kind: []
    gui_window.is_pressed = lambda *keys: False
    gui_window.get_cursor_pos = lambda: (0.5, 0.5)


def measure(name: str, frames: int, warmup: int, offscreen: bool, arch: str | None) -> dict:
    """One variant in this process: the medians over ``frames`` frames after ``warmup`` frames."""
    settings = VARIANTS[name]
    import taichi as ti  # here, after pbf: it keeps Taichi's banner off

    start_backend(arch, quiet=True)
    sim = Simulation(SCENE, quiet=True)
    size = sim.scene.render.width_px, sim.scene.render.height_px
    try:
        gui_window = window.open_window("pbf benchmark", *size, vsync=not offscreen, show_window=not offscreen)
    except window.WindowUnavailable as reason:
        raise SystemExit(f"no window: {reason}") from None
    if offscreen:
        make_offscreen(gui_window)
    viewer = window.WindowViewer(sim, gui_window)
    viewer.surface = settings.get("surface", False)
    viewer.paused = settings.get("paused", False)

    def frame():
        if viewer.advance():
            step()
        viewer.show()

    spent = {}  # the frame's phases: (wall, CPU) ms, the process's CPU time (every thread's)

    def timed(phase, function):  # ``function``, adding its time to ``phase`` at each call
        def run(*args, **kwargs):
            clock = Clock()
            result = function(*args, **kwargs)
            spent[phase] = tuple(a + 1e3 * b for a, b in zip(spent.get(phase, (0.0, 0.0)), clock.lap()))
            return result

        return run

    step = timed("sim", lambda: (sim.step(), ti.sync()))
    frame = timed("frame", frame)
    for phase in ("draw", "panel"):
        setattr(viewer, phase, timed(phase, getattr(viewer, phase)))
    viewer.window.show = timed("show", viewer.window.show)
    viewer.show()
    for _ in range(warmup):
        frame()
    x_start, whole, rows = None if offscreen else x_server_cpu_s(), Clock(), []
    for _ in range(frames):
        spent.clear()
        frame()
        rows.append(dict(spent))
    (elapsed, cpu_s), x_end = whole.lap(), None if offscreen else x_server_cpu_s()
    result = {
        "variant": name,
        "fps": frames / elapsed,
        "load": os.getloadavg()[0],
        "cpu": 1e3 * cpu_s / frames,
        "X": None if x_start is None or x_end is None else 1e3 * (x_end - x_start) / frames,
    }
    for phase in PHASES:
        present = any(phase in row for row in rows)
        wall, cpu = medians(row.get(phase, (0.0, 0.0)) for row in rows) if present else (None, None)
        result[phase], result[phase + "_cpu"] = wall, cpu
    return result


def table(results: dict[str, list[dict]]) -> str:
    """Per variant, the median over its rounds of each figure ("-" where none was measured)."""

    def cell(rows, *keys):
        values = [[r[key] for r in rows if r[key] is not None] for key in keys]
        return ", ".join(f"{statistics.median(v):.1f}" if v else "-" for v in values)

    head = ["variant", "fps", "frame ms", "sim ms", "draw ms", "panel ms", "show ms", "cpu ms/frame", "X ms/frame"]
    keys = ("fps", "frame", "sim", "draw", "panel", "show", "cpu", "X")
    cpu = ("sim_cpu", "draw_cpu", "show_cpu")
    rows = [
        [name, *(cell(runs, k) for k in keys), cell(runs, *cpu), cell(runs, "load")] for name, runs in results.items()
    ]
    return markdown([*head, "sim, draw, show cpu ms", "load"], rows)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=at_least(1), default=150, help="measured frames per run (default 150)")
    parser.add_argument("--rounds", type=at_least(1), default=3, help="runs of each variant, alternated (default 3)")
    parser.add_argument("--variants", default="window,paused", help=f"comma-separated, from: {', '.join(VARIANTS)}")
    parser.add_argument("--warmup", type=at_least(0), default=WARMUP_FRAMES, help="frames before the measured ones")
    parser.add_argument("--offscreen", action="store_true", help="GGUI's show_window=False: Vulkan, no display")
    parser.add_argument("--arch", default=None, help="the simulation's and renderer's backend (default: auto)")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # a single run, in this process, printed as JSON
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(measure(args.one, args.frames, args.warmup, args.offscreen, args.arch)), flush=True)
        return
    names = [name.strip() for name in args.variants.split(",") if name.strip()]
    unknown = [name for name in names if name not in VARIANTS]
    if unknown:
        parser.error(f"unknown variant {unknown[0]!r}; known: {', '.join(VARIANTS)}")
    options = ["--frames", str(args.frames), "--warmup", str(args.warmup)] + ["--offscreen"] * args.offscreen
    options += ["--arch", args.arch] if args.arch else []
    results = {name: [] for name in names}
    for round_ in range(args.rounds):
        for name in names:  # each run a fresh process, as a user's window
            try:
                output = fresh([sys.executable, __file__, "--one", name, *options])
            except RunFailed as failure:
                raise SystemExit(f"{name}: {failure}") from None
            result = json.loads(output.strip().splitlines()[-1])
            results[name].append(result)
            phases = " + ".join(f"{p} {result[p]:.1f}" for p in PHASES[1:] if result[p] is not None)
            progress = f"round {round_ + 1}/{args.rounds} {name} (load {result['load']:.1f}): {result['fps']:.1f} fps"
            print(f"{progress}, {phases} ms", file=sys.stderr, flush=True)
    where = "offscreen (GGUI show_window=False; show = draw + read back)" if args.offscreen else "in a window"
    backend = start_backend(args.arch, quiet=True)  # started here only to be named
    print(
        f"{SCENE}, {args.frames} frames × {args.rounds} rounds, {where}, on {backend}, medians (ms; cpu: all threads)"
    )
    print(table(results))


if __name__ == "__main__":
    main()
