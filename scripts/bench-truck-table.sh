#!/usr/bin/env bash
# Every calibrator of rigcal on the simulator's truck rig (the paper's MS-Cal layout), in the
# layout of the supplementary's Tables A3 and A5: per camera, the checkerboard corner
# re-projection error (px at 1920 wide) on a held-out checkerboard collect; per LiDAR, the
# LiDAR–LiDAR point-to-plane registration error (cm) on a held-out stationary street collect.
# Classical methods calibrate on a checkerboard collect (as in the paper); UniCal on a short
# figure-8 drive through the street scene. Every method starts from the same 2° / 20 cm guess.
#
#   scripts/bench-truck-table.sh            # prints the Markdown tables
#
# Release build; several minutes on two cores (UniCal dominates).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}"
cargo build -q --release --no-default-features --bin rigcal
bin="$CARGO_TARGET_DIR/release/rigcal"
work="${TMPDIR:-/tmp}/rigcal-bench-truck"
mkdir -p "$work"
synth() { # name scene trajectory seconds seed
  [ -f "$work/$1.mcap" ] || "$bin" synth --scene "$2" --rig truck --trajectory "$3" --seconds "$4" \
    --scale 0.5 --perturb-deg 2 --perturb-cm 20 --seed "$5" --out "$work/$1.mcap" \
    --ground-truth "$work/gt.yaml" >/dev/null
}
synth boards checkerboard stationary 1 7         # calibration collect (classical)
synth boards-eval checkerboard stationary 1 11   # held-out checkerboard collect
synth street-eval urban stationary 0.5 13        # held-out LiDAR collect
synth drive urban figure8 4 7                    # UniCal's drive
methods="initial icp mi target pose-graph unical"
for m in $methods; do
  out="$work/$m.yaml"
  [ -f "$out" ] && continue
  start=$(date +%s.%N)
  case $m in
    # The start every method shares: the calibration collect's /tf_static.
    initial) "$bin" calibrate "$work/boards.mcap" --method edge --iterations 0 --out "$out" >/dev/null 2>"$work/$m.log" ;;
    unical) printf 'cameras:\n  images_per_camera: 2\n' >"$work/unical-config.yaml"
            "$bin" calibrate "$work/drive.mcap" --init "$work/boards.mcap" --method unical \
              --config "$work/unical-config.yaml" --out "$out" >/dev/null 2>"$work/$m.log" ;;
    *) "$bin" calibrate "$work/boards.mcap" --method "$m" --out "$out" >/dev/null 2>"$work/$m.log" ;;
  esac
  end=$(date +%s.%N)
  echo "$m $(echo "$end - $start" | bc)" >> "$work/times.txt"
done
for m in $methods; do
  [ -f "$work/$m-boards.json" ] || "$bin" eval "$work/boards-eval.mcap" --ground-truth "$work/gt.yaml" \
    --calibration "$work/$m.yaml" --checkerboard --frames 3 --json "$work/$m-boards.json" >/dev/null 2>&1
  [ -f "$work/$m-street.json" ] || "$bin" eval "$work/street-eval.mcap" --ground-truth "$work/gt.yaml" \
    --calibration "$work/$m.yaml" --frames 3 --json "$work/$m-street.json" >/dev/null 2>&1
done
python3 benches/truck_table.py "$work" $methods
