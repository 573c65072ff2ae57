"""How far a ModelNet40 shape's own points lie from its coordinate-wise median, in medians of
that distance: the margin behind rgm_model::policy::TUNED.frame.far_outlier (docs/geom.md, "Far
outliers"). Plain Python, no NumPy.

    python3 tools/far_outliers.py ../shared/data/modelnet40_npy1024 [SHAPES]
"""

import glob
import math
import random
import struct
import sys


def points(path):
    data = open(path, "rb").read()
    header = 10 + struct.unpack("<H", data[8:10])[0]
    n = (len(data) - header) // 12
    v = struct.unpack(f"<{3 * n}f", data[header : header + 12 * n])
    return [v[3 * i : 3 * i + 3] for i in range(n)]


def ratio(cloud):
    """The farthest point's distance from the median, over the median distance."""
    n = len(cloud)
    middle = [sorted(p[c] for p in cloud)[n // 2] for c in range(3)]
    d = sorted(math.dist(p, middle) for p in cloud)
    return d[-1] / d[n // 2]


def crop(cloud, rng):
    """70 % of the points, cut by a plane of random direction (the partial setting's crop)."""
    z = [rng.gauss(0, 1) for _ in range(3)]
    return sorted(cloud, key=lambda p: -sum(a * b for a, b in zip(p, z)))[: len(cloud) * 7 // 10]


def main():
    root = sys.argv[1]
    count = int(sys.argv[2]) if len(sys.argv) > 2 else 1500
    rng = random.Random(0)
    files = rng.sample(sorted(glob.glob(f"{root}/*/train/*.npy")), count)
    whole, cropped = [], []
    for f in files:
        cloud = points(f)
        whole.append((ratio(cloud), f.split("/")[-1]))
        cropped.append((ratio(crop(cloud, rng)), f.split("/")[-1]))
    for name, values in (("whole", whole), ("70 % crop", cropped)):
        values.sort()
        print(
            f"{name}: {len(values)} shapes, 99th percentile {values[len(values) * 99 // 100][0]:.2f}, "
            f"largest {values[-1][0]:.2f} ({values[-1][1]})"
        )


main()
