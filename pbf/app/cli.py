"""Command line: open a scene in a window, render it headless to PNG/video/particle files, or list presets.

    python run.py [SCENE] [--set KEY=VALUE]...               # the window (headless when none can open)
    python run.py SCENE --headless --frames N --out DIR [--video FILE.mp4] [--export ply|npz|mesh]...
    python run.py --list

It builds a Simulation and a viewer (window, headless frames or statistics) and hands both to the
one loop of ``pbf.app.loop``.
"""
import argparse
import sys
from pathlib import Path

from pbf import scene as schema
from pbf.app import export, loop
from pbf.app.headless import FrameWriter
from pbf.solver import ARCHES, ENV_VAR, BackendError, Simulation

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="run.py", description="Position Based Fluids in Taichi.")
    parser.add_argument("scene", nargs="?", default="dam_break", help="preset name or path to a TOML file")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene key, e.g. --set solver.iterations=6 (repeatable)")
    parser.add_argument("--arch", choices=ARCHES, default=None,
                        help=f"Taichi backend (default: ${ENV_VAR} or auto)")
    parser.add_argument("--list", action="store_true", help="list the presets and exit")
    output = parser.add_argument_group("headless output")
    output.add_argument("--headless", action="store_true", help="render frames to files instead of a window")
    output.add_argument("--stats-only", action="store_true", help="simulate and print statistics, render nothing")
    output.add_argument("--frames", type=int, default=180, help="frames to simulate (default 180: 3 s at 60 fps)")
    output.add_argument("--out", type=Path, default=None, help="folder for PNG frames (default out/SCENE)")
    output.add_argument("--video", type=Path, default=None, help="also encode the frames as a video (.mp4)")
    output.add_argument("--export", choices=export.EXPORTS, action="append", default=None,
                        help="also write per frame the particles (ply, npz: positions and velocities) or the "
                             "fluid's surface (mesh: PLY or OBJ, see surface.mesh_format); repeatable")
    view = parser.add_argument_group("view (shortcuts for --set camera.* and render.*)")
    view.add_argument("--size", metavar="WxH", help="image size in pixels, e.g. 1920x1080")
    view.add_argument("--camera", metavar="X,Y,Z", help="eye position, m")
    view.add_argument("--look-at", metavar="X,Y,Z", help="point at the image centre, m")
    view.add_argument("--fov", metavar="DEG", help="vertical field of view, degrees")
    view.add_argument("--colour-by", choices=("speed", "density"), help="particle colour")
    view.add_argument("--colour-map", metavar="NAME", help="Matplotlib colour map, e.g. viridis")
    view.add_argument("--style", choices=("particles", "surface"),
                      help="headless frames: particles as coloured spheres, or the water's surface")
    args = parser.parse_args(argv)
    if args.frames < 1:
        parser.error("--frames: expected an integer ≥ 1")
    if args.video is not None and args.video.suffix.lower() not in VIDEO_SUFFIXES:
        parser.error(f"--video {args.video}: expected a file ending in {', '.join(VIDEO_SUFFIXES)}")
    args.set = view_overrides(parser, args) + args.set
    return args


def view_overrides(parser, args) -> list[str]:
    """The view options as --set assignments, so the scene validates them like any other key."""
    sets = []
    if args.size:
        width, _, height = args.size.lower().partition("x")
        if not (width.isdigit() and height.isdigit()):
            parser.error(f"--size {args.size}: expected WIDTHxHEIGHT in pixels, e.g. 1280x720")
        sets += [f"render.width_px={width}", f"render.height_px={height}"]
    for option, key in (("camera", "camera.position_m"), ("look_at", "camera.look_at_m")):
        value = getattr(args, option)
        if value:
            sets.append(f"{key}=[{value}]")
    if args.fov:
        sets.append(f"camera.fov_deg={args.fov}")
    if args.colour_by:
        sets.append(f'render.colour_by="{args.colour_by}"')
    if args.colour_map:
        sets.append(f'render.colour_map="{args.colour_map}"')
    if args.style:
        sets.append(f'render.style="{args.style}"')
    return sets


def list_presets() -> None:
    for path in sorted(schema.SCENES_DIR.glob("*.toml")):
        scene = schema.load_scene(path)
        print(f"{path.stem:18s} {scene.particle_count:>10,} particles  {scene.description}")


def choose_viewer(sim, args):
    """The viewer the options ask for, and the frames to run (None: until the window closes)."""
    out = args.out or Path("out") / sim.scene.name
    if args.stats_only:
        return loop.StatsViewer(sim, args.frames), args.frames
    if not args.headless:
        from pbf.app import window

        try:
            return window.WindowViewer(sim, window.open_window(f"pbf: {sim.scene.name}", sim.scene.render.width_px,
                                                               sim.scene.render.height_px)), None
        except window.WindowUnavailable as reason:
            print(f"[pbf] no window ({reason}); rendering {args.frames} frames headless instead")
    return FrameWriter(sim, args.frames, out, video=args.video, export=args.export), args.frames


def report_written(sim, args, viewer) -> None:
    print(loop.stats_line(sim))
    written = f"{len(viewer.paths)} frames in {viewer.out_dir}/"
    if args.video:
        written += f", video {args.video}"
    if args.export:
        written += f", {' and '.join(args.export)} files in {viewer.out_dir}/"
    print(f"[pbf] wrote {written}")


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.list:
        list_presets()
        return 0
    try:
        scene = schema.load_scene(args.scene, args.set)
        sim = Simulation(scene, arch=args.arch)
    except (schema.SceneError, BackendError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"[pbf] {scene.name}: {sim.particle_count:,} particles, Δt = {sim.dt_s * 1e3:.2f} ms, "
          f"{sim.control.iterations} iterations")
    viewer, frames = choose_viewer(sim, args)
    loop.run(sim, viewer, frames)
    if isinstance(viewer, FrameWriter):
        report_written(sim, args, viewer)
    return 0
