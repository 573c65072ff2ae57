#!/usr/bin/env python3
"""The redkitchen rooms made unlike the dev set (docs/baselines.md, "Rooms unlike the dev set"):
each fragment of ../shared/data/scenes/redkitchen written again as binary PLY into OUT/VARIANT/
with the folder's gt.log, for `rgm eval --scenes OUT/VARIANT` and
`tools/scenes/open3d_scenes.py --scenes OUT/VARIANT`. Seeded per fragment:
- quarter: a random quarter of the points (a sparser scanner);
- strays5: 5 % more points, uniform in the fragment's bounding box (spurious returns).

    python3 tools/scenes/stress_rooms.py OUT [--variants quarter strays5]
"""
import argparse
import gzip
import pathlib
import shutil
import tempfile
import zlib

import numpy as np
import open3d as o3d

ROOMS = pathlib.Path(__file__).resolve().parents[2].parent / "shared/data/scenes/redkitchen"


def read(path):
    if path.suffix == ".gz":
        with tempfile.NamedTemporaryFile(suffix=path.stem[path.stem.rfind("."):]) as plain:
            plain.write(gzip.open(path).read())
            plain.flush()
            return np.asarray(o3d.io.read_point_cloud(plain.name).points)
    return np.asarray(o3d.io.read_point_cloud(str(path)).points)


def variant(points, how, rng):
    if how == "quarter":
        return points[rng.permutation(len(points))[: len(points) // 4]]
    low, high = points.min(0), points.max(0)
    strays = rng.uniform(low, high, size=(len(points) // 20, 3))
    both = np.concatenate([points, strays])
    return both[rng.permutation(len(both))]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=pathlib.Path)
    parser.add_argument("--variants", nargs="+", default=["quarter", "strays5"], choices=["quarter", "strays5"])
    args = parser.parse_args()
    fragments = sorted(p for p in ROOMS.iterdir() if p.name.startswith("cloud_bin_"))
    for how in args.variants:
        folder = args.out / how
        folder.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOMS / "gt.log", folder / "gt.log")
        for path in fragments:
            stem = path.name.split(".")[0]
            rng = np.random.default_rng(zlib.crc32(f"{how}/{stem}".encode()))
            moved = variant(read(path), how, rng)
            cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(moved))
            o3d.io.write_point_cloud(str(folder / f"{stem}.ply"), cloud)
        print(f"wrote {len(fragments)} fragments to {folder}")


if __name__ == "__main__":
    main()
