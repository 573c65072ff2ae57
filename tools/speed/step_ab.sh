#!/usr/bin/env bash
# Issue 24's same-run A/B of one training step (`fast`, 384 points, forward + BCE + backward, the
# built-in weights, one core): the `speed` example built at the issue's start (8daedb6, OpenBLAS
# products) against the working tree's, f32 and bf16, and optionally a third commit's in bf16,
# round-robin with the order rotated each round. Prints one line per process: round, arm, the
# example's JSON, then "TIME user sys wall".
#
#   bash tools/speed/step_ab.sh [ROUNDS] [START_COMMIT] [OTHER_COMMIT]     (10, 8daedb6, none)
#
# Builds the start (and the other commit) in temporary worktrees sharing one target folder
# (minutes, one job) and removes them afterwards. On a loaded machine the user times are the
# steadier figure.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROUNDS=${1:-10}
START=${2:-8daedb6}
OTHER=${3:-}
WORK=$(mktemp -d)
trap 'for w in start other; do git worktree remove --force "$WORK/$w" 2>/dev/null || true; done; rm -rf "$WORK"' EXIT
build_at() { # name commit
  git worktree add -q "$WORK/$1" "$2"
  (cd "$WORK/$1" && CARGO_TARGET_DIR="$WORK/target" nice cargo build -q --release -p rgm-benches --example speed -j 1)
  cp "$WORK/target/release/examples/speed" "$WORK/speed-$1"
}
build_at start "$START"
[ -z "$OTHER" ] || build_at other "$OTHER"
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
arms=(start head-f32 head-bf16)
[ -z "$OTHER" ] || arms+=(other-bf16)
for r in $(seq 1 "$ROUNDS"); do
  for i in "${!arms[@]}"; do
    arm=${arms[$(((i + r) % ${#arms[@]}))]}
    case $arm in
      start) run start "$WORK/speed-start" f32 ;;
      head-f32) run head-f32 "$WORK/speed-head" f32 ;;
      head-bf16) run head-bf16 "$WORK/speed-head" bf16 ;;
      other-bf16) run other-bf16 "$WORK/speed-other" bf16 ;;
    esac
  done
done
echo "# $(date -u +%FT%TZ) $(uptime)"
