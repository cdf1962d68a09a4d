"""What the fluid surface costs: meshing per frame (``--export mesh``) and the surface renderer against
the sphere renderer (``--style surface`` against particles) on the seed dam break.

    python benchmarks/surface.py [--sizes 8000 64000] [--frames 90] [--every 10] [--rounds 5]

For each size the dam break (the ``dam_break`` preset, its spacing scaled to the particle count) runs
``--frames`` frames from rest; every ``--every``-th frame from the 10th on (fall, impact, splash, run-up)
its particles are meshed with the scene's ``[surface]`` settings, once deterministic (one thread, one
global grid: the default) and once with splashsurf's parallel subdomains. At the seed size the same
frames are also rendered at 1280 × 720 with both renderers, alternating, ``--rounds`` times each.
Every figure is a median over the frames and rounds (ms of wall time, the frame copied to the host
included, as the headless writer uses it); the ratio is the median of the per-frame ratios.

``--volume`` measures instead how much water the mesh holds: the tests' resting column (a 0.3 m tank
filled 0.3 m deep, settled for 20 frames) and then the dam break's frames from rest (at 8,000 particles
unless ``--sizes`` says otherwise), each meshed with the scene's ``[surface]`` settings, with each
``--candidate`` (``KEY=VALUE`` overrides separated by spaces), in an order that alternates from frame
to frame.
Per frame it prints the enclosed volume over the water's (particle count × particle mass / rest
density) and ``!`` where the mesh is not closed; then, over the dam break's frames, the ratio farthest
from 1, each variant's median ms per mesh, the median of its per-frame time over the defaults', its
median triangle count and the median share of them lying flat on a wall; last, a lone particle's
droplet over the particle's volume (spray).

    python benchmarks/surface.py --volume [--sizes 8000] [--candidate "surface.iso_level=0.55" ...]
"""

import argparse
import dataclasses
import statistics
import time

import numpy as np

from pbf.app.mesh import Mesh, reconstruct
from pbf.app.render import SceneRenderer
from pbf.scene import from_dict, load_scene
from pbf.solver import Simulation, start_backend

SEED_PARTICLES = 8000


def timed_ms(function) -> tuple[float, object]:
    started = time.perf_counter()
    result = function()
    return (time.perf_counter() - started) * 1e3, result


def measure(particles: int, frames: int, every: int, rounds: int) -> None:
    scene = dam_break(particles)
    parallel = dataclasses.replace(scene, surface=dataclasses.replace(scene.surface, deterministic=False))
    sim = Simulation(scene, quiet=True)
    rendering = sim.particle_count == SEED_PARTICLES
    if rendering:
        spheres, surface = SceneRenderer(sim, style="particles"), SceneRenderer(sim, style="surface")
        spheres.frame(), surface.frame()  # compiles the kernels
    mesh_ms, parallel_ms, triangles, sphere_ms, surface_ms, ratios = [], [], [], [], [], []
    for frame in range(10, frames + 1, every):
        sim.step(frame - sim.frame)
        positions = sim.positions()
        elapsed, mesh = timed_ms(lambda: reconstruct(positions, scene))
        mesh_ms.append(elapsed)
        triangles.append(len(mesh.triangles))
        parallel_ms.append(timed_ms(lambda: reconstruct(positions, parallel))[0])
        if rendering:
            for _ in range(rounds):
                a, b = timed_ms(spheres.frame)[0], timed_ms(surface.frame)[0]
                sphere_ms.append(a)
                surface_ms.append(b)
                ratios.append(b / a)
    median = statistics.median
    print(
        f"{sim.particle_count:>9,} particles, {len(mesh_ms)} frames: mesh {median(mesh_ms):7.1f} ms "
        f"(deterministic; {min(mesh_ms):.1f}-{max(mesh_ms):.1f}), {median(parallel_ms):7.1f} ms parallel "
        f"subdomains, {median(triangles):,.0f} triangles"
    )
    if rendering:
        print(
            f"{'':>9}  1280×720 frame: spheres {median(sphere_ms):6.1f} ms, surface {median(surface_ms):6.1f} ms, "
            f"surface / spheres {median(ratios):.2f} (per-frame ratios {min(ratios):.2f}-{max(ratios):.2f})"
        )


RESTING_COLUMN = {
    "name": "resting column",
    "container": {"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.6, 0.3]},
    "fluid": {"spacing_m": 0.025, "blocks": [{"min_m": [0.0, 0.0, 0.0], "max_m": [0.3, 0.3, 0.3]}]},
    "time": {"substeps": 4},
    "solver": {"iterations": 4},
}
"""The resting column of tests/test_mesh.py: 12 × 12 × 12 particles against five walls."""


def volume_variants(candidates: list[str]) -> list[tuple[str, object]]:
    """(name, function of (positions, scene) → Mesh) for the defaults and each candidate."""
    variants = [("defaults", reconstruct)]
    for number, candidate in enumerate(candidates, 1):
        overrides = candidate.split()
        print(f"candidate {number}: {candidate}")

        def meshed(positions, scene, overrides=overrides):
            return reconstruct(positions, load_scene(scene, overrides))

        variants.append((f"candidate {number}", meshed))
    return variants


def dam_break(particles: int):
    """The seed dam break with its spacing scaled to about ``particles`` particles."""
    seed = load_scene("dam_break")
    spacing = seed.fluid.spacing_m * (SEED_PARTICLES / particles) ** (1 / 3)
    return load_scene("dam_break", [f"fluid.spacing_m={spacing}"])


def wall_share(mesh: Mesh, scene) -> float:
    """The share of the triangles lying flat on a container wall (all three corners on its plane)."""
    corners = mesh.vertices[mesh.triangles]
    flat = np.zeros(len(corners), bool)
    for axis in range(3):
        for wall in (scene.container.min_m[axis], scene.container.max_m[axis]):
            flat |= (corners[:, :, axis] == np.float32(wall)).all(axis=1)
    return float(flat.mean()) if len(flat) else 0.0


def measure_volume(particles: int, frames: int, every: int, candidates: list[str]) -> None:
    variants = volume_variants(candidates)
    ratios = {name: [] for name, _ in variants}
    times = {name: [] for name, _ in variants}
    triangles = {name: [] for name, _ in variants}
    on_walls = {name: [] for name, _ in variants}
    width = max(12, *(len(name) for name, _ in variants))

    def mesh_all(label: str, sim: Simulation, round_number: int) -> None:
        positions = sim.positions()
        water_m3 = sim.particle_count * sim.model.particle_mass_kg / sim.scene.fluid.rest_density_kg_m3
        order = variants if round_number % 2 == 0 else variants[::-1]
        results = {}
        for name, function in order:
            elapsed, mesh = timed_ms(lambda: function(positions, sim.scene))
            results[name] = (mesh.enclosed_volume_m3() / water_m3, mesh.is_closed())
            if label != "rest":
                ratios[name].append(results[name][0])
                times[name].append(elapsed)
                triangles[name].append(len(mesh.triangles))
                on_walls[name].append(wall_share(mesh, sim.scene))
        cells = (f"{results[name][0]:>{width}.3f}{' ' if results[name][1] else '!'}" for name, _ in variants)
        print(f"{label:>6}" + "".join(cells))

    print("enclosed volume / water's volume (! where not closed)")
    print(f"{'frame':>6}" + "".join(f"{name:>{width}} " for name, _ in variants))
    column = Simulation(from_dict(RESTING_COLUMN), quiet=True)
    column.step(20)
    mesh_all("rest", column, 0)
    sim = Simulation(dam_break(particles), quiet=True)
    print(f"dam break, {sim.particle_count:,} particles")
    for round_number, frame in enumerate(range(10, frames + 1, every)):
        sim.step(frame - sim.frame)
        mesh_all(str(frame), sim, round_number)
    median = statistics.median
    print(f"{'worst':>6}" + "".join(f"{max(ratios[n], key=lambda r: abs(r - 1)):>{width}.3f} " for n, _ in variants))
    print(f"{'ms':>6}" + "".join(f"{median(times[n]):>{width}.1f} " for n, _ in variants))
    base = times[variants[0][0]]
    relative = (median(t / b for t, b in zip(times[n], base)) for n, _ in variants)
    print(f"{'÷ def':>6}" + "".join(f"{r:>{width}.2f} " for r in relative))
    print(f"{'tris':>6}" + "".join(f"{median(triangles[n]):>{width},.0f} " for n, _ in variants))
    print(f"{'walls':>6}" + "".join(f"{median(on_walls[n]):>{width}.2f} " for n, _ in variants))
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
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--volume", action="store_true", help="the volume the mesh holds, per frame, instead")
    parser.add_argument(
        "--candidate",
        action="append",
        default=[],
        help="with --volume: [surface] overrides to compare, e.g. 'surface.iso_level=0.55'",
        metavar="'KEY=VALUE ...'",
    )
    args = parser.parse_args(argv)
    start_backend(args.arch, quiet=False)
    if args.volume:
        for particles in args.sizes or [SEED_PARTICLES]:
            measure_volume(particles, args.frames, args.every, args.candidate)
        return
    for particles in args.sizes or [SEED_PARTICLES, 64000]:
        measure(particles, args.frames, args.every, args.rounds)


if __name__ == "__main__":
    main()
