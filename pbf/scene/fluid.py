"""The fluid: its spacing, rest density, blocks and particle budget."""

from __future__ import annotations

from dataclasses import dataclass

from pbf.scene.geometry import Block
from pbf.scene.schema import _at_most_tables, _between, key

MAX_TABLES = 1000
"""Most [[fluid.blocks]] in a scene: the overlap check compares every pair."""


@dataclass(frozen=True)
class Fluid:
    spacing_m: float = key(0.025, _between(1e-4, 100.0), "particle spacing s (the lattice pitch), m")
    rest_density_kg_m3: float = key(1000.0, _between(1e-3, 1e5), "rest density ρ0, kg/m³")
    blocks: tuple[Block, ...] = key((), _at_most_tables(MAX_TABLES), "fluid blocks ([[fluid.blocks]] tables)")
    max_particles: int = key(
        0,
        _between(0, 2**31 - 1),
        "particle budget, allocated at the start: at least the "
        "blocks' particles and all that the emitters add; 0: exactly that many",
    )
