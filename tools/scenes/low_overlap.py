#!/usr/bin/env python3
"""Low-overlap scene pairs made from a scene folder's pairs (3DMatch layout, default the redkitchen
pairs of ../shared/data/scenes), as a check of how the scene stage generalises (issue 42; the
3DLoMatch benchmark's pairs overlap 10-30 %): each source is cut by a plane, keeping its side away
from the target, until SHARE of the points kept lie within 5 cm of the target under the truth.
Writes a folder in the same layout (the targets linked, the cut sources as cloud_bin_{100+k}.ply,
the gt.log), to be scored by `rgm eval --scenes` and tools/scenes/open3d_scenes.py:

    /work/o3dvenv/bin/python tools/scenes/low_overlap.py OUT [--share 0.2] [--scenes DIR]

A source that already overlaps no more than SHARE is kept whole. Needs NumPy and Open3D.
"""
import argparse
import gzip
import pathlib
import tempfile

import numpy as np
import open3d as o3d

root = pathlib.Path(__file__).resolve().parents[2]


def fragment(folder, k):
    for name in (f"{p}{k}.{e}" for p in ("cloud_bin_", "") for e in ("ply.gz", "pcd", "ply")):
        if (folder / name).exists():
            return folder / name
    raise SystemExit(f"no fragment {k} in {folder}")


def read(path):
    if path.name.endswith(".gz"):
        with tempfile.NamedTemporaryFile(suffix=".ply") as f:
            f.write(gzip.open(path).read())
            f.flush()
            return o3d.io.read_point_cloud(f.name)
    return o3d.io.read_point_cloud(str(path))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=pathlib.Path)
    parser.add_argument("--share", type=float, default=0.2)
    parser.add_argument("--scenes", type=pathlib.Path, default=root.parent / "shared/data/scenes/redkitchen")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    lines = [l for l in (args.scenes / "gt.log").read_text().split("\n") if l.strip()]
    log = []
    for k, b in enumerate(range(0, len(lines), 5)):
        i, j, n = lines[b].split()
        T = np.array([[float(v) for v in lines[b + r].split()] for r in range(1, 5)])
        target_path = fragment(args.scenes, i)
        link = args.out / target_path.name
        if not link.exists():
            link.symlink_to(target_path.resolve())
        source = read(fragment(args.scenes, j))
        target = read(target_path)
        moved = o3d.geometry.PointCloud(source).transform(T)
        near = np.asarray(moved.compute_point_cloud_distance(target)) < 0.05
        points = np.asarray(moved.points)
        keep = np.ones(len(points), bool)
        if near.mean() > args.share:
            # Away from the overlap: keep the points furthest along u, the fewest cut that
            # leaves the share of overlapping points at SHARE.
            u = points[~near].mean(0) - points[near].mean(0)
            u /= np.linalg.norm(u)
            along = points @ u
            lo, hi = along.min(), along.max()
            for _ in range(50):
                mid = (lo + hi) / 2
                kept = along >= mid
                if kept.sum() == 0 or near[kept].mean() < args.share:
                    hi = mid
                else:
                    lo = mid
            keep = along >= lo
        cut = source.select_by_index(np.flatnonzero(keep))
        number = 100 + k
        o3d.io.write_point_cloud(str(args.out / f"cloud_bin_{number}.ply"), cut)
        print(f"{j:>3} -> {i:>3}: {near.mean():.2f} overlapping, kept {keep.sum():,} of {len(keep):,} points, "
              f"{near[keep].mean():.2f} overlapping")
        log.append(f"{i}\t{number}\t{n}\n" + "\n".join(lines[b + 1:b + 5]))
    (args.out / "gt.log").write_text("\n".join(log) + "\n")


if __name__ == "__main__":
    main()
