"""The rivals of each result of run.py (docs/confidence.md, "No rival"): each other candidate that
scores at least 0.7 of the chosen one, with how far apart they are, its share of the score, and
how both coincide in the unit-sphere frame (0.02 / 0.08) and in point spacings (1.5 / 16).

    python tools/confidence/rivals.py RUN.jsonl FEATURES.json [FEATURES.json ...]
"""
import json, sys, numpy as np, open3d as o3d, gzip, tempfile, os
def pc(x): return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(x))
cache={}
def load(path):
    if path in cache: return cache[path]
    if path.endswith(".gz"):
        tmp = tempfile.NamedTemporaryFile(suffix=".ply", delete=False); tmp.write(gzip.open(path).read()); tmp.close()
        p = o3d.io.read_point_cloud(tmp.name); os.unlink(tmp.name)
    else: p = o3d.io.read_point_cloud(path)
    cache[path]=np.asarray(p.points); return cache[path]
def coinc(S,T,near,far):
    d=np.concatenate([np.asarray(pc(S).compute_point_cloud_distance(pc(T))),np.asarray(pc(T).compute_point_cloud_distance(pc(S)))]); f=(d<far).sum(); return (d<near).sum()/max(f,1)
def diff(A,B):
    A=np.array(A);B=np.array(B);D=np.linalg.inv(A)@B; return np.degrees(np.arccos(np.clip((np.trace(D[:3,:3])-1)/2,-1,1))), np.linalg.norm(A[:3,3]-B[:3,3])
feat={}
for f in sys.argv[2:]:
    for r in json.load(open(f)): feat[(r['kind'],r['name'])]=r
rng=np.random.default_rng(0)
for line in open(sys.argv[1]):
    r=json.loads(line); c=[x for x in r['candidates'] if x['score'] is not None]
    fr=feat.get((r['kind'],r['source'].split('/')[-1]))
    if len(c)<2: continue
    ch=[x for x in c if x['method']==r['chosen']][0]
    for o in c:
        if o is ch: continue
        ratio=o['score']/ch['score']
        if ratio<0.7: continue
        S,T=load(r['source']),load(r['target'])
        scale = max(np.linalg.norm(S - S.mean(0), axis=1).max(), np.linalg.norm(T - T.mean(0), axis=1).max())
        if scale<1.5: scale=1.0
        S=S[rng.choice(len(S),min(len(S),20000),replace=False)]; T=T[rng.choice(len(T),min(len(T),20000),replace=False)]
        M=np.array(o['transform']); Sm=(S@M[:3,:3].T+M[:3,3])/scale
        M2=np.array(ch['transform']); Sc=(S@M2[:3,:3].T+M2[:3,3])/scale
        sp=max(fr['sp_s'],fr['sp_t'])
        a,t=diff(ch['transform'],o['transform'])
        print('%-5s right=%d reg=%d ang=%6.1f dt=%.3f ratio=%.3f rivalco=%.2f chosenco=%.2f rivalsp=%.2f chosensp=%.2f %s'%(fr['kind'],fr['right'],fr['reg'],a,t/scale,ratio,coinc(Sm,T/scale,.02,.08),coinc(Sc,T/scale,.02,.08),coinc(Sm,T/scale,1.5*sp,16*sp),coinc(Sc,T/scale,1.5*sp,16*sp),fr['name']),flush=True)
