#!/usr/bin/env python3
"""Open3D FPFH + RANSAC, then point-to-plane ICP, on the real scan pairs written by `rgm pairs --scans`.

Usage:
    pip install open3d==0.20.0        # needs: apt-get install libusb-1.0-0
    rgm pairs --scans ../shared/data/stanford/bunny ../shared/data/stanford/dragon_stand --out scanpairs/
    OMP_NUM_THREADS=1 python3 tools/baselines/open3d_scans.py scanpairs/bunny --out open3d_bunny.json
    rgm score open3d_bunny.json --pairs scanpairs/bunny

Open3D's global-registration tutorial pipeline, every length a fixed fraction of the pair's own size
(no ground truth: size = the larger of the two clouds' bounding-box diagonals; voxel v = 2 % of it):
- each cloud voxel-downsampled at v; normals over radius 2v (max 30 neighbours); FPFH over radius 5v
  (max 100 neighbours);
- RANSAC on the features (registration_ransac_based_on_feature_matching: mutual filter off,
  maximum correspondence distance 1.5v, point-to-point estimation, 3 points per sample, checkers
  edge length 0.9 and distance 1.5v, at most 100,000 iterations at confidence 0.999);
- point-to-plane ICP on the full clouds (normals over radius 2v, max 30) at distance 0.4v, Open3D's
  default convergence criteria; with --second-stage, another at 0.4v / 5. With --icp-on-downsampled,
  the ICP runs on the downsampled clouds instead (their normals the FPFH's), at 0.4v unless
  --icp-distance-share says otherwise: a cheaper recipe (no normals or searches on the full clouds),
  as a user might write it (docs/baselines.md, "Open3D's ICP on the downsampled clouds").

Open3D's random generator is seeded (--seed, default 0) before every pair. A pair's time is the
wall time of all the above (the clouds read beforehand), one thread: OMP_NUM_THREADS=1 is set before
Open3D loads.
"""
import argparse
import json
import os
import pathlib
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402

reg = o3d.pipelines.registration


def size(pcd):
    box = pcd.get_axis_aligned_bounding_box()
    return float(np.linalg.norm(box.get_max_bound() - box.get_min_bound()))


def fpfh(pcd, voxel):
    down = pcd.voxel_down_sample(voxel)
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    feature = reg.compute_fpfh_feature(down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
    return down, feature


def ransac_icp(src, tgt, voxel, icp_distances, downsampled=False):
    """Open3D's tutorial pipeline at voxel `voxel`: FPFH + RANSAC on the downsampled pair, then
    point-to-plane ICP on the full clouds (the downsampled ones with `downsampled`) at each of
    `icp_distances` in turn."""
    src_down, src_fpfh = fpfh(src, voxel)
    tgt_down, tgt_fpfh = fpfh(tgt, voxel)
    distance = 1.5 * voxel
    ransac = reg.registration_ransac_based_on_feature_matching(
        src_down,
        tgt_down,
        src_fpfh,
        tgt_fpfh,
        False,
        distance,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(distance)],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    if downsampled:
        src, tgt = src_down, tgt_down
    else:
        tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    transform = ransac.transformation
    for d in icp_distances:
        transform = reg.registration_icp(src, tgt, d, transform, reg.TransformationEstimationPointToPlane()).transformation
    return transform


def register(src, tgt, args):
    voxel = args.voxel_share * max(size(src), size(tgt))
    first = args.icp_distance_share * voxel
    return ransac_icp(src, tgt, voxel, [first] + ([first / 5] if args.second_stage else []), args.icp_on_downsampled)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("pairs", type=pathlib.Path, help="one scan folder written by `rgm pairs --scans`")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="JSON file for `rgm score`")
    parser.add_argument("--voxel-share", type=float, default=0.02, help="voxel as a share of the pair's size")
    parser.add_argument("--second-stage", action="store_true", help="a second ICP stage at a fifth of the first's distance")
    parser.add_argument("--icp-on-downsampled", action="store_true", help="ICP on the downsampled clouds, not the full ones")
    parser.add_argument("--icp-distance-share", type=float, default=0.4, help="ICP's distance as a share of the voxel")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    manifest = json.loads((args.pairs / "pairs.json").read_text())
    records = []
    for entry in manifest["pairs"]:
        src = o3d.io.read_point_cloud(str(args.pairs / entry["source"]))
        tgt = o3d.io.read_point_cloud(str(args.pairs / entry["target"]))
        o3d.utility.random.seed(args.seed)
        start = time.perf_counter()
        transform = register(src, tgt, args)
        elapsed_ms = 1000.0 * (time.perf_counter() - start)
        records.append({"index": entry["index"], "transform": np.asarray(transform).tolist(), "time_ms": elapsed_ms})
    name = "open3d-ransac-icp" + ("2" if args.second_stage else "") + ("-downsampled" if args.icp_on_downsampled else "")
    args.out.write_text(json.dumps({"method": name, "pairs": records}))
    print(f"wrote {len(records)} transforms to {args.out}")


if __name__ == "__main__":
    main()
