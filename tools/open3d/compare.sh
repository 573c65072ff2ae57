#!/usr/bin/env bash
# ICP and FGR of rgm and of Open3D on the same ModelNet40 test pairs, scored by the same code.
# Usage: bash tools/open3d/compare.sh [SETTING] [LIMIT] [DATA]   (defaults: partial, all, ../shared/data/modelnet40_npy1024)
# SETTING: clean, noise, partial or partial-unseen (partial-to-partial on the unseen categories).
# Open3D's complete pipelines as well (FGR + ICP, RANSAC + ICP; Open3D only, there is no rgm method
# of the same name to run beside them): PIPELINES="fgr_icp ransac_icp" bash tools/open3d/compare.sh partial
# Needs: pip install open3d-cpu==0.20.0 (and apt-get install libusb-1.0-0). Writes target/compare-SETTING/.
set -euo pipefail
cd "$(dirname "$0")/../.."
setting=${1:-partial}
limit=${2:-}
data=${3:-../shared/data/modelnet40_npy1024}
out=target/compare-$setting
mkdir -p "$out"
cargo build --release --bin rgm
rgm=target/release/rgm
lim=()
[ -n "$limit" ] && lim=(--limit "$limit")
protocol=(--setting "$setting")
[ "$setting" = partial-unseen ] && protocol=(--setting partial --unseen)
$rgm pairs "${protocol[@]}" "${lim[@]}" --out "$out/pairs" --data "$data"
for method in icp fgr ${PIPELINES:-}; do
  OMP_NUM_THREADS=1 python3 tools/open3d/register_pairs.py "$out/pairs" --method $method --out "$out/open3d_$method.json"
done
for method in icp fgr; do
  $rgm eval --method $method "${protocol[@]}" "${lim[@]}" --data "$data" --json "$out/rgm_$method.json"
done
for method in icp fgr ${PIPELINES:-}; do
  $rgm score "$out/open3d_$method.json" --pairs "$out/pairs" --json "$out/open3d_${method}_scored.json"
done
