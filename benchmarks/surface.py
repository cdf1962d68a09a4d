"""What the fluid surface costs: meshing per frame (``--export mesh``) and the surface renderer against
the sphere renderer (``--style surface`` against particles) on the seed dam break.

    python benchmarks/surface.py [--sizes 8000 64000] [--frames 90] [--every 10] [--rounds 5]
    xvfb-run -a -s "-screen 0 1920x1080x24" python benchmarks/surface.py --window    # needs Vulkan

For each size the dam break (the ``dam_break`` preset, its spacing scaled to the particle count) runs
``--frames`` frames from rest; every ``--every``-th frame from the 10th on (fall, impact, splash, run-up)
its particles are meshed with the scene's ``[surface]`` settings, once deterministic (one thread, one
global grid: the default) and once with splashsurf's parallel subdomains. At the seed size the same
frames are also rendered at 1280 × 720 with both renderers, alternating, ``--rounds`` times each.
Every figure is a median over the frames and rounds (ms of wall time, the frame copied to the host
included, as the headless writer uses it); the ratio is the median of the per-frame ratios.

``--window`` opens the GGUI window at the seed scene's 1280 × 720 instead and, for ``--frames`` frames,
steps the simulation and shows each frame twice, as particles and as the surface (key v): the frame
rate of each is 1 / (median step + median show), the show including the panel and the present.
"""

import argparse
import dataclasses
import statistics
import time

from pbf.app.render import SceneRenderer
from pbf.app.surface import reconstruct
from pbf.scene import load_scene
from pbf.solver import Simulation, start_backend

SEED_PARTICLES = 8000


def timed_ms(function) -> tuple[float, object]:
    started = time.perf_counter()
    result = function()
    return (time.perf_counter() - started) * 1e3, result


def measure(particles: int, frames: int, every: int, rounds: int) -> None:
    seed = load_scene("dam_break")
    spacing = seed.fluid.spacing_m * (SEED_PARTICLES / particles) ** (1 / 3)
    scene = load_scene("dam_break", [f"fluid.spacing_m={spacing}"])
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


def measure_window(frames: int) -> None:
    from pbf.app import window

    sim = Simulation("dam_break", quiet=True)
    viewer = window.WindowViewer(
        sim, window.open_window("pbf benchmark", sim.scene.render.width_px, sim.scene.render.height_px)
    )
    shows = {False: [], True: []}
    for surface in shows:  # compiles both renderers
        viewer.surface = surface
        viewer.show()
    sim.step()  # compiles the step's kernels, so that the median step is a step
    steps = []
    for _ in range(frames):
        steps.append(timed_ms(sim.step)[0])
        for surface, times in shows.items():
            viewer.surface = surface
            times.append(timed_ms(viewer.show)[0])
    step = statistics.median(steps)
    for surface, times in shows.items():
        show = statistics.median(times)
        print(
            f"window, {'surface' if surface else 'particles'}: show {show:.0f} ms + step {step:.0f} ms = "
            f"{1e3 / (show + step):.1f} fps"
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[SEED_PARTICLES, 64000])
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--window", action="store_true", help="the window's frame rate instead (needs a display)")
    args = parser.parse_args(argv)
    start_backend(args.arch, quiet=False)
    if args.window:
        measure_window(args.frames)
        return
    for particles in args.sizes:
        measure(particles, args.frames, args.every, args.rounds)


if __name__ == "__main__":
    main()
