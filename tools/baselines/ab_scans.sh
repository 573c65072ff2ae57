#!/usr/bin/env bash
# Two builds of rgm on the 42 Stanford pairs, one thread each, pinned to one core, ROUNDS rounds
# (default 2) alternating: each folder's mean of per-pair minimum times, the median rotation
# errors, and how many transforms are identical (an exact change keeps all 42). Pauses the
# training queue while it runs (docs/baselines.md, issue 57).
#   [ROUNDS=5] bash tools/baselines/ab_scans.sh BEFORE_RGM AFTER_RGM [OUT]
set -euo pipefail
cd "$(dirname "$0")/../.."
before=$1 after=$2 out=${3:-/tmp/rgm-ab-scans} rounds=${ROUNDS:-2} core=${CORE:-1}
export OPENBLAS_NUM_THREADS=1 RAYON_NUM_THREADS=1
mkdir -p "$out"
queue=$(pgrep -f '^runs/rgm-train train' || true)
[ -n "$queue" ] && kill -STOP $queue
trap '[ -n "$queue" ] && kill -CONT $queue' EXIT
echo "# $(date -u +%FT%TZ) $(lscpu | sed -n 's/^Model name: *//p')"
for round in $(seq "$rounds"); do
  for build in before after; do
    taskset -c "$core" "${!build}" eval --scans ../shared/data/stanford/bunny \
      ../shared/data/stanford/dragon_stand --method auto --refine --workers 1 --threads 1 \
      --json "$out/$build-$round.json" >/dev/null 2>&1
  done
done
python3 - "$out" "$rounds" <<'PY'
import json, statistics, sys
out, rounds = sys.argv[1], range(1, int(sys.argv[2]) + 1)
runs = {b: [json.load(open(f"{out}/{b}-{r}.json"))["folders"] for r in rounds] for b in ("before", "after")}
same = total = 0
for f, folder in enumerate(runs["before"][0]):
    mean = {}
    for b in runs:
        pairs = [run[f]["pairs"] for run in runs[b]]
        mean[b] = statistics.mean(min(p[i]["time_ms"] for p in pairs) for i in range(len(pairs[0])))
    errors = {b: statistics.median(p["rotation_error_deg"] for p in runs[b][0][f]["pairs"]) for b in runs}
    for x, y in zip(folder["pairs"], runs["after"][0][f]["pairs"]):
        total += 1
        same += x["transform"] == y["transform"]
    print(f"{folder['scans']}: before {mean['before']:.1f} ms, after {mean['after']:.1f} ms "
          f"({mean['after'] / mean['before']:.3f}); median rotation error {errors['before']:.4f}° → {errors['after']:.4f}°")
print(f"identical transforms: {same} of {total}")
PY
