#!/usr/bin/env python3
"""Run Open3D's ICP or FGR on the pairs written by `rgm pairs`, as a measuring stick for rgm.

Usage:
    pip install open3d-cpu==0.20.0   # needs: apt-get install libusb-1.0-0
    rgm pairs --setting partial --out pairs/ --data DIR
    python3 tools/open3d/register_pairs.py pairs/ --method fgr --out open3d_fgr.json
    rgm score open3d_fgr.json --pairs pairs/

Settings follow the measurements quoted in the project's issue 2: normals by PCA over radius 0.2
(max 30 neighbours) oriented away from the centroid, FPFH radius 0.4 (max 100 neighbours), FGR with
Open3D's default options except decrease_mu=True (the FGR paper's graduated non-convexity, as
rgm's FGR does; Open3D 0.20 defaults to False — pass --no-decrease-mu for that); ICP point-to-point from the identity with Open3D's default convergence
criteria. The time of each pair is the method's own time (normals + features + registration for
FGR), one thread (OMP_NUM_THREADS=1 is set before Open3D loads).
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
        result = reg.registration_icp(
            src, tgt, args.icp_distance, np.eye(4), reg.TransformationEstimationPointToPoint()
        )
    else:
        fs = features(src, args.normal_radius, args.fpfh_radius)
        ft = features(tgt, args.normal_radius, args.fpfh_radius)
        option = reg.FastGlobalRegistrationOption(decrease_mu=args.decrease_mu)
        result = reg.registration_fgr_based_on_feature_matching(src, tgt, fs, ft, option)
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("pairs", type=pathlib.Path, help="folder written by `rgm pairs`")
    parser.add_argument("--method", choices=["icp", "fgr"], required=True)
    parser.add_argument("--out", type=pathlib.Path, required=True, help="JSON file for `rgm score`")
    parser.add_argument("--icp-distance", type=float, default=0.1)
    parser.add_argument("--normal-radius", type=float, default=0.2)
    parser.add_argument("--fpfh-radius", type=float, default=0.4)
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
        start = time.perf_counter()
        result = register(args.method, src, tgt, args)
        elapsed_ms = 1000.0 * (time.perf_counter() - start)
        records.append(
            {
                "index": entry["index"],
                "transform": np.asarray(result.transformation).tolist(),
                "time_ms": elapsed_ms,
            }
        )
    name = f"open3d-{args.method}" + ("" if args.method == "icp" or args.decrease_mu else "-nomu")
    args.out.write_text(json.dumps({"method": name, "pairs": records}))
    print(f"wrote {len(records)} transforms to {args.out}")


if __name__ == "__main__":
    main()
