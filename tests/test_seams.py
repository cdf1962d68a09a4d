"""The seams new features attach to: the per-particle field registry (declared once, carried by the
sort, kept by snapshots, reset for emitted particles) and the boundaries behind one interface."""

import numpy as np
import pytest
import taichi as ti

from pbf.solver import Simulation
from pbf.solver.state import PARTICLE_FIELDS, Snapshot
from tests.scenes import small_dam_break


def test_every_registered_field_is_allocated_for_the_capacity():
    sim = Simulation(small_dam_break(), quiet=True)
    assert sim.model.allocated >= sim.model.capacity
    for spec in PARTICLE_FIELDS:
        values = getattr(sim.state, spec.name)
        assert values.shape == (sim.model.allocated,)
        assert (values.n if spec.components == 3 else 1) == spec.components


def test_the_sort_carries_every_field_and_snapshots_keep_the_kept_ones():
    # Λ set to each particle's creation index survives every re-sort of a splashing run: the sort
    # moves it with its particle (nothing writes Λ without the divergence pass).
    sim = Simulation(small_dam_break(), quiet=True)
    n = sim.particle_count
    marks = np.arange(n, dtype=np.float32)
    start = sim.snapshot()
    sim.restore(Snapshot(start.positions_m, start.velocities_m_s, 0.0, 0, fields={"multiplier": marks}))
    sim.step(20)
    assert np.array_equal(sim.state.in_creation_order(sim.state.multiplier), marks)
    assert np.array_equal(sim.state.in_creation_order(sim.state.index), marks)
    kept = sim.snapshot()
    assert set(kept.fields) == {s.name for s in PARTICLE_FIELDS if s.kept} - {"x", "v"}
    assert np.array_equal(kept.fields["multiplier"], marks)


def test_a_snapshot_with_a_field_of_the_wrong_shape_or_name_is_refused():
    sim = Simulation(small_dam_break(), quiet=True)
    start = sim.snapshot()
    with pytest.raises(ValueError, match=r"fields\['multiplier'\] of shape"):
        sim.restore(Snapshot(start.positions_m, start.velocities_m_s, 0.0, 0, fields={"multiplier": np.zeros(3)}))
    with pytest.raises(ValueError, match="unknown particle field 'temperature'"):
        sim.restore(
            Snapshot(
                start.positions_m,
                start.velocities_m_s,
                0.0,
                0,
                fields={"temperature": np.zeros(len(start.positions_m))},
            )
        )


@ti.data_oriented
class Probe:
    """Calls the boundaries' interface at given points, as a stage's kernel does."""

    def __init__(self, boundaries, points):
        self.boundaries = boundaries
        self.points = ti.Vector.field(3, ti.f32, shape=len(points))
        self.points.from_numpy(np.asarray(points, np.float32))
        self.projected = ti.Vector.field(3, ti.f32, shape=len(points))
        self.density = ti.field(ti.f32, shape=(3, len(points)))

    @ti.kernel
    def run(self):
        for i in self.points:
            p = self.points[i]
            self.projected[i] = self.boundaries.project(p)
            all_parts, _ = self.boundaries.ghost(p, False)
            container, _ = self.boundaries.container.ghost(p)
            obstacles, _ = self.boundaries.obstacles.ghost(p)
            self.density[0, i] = all_parts
            self.density[1, i] = container
            self.density[2, i] = obstacles


def test_the_boundaries_sum_their_parts_and_project_into_the_fluid_domain():
    scene = small_dam_break()
    scene["obstacles"] = [{"min_m": [0.5, 0.0, 0.2], "max_m": [0.6, 0.2, 0.4]}]
    sim = Simulation(scene, quiet=True)
    r = sim.scene.particle_radius_m
    points = [
        [0.55, 0.18, 0.3],  # inside the obstacle: pushed out through its nearest open face (the top)
        [-0.5, 0.3, 0.3],  # outside the container: clamped in
        [0.49, 0.01, 0.3],  # in the corner of floor and obstacle: both ghosts count
        [0.3, 0.3, 0.3],
    ]
    probe = Probe(sim.boundaries, points)
    probe.run()
    projected = probe.projected.to_numpy()
    assert projected[0] == pytest.approx([0.55, 0.2 + r, 0.3], abs=1e-6)
    assert projected[1][0] == pytest.approx(r, abs=1e-6)
    density = probe.density.to_numpy()
    assert density[0] == pytest.approx(density[1] + density[2], abs=1e-6)
    assert density[1, 2] > 0.0 and density[2, 2] > 0.0
    assert [type(part).__name__ for part in sim.boundaries.parts] == ["Container", "Obstacles"]
