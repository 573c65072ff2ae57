#!/usr/bin/env bash
# Issue 24's same-run A/B of one training step (`fast`, 384 points, forward + BCE + backward, the
# built-in weights, one core): the `speed` example built at the issue's start (8daedb6, OpenBLAS
# products) against the working tree's, f32 and bf16, round-robin with the order rotated each
# round. Prints one line per process: round, arm, the example's JSON, then "TIME user sys wall".
#
#   bash tools/speed/step_ab.sh [ROUNDS] [START_COMMIT]     (10, 8daedb6)
#
# Builds the start in a temporary worktree with its own target folder (minutes, one job) and
# removes both afterwards. On a loaded machine the user times are the steadier figure.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROUNDS=${1:-10}
START=${2:-8daedb6}
WORK=$(mktemp -d)
trap 'git worktree remove --force "$WORK/start" 2>/dev/null || true; rm -rf "$WORK"' EXIT
git worktree add -q "$WORK/start" "$START"
(cd "$WORK/start" && CARGO_TARGET_DIR="$WORK/target" nice cargo build -q --release -p rgm-benches --example speed -j 1)
cp "$WORK/target/release/examples/speed" "$WORK/speed-start"
nice cargo build -q --release -p rgm-benches --example speed -j 1
cp target/release/examples/speed "$WORK/speed-head"
run() { # arm binary precision
  local out
  out=$(OPENBLAS_NUM_THREADS=1 RAYON_NUM_THREADS=1 /usr/bin/time -f "TIME %U %S %e" \
    taskset -c 1 "$2" --preset fast --what train --points 384 --reps 9 \
    --weights crates/rgm-model/weights/partial-fast.safetensors --precision "$3" 2>&1)
  echo "$r $1 $(grep '^{' <<<"$out") $(grep '^TIME' <<<"$out")"
}
echo "# $(date -u +%FT%TZ) $(grep -m1 'model name' /proc/cpuinfo) $(uptime)"
for r in $(seq 1 "$ROUNDS"); do
  case $((r % 3)) in
    1) order="start head-f32 head-bf16" ;;
    2) order="head-f32 head-bf16 start" ;;
    0) order="head-bf16 start head-f32" ;;
  esac
  for arm in $order; do
    case $arm in
      start) run start "$WORK/speed-start" f32 ;;
      head-f32) run head-f32 "$WORK/speed-head" f32 ;;
      head-bf16) run head-bf16 "$WORK/speed-head" bf16 ;;
    esac
  done
done
echo "# $(date -u +%FT%TZ) $(uptime)"
