"""`rgm register --json` on each pair of a make_pairs.py list, one JSON line per pair (resumes).

    python tools/confidence/run.py RGM PAIRS.json OUT.jsonl [-- rgm register options]
"""
import json, subprocess, sys, numpy as np, pathlib
rgm = sys.argv[1]; pairs = json.load(open(sys.argv[2])); out = pathlib.Path(sys.argv[3])
extra = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
done = {}
if out.exists():
    for l in open(out): r = json.loads(l); done[(r["source"], r["target"])] = r
f = open(out, "a")
for p in pairs:
    key = (p["source"], p["target"])
    if key in done: continue
    cp = subprocess.run([rgm, "register", p["source"], p["target"], "--json", "--threads", "2", *extra], capture_output=True, text=True)
    try: r = json.loads(cp.stdout)
    except Exception: r = {"error": cp.stderr[-300:]}
    r.update(source=p["source"], target=p["target"], kind=p["kind"], gt=p["T"])
    f.write(json.dumps(r) + "\n"); f.flush()
