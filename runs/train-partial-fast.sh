#!/bin/bash
# The first partial model (docs/training/partial-fast). Resumable: run it again to continue
# from the last checkpoint in runs/partial-fast. Runs in the background; console output in
# runs/partial-fast/train.out, process id in runs/partial-fast/train.pid.
set -euo pipefail
cd "$(dirname "$0")/.."
# A frozen copy of the binary, so rebuilding the workspace does not touch the running job.
if [ ! -x runs/rgm-train ]; then
  cargo build --release --bin rgm
  cp target/release/rgm runs/rgm-train
fi
mkdir -p runs/partial-fast
nohup runs/rgm-train train --data "${RGM_DATA:-../shared/data/modelnet40_npy1024}" \
  --out runs/partial-fast --setting partial --preset fast --match-points 384 \
  --optimizer adam --lr 3e-4 --epochs 100 --milestones 60,80 --val-shapes 300 \
  --checkpoint-every 50 --workers 2 --test-statistics cloud >> runs/partial-fast/train.out 2>&1 &
echo $! > runs/partial-fast/train.pid
echo "training in the background, pid $(cat runs/partial-fast/train.pid)"
