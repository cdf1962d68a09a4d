"""A model of the bytes a substep moves per particle, by stage, from the arrays each pass reads and writes.

    python -m pbf.study.bench traffic [--sizes 1000000] [--iterations 4]

At a million particles a GPU substep is bound by memory, not by arithmetic or launches: the sorted
particles' positions (12 MB) fit in an H200's 60 MB L2 cache, so what a pass gathers from its
neighbours mostly comes from there, while what it streams (its own particle's arrays, in sorted
order, read or written once) comes from the GPU's memory. The model counts both, per particle and
substep, for two designs of the neighbour search:

* ``lists`` (today's device path): a pass over the grid writes each particle's neighbour indices and
  does the first iteration's λ pass with the pairs it finds (``DensityConstraint.first_in_visit``), and
  every later pass reads the lists back and gathers the neighbours through them;
* ``cells``: no lists; every pass walks the cells around the particle (contiguous slots in the sorted
  order: ``NeighbourGrid.column_range``) and tests each candidate's distance again.

Figures are bytes per particle. ``neighbours`` is the mean count within h, ``candidates`` the mean
count in the 5 × 5 columns of 5 cells a particle visits (cells h/2 wide), ``cells`` the grid's cells
per particle. The numbers come from the fields named in each row, read off the kernels of
``pbf.solver``; a 4-byte float or index, a 12-byte vector. Neither cache effects within a pass nor
atomics' cost are modelled: it is a floor to compare designs by, not a prediction.
"""

from __future__ import annotations

from dataclasses import dataclass

VECTOR, SCALAR = 12, 4
CARRIED = 2 * VECTOR + 3 * SCALAR + VECTOR
"""The arrays the sort carries: x, v, creation index, Λ, the pressure sum, and x*."""
H200_BANDWIDTH = 4.8e12
"""An H200's memory bandwidth, bytes per second (HBM3e)."""


@dataclass(frozen=True)
class Pass:
    stage: str
    name: str
    streamed: float
    """Bytes per particle read and written in the particle's own slots (from memory)."""
    gathered: float
    """Bytes per particle read from other particles' slots (mostly from the L2 cache)."""
    per_iteration: bool = False
    after_first: bool = False
    """A pass of every iteration but the first (whose work another pass does)."""


def passes(design: str, neighbours: float, candidates: float, cells: float) -> list[Pass]:
    """The passes of one substep (4-byte indices and floats, 12-byte vectors)."""
    k, c = neighbours, candidates
    listed = design == "lists"
    # A pass over a particle's neighbours: through its list (start, end and k indices), or through the
    # 25 columns of the cells around it (two cell starts each) and every candidate's position.
    visit_stream = 2 * SCALAR + k * SCALAR if listed else 0.0
    visit_gather = k * VECTOR if listed else 25 * 2 * SCALAR + c * VECTOR
    rows = [
        Pass(
            "predict",
            "v += Δt g, x* = x + Δt v, its cell and rank: x, v in; v, x*, cell, rank out",
            4 * VECTOR + 2 * SCALAR,
            0.0,
        ),
        Pass("sort", "prefix sum over the cells (count in, start out)", 2 * SCALAR * cells, 0.0),
        Pass("sort", "scatter: cell, rank in, cell start gathered; members out", 3 * SCALAR, SCALAR),
        Pass(
            "sort",
            "place in the cell by key, gathered there: member, cell, starts in, the cell's keys; order, scratch, "
            "the walls' ghost out",
            4 * SCALAR + CARRIED + SCALAR + VECTOR,
            2 * SCALAR + CARRIED,
        ),
    ]
    # The visit that follows the sort takes the carried arrays back from scratch (2 × CARRIED streamed),
    # and with lists does the first iteration's λ pass: the walls' ghost in, the denominator and λ, L,
    # L before out (the ghost beyond the surface: C_i and the colour gradient instead, as many bytes).
    rows.append(
        Pass(
            "neighbour lists" if listed else "sort",
            "visit the cells: x* in, candidates' x* gathered; indices, count, start, end out; carried taken back; "
            "the first λ: the walls' ghost in, denominator, λ, L, L before out"
            if listed
            else "the carried arrays taken back from scratch",
            (VECTOR + k * SCALAR + 3 * SCALAR + SCALAR + VECTOR + 4 * SCALAR if listed else 0.0) + 2 * CARRIED,
            25 * 2 * SCALAR + c * VECTOR if listed else 0.0,
        )
    )
    rows += [
        Pass(
            "iterations",
            "λ: x*, denominator, L, L before, the walls' ghost in; λ, L, L before out; neighbours' x*",
            VECTOR + 3 * SCALAR + SCALAR + VECTOR + 3 * SCALAR + visit_stream,
            visit_gather,
            True,
            after_first=listed,
        ),
        Pass(
            "iterations",
            "Δx: x*, λ, the walls' gradient, x^{k-1} in; x^{k+1}, the walls' ghost there out; neighbours' x* and λ",
            4 * VECTOR + SCALAR + SCALAR + VECTOR + visit_stream,
            visit_gather + k * SCALAR,
            True,
        ),
        Pass(
            "velocity, vorticity, XSPH",
            "v = (x* − x)/Δt, ω: x, x* in; ω, |ω|, v out; neighbours' x*, v",
            2 * VECTOR + 2 * VECTOR + SCALAR + visit_stream,
            visit_gather + k * VECTOR,
        ),
        Pass(
            "velocity, vorticity, XSPH",
            "confinement, XSPH, x = x*: x*, v, ω in; v, x, pressure out; neighbours' x*, v, |ω|",
            3 * VECTOR + 2 * VECTOR + SCALAR + visit_stream,
            visit_gather + k * (VECTOR + SCALAR),
        ),
    ]
    return rows


def by_stage(rows: list[Pass], iterations: int) -> dict[str, tuple[float, float]]:
    """(streamed, gathered) bytes per particle per substep, by stage, the iterations' passes counted
    ``iterations`` times."""
    stages: dict[str, tuple[float, float]] = {}
    for row in rows:
        times = (iterations - row.after_first) if row.per_iteration else 1
        streamed, gathered = stages.get(row.stage, (0.0, 0.0))
        stages[row.stage] = (streamed + times * row.streamed, gathered + times * row.gathered)
    return stages


def measured_counts(sim) -> tuple[float, float, float]:
    """(neighbours, candidates, cells) per particle of a simulation's current state: the mean count
    within h, the mean count in the cells a particle visits (its own ± the grid's reach along each
    axis), and the grid's cells per particle."""
    import numpy as np

    grid = sim.model.grid
    positions = sim.positions().astype(np.float64)
    lower, upper = np.asarray(grid.lower_m), np.asarray(grid.upper_m)
    resolution = np.asarray(grid.resolution)
    cell = np.clip(((positions - lower) / (upper - lower) * resolution).astype(int), 0, resolution - 1)
    counts = np.zeros(resolution, np.int64)
    np.add.at(counts, tuple(cell.T), 1)
    reach = grid.reach
    padded = np.pad(counts, reach)
    box = padded.cumsum(0).cumsum(1).cumsum(2)
    box = np.pad(box, ((1, 0), (1, 0), (1, 0)))
    width = 2 * reach + 1
    # The sum over the (2 reach + 1)³ cells around each cell, by inclusion-exclusion on the cumulative sums.
    total = np.zeros(resolution, np.int64)
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                sign = (-1) ** (3 - dx - dy - dz)
                total += (
                    sign
                    * box[
                        dx * width : dx * width + resolution[0],
                        dy * width : dy * width + resolution[1],
                        dz * width : dz * width + resolution[2],
                    ]
                )
    candidates = float(total[tuple(cell.T)].mean())
    return float(sim.neighbour_counts().mean()), candidates, grid.cell_count / len(positions)


def table(particles: int, iterations: int, neighbours: float, candidates: float, cells: float) -> str:
    """Both designs side by side, with the floor time of the streamed bytes at an H200's bandwidth."""
    designs = {name: by_stage(passes(name, neighbours, candidates, cells), iterations) for name in ("lists", "cells")}
    lines = [
        f"bytes per particle and substep, {iterations} iterations, {neighbours:g} neighbours, "
        f"{candidates:g} candidates, {cells:g} cells per particle",
        f"{'stage':<28} {'lists: streamed':>16} {'gathered':>10} {'cells: streamed':>16} {'gathered':>10}",
    ]
    totals = {name: [0.0, 0.0] for name in designs}
    for stage in designs["lists"]:
        cells_row = designs["cells"].get(stage, (0.0, 0.0))
        lists_row = designs["lists"][stage]
        lines.append(
            f"{stage:<28} {lists_row[0]:>16.0f} {lists_row[1]:>10.0f} {cells_row[0]:>16.0f} {cells_row[1]:>10.0f}"
        )
        for name, row in (("lists", lists_row), ("cells", cells_row)):
            totals[name][0] += row[0]
            totals[name][1] += row[1]
    lines.append(
        f"{'total':<28} {totals['lists'][0]:>16.0f} {totals['lists'][1]:>10.0f} "
        f"{totals['cells'][0]:>16.0f} {totals['cells'][1]:>10.0f}"
    )
    for name, (streamed, gathered) in totals.items():
        floor_ms = particles * streamed / H200_BANDWIDTH * 1e3
        lines.append(
            f"{name}: {particles:,} particles stream {particles * streamed / 1e9:.2f} GB a substep "
            f"(floor {floor_ms:.2f} ms at {H200_BANDWIDTH / 1e12:g} TB/s) and gather "
            f"{particles * gathered / 1e9:.2f} GB, mostly from the L2 cache"
        )
    return "\n".join(lines)
