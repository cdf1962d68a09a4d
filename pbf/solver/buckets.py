"""The capacity buckets a cache folder holds compiled: a start may take one a size up instead of its own.

The solver sizes its arrays by capacity buckets, powers of two (``pbf.solver.model.allocation``),
because Taichi's offline cache names a compiled kernel by the shapes of the fields it touches: a
scene whose counts fall into a bucket no run before used compiles every kernel again.

An array's length changes nothing of the results (``tests/test_start_cache.py``). A start therefore
takes, where its own buckets were never compiled, the smallest pair of buckets a run before compiled
that holds it and is at most one size up on each (:func:`pbf.solver.model.reused_allocation`), while
that adds at most REUSE_LIMIT_BYTES of memory.

Each start records its pair in ``pbf_buckets.txt`` in Taichi's offline cache folder, a line of
"particles cells" each, only while the offline cache is on.
"""

from __future__ import annotations

from pathlib import Path

from pbf.solver.launch import compile_config

FILE = "pbf_buckets.txt"
"""The record, in Taichi's offline cache folder."""
REUSE_LIMIT_BYTES = 64 << 20
"""The most memory a larger bucket may add."""


def _path() -> Path | None:
    """The record's path: None while Taichi's offline cache is off."""
    config = compile_config()
    if not config.offline_cache:
        return None
    return Path(config.offline_cache_file_path) / FILE


def compiled() -> frozenset[tuple[int, int]]:
    """The (particles, cells) bucket pairs the starts before recorded in this cache folder (none when
    the offline cache is off, the record is missing or unreadable; a line that is not two positive
    integers is skipped)."""
    path = _path()
    if path is None:
        return frozenset()
    try:
        text = path.read_text(encoding="ascii", errors="replace")
    except OSError:
        return frozenset()
    pairs = set()
    for line in text.splitlines():
        words = line.split()
        if len(words) == 2 and all(word.isdigit() for word in words):
            particles, cells = map(int, words)
            if particles > 0 and cells > 0:
                pairs.add((particles, cells))
    return frozenset(pairs)


def record(particles: int, cells: int) -> None:
    """Add the pair a start allocates to the record (once); a folder that cannot be written is skipped."""
    path = _path()
    if path is None or (particles, cells) in compiled():
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a", encoding="ascii") as file:  # one short line: starts beside this one append whole lines
            file.write(f"{particles} {cells}\n")
    except OSError:
        return
