#!/usr/bin/env python3
"""The whole-overlap rule of the cascade (`rgm_registration::check::Acceptance::whole`) read off dumps of
`default_study --study cascade --dump FILE` (one per setting).

Usage: python3 tools/cascade_whole.py SETTING=FILE [SETTING=FILE ...]

With the score threshold and turned-share limit of `TUNED.accept` fixed, FGR's result is also taken when
its overlap at a looser distance (the dump's last columns: 0.03, 0.04, 0.05; the score's own 0.02
first) reaches W. Printed per (distance, W) and setting: recall, share off by more than 45 degrees,
candidate time per pair, share of pairs that run the network, and the pairs whose outcome differs
from the rule without it (docs/training/default-study/cascade-whole-overlap.md).
"""
import sys

SCORE, TURNED = 0.55, 0.3
DISTANCES = [0.02, 0.03, 0.04, 0.05]
WHOLES = [float("inf"), 1.99, 1.98, 1.97, 1.96, 1.95, 1.94, 1.92, 1.9, 1.85, 1.8]


def read(path):
    rows = []
    for line in open(path):
        f = line.split()
        fgr = (float(f[1]), f[2] == "true", float(f[3]), float(f[4]))
        rgm = (float(f[5]), f[6] == "true", float(f[7]), float(f[8]))
        loose = [float(f[1])] + [float(x) for x in f[10:13]]
        rows.append((int(f[0]), fgr, rgm, float(f[9]), loose))
    return rows


def simulate(rows, k, whole):
    picks, ms, net = [], 0.0, 0
    for _, fgr, rgm, turned, loose in rows:
        ms += fgr[3]
        if fgr[0] >= SCORE and (turned <= TURNED or loose[k] >= whole):
            pick = fgr
        else:
            net += 1
            ms += rgm[3]
            pick = rgm if rgm[0] > fgr[0] else fgr
        picks.append(pick)
    return picks, ms, net


sets = [(a.split("=", 1)[0], read(a.split("=", 1)[1])) for a in sys.argv[1:]]
print("| distance | W | " + " | ".join(f"{s}: recall / > 45° / ms / network / changed" for s, _ in sets) + " |")
print("|---:|---:|" + "---:|" * len(sets))
for k, d in enumerate(DISTANCES):
    for w in WHOLES:
        if w == float("inf") and k > 0:
            continue
        cells = []
        for _, rows in sets:
            base, _, _ = simulate(rows, 0, float("inf"))
            picks, ms, net = simulate(rows, k, w)
            n = len(rows)
            recall = 100 * sum(p[1] for p in picks) / n
            wild = 100 * sum(p[2] > 45 for p in picks) / n
            changed = sum((p[1], p[2] > 45) != (b[1], b[2] > 45) for p, b in zip(picks, base))
            cells.append(f"{recall:.2f} % / {wild:.2f} % / {ms / n:.0f} / {100 * net / n:.1f} % / {changed}")
        print(f"| {d} | {w} | " + " | ".join(cells) + " |")
