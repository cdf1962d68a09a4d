"""Where a GPU's time goes between its kernels: Nsight Systems' trace of a run, added up.

    nsys profile -t cuda -o substeps python benchmarks/substep_time.py --arch cuda --sizes 1000000 \\
        --rounds 1 --substeps 40
    python benchmarks/kernel_gaps.py substeps.nsys-rep --last-ms 150 --substeps 40

Of the operations that began in the trace's last ``--last-ms``: the time some ran and none did, the
operations by name, and the longest idle gaps with what ran on either side (a substep's with ``--substeps``).
"""

from __future__ import annotations

import argparse
import csv
import shutil
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

LONGEST = 10
"""Idle gaps listed."""


def trace_csv(path: Path) -> str:
    """The cuda_gpu_trace report of ``path`` as CSV text: read as it is, or made by ``nsys stats``."""
    if path.suffix != ".nsys-rep":
        return path.read_text(encoding="utf-8", errors="replace")
    nsys = shutil.which("nsys")
    if nsys is None:
        raise ValueError(f"{path}: an Nsight Systems report needs nsys on PATH to read (or give its CSV)")
    for report in ("cuda_gpu_trace", "gputrace"):  # the report's name since Nsight Systems 2021.5, and before
        command = [nsys, "stats", "--report", report, "--format", "csv", "--output", "-", str(path)]
        done = subprocess.run(command, capture_output=True, text=True, timeout=600)
        if done.returncode == 0 and any(is_header(line) for line in done.stdout.splitlines()):
            return done.stdout
    raise ValueError(f"{path}: nsys stats gave no GPU trace: {(done.stderr or done.stdout).strip()[-300:]}")


def is_header(line: str) -> bool:
    cells = [cell.strip().strip('"') for cell in line.split(",")]
    return "Name" in cells and all(any(c.startswith(word) for c in cells) for word in ("Start", "Duration"))


def operations(text: str) -> list[tuple[float, float, str]]:
    """(start ns, duration ns, name) of every row, sorted by start. The header is the first line that
    names a start, a duration and a name (nsys may print notes before it)."""
    lines = text.splitlines()
    first = next((k for k, line in enumerate(lines) if is_header(line)), None)
    if first is None:
        raise ValueError("no header with Start, Duration and Name columns: not a cuda_gpu_trace report")
    rows = csv.reader(lines[first:])
    header = [cell.strip() for cell in next(rows)]
    start, duration = (next(k for k, c in enumerate(header) if c.startswith(word)) for word in ("Start", "Duration"))
    name, found = header.index("Name"), []
    for row in rows:
        try:
            found.append((float(row[start]), float(row[duration]), row[name].strip()))
        except (ValueError, IndexError):  # a note or a blank line after the table
            continue
    if not found:
        raise ValueError("the report holds no operations")
    return sorted(found)


def analyse(ops: list[tuple[float, float, str]], last_ms: float | None) -> dict:
    """The window's length, busy and idle time, totals by name and the idle gaps, in ns."""
    if last_ms is not None:
        end = max(s + d for s, d, _ in ops)
        ops = [op for op in ops if op[0] >= end - last_ms * 1e6]
        if not ops:  # the last operation began before the window: it alone outlasts it
            raise ValueError(f"no operation began in the last {last_ms:g} ms of the trace; give a longer --last-ms")
    begin, end = ops[0][0], max(s + d for s, d, _ in ops)
    by_name: dict[str, list[float]] = defaultdict(lambda: [0, 0.0])
    busy, gaps, reach, before = 0.0, [], begin, ops[0][2]
    for s, d, name in ops:
        by_name[name][0] += 1
        by_name[name][1] += d
        if s > reach:
            gaps.append((s - reach, before, name))
        if s + d > reach:
            busy += s + d - max(s, reach)
            reach, before = s + d, name
    by_name = sorted(by_name.items(), key=lambda item: -item[1][1])
    return dict(window=end - begin, busy=busy, idle=end - begin - busy, operations=len(ops), by_name=by_name,
                gaps=sorted(gaps, reverse=True)[:LONGEST], gap_count=len(gaps))  # fmt: skip


def report(result: dict, substeps: int | None) -> None:
    scale = 1e3 * (substeps or 1)  # ns → µs, per substep where given

    def us(ns: float) -> str:
        return f"{ns / scale:,.1f} µs" + (" a substep" if substeps else "")

    idle_share = result["idle"] / result["window"] if result["window"] > 0 else 0.0
    print(f"{result['operations']} operations in a window of {us(result['window'])}")
    idle = f"{us(result['idle'])} ({idle_share:.0%} of the window, {result['gap_count']} gaps)"
    print(f"  something ran: {us(result['busy'])}; nothing ran: {idle}\n")
    print(f"{'count':>7} {'total µs':>11} {'mean µs':>9}  operation")
    for name, (count, total) in result["by_name"]:
        shown = f"{count / (substeps or 1):g}" if substeps else f"{count}"
        print(f"{shown:>7} {total / scale:>11.1f} {total / count / 1e3:>9.1f}  {name[:100]}")
    print(f"\nthe {len(result['gaps'])} longest gaps (µs): what ended → what began")
    for gap, before, after in result["gaps"]:
        print(f"{gap / 1e3:>9.1f}  {before[:60]} → {after[:60]}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, help="an .nsys-rep file, or its cuda_gpu_trace report as CSV")
    parser.add_argument("--last-ms", type=float, default=None, help="only what began in the trace's last ms")
    parser.add_argument("--substeps", type=int, default=None, help="the substeps in that window: totals per substep")
    args = parser.parse_args(argv)
    if not args.report.is_file():
        parser.error(f"report {str(args.report)!r}: no such file")
    if (args.last_ms is not None and not args.last_ms > 0) or (args.substeps is not None and args.substeps < 1):
        parser.error(f"--last-ms {args.last_ms}, --substeps {args.substeps}: a positive length, at least 1")
    try:
        result = analyse(operations(trace_csv(args.report)), args.last_ms)
    except ValueError as error:
        print(f"kernel_gaps: {error}", file=sys.stderr)
        return 1
    report(result, args.substeps)
    return 0


if __name__ == "__main__":
    sys.exit(main())
