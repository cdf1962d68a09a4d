"""The water each mesh of the fluid's surface holds (``--export mesh``) on the seed dam break, and what
meshing it costs; the surface renderer's cost is ``python -m benchmarks.frames``'s.

    python benchmarks/surface.py [--sizes 8000 64000] [--frames 90] [--every 10]

A resting column, then the dam break scaled to each size (default the seed's 8,000 particles), every
``--every``-th frame from the 10th on meshed with the ``[surface]`` defaults: the enclosed volume over
the water's (``!`` where not closed), then over the dam break's frames the worst ratio and the medians
of ms, triangles and the share on the walls, and a lone particle's drop over its own volume.
"""

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: the checkout on the path, for benchmarks.lab
    sys.path.append(str(Path(__file__).resolve().parent.parent))
from benchmarks.lab import Clock  # noqa: E402
from pbf.app.mesh import Mesh, reconstruct  # noqa: E402
from pbf.scene import from_dict  # noqa: E402
from pbf.solver import Simulation, start_backend  # noqa: E402
from pbf.study.common import scaled  # noqa: E402

SEED_PARTICLES = 8000
RESTING_COLUMN = {
    "name": "resting column",
    "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.6, 0.3]},
    "fluid": {"spacing_m": 0.025, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.3, 0.3]}]},
    "time": {"substeps": 4},
    "solver": {"iterations": 4},
}
"""The resting column of tests/test_mesh.py: 12 × 12 × 12 particles against five walls."""


def wall_share(mesh: Mesh, scene) -> float:
    """The share of the triangles lying flat on a container wall (all three corners on its plane)."""
    corners = mesh.vertices[mesh.triangles]
    flat = np.zeros(len(corners), bool)
    for axis in range(3):
        for wall in (scene.container.min_m[axis], scene.container.max_m[axis]):
            flat |= (corners[:, :, axis] == np.float32(wall)).all(axis=1)
    return float(flat.mean()) if len(flat) else 0.0


def measure(particles: int, frames: int, every: int) -> None:
    figures = {"ratio": [], "ms": [], "tris": [], "walls": []}

    def record(label: str, sim: Simulation) -> None:
        water_m3 = sim.particle_count * sim.model.particle_mass_kg / sim.scene.fluid.rest_density_kg_m3
        positions, clock = sim.positions(), Clock()
        mesh = reconstruct(positions, sim.scene)
        wall_s = clock.lap()[0]
        ratio = mesh.enclosed_volume_m3() / water_m3
        print(f"{label:>6} {ratio:>9.3f}{' ' if mesh.is_closed() else '!'}")
        if label != "rest":
            for key, value in zip(figures, (ratio, wall_s * 1e3, len(mesh.triangles), wall_share(mesh, sim.scene))):
                figures[key].append(value)

    print(f"enclosed volume / water's volume (! where not closed)\n{'frame':>6} {'defaults':>9}")
    column = Simulation(from_dict(RESTING_COLUMN), quiet=True)
    column.step(20)
    record("rest", column)
    sim = Simulation(scaled("dam_break", particles, SEED_PARTICLES), quiet=True)
    print(f"dam break, {sim.particle_count:,} particles")
    for frame in range(10, frames + 1, every):
        sim.step(frame - sim.frame)
        record(str(frame), sim)
    median = statistics.median
    print(f"{'worst':>6} {max(figures['ratio'], key=lambda r: abs(r - 1)):>9.3f}")
    print(f"{'ms':>6} {median(figures['ms']):>9.1f}\n{'tris':>6} {median(figures['tris']):>9,.0f}")
    print(f"{'walls':>6} {median(figures['walls']):>9.2f}")
    # Spray: one particle alone in the middle of the seed's container, its mesh over its own volume.
    lone = np.array([[0.5 * (a + b) for a, b in zip(sim.scene.container.min_m, sim.scene.container.max_m)]], np.float32)
    particle_m3 = sim.model.particle_mass_kg / sim.scene.fluid.rest_density_kg_m3
    print(f"{'drop':>6} {reconstruct(lone, sim.scene).enclosed_volume_m3() / particle_m3:>9.2f}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[SEED_PARTICLES], help="particle counts (8000)")
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--every", type=int, default=10)
    args = parser.parse_args(argv)
    start_backend("cpu", quiet=False)
    for particles in args.sizes:
        measure(particles, args.frames, args.every)


if __name__ == "__main__":
    main()
