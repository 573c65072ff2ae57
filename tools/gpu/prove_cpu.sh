#!/usr/bin/env bash
# The GPU trainer's proofs on the CPU (issue 41), before any GPU window spends its minutes on it.
# Needs PyTorch (any recent version; PYTHON names the interpreter) and the data; CI runs only the
# step proof (crates/rgm-model/tests/gpu_trainer_step.rs), which needs neither.
#
#   PYTHON=/path/to/python-with-torch bash tools/gpu/prove_cpu.sh
#
# 1. pairs: the trainer's pairs against rgm-data's, statistic by statistic (2,000 training pairs
#    per setting, cut to 384 points as `rgm train` cuts them);
# 2. one step: the trainer's batched step against `rgm train`'s, loss and every gradient;
# 3. checkpoints: a run the trainer started is resumed by `rgm train`, the one `rgm train` wrote
#    is resumed by the trainer, its weights are read by `rgm register --weights`, and the trainer
#    resumes the committed snapshot of runs/partial-fast-717 (bf16 weights, Log8 Adam moments).
# PROOFS="3" (or "1 3", ...) runs only those.
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PYTHON:-python3}
DATA=${RGM_DATA:-../shared/data/modelnet40_npy1024}
PACK=${PACK:-target/modelnet40-train.pack.safetensors}
TRAINER="$PY tools/gpu/rgm_gpu_train.py"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cargo build -q --release --bin rgm
RGM=target/release/rgm
[ -f "$PACK" ] || cargo xtask pack-modelnet --data "$DATA" --out "$PACK"

PROOFS=${PROOFS:-1 2 3}
if [[ " $PROOFS " == *" 1 "* ]]; then
echo "== 1. pairs"
$TRAINER check-rebuild
for setting in partial noise clean; do
  cargo run -q --release -p rgm-data --example pair_stats -- "$DATA" "$setting" 2000 384 >"$work/rgm-$setting.json"
  echo "-- $setting"
  $TRAINER pair-stats --pack "$PACK" --setting "$setting" --pairs 2000 --match-points 384 \
    --compare "$work/rgm-$setting.json" | tail -n +2
done

fi

if [[ " $PROOFS " == *" 2 "* ]]; then
echo "== 2. one step"
cargo test -q --release -p rgm-model --test gpu_trainer_step
fi

if [[ " $PROOFS " == *" 3 "* ]]; then
echo "== 3. checkpoints"
# The options of one run, as both trainers take them (tiny network, 8 shapes: seconds a step).
run="$work/run"
common=(--preset tiny --train-shapes 8 --val-shapes 4 --batch 4 --epochs 8 --milestones 6 --lr 3e-4)
epoch() { $PY -c 'import json, sys; s = json.load(open(sys.argv[1])); print(s["epoch"], s["batch"], s["steps"])' "$run/state.json"; }
$TRAINER train --pack "$PACK" --run "$run" --device cpu --minutes 0.05 "${common[@]}"
echo "trainer wrote: epoch, batch, steps = $(epoch)"
read -r e _ steps <<<"$(epoch)"
$RGM train --data "$DATA" --out "$run" "${common[@]}" --optimizer adam --match-points 384 \
  --val-sample spread --test-statistics cloud --workers 2 --until-epoch $((e + 1)) 2>&1 | tail -n 2
read -r e2 b2 steps2 <<<"$(epoch)"
echo "rgm train resumed it: epoch, batch, steps = $e2 $b2 $steps2"
[ "$steps2" -gt "$steps" ] || { echo "FAIL: rgm train did not go on from the trainer's checkpoint"; exit 1; }
grep -q '"kind":"validation"' "$run/log.jsonl" || { echo "FAIL: no validation record from rgm train"; exit 1; }
$TRAINER train --pack "$PACK" --run "$run" --device cpu --minutes 0.05
read -r _ _ steps3 <<<"$(epoch)"
[ "$steps3" -gt "$steps2" ] || { echo "FAIL: the trainer did not go on from rgm train's checkpoint"; exit 1; }
echo "the trainer resumed rgm train's checkpoint: steps $steps2 → $steps3"
$RGM pairs --setting partial --limit 1 --out "$work/pairs" --data "$DATA" >/dev/null
src=$(find "$work/pairs" -name '*source*.ply' | head -1)
tgt=$(find "$work/pairs" -name '*target*.ply' | head -1)
# The tiny run registers nothing yet: a fast one, one step from the built-in model, does.
$TRAINER train --pack "$PACK" --run "$work/fast" --device cpu --minutes 0.01 --preset fast --match-points 0 \
  --init crates/rgm-model/weights/partial-fast.safetensors
$RGM register "$src" "$tgt" --method rgm --weights "$work/fast/last.safetensors" --preset fast \
  --test-statistics cloud --json >"$work/register.json"
echo "rgm register --weights read the trainer's weights: $(head -c 160 "$work/register.json" | tr -d '\n')…"
snap="$work/snapshot"
mkdir -p "$snap"
for f in config.json state.json log.jsonl last.safetensors last.optim.safetensors; do
  git show "HEAD:runs/partial-fast-717/$f" >"$snap/$f"
done
$TRAINER train --pack "$PACK" --run "$snap" --device cpu --minutes 0.02
echo "the trainer resumed the committed snapshot of runs/partial-fast-717 (bf16 weights, Log8 moments)"
fi
echo "== proofs $PROOFS passed"
