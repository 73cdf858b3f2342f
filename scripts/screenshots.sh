#!/usr/bin/env bash
# Render screenshots/ from the real studio window under Xvfb with Mesa's software Vulkan
# (lavapipe): the PandaSet drive (one camera, all cameras, reprojection checks, export) and the
# demo drive before and after a run of the optimiser. Views are set with session files
# (`rigcal studio --session`), buttons are clicked with xdotool.
# Usage: scripts/screenshots.sh [SHOT…]  (default: all of pandaset pandaset-unical pandaset-grid pandaset-checks
# pandaset-export checkerboard-checks demo)      Needs: xvfb mesa-vulkan-drivers libvulkan1 imagemagick xdotool
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${RIGCAL_BIN:-target/release/rigcal}"
[ -x "$bin" ] || cargo build --release
mkdir -p screenshots
log="$(cd ../shared/data/pandaset-002 && pwd)/pandaset-002.mcap"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/rigcal-xdg}"; mkdir -p "$XDG_RUNTIME_DIR"
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
tmp="$(mktemp -d)"
display=":$((90 + RANDOM % 9))"
Xvfb "$display" -screen 0 1600x1000x24 >/dev/null 2>&1 &
xvfb=$!
app=""
trap 'kill $app $xvfb 2>/dev/null || true; rm -rf "$tmp"' EXIT
sleep 1
export DISPLAY="$display"

session() { # name camera grid accumulate colour tab
  cat > "$tmp/$1.json" <<JSON
{"rigcal_session": 1, "log": "$log", "initial": null, "current": null, "camera": $2,
 "view": {"grid": $3, "accumulate": $4, "color_by": "$5", "tab": "$6"}}
JSON
}
start() { "$bin" studio "$@" >"$tmp/studio.log" 2>&1 & app=$!; }
stop() { kill "$app" 2>/dev/null || true; wait "$app" 2>/dev/null || true; app=""; }
shot() { sleep "$2"; xdotool mousemove 1599 999; sleep 0.5; import -window root "screenshots/$1.png"; echo "wrote screenshots/$1.png"; }
click() { xdotool mousemove "$1" "$2" click 1; }
SHOTS="$*"
want() { [ -z "$SHOTS" ] || [[ " $SHOTS " == *" $1 "* ]]; }

if want pandaset; then
  session one 3 false 0 range optimise
  start --session "$tmp/one.json"; shot pandaset 6; stop
fi
if want pandaset-unical; then
  # The optimiser panel on UniCal (its options, the hand-eye among them), chosen by the session,
  # with rolling-shutter cameras (NeuRAD's PandaSet readout) under the image.
  cat > "$tmp/unical.json" <<JSON
{"rigcal_session": 1, "log": "$log", "initial": null, "current": null, "camera": 3, "frame": 15,
 "view": {"color_by": "range", "tab": "optimise", "optimiser_method": "unical",
          "camera_readout_ms": [-30.0, 10.0]}}
JSON
  start --session "$tmp/unical.json"; shot pandaset-unical 6; stop
fi
if want pandaset-grid; then
  session grid 3 true 2 lidar optimise
  start --session "$tmp/grid.json"; shot pandaset-grid 10; stop
fi
if want pandaset-checks; then
  session checks 3 false 0 height checks
  start --session "$tmp/checks.json"; sleep 5
  click 1261 156   # Checks: "Score every pair"
  shot pandaset-checks 90; stop
fi
if want pandaset-export; then
  # The export panel on the URDF format (chosen through the session's view).
  cat > "$tmp/export.json" <<JSON
{"rigcal_session": 1, "log": "$log", "initial": null, "current": null, "camera": 3,
 "view": {"color_by": "intensity", "tab": "export", "export_format": "urdf"}}
JSON
  start --session "$tmp/export.json"; shot pandaset-export 6; stop
fi
if want checkerboard-checks; then
  # The stationary checkerboard scene with a 1° / 5 cm initial guess; the ground truth loaded as
  # the current extrinsics, so the corner error shows before (initial) and after (current).
  "$bin" synth --scene checkerboard --rig pandaset --trajectory stationary --seconds 1 \
    --perturb-deg 1 --perturb-cm 5 --seed 3 --out "$tmp/cb.mcap" --ground-truth "$tmp/cb-gt.yaml" >/dev/null
  cat > "$tmp/cb.json" <<JSON
{"rigcal_session": 1, "log": "$tmp/cb.mcap", "initial": null, "current": null, "camera": 0,
 "view": {"tab": "checks", "color_by": "intensity"}}
JSON
  start --session "$tmp/cb.json" --calibration "$tmp/cb-gt.yaml"; sleep 6
  click 1277 276   # Checks: "Measure corner error"
  shot checkerboard-checks 45; stop
fi
[ -n "$SHOTS" ] && ! want demo && exit 0

# The demo drive (generated into the cache on first start), before and after the optimiser.
cache="${XDG_CACHE_HOME:-$HOME/.cache}/rigcal"
ls "$cache"/demo-*.mcap >/dev/null 2>&1 && wait_demo=8 || wait_demo=80
start; shot demo-initial "$wait_demo"
click 1218 321  # Optimise ▸ Start (below the method, the reference and the cameras)
shot demo-after-optimiser 90; stop
