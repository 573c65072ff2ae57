#!/usr/bin/env python3
"""rgm register on chosen pairs, --threads 1 and 2, binaries alternated, per-pair medians.

Usage: python3 tools/speed/pairs_ab.py PAIRS_DIR ROUNDS INDICES BINARY [BINARY ...]
  PAIRS_DIR  a folder `rgm pairs --out` wrote (its pairs.json names the files)
  ROUNDS     runs of every (pair, binary, thread count); the order reverses every other round
  INDICES    pair indices, comma-separated (e.g. 20,40,30)
Prints per pair and binary: median process wall at 1 / 2 threads, their ratio, and the
method's own `time_ms` (from --json). Run it at real-time priority beside other work
(`chrt -f 50 python3 ...`); compare only binaries measured in one run.
"""
import json, os, statistics, subprocess, sys, time

out, rounds, indices, binaries = sys.argv[1], int(sys.argv[2]), sys.argv[3].split(","), sys.argv[4:]
pairs = {p["index"]: p for p in json.load(open(f"{out}/pairs.json"))["pairs"]}
walls, times = {}, {}
for r in range(rounds):
    for i in indices:
        p = pairs[int(i)]
        order = [(b, th) for b in binaries for th in (1, 2)]
        for b, th in order if r % 2 == 0 else order[::-1]:
            t0 = time.perf_counter()
            res = subprocess.run([b, "--threads", str(th), "register", f"{out}/{p['source']}",
                                  f"{out}/{p['target']}", "--json"],
                                 capture_output=True, text=True, check=True)
            walls.setdefault((i, b, th), []).append((time.perf_counter() - t0) * 1e3)
            times.setdefault((i, b, th), []).append(json.loads(res.stdout)["time_ms"])
for i in indices:
    line = f"pair {int(i):04d}:"
    for b in binaries:
        w1, w2 = statistics.median(walls[i, b, 1]), statistics.median(walls[i, b, 2])
        t1, t2 = statistics.median(times[i, b, 1]), statistics.median(times[i, b, 2])
        line += f"  {os.path.basename(b)}: wall {w1:.1f}/{w2:.1f} = {w2 / w1:.3f} (time_ms {t1:.1f}/{t2:.1f})"
    print(line, flush=True)
