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
import gzip
import pathlib
import sys

import numpy as np


def read_ascii_ply(path):
    with gzip.open(path, "rt") if path.suffix == ".gz" else open(path) as f:
        count = None
        for line in f:
            words = line.split()
            if words[:2] == ["element", "vertex"]:
                count = int(words[2])
            if words and words[0] == "end_header":
                break
        rows = [f.readline().split()[:3] for _ in range(count)]
    return np.array(rows, dtype=np.float64)


def quaternion_rotation(x, y, z, w):
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def main():
    folder, n, out = pathlib.Path(sys.argv[1]), int(sys.argv[2]), pathlib.Path(sys.argv[3])
    conf = next(folder.glob("*.conf"))
    merged = []
    for line in conf.read_text().splitlines():
        words = line.split()
        if not words or words[0] != "bmesh":
            continue
        path = folder / words[1]
        if not path.exists():
            path = folder / (words[1] + ".gz")
        t = np.array([float(v) for v in words[2:5]])
        r = quaternion_rotation(*[float(v) for v in words[5:9]])
        merged.append(read_ascii_ply(path) @ r + t)  # (R^T p^T)^T = p R
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
