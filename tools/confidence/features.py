"""Ground-truth-free features of each result of run.py, with whether it is right (within 5° and
5 % of the pair's size of the ground truth): the shares of each cloud within fixed distances of
the other in the pair's unit-sphere frame (fs0.02, ft0.02, …) and within multiples of the point
spacing (ks1.5, kt16, …). The study that chose the confidence's lengths (docs/confidence.md).

    python tools/confidence/features.py RUN.jsonl FEATURES.json
"""
import json, sys, numpy as np, open3d as o3d
cache = {}
def load(path):
    if path not in cache:
        if path.endswith(".gz"):
            import gzip, tempfile, os
            tmp = tempfile.NamedTemporaryFile(suffix=".ply", delete=False); tmp.write(gzip.open(path).read()); tmp.close()
            pc = o3d.io.read_point_cloud(tmp.name); os.unlink(tmp.name)
        else: pc = o3d.io.read_point_cloud(path)
        cache[path] = np.asarray(pc.points)
    return cache[path]
def err(T, G):
    D = np.linalg.inv(G) @ T
    return np.degrees(np.arccos(np.clip((np.trace(D[:3,:3]) - 1) / 2, -1, 1))), np.linalg.norm(T[:3,3] - G[:3,3])
def pc(x): return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(x))
def spacing(x):
    tree = o3d.geometry.KDTreeFlann(pc(x))
    idx = np.random.default_rng(0).choice(len(x), min(len(x), 2000), replace=False)
    return float(np.median([np.sqrt(tree.search_knn_vector_3d(x[i], 2)[2][1]) for i in idx]))
rows = []
for line in open(sys.argv[1]):
    r = json.loads(line)
    if "error" in r: continue
    S, T = load(r["source"]), load(r["target"])
    M = np.array(r["transform"])
    scale = max(np.linalg.norm(S - S.mean(0), axis=1).max(), np.linalg.norm(T - T.mean(0), axis=1).max())
    if scale < 1.5: scale = 1.0  # ModelNet pairs are used as given
    Sm = S @ M[:3,:3].T + M[:3,3]
    ds = np.asarray(pc(Sm).compute_point_cloud_distance(pc(T))) / scale
    dt = np.asarray(pc(T).compute_point_cloud_distance(pc(Sm))) / scale
    if r["gt"] is None: right = False; a = t = None
    else:
        G = np.array(r["gt"]); a, t = err(M, G); t /= scale
        right = bool(a < 5 and t < 0.05); a, t = float(a), float(t)
    row = dict(kind=r["kind"], name=r["source"].split("/")[-1], right=right, reg=r["registered"], rot=a, tr=t, time_ms=r["time_ms"],
               n_s=len(S), n_t=len(T), sp_s=spacing(S)/scale, sp_t=spacing(T)/scale, chosen=r["chosen"],
               cands=[(c["method"], c["score"]) for c in r["candidates"]])
    for d in (0.005, 0.01, 0.02, 0.04, 0.08):
        row[f"fs{d}"] = float((ds < d).mean()); row[f"ft{d}"] = float((dt < d).mean())
    sp = max(row["sp_s"], row["sp_t"])
    for k in (1, 1.5, 2, 3, 4, 6, 8, 16, 32):
        row[f"ks{k}"] = float((ds < k*sp).mean()); row[f"kt{k}"] = float((dt < k*sp).mean())
    row["med_s"] = float(np.median(ds)); row["med_t"] = float(np.median(dt))
    rows.append(row)
json.dump(rows, open(sys.argv[2], "w"))
print(len(rows))
