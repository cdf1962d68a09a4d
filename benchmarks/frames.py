"""The headless frame's cost without the simulation: the renderers and the PNG writer alone on the seed
at t = 1 s, both styles, in frames a second and CPU ms a frame (every thread's); and ``look``, how the
surface style reads (docs/RENDERING.md, "Measured").

    python -m benchmarks.frames [--size 1920x1080] [--arch cuda] [--repeats 20]
    python -m benchmarks.frames look [--size 640x360] [--images out/look]

The two styles are drawn alternately (a busy machine slows both alike) until the image is on the
host, medians reported; the PNG encoder and the threaded writer (``pbf.app.writer``) write those
images. ``look``, from the renderer's normals and water mask: a settled pool's *top face* (water
pixels facing up within 45°, two spacings inside the side walls: the share within 5° of vertical and
the median angle, beside the particles' own top) and a splash's *speckle* (water pixels whose normal
is over 30° from their same-surface neighbours' mean).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.lab import Clock, image_size, markdown, medians
from pbf.app.render import SceneRenderer
from pbf.app.writer import FrameFiles, write_png
from pbf.solver import Simulation, start_backend
from pbf.study.common import run_command

STYLES = ("particles", "surface")


def timed_frames(renderers: dict, repeats: int) -> dict:
    """Per style: (wall seconds, CPU seconds) of each of ``repeats`` frames, the styles alternating."""
    times = {style: [] for style in renderers}
    for _ in range(repeats):
        for style, renderer in renderers.items():
            clock = Clock()
            renderer.frame()
            times[style].append(clock.lap())
    return times


def encoded(image, repeats: int, folder: Path) -> tuple[float, float, int]:
    """Median wall and CPU seconds of one PNG of ``image`` (the writer's encoder), and its bytes."""
    path, clock, times = folder / "frame.png", Clock(), []
    for _ in range(repeats):
        write_png(path, image)
        times.append(clock.lap())
    return *medians(times), path.stat().st_size


def threaded(images: list, folder: Path) -> tuple[float, float, int]:
    """Seconds and CPU seconds the threaded writer takes to write ``images`` (submit to close), its threads."""
    files, clock = FrameFiles(), Clock()
    for number, image in enumerate(images):
        files.submit(folder / f"frame_{number:05d}.png", image.copy())
    files.close()
    return *clock.lap(), files.workers


def row(label: str, wall_s: float, cpu_s: float, extra: str = "") -> str:
    rate = 1.0 / wall_s if wall_s > 0 else float("inf")
    return f"| {label} | {rate:,.1f} | {wall_s * 1e3:.1f} | {cpu_s * 1e3:.1f} | {extra} |"


FACES_UP_DEG = 45.0  # a water pixel is on a pool's top face when its normal is within this of vertical,
WALL_INSET_SPACINGS = 2.0  # and its surface point this far inside the side walls (the rim left out)
FLAT_DEG = 5.0  # the top face's pixels within this of vertical are flat
SPECKLE_DEG = 30.0  # a water pixel whose normal turns more than this from its neighbours' mean is speckle
SAME_SURFACE_SPACINGS = 2.0  # neighbours whose depths differ by less are on one surface (twice the narrow range)
POOLS = (("hydrostatic", 60), ("dam_break", 180), ("dam_break", 480))  # t = 1 s; the seed at 3 s and at rest, 8 s
SPLASH = ("dam_break", range(27, 41))  # the splash measured: the seed's frames 27-40
POUR = ("pour", 150)  # the frame --images adds (not measured)


def surface_points(view, depth: np.ndarray) -> np.ndarray:
    """World positions (h, w, 3) of the surface at each coarse pixel of view depth ``depth``."""
    height, width = depth.shape
    right, up, forward = view.basis()
    focal = view.focal_px(height)
    rows, cols = np.mgrid[0:height, 0:width]
    u = (cols + 0.5 - 0.5 * width) / focal
    w = (0.5 * height - rows - 0.5) / focal
    rays = u[..., None] * right + w[..., None] * up + forward  # forward part 1: depth times ray
    return view.eye + np.where(depth < 1e29, depth, 0.0)[..., None] * rays


def top_face(normals, water, depth, view, scene) -> dict:
    """The tilt of a pool's top face (see the module's ``look``): its pixels, the share within 5° of
    vertical, and the median and 95th percentile angle, degrees."""
    points = surface_points(view, depth)
    inset = WALL_INSET_SPACINGS * scene.fluid.spacing_m
    lower, upper = np.asarray(scene.container.min_m), np.asarray(scene.container.max_m)
    inside = np.ones(water.shape, bool)
    for axis in (0, 2):
        inside &= (points[..., axis] > lower[axis] + inset) & (points[..., axis] < upper[axis] - inset)
    tilt = np.degrees(np.arccos(np.clip(normals[..., 1], -1.0, 1.0)))
    face = water & inside & (tilt < FACES_UP_DEG)
    angles = tilt[face]
    if not angles.size:
        return {"pixels": 0, "flat": float("nan"), "median_deg": float("nan"), "p95_deg": float("nan")}
    flat, median, p95 = float(np.mean(angles < FLAT_DEG)), float(np.median(angles)), float(np.percentile(angles, 95))
    return {"pixels": int(face.sum()), "flat": flat, "median_deg": median, "p95_deg": p95}


def particles_top(positions: np.ndarray, scene) -> dict:
    """The tilt the particles themselves give a pool's top: the highest particle in each column two
    spacings square, a cubic in x and z fitted to those heights by least squares (the waves, without the
    particles' own bumps), and its slope at the columns: the share within 5° of level and the median,
    degrees. What a renderer that smooths only the particles' bumps can reach."""
    column = 2.0 * scene.fluid.spacing_m
    cells = np.floor(positions[:, [0, 2]] / column).astype(np.int64)
    keys, inverse = np.unique(cells, axis=0, return_inverse=True)
    heights = np.full(len(keys), -np.inf)
    np.maximum.at(heights, inverse.ravel(), positions[:, 1])
    x, z = ((keys + 0.5) * column).T
    terms = np.stack([np.ones_like(x), x, z, x * x, x * z, z * z, x**3, x * x * z, x * z * z, z**3], axis=1)
    c = np.linalg.lstsq(terms, heights, rcond=None)[0]
    slope_x = c[1] + 2 * c[3] * x + c[4] * z + 3 * c[6] * x * x + 2 * c[7] * x * z + c[8] * z * z
    slope_z = c[2] + c[4] * x + 2 * c[5] * z + c[7] * x * x + 2 * c[8] * x * z + 3 * c[9] * z * z
    angles = np.degrees(np.arctan(np.hypot(slope_x, slope_z)))
    return {"flat": float(np.mean(angles < FLAT_DEG)), "median_deg": float(np.median(angles))}


def speckle(normals, water, depth, surface_m: float) -> float:
    """The share of water pixels whose normal is more than 30° from the mean normal of their neighbours
    on the same surface: the water among the eight around it whose depth is within ``surface_m`` of its
    own (a drop in front of the pool is another surface, and its outline no speckle). A pixel with no
    such neighbour counts as speckle."""
    height, width = water.shape
    far = 1e30  # the renderer's FAR: no water
    depth = np.where(water, depth, far)
    padded_depth = np.pad(depth, 1, constant_values=far)
    padded = np.pad(normals, ((1, 1), (1, 1), (0, 0)))
    around = np.zeros_like(normals)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                same = np.abs(padded_depth[1 + dr : 1 + dr + height, 1 + dc : 1 + dc + width] - depth) <= surface_m
                around += padded[1 + dr : 1 + dr + height, 1 + dc : 1 + dc + width] * same[..., None]
    length = np.linalg.norm(around, axis=-1)
    cosine = np.sum(normals * around, axis=-1) / np.maximum(length, 1e-12)
    rough = (length < 1e-6) | (cosine < np.cos(np.radians(SPECKLE_DEG)))
    return float(np.sum(rough & water) / max(int(water.sum()), 1))


def look(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.frames look", description="how the surface style reads: settled pools, a splash"
    )
    parser.add_argument("--size", type=image_size, default=None, help="image size WIDTHxHEIGHT (default: the scenes')")
    parser.add_argument("--arch", default=None, help="Taichi backend (default: auto; see pbf --help)")
    parser.add_argument("--images", type=Path, default=None, help="write the measured frames (and pour's) here")
    args = parser.parse_args(argv)
    backend = start_backend(args.arch)

    def renderer(sim):  # the surface style at --size, else the scene's
        width, height = args.size or (sim.scene.render.width_px, sim.scene.render.height_px)
        return SceneRenderer(sim, width, height, style="surface")

    def save(name, image):  # with --images: the pools, the splash's first frame and POUR's
        if args.images is not None:
            args.images.mkdir(parents=True, exist_ok=True)
            write_png(args.images / f"{name}.png", image)

    rows = []
    for preset, frame in POOLS:
        sim = Simulation(preset, quiet=True)
        sim.step(frame)
        draw = renderer(sim)
        save(f"{preset}_{frame}", draw.frame())
        pool, top = top_face(*draw.renderer.surface(), draw.view, sim.scene), particles_top(sim.positions(), sim.scene)
        cells = f"{pool['pixels']:,} {100 * pool['flat']:.1f}% {pool['median_deg']:.2f}° {pool['p95_deg']:.1f}°"
        rows.append(
            [f"{preset}, frame {frame}", *cells.split(), f"{100 * top['flat']:.1f}%", f"{top['median_deg']:.2f}°"]
        )
    preset, frames = SPLASH
    sim = Simulation(preset, quiet=True)
    draw, shares = renderer(sim), []
    for frame in frames:
        sim.step(frame - sim.frame)
        image = draw.frame()
        if frame == frames[0]:
            save(f"{preset}_{frame}", image)
        normals, water, depth = draw.renderer.surface()
        shares.append(100 * speckle(normals, water, depth, SAME_SURFACE_SPACINGS * sim.scene.fluid.spacing_m))
    if args.images is not None:
        sim = Simulation(POUR[0], quiet=True)
        sim.step(POUR[1])
        save(f"{POUR[0]}_{POUR[1]}", renderer(sim).frame())
    shown = "the scenes' size" if args.size is None else f"{args.size[0]}×{args.size[1]}"
    head = ["settled pool", "top-face pixels", f"within {FLAT_DEG:g}° of vertical", "median", "95th percentile"]
    print(f"The surface style, {backend}, {shown}\n")
    print(markdown([*head, f"the particles' top: within {FLAT_DEG:g}°", "median"], rows))
    head = ["splash", f"speckle (normal > {SPECKLE_DEG:g}° from its neighbours'), mean", "least", "most"]
    cells = [f"{value:.1f}%" for value in (np.mean(shares), min(shares), max(shares))]
    print("\n" + markdown(head, [[f"{preset}, frames {frames[0]}-{frames[-1]}", *cells]]))
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--at-frame", type=int, default=60, help="frames stepped before timing (default: 60)")
    parser.add_argument("--size", type=image_size, default=None, help="image size WIDTHxHEIGHT (default: the scene's)")
    parser.add_argument("--repeats", type=int, default=20, help="frames timed per style (default: 20)")
    parser.add_argument("--arch", default=None, help="Taichi backend (default: auto; see pbf --help)")
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["look"]:
        return look(argv[1:])
    args = parser.parse_args(argv)

    import taichi as ti  # here, after pbf: it keeps Taichi's banner off

    backend = start_backend(args.arch)
    sim = Simulation("dam_break", quiet=True)
    width, height = args.size or (sim.scene.render.width_px, sim.scene.render.height_px)
    renderers = {style: SceneRenderer(sim, width, height, style=style) for style in STYLES}
    # The surface style's white water follows the run from its start (the last frames' updates timed).
    renderers["surface"].frame()
    white_water = renderers["surface"].white_water
    updates = []
    for _ in range(args.at_frame):
        sim.step()
        if white_water is not None:
            clock = Clock()
            white_water.sync()
            ti.sync()
            updates.append(clock.lap())
    images = {style: renderer.frame() for style, renderer in renderers.items()}  # compiles
    timed_frames(renderers, 2)  # and warms the caches
    times = timed_frames(renderers, args.repeats)

    print(
        f"{sim.scene.name} at t = {sim.time_s:.2f} s, {sim.particle_count:,} particles, {width}×{height}, "
        f"{backend}; medians of {args.repeats} frames, the styles alternating\n"
    )
    print("| stage | frames/s | wall ms/frame | CPU ms/frame | |\n|---|---:|---:|---:|---|")
    drawn = {style: medians(times[style]) for style in STYLES}
    for style in STYLES:
        print(row(f"draw, {style}", *drawn[style], "to a host array"))
    with tempfile.TemporaryDirectory() as folder:
        for style in STYLES:
            wall, cpu, size_bytes = encoded(images[style], max(3, args.repeats // 4), Path(folder))
            print(row(f"PNG, Sub filter, level 1, {style}", wall, cpu, f"{size_bytes / 1024:,.0f} KiB"))
        for style in STYLES:
            wall, cpu, workers = threaded([images[style]] * args.repeats, Path(folder))
            extra = f"{workers} thread{'s' if workers > 1 else ''}, in order, level 1"
            print(row(f"writer, {style}", wall / args.repeats, cpu / args.repeats, extra))
    ratio = [drawn["surface"][k] / drawn["particles"][k] for k in (0, 1)]
    if white_water is not None:
        live, update = white_water.counts()[0], medians(updates[-10:] or [(0.0, 0.0)])
        print("\n" + row("white water's update (last 10 frames)", *update, f"{live:,} diffuse particles"))
    print(f"\nThe surface takes {ratio[0]:.2f}× the particles' time to draw ({ratio[1]:.2f}× their CPU time).")
    if white_water is not None:
        total = (drawn["surface"][1] + update[1]) / drawn["particles"][1]
        print(f"With white water's update, {total:.2f}× their CPU time ({live:,} diffuse particles).")
    return 0


if __name__ == "__main__":
    run_command(main)
