#!/usr/bin/env bash
# Studio benchmarks for BENCHMARKS.md: time from launch to the first picture (a camera image with
# its LiDAR overlay) and frame time of the real window under Xvfb with Mesa's software Vulkan
# (lavapipe): one camera, and all six PandaSet cameras with ±15 accumulated sweeps (≥ 1M points).
# Usage: scripts/bench-studio.sh   (release build; needs xvfb mesa-vulkan-drivers libvulkan1)
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${RIGCAL_BIN:-target/release/rigcal}"
[ -x "$bin" ] || cargo build --release
log="$(cd ../shared/data/pandaset-002 && pwd)/pandaset-002.mcap"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/rigcal-xdg}"; mkdir -p "$XDG_RUNTIME_DIR"
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
# Keep the user's own session and recent files out of it.
export XDG_CACHE_HOME="$(mktemp -d)"
tmp="$(mktemp -d)"
display=":$((80 + RANDOM % 9))"
Xvfb "$display" -screen 0 1600x1000x24 >/dev/null 2>&1 &
xvfb=$!
trap 'kill $xvfb 2>/dev/null || true; rm -rf "$tmp" "$XDG_CACHE_HOME"' EXIT
sleep 1
session() { # name grid accumulate
  cat > "$tmp/$1.json" <<JSON
{"rigcal_session": 1, "log": "$log", "initial": null, "current": null,
 "view": {"grid": $2, "accumulate": $3}}
JSON
}
session one false 0
session grid0 true 0
session grid true 15
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); $(date -u +%F)"
for case in one grid0 grid; do
  echo "== $case"
  DISPLAY="$display" RIGCAL_PROFILE_FRAMES=30 timeout 600 "$bin" studio --session "$tmp/$case.json" 2>/dev/null
done
echo "== launch to first picture, default (one camera, the PandaSet log), 3 runs"
for i in 1 2 3; do
  DISPLAY="$display" RIGCAL_PROFILE_FRAMES=1 timeout 600 "$bin" studio "$log" 2>/dev/null | head -1
done
echo "== the demo: first start (the simulator writes the demo drive), then from the cache"
for i in 1 2; do
  DISPLAY="$display" RIGCAL_PROFILE_FRAMES=1 timeout 900 "$bin" 2>/dev/null | head -1
done
