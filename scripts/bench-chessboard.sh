#!/usr/bin/env bash
# Checkerboard corners, rigcal vs OpenCV's findChessboardCornersSB, side by side on the same
# crops of the simulator's checkerboard scene (every camera of the pandaset rig at 1920 x 1080,
# each board whose inner corners are all in view), against the simulator's true corners.
# Prints one Markdown row per board and tool, then the totals. Needs Python 3 (OpenCV comes
# from PyPI into the virtual environment the export checks use).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}"
venv="${RIGCAL_VENV:-$HOME/.cache/rigcal-venv}"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q --disable-pip-version-check -r tests/exports/requirements.txt
cargo build -q --release --no-default-features --example chessboard_compare
work="${TMPDIR:-/tmp}/rigcal-bench-chessboard"
rm -rf "$work" && mkdir -p "$work"
"$CARGO_TARGET_DIR/release/examples/chessboard_compare" "$work" "${1:-1.0}" > "$work/rigcal.jsonl"
"$venv/bin/python" benches/chessboard_opencv.py "$work" < "$work/rigcal.jsonl" > "$work/opencv.jsonl"
"$venv/bin/python" - "$work" <<'PY'
import json, sys
work = sys.argv[1]
rows = [json.loads(l) for f in ("rigcal", "opencv") for l in open(f"{work}/{f}.jsonl") if l.strip()]
print("| board | tool | found | mean corner error (px) | time (ms) |")
print("|---|---|---|---|---|")
for r in sorted(rows, key=lambda r: (r["name"], r["tool"])):
    e = "—" if r["mean_error_px"] is None else f"{r['mean_error_px']:.3f}"
    print(f"| {r['name']} | {r['tool']} | {'yes' if r['found'] else 'no'} | {e} | {1000 * r['seconds']:.1f} |")
for tool in ("rigcal", "opencv"):
    mine = [r for r in rows if r["tool"] == tool]
    found = [r for r in mine if r["found"]]
    errs = [r["mean_error_px"] for r in found]
    both = [r for r in found if any(o["name"] == r["name"] and o["found"] and o["tool"] != tool for o in rows)]
    eb = [r["mean_error_px"] for r in both]
    print(f"\n**{tool}**: {len(found)} of {len(mine)} boards found; mean corner error {sum(errs)/max(len(errs),1):.3f} px "
          f"(on the {len(both)} boards both found: {sum(eb)/max(len(eb),1):.3f} px); "
          f"total time {sum(r['seconds'] for r in mine)*1000:.0f} ms")
PY
