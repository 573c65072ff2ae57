"""A Stanford scan folder as the tools read it (`../shared/data/stanford/README.md`): its ASCII
PLY scans, gzip-compressed or not, and the `.conf` poses, p_world = R(q)^T p + t."""
import gzip

import numpy as np


def read_ascii_ply(path):
    """The vertices (x y z, the first three columns) of an ASCII PLY. The header is read line
    by line to `end_header`, so the stray `bye` lines of six dragon scans, which Open3D's own
    reader refuses, do no harm."""
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


def read_folder(folder):
    """(name, points, t_world_scan 4x4) per `bmesh` line of the folder's `.conf` file."""
    conf = next(folder.glob("*.conf"))
    scans = []
    for line in conf.read_text().splitlines():
        tokens = line.split()
        if not tokens or tokens[0] != "bmesh":
            continue
        name = tokens[1]
        pose = np.eye(4)
        pose[:3, :3] = quaternion_rotation(*[float(v) for v in tokens[5:9]]).T
        pose[:3, 3] = [float(v) for v in tokens[2:5]]
        path = folder / name if (folder / name).exists() else folder / (name + ".gz")
        scans.append((name, read_ascii_ply(path), pose))
    return scans
