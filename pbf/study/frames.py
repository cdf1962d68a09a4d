"""The headless frame's cost without the simulation: the renderer and the PNG writer alone on a fixed
state, both styles, as frames a second and CPU milliseconds a frame.

    python -m pbf.study.frames                      # the seed scene at t = 1 s, 1280×720
    python -m pbf.study.frames --size 1920x1080 --arch cuda

The scene is stepped to ``--at-frame`` once; then the two styles are drawn alternately, frame after
frame (so that a busy machine slows both alike), and the medians are reported. Drawing counts until
the image is on the host (``SceneRenderer.frame``: the device synchronised by its one copy). Writing
is PNG encoding at several zlib levels and as Pillow writes it (size and time, one thread), and the threaded writer
(``pbf.app.writer.FrameFiles``) writing ``--repeats`` frames of each style into a temporary folder,
its rate the throughput with its default threads. CPU milliseconds are the process's CPU time (all
threads) over the frames: on a GPU backend they are what the host spends, on the CPU backend they
include the kernels' threads.

``--whole N`` adds the whole frame of a headless run, simulation included, in one process: from the
same state, N frames stepped and written each way (simulation only; the frame drawn and written with
Pillow's PNG on the main thread, as before; with our PNG on the main thread; with the threaded
writer), the ways alternating round by round (``--rounds``), medians:

    python -m pbf.study.frames --whole 15 --rounds 5

This study's subject is the application's renderer and writer, so it imports ``pbf.app`` (the other
studies measure the solver only).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from pbf.study.common import run_command

STYLES = ("particles", "surface")
LEVELS = (1, 3, 6)
"""zlib levels of the writer's encoder compared: its own (1), a middle one, and Pillow's default (6);
beside them Pillow's PNG at its defaults (five filters tried per row, level 6), as frames were written
before."""


def size(text: str) -> tuple[int, int]:
    width, _, height = text.partition("x")
    try:
        return int(width), int(height)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WIDTHxHEIGHT, e.g. 1280x720") from None


def timed_frames(renderers: dict, repeats: int) -> dict:
    """Per style: (wall seconds, CPU seconds) of each of ``repeats`` frames, the styles alternating."""
    times = {style: [] for style in renderers}
    for _ in range(repeats):
        for style, renderer in renderers.items():
            wall, cpu = time.perf_counter(), time.process_time()
            renderer.frame()
            times[style].append((time.perf_counter() - wall, time.process_time() - cpu))
    return times


def pillow_png(path: Path, image, level: int) -> None:
    """Pillow's PNG at its defaults (``level`` is ignored): how frames were written before."""
    from PIL import Image

    Image.fromarray(image).save(path, format="PNG")


def encoded(image, level: int, repeats: int, folder: Path, encoder=None) -> tuple[float, float, int]:
    """Median wall and CPU seconds of one PNG of ``image`` at zlib ``level``, and its size in bytes."""
    from pbf.app.writer import write_png

    encoder = encoder or write_png
    path = folder / f"level{level}.png"
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        encoder(path, image, level)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus), path.stat().st_size


def threaded(images: list, folder: Path) -> tuple[float, float, int]:
    """Seconds and CPU seconds the threaded writer takes to write ``images`` (submit to close), and its
    threads."""
    from pbf.app.writer import FrameFiles

    files = FrameFiles()
    wall, cpu = time.perf_counter(), time.process_time()
    for number, image in enumerate(images):
        files.submit(folder / f"frame_{number:05d}.png", image.copy())
    files.close()
    return time.perf_counter() - wall, time.process_time() - cpu, files.workers


WAYS = ("simulation only", "Pillow's PNG on the main thread (before)", "our PNG on the main thread", "threaded writer")


def whole_frames(sim, renderer, frames: int, rounds: int, folder: Path) -> dict:
    """Per way of writing: (wall seconds, CPU seconds) a frame of each round, simulation included, every
    round from the same state."""
    import taichi as ti

    from pbf.app.writer import FrameFiles, write_png

    start = sim.snapshot()
    times = {way: [] for way in WAYS}
    for _ in range(rounds):
        for way in WAYS:
            sim.restore(start)
            files = FrameFiles() if way == "threaded writer" else None
            wall, cpu = time.perf_counter(), time.process_time()
            for number in range(frames):
                sim.step()
                if way == "simulation only":
                    continue
                image, path = renderer.frame(), folder / f"frame_{number:05d}.png"
                if files is not None:
                    files.submit(path, image)
                elif way.startswith("Pillow"):
                    pillow_png(path, image, 6)
                else:
                    write_png(path, image)
            if files is not None:
                files.close()
            ti.sync()
            times[way].append(((time.perf_counter() - wall) / frames, (time.process_time() - cpu) / frames))
    return times


def row(label: str, wall_s: float, cpu_s: float, extra: str = "") -> str:
    rate = 1.0 / wall_s if wall_s > 0 else float("inf")
    return f"| {label} | {rate:,.1f} | {wall_s * 1e3:.1f} | {cpu_s * 1e3:.1f} | {extra} |"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--scene", default="dam_break", help="preset or TOML file (default: dam_break)")
    parser.add_argument("--at-frame", type=int, default=60, help="frames stepped before timing (default: 60)")
    parser.add_argument("--size", type=size, default=None, help="image size WIDTHxHEIGHT (default: the scene's)")
    parser.add_argument("--repeats", type=int, default=20, help="frames timed per style (default: 20)")
    parser.add_argument("--arch", default=None, help="Taichi backend (default: auto; see pbf --help)")
    parser.add_argument(
        "--whole", type=int, default=0, help="also time N whole frames (simulation, draw, write) each way"
    )
    parser.add_argument("--rounds", type=int, default=5, help="rounds of --whole, the ways alternating (default: 5)")
    parser.add_argument("--style", choices=STYLES, default="particles", help="the style --whole draws")
    args = parser.parse_args(argv)

    from pbf.app.render import SceneRenderer
    from pbf.solver import Simulation, start_backend

    backend = start_backend(args.arch)
    sim = Simulation(args.scene, quiet=True)
    sim.step(args.at_frame)
    width, height = args.size or (sim.scene.render.width_px, sim.scene.render.height_px)
    renderers = {style: SceneRenderer(sim, width, height, style=style) for style in STYLES}
    images = {style: renderer.frame() for style, renderer in renderers.items()}  # compiles
    timed_frames(renderers, 2)  # and warms the caches
    times = timed_frames(renderers, args.repeats)

    print(
        f"{sim.scene.name} at t = {sim.time_s:.2f} s, {sim.particle_count:,} particles, {width}×{height}, "
        f"{backend}; medians of {args.repeats} frames, the styles alternating"
    )
    print()
    print("| stage | frames/s | wall ms/frame | CPU ms/frame | |")
    print("|---|---:|---:|---:|---|")
    medians = {}
    for style in STYLES:
        wall = statistics.median(t[0] for t in times[style])
        cpu = statistics.median(t[1] for t in times[style])
        medians[style] = wall
        print(row(f"draw, {style}", wall, cpu, "to a host array"))
    with tempfile.TemporaryDirectory() as folder:
        repeats = max(3, args.repeats // 4)
        for style in STYLES:
            for level in LEVELS:
                wall, cpu, size_bytes = encoded(images[style], level, repeats, Path(folder))
                print(row(f"PNG, Sub filter, level {level}, {style}", wall, cpu, f"{size_bytes / 1024:,.0f} KiB"))
            wall, cpu, size_bytes = encoded(images[style], 6, repeats, Path(folder), pillow_png)
            print(row(f"PNG, Pillow's defaults, {style}", wall, cpu, f"{size_bytes / 1024:,.0f} KiB"))
        for style in STYLES:
            with tempfile.TemporaryDirectory() as frames:
                wall, cpu, workers = threaded([images[style]] * args.repeats, Path(frames))
                print(
                    row(
                        f"writer, {style}",
                        wall / args.repeats,
                        cpu / args.repeats,
                        f"{workers} thread{'s' if workers > 1 else ''}, in order, level 1",
                    )
                )
    print()
    print(f"The surface takes {medians['surface'] / medians['particles']:.2f}× the particles' time to draw.")
    if args.whole:
        with tempfile.TemporaryDirectory() as folder:
            times = whole_frames(sim, renderers[args.style], args.whole, args.rounds, Path(folder))
        print()
        print(
            f"Whole frames from t = {args.at_frame * sim.scene.time.frame_dt_s:.2f} s, {args.style}: "
            f"{args.whole} frames a round, {args.rounds} rounds, the ways alternating, medians"
        )
        print()
        print("| way | wall ms a frame | added to the simulation's | CPU ms a frame | added |")
        print("|---|---:|---:|---:|---:|")
        wall = {way: statistics.median(t[0] for t in times[way]) for way in WAYS}
        cpu = {way: statistics.median(t[1] for t in times[way]) for way in WAYS}
        base = WAYS[0]
        for way in WAYS:
            added = "" if way == base else f"{(wall[way] - wall[base]) * 1e3:.1f}"
            cpu_added = "" if way == base else f"{(cpu[way] - cpu[base]) * 1e3:.1f}"
            print(f"| {way} | {wall[way] * 1e3:.1f} | {added} | {cpu[way] * 1e3:.1f} | {cpu_added} |")
    return 0


if __name__ == "__main__":
    run_command(main)
