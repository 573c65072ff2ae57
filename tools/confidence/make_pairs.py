"""Issue 44 D1's reproducers, and the dev pairs beside them, for calibrating the confidence
(docs/confidence.md). Needs numpy and open3d.

    python tools/confidence/make_pairs.py OUT [--holdout]

writes OUT/hostile/*.ply and OUT/hostile.json: 15 ball crops holding 15 % of the merged bunny
(200,000 of its scans' points in the world frame), each at a random pose, against the merged
bunny; 7 pairs of real scans that do not overlap (a bunny scan and a dragon scan; the two
outer 45 % of one scan); 40 ModelNet40 test shapes split by a random plane into two 55 %
parts that share 10 % of the points, jittered as the benchmark jitters. And OUT/natural.json:
the validation pairs `rgm pairs --split validation --every 10` wrote to OUT/mnval, the Stanford
pairs `rgm pairs --scans` wrote to OUT/stan, and the 12 redkitchen pairs. Each entry: kind,
source, target, T (T_target_source; null when the clouds do not overlap).

With --holdout, pairs the confidence was not chosen on, made the same way by another seed: the
crops are of the merged dragon, the non-overlapping pairs of other scans, the 10 % pairs of
other test shapes (a few may repeat by chance), and the natural pairs are the ModelNet40 test
pairs `rgm pairs --split test --every 20` wrote to OUT/mntest (no Stanford or room pairs: the
data has no others).
"""
import gzip, json, pathlib, sys, numpy as np, open3d as o3d
holdout = "--holdout" in sys.argv[2:]
rng = np.random.default_rng(20261129 if holdout else 20261128)
root = pathlib.Path(__file__).resolve().parents[3] / "shared/data"
base = pathlib.Path(sys.argv[1])
out = base / "hostile"; out.mkdir(parents=True, exist_ok=True)

def read_ply_gz(path):
    lines = gzip.open(path, "rt").read().split("\n")
    n = 0; i = 0
    while not lines[i].startswith("end_header"):
        if lines[i].startswith("element vertex"): n = int(lines[i].split()[2])
        i += 1
    return np.array([[float(v) for v in l.split()[:3]] for l in lines[i+1:i+1+n]])

def quat_R(qx, qy, qz, qw):
    return np.array([[1-2*(qy*qy+qz*qz), 2*(qx*qy-qz*qw), 2*(qx*qz+qy*qw)],
                     [2*(qx*qy+qz*qw), 1-2*(qx*qx+qz*qz), 2*(qy*qz-qx*qw)],
                     [2*(qx*qz-qy*qw), 2*(qy*qz+qx*qw), 1-2*(qx*qx+qy*qy)]])

def scans(folder, conf):
    res = {}
    for l in open(root/"stanford"/folder/conf):
        f = l.split()
        if not f or f[0] != "bmesh": continue
        t = np.array(list(map(float, f[2:5]))); q = list(map(float, f[5:9]))
        name = f[1].replace(".ply", "")
        p = read_ply_gz(root/"stanford"/folder/(name+".ply.gz"))
        res[name] = p @ quat_R(*q) + t  # R^T p + t, rows
    return res

def rand_rot(max_deg=None):
    while True:
        a = rng.normal(size=3); a /= np.linalg.norm(a)
        ang = np.radians(rng.uniform(0, max_deg)) if max_deg else rng.uniform(0, np.pi)
        K = np.array([[0,-a[2],a[1]],[a[2],0,-a[0]],[-a[1],a[0],0]])
        return np.eye(3) + np.sin(ang)*K + (1-np.cos(ang))*K@K

def write(name, pts):
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    o3d.io.write_point_cloud(str(out/name), pc)
    return str(out/name)

def moved(pts, R, t):  # source = R pts + t, so T_target_source = inverse
    return pts @ R.T + t, np.block([[R.T, (-R.T@t)[:,None]],[np.zeros((1,3)), np.ones((1,1))]])

pairs = []
bunny = scans("bunny", "bun.conf")
dragon = scans("dragon_stand", "dragonStandRight.conf")
whole = "dragon" if holdout else "bunny"
merged = np.concatenate(list((dragon if holdout else bunny).values()))
sel = rng.choice(len(merged), 200_000, replace=False); merged = merged[sel]
tgt = write(f"{whole}_merged.ply", merged)
ext = np.linalg.norm(merged - merged.mean(0), axis=1).max()
for k in range(15):
    c = merged[rng.integers(len(merged))]
    d = np.linalg.norm(merged - c, axis=1)
    crop = merged[d <= np.quantile(d, 0.15)]
    src_pts, T = moved(crop, rand_rot(), rng.uniform(-0.5, 0.5, 3)*ext)
    pairs.append(dict(kind="part", source=write(f"crop{k}.ply", src_pts), target=tgt, T=T.tolist()))
# non-overlapping real scans: bunny vs dragon, and the two halves of one scan
apart = [("bun045", "dragonStandRight_24"), ("bun315", "dragonStandRight_120"), ("chin", "dragonStandRight_216")] if holdout \
    else [("bun000", "dragonStandRight_0"), ("bun090", "dragonStandRight_96"), ("top2", "dragonStandRight_192")]
halves = ["bun045", "bun315", "dragonStandRight_144", "dragonStandRight_288"] if holdout \
    else ["bun000", "bun180", "bun270", "dragonStandRight_48"]
for k, (b, d) in enumerate(apart):
    s, T = moved(bunny[b], rand_rot(45), rng.uniform(-0.03, 0.03, 3))
    pairs.append(dict(kind="none", source=write(f"none_bd{k}.ply", s), target=write(f"none_d{k}.ply", dragon[d]), T=None))
for k, name in enumerate(halves):
    p = bunny.get(name, dragon.get(name))
    a = rng.normal(size=3); a /= np.linalg.norm(a)
    proj = (p - p.mean(0)) @ a
    left, right = p[proj < np.quantile(proj, 0.45)], p[proj > np.quantile(proj, 0.55)]
    s, T = moved(left, rand_rot(45), rng.uniform(-0.03, 0.03, 3))
    pairs.append(dict(kind="none", source=write(f"none_half{k}_a.ply", s), target=write(f"none_half{k}_b.ply", right), T=None))
# ModelNet at ~10 % overlap: the shape split by a random plane, 55 % each side
shapes = sorted((root/"modelnet40_npy1024").glob("*/test/*.npy"))
for k, f in enumerate(rng.choice(len(shapes), 40, replace=False)):
    p = np.load(shapes[f]).astype(np.float64)[:, :3]
    a = rng.normal(size=3); a /= np.linalg.norm(a)
    proj = p @ a
    s = p[proj >= np.quantile(proj, 0.45)]; t = p[proj <= np.quantile(proj, 0.55)]
    jit = lambda x: x + np.clip(rng.normal(0, 0.01, x.shape), -0.05, 0.05)
    s, T = moved(jit(s), rand_rot(45), rng.uniform(-0.5, 0.5, 3))
    pairs.append(dict(kind="mn10", source=write(f"mn10_{k}_s.ply", s), target=write(f"mn10_{k}_t.ply", jit(t)), T=T.tolist()))
json.dump(pairs, open(base / "hostile.json", "w"), indent=0)

natural = []
folders = [("mntest", "mn")] if holdout else [("mnval", "mn"), ("stan/bunny", "stan"), ("stan/dragon_stand", "stan")]
for folder, kind in folders:
    for p in json.load(open(base / folder / "pairs.json"))["pairs"]:
        natural.append(dict(kind=kind, source=str(base / folder / p["source"]),
                            target=str(base / folder / p["target"]), T=p["t_target_source"]))
kitchen = root / "scenes/redkitchen"
fragment = lambda k: str(next(p for p in [kitchen / f"cloud_bin_{k}.ply.gz", kitchen / f"cloud_bin_{k}.pcd"] if p.exists()))
lines = (kitchen / "gt.log").read_text().split("\n")
for b in range(0, len(lines) - 4, 5) if not holdout else []:
    h = lines[b].split()
    if len(h) == 3:
        T = [[float(v) for v in lines[b + r].split()] for r in range(1, 5)]
        natural.append(dict(kind="room", source=fragment(int(h[1])), target=fragment(int(h[0])), T=T))
json.dump(natural, open(base / "natural.json", "w"))
print(len(pairs), "hostile pairs,", len(natural), "natural pairs")
