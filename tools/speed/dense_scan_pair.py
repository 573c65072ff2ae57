#!/usr/bin/env python3
"""A registration pair of N-point real-scan clouds, for measuring rgm's cost on dense clouds.

Usage:
    python3 tools/speed/dense_scan_pair.py ../shared/data/stanford/bunny 200000 /tmp/dense
    rgm register /tmp/dense/source.npy /tmp/dense/target.npy

Every scan of the folder is read (gzip-compressed ASCII PLY, x y z first), moved into the common
frame by its `.conf` pose (p_world = R(q)^T p + t) and merged; the target is N points drawn from the
merged cloud at random, the source another N points drawn independently, turned by 30 degrees
about (1, 1, 0) and shifted by 0.02 (the object's units). Seeded: the same command writes the same
files. The ground truth is written as truth.txt (4x4 t_target_source).
"""
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from stanford import read_folder  # noqa: E402


def main():
    folder, n, out = pathlib.Path(sys.argv[1]), int(sys.argv[2]), pathlib.Path(sys.argv[3])
    # p_world = R^T p + t, row by row: p R + t.
    merged = [points @ pose[:3, :3].T + pose[:3, 3] for _, points, pose in read_folder(folder)]
    cloud = np.concatenate(merged)
    rng = np.random.default_rng(0)
    target = cloud[rng.choice(len(cloud), n, replace=len(cloud) < n)]
    source = cloud[rng.choice(len(cloud), n, replace=len(cloud) < n)]
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    angle = np.radians(30.0)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    g = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k  # the motion of the source
    shift = np.array([0.02, 0.0, 0.0])
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "target.npy", target)
    np.save(out / "source.npy", source @ g.T + shift)
    truth = np.eye(4)
    truth[:3, :3] = g.T
    truth[:3, 3] = -g.T @ shift
    np.savetxt(out / "truth.txt", truth)
    print(f"{len(cloud)} points merged; wrote {n}-point source and target to {out}")


if __name__ == "__main__":
    main()
