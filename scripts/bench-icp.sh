#!/usr/bin/env bash
# Point-to-plane ICP, rigcal vs Open3D (the paper's ICP baseline), side by side on the same
# clouds: a simulated drive's Pandar64–PandarGT pair and the real PandaSet pair. Prints one
# Markdown row per tool and case, and the time ratio. Needs Python 3 (Open3D comes from PyPI
# into a virtual environment under ~/.cache).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}"
venv="$HOME/.cache/rigcal-open3d"
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import open3d" 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "open3d==0.19.0"
fi
cargo build -q --release --no-default-features --example icp_compare --bin rigcal
bin="$CARGO_TARGET_DIR/release"
work="${TMPDIR:-/tmp}/rigcal-bench-icp"
mkdir -p "$work"
if [ ! -f "$work/sim.mcap" ]; then
  # Stationary: the rigid comparison needs sweeps without rolling-shutter motion (the paper ran
  # its ICP baseline on stationary scenes); rigcal's own ICP also handles moving drives.
  "$bin/rigcal" synth --scene urban --rig pandaset --trajectory stationary --seconds 1 --scale 0.25 \
    --seed 7 --out "$work/sim.mcap" --ground-truth "$work/sim-gt.yaml"
fi
row() {
  python3 -c '
import json, sys
r = json.loads(sys.argv[2])
r["case"] = sys.argv[1]
print("| {case} | {tool} | {source_points} / {target_points} | {rotation_deg:.4f}° | {translation_cm:.2f} cm | {fitness:.3f} | {inlier_rmse_cm:.2f} cm | {seconds:.3f} s |".format(**r))
' "$1" "$2"
}
echo "| case | tool | source / target points | rotation error | translation error | fitness | inlier RMSE | time |"
echo "|---|---|---|---|---|---|---|---|"
for case in sim pandaset; do
  if [ "$case" = sim ]; then
    log="$work/sim.mcap"; gt="$work/sim-gt.yaml"
  else
    log="../shared/data/pandaset-002/pandaset-002.mcap"; gt="../shared/data/pandaset-002/ground_truth.json"
  fi
  ours=$("$bin/examples/icp_compare" "$log" "$gt" "$work/$case")
  theirs=$("$venv/bin/python" benches/icp_open3d.py "$work/$case")
  row "$case" "$ours"
  row "$case" "$theirs"
  python3 -c '
import json, sys
a, b = json.loads(sys.argv[2]), json.loads(sys.argv[3])
print("| {} | ratio | | | | | | Open3D / rigcal = {:.2f}× |".format(sys.argv[1], b["seconds"] / a["seconds"]))
' "$case" "$ours" "$theirs"
done
