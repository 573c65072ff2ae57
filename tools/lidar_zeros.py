"""A LiDAR pair densified to about a million points per sweep, with and without missing returns
stored as (0, 0, 0), for timing `rgm register` on copies of one point (issue 59, E2;
`docs/speed.md`, "Copies of one point"): between each point of `../shared/data/scenes/lidar`'s
two sweeps (binary PCD, x y z intensity, in the scanner's order: `--beams` points a column, so a
beam's next point is `--beams` on) and the next point of its beam, when the two lie within
`--gap` metres (one surface), `--copies` − 1 more points evenly on the segment, as a scanner of
that many times the azimuth resolution would see them; then
`--zeros` of the points (seed 0) set to the origin. Writes OUT/{source,target}{,_zeros}.npy.

    python tools/lidar_zeros.py ../shared/data/scenes/lidar OUT --copies 15 --zeros 0.3
"""
import argparse
import pathlib

import numpy as np


def read_pcd(path):
    data = path.read_bytes()
    end = data.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = data[:end].decode().split("\n")
    points = int(next(l for l in header if l.startswith("POINTS")).split()[1])
    fields = len(next(l for l in header if l.startswith("FIELDS")).split()) - 1
    values = np.frombuffer(data[end:], dtype="<f4", count=points * fields).reshape(points, fields)
    return values[:, :3].astype(np.float64)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("out")
    parser.add_argument("--copies", type=int, default=10)
    parser.add_argument("--zeros", type=float, default=0.3)
    parser.add_argument("--gap", type=float, default=0.3)
    parser.add_argument("--beams", type=int, default=32)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sweeps = sorted(pathlib.Path(args.folder).glob("*.pcd"))
    for name, path in zip(["source", "target"], sweeps[::-1]):
        points = read_pcd(path)
        points = points[np.isfinite(points).all(1)]
        b = args.beams
        step = points[b:] - points[:-b]  # (N - b, 3): each point to its beam's next
        near = np.linalg.norm(step, axis=1) < args.gap
        parts = [points]
        for k in range(1, args.copies):
            parts.append(points[:-b][near] + (k / args.copies) * step[near])
        dense = np.concatenate(parts)
        np.save(out / f"{name}.npy", dense)
        zeros = dense.copy()
        zeros[rng.random(len(zeros)) < args.zeros] = 0.0
        np.save(out / f"{name}_zeros.npy", zeros)
        print(f"{name}: {path.name}, {len(dense)} points, {int((zeros == 0).all(1).sum())} at the origin")


if __name__ == "__main__":
    main()
