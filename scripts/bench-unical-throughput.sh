#!/usr/bin/env bash
# UniCal's throughput at the CPU preset beside the machine's dense f32 matrix-multiply rate
# (OpenBLAS sgemm through numpy, 2048², as many threads as rayon uses), in one run.
#
#   scripts/bench-unical-throughput.sh [RENDER_STEPS]
#
# numpy comes from the venv .ci/run keeps for the export checks (created here when missing).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}"
VENV="${RIGCAL_VENV:-$HOME/.cache/rigcal-venv}"
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -c "import numpy" 2>/dev/null || "$VENV/bin/pip" install -q numpy
threads=$(nproc)
OPENBLAS_NUM_THREADS=$threads OMP_NUM_THREADS=$threads "$VENV/bin/python" - <<'PY'
import time, numpy as np
n = 2048
a = np.random.rand(n, n).astype(np.float32)
b = np.random.rand(n, n).astype(np.float32)
a @ b  # warm-up
runs = []
for _ in range(5):
    t = time.perf_counter(); a @ b; runs.append(time.perf_counter() - t)
best = min(runs)
print(f"sgemm {n}²: {2 * n**3 / best / 1e9:.1f} GFLOP/s (best of 5, {best * 1e3:.0f} ms)")
PY
cargo build -q --release --no-default-features --example unical_throughput
/usr/bin/time -f "wall %e s, peak RSS %M KB" "$CARGO_TARGET_DIR/release/examples/unical_throughput" "${1:-60}"
