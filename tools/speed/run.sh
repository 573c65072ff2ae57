#!/usr/bin/env bash
# The numbers of docs/speed.md: rgm (benches/examples/speed.rs) and the PyTorch reference
# (tools/speed/reference_speed.py) side by side in one run, one process per configuration (its
# own peak memory), JSON lines to $OUT (default target/speed.jsonl).
#
#   bash tools/speed/run.sh [--pause PIDFILE] [--reps N]
#
# --pause PIDFILE stops the process in PIDFILE (a training run that would share the cores) for
# the duration and always resumes it, even on failure or interruption.
set -euo pipefail
cd "$(dirname "$0")/../.."
REPS=5
PAUSE=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --pause) PAUSE="$2"; shift 2 ;;
    --reps) REPS="$2"; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
OUT="${OUT:-target/speed.jsonl}"
cargo build --release -q -p rgm-benches --example speed
BIN="${CARGO_TARGET_DIR:-target}/release/examples/speed"
if [[ -n "$PAUSE" ]] && kill -0 "$(cat "$PAUSE")" 2>/dev/null; then
  PID="$(cat "$PAUSE")"
  trap 'kill -CONT "$PID" 2>/dev/null || true' EXIT INT TERM
  kill -STOP "$PID"
  echo "paused $PID" >&2
fi
uptime >&2
: > "$OUT"
for what in forward train procedure; do
  for preset in paper fast; do
    "$BIN" --preset "$preset" --what "$what" --reps "$REPS" | tee -a "$OUT"
    python3 tools/speed/reference_speed.py --preset "$preset" --what "$what" --reps 3 | tee -a "$OUT"
  done
done
# As rgm ships: the built-in fast model matching on 384 points.
"$BIN" --preset fast --what procedure --match-points 384 --weights "${WEIGHTS:-crates/rgm-model/weights/partial-fast.safetensors}" --reps "$REPS" | tee -a "$OUT"
