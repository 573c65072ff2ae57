#!/usr/bin/env bash
# rgm register's default and Open3D RANSAC + ICP on the same real scan pairs, one thread each, one
# after the other on the same machine (docs/baselines.md, "Real scans").
#   bash tools/baselines/scans.sh [OUT] [SCAN FOLDERS...]
# Needs target/release/rgm (cargo build --release) and open3d 0.20 (pip install open3d==0.20.0).
set -euo pipefail
out=${1:-/tmp/rgm-scans}
shift || true
folders=("$@")
[ ${#folders[@]} -gt 0 ] || folders=(../shared/data/stanford/bunny ../shared/data/stanford/dragon_stand)
export OPENBLAS_NUM_THREADS=1 RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1
rgm=target/release/rgm
mkdir -p "$out"
"$rgm" pairs --scans "${folders[@]}" --out "$out/pairs" 2>/dev/null
"$rgm" eval --scans "${folders[@]}" --method auto --refine --workers 1 --json "$out/rgm.json" 2>/dev/null
for dir in "${folders[@]}"; do
  name=$(basename "$dir")
  for stages in "" "--second-stage"; do
    python3 tools/baselines/open3d_scans.py "$out/pairs/$name" $stages --out "$out/open3d$stages-$name.json" >/dev/null
    "$rgm" score "$out/open3d$stages-$name.json" --pairs "$out/pairs/$name" | tail -n 1
  done
done
