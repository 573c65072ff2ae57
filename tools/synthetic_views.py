"""Scans of one object seen from many directions, each in its own random frame, for timing
`rgm merge` on many scans (`docs/speed.md`, "Many scans"): the points of a dense model (a PLY,
e.g. a merged `model.ply`) whose normals face each of N directions spread evenly over the
sphere (a Fibonacci lattice), at most P of them per view evenly along the model's order, each view moved by a
random rigid motion (seed 0) and written as binary PLY.

    python tools/synthetic_views.py model.ply OUT_DIR --views 50 --points 40000

Needs numpy and open3d (normals). Facing is not occlusion: a view holds every point whose normal
points within 75° of the direction, on both sides of a thin part too."""
import argparse
import pathlib

import numpy as np
import open3d as o3d


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("out")
    parser.add_argument("--views", type=int, default=50)
    parser.add_argument("--points", type=int, default=40000)
    args = parser.parse_args()
    cloud = o3d.io.read_point_cloud(args.model)
    points = np.asarray(cloud.points)
    spacing = np.median(np.asarray(cloud.compute_nearest_neighbor_distance()))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=6 * spacing, max_nn=30))
    # Normals point away from the centroid (the model is a closed-ish object).
    normals = np.asarray(cloud.normals)
    outward = np.einsum("ij,ij->i", normals, points - points.mean(0)) < 0
    normals[outward] *= -1
    rng = np.random.default_rng(0)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    golden = np.pi * (3 - np.sqrt(5))
    for k in range(args.views):
        z = 1 - 2 * (k + 0.5) / args.views
        r = np.sqrt(1 - z * z)
        direction = np.array([r * np.cos(golden * k), r * np.sin(golden * k), z])
        seen = points[normals @ direction > np.cos(np.radians(75))]
        seen = seen[np.linspace(0, len(seen) - 1, min(args.points, len(seen))).astype(int)]
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        moved = seen @ q.T + rng.uniform(-0.1, 0.1, size=3)
        view = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(moved))
        o3d.io.write_point_cloud(str(out / f"view{k:02d}.ply"), view)
        print(f"view{k:02d}.ply: {len(moved)} points")


if __name__ == "__main__":
    main()
