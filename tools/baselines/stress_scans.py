#!/usr/bin/env python3
"""The Stanford scan pairs made unlike the dev set, to see how rgm (and Open3D) hold up on data the
project does not have (docs/baselines.md, "Data unlike the dev set").

    rgm pairs --scans ../shared/data/stanford/bunny ../shared/data/stanford/dragon_stand --out PAIRS
    python3 tools/baselines/stress_scans.py RGM [RGM ...] --pairs PAIRS --out DIR [--variants V ...] [--open3d]

Each variant is written once under DIR/VARIANT/{bunny,dragon_stand} (binary PLY and pairs.json,
the ground truth carried over), seeded per pair:
- orig: the pairs as `rgm pairs` wrote them;
- strays1, strays5, strays20: 1, 5 or 20 % more points, uniform in each cloud's bounding box;
- quarter: a random quarter of each cloud's points (a sparser scanner);
- noisy: Gaussian noise of σ 0.5 mm per coordinate (about one point spacing);
- mm: every length in millimetres;
- turned: the source turned once more about its centroid by up to 180°;
- shuffled: the points in random order.

Each build runs `rgm --threads 1 register --pairs … --workers 1` (one thread); Open3D runs
tools/baselines/open3d_scans.py. Printed per variant and object: pairs within 2° / 1 % of the
diagonal, the median and largest rotation error, the mean time per pair (each method's own,
files read beforehand) and which stage's result rgm chose.
"""
import argparse
import json
import pathlib
import statistics
import subprocess
import sys

import numpy as np

OBJECTS = ("bunny", "dragon_stand")
ROOT = pathlib.Path(__file__).resolve().parents[2]


def read_ply(path):
    """The vertices of a binary little-endian float32 PLY (as `rgm pairs` writes them)."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    if "binary_little_endian" not in header or header.count("property float") != 3:
        sys.exit(f"{path}: not the float32 x y z PLY that `rgm pairs` writes")
    count = int(next(line for line in header.splitlines() if line.startswith("element vertex")).split()[2])
    return np.frombuffer(data[end:end + 12 * count], dtype="<f4").reshape(count, 3).astype(np.float64)


def write_ply(path, points):
    points = np.asarray(points, dtype="<f4")
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n")
    path.write_bytes(header.encode() + points.tobytes())


def strays(share):
    def make(rng, source, target, truth, diagonal):
        def add(cloud):
            low, high = cloud.min(0), cloud.max(0)
            extra = rng.uniform(low, high, (int(len(cloud) * share), 3))
            return np.vstack([cloud, extra])[rng.permutation(len(cloud) + len(extra))]
        return add(source), add(target), truth, diagonal
    return make


def quarter(rng, source, target, truth, diagonal):
    return source[rng.random(len(source)) < 0.25], target[rng.random(len(target)) < 0.25], truth, diagonal


def noisy(rng, source, target, truth, diagonal):
    return (source + rng.normal(0, 5e-4, source.shape), target + rng.normal(0, 5e-4, target.shape),
            truth, diagonal)


def mm(rng, source, target, truth, diagonal):
    scaled = truth.copy()
    scaled[:3, 3] *= 1000
    return source * 1000, target * 1000, scaled, diagonal * 1000


def turned(rng, source, target, truth, diagonal):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    angle = np.radians(rng.uniform(0, 180))
    rotation = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    centre = source.mean(0)
    move = np.eye(4)
    move[:3, :3], move[:3, 3] = rotation, centre - rotation @ centre
    return (source - centre) @ rotation.T + centre, target, truth @ np.linalg.inv(move), diagonal


def shuffled(rng, source, target, truth, diagonal):
    return source[rng.permutation(len(source))], target[rng.permutation(len(target))], truth, diagonal


VARIANTS = {"orig": None, "strays1": strays(0.01), "strays5": strays(0.05), "strays20": strays(0.2),
            "quarter": quarter, "noisy": noisy, "mm": mm, "turned": turned, "shuffled": shuffled}


def write_variant(pairs_root, out, name):
    for scans in OBJECTS:
        folder = out / name / scans
        if (folder / "pairs.json").exists():
            continue
        folder.mkdir(parents=True, exist_ok=True)
        manifest = json.loads((pairs_root / scans / "pairs.json").read_text())
        written = []
        for entry in manifest["pairs"]:
            rng = np.random.default_rng(1000 + entry["index"])
            source = read_ply(pairs_root / scans / entry["source"])
            target = read_ply(pairs_root / scans / entry["target"])
            truth = np.array(entry["t_target_source"])
            if VARIANTS[name] is not None:
                source, target, truth, diagonal = VARIANTS[name](rng, source, target, truth, entry["diagonal"])
                entry = dict(entry, t_target_source=truth.tolist(), diagonal=diagonal)
            write_ply(folder / entry["source"], source)
            write_ply(folder / entry["target"], target)
            written.append(entry)
        (folder / "pairs.json").write_text(json.dumps(dict(manifest, pairs=written)))


def errors(found, truth, centroid, diagonal):
    """Rotation error (degrees) and the source centroid's displacement as a share of the diagonal."""
    relative = truth[:3, :3].T @ found[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(relative) - 1) / 2, -1, 1)))
    moved = lambda t: t[:3, :3] @ centroid + t[:3, 3]  # noqa: E731
    return angle, np.linalg.norm(moved(found) - moved(truth)) / diagonal


def rgm_transforms(rgm, folder, out):
    lines = out / f"{pathlib.Path(rgm).name}-{folder.parent.name}-{folder.name}.jsonl"
    lines.unlink(missing_ok=True)
    subprocess.run([rgm, "--threads", "1", "register", "--pairs", str(folder / "pairs.json"), "--output",
                    str(lines), "--workers", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    found = {}
    for line in lines.read_text().splitlines()[1:]:
        record = json.loads(line)
        if "transform" in record:
            found[record["source"]] = (record["transform"], record["time_ms"], record.get("chosen"))
    return found


def open3d_transforms(folder, out):
    result = out / f"open3d-{folder.parent.name}-{folder.name}.json"
    subprocess.run([sys.executable, str(ROOT / "tools/baselines/open3d_scans.py"), str(folder), "--out", str(result)],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    manifest = json.loads((folder / "pairs.json").read_text())
    by_index = {r["index"]: r for r in json.loads(result.read_text())["pairs"]}
    return {e["source"]: (by_index[e["index"]]["transform"], by_index[e["index"]]["time_ms"], "open3d")
            for e in manifest["pairs"] if e["index"] in by_index}


def report(label, name, folder, found):
    manifest = json.loads((folder / "pairs.json").read_text())
    angles, times, within, chosen = [], [], 0, {}
    for entry in manifest["pairs"]:
        if entry["source"] not in found:
            angles.append(float("inf"))
            continue
        transform, time_ms, stage = found[entry["source"]]
        centroid = read_ply(folder / entry["source"]).mean(0)
        angle, shift = errors(np.array(transform), np.array(entry["t_target_source"]), centroid, entry["diagonal"])
        angles.append(angle)
        times.append(time_ms)
        within += angle < 2 and shift < 0.01
        chosen[stage] = chosen.get(stage, 0) + 1
    mean = statistics.mean(times) if times else float("nan")
    print(f"{label:14s} {name:9s} {folder.name:12s} {within:2d}/{len(manifest['pairs'])} within 2°/1 %  "
          f"median {statistics.median(angles):.3f}°  largest {max(angles):7.2f}°  {mean:7.1f} ms  {chosen}",
          flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("rgm", nargs="+", help="rgm binaries to compare")
    parser.add_argument("--pairs", type=pathlib.Path, required=True, help="the folder `rgm pairs --scans` wrote")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="where the variants and results go")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--open3d", action="store_true", help="also Open3D (tools/baselines/open3d_scans.py)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.variants:
        if name != "orig":
            write_variant(args.pairs, args.out, name)
        for scans in OBJECTS:
            folder = (args.pairs if name == "orig" else args.out / name) / scans
            for rgm in args.rgm:
                report(pathlib.Path(rgm).name, name, folder, rgm_transforms(rgm, folder, args.out))
            if args.open3d:
                report("open3d", name, folder, open3d_transforms(folder, args.out))


if __name__ == "__main__":
    main()
