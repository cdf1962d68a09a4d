"""Versions of the simulator timed against each other, alternated in fresh processes: medians and ratios.

    python benchmarks/ab.py HEAD 3153ce8 --arch cpu --sizes 8000 64000 --rounds 5
    python benchmarks/ab.py . ../base --arch cuda --sizes 8000 64000 1000000

A version is a folder holding ``pbf/`` or a git revision of this checkout; the first is the base of
the ratios. Each round runs every version once, the order rotating, as this checkout's
``substep_time.py`` in a fresh process with the version's folder first on PYTHONPATH. Per version and
size: the median over the rounds of ms a substep (a round's: the median of ``--inner`` stretches of
``--substeps``), its range, the host's CPU ms, and the rounds' paired ratios to the base.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from types import SimpleNamespace

if __package__ in (None, ""):  # run as a script: the checkout on the path, for benchmarks.lab
    sys.path.append(str(Path(__file__).resolve().parent.parent))
from benchmarks.lab import CHECKOUT, RunFailed, at_least, export, fresh, revision, spread  # noqa: E402

TIMER = Path(__file__).resolve().parent / "substep_time.py"
RUN_TIMEOUT_S = 3600
"""One version's run of one round: a million particles on the CPU backend take minutes."""

SIZE_ROW = re.compile(r"^\s*([\d,]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s*$")
"""substep_time.py's row for a size: particles, ms/substep, host issue ms, host CPU ms, built s."""


def is_package_folder(path: Path) -> bool:
    return (path / "pbf" / "__init__.py").is_file()


def resolve(given_versions: list[str], scratch: Path, parser: argparse.ArgumentParser) -> list[SimpleNamespace]:
    """Every version: as given, its label, the folder its package is imported from, after checking them
    all (nothing is exported before every one is known); and what its runs print: by size asked, the
    particles its scene holds and a round's ms a substep and host CPU ms."""
    found = []
    for given in given_versions:
        path = Path(given).expanduser()
        if path.is_dir() and not is_package_folder(path):
            parser.error(f"version {given!r}: the folder holds no pbf/__init__.py; give a checkout of the project")
        commit = None if path.is_dir() else revision(given)
        if not path.is_dir() and commit is None:
            parser.error(f"version {given!r}: neither a folder nor a git revision of {CHECKOUT}; give a checkout's "
                         "folder or a commit, branch or tag")  # fmt: skip
        found.append((given, path.resolve() if commit is None else None, commit))
    versions, exported = [], {}
    for n, (given, folder, commit) in enumerate(found):
        if folder is None:
            if commit not in exported:  # a commit named twice (say, to see two runs' spread) is one export
                try:
                    exported[commit] = export(commit, scratch)
                except (OSError, subprocess.SubprocessError, tarfile.TarError) as error:
                    parser.error(f"version {given!r}: exporting commit {commit[:12]} failed: {error}")
            folder = exported[commit]
            if not is_package_folder(folder):
                parser.error(f"version {given!r}: commit {commit[:12]} holds no pbf/__init__.py")
        label = chr(ord("A") + n)
        versions.append(SimpleNamespace(given=given, label=label, folder=folder, particles={}, ms={}, host_cpu_ms={}))
    return versions


def run_once(version: SimpleNamespace, timer_args: list[str], sizes: list[int], workdir: Path) -> None:
    """One fresh process of substep_time.py with ``version``'s package, its rows recorded."""
    name = f"version {version.label} ({version.given})"
    try:
        output = fresh([sys.executable, str(TIMER), *timer_args], [version.folder], RUN_TIMEOUT_S, workdir)
    except RunFailed as failure:
        raise RunFailed(f"{name}: its run failed: {failure}") from None
    rows = [row for row in map(SIZE_ROW.match, output.splitlines()) if row]
    if len(rows) != len(sizes):
        raise RunFailed(f"{name}: {len(rows)} size rows printed, not {len(sizes)}")
    for size, row in zip(sizes, rows):
        version.particles[size] = int(row.group(1).replace(",", ""))
        version.ms.setdefault(size, []).append(float(row.group(2)))
        version.host_cpu_ms.setdefault(size, []).append(float(row.group(4)))


def report(versions: list[SimpleNamespace], args) -> None:
    base = versions[0]
    print()
    for version in versions:
        print(f"  {version.label}: {version.given} ({version.folder})")
    print(
        f"  {args.arch or 'the default backend'}; {args.rounds} rounds, alternated; a round's figure: the "
        f"median of {args.inner} stretches of {args.substeps} substeps"
    )
    ratio_head = f"ratio to {base.label} (range)"
    print(f"\n{'particles':>10} {'version':<8} {'ms/substep (range)':>26} {'host CPU ms':>12} {ratio_head:>20}")
    for size in args.sizes:
        for v in versions:  # the ratios round by round: each round ran both, close in time
            ratio = spread(a / b for a, b in zip(v.ms[size], base.ms[size]))
            host_ms = statistics.median(v.host_cpu_ms[size])
            print(f"{v.particles[size]:>10,} {v.label:<8} {spread(v.ms[size], 3):>26} {host_ms:>12.3f} {ratio:>20}")


def parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("versions", nargs="+", help="folders holding pbf/, or git revisions of this checkout")
    parser.add_argument("--arch", default=None, help="Taichi's backend for every run (default: as the program picks)")
    parser.add_argument("--sizes", type=at_least(1), nargs="+", required=True, help="the seed dam break at these")
    parser.add_argument("--rounds", type=at_least(1), default=3, help="runs of each version, alternated (default 3)")
    parser.add_argument("--inner", type=at_least(1), default=3, help="timed stretches in a run, their median kept")
    parser.add_argument("--substeps", type=at_least(1), default=40, help="substeps of a timed stretch (default 40)")
    args = parser.parse_args(argv)
    if len(args.versions) < 2:
        parser.error("versions: give at least two to compare (the first is the base of the ratios)")
    from pbf.solver.backend import ARCHES

    if args.arch is not None and args.arch.lower() not in ARCHES:
        parser.error(f"--arch {args.arch!r}: unknown backend; allowed: {', '.join(ARCHES)}")
    return parser, args


def main(argv=None) -> int:
    parser, args = parse(argv)
    timer_args = ["--rounds", str(args.inner), "--substeps", str(args.substeps)]
    timer_args += ["--arch", args.arch] if args.arch is not None else []
    timer_args += ["--sizes", *map(str, args.sizes)]
    with tempfile.TemporaryDirectory(prefix="pbf-ab-") as scratch:
        versions = resolve(args.versions, Path(scratch), parser)
        workdir = Path(scratch) / "work"
        workdir.mkdir()
        try:
            for round_ in range(args.rounds):
                order = versions[round_ % len(versions) :] + versions[: round_ % len(versions)]
                print(f"round {round_ + 1} of {args.rounds}: " + ", ".join(v.label for v in order), flush=True)
                for version in order:
                    run_once(version, timer_args, args.sizes, workdir)
        except RunFailed as failure:
            print(f"ab: {failure}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            print("ab: interrupted; nothing reported", file=sys.stderr)
            return 130
    report(versions, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
