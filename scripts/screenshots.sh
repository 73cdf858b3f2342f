#!/usr/bin/env bash
# Render screenshots/ from the real studio window under Xvfb with Mesa's software Vulkan (lavapipe).
# Usage: scripts/screenshots.sh [name log.mcap [extra args…]]   (default: the PandaSet drive)
# Needs: xvfb mesa-vulkan-drivers libvulkan1 imagemagick x11-apps (apt-get install …).
set -euo pipefail
cd "$(dirname "$0")/.."
name="${1:-pandaset}"; shift || true
log="${1:-../shared/data/pandaset-002/pandaset-002.mcap}"; shift || true
bin="${RIGCAL_BIN:-target/release/rigcal}"
[ -x "$bin" ] || cargo build --release
mkdir -p screenshots
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/rigcal-xdg}"; mkdir -p "$XDG_RUNTIME_DIR"
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
display=":$((90 + RANDOM % 9))"
Xvfb "$display" -screen 0 1600x1000x24 >/dev/null 2>&1 &
xvfb=$!
trap 'kill $app $xvfb 2>/dev/null || true' EXIT
sleep 1
DISPLAY="$display" "$bin" studio "$log" "$@" >/tmp/rigcal-studio.log 2>&1 &
app=$!
sleep "${WAIT_SECS:-12}"
DISPLAY="$display" import -window root "screenshots/$name.png"
echo "wrote screenshots/$name.png"
