#!/usr/bin/env python3
"""The cascade's thresholds read off a dump of `default_study --study cascade --dump FILE`.

Usage: python3 tools/cascade_grid.py FILE

For every (score threshold, turned-share limit) on a fine grid: recall, share off by more than 45 degrees,
candidate time per pair and share of pairs that run the network, as the default would give with FGR
first; printed: the cheapest within 0.1 and 0.2 points of running both on every pair
(docs/training/default-study/cascade-1980-validation.md).
"""
import sys
rows=[]
for l in open(sys.argv[1]):
    f=l.split()
    i=int(f[0]); fgr=(float(f[1]),f[2]=='true',float(f[3]),float(f[4])); rgm=(float(f[5]),f[6]=='true',float(f[7]),float(f[8])); turned=float(f[9])
    rows.append((fgr,rgm,turned))
n=len(rows)
def sim(th,tu):
    rec=wild=ms=net=0
    for fgr,rgm,turned in rows:
        ms+=fgr[3]
        if fgr[0]>=th and turned<=tu: pick=fgr
        else:
            net+=1; ms+=rgm[3]; pick=rgm if rgm[0]>fgr[0] else fgr
        rec+=pick[1]; wild+=pick[2]>45
    return 100*rec/n,100*wild/n,ms/n,100*net/n
br,bw,bms,_=sim(float('inf'),0)
print(f"n={n} both: recall {br:.2f} >45 {bw:.2f} ms {bms:.0f}")
res=[]
for th in [x/20 for x in range(0,25)]:
    for tu in [x/20 for x in range(2,21)]+[float('inf')]:
        r,w,ms,net=sim(th,tu); res.append((ms,th,tu,r,w,net))
ok=[x for x in res if x[3]>=br-0.1 and x[4]<=bw+0.1]
ok.sort()
print("cheapest within 0.1 points of both:")
for x in ok[:8]: print("ms %.0f score>=%.2f turned<=%.2f recall %.2f >45 %.2f network %.1f%%"%x)
ok2=[x for x in res if x[3]>=br-0.2 and x[4]<=bw+0.2]; ok2.sort()
print("cheapest within 0.2 points:")
for x in ok2[:5]: print("ms %.0f score>=%.2f turned<=%.2f recall %.2f >45 %.2f network %.1f%%"%x)
