"""What rigid bodies cost: floating_boxes' frames with its four boxes against the same pool without
them, runs interleaved frame by frame, medians; and the particles within reach of a body (those the
reaction sums over). With ``momentum``: the momentum a box passes to water at rest, no gravity, no
wall within reach (tests/test_bodies.py's scene). Prints a table.

    PYTHONPATH=$PWD python benchmarks/bodies.py [frames]
    PYTHONPATH=$PWD python benchmarks/bodies.py momentum
"""

import sys
import time
from dataclasses import replace

import numpy as np

from pbf import Simulation, load_scene


def main(frames: int = 20) -> None:
    with_bodies = load_scene("floating_boxes", ["time.settle_s=0"])
    without = replace(with_bodies, bodies=())
    sims = {"4 bodies": Simulation(with_bodies, quiet=True), "no bodies": Simulation(without, quiet=True)}
    for sim in sims.values():
        sim.step(2)  # compile
    times = {name: [] for name in sims}
    for _ in range(frames):
        for name, sim in sims.items():
            start = time.perf_counter()
            sim.step()
            sim.stats()  # a read-back: the frame's work is done
            times[name].append((time.perf_counter() - start) / sim.frame_substeps)
    sim = sims["4 bodies"]
    x = sim.positions()
    h = sim.scene.kernel_radius_m
    near = 0
    for row, body in zip(sim.body_states(), sim.scene.bodies):
        local = (x - row[0:3]) @ _rotation(row[3:7])
        gap = np.linalg.norm(np.maximum(np.abs(local) - body.half_extents(), 0.0), axis=1)
        near += int(np.sum(gap < h))
    a, b = np.median(times["4 bodies"]), np.median(times["no bodies"])
    print("| scene | particles | median ms/substep |\n|---|---|---|")
    print(f"| floating_boxes, no bodies | {sims['no bodies'].particle_count:,} | {1e3 * b:.2f} |")
    print(f"| floating_boxes, 4 bodies | {sim.particle_count:,} | {1e3 * a:.2f} |")
    print(
        f"\nper body: {1e3 * (a - b) / 4:.3f} ms/substep; particles within h of a body: {near:,} "
        f"({1e6 * (a - b) / max(near, 1):.2f} µs per coupled particle per substep)"
    )


def momentum(frames: int = 24) -> None:
    spacing = 0.025
    scene = {
        "name": "push",
        "gravity_m_s2": [0, 0, 0],
        "container": {"max_m": [1.0, 0.5, 0.5]},
        "fluid": {"spacing_m": spacing, "blocks": [{"min_m": [0.35, 0.1, 0.1], "max_m": [0.65, 0.4, 0.4]}]},
        "bodies": [
            {
                "size_m": [0.05, 0.06, 0.06],
                "density_kg_m3": 1000,
                "position_m": [0.25, 0.25, 0.25],
                "velocity_m_s": [0.5, 0, 0],
            }
        ],
        "solver": {"iterations": 10, "target_density_error": 0.001},
    }
    sim = Simulation(scene, quiet=True)
    mass, body_mass = sim.model.particle_mass_kg, 1000 * 0.1 * 0.12 * 0.12
    start = body_mass * 0.5
    print("| t (s) | box v_x (m/s) | water P_x / P0 | box P_x / P0 | total / P0 |\n|---|---|---|---|---|")
    for frame in range(frames):
        sim.step()
        if frame % 3 == 2:
            vx = sim.body_states()[0, 7]
            water = mass * float(sim.velocities()[:, 0].sum())
            print(
                f"| {sim.time_s:.2f} | {vx:.3f} | {water / start:.3f} | {body_mass * vx / start:.3f} | "
                f"{(water + body_mass * vx) / start:.3f} |"
            )


def _rotation(q):
    from pbf.solver import quaternion_matrix_np

    return quaternion_matrix_np(q)


if __name__ == "__main__":
    if sys.argv[1:2] == ["momentum"]:
        momentum()
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
