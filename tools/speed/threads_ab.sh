#!/usr/bin/env bash
# rgm --threads 1 and 2 on one pair at a time: rgm register on every 10th partial test pair (10 pairs), --threads 1 and 2 alternated, 3 rounds.
# Prints per binary and thread count: the method's time_ms (from --json), the process's wall and CPU (user + sys) ms.
# Run from the repository root; RGM=path picks the binary, RGM="a b" compares two, alternated pair by pair (the
# first makes the pairs); PAIRS=DIR takes the pairs from a folder `rgm pairs`
# wrote (its first 10), for a machine without the data. On a loaded machine, `nice -n -10 bash tools/speed/threads_ab.sh`.
set -euo pipefail
RGM=${RGM:-target/release/rgm}
FIRST=${RGM%% *}
OUT=/tmp/threads-ab
rm -rf $OUT; mkdir -p $OUT
if [ -n "${PAIRS:-}" ]; then
  cp -r "$PAIRS" $OUT/pairs
else
  $FIRST pairs --data ../shared/data/modelnet40_npy1024 --setting partial --every 10 --limit 10 --out $OUT/pairs > /dev/null
fi
python3 - "$OUT" $RGM <<'PY'
import json, resource, subprocess, sys, time, statistics
out, binaries = sys.argv[1], sys.argv[2:]
pairs = json.load(open(f"{out}/pairs/pairs.json"))["pairs"][:10]
runs = [(b, th) for b in binaries for th in (1, 2)]
rows, walls, cpus = ({k: [] for k in runs} for _ in range(3))
for rnd in range(3):
    for p in pairs:
        for b, th in (runs if rnd % 2 == 0 else runs[::-1]):
            s, t = f"{out}/pairs/{p['source']}", f"{out}/pairs/{p['target']}"
            u0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            r = subprocess.run([b, "--threads", str(th), "register", s, t, "--json"], capture_output=True, text=True, check=True)
            wall = (time.perf_counter() - t0) * 1e3
            u1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus[b, th].append((u1.ru_utime - u0.ru_utime + u1.ru_stime - u0.ru_stime) * 1e3)
            v = json.loads(r.stdout)
            rows[b, th].append(v["time_ms"]); walls[b, th].append(wall)
for b in binaries:
    for th in (1, 2):
        k = (b, th)
        print(f"{b} threads {th}: method time median {statistics.median(rows[k]):.1f} ms, mean {statistics.mean(rows[k]):.1f} ms; process wall median {statistics.median(walls[k]):.1f} ms, CPU median {statistics.median(cpus[k]):.1f} ms (n={len(rows[k])})")
    print(f"{b}: ratio of means (method time) 2/1: {statistics.mean(rows[b, 2])/statistics.mean(rows[b, 1]):.3f}; of median walls: {statistics.median(walls[b, 2])/statistics.median(walls[b, 1]):.3f}")
PY
