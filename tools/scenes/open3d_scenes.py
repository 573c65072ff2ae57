#!/usr/bin/env python3
"""Open3D's FPFH + RANSAC + ICP tutorial pipeline on the pairs of a scene folder in the 3DMatch
layout (gt.log; fragment k the file cloud_bin_k.* or k.*; default the redkitchen pairs of
../shared/data/scenes), scored as `rgm eval --scenes` scores rgm (rotation error < 15°,
translation error < 0.3 m), one thread (OMP_NUM_THREADS=1):

    /work/o3dvenv/bin/python tools/scenes/open3d_scenes.py [--voxel 0.05] [--scenes DIR]

The pipeline (as tools/baselines/open3d_scans.py, with a fixed voxel v = 5 cm): each cloud
voxel-downsampled at v; normals over radius 2v (max 30); FPFH over radius 5v (max 100); RANSAC on
the features (mutual filter off, inliers within 1.5v, edge-length check 0.9 and distance check,
100,000 iterations, confidence 0.999); point-to-plane ICP on the full clouds at 0.4v (target
normals over radius 2v, max 30), or with --icp-on-downsampled on the downsampled clouds. The
time is the wall time of all that, the clouds read before.
"""
import argparse
import gzip
import math
import os
import pathlib
import statistics
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402

root = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(root / "tools/baselines"))
from open3d_scans import ransac_icp  # noqa: E402
data = root.parent / "shared/data/scenes/redkitchen"


def read(k):
    for name in (f"{prefix}{k}.{ext}" for prefix in ("cloud_bin_", "") for ext in ("ply.gz", "pcd", "ply")):
        path = data / name
        if not path.exists():
            continue
        if name.endswith(".gz"):
            with tempfile.NamedTemporaryFile(suffix=".ply") as f:
                f.write(gzip.open(path).read())
                f.flush()
                return o3d.io.read_point_cloud(f.name)
        return o3d.io.read_point_cloud(str(path))
    raise SystemExit(f"no fragment {k} in {data}")


def register(src, tgt, voxel, downsampled):
    return np.asarray(ransac_icp(src, tgt, voxel, [0.4 * voxel], downsampled))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--voxel", type=float, default=0.05, help="voxel in metres (default 0.05)")
    parser.add_argument("--scenes", type=pathlib.Path, help="the scene folder (default redkitchen)")
    parser.add_argument("--icp-on-downsampled", action="store_true",
                        help="ICP on the downsampled clouds (open3d_scans.py's cheaper recipe)")
    args = parser.parse_args()
    global data
    data = args.scenes or data
    o3d.utility.random.seed(0)
    lines = [l for l in (data / "gt.log").read_text().split("\n") if l.strip()]
    ok, rot, tra, times = 0, [], [], []
    for b in range(0, len(lines) - 4, 5):
        head = lines[b].split()
        if len(head) != 3:
            continue
        i, j = int(head[0]), int(head[1])
        T = np.array([[float(v) for v in lines[b + r].split()] for r in range(1, 5)])
        src, tgt = read(j), read(i)
        start = time.perf_counter()
        M = register(src, tgt, args.voxel, args.icp_on_downsampled)
        wall = time.perf_counter() - start
        re = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(T[:3, :3].T @ M[:3, :3]) - 1) / 2))))
        te = float(np.linalg.norm(M[:3, 3] - T[:3, 3]))
        good = re < 15 and te < 0.3
        ok += good
        rot.append(re)
        tra.append(te)
        times.append(wall)
        print(f"{j:>2} -> {i:>2}: {'ok  ' if good else 'FAIL'} {re:7.2f}° {te:6.3f} m  {wall:6.2f} s  open3d")
    print(f"{ok}/{len(rot)} within 15° and 0.3 m; median {statistics.median(rot):.2f}° "
          f"{statistics.median(tra):.3f} m; mean time {statistics.mean(times):.2f} s (wall, file reading not included)")


if __name__ == "__main__":
    main()
