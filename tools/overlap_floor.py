"""The default method's best overlap score against the truth on pairs written by `rgm pairs`:
the evidence behind rgm_model::policy::TUNED.scoring.min_overlap (docs/geom.md, "Far outliers and extreme
scales"). Plain Python.

    rgm pairs --data DATA --split validation --every 20 --limit 100 --out PAIRS
    python3 tools/overlap_floor.py target/release/rgm PAIRS
"""

import json, subprocess, sys, math
rgm, d = sys.argv[1], sys.argv[2]
m = json.load(open(f"{d}/pairs.json"))
rows = []
for e in m["pairs"]:
    out = subprocess.run([rgm, "register", f"{d}/{e['source']}", f"{d}/{e['target']}", "--json"], capture_output=True, text=True)
    v = json.loads(out.stdout)
    R = [r[:3] for r in v["transform"][:3]]
    G = [r[:3] for r in e["t_target_source"][:3]]
    tr = sum(G[k][i] * R[k][i] for i in range(3) for k in range(3))  # trace(G^T R)
    ang = math.degrees(math.acos(max(-1, min(1, (tr - 1) / 2))))
    score = max(c["score"] for c in v["candidates"] if c["score"] is not None)
    rows.append((score, ang, v["registered"]))
    print(e["index"], f"{score:.3f}", f"{ang:.2f}", v["registered"], flush=True)
ok = [s for s, a, _ in rows if a < 5]
bad = [s for s, a, _ in rows if a >= 5]
print("pairs", len(rows), "right (<5 deg)", len(ok), "lowest score among right", min(ok) if ok else None,
      "wrong", len(bad), "their scores", sorted(bad))
print("not registered", sum(1 for r in rows if not r[2]))
