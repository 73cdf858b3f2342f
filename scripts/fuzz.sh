#!/usr/bin/env bash
# Coverage-guided fuzzing of rigcal's readers with libFuzzer on the stable toolchain.
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET ...]   # default: 60 s each, every target
#   scripts/fuzz.sh seeds                               # rewrite fuzz/corpus/ from the fixtures
#
# Targets (fuzz/fuzz_targets/): mcap (container, chunk walk, index, frame loads), ros2 (CDR
# messages), foxglove (protobuf and JSON), text (native YAML, --config YAML, camera_info YAML,
# URDF, dataset JSON, pasted transforms). The instrumentation is what cargo-fuzz passes to rustc,
# given here as stable -C flags (no nightly, no sanitizer: safe Rust's failures are panics,
# aborts, hangs and runaway memory, which libFuzzer catches without one). Each target runs on a
# scratch copy of its committed seeds (fuzz/corpus/TARGET); a crash, hang or out-of-memory
# input is written to fuzz/artifacts/TARGET/ and fails the script: turn it into a regression
# test (tests/fuzz_regressions.rs) and fix it. The last lines of each run (executions,
# coverage) are printed; RELIABILITY.md records them.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/rigcal-target}/fuzz"
export CARGO_INCREMENTAL=0
triple="$(rustc -vV | sed -n 's/^host: //p')"

if [ "${1:-}" = seeds ]; then
  # The seed writer is not instrumented: a plain build of the same crate.
  cargo run --release --bin seeds
  exit 0
fi

secs="${1:-60}"
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(mcap ros2 foxglove text)

# --target keeps the flags off build scripts and proc macros.
RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Cdebug-assertions -Coverflow-checks" \
  cargo build --release --target "$triple" $(printf -- '--bin %s ' "${targets[@]}")

status=0
for t in "${targets[@]}"; do
  work="$CARGO_TARGET_DIR/corpus-$t"
  rm -rf "$work" && mkdir -p "$work" "artifacts/$t"
  echo "== fuzz $t (${secs} s)"
  # -rss_limit_mb: an input that makes a reader allocate gigabytes is a finding too.
  if ! "$CARGO_TARGET_DIR/$triple/release/$t" "$work" "corpus/$t" \
      -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -max_len=262144 \
      -artifact_prefix="artifacts/$t/" -print_final_stats=1 >"$work.log" 2>&1; then
    status=1
    echo "fuzz $t FOUND A FAILURE: see fuzz/artifacts/$t/ and $work.log"
  fi
  grep -E "^#[0-9]+.*DONE|stat::number_of_executed_units|stat::peak_rss_mb|^==.*ERROR|panicked" "$work.log" | tail -5 || true
done
exit $status
