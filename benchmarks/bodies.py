"""What rigid bodies cost: floating_boxes' frames with its four boxes against the same pool without
them, runs interleaved frame by frame, medians; and the particles within reach of a body (those the
reaction sums over). Prints a table.

    PYTHONPATH=$PWD python benchmarks/bodies.py [frames]
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
    print(f"\nper body: {1e3 * (a - b) / 4:.3f} ms/substep; particles within h of a body: {near:,} "
          f"({1e6 * (a - b) / max(near, 1):.2f} µs per coupled particle per substep)")


def _rotation(q):
    from pbf.solver import quaternion_matrix_np

    return quaternion_matrix_np(q)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
