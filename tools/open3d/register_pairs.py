#!/usr/bin/env python3
"""Run Open3D's ICP, FGR, FGR + ICP or RANSAC + ICP on the pairs written by `rgm pairs`, as a measuring stick for rgm.

Usage:
    pip install open3d-cpu==0.20.0   # needs: apt-get install libusb-1.0-0
    rgm pairs --setting partial --out pairs/ --data DIR
    python3 tools/open3d/register_pairs.py pairs/ --method fgr --out open3d_fgr.json
    rgm score open3d_fgr.json --pairs pairs/

Settings follow the measurements quoted in the project's issue 2: normals by PCA over radius 0.2
(max 30 neighbours) oriented away from the centroid, FPFH radius 0.4 (max 100 neighbours), FGR with
Open3D's default options except decrease_mu=True (the FGR paper's graduated non-convexity, as
rgm's FGR does; Open3D 0.20 defaults to False — pass --no-decrease-mu for that); ICP point-to-point from the identity with Open3D's default convergence
criteria.

Two complete classical pipelines, Open3D's best on these pairs, are there to compare with
`rgm register`'s default:
- fgr_icp: FGR as above, then Open3D point-to-point ICP from FGR's transform with maximum
  correspondence distance 0.05 (--refine-distance) and Open3D's default convergence criteria.
- ransac_icp: RANSAC on the same FPFH features
  (registration_ransac_based_on_feature_matching: no mutual filter, maximum correspondence
  distance 0.05, point-to-point estimation without scaling, 3 points per sample, checkers edge
  length 0.9 and distance 0.05, at most 100,000 iterations at confidence 0.999), then the same ICP.

Open3D's random generator is seeded (--seed, default 0) before every pair, so a run is repeatable
and a pair's result does not depend on the pairs before it. The time of each pair is the
method's own wall time (normals + features + registration + ICP), one thread (OMP_NUM_THREADS=1 is
set before Open3D loads); the process's CPU time for the same work is kept beside it as cpu_ms.
"""
import argparse
import json
import os
import pathlib
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402


def load(path):
    return o3d.io.read_point_cloud(str(path))


def features(pcd, normal_radius, fpfh_radius):
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=normal_radius, max_nn=30))
    centre = np.asarray(pcd.points).mean(axis=0)
    normals = np.asarray(pcd.normals)
    away = np.einsum("ij,ij->i", normals, np.asarray(pcd.points) - centre) < 0
    normals[away] *= -1.0
    pcd.normals = o3d.utility.Vector3dVector(normals)
    return o3d.pipelines.registration.compute_fpfh_feature(
        pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=fpfh_radius, max_nn=100)
    )


def register(method, src, tgt, args):
    reg = o3d.pipelines.registration
    if method == "icp":
        return reg.registration_icp(
            src, tgt, args.icp_distance, np.eye(4), reg.TransformationEstimationPointToPoint()
        )
    fs = features(src, args.normal_radius, args.fpfh_radius)
    ft = features(tgt, args.normal_radius, args.fpfh_radius)
    if method in ("fgr", "fgr_icp"):
        option = reg.FastGlobalRegistrationOption(decrease_mu=args.decrease_mu)
        result = reg.registration_fgr_based_on_feature_matching(src, tgt, fs, ft, option)
    else:
        result = reg.registration_ransac_based_on_feature_matching(
            src,
            tgt,
            fs,
            ft,
            False,
            args.ransac_distance,
            reg.TransformationEstimationPointToPoint(False),
            3,
            [
                reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                reg.CorrespondenceCheckerBasedOnDistance(args.ransac_distance),
            ],
            reg.RANSACConvergenceCriteria(args.ransac_iterations, args.ransac_confidence),
        )
    if method == "fgr":
        return result
    return reg.registration_icp(
        src, tgt, args.refine_distance, result.transformation, reg.TransformationEstimationPointToPoint()
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("pairs", type=pathlib.Path, help="folder written by `rgm pairs`")
    parser.add_argument("--method", choices=["icp", "fgr", "fgr_icp", "ransac_icp"], required=True)
    parser.add_argument("--out", type=pathlib.Path, required=True, help="JSON file for `rgm score`")
    parser.add_argument("--icp-distance", type=float, default=0.1)
    parser.add_argument("--normal-radius", type=float, default=0.2)
    parser.add_argument("--fpfh-radius", type=float, default=0.4)
    parser.add_argument("--refine-distance", type=float, default=0.05, help="ICP after FGR or RANSAC")
    parser.add_argument("--ransac-distance", type=float, default=0.05)
    parser.add_argument("--ransac-iterations", type=int, default=100000)
    parser.add_argument("--ransac-confidence", type=float, default=0.999)
    parser.add_argument("--seed", type=int, default=0, help="Open3D's random generator, seeded before every pair")
    parser.add_argument(
        "--decrease-mu",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="FGR's graduated non-convexity (the paper's algorithm, rgm's default); Open3D's own default is off",
    )
    args = parser.parse_args()

    manifest = json.loads((args.pairs / "pairs.json").read_text())
    records = []
    for entry in manifest["pairs"]:
        src = load(args.pairs / entry["source"])
        tgt = load(args.pairs / entry["target"])
        o3d.utility.random.seed(args.seed)
        start, start_cpu = time.perf_counter(), time.process_time()
        result = register(args.method, src, tgt, args)
        elapsed_ms = 1000.0 * (time.perf_counter() - start)
        cpu_ms = 1000.0 * (time.process_time() - start_cpu)
        records.append(
            {
                "index": entry["index"],
                "transform": np.asarray(result.transformation).tolist(),
                "time_ms": elapsed_ms,
                "cpu_ms": cpu_ms,
            }
        )
    uses_mu = args.method in ("fgr", "fgr_icp")
    name = f"open3d-{args.method.replace('_', '-')}" + ("" if not uses_mu or args.decrease_mu else "-nomu")
    args.out.write_text(json.dumps({"method": name, "pairs": records}))
    print(f"wrote {len(records)} transforms to {args.out}")


if __name__ == "__main__":
    main()
