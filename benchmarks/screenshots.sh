#!/usr/bin/env bash
# The window's screenshots in docs/window_tour.png: the start (an empty kernel cache, so the compile
# line shows), the seed dam break running, the help (key h) and the surface view (key v), under a
# virtual display. Needs xvfb, xdotool and imagemagick (apt-get install xvfb xdotool imagemagick)
# and a Vulkan driver for GGUI (mesa-vulkan-drivers libvulkan1). About 2 minutes on 2 cores.
#
#   bash benchmarks/screenshots.sh [OUT.png]        # default docs/window_tour.png
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-docs/window_tour.png}
work=$(mktemp -d)
trap 'kill ${run:-} ${xvfb:-} 2>/dev/null || true; rm -rf "$work"' EXIT
export DISPLAY=:$((70 + RANDOM % 20))
Xvfb "$DISPLAY" -screen 0 1400x820x24 >/dev/null 2>&1 & xvfb=$!
sleep 2

window() {  # the window's id, once it is mapped
  for _ in $(seq 1 240); do id=$(xdotool search --name "^pbf" 2>/dev/null | head -1 || true); [ -n "$id" ] && { echo "$id"; return; }; sleep 0.25; done
  echo "no window appeared" >&2; exit 1
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
