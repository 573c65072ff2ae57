#!/usr/bin/env bash
# rgm --threads 1 and 2 on one pair at a time: rgm register on every 10th partial test pair (10 pairs), --threads 1 and 2 alternated, 3 rounds.
# Prints per thread count: the method's time_ms (from --json), the process's wall and CPU (user + sys) ms.
# Run from the repository root; RGM=path picks the binary; PAIRS=DIR takes the pairs from a folder `rgm pairs`
# wrote (its first 10), for a machine without the data. On a loaded machine, `nice -n -10 bash tools/speed/threads_ab.sh`.
set -euo pipefail
RGM=${RGM:-target/release/rgm}
OUT=/tmp/threads-ab
rm -rf $OUT; mkdir -p $OUT
if [ -n "${PAIRS:-}" ]; then
  cp -r "$PAIRS" $OUT/pairs
else
  $RGM pairs --data ../shared/data/modelnet40_npy1024 --setting partial --every 10 --limit 10 --out $OUT/pairs > /dev/null
fi
python3 - "$RGM" "$OUT" <<'PY'
import json, resource, subprocess, sys, time, statistics
rgm, out = sys.argv[1], sys.argv[2]
pairs = json.load(open(f"{out}/pairs/pairs.json"))["pairs"][:10]
rows = {1: [], 2: []}
walls = {1: [], 2: []}
cpus = {1: [], 2: []}
for rnd in range(3):
    for p in pairs:
        for th in ([1, 2] if rnd % 2 == 0 else [2, 1]):
            s, t = f"{out}/pairs/{p['source']}", f"{out}/pairs/{p['target']}"
            u0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            r = subprocess.run([rgm, "--threads", str(th), "register", s, t, "--json"], capture_output=True, text=True, check=True)
            wall = (time.perf_counter() - t0) * 1e3
            u1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus[th].append((u1.ru_utime - u0.ru_utime + u1.ru_stime - u0.ru_stime) * 1e3)
            v = json.loads(r.stdout)
            rows[th].append(v["time_ms"]); walls[th].append(wall)
for th in (1, 2):
    print(f"threads {th}: method time median {statistics.median(rows[th]):.1f} ms, mean {statistics.mean(rows[th]):.1f} ms; process wall median {statistics.median(walls[th]):.1f} ms, CPU median {statistics.median(cpus[th]):.1f} ms (n={len(rows[th])})")
print(f"ratio of means (method time) 2/1: {statistics.mean(rows[2])/statistics.mean(rows[1]):.3f}; of median walls: {statistics.median(walls[2])/statistics.median(walls[1]):.3f}")
PY
