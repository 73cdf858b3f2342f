#!/usr/bin/env bash
# Where a UniCal step's time goes in the pipeline's default run (issue 59's profile): the plain
# command runs on LOG; once its optimisation has passed step 200 (every phase started, most hash
# levels open), `perf` samples it for SECONDS with call graphs, and the share of the run's time
# spent in (below) each part of the step is printed. Shares overlap where one part calls another
# (the batched MLP passes call the matrix product, the LiDAR and camera terms call everything).
#
#   scripts/profile-unical-step.sh LOG.mcap [SECONDS]
#
# Needs `perf` (Debian: linux-perf); `cpu-clock` sampling works where hardware counters do not.
set -euo pipefail
cd "$(dirname "$0")/.."
log="${1:?usage: scripts/profile-unical-step.sh LOG.mcap [SECONDS]}"
secs="${2:-30}"
command -v perf >/dev/null || { echo "perf not found (apt-get install linux-perf)" >&2; exit 1; }
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}"
cargo build -q --release --no-default-features --bin rigcal
out="$(mktemp -d)"
"$CARGO_TARGET_DIR/release/rigcal" calibrate "$log" --out "$out/calib.yaml" >"$out/run.log" 2>&1 &
pid=$!
trap 'kill "$pid" 2>/dev/null || true' EXIT
until grep -q "calibrate: 200/" "$out/run.log"; do
  kill -0 "$pid" 2>/dev/null || { echo "the run ended before step 200: $out/run.log" >&2; exit 1; }
  sleep 1
done
perf record -q -e cpu-clock -F 199 --call-graph dwarf,16384 -p "$pid" -o "$out/perf.data" -- sleep "$secs" 2>/dev/null
kill "$pid" 2>/dev/null || true
perf report -i "$out/perf.data" --children --sort symbol --stdio 2>/dev/null >"$out/report.txt"
share() {
  # The largest inclusive share among the lines naming the symbol (or its AVX-512 / AVX2 copy).
  local pct
  pct=$(awk -v sym="] $2" '{
      i = index($0, sym); if (i == 0) next
      rest = substr($0, i + length(sym))
      if (rest == "" || rest ~ /^ / || rest ~ /^::avx(512|2)( |$)/) {
        v = $1; sub(/%/, "", v); if (v + 0 > best) best = v + 0
      }
    } END { printf "%.1f%%", best }' "$out/report.txt")
  printf '| %s | %s |\n' "$1" "$pct"
}
echo "| part of the step (inclusive) | share of the run's samples |"
echo "|---|---|"
share "LiDAR terms (every LiDAR's rays)" "rigcal::unical::lidar_terms::lidar_step"
share "camera colour terms (every camera's rays)" "rigcal::unical::camera_rgb::colour_step"
share "surface-alignment term" "rigcal::unical::depth_calib::alignment::<impl rigcal::unical::depth_calib::DepthCalibration>::alignment_gradients"
share "hash grid: encoding (table gather)" "rigcal::unical::hash_grid::encode_wide"
share "hash grid: backward (table scatter, spatial gradient)" "rigcal::unical::hash_grid::backward_wide"
share "scatter into the gradient accumulators" "rigcal::unical::hash_grid::GradAccumulator::add_one"
share "MLP forward, batched (geometry decoders)" "rigcal::unical::mlp::Mlp::forward_many"
share "MLP backward, batched (geometry decoders)" "rigcal::unical::mlp::Mlp::backward_many"
share "of which the matrix products" "rigcal::unical::gemm::gemm_acc"
share "MLP forward, one at a time (colour, sky, intensity decoders)" "rigcal::unical::mlp::Mlp::forward"
share "MLP backward, one at a time" "rigcal::unical::mlp::Mlp::backward"
share "compositing" "rigcal::unical::composite::composite"
share "compositing backward" "rigcal::unical::composite::composite_backward"
share "regulariser: Eikonal" "rigcal::unical::regulariser::eikonal_many"
share "regulariser: weight suppression" "rigcal::unical::regulariser::weight_suppression"
share "Adam: hash tables" "rigcal::unical::adam::SparseAdam::step_accumulated"
share "Adam: decoders" "rigcal::unical::adam::DenseAdam::step"
share "ray generation: LiDAR returns" "rigcal::unical::depth_calib::sampling::<impl rigcal::unical::depth_calib::DepthCalibration>::draw_rays"
share "ray generation: camera pixels (heat-map draws)" "rigcal::unical::depth_calib::sampling::<impl rigcal::unical::depth_calib::DepthCalibration>::draw_camera_rays"
share "of which samples along rays (occupancy grid)" "rigcal::unical::occupancy::OccupancyGrid::sample"
share "silhouette heat maps refreshed" "rigcal::unical::depth_calib::sampling::<impl rigcal::unical::depth_calib::DepthCalibration>::refresh_silhouettes"
share "memory allocation and release" "__GI___libc_malloc (inlined)"
echo
echo "run log, perf data and the whole report: $out"
