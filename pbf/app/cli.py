"""Command line: open a scene in a window, render it headless to PNG/video/particle files, or list presets.

    python run.py [SCENE] [--set KEY=VALUE]...               # the window (headless when none can open)
    python run.py SCENE --headless --frames N --out DIR [--video FILE.mp4 [--no-png]] [--export ply|npz|mesh]...
    python run.py --list
    python run.py --keys                                      # every scene key (docs/KEYS.md)

Everything the user gives is checked before Taichi starts and before anything is written: the
options (each either takes effect or is refused, none is ignored), the scene with its overrides,
the backend and every output path. A failure prints one line to stderr and returns 2. Only then does
it start the backend, try the window (or say in one line why there is none), say whether the kernels
compile or load from Taichi's offline cache, build a Simulation and a viewer (window, headless frames
or statistics) and hand both to the one loop of ``pbf.app.loop``, saying how long the start took once
the first frame is shown. A frame whose files cannot be made (its surface mesh) ends the run with one
line and status 1, the frames before it whole.
"""

import argparse
import difflib
import json
import os
import re
import sys
import time
from pathlib import Path

from pbf import scene as schema
from pbf.app import export, outputs
from pbf.app.keys import HELP

ARCHES = ("auto", "cpu", "gpu", "cuda", "vulkan", "metal")
"""``pbf.solver.ARCHES`` (tests/test_options.py checks that they agree), named here so that ``--help``
and a bad backend are answered without importing the solver."""
ARCH_VARIABLE = "PBF_ARCH"
"""``pbf.solver.ENV_VAR``."""
EPILOG = "\n".join(
    [
        "examples:",
        "  %(prog)s                   the seed dam break in a window (headless without one)",
        "  %(prog)s dam_break --headless --frames 120 --video out/dam_break.mp4 --no-png",
        "  %(prog)s drop_into_pool --headless --frames 60 --export ply --export mesh",
        "  %(prog)s dam_break --set solver.iterations=8 --set fluid.spacing_m=0.02",
        "  %(prog)s my_scene.toml --stats-only    your own scene file (copy one from scenes/)",
        "  %(prog)s --list            the presets",
        "",
        "in the window:",
        *(f"  {line.strip()}" for line in HELP),
    ]
)
"""The end of --help: examples and the window's mouse and keys."""
HEADLESS_FRAMES = 180
"""Frames a headless or statistics run takes without --frames: 3 s at 60 fps."""


class UsageError(ValueError):
    """A command line that cannot run; the message names the option and what is allowed."""


class Parser(argparse.ArgumentParser):
    """argparse, except that a mistake raises UsageError instead of printing the usage block and
    exiting, so that ``parse_args`` reports argparse's mistakes and its own checks alike."""

    def error(self, message):
        raise UsageError(message)


def frame_count(text: str) -> int:
    """--frames: a whole number of frames from 1 to outputs.MAX_FRAMES."""
    allowed = f"a whole number of frames in [1, {outputs.MAX_FRAMES:,}] (frame files have five digits)"
    try:
        value = int(text)
    except ValueError:  # also an integer of more digits than int() reads
        raise argparse.ArgumentTypeError(f"expected {allowed}, got {schema.echo(text)}") from None
    if not 1 <= value <= outputs.MAX_FRAMES:
        raise argparse.ArgumentTypeError(f"expected {allowed}, got {schema.echo(text)}")
    return value


def build_parser() -> Parser:
    # No prog: argparse names the program as it was called, run.py or the installed pbf command.
    # allow_abbrev=False: argparse would read a mistyped --frame as --frames, or --over as --overwrite.
    parser = Parser(
        allow_abbrev=False,
        description="Position Based Fluids in Taichi: a window, headless frames and video, particle and surface files.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=EPILOG,
    )
    parser.add_argument("scene", nargs="?", default=None, help="preset name or path to a TOML file (default dam_break)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scene key, e.g. --set solver.iterations=6 (repeatable)",
    )
    parser.add_argument(
        "--arch",
        choices=ARCHES,
        default=None,
        help=f"Taichi backend (default: ${ARCH_VARIABLE} or auto: CUDA, else a hardware Vulkan or "
        f"Metal GPU, else the CPU; gpu: the best GPU backend found)",
    )
    parser.add_argument("--list", action="store_true", help="list the presets and exit")
    parser.add_argument(
        "--keys",
        action="store_true",
        help="print the reference of every scene key (Markdown, as docs/KEYS.md) and exit",
    )
    output = parser.add_argument_group("output")
    mode = output.add_mutually_exclusive_group()
    mode.add_argument("--headless", action="store_true", help="render frames to files instead of a window")
    mode.add_argument("--stats-only", action="store_true", help="simulate and print statistics, render nothing")
    output.add_argument(
        "--frames",
        type=frame_count,
        default=None,
        help=f"frames to simulate (default: {HEADLESS_FRAMES}, 3 s at 60 fps, headless; the window runs until closed)",
    )
    output.add_argument(
        "--out",
        default=None,
        help="folder for PNG frames and --export files (default out/ + the scene file's name, or the next "
        "free out/NAME-2 … when it holds an earlier run; also where the window writes when none can open); a folder "
        "given here that holds an earlier run's files is refused unless --overwrite",
    )
    output.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run's files in --out, or in the default folder out/NAME (only "
        "frame_*.png, particles_*.ply/.npz and surface_*.ply/.obj are removed), and an existing --video file",
    )
    output.add_argument(
        "--video",
        default=None,
        help="also encode the frames as a video (.mp4, H.264); needs --headless; with --no-png instead of PNG frames",
    )
    output.add_argument(
        "--no-png",
        action="store_true",
        help="write the --video alone, without the PNG frames (--export files still go to --out)",
    )
    output.add_argument(
        "--export",
        choices=export.EXPORTS,
        action="append",
        default=None,
        help="also write per frame the particles (ply, npz: positions and velocities) or the "
        "fluid's surface (mesh: PLY or OBJ, see surface.mesh_format); repeatable; needs "
        "--headless",
    )
    view = parser.add_argument_group("view (shortcuts for --set camera.* and render.*; not with --stats-only)")
    view.add_argument("--size", metavar="WxH", help="image size in pixels, e.g. 1920x1080")
    view.add_argument("--camera", metavar="X,Y,Z", help="eye position, m")
    view.add_argument("--look-at", metavar="X,Y,Z", help="point at the image centre, m")
    view.add_argument("--fov", metavar="DEG", help="vertical field of view, degrees")
    view.add_argument(
        "--colour-by", choices=("speed", "density"), help="particle colour, with its legend on headless frames"
    )
    view.add_argument("--colour-map", metavar="NAME", help="Matplotlib colour map, e.g. viridis")
    view.add_argument(
        "--style",
        choices=("particles", "surface"),
        help="headless frames: particles as coloured spheres, or the water's surface",
    )
    return parser


VIEW_OPTIONS = ("size", "camera", "look_at", "fov", "colour_by", "colour_map", "style")
FILE_OPTIONS = ("video", "export")


def _option(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def parse_args(argv=None):
    """The options, checked; a mistake prints one line to stderr and exits with status 2, as
    argparse does, but without the usage block."""
    try:
        return checked_args(argv)
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        raise SystemExit(2) from None


def checked_args(argv=None):
    """The options, checked for what no single option can see: unknown options (with the closest
    known one), options that contradict the mode or would do nothing in it, and empty values."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        word = unknown[0]
        if word.startswith("-"):
            known = [s for action in parser._actions for s in action.option_strings]
            closest = difflib.get_close_matches(word.split("=", 1)[0], known, n=1, cutoff=0.6)
            hint = f"; did you mean {closest[0]}?" if closest else "; python run.py --help lists every option"
            raise UsageError(f"unknown option {schema.echo(word)}{hint}")
        raise UsageError(f"unexpected argument {schema.echo(word)}: one scene at a time, options start with --")
    given = [
        dest
        for dest in ("scene", "arch", "frames", "out", *FILE_OPTIONS, *VIEW_OPTIONS)
        if getattr(args, dest) is not None
    ] + [d for d in ("set", "headless", "stats_only", "no_png") if getattr(args, d)]
    if args.list and args.keys:
        raise UsageError("--list and --keys each print a reference; give one of the two")
    for flag, does in (("list", "lists the presets"), ("keys", "prints the key reference")):
        if getattr(args, flag) and given:
            other = "the scene" if given[0] == "scene" else _option(given[0])
            raise UsageError(f"--{flag} {does} and takes no other option; drop {other}")
    for dest in (*FILE_OPTIONS, *VIEW_OPTIONS, "out"):
        if args.stats_only and getattr(args, dest) is not None:
            raise UsageError(f"{_option(dest)}: --stats-only renders and writes nothing; drop one of the two")
    if args.stats_only and args.overwrite:
        raise UsageError("--overwrite: --stats-only writes nothing to replace; drop one of the two")
    if args.stats_only and args.no_png:
        raise UsageError("--no-png: --stats-only renders and writes nothing; drop one of the two")
    if args.no_png and args.video is None:
        raise UsageError("--no-png writes a video instead of the PNG frames: add --video FILE.mp4, or drop --no-png")
    if args.no_png and args.out is not None and not args.export:
        # Without PNG frames or --export files nothing goes into the folder: --out would do nothing.
        raise UsageError("--out: with --no-png only --export files go there; drop --out, or add --export")
    if args.headless and args.style == "surface":
        for dest in ("colour_by", "colour_map"):
            if getattr(args, dest) is not None:
                raise UsageError(
                    f"{_option(dest)}: --style surface draws the water's surface, without particle "
                    f"colours; drop one of the two"
                )
    for dest in FILE_OPTIONS:
        if not (args.headless or args.stats_only) and getattr(args, dest) is not None:
            raise UsageError(f"{_option(dest)} writes files, which the window does not; add --headless")
    args.scene = args.scene if args.scene is not None else "dam_break"
    arch = args.arch or os.environ.get(ARCH_VARIABLE) or "auto"
    if arch.lower() not in ARCHES:
        raise UsageError(f"{ARCH_VARIABLE}={schema.echo(arch)}: unknown backend; allowed: {', '.join(ARCHES)}")
    args.view = view_overrides(args)
    return args


def _numbers(text: str, option: str, count: int, example: str) -> list[float]:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count:
        raise UsageError(f"{option} {schema.echo(text)}: expected {example}")
    return values


def view_overrides(args) -> dict[str, str]:
    """The view options as --set assignments (so the scene validates them like any other key), each
    with the option it came from: ``{"render.width_px=1920": "command line --size 1920x1080"}``.
    Values are written as TOML here (numbers by repr, strings quoted and escaped by json.dumps), never
    pasted in, so no option can smuggle in another key."""
    sets = {}
    if args.size is not None:
        width, _, height = args.size.lower().partition("x")
        if not (width.isdigit() and height.isdigit() and width.isascii() and height.isascii()):
            raise UsageError(f"--size {schema.echo(args.size)}: expected WIDTHxHEIGHT in pixels, e.g. 1280x720")
        label = f"command line --size {schema.echo(args.size)}"
        sets |= {f"render.width_px={int(width)}": label, f"render.height_px={int(height)}": label}
    for dest, key in (("camera", "camera.position_m"), ("look_at", "camera.look_at_m")):
        text = getattr(args, dest)
        if text is not None:
            values = _numbers(text, _option(dest), 3, "X,Y,Z in metres, e.g. 1.6,1.2,2.0")
            sets[f"{key}=[{', '.join(map(repr, values))}]"] = f"command line {_option(dest)} {schema.echo(text)}"
    if args.fov is not None:
        fov = _numbers(args.fov, "--fov", 1, "degrees, e.g. 35")[0]
        sets[f"camera.fov_deg={fov!r}"] = f"command line --fov {schema.echo(args.fov)}"
    for dest, key in (
        ("colour_by", "render.colour_by"),
        ("colour_map", "render.colour_map"),
        ("style", "render.style"),
    ):
        text = getattr(args, dest)
        if text is not None:
            sets[f"{key}={json.dumps(text, ensure_ascii=False)}"] = f"command line {_option(dest)} {schema.echo(text)}"
    return sets


def load(args) -> schema.Scene:
    """The scene with the view options and then the --set overrides applied (--set wins); an error
    in a value from the command line names the option it came from. --colour-by also turns on the
    headless frames' legend (colours alone say nothing of what they measure), where the scene draws
    particles and no --set says otherwise."""
    try:
        scene = schema.load_scene(args.scene, [*args.view, *args.set], schema.COMMAND_LINE)
        legend_set = any(assignment.split("=", 1)[0].strip() == "render.legend" for assignment in args.set)
        if args.colour_by is not None and scene.render.style == "particles" and not legend_set:
            scene = schema.load_scene(args.scene, [*args.view, "render.legend=true", *args.set], schema.COMMAND_LINE)
        return scene
    except schema.SceneError as error:
        if args.scene in REFERENCES and "no such scene file" in str(error):
            # `pbf keys` reads as a subcommand; the references are options, like --help.
            raise UsageError(
                f"{args.scene}: no such scene file or preset; {REFERENCES[args.scene]} is printed by "
                f"--{args.scene} (pbf --{args.scene}, python run.py --{args.scene})"
            ) from None
        raise schema.attribute(error, command_line_keys(args)) from None


REFERENCES = {"keys": "the reference of every scene key", "list": "the list of presets"}
"""The options that print a reference instead of running a scene, by the word a user may type for them."""


def command_line_keys(args) -> dict[str, str]:
    """Every dotted key the command line set, with the option that set it last (--set after the
    view options, as they are applied), for schema.attribute."""
    labels = {assignment.split("=", 1)[0]: label for assignment, label in args.view.items()}
    for assignment in args.set:
        labels[assignment.split("=", 1)[0].strip()] = f"{schema.COMMAND_LINE} {schema.echo(assignment)}"
    return labels


def list_presets() -> None:
    for path in sorted(schema.SCENES_DIR.glob("*.toml")):
        scene = schema.load_scene(path)
        count = f"{scene.particle_count:,}"
        if scene.emitted_count:  # emitters add particles as the scene runs
            count += f" → {scene.particle_capacity:,}"
        print(f"{path.stem:18s} {count:>16} particles  {scene.description}")


def check_view(scene, args) -> None:
    """Colour options that the scene's own render.style = "surface" would ignore in headless frames."""
    if args.headless and scene.render.style == "surface" and args.style is None:
        for dest in ("colour_by", "colour_map"):
            if getattr(args, dest) is not None:
                raise UsageError(
                    f"{_option(dest)}: the scene's render.style = \"surface\" draws the water's "
                    f"surface, without particle colours; drop it, or add --style particles"
                )


DEFAULT_OUT_LABEL = "the default output folder (--out)"


def plan_outputs(scene, args) -> tuple[Path | None, Path | None]:
    """The frame folder and video the run may write, both checked (OutputError) before Taichi starts;
    (None, None) for --stats-only, which writes nothing. A window run is checked as a headless one: it
    writes there when no window can open, which is known only once Taichi has started. An earlier
    run's files in a folder named by --out are refused unless --overwrite; without --out the run takes
    the next free default folder (out/dam_break, out/dam_break-2 …), and --overwrite replaces the
    first's. The folder is None when the run writes nothing there (--no-png without --export)."""
    check_view(scene, args)
    if args.stats_only:
        return None, None
    video = outputs.check_video(args.video, "--video", args.overwrite) if args.video is not None else None
    if args.no_png and not args.export:
        return None, video
    if args.out is not None:
        out = outputs.check_folder(args.out, "--out", args.overwrite)
    else:
        default = outputs.default_folder(scene.source)
        free = default if args.overwrite else outputs.free_default_folder(default)
        out = outputs.check_folder(str(free), DEFAULT_OUT_LABEL, args.overwrite)
        if free != default:
            args.taken_default = default
    return out, video


def frame_writer(sim, args, frames, out, video):
    """The headless viewer, after removing the files an earlier run left in ``out`` (only with --overwrite:
    otherwise such a folder is refused)."""
    from pbf.app.headless import FrameWriter

    if out is None:  # --no-png without --export: the video alone, no folder
        return FrameWriter(sim, frames, None, video=video, png=False)
    label = "--out" if args.out is not None else DEFAULT_OUT_LABEL
    outputs.check_folder(str(out), label, args.overwrite)  # again: files may have appeared since the start
    removed = outputs.clear_earlier(out)
    if removed:
        print(f"[pbf] removed {len(removed)} files of an earlier run from {out}/ ({removed[0].name} …)")
    taken = getattr(args, "taken_default", None)
    if taken is not None:
        print(f"[pbf] {taken}/ holds an earlier run, kept: writing to {out}/ instead (--out names the folder)")
    return FrameWriter(sim, frames, out, video=video, export=args.export, png=not args.no_png)


def try_window(scene, args, waiting: str):
    """The GGUI window the options ask for, or None (headless: asked for, or no window can open here, which
    is said in one line); it shows ``waiting`` until the first frame."""
    if args.headless or args.stats_only:
        return None
    from pbf.app import window

    try:
        gui_window = window.open_window(f"pbf: {scene.name}", scene.render.width_px, scene.render.height_px)
    except window.WindowUnavailable as reason:
        print(f"[pbf] no window: {reason}; rendering headless instead")
        return None
    window.show_waiting(gui_window, scene.render.background_rgb, [waiting.removeprefix("[pbf] ")])
    return gui_window


def choose_viewer(sim, args, gui_window, out, video):
    """The viewer the options ask for, and the frames to run (None: until the window closes)."""
    frames = args.frames or HEADLESS_FRAMES
    if args.stats_only:
        from pbf.app import loop

        return loop.StatsViewer(sim, frames), frames
    if gui_window is not None:
        from pbf.app import window

        if args.out is not None:
            print(f"[pbf] the window opened: nothing is written to --out {out} (it is for headless runs)")
        return window.WindowViewer(sim, gui_window), args.frames
    viewer = frame_writer(sim, args, frames, out, video)
    steps = f"{frames} step{'s' if frames > 1 else ''}"
    print(f"[pbf] rendering {frames + 1} frames (the start and {steps}) into {video if args.no_png else f'{out}/'}")
    return viewer, frames


def scene_line(sim) -> str:
    """The scene's particles (now, and what its emitters will add), Δt and iterations."""
    count = f"{sim.particle_count:,} particles"
    if sim.model.capacity > sim.particle_count:
        count += f" now, up to {sim.model.capacity:,} from its emitters;"
    else:
        count += ","
    return f"[pbf] {sim.scene.name}: {count} Δt = {sim.dt_s * 1e3:.2f} ms, {sim.control.iterations} iterations"


# Said before the first kernel is prepared (``kernels_line`` picks one): compiling the solver's and the
# renderer's kernels takes seconds (docs/BENCHMARKS.md, "The window"), loading them far less, and nothing
# else would show meanwhile; the line after the first frame says how long it took.
COMPILING = "[pbf] compiling kernels (Taichi's offline cache holds none yet; later starts load them from it) ..."
LOADING = "[pbf] loading kernels from Taichi's offline cache, compiling any it does not hold ..."
UNCACHED = "[pbf] compiling kernels (Taichi's offline cache is off) ..."


def kernels_line(cache_on: bool, cache_folder: Path) -> str:
    """What preparing the kernels will do: compile them all when Taichi's offline cache is off or holds
    no kernel (a first run, or a fresh cache folder), else load those an earlier run compiled. Whether it
    holds this scene's kernels for this backend cannot be known before asking Taichi for each, so a
    cache with kernels in it is said to be loaded from, compiling what it lacks."""
    if not cache_on:
        return UNCACHED
    try:
        cached = next(cache_folder.rglob("*.tic"), None) is not None
    except OSError:
        cached = False
    return LOADING if cached else COMPILING


def kernel_cache() -> tuple[bool, Path]:
    """Whether the running Taichi keeps an offline cache of compiled kernels, and its folder
    (``TI_OFFLINE_CACHE``, ``TI_OFFLINE_CACHE_FILE_PATH``; by default ~/.cache/taichi/ticache)."""
    import taichi as ti

    config = ti.cfg
    return bool(config.offline_cache), Path(config.offline_cache_file_path)


def backend_message(text: str, option: str | None, variable: str | None) -> str:
    """The solver's BackendError, worded for Python (``arch='cuda' was requested …; use arch='cpu' or
    'auto'``), as the command line says it: the request as it was given, ``--arch cuda`` or
    ``PBF_ARCH=cuda`` (``option``, else ``variable``), and the remedies as options."""
    requested = (option or variable or "auto").lower()
    given = f"--arch {option}" if option else f"{ARCH_VARIABLE}={variable}" if variable else "--arch auto"
    text = text.replace(f"arch={requested!r}", given)
    text = re.sub(r"\barch='(\w+)' or '(\w+)'", r"--arch \1 or --arch \2", text)
    return re.sub(r"\barch='(\w+)'", r"--arch \1", text)


def report_written(sim, args, viewer) -> None:
    from pbf.app import loop

    print(loop.stats_line(sim))
    render = sim.scene.render
    if args.no_png:
        print(f"[pbf] wrote {video_written(args, viewer, render)}")
        return
    written = f"{len(viewer.paths)} frames in {viewer.out_dir}/"
    if args.video:
        written += f", video {args.video}"
    if args.export:
        written += f", {' and '.join(args.export)} files in {viewer.out_dir}/"
    # The folder held none of a run's own files before this one (outputs.check_folder), so those it
    # holds now are what this run wrote: a bare run's 181 frames take some 50 MB, every time.
    files = outputs.earlier_files(viewer.out_dir) + ([Path(args.video)] if args.video else [])
    size = sum(path.stat().st_size for path in files if path.is_file())
    written += f": {_size(size)} (PNG frames at {render.width_px}×{render.height_px})"
    if not args.video:
        # A run that fell back from the window needs --headless for --video (checked_args refuses it otherwise).
        headless = "" if args.headless else "--headless "
        written += (
            f"; a video instead: {headless}--video {viewer.out_dir}.mp4 --no-png; "
            f"fewer or smaller frames: --frames N, --size WxH"
        )
    print(f"[pbf] wrote {written}")


def video_written(args, viewer, render) -> str:
    """What a --no-png run wrote: the video and its size, then the --export files and theirs."""
    written = (
        f"{viewer.shown} frames as a video, {args.video}: {_size(Path(args.video).stat().st_size)} "
        f"(H.264 at {render.width_px}×{render.height_px})"
    )
    if args.export:
        # As for PNG frames: the folder held none of a run's own files before this one.
        size = sum(path.stat().st_size for path in outputs.earlier_files(viewer.out_dir) if path.is_file())
        written += f"; {' and '.join(args.export)} files in {viewer.out_dir}/: {_size(size)}"
    return written


def _size(size: int) -> str:
    """Bytes as a reader reads them: 52.5 MB, 840 kB."""
    if size >= 1e6:
        return f"{size / 1e6:.1f} MB"
    return f"{size / 1e3:.0f} kB" if size >= 1e3 else f"{size} bytes"


def main(argv=None) -> int:
    """Run the command line; returns the exit status (0, or 2 after one line on stderr). A reader that
    stops early (``pbf --list | head -1``) ends it quietly, with 0."""
    return quiet_when_the_reader_closes(lambda: _main(argv))


def quiet_when_the_reader_closes(command) -> int:
    """``command()``'s exit status, or 0 without a traceback when the pipe its output goes to closes
    (``| head -1``): the reader has what it wanted."""
    try:
        status = command()
        sys.stdout.flush()  # here, where a closed pipe is caught, not in Python's flush at exit
        return status
    except BrokenPipeError:
        # Python flushes stdout again at exit, which would fail the same way: what is left goes to
        # devnull instead (the recipe of the signal module's docs).
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


def _main(argv) -> int:
    try:
        args = parse_args(argv)
        if args.list:
            list_presets()
            return 0
        if args.keys:
            from pbf.scene.reference import reference

            print(reference(), end="")
            return 0
        scene = load(args)
        out, video = plan_outputs(scene, args)
    except SystemExit as done:  # --help, or a mistake parse_args reported
        return done.code
    except (schema.SceneError, outputs.OutputError, UsageError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    from pbf.app import loop
    from pbf.app.headless import ExportError, FrameWriter
    from pbf.solver import BackendError, Simulation, start_backend

    try:
        start_backend(args.arch)  # the start line; the window needs the backend running
        preparing = kernels_line(*kernel_cache())  # before the window: its first frames show it
        gui_window = try_window(scene, args, preparing)
        print(preparing, flush=True)
        started = time.perf_counter()
        sim = Simulation(scene, arch=args.arch)  # derives the Model and checks memory before Taichi allocates
    except schema.SceneError as error:
        print(f"error: {schema.attribute(error, command_line_keys(args))}", file=sys.stderr)
        return 2
    except BackendError as error:
        print(f"error: {backend_message(str(error), args.arch, os.environ.get(ARCH_VARIABLE))}", file=sys.stderr)
        return 2
    print(scene_line(sim), flush=True)
    try:
        viewer, frames = choose_viewer(sim, args, gui_window, out, video)
    except outputs.OutputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    loop.warm_up(sim)  # the step's kernels before the first picture rather than after it

    def ready():
        done = "" if args.stats_only else " and the first frame drawn"
        print(f"[pbf] kernels ready{done} in {time.perf_counter() - started:.1f} s", flush=True)

    try:
        loop.run(sim, viewer, frames, first_shown=ready)
    except ExportError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if isinstance(viewer, FrameWriter):
        report_written(sim, args, viewer)
    return 0
