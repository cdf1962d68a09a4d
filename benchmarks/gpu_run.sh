#!/usr/bin/env bash
# The GPU figures docs/BENCHMARKS.md lacks, in one run on an NVIDIA machine (CUDA), about 9 minutes:
#
#   bash benchmarks/gpu_run.sh [BASE]       # BUDGET=SECONDS caps it (default 520; a device run: timeout 560 s)
#
# BASE: an earlier version's folder to time this one against (benchmarks/ab.py); without git there,
# export it here first: mkdir -p .gpu/base && git archive REV pbf | tar -x -C .gpu/base. The packages
# come from .gpu/whl where it holds wheels (../shared/gpu/prepare.sh: that machine reaches no registry).
# Each step runs under its own limit, so one that fails or hangs leaves the others. In $OUT (default
# out/gpu): summary.txt with each step's table, a log a step, cuda.npz (the physics, for
# ../shared/gpu/judge.py) and Nsight Systems' trace where nsys is installed. The steps, most wanted
# first: the physics (tests/vulkan_run.py), the substep against BASE, the gaps between kernels
# (benchmarks/kernel_gaps.py), dam_break_large's frame rate, 10 M particles, CUDA's launch counts.
set -u
export PYTHONUNBUFFERED=1 TQDM_MININTERVAL=5
BASE=${1:-}
if [[ -n $BASE && ! -f $BASE/pbf/__init__.py ]]; then
  echo "gpu_run: BASE '$BASE' holds no pbf/__init__.py; give an exported version's folder (see the header)" >&2
  exit 2
fi
# Paths as given from here, then everything runs from the project's root.
[[ -n $BASE ]] && BASE=$(realpath "$BASE")
OUT=${OUT:+$(realpath -m "$OUT")}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT" || exit 1
OUT=${OUT:-$ROOT/out/gpu}
BUDGET=${BUDGET:-520}
PY=${PY:-python3}
# Smaller and elsewhere, to try the script itself: ARCH=cpu SIZES=1000 BIG=2000 LARGE=dam_break
# COUNTS_LIMIT=240 (the launch counts' 45 s is a GPU's; the CPU takes a minute under load).
ARCH=${ARCH:-cuda} SIZES=${SIZES:-8000 64000 1000000} BIG=${BIG:-10000000} LARGE=${LARGE:-dam_break_large}
T0=$(date +%s)
mkdir -p "$OUT"
S=$OUT/summary.txt
: >"$S"

left() { echo $((BUDGET - ($(date +%s) - T0))); }
step() { # step NAME LIMIT COMMAND...: the command's output in $OUT/NAME.log, its last lines in the summary
  local name=$1 limit=$2 rem t rc
  shift 2
  rem=$(left)
  if ((rem < 20)); then echo "$name: skipped, $rem s of the budget left" | tee -a "$S"; return; fi
  ((limit > rem - 10)) && limit=$((rem - 10))
  t=$(date +%s)
  timeout -k 5 "$limit" "$@" >"$OUT/$name.log" 2>&1
  rc=$?
  echo "== $name: rc $rc, $(($(date +%s) - t)) s (limit $limit s)" | tee -a "$S"
  tr '\r' '\n' <"$OUT/$name.log" | grep -v "%|" | tail -"${LINES_KEPT:-14}" | tee -a "$S"
}

if [[ -d .gpu/whl ]]; then # into a temporary folder, removed at the end (no Vulkan step: no GL packages)
  SITE=$(mktemp -d)
  trap 'rm -rf "$SITE"' EXIT
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$SITE" \
    .gpu/whl/*.whl >"$OUT/pip.log" 2>&1 || echo "pip install failed ($OUT/pip.log)" | tee -a "$S"
  export PYTHONPATH=$SITE:$ROOT
else
  export PYTHONPATH=$ROOT${PYTHONPATH:+:$PYTHONPATH}
fi
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.max.sm --format=csv 2>&1 | tee -a "$S"

# In the order of what the docs lack most, as the budget may not reach the last steps.
step physics 120 $PY tests/vulkan_run.py "$OUT/$ARCH.npz" "$ARCH" kernel scan grid seed rest
if [[ -n $BASE ]]; then
  step ab 180 $PY benchmarks/ab.py "$BASE" "$ROOT" --arch "$ARCH" --sizes $SIZES --rounds 2 --inner 7
else
  step sizes 120 $PY benchmarks/substep_time.py --arch "$ARCH" --sizes $SIZES
fi
if command -v nsys >/dev/null; then
  # The last of SIZES (a million): the trace ends with its 40 timed substeps, 3 ms or so each at a
  # million particles, so the last 60 ms lie inside them.
  step nsys 90 nsys profile --trace cuda --force-overwrite true --output "$OUT/substeps" \
    $PY benchmarks/substep_time.py --arch "$ARCH" --sizes "${SIZES##* }" --rounds 1 --substeps 40
  LINES_KEPT=40 step gaps 30 $PY benchmarks/kernel_gaps.py "$OUT/substeps.nsys-rep" --last-ms 60
else
  echo "== nsys: not installed here; no timeline" | tee -a "$S"
fi
step large 60 $PY benchmarks/substep_time.py --arch "$ARCH" --preset "$LARGE"
step ten_million 60 $PY benchmarks/substep_time.py --arch "$ARCH" --sizes $BIG --rounds 3
step counts "${COUNTS_LIMIT:-45}" $PY -m benchmarks.bench counts --arch "$ARCH" --sizes 8000
echo "total $(($(date +%s) - T0)) s" | tee -a "$S"
