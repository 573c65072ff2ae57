#!/usr/bin/env bash
# ICP and FGR of rgm and of Open3D on the same ModelNet40 test pairs, scored by the same code.
# Usage: bash tools/open3d/compare.sh [SETTING] [LIMIT] [DATA]   (defaults: partial, all, ../shared/data/modelnet40_npy1024)
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
$rgm pairs --setting "$setting" "${lim[@]}" --out "$out/pairs" --data "$data"
for method in icp fgr; do
  OMP_NUM_THREADS=1 python3 tools/open3d/register_pairs.py "$out/pairs" --method $method --out "$out/open3d_$method.json"
done
for method in icp fgr; do
  $rgm eval --method $method --setting "$setting" "${lim[@]}" --data "$data" --json "$out/rgm_$method.json"
  $rgm score "$out/open3d_$method.json" --pairs "$out/pairs" --json "$out/open3d_${method}_scored.json"
done
