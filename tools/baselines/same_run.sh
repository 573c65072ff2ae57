#!/usr/bin/env bash
# Two builds of rgm and Open3D 0.20 in one run, one thread each, pinned to one core: the Stanford
# pairs (ROUNDS rounds, default two, each method alternating), the redkitchen and LiDAR pairs of
# tools/scenes/benchmark.sh, and Open3D's scene pipeline (docs/baselines.md, issue 57).
#   [ROUNDS=2] bash tools/baselines/same_run.sh BEFORE_RGM AFTER_RGM [OUT]
# Stop other jobs first (the training queue: kill -STOP its pids; kill -CONT after). Needs
# open3d==0.20.0 (and libusb-1.0-0). The summary's "per-pair min" is each pair's faster of the
# ROUNDS rounds, averaged: a shared machine's stalls fall out of it.
set -euo pipefail
cd "$(dirname "$0")/../.."
before=$1 after=$2 out=${3:-/tmp/rgm-same-run}
core=${CORE:-1} rounds=${ROUNDS:-2}
export OPENBLAS_NUM_THREADS=1 RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1
folders=(../shared/data/stanford/bunny ../shared/data/stanford/dragon_stand)
mkdir -p "$out"
echo "# $(date -u +%FT%TZ) $(lscpu | sed -n 's/^Model name: *//p')"
"$after" pairs --scans "${folders[@]}" --out "$out/pairs" >/dev/null 2>&1
for round in $(seq "$rounds"); do
  for build in before after; do
    rgm=${!build}
    taskset -c "$core" "$rgm" eval --scans "${folders[@]}" --method auto --refine --workers 1 \
      --threads 1 --json "$out/scans-$build-$round.json" 2>/dev/null | grep "^| auto" |
      grep -v " all " | sed "s/^/$build, round $round: /"
  done
  for dir in "${folders[@]}"; do
    name=$(basename "$dir")
    taskset -c "$core" python3 tools/baselines/open3d_scans.py "$out/pairs/$name" \
      --out "$out/open3d-$name-$round.json" >/dev/null 2>&1
    "$after" score "$out/open3d-$name-$round.json" --pairs "$out/pairs/$name" 2>/dev/null |
      tail -n 1 | sed "s/^/open3d, round $round: /"
  done
done
for build in before after; do
  taskset -c "$core" bash tools/scenes/benchmark.sh "${!build}" 2>/dev/null | grep "^| auto" |
    sed "s/^/$build: /"
done
taskset -c "$core" python3 tools/scenes/open3d_scenes.py 2>/dev/null | tail -n 1 |
  sed "s/^/open3d redkitchen: /"
taskset -c "$core" python3 tools/scenes/open3d_scenes.py --scenes target/scenes/lidar 2>/dev/null |
  tail -n 1 | sed "s/^/open3d lidar: /"
python3 - "$out" "$rounds" <<'EOF'
import json, statistics, sys
out, rounds = sys.argv[1], range(1, int(sys.argv[2]) + 1)
times = {}
for build in ("before", "after"):
    for r in rounds:
        for folder in json.load(open(f"{out}/scans-{build}-{r}.json"))["folders"]:
            for p in folder["pairs"]:
                times.setdefault((build, folder["scans"]), {}).setdefault(p["index"], []).append(p["time_ms"])
for name in ("bunny", "dragon_stand"):
    for r in rounds:
        for i, p in enumerate(json.load(open(f"{out}/open3d-{name}-{r}.json"))["pairs"]):
            times.setdefault(("open3d", name), {}).setdefault(i, []).append(p["time_ms"])
for name in ("bunny", "dragon_stand"):
    mean = {m: statistics.mean(min(v) for v in times[(m, name)].values()) for m in ("before", "after", "open3d")}
    print(f"{name}: per-pair min, before {mean['before']:.1f} ms ({mean['before'] / mean['open3d']:.2f}x Open3D), "
          f"after {mean['after']:.1f} ms ({mean['after'] / mean['open3d']:.2f}x), Open3D {mean['open3d']:.1f} ms")
EOF
echo "# $(date -u +%FT%TZ) done"
