#!/usr/bin/env bash
# The window's screenshots as one sheet: the start (an empty kernel cache, so the compile line shows),
# the seed dam break running, the help (key h) and the surface view (key v), under a virtual display.
# Needs xvfb, xdotool and imagemagick (apt-get install xvfb xdotool imagemagick) and a Vulkan driver
# for GGUI (mesa-vulkan-drivers libvulkan1). About 2 minutes on 2 cores.
#
#   bash benchmarks/screenshots.sh [OUT.png]        # default out/window_tour.png
#   bash benchmarks/screenshots.sh --docs           # docs/window_tour.png, the README's picture
set -euo pipefail

# What is missing, all of it at once, before anything starts (the window's wait would end only in
# "no window appeared").
missing=()
command -v Xvfb >/dev/null || missing+=("Xvfb, the virtual display (apt-get install xvfb)")
command -v xdotool >/dev/null || missing+=("xdotool, which finds the window and presses its keys (apt-get install xdotool)")
command -v import >/dev/null || missing+=("ImageMagick's import, which takes the screenshots (apt-get install imagemagick)")
command -v python >/dev/null || missing+=("python with pbf installed (python3 -m venv .venv && . .venv/bin/activate && pip install -e .)")
if [ ${#missing[@]} -gt 0 ]; then
  echo "screenshots.sh needs what is not installed here:" >&2
  printf '  %s\n' "${missing[@]}" >&2
  exit 1
fi

cd "$(dirname "$0")/.."
case "${1:-}" in
  --docs) out=docs/window_tour.png ;;
  -*) echo "screenshots.sh: unknown option $1; usage: bash benchmarks/screenshots.sh [OUT.png | --docs]" >&2; exit 2 ;;
  *) out=${1:-out/window_tour.png} ;;
esac
mkdir -p "$(dirname "$out")"
work=$(mktemp -d)
trap 'kill ${run:-} ${xvfb:-} 2>/dev/null || true; rm -rf "$work"' EXIT
export DISPLAY=:$((70 + RANDOM % 20))
Xvfb "$DISPLAY" -screen 0 1400x820x24 >"$work/xvfb.log" 2>&1 & xvfb=$!
sleep 2
kill -0 "$xvfb" 2>/dev/null || { echo "Xvfb did not start on $DISPLAY: $(tail -1 "$work/xvfb.log")" >&2; exit 1; }

window() {  # the window's id, once it is mapped; the run's own reason when it fell back to frames
  for _ in $(seq 1 240); do
    id=$(xdotool search --name "^pbf" 2>/dev/null | head -1 || true); [ -n "$id" ] && { echo "$id"; return; }
    reason=$(grep -h "\[pbf\] no window:" "$work"/*.log 2>/dev/null | tail -1 || true)
    [ -n "$reason" ] && { echo "no window appeared: ${reason#\[pbf\] no window: }" >&2; exit 1; }
    sleep 0.25
  done
  echo "no window appeared within a minute, and the run gave no reason" >&2; exit 1
}
ready() {  # waits for the start line that follows the first picture
  for _ in $(seq 1 300); do grep -q "kernels ready" "$1" && return; sleep 1; done
  echo "the run never drew its first frame" >&2; exit 1
}

# 1. A first start: an empty kernel cache, the compile line in the window.
TI_OFFLINE_CACHE_FILE_PATH="$work/cache" MESA_SHADER_CACHE_DIR="$work/cache/mesa" python run.py dam_break >"$work/first.log" 2>&1 & run=$!
id=$(window); sleep 1.5; import -window "$id" "$work/start.png"
ready "$work/first.log"; kill "$run"; wait "$run" 2>/dev/null || true

# 2-4. A warm start: running, then the help, then the surface view.
python run.py dam_break >"$work/second.log" 2>&1 & run=$!
id=$(window); ready "$work/second.log"; sleep 8; import -window "$id" "$work/running.png"
xdotool windowfocus --sync "$id"; sleep 0.5
xdotool key h; sleep 4; import -window "$id" "$work/help.png"
xdotool key h; sleep 1; xdotool key v; sleep 20; import -window "$id" "$work/surface.png"
kill "$run"; wait "$run" 2>/dev/null || true

python - "$work" "$out" <<'PY'
import sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
from PIL import Image
work, out = sys.argv[1:]
titles = {"start": "first start: compiling", "running": "running", "help": "key h: help", "surface": "key v: surface"}
figure, axes = plt.subplots(2, 2, figsize=(12.8, 7.6))
for axis, (name, title) in zip(axes.flat, titles.items()):
    axis.imshow(Image.open(f"{work}/{name}.png").convert("RGB"))
    axis.set_title(title, fontsize=10)
    axis.axis("off")
figure.tight_layout(pad=0.6)
figure.savefig(out, dpi=100)
print(f"wrote {out}")
PY
