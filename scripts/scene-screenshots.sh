#!/usr/bin/env bash
# One studio screenshot per simulator scene: synthesize a short half-size drive of each scene
# (perturbed by 1.5°/5 cm like the demo) and capture the real window with scripts/screenshots.sh.
# Usage: scripts/scene-screenshots.sh [SCENE…]   (RIGCAL_BIN as for screenshots.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${RIGCAL_BIN:-target/release/rigcal}"
[ -x "$bin" ] || cargo build --release
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
for scene in ${*:-urban parking-lot featureless checkerboard}; do
  traj=figure8
  [ "$scene" = checkerboard ] && traj=stationary
  "$bin" synth --scene "$scene" --rig pandaset --trajectory "$traj" --seconds 1 --seed 7 \
    --perturb-deg 1.5 --perturb-cm 5 --scale 0.5 --out "$tmp/$scene.mcap" --ground-truth "$tmp/$scene.yaml"
  RIGCAL_BIN="$bin" WAIT_SECS="${WAIT_SECS:-15}" scripts/screenshots.sh "scene-$scene" "$tmp/$scene.mcap"
done
