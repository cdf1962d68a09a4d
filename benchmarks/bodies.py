"""What rigid bodies cost, and the figures of docs/VALIDATION.md's "Floating bodies".

    PYTHONPATH=$PWD python benchmarks/bodies.py [frames]     # the cost (docs/BENCHMARKS.md, "Bodies")
    PYTHONPATH=$PWD python benchmarks/bodies.py momentum     # a box driven into water at rest
    PYTHONPATH=$PWD python benchmarks/bodies.py archimedes   # boxes floating at their drafts

The cost: floating_boxes' frames with its four boxes against the same pool without them, interleaved,
medians, and the particles within h of a body (those the reaction sums over). ``momentum``: the x
momenta of the water, the box and the reaction in flight, no gravity, no wall within reach.
``archimedes``: boxes of 300-900 kg/m³ let go at their draft in a settled pool, their drafts against
the levels the water's volume and its pressure give. The scenes are tests/test_bodies.py's.
"""

import sys
import time
from dataclasses import replace

import numpy as np

from benchmarks.lab import markdown
from pbf import Simulation, load_scene
from pbf.solver import quaternion_matrix_np

SPACING = 0.025
HALF = (0.1, 0.06, 0.1)
"""The floating box's half extents (tests/test_bodies.py's Archimedes test), m."""


def main(frames: int = 20) -> None:
    with_bodies = load_scene("floating_boxes", ["time.settle_s=0"])
    without = replace(with_bodies, bodies=())
    sims = {"no bodies": Simulation(without, quiet=True), "4 bodies": Simulation(with_bodies, quiet=True)}
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
    x, h = sim.positions(), sim.scene.kernel_radius_m
    near = 0
    for row, body in zip(sim.body_states(), sim.scene.bodies):
        local = (x - row[0:3]) @ quaternion_matrix_np(row[3:7])
        near += int(np.sum(np.linalg.norm(np.maximum(np.abs(local) - body.half_extents(), 0.0), axis=1) < h))
    base, more = np.median(times["no bodies"]), np.median(times["4 bodies"]) - np.median(times["no bodies"])
    per_body, per_particle = f"{1e3 * more / 4:.2f} ms", f"{1e6 * more / near:.2f} µs"
    rows = [["no bodies", f"{sim.particle_count:,}", f"{1e3 * base:.2f}", "", ""]]
    rows.append(["4 bodies", f"{sim.particle_count:,}", f"{1e3 * (base + more):.2f}", per_body, per_particle])
    head = ["floating_boxes", "particles", "median ms/substep", "per body", "per particle within h of a body"]
    print(markdown(head, rows) + f"\n\nparticles within h of a body at the end: {near:,}")


def one_body(name: str, container_m: list, water_m: tuple, body: dict, **extra) -> Simulation:
    """A box ``body`` and a block of water (``water_m``: its lower and upper corners), at tests/test_bodies.py's
    spacing and solver."""
    scene = {
        "name": name,
        "container": {"max_m": container_m},
        "fluid": {"spacing_m": SPACING, "blocks": [{"min_m": water_m[0], "max_m": water_m[1]}]},
        "bodies": [body],
        "solver": {"iterations": 10, "target_density_error": 0.001},
        **extra,
    }
    return Simulation(scene, quiet=True)


def momentum(frames: int = 24) -> None:
    body = dict(size_m=[0.05, 0.06, 0.06], density_kg_m3=1000, position_m=[0.25] * 3, velocity_m_s=[0.5, 0, 0])
    water = [0.35, 0.1, 0.1], [0.65, 0.4, 0.4]
    sim = one_body("push", [1.0, 0.5, 0.5], water, body, gravity_m_s2=[0, 0, 0])
    mass, body_mass = sim.model.particle_mass_kg, 1000 * 0.1 * 0.12 * 0.12
    start, rows = body_mass * 0.5, []
    for frame in range(frames):
        sim.step()
        if frame % 3 == 2:
            # The water's, the box's, and the reaction of the last substep, which the box takes in its
            # next step (the coupling is explicit), kg m/s.
            row = sim.body_states()[0]
            water, box = mass * float(sim.velocities()[:, 0].sum()), body_mass * float(row[7])
            flight = float(row[13]) * sim.last_dt_s
            shares = (f"{p / start:.3f}" for p in (water, box, flight, water + box + flight))
            rows.append([f"{sim.time_s:.2f}", f"{row[7]:.3f}", *shares])
    head = ["t (s)", "box v_x (m/s)", "water P_x / P0", "box P_x / P0", "reaction in flight / P0", "total / P0"]
    print(markdown(head, rows))


def floating(density: float, frames: int = 60, measured_from: int = 20) -> dict:
    """The Archimedes test's run: a box of ``density`` let go at its draft in a settled pool 0.2 m deep,
    0.4 m square; its mean draft / height over frames 20-60 against the water's volume level and its
    pressure level (where the far field's fitted pressure is zero), its fastest speed and the median of
    the pool's fastest particle."""
    at = [0.2, 0.2 + HALF[1] * (1 - 2 * density / 1000), 0.2]
    body = dict(size_m=list(HALF), density_kg_m3=density, position_m=at)
    sim = one_body("pool", [0.4, 0.4, 0.4], ([0, 0, 0], [0.4, 0.2, 0.4]), body, time={"settle_s": 0.3})
    volume = sim.particle_count * sim.model.particle_mass_kg / 1000.0
    area, pool_area, height = 4 * HALF[0] * HALF[2], 0.16, 2 * HALF[1]
    by_volume, by_pressure, speeds, fastest = [], [], [], []
    for frame in range(frames):
        sim.step()
        if frame < measured_from:
            continue
        row = sim.body_states()[0]
        bottom = row[1] - HALF[1]
        by_volume.append(((volume - area * bottom) / (pool_area - area) - bottom) / height)
        x, p = sim.positions(), sim.pressures()
        far = np.max(np.abs(x[:, [0, 2]] - 0.2), axis=1) > HALF[0] + 0.05
        rows = far & (x[:, 1] > 0.04) & (x[:, 1] < 0.16)
        slope, intercept = np.polyfit(x[rows, 1], p[rows], 1)
        by_pressure.append((-intercept / slope - bottom) / height)
        speeds.append(float(np.linalg.norm(row[7:10])))
        fastest.append(float(np.linalg.norm(sim.velocities(), axis=1).max()))
    return dict(volume=np.mean(by_volume), volume_rms=np.std(by_volume), pressure=np.mean(by_pressure),
                speed=max(speeds), median_speed=np.median(speeds), pool_fastest=np.median(fastest))  # fmt: skip


def archimedes() -> None:
    rows = []
    for density in (300.0, 500.0, 700.0, 900.0):
        r, e = floating(density), density / 1000
        by_volume = [f"{r['volume']:.3f} ± {r['volume_rms']:.3f}", f"{r['volume'] / e - 1:+.1%}"]
        by_pressure = [f"{r['pressure']:.3f}", f"{r['pressure'] / e - 1:+.1%}"]
        speeds = [f"{r['speed']:.3f}", f"{r['median_speed'] / r['pool_fastest']:.2f}"]
        rows.append([f"{density:.0f}", f"{e:.2f}", *by_volume, *by_pressure, *speeds])
    head = ["box kg/m³", "expected draft / height", "draft (volume level)", "error", "draft (pressure level)", "error"]
    print(markdown([*head, "body's fastest (m/s)", "body's median / pool's fastest median"], rows))


MODES = {"momentum": momentum, "archimedes": archimedes}

if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 else "20"
    if mode in MODES:
        MODES[mode]()
    elif mode.isdigit():
        main(int(mode))
    else:
        sys.exit(f"bodies.py: {mode!r}: expected a number of frames, momentum or archimedes")
