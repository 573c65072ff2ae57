#!/usr/bin/env python3
"""rgm register on the redkitchen pairs of ../shared/data/scenes (3DMatch gt.log), scored by the
3DMatch criterion (rotation error < 15°, translation error < 0.3 m), with median errors and time.

    python3 tools/scenes/redkitchen.py [RGM_BINARY] [-- extra rgm register options]

gt.log gives T with p_i = T p_j: fragment j is the source, i the target. A fragment stored as
.pcd (cloud_bin_7) is read as it is. Python standard library only.
"""
import json
import math
import pathlib
import statistics
import subprocess
import sys
import time

root = pathlib.Path(__file__).resolve().parents[2]
data = root.parent / "shared/data/scenes/redkitchen"
args = sys.argv[1:]
extra = args[args.index("--") + 1:] if "--" in args else []
args = args[: args.index("--")] if "--" in args else args
rgm = args[0] if args else str(root / "target/release/rgm")


def fragment(k):
    for name in (f"cloud_bin_{k}.ply.gz", f"cloud_bin_{k}.pcd"):
        if (data / name).exists():
            return data / name
    raise SystemExit(f"no fragment {k} in {data}")


lines = (data / "gt.log").read_text().split("\n")
pairs = []
for b in range(0, len(lines) - 4, 5):
    head = lines[b].split()
    if len(head) != 3:
        continue
    i, j = int(head[0]), int(head[1])
    T = [[float(v) for v in lines[b + r].split()] for r in range(1, 5)]
    pairs.append((i, j, T))

ok, rot, tra, times = 0, [], [], []
for i, j, T in pairs:
    start = time.perf_counter()
    out = subprocess.run([rgm, "register", str(fragment(j)), str(fragment(i)), "--json", *extra],
                         capture_output=True, text=True)
    wall = time.perf_counter() - start
    if out.returncode != 0:
        print(f"{j}->{i}: rgm failed ({out.returncode}): {out.stderr.strip()[:200]}")
        continue
    d = json.loads(out.stdout)
    M = d["transform"]
    # Rotation error: the angle of R_gt^T R; translation error: |t - t_gt|.
    trace = sum(sum(T[k][r] * M[k][r] for k in range(3)) for r in range(3))
    re = math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1) / 2))))
    te = math.dist([M[r][3] for r in range(3)], [T[r][3] for r in range(3)])
    good = re < 15 and te < 0.3
    ok += good
    rot.append(re)
    tra.append(te)
    times.append(wall)
    print(f"{j:>2} -> {i:>2}: {'ok  ' if good else 'FAIL'} {re:7.2f}° {te:6.3f} m  {wall:6.2f} s  "
          f"{d['method']} registered={d['registered']} chosen={d.get('chosen')}")
print(f"{ok}/{len(pairs)} within 15° and 0.3 m; median {statistics.median(rot):.2f}° "
      f"{statistics.median(tra):.3f} m; mean time {statistics.mean(times):.2f} s (wall, file reading included)")
