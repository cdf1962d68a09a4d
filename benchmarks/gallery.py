"""Every preset's headless frame at a moment that shows its action, as one contact sheet.

    python benchmarks/gallery.py                       # out/presets.png (about 10 min on 2 cores)
    python benchmarks/gallery.py --docs                # docs/presets.png, the README's picture
    python benchmarks/gallery.py --presets pour --out out/gallery.png --size 320x180

Each preset runs from its start, as shipped, to the time in ``MOMENTS`` and is rendered by the
headless renderer with its own camera (``SceneRenderer``, the scene's ``render.style``), at a reduced
size; the sheet puts them in a grid, each titled with its name, particle count and time.
``dam_break_large`` (1,000,000 particles) is left out unless named: on a CPU it takes minutes a frame.
"""

import argparse
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
if __package__ in (None, ""):  # run as a script: the checkout on the path, for benchmarks.lab
    sys.path.append(str(Path(__file__).resolve().parent.parent))
import matplotlib.pyplot as plt  # noqa: E402
from tqdm import tqdm  # noqa: E402

from benchmarks.lab import image_size  # noqa: E402
from pbf.app.render import SceneRenderer  # noqa: E402
from pbf.scene import SCENES_DIR  # noqa: E402
from pbf.solver import Simulation  # noqa: E402

MOMENTS = {
    "dam_break": 0.45,
    "dam_break_large": 0.45,
    "dam_break_obstacle": 0.6,
    "double_dam_break": 0.5,
    "drop_into_pool": 0.7,
    "floating_boxes": 1.0,
    "hydrostatic": 0.5,
    "martin_moyce": 0.3,
    "pour": 3.0,
    "sloshing": 0.6,
    "wave_tank": 2.5,
    "wave_tank_float": 2.5,
}
"""Seconds from the start at which each preset shows what it is for (the default: 1 s)."""


def frame_of(name: str, width: int, height: int):
    sim = Simulation(name, quiet=True)
    frames = round(MOMENTS.get(name, 1.0) / sim.scene.time.frame_dt_s)
    for _ in tqdm(range(frames), desc=name, unit="frame", leave=False):
        sim.step()
    return SceneRenderer(sim, width, height).frame(), sim.particle_count, frames * sim.scene.time.frame_dt_s


OUT = Path("out/presets.png")
"""Where the sheet goes by default: not the tracked docs/presets.png, which only --docs replaces."""
DOCS = Path(__file__).resolve().parent.parent / "docs" / "presets.png"


def parse(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    available = sorted(p.stem for p in SCENES_DIR.glob("*.toml"))
    parser.add_argument("--presets", nargs="+", choices=available, help="which (default: all but dam_break_large)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--out", type=Path, default=OUT, help=f"the sheet (PNG; default {OUT})")
    where.add_argument("--docs", action="store_true", help="replace the README's picture, docs/presets.png")
    parser.add_argument("--size", type=image_size, default=(480, 270), help="each frame, WxH pixels (default 480x270)")
    parser.add_argument("--columns", type=int, choices=range(1, 7), default=3, metavar="1-6", help="frames per row")
    args = parser.parse_args(argv)
    args.out = DOCS if args.docs else args.out
    if args.out.suffix.lower() != ".png":
        parser.error(f"--out: expected a .png file, got {str(args.out)!r}")
    return args


def main(argv=None) -> None:
    args = parse(argv)
    names = args.presets or sorted(p.stem for p in SCENES_DIR.glob("*.toml") if p.stem != "dam_break_large")
    width, height = args.size
    shots = [(name, *frame_of(name, width, height)) for name in tqdm(names, desc="presets", unit="preset")]
    rows = math.ceil(len(shots) / args.columns)
    figure, axes = plt.subplots(rows, args.columns, figsize=(args.columns * width / 100, rows * (height + 40) / 100))
    for k, axis in enumerate(getattr(axes, "flat", [axes])):
        axis.axis("off")
        if k < len(shots):
            name, image, particles, seconds = shots[k]
            axis.imshow(image)
            axis.set_title(f"{name}: {particles:,} particles, t = {seconds:.2f} s", fontsize=9)
    figure.tight_layout(pad=0.8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=100)
    print(f"wrote {args.out} ({len(shots)} presets)")


if __name__ == "__main__":
    main()
