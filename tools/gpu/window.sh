#!/usr/bin/env bash
# One GPU training window (docs/training/gpu.md): trains several runs side by side on the one GPU
# (the fast network leaves most of it idle), each for MINUTES of wall time, each checkpointing
# every minute as two files in $OUT (NAME.tar: config, state, log, weights; NAME.optim.safetensors:
# Adam's moments), so that a window cut short still brings back its last minute's work.
#
#   bash tools/gpu/window.sh MINUTES PACK "NAME|RUN_FOLDER|TRAINER OPTIONS" ...
#
# RUN_FOLDER is resumed when it holds state.json (an rgm run folder, from `rgm train` or from
# an earlier window), else a new run starts there with the options. At most four runs: the
# machine brings back eight files.
set -uo pipefail
minutes=$1 pack=$2
shift 2
OUT=${OUT:-out/gpu-window}
mkdir -p "$OUT"
work=$(mktemp -d)
PY=${PYTHON:-python3}
echo "window: $(date -u +%FT%TZ), ${minutes} min, pack $pack, $# runs"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
"$PY" -c 'import torch; print("torch", torch.__version__, "cuda", torch.cuda.is_available())'
[ $# -le 4 ] || { echo "window: at most 4 runs (8 files come back)"; exit 2; }
pids=()
for spec in "$@"; do
  IFS='|' read -r name folder options <<<"$spec"
  mkdir -p "$work/$name"
  if [ -f "$folder/state.json" ]; then
    cp -r "$folder/." "$work/$name/"
  fi
  # shellcheck disable=SC2086
  PYTHONUNBUFFERED=1 "$PY" tools/gpu/rgm_gpu_train.py train --pack "$pack" --run "$work/$name" \
    --bundle "$OUT/$name" --minutes "$minutes" $options &
  pids+=($!)
done
status=0
for pid in "${pids[@]}"; do
  wait "$pid" || status=1
done
nvidia-smi --query-gpu=memory.used,utilization.gpu --format=csv,noheader || true
ls -l "$OUT"
echo "window: done $(date -u +%FT%TZ), status $status"
exit $status
