"""Scores an `rgm merge` of 3DMatch fragments against the scene's `gt.log` (docs/multiway.md,
"A room"): for every pair (i, j) of gt.log whose fragments the merge placed in one component,
the merge's relative pose P_i^-1 P_j against gt.log's T (p_i = T p_j): its rotation error in
degrees and translation error in metres, and whether it is within 3DMatch's 15° and 0.3 m.
Fragments are matched to gt.log's indices by the number in their file names (cloud_bin_N).

    rgm merge ../shared/data/scenes/redkitchen/cloud_bin_* --out merged/
    python3 tools/scenes/merge_against_gt_log.py merged/poses.json ../shared/data/scenes/redkitchen/gt.log
"""
import json
import math
import re
import statistics
import sys


def inverse(m):
    r = [[m[j][i] for j in range(3)] for i in range(3)]
    t = [-sum(r[i][k] * m[k][3] for k in range(3)) for i in range(3)]
    return [r[0] + [t[0]], r[1] + [t[1]], r[2] + [t[2]], [0.0, 0.0, 0.0, 1.0]]


def product(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def main(poses_path, gt_path):
    merged = json.load(open(poses_path))
    index = {int(re.search(r"cloud_bin_(\d+)", s).group(1)): k for k, s in enumerate(merged["scans"])}
    lines = [l for l in open(gt_path).read().split("\n") if l.strip()]
    rotations, shifts, within = [], [], 0
    for k in range(0, len(lines), 5):
        i, j = (int(v) for v in lines[k].split()[:2])
        truth = [[float(v) for v in lines[k + r].split()] for r in range(1, 5)]
        a, b = index.get(i), index.get(j)
        if a is None or b is None:
            continue
        pa, pb = merged["poses"][a], merged["poses"][b]
        if pa is None or pb is None or merged["component"][a] != merged["component"][b]:
            print(f"{i}-{j}: not in one component")
            continue
        relative = product(inverse(pa), pb)
        error = product(inverse(truth), relative)
        cosine = max(-1.0, min(1.0, (error[0][0] + error[1][1] + error[2][2] - 1) / 2))
        rotation = math.degrees(math.acos(cosine))
        shift = math.dist([relative[r][3] for r in range(3)], [truth[r][3] for r in range(3)])
        rotations.append(rotation)
        shifts.append(shift)
        within += rotation < 15 and shift < 0.3
        print(f"{i}-{j}: {rotation:.2f}° {shift:.3f} m")
    pairs = len(lines) // 5
    print(f"{within} / {pairs} within 15° and 0.3 m; median {statistics.median(rotations):.2f}°, "
          f"{statistics.median(shifts):.3f} m")


if __name__ == "__main__":
    main(*sys.argv[1:3])
