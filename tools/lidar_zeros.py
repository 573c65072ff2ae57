"""A LiDAR pair densified to about a million points per sweep, with and without missing returns
stored as (0, 0, 0), for timing `rgm register` on copies of one point (issue 59, E2;
`docs/speed.md`, "Copies of one point"): each point of `../shared/data/scenes/lidar`'s two
sweeps (binary PCD, x y z intensity) repeated `--copies` times with a 2 cm jitter (seed 0), then
`--zeros` of the points set to the origin. Writes OUT/{source,target}{,_zeros}.npy.

    python tools/lidar_zeros.py ../shared/data/scenes/lidar OUT --copies 10 --zeros 0.3
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
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sweeps = sorted(pathlib.Path(args.folder).glob("*.pcd"))
    for name, path in zip(["source", "target"], sweeps[::-1]):
        points = read_pcd(path)
        points = points[np.isfinite(points).all(1)]
        dense = np.repeat(points, args.copies, axis=0)
        dense += rng.normal(scale=0.02, size=dense.shape)
        rng.shuffle(dense)
        np.save(out / f"{name}.npy", dense)
        zeros = dense.copy()
        zeros[rng.random(len(zeros)) < args.zeros] = 0.0
        np.save(out / f"{name}_zeros.npy", zeros)
        print(f"{name}: {path.name}, {len(dense)} points, {int((zeros == 0).all(1).sum())} at the origin")


if __name__ == "__main__":
    main()
