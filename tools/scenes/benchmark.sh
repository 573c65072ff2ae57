#!/bin/bash
# The scene benchmark (issue 42): `rgm eval --scenes` on ../shared/data/scenes.
#
#   bash tools/scenes/benchmark.sh [RGM_BINARY] [-- extra rgm eval options]
#
# redkitchen: the 12 pairs of its gt.log (3DMatch) as published. lidar: the one LiDAR pair, its
# source turned by known rotations up to 180° (about the vertical and about (1, 1, 1)); the pair
# has no gt.log, so one is written from relative.txt (target ← source) into a scratch folder
# beside links to the two sweeps. The method: `rgm eval --scenes`'s default, `rgm register`'s
# (auto, refined); one thread, one pair at a time; per-pair JSON in target/scenes/.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
data="$root/../shared/data/scenes"
rgm="$root/target/release/rgm"
if [[ $# -gt 0 && "$1" != "--" ]]; then rgm="$1"; shift; fi
[[ "${1:-}" == "--" ]] && shift
out="$root/target/scenes"
mkdir -p "$out/lidar"
ln -sf "$data/lidar/251370668.pcd" "$data/lidar/251371071.pcd" "$out/lidar/"
# gt.log: `i j n` (target i, source j), then the 4×4 matrix mapping j onto i.
{ echo "251370668 251371071 2"; cat "$data/lidar/relative.txt"; } > "$out/lidar/gt.log"
common=(--threads 1 --workers 1)
echo "# $(date -u +%FT%TZ), $(lscpu | sed -n 's/^Model name: *//p'), $("$rgm" --version)"
"$rgm" eval --scenes "$data/redkitchen" "${common[@]}" --json "$out/redkitchen.json" "$@"
"$rgm" eval --scenes "$out/lidar" --turns 0 45 90 135 180 90@1,1,1 180@1,1,1 "${common[@]}" \
  --json "$out/lidar.json" "$@"
