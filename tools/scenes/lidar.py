#!/usr/bin/env python3
"""rgm register on the LiDAR pair of ../shared/data/scenes/lidar, its source first turned by known
rotations (about the vertical and about a tilted axis, up to 180°), scored against relative.txt
composed with each turn (rotation error, translation error; success: < 15° and < 0.3 m):

    /work/o3dvenv/bin/python tools/scenes/lidar.py [RGM_BINARY] [-- extra rgm register options]

Needs NumPy (the PCD files are read here and the turned sources written as .npy to a
temporary folder).
"""
import json
import math
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

root = pathlib.Path(__file__).resolve().parents[2]
data = root.parent / "shared/data/scenes/lidar"
args = sys.argv[1:]
extra = args[args.index("--") + 1:] if "--" in args else []
args = args[: args.index("--")] if "--" in args else args
rgm = args[0] if args else str(root / "target/release/rgm")


def read_pcd(path):
    raw = path.read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = dict(line.split(" ", 1) for line in raw[:end].decode().splitlines() if not line.startswith("#"))
    fields = header["FIELDS"].split()
    points = np.frombuffer(raw[end:], dtype="<f4").reshape(-1, len(fields))
    return points[:, :3].astype(np.float64)


def turn(axis, degrees):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = math.radians(degrees)
    return np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k


source = read_pcd(data / "251371071.pcd")
relative = np.loadtxt(data / "relative.txt")
turns = [((0, 0, 1), d) for d in (0, 45, 90, 135, 180)] + [((1, 1, 1), d) for d in (90, 180)]
ok, rot, tra, times = 0, [], [], []
with tempfile.TemporaryDirectory() as tmp:
    for axis, degrees in turns:
        R = turn(axis, degrees)
        path = pathlib.Path(tmp) / "source.npy"
        np.save(path, source @ R.T)
        # The turned source x' = R x: the target ← turned-source transform is relative · R⁻¹.
        truth = relative.copy()
        truth[:3, :3] = relative[:3, :3] @ R.T
        start = time.perf_counter()
        out = subprocess.run([rgm, "register", str(path), str(data / "251370668.pcd"), "--json", *extra],
                             capture_output=True, text=True)
        wall = time.perf_counter() - start
        if out.returncode != 0:
            print(f"{axis} {degrees}°: rgm failed ({out.returncode}): {out.stderr.strip()[:200]}")
            continue
        d = json.loads(out.stdout)
        M = np.array(d["transform"])
        re = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(truth[:3, :3].T @ M[:3, :3]) - 1) / 2))))
        te = float(np.linalg.norm(M[:3, 3] - truth[:3, 3]))
        good = re < 15 and te < 0.3
        ok += good
        rot.append(re)
        tra.append(te)
        times.append(wall)
        print(f"turned {degrees:>3}° about {axis}: {'ok  ' if good else 'FAIL'} {re:7.2f}° {te:6.3f} m  "
              f"{wall:6.2f} s  {d['method']} chosen={d.get('chosen')}")
print(f"{ok}/{len(turns)} within 15° and 0.3 m; median {np.median(rot):.2f}° {np.median(tra):.3f} m; "
      f"mean time {np.mean(times):.2f} s (wall, file reading included)")
