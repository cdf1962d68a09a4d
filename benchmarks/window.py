"""Where a frame of the interactive window goes: the simulation's step, our renderer's draw, the
panel and GGUI's show (the canvas image, the panel's drawing, the present), each in wall-clock and
CPU milliseconds, for the window's renderer and the levers tried on it (docs/BENCHMARKS.md, "The
window"). Needs a display and Vulkan; on a machine without either:

    xvfb-run -a -s "-screen 0 1920x1080x24" python benchmarks/window.py [--frames 150] [--rounds 3]
        [--variants window,before,...] [--scene dam_break] [--warmup 30]

(Debian/Ubuntu: ``apt-get install xvfb mesa-vulkan-drivers libvulkan1`` gives a virtual display and
Mesa's software Vulkan, lavapipe.)

Each variant runs in a fresh process (some levers are environment variables read when the Vulkan
driver or Taichi starts), the variants alternate round by round, and every figure is the median over
the rounds of a round's median over its frames, after ``--warmup`` frames (JIT, the first impact);
``fps`` is the frames over the wall time they took. The frames are those of ``python run.py``: the
seed scene from rest at 1280 × 720, the same camera, no input. ``cpu`` is the CPU time of the
window's process per frame (every thread: Taichi's, the Vulkan driver's), ``X`` that of the X server
(Xvfb) when there is one to read, and for "sim-in-second-process" (the solver a frame ahead in a
process of its own; "sim" is then the wait for it, "sim in its process" its own step) ``sim process
cpu`` that of the other process: on a 2-core machine the frame rate cannot exceed 2000 / (their sum),
whatever overlaps.

``--offscreen`` runs the same loop without a display: GGUI draws into an offscreen image
(``ti.ui.Window(..., show_window=False)``; Vulkan, but no X server), and a frame's ``show`` is
drawing it and reading it back to the host (``get_image_buffer_as_numpy``: Taichi 1.7.4 has no present
without a surface), a copy a shown window does not make. ``--arch`` picks the simulation's and the
renderer's backend (GGUI itself always draws with Vulkan). On a machine with a GPU and no display:

    python benchmarks/window.py --offscreen --arch cuda --frames 300 --rounds 3 --variants window,surface,paused

``--start`` measures instead how long ``python run.py`` takes from its launch to the first frame, in
the window and headless, with an empty Taichi kernel cache (a first run: ``TI_OFFLINE_CACHE_FILE_PATH``
and Mesa's shader cache pointed at empty folders) and again with the cache that run filled, in
``--rounds`` alternated rounds; it also counts the files each start adds to the kernel cache (none on
a second start: every kernel, the window's and the renderers' included, came from the cache):

    xvfb-run -a -s "-screen 0 1920x1080x24" python benchmarks/window.py --start [--rounds 3] [--scene dam_break]
"""

import argparse
import gc
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BEFORE = {"draw": "ggui", "env": {"LP_PERF": ""}, "stats_interval_s": 0.0}
"""The window as it was before these changes: GGUI's own particles and lines, lavapipe's default
(bilinear) sampling, statistics every frame."""
# What each variant changes against "window" (the window as python run.py opens it).
VARIANTS = {
    "window": {},
    "before": BEFORE,
    "before-uniform-colour": {**BEFORE, "colour": False},
    "before-no-lines": {**BEFORE, "lines": False},
    "paused": {"paused": True},
    "paused-before": {"paused": True, **BEFORE},
    "empty-canvas": {"draw": "none"},
    "surface": {"surface": True},
    "set-image": {"draw": "set_image"},
    "unsorted-splat": {"front_to_back": False},
    "lavapipe-bilinear": {"env": {"LP_PERF": ""}},
    "paused-lavapipe-no-texturing": {"paused": True, "env": {"LP_PERF": "no_linear,no_tex"}},
    "stats-every-frame": {"stats_interval_s": 0.0},
    "no-panel": {"panel": False},
    "no-vsync": {"vsync": False},
    "taichi-1-thread": {"cpu_threads": 1},
    "lavapipe-1-thread": {"env": {"LP_NUM_THREADS": "1"}},
    "lavapipe-0-threads": {"env": {"LP_NUM_THREADS": "0"}},
    "gc-freeze": {"gc": "freeze"},
    "malloc-keeps-memory": {
        "env": {"GLIBC_TUNABLES": "glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=268435456"}
    },
    "sim-in-second-process": {"sim_process": True},
    "sim-in-second-process-renderer-1-thread": {"sim_process": True, "cpu_threads": 1},
}
DEFAULT_VARIANTS = ("window", "before", "paused", "empty-canvas", "sim-in-second-process")
WARMUP_FRAMES = 30
"""Frames before the measured ones by default: the kernels compile and the block reaches the floor."""
PHASES = ("frame", "sim", "sim_own", "draw", "panel", "show")


def process_cpu_s(pid: int) -> float:
    """CPU seconds process ``pid`` has used (all its threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def x_server_cpu_s() -> float | None:
    """CPU seconds the X server of $DISPLAY has used, if it is an Xvfb or Xorg process we can read."""
    display = os.environ.get("DISPLAY", "")
    for proc in Path("/proc").iterdir():
        try:
            if not proc.name.isdigit():
                continue
            argv = (proc / "cmdline").read_bytes().split(b"\0")
            if Path(argv[0].decode()).name in ("Xvfb", "Xorg") and display.encode() in argv:
                return process_cpu_s(int(proc.name))
        except (OSError, IndexError, UnicodeDecodeError):
            continue
    return None


class Clock:
    """Wall and process CPU time, in ms, of the phases of one frame."""

    def __init__(self):
        self.spent = {}

    def timed(self, phase, function):
        def run(*args, **kwargs):
            wall, cpu = time.perf_counter(), time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.add(phase, time.perf_counter() - wall, time.process_time() - cpu)

        return run

    def add(self, phase, wall_s, cpu_s):
        w, c = self.spent.get(phase, (0.0, 0.0))
        self.spent[phase] = (w + 1e3 * wall_s, c + 1e3 * cpu_s)


def make_offscreen(gui_window) -> None:
    """A window without a display as the viewer uses one: its ``show`` draws the frame (GGUI draws it
    when its image is read), and its input, which GGUI refuses without a display, is none: no key, no
    button, the cursor in the middle (the benchmark gives no input either)."""
    gui_window.show = lambda: gui_window.get_image_buffer_as_numpy()
    gui_window.get_events = lambda *kind: []
    gui_window.is_pressed = lambda *keys: False
    gui_window.get_cursor_pos = lambda: (0.5, 0.5)


def measure(
    name: str, frames: int, scene: str, warmup: int = WARMUP_FRAMES, offscreen: bool = False, arch: str | None = None
) -> dict:
    """One variant in this process: the medians over ``frames`` frames after ``warmup`` frames."""
    settings = VARIANTS[name]
    import taichi as ti

    from pbf.app import window  # pbf first: it keeps Taichi's banner off
    from pbf.solver import Simulation, start_backend

    start_backend(arch, quiet=True, cpu_threads=settings.get("cpu_threads"))
    sim = Simulation(scene, quiet=True)
    try:
        gui_window = window.open_window(
            "pbf benchmark",
            sim.scene.render.width_px,
            sim.scene.render.height_px,
            vsync=settings.get("vsync", True) and not offscreen,
            show_window=not offscreen,
        )
    except window.WindowUnavailable as reason:
        raise SystemExit(f"no window: {reason}") from None
    if offscreen:
        make_offscreen(gui_window)
    viewer = window.WindowViewer(sim, gui_window)
    viewer.surface = settings.get("surface", False)
    viewer.paused = settings.get("paused", False)
    window.STATS_INTERVAL_S = settings.get("stats_interval_s", window.STATS_INTERVAL_S)
    draw = settings.get("draw", "ours")
    if draw == "ggui":
        viewer.draw = lambda: draw_ggui_particles(viewer, settings.get("colour", True), settings.get("lines", True))
    elif draw == "none":
        viewer.draw = lambda: viewer.window.get_canvas().set_background_color(tuple(viewer.render.background_rgb))
    elif draw == "set_image":
        viewer.draw = lambda: draw_through_set_image(viewer)
    if not settings.get("front_to_back", True):
        viewer.draw()  # makes the renderer
        viewer.frames.spheres.front_to_back = False
    if not settings.get("panel", True):
        viewer.panel = lambda stats: None

    other = SimulationProcess(sim, scene) if settings.get("sim_process") else None

    def step():
        if other:
            other.step()
        else:
            sim.step()
            ti.sync()

    clock = Clock()
    viewer.draw = clock.timed("draw", viewer.draw)
    viewer.panel = clock.timed("panel", viewer.panel)
    viewer.window.show = clock.timed("show", viewer.window.show)
    rows = []
    x_start = cpu_start = None
    viewer.show()
    for frame in range(warmup + frames):
        if frame == warmup:
            if settings.get("gc") == "freeze":
                gc.collect()
                gc.freeze()
            x_start = None if offscreen else x_server_cpu_s()
            cpu_start, wall_start = time.process_time(), time.perf_counter()
            other_start = process_cpu_s(other.process.pid) if other else None
        clock.spent = {}
        wall, cpu = time.perf_counter(), time.process_time()
        if viewer.advance():
            clock.timed("sim", step)()
        viewer.show()
        clock.add("frame", time.perf_counter() - wall, time.process_time() - cpu)
        if frame >= warmup:
            rows.append(dict(clock.spent))
    elapsed = time.perf_counter() - wall_start
    x_end = None if offscreen else x_server_cpu_s()
    other_end = process_cpu_s(other.process.pid) if other else None
    if other:
        for row, step_ms in zip(rows, other.step_ms[-len(rows) :]):
            row["sim_own"] = (step_ms, 0.0)
        other.close()
    result = {
        "variant": name,
        "fps": frames / elapsed,
        "load": os.getloadavg()[0],
        "cpu": 1e3 * (time.process_time() - cpu_start) / frames,
        "X": None if x_start is None or x_end is None else 1e3 * (x_end - x_start) / frames,
        "sim_process_cpu": None if other_end is None else 1e3 * (other_end - other_start) / frames,
    }
    for phase in PHASES:
        present = any(phase in row for row in rows)
        result[phase] = statistics.median(row.get(phase, (0.0, 0.0))[0] for row in rows) if present else None
        result[phase + "_cpu"] = statistics.median(row.get(phase, (0.0, 0.0))[1] for row in rows) if present else None
    return result


class SimulationProcess:
    """The one lever that can overlap the simulation with the rendering, as a prototype: the solver in a
    process of its own, a frame ahead (in one process they cannot overlap: a Taichi kernel launch and
    GGUI's show both hold Python's GIL from start to end). ``step`` takes the frame the other process
    finished (positions and velocities through a pipe, into the fields of this process's Simulation,
    which the renderer reads) and starts it on the next, so the two run side by side; the step phase
    then measures the wait, and ``step_ms`` keeps the other process's own time per frame."""

    def __init__(self, sim, scene: str):
        import multiprocessing

        self.sim = sim
        self.step_ms = []
        context = multiprocessing.get_context("spawn")  # a fresh interpreter: Taichi does not survive fork
        self.connection, child = context.Pipe()
        self.process = context.Process(target=simulate, args=(scene, child), daemon=True)
        self.process.start()
        self.connection.recv()  # built and compiled
        self.connection.send("step")

    def step(self):
        positions, velocities, step_ms = self.connection.recv()
        self.connection.send("step")
        self.sim.state.x.from_numpy(positions)  # the fields Simulation.readout() hands the renderer
        self.sim.state.v.from_numpy(velocities)
        self.step_ms.append(step_ms)

    def close(self):
        self.connection.send("stop")
        self.process.join(timeout=10)


def simulate(scene: str, connection) -> None:
    """The other process of ``SimulationProcess``: steps a frame whenever asked and sends its particles."""
    import taichi as ti

    from pbf.solver import Simulation, start_backend

    start_backend(quiet=True)
    sim = Simulation(scene, quiet=True)
    sim.step()
    connection.send("ready")
    while connection.recv() == "step":
        started = time.perf_counter()
        sim.step()
        ti.sync()
        step_ms = 1e3 * (time.perf_counter() - started)
        connection.send((sim.state.x.to_numpy(), sim.state.v.to_numpy(), step_ms))


def draw_ggui_particles(viewer, per_vertex_colour: bool, lines: bool) -> None:
    """The window's drawing before our renderer took over: GGUI's own particles (a sphere impostor per
    particle whose fragment shader writes depth) and lines."""
    import taichi as ti

    from pbf.app.render import LIGHT_DIRECTION, scene_edges

    if not hasattr(viewer, "ggui_edges"):
        edges = scene_edges(viewer.sim.scene)
        viewer.ggui_edges = ti.Vector.field(3, ti.f32, shape=len(edges))
        viewer.ggui_edges.from_numpy(edges)
        viewer.ggui_camera = ti.ui.Camera()
    view = viewer.camera.view()
    camera = viewer.ggui_camera
    camera.position(*view.eye)
    camera.lookat(*view.target)
    camera.up(0.0, 1.0, 0.0)
    camera.fov(view.fov_deg)
    scene = viewer.window.get_scene()
    scene.set_camera(camera)
    scene.ambient_light((0.35, 0.35, 0.35))
    scene.point_light(pos=tuple(view.eye + 10.0 * LIGHT_DIRECTION), color=(0.9, 0.9, 0.9))
    width, height = viewer.window.get_window_shape()
    particles = viewer.sim.readout()
    colour = {"per_vertex_color": viewer.frames.colours.update()} if per_vertex_colour else {"color": (0.3, 0.5, 0.9)}
    scene.particles(
        particles.positions, radius=particles.radius_m * height / width, index_count=particles.count, **colour
    )
    if lines:
        scene.lines(viewer.ggui_edges, width=1.5, color=tuple(viewer.render.container_rgb))
    canvas = viewer.window.get_canvas()
    canvas.set_background_color(tuple(viewer.render.background_rgb))
    canvas.scene(scene)


def draw_through_set_image(viewer) -> None:
    """Our renderer's frame handed over as the window did before ``show_packed``: copied into a (W, H)
    field of RGB bytes (y up) and given to GGUI's public ``Canvas.set_image``, which converts it into
    packed words with a pass of its own."""
    import taichi as ti

    from pbf.app import window

    @ti.kernel
    def to_field(packed: ti.types.ndarray(dtype=ti.u32, ndim=2), rgb: ti.template()):
        for x, y in rgb:
            word = packed[x, y]
            rgb[x, y] = ti.Vector([word & 0xFF, (word >> 8) & 0xFF, (word >> 16) & 0xFF], ti.u8)

    def set_image(canvas, packed):
        if getattr(viewer, "rgb_field", None) is None or viewer.rgb_field.shape != packed.shape:
            viewer.rgb_field = ti.Vector.field(3, ti.u8, shape=packed.shape)
        to_field(packed, viewer.rgb_field)
        canvas.set_image(viewer.rgb_field)

    show_packed = window.show_packed
    window.show_packed = set_image
    try:
        window.WindowViewer.draw(viewer)
    finally:
        window.show_packed = show_packed


def backend_name(arch: str | None) -> str:
    """The backend the runs used, as the start line names it (started here only to be named)."""
    from pbf.solver import start_backend

    return start_backend(arch, quiet=True)


def table(results: dict[str, list[dict]]) -> str:
    def cell(rows, key):
        values = [r[key] for r in rows if r[key] is not None]
        return f"{statistics.median(values):.1f}" if values else "-"

    header = (
        "| variant | fps | frame ms | sim ms | sim in its process ms | draw ms | panel ms | show ms | "
        "cpu ms/frame | sim process cpu ms/frame | X ms/frame | sim, draw, show cpu ms | load |"
    )
    lines = [header, "|---|" + "---:|" * (header.count("|") - 2)]
    for name, rows in results.items():
        lines.append(
            f"| {name} | {cell(rows, 'fps')} | {cell(rows, 'frame')} | {cell(rows, 'sim')} | "
            f"{cell(rows, 'sim_own')} | "
            f"{cell(rows, 'draw')} | {cell(rows, 'panel')} | {cell(rows, 'show')} | {cell(rows, 'cpu')} | "
            f"{cell(rows, 'sim_process_cpu')} | "
            f"{cell(rows, 'X')} | {cell(rows, 'sim_cpu')}, {cell(rows, 'draw_cpu')}, "
            f"{cell(rows, 'show_cpu')} | {cell(rows, 'load')} |"
        )
    return "\n".join(lines)


RUN = Path(__file__).resolve().parent.parent / "run.py"
READY = "[pbf] kernels ready and the first frame drawn in "
"""The line ``python run.py`` prints once its first frame is drawn (``pbf.app.cli``)."""


def first_frame_s(scene: str, window: bool, cache: Path, out: Path) -> tuple[float, float, int]:
    """Start ``python run.py`` with the kernel cache in ``cache``; returns the seconds from its launch to
    the line saying the first frame is drawn, the seconds that line gives (from before the first kernel
    compiles), and the files the run added to the cache. The run is then stopped."""
    before = len(list(cache.rglob("*")))
    command = [sys.executable, str(RUN), scene, "--frames", "1", "--out", str(out), "--overwrite"]
    env = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": str(cache), "MESA_SHADER_CACHE_DIR": str(cache / "mesa")}
    started = time.perf_counter()
    process = subprocess.Popen(
        command if window else [*command, "--headless"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    reported = None
    for line in process.stdout:
        if line.startswith(READY):
            seconds = time.perf_counter() - started
            reported = float(line[len(READY) :].split()[0])
            break
        if window and line.startswith("[pbf] no window"):
            process.kill()
            raise SystemExit(line.strip())
    process.wait()  # one frame after the first: the process ends by itself
    if reported is None:
        raise SystemExit(f"run.py {scene} ended without its first frame (status {process.returncode})")
    return seconds, reported, len(list(cache.rglob("*"))) - before


def start_times(scene: str, rounds: int) -> str:
    """The table of ``--start``: medians over the rounds, the rounds' figures beside them."""
    rows = {(where, cache): [] for where in ("window", "headless") for cache in ("empty", "filled")}
    for round_ in range(rounds):
        for where in ("window", "headless"):
            with tempfile.TemporaryDirectory() as folder:
                cache, out = Path(folder) / "cache", Path(folder) / "out"
                cache.mkdir()
                for state in ("empty", "filled"):  # the first start fills the cache the second reads
                    result = first_frame_s(scene, where == "window", cache, out)
                    rows[where, state].append(result)
                    print(
                        f"round {round_ + 1}/{rounds} {where}, cache {state}: first frame after {result[0]:.1f} s "
                        f"({result[1]:.1f} s from the compile line), {result[2]} new cache files",
                        file=sys.stderr,
                        flush=True,
                    )
    lines = [
        "| start | kernel cache | s to the first frame: median (runs) | s from the compile line | new cache files |",
        "|---|---|---:|---:|---:|",
    ]
    for (where, state), results in rows.items():
        launch, reported, added = zip(*results)
        runs = ", ".join(f"{value:.1f}" for value in launch)
        lines.append(
            f"| {where} | {state} | **{statistics.median(launch):.1f}** ({runs}) | {statistics.median(reported):.1f} "
            f"| {max(added)} |"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--frames", type=int, default=150, help="measured frames per run (default 150)")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each variant, alternated (default 3)")
    parser.add_argument(
        "--variants", default=",".join(DEFAULT_VARIANTS), help=f"comma-separated, from: {', '.join(VARIANTS)}"
    )
    parser.add_argument("--scene", default="dam_break")
    parser.add_argument(
        "--warmup", type=int, default=WARMUP_FRAMES, help=f"frames before the measured ones (default {WARMUP_FRAMES})"
    )
    parser.add_argument(
        "--offscreen", action="store_true", help="draw offscreen (GGUI's show_window=False): Vulkan, no display"
    )
    parser.add_argument("--arch", default=None, help="the simulation's and renderer's backend (default: auto)")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # a single run, in this process, printed as JSON
    parser.add_argument(
        "--start", action="store_true", help="time python run.py's start to its first frame, cache empty and filled"
    )
    args = parser.parse_args(argv)
    if args.frames < 1 or args.rounds < 1 or args.warmup < 0:
        parser.error(
            f"--frames {args.frames}, --rounds {args.rounds}, --warmup {args.warmup}: allowed at least 1, 1 and 0"
        )
    if args.one:
        result = measure(args.one, args.frames, args.scene, args.warmup, args.offscreen, args.arch)
        print(json.dumps(result), flush=True)
        return
    if args.start:
        load = os.getloadavg()[0]
        print(f"{args.scene}: python run.py's start, {args.rounds} rounds (load at the start {load:.1f})")
        print(start_times(args.scene, args.rounds))
        return
    names = [name.strip() for name in args.variants.split(",") if name.strip()]
    unknown = [name for name in names if name not in VARIANTS]
    if unknown:
        parser.error(f"unknown variant {unknown[0]!r}; known: {', '.join(VARIANTS)}")
    results = {name: [] for name in names}
    for round_ in range(args.rounds):
        for name in names:
            # Environment variables of a variant are set before the process starts: the C library
            # and the Vulkan driver read theirs when they load.
            run = subprocess.run(
                [
                    sys.executable,
                    __file__,
                    "--one",
                    name,
                    "--frames",
                    str(args.frames),
                    "--scene",
                    args.scene,
                    "--warmup",
                    str(args.warmup),
                    *(["--offscreen"] if args.offscreen else []),
                    *(["--arch", args.arch] if args.arch else []),
                ],
                capture_output=True,
                text=True,
                env={**os.environ, **VARIANTS[name].get("env", {})},
            )
            if run.returncode != 0:
                raise SystemExit(f"{name}: {(run.stderr or run.stdout).strip().splitlines()[-1]}")
            result = json.loads(run.stdout.strip().splitlines()[-1])
            results[name].append(result)
            phases = " + ".join(
                f"{phase} {result[phase]:.1f}"
                for phase in ("sim", "draw", "panel", "show")
                if result[phase] is not None
            )
            print(
                f"round {round_ + 1}/{args.rounds} {name} (load {result['load']:.1f}): {result['fps']:.1f} fps, "
                f"{phases} ms",
                file=sys.stderr,
                flush=True,
            )
    where = "offscreen (GGUI show_window=False; show = draw + read back)" if args.offscreen else "in a window"
    print(
        f"{args.scene}, {args.frames} frames × {args.rounds} rounds, {where}, on {backend_name(args.arch)}, "
        f"medians (ms per frame; cpu: all threads)"
    )
    print(table(results))


if __name__ == "__main__":
    main()
