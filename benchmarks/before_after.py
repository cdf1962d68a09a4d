"""Before and after: frames of the surface style drawn by an earlier commit's code and by this tree's, side by
side, at the same frames (docs/RENDERING.md's white-water figures).

    python benchmarks/before_after.py 0939edd --shot dam_break:0,25,35,45 --shot pour:60 --size 640x360 \\
        --out docs/white_water_before_after.png

Each side runs in a process of its own on Taichi's CPU backend: the earlier commit exported with ``git
archive`` into a temporary folder, this tree as it is. Rows are the shots' frames, the left column
before, the right after."""

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: the checkout on the path, for benchmarks.lab
    sys.path.append(str(Path(__file__).resolve().parent.parent))
from benchmarks.lab import CHECKOUT as ROOT  # noqa: E402
from benchmarks.lab import export, fresh, image_size, revision  # noqa: E402

DRAW = """
import json, sys
import numpy as np
from pbf.solver import Simulation, start_backend
from pbf.app.render import SceneRenderer
start_backend("cpu", quiet=True)
shots, width, height, out = json.loads(sys.argv[1])
images = []
for scene, frames in shots:
    sim = Simulation(scene, quiet=True, overrides=["render.style=surface"])
    renderer = SceneRenderer(sim, width, height, style="surface")
    for frame in range(max(frames) + 1):
        if frame:
            sim.step()
        image = renderer.frame()  # every frame: what follows the run from frame to frame sees each one
        if frame in frames:
            images.append(image)
np.save(out, np.stack(images))
"""


def draw(source: Path, shots, width: int, height: int, folder: Path) -> np.ndarray:
    out, script = folder / f"{source.name}.npy", folder / "draw.py"
    script.write_text(DRAW)
    fresh([sys.executable, str(script), json.dumps([shots, width, height, str(out)])], [source])
    return np.load(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", help="the earlier commit")
    parser.add_argument("--shot", action="append", required=True, help="SCENE:FRAME,FRAME,… (repeatable)")
    parser.add_argument("--size", type=image_size, default="640x360", help="WIDTHxHEIGHT of each frame")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "before_after.png")
    args = parser.parse_args(argv)
    width, height = args.size
    commit = revision(args.before)
    if commit is None:
        parser.error(f"{args.before!r}: not a git revision of {ROOT}")
    shots = [(scene, [int(f) for f in frames.split(",")]) for scene, frames in (s.split(":") for s in args.shot)]
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        before = draw(export(commit, folder), shots, width, height, folder)
        after = draw(ROOT, shots, width, height, folder)
    rows = [np.concatenate([b, np.full((height, 8, 3), 255, np.uint8), a], axis=1) for b, a in zip(before, after)]
    grid = np.concatenate([np.concatenate([r, np.full((8, r.shape[1], 3), 255, np.uint8)]) for r in rows])[:-8]
    import imageio.v3 as iio

    args.out.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(args.out, grid)
    print(f"{args.out}: {len(rows)} rows, before ({args.before}) left, after right")
    return 0


if __name__ == "__main__":
    sys.exit(main())
