#!/usr/bin/env bash
# The camera methods on the real logs in ../shared (issue 60's acceptance): every sensor of the
# log's own calibration moved 1° / 10 cm (`--perturb-deg 1 --perturb-cm 10`, one random axis
# per sensor and seed), then `calibrate --method M`, then `eval` against the dataset's
# reference. Prints one Markdown row per data set, method and seed with every camera's error
# at the start and at the end (after aligning the reference LiDAR, as `eval` does), the
# verdict the run gave it and its wall time, then the mean and worst per data set and method.
#
#   scripts/bench-real-cameras.sh [METHODS] [SEEDS] [DATASETS]
#   scripts/bench-real-cameras.sh "edge mi" "301 302 303 304 305" "kitti360 kitti000008 pandaset"
#   RIGCAL_BIN=/tmp/rigcal-before TMPDIR=/tmp/before scripts/bench-real-cameras.sh auto 306 kitti360
#   RIGCAL_CONFIG=trial.yaml scripts/bench-real-cameras.sh auto 306 pandaset   (a configuration
#   file given to every calibrate run with --config, to compare a setting before and after)
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}"
methods="${1:-edge mi}"
seeds="${2:-301 302 303 304 305}"
datasets="${3:-kitti360 kitti000008 pandaset}"
# RIGCAL_BIN: a binary built elsewhere (another commit, for a before/after in one sitting).
if [ -n "${RIGCAL_BIN:-}" ]; then
  bin="$RIGCAL_BIN"
else
  cargo build -q --release --no-default-features --bin rigcal
  bin="$CARGO_TARGET_DIR/release/rigcal"
fi
work="${TMPDIR:-/tmp}/rigcal-bench-real-cameras"
mkdir -p "$work"
data=../shared/data
log_of() {
  case "$1" in
    kitti360) echo "$data/kitti360-sample/kitti360-20-frames.mcap" ;;
    kitti000008) echo "$data/kitti-000008/kitti-000008.mcap" ;;
    pandaset) echo "$data/pandaset-002/pandaset-002.mcap" ;;
  esac
}
gt_of() {
  case "$1" in
    kitti360) echo "$data/kitti360-sample/ground_truth.json" ;;
    kitti000008) echo "$data/kitti-000008/ground_truth.json" ;;
    pandaset) echo "$data/pandaset-002/ground_truth.json" ;;
  esac
}
rows="$work/rows.jsonl"
: > "$rows"
for d in $datasets; do
  log=$(log_of "$d"); gt=$(gt_of "$d")
  for s in $seeds; do
    # The start: the perturbed guess as written (edge alignment with no step keeps it).
    start="$work/$d-start-$s"
    "$bin" calibrate "$log" --method edge --iterations 0 --perturb-deg 1 --perturb-cm 10 \
      --seed "$s" --out "$start.yaml" > "$start.txt" 2>&1
    "$bin" eval "$log" --ground-truth "$gt" --calibration "$start.yaml" --json "$start.json" \
      > /dev/null 2>&1
    for m in $methods; do
      out="$work/$d-$m-$s"
      t0=$(date +%s.%N)
      "$bin" calibrate "$log" --method "$m" --perturb-deg 1 --perturb-cm 10 --seed "$s" \
        ${RIGCAL_CONFIG:+--config "$RIGCAL_CONFIG"} --out "$out.yaml" > "$out.txt" 2>&1 || true
      t1=$(date +%s.%N)
      "$bin" eval "$log" --ground-truth "$gt" --calibration "$out.yaml" --json "$out.json" \
        > /dev/null 2>&1
      python3 - "$d" "$m" "$s" "$start.json" "$out.json" "$out.yaml" "$t0" "$t1" >> "$rows" <<'EOF'
import json, sys, yaml
d, m, s, start, end, out, t0, t1 = sys.argv[1:]
a = {p["sensor"]: p for p in json.load(open(start))["poses"]}
b = {p["sensor"]: p for p in json.load(open(end))["poses"]}
doc = yaml.safe_load(open(out))
report = {r["name"]: r for r in (doc.get("metrics", {}).get("report") or {}).get("sensors", [])}
cams = [n for n in b if n in report and report[n].get("kind") == "camera"]
print(json.dumps({
    "data": d, "method": m, "seed": int(s), "secs": float(t1) - float(t0),
    "cameras": [{
        "name": n,
        "start": [a[n]["rotation_deg"], a[n]["translation_m"] * 100],
        "end": [b[n]["rotation_deg"], b[n]["translation_m"] * 100],
        "verdict": report[n]["verdict"],
    } for n in cams],
}))
EOF
      tail -n 1 "$rows" | python3 -c '
import json, sys
r = json.loads(sys.stdin.read())
cells = "; ".join("{name} {start[0]:.2f}° / {start[1]:.1f} cm → {end[0]:.3f}° / {end[1]:.2f} cm ({verdict})".format(**c) for c in r["cameras"])
print("| {data} | {method} | {seed} | ".format(**r) + cells + " | {:.0f} s |".format(r["secs"]))'
    done
  done
done
echo
echo "| data | method | seeds | mean camera rotation start → end | mean translation start → end | worst rotation end | worse rotation than the start (of all) | failed verdicts |"
echo "|---|---|---|---|---|---|---|---|"
python3 - "$rows" <<'EOF'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
keys = sorted({(r["data"], r["method"]) for r in rows})
for d, m in keys:
    rs = [r for r in rows if (r["data"], r["method"]) == (d, m)]
    cams = [c for r in rs for c in r["cameras"]]
    if not cams:
        continue
    mean = lambda f: sum(f(c) for c in cams) / len(cams)
    # A camera kept at its start reads back equal up to rounding: worse means by more than 1e-6°.
    worse = sum(c["end"][0] > c["start"][0] + 1e-6 for c in cams)
    failed = sum(c["verdict"] == "failed" for c in cams)
    print(f"| {d} | {m} | {len(rs)} | {mean(lambda c: c['start'][0]):.3f}° → {mean(lambda c: c['end'][0]):.3f}° | "
          f"{mean(lambda c: c['start'][1]):.2f} → {mean(lambda c: c['end'][1]):.2f} cm | "
          f"{max(c['end'][0] for c in cams):.3f}° | {worse} of {len(cams)} | {failed} |")
EOF
