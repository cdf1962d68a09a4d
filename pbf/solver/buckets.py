"""The capacity buckets a cache folder holds compiled, a "particles cells" line per start: a start whose
own were never compiled may take a pair one size up that was (:func:`pbf.solver.model.reused_allocation`).
"""

from __future__ import annotations

from pathlib import Path

from pbf.solver.launch import compile_config

FILE = "pbf_buckets.txt"
REUSE_LIMIT_BYTES = 64 << 20
"""The most memory a larger bucket may add."""


def cache_folder(name: str) -> Path | None:
    """``name`` in Taichi's offline cache folder, where the solver keeps what starts reuse: None while the
    cache is off."""
    config = compile_config()
    return Path(config.offline_cache_file_path) / name if config.offline_cache else None


def compiled() -> frozenset[tuple[int, int]]:
    """The (particles, cells) pairs recorded in this cache folder (lines that are not two positive integers skipped)."""
    path = cache_folder(FILE)
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
    path = cache_folder(FILE)
    if path is None or (particles, cells) in compiled():
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a", encoding="ascii") as file:  # one short line: concurrent appends stay whole
            file.write(f"{particles} {cells}\n")
    except OSError:
        return
