#!/usr/bin/env python3
"""Open3D's multiway recipe on a Stanford scan folder (the anchor of issue 56), scored as
`rgm eval --multiway` scores rgm: per-scan rotation error and RMS displacement as a share of the
object's diagonal, after the one rigid motion that best maps the result's frame onto the `.conf`
poses' (Kabsch over at most 2,000 points of each scan).

Usage:
    pip install open3d==0.20.0        # needs: apt-get install libusb-1.0-0
    OMP_NUM_THREADS=1 python3 tools/baselines/open3d_multiway.py ../shared/data/stanford/bunny

The recipe (Open3D's reconstruction system and multiway-registration tutorial), every length a
fraction of the object's diagonal d (v = 2 % of d):
- every pair: FPFH (normals over 2v, features over 5v) + RANSAC on the scans voxel-downsampled at
  v (mutual filter off, distance 1.5v, checkers 0.9 and 1.5v, 100,000 iterations at 0.999), then
  point-to-plane ICP on the full scans at 0.4v (--icp) and its information matrix;
- initial poses from the maximum spanning tree of ICP fitness (its edges odometry), every other
  pair with fitness >= 0.3 an uncertain loop closure;
- `global_optimization` (Levenberg-Marquardt, max correspondence distance 0.4v (--icp), edge prune
  threshold 0.25, the tree's root the reference node).
The scans are read in their own scanner frames (no initial poses); Open3D's generator is seeded.
The time is the wall time of all the above, the scans read beforehand, one thread.
"""
import argparse
import json
import os
import pathlib
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from stanford import read_folder  # noqa: E402

reg = o3d.pipelines.registration


def kabsch(a, b):
    """The rigid 4x4 that best maps points a onto b."""
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1, 1, d]) @ u.T
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, cb - r @ ca
    return m


def apply(m, p):
    return p @ m[:3, :3].T + m[:3, 3]


def merge(clouds, v, icp):
    """Poses model <- scan by the recipe (None for a scan the tree did not reach)."""
    n = len(clouds)
    normals = o3d.geometry.KDTreeSearchParamHybrid(radius=2 * v, max_nn=30)
    down, feats = [], []
    for c in clouds:
        c.estimate_normals(normals)
        d = c.voxel_down_sample(v)
        d.estimate_normals(normals)
        down.append(d)
        feats.append(reg.compute_fpfh_feature(d, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * v, max_nn=100)))
    edges = []
    for s in range(n):
        for t in range(s + 1, n):
            o3d.utility.random.seed(0)
            ransac = reg.registration_ransac_based_on_feature_matching(
                down[s], down[t], feats[s], feats[t], False, 1.5 * v,
                reg.TransformationEstimationPointToPoint(False), 3,
                [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(1.5 * v)],
                reg.RANSACConvergenceCriteria(100000, 0.999),
            )
            fit = reg.registration_icp(
                clouds[s], clouds[t], icp * v, ransac.transformation, reg.TransformationEstimationPointToPlane()
            )
            info = reg.get_information_matrix_from_point_clouds(clouds[s], clouds[t], icp * v, fit.transformation)
            edges.append((fit.fitness, s, t, fit.transformation, info))
    # Maximum spanning tree of fitness (Kruskal), from the scan with the most fitness on it.
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    tree = set()
    for e in sorted(edges, key=lambda e: -e[0]):
        a, b = find(e[1]), find(e[2])
        if a != b and e[0] > 0:
            parent[a] = b
            tree.add((e[1], e[2]))
    strength = np.zeros(n)
    for f, s, t, _, _ in edges:
        if (s, t) in tree:
            strength[s] += f
            strength[t] += f
    root = int(np.argmax(strength))
    poses = {root: np.eye(4)}  # model <- scan
    grew = True
    while grew:
        grew = False
        for f, s, t, m, _ in edges:
            if (s, t) not in tree:
                continue
            if t in poses and s not in poses:
                poses[s] = poses[t] @ m  # m: t <- s
                grew = True
            elif s in poses and t not in poses:
                poses[t] = poses[s] @ np.linalg.inv(m)
                grew = True
    graph = reg.PoseGraph()
    order = sorted(poses)
    slot = {s: k for k, s in enumerate(order)}
    for s in order:
        graph.nodes.append(reg.PoseGraphNode(poses[s]))
    for f, s, t, m, info in edges:
        if s not in slot or t not in slot:
            continue
        if (s, t) in tree:
            graph.edges.append(reg.PoseGraphEdge(slot[s], slot[t], m, info, uncertain=False))
        elif f >= 0.3:
            graph.edges.append(reg.PoseGraphEdge(slot[s], slot[t], m, info, uncertain=True))
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=icp * v, edge_prune_threshold=0.25, reference_node=slot[root]
    )
    reg.global_optimization(
        graph, reg.GlobalOptimizationLevenbergMarquardt(), reg.GlobalOptimizationConvergenceCriteria(), option
    )
    # Open3D's node pose maps the node's points into the model frame.
    return [np.asarray(graph.nodes[slot[s]].pose) if s in slot else None for s in range(n)]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=pathlib.Path)
    parser.add_argument("--out", type=pathlib.Path, help="per-scan errors as JSON")
    parser.add_argument(
        "--icp", type=float, default=0.4,
        help="ICP's and the optimiser's correspondence distance in voxels (0.4: the tutorial's; 1: every length 2 %%)",
    )
    args = parser.parse_args()
    scans = read_folder(args.folder)
    world = np.concatenate([apply(p, pts) for _, pts, p in scans])
    diagonal = float(np.linalg.norm(world.max(0) - world.min(0)))
    clouds = []
    for _, pts, _ in scans:
        c = o3d.geometry.PointCloud()
        c.points = o3d.utility.Vector3dVector(pts)
        clouds.append(c)
    start = time.perf_counter()
    found = merge(clouds, 0.02 * diagonal, args.icp)
    seconds = time.perf_counter() - start
    samples = [pts[:: max(1, -(-len(pts) // 2000))] for _, pts, _ in scans]
    placed = [k for k, f in enumerate(found) if f is not None]
    model = np.concatenate([apply(found[k], samples[k]) for k in placed])
    truth = np.concatenate([apply(scans[k][2], samples[k]) for k in placed])
    align = kabsch(model, truth)
    rows = []
    for k, (name, _, pose) in enumerate(scans):
        if found[k] is None:
            rows.append({"scan": name, "placed": False})
            continue
        placed_pose = align @ found[k]
        off = np.linalg.inv(pose) @ placed_pose
        angle = float(np.degrees(np.arccos(np.clip((np.trace(off[:3, :3]) - 1) / 2, -1, 1))))
        rms = float(np.sqrt(np.mean(np.sum((apply(placed_pose, samples[k]) - apply(pose, samples[k])) ** 2, 1))))
        rows.append({"scan": name, "placed": True, "rotation_deg": angle, "rms_diagonal": rms / diagonal})
    ok = [r for r in rows if r["placed"]]
    rot = [r["rotation_deg"] for r in ok]
    within = sum(r["rotation_deg"] <= 1 and r["rms_diagonal"] <= 0.005 for r in ok)
    print(
        f"{args.folder.name}\t{len(rows)}\t{len(ok)}\t{within}\t{max(rot):.3f}°\t{np.median(rot):.3f}°\t"
        f"{100 * max(r['rms_diagonal'] for r in ok):.3f} %\t{seconds:.1f} s"
    )
    for r in rows:
        print(f"  {r['scan']}\t" + (f"{r['rotation_deg']:.3f}°\t{100 * r['rms_diagonal']:.3f} %" if r["placed"] else "not placed"))
    if args.out:
        args.out.write_text(json.dumps({"folder": str(args.folder), "time_s": seconds, "scans": rows}, indent=1))


if __name__ == "__main__":
    main()
