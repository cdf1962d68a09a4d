"""What meshing the fluid's surface costs (``--export mesh``) on the seed dam break, and the water each mesh
holds (``--volume``); the surface renderer's cost is ``python -m benchmarks.frames``'s.

    python benchmarks/surface.py [--sizes 8000 64000] [--frames 90] [--every 10]
    python benchmarks/surface.py --volume [--sizes 8000] [--candidate "surface.iso_level=0.55" ...]

The dam break scaled to each size runs ``--frames`` frames; every ``--every``-th from the 10th on is
meshed with the ``[surface]`` settings, deterministic (the default) and with splashsurf's parallel
subdomains: medians of ms. ``--volume``: a resting column, then the dam break's frames, each meshed
with the defaults and each ``--candidate`` in alternating order: the enclosed volume over the water's
(``!`` where not closed), the worst ratio, ms, triangles, the share on the walls, a lone particle's drop.
"""

import argparse
import dataclasses
import statistics
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: the checkout on the path, for benchmarks.lab
    sys.path.append(str(Path(__file__).resolve().parent.parent))
from benchmarks.lab import spread, timed  # noqa: E402
from pbf.app.mesh import Mesh, reconstruct  # noqa: E402
from pbf.scene import from_dict, load_scene  # noqa: E402
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


def timed_ms(function, *args) -> tuple[float, object]:
    """Wall ms of ``function(*args)``, and its result."""
    (wall, _), result = timed(function, *args)
    return wall * 1e3, result


def measure(particles: int, frames: int, every: int) -> None:
    scene = scaled("dam_break", particles, SEED_PARTICLES)
    parallel = dataclasses.replace(scene, surface=dataclasses.replace(scene.surface, deterministic=False))
    sim = Simulation(scene, quiet=True)
    mesh_ms, parallel_ms, triangles = [], [], []
    for frame in range(10, frames + 1, every):
        sim.step(frame - sim.frame)
        positions = sim.positions()
        elapsed, mesh = timed_ms(reconstruct, positions, scene)
        mesh_ms.append(elapsed)
        triangles.append(len(mesh.triangles))
        parallel_ms.append(timed_ms(reconstruct, positions, parallel)[0])
    print(
        f"{sim.particle_count:>9,} particles, {len(mesh_ms)} frames: mesh {spread(mesh_ms, 1)} ms (deterministic), "
        f"{statistics.median(parallel_ms):7.1f} ms parallel subdomains, {statistics.median(triangles):,.0f} triangles"
    )


def wall_share(mesh: Mesh, scene) -> float:
    """The share of the triangles lying flat on a container wall (all three corners on its plane)."""
    corners = mesh.vertices[mesh.triangles]
    flat = np.zeros(len(corners), bool)
    for axis in range(3):
        for wall in (scene.container.min_m[axis], scene.container.max_m[axis]):
            flat |= (corners[:, :, axis] == np.float32(wall)).all(axis=1)
    return float(flat.mean()) if len(flat) else 0.0


def measure_volume(particles: int, frames: int, every: int, candidates: list[str]) -> None:
    variants = [("defaults", reconstruct)]
    for number, candidate in enumerate(candidates, 1):
        print(f"candidate {number}: {candidate}")
        overrides = candidate.split()
        variants.append((f"candidate {number}", lambda x, scene, o=overrides: reconstruct(x, load_scene(scene, o))))
    figures = {name: {"ratio": [], "ms": [], "tris": [], "walls": []} for name, _ in variants}
    width = max(12, *(len(name) for name, _ in variants))

    def mesh_all(label: str, sim: Simulation, round_number: int) -> None:
        positions, cells = sim.positions(), {}
        water_m3 = sim.particle_count * sim.model.particle_mass_kg / sim.scene.fluid.rest_density_kg_m3
        for name, function in variants if round_number % 2 == 0 else variants[::-1]:
            elapsed, mesh = timed_ms(function, positions, sim.scene)
            ratio = mesh.enclosed_volume_m3() / water_m3
            cells[name] = f"{ratio:>{width}.3f}{' ' if mesh.is_closed() else '!'}"
            for key, value in zip(figures[name], (ratio, elapsed, len(mesh.triangles), wall_share(mesh, sim.scene))):
                figures[name][key] += [value] if label != "rest" else []
        print(f"{label:>6}" + "".join(cells[name] for name, _ in variants))

    print("enclosed volume / water's volume (! where not closed)")
    print(f"{'frame':>6}" + "".join(f"{name:>{width}} " for name, _ in variants))
    column = Simulation(from_dict(RESTING_COLUMN), quiet=True)
    column.step(20)
    mesh_all("rest", column, 0)
    sim = Simulation(scaled("dam_break", particles, SEED_PARTICLES), quiet=True)
    print(f"dam break, {sim.particle_count:,} particles")
    for round_number, frame in enumerate(range(10, frames + 1, every)):
        sim.step(frame - sim.frame)
        mesh_all(str(frame), sim, round_number)
    median, base = statistics.median, figures["defaults"]["ms"]
    rows = {
        "worst": ("3f", lambda f: max(f["ratio"], key=lambda r: abs(r - 1))),
        "ms": ("1f", lambda f: median(f["ms"])),
        "÷ def": ("2f", lambda f: median(t / b for t, b in zip(f["ms"], base))),
        "tris": (",.0f", lambda f: median(f["tris"])),
        "walls": ("2f", lambda f: median(f["walls"])),
    }
    for label, (form, value) in rows.items():
        print(f"{label:>6}" + "".join(f"{value(figures[name]):>{width}{form}} " for name, _ in variants))
    # Spray: one particle alone in the middle of the seed's container, its mesh over its own volume.
    lone = np.array([[0.5 * (a + b) for a, b in zip(sim.scene.container.min_m, sim.scene.container.max_m)]], np.float32)
    particle_m3 = sim.model.particle_mass_kg / sim.scene.fluid.rest_density_kg_m3
    droplets = (function(lone, sim.scene).enclosed_volume_m3() / particle_m3 for _, function in variants)
    print(f"{'drop':>6}" + "".join(f"{d:>{width}.2f} " for d in droplets))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", help="particle counts (8000 64000; --volume: 8000)")
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--volume", action="store_true", help="the volume the mesh holds, per frame, instead")
    parser.add_argument("--candidate", action="append", default=[], metavar="'KEY=VALUE ...'",
                        help="with --volume: [surface] overrides, e.g. 'surface.iso_level=0.55'")  # fmt: skip
    args = parser.parse_args(argv)
    start_backend("cpu", quiet=False)
    for particles in args.sizes or ([SEED_PARTICLES] if args.volume else [SEED_PARTICLES, 64000]):
        if args.volume:
            measure_volume(particles, args.frames, args.every, args.candidate)
        else:
            measure(particles, args.frames, args.every)


if __name__ == "__main__":
    main()
