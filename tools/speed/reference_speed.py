#!/usr/bin/env python3
"""Times the PyTorch reference (`tools/reference/rgm_reference.py`) the way
`cargo run --release -p rgm-model --example speed` times rgm, and prints one JSON line per
configuration: forward (evaluation mode, no autograd), train (training-mode forward, BCE loss,
backward) and the full test-time procedure of spec §4 as the authors run it (2 passes; each
pass runs the network on (X, Y) and on (Y, X), inlier selection, scipy's linear assignment,
cycle consistency, weighted SVD). Random weights, 2 threads (the anchor's setting).

Usage: python3 tools/speed/reference_speed.py --preset paper --what procedure [--points 717] [--reps 3]
Needs torch, numpy, scipy.
"""
import argparse
import json
import math
import os
import resource
import sys
import time

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "reference"))
from rgm_reference import PAPER, RGM, loss_bce  # noqa: E402

PRESETS = {
    "paper": PAPER,
    "fast": dict(PAPER, dgcnn=(16, 16, 32, 64), edge=128, q=128, ff=256),
}


def pair(n, seed=1):
    """n points uniform in the unit ball and their copy at (20°, 10°, 30°), (0.2, −0.1, 0.3), shuffled."""
    rng = np.random.default_rng(seed)
    pts = []
    while len(pts) < n:
        p = rng.uniform(-1, 1, 3)
        if p @ p <= 1:
            pts.append(p)
    x = np.array(pts)
    a, b, c = np.radians([20, 10, 30])
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    order = rng.permutation(n)
    y = (x @ (rx @ ry @ rz).T + [0.2, -0.1, 0.3])[order]
    gt = np.zeros((n, n))
    gt[order, np.arange(n)] = 1
    return x, y, gt


def hard(c):
    """Inlier rows/columns (sum > 0.5), then the maximum-score assignment on them (0/1 matrix)."""
    rows = np.where(c.sum(1) > 0.5)[0]
    cols = np.where(c.sum(0) > 0.5)[0]
    out = np.zeros_like(c)
    if len(rows) and len(cols):
        r, k = linear_sum_assignment(c[np.ix_(rows, cols)], maximize=True)
        out[rows[r], cols[k]] = 1
    return out


def kabsch(x, y, w):
    cx, cy = (w[:, None] * x).sum(0) / w.sum(), (w[:, None] * y).sum(0) / w.sum()
    h = ((x - cx) * w[:, None]).T @ (y - cy)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1, 1, d]) @ u.T
    return r, cy - r @ cx


def procedure(model, x, y, passes=2):
    r_total, t_total = np.eye(3), np.zeros(3)
    for _ in range(passes):
        moved = x @ r_total.T + t_total
        xt, yt = (torch.tensor(a, dtype=torch.float32)[None] for a in (moved, y))
        forward = hard(model(xt, yt)[0].numpy())
        reverse = hard(model(yt, xt)[0].numpy())
        both = forward * reverse.T
        i, j = np.nonzero(both)
        if len(i) < 3:
            break
        r, t = kabsch(moved[i], y[j], np.ones(len(i)))
        r_total, t_total = r @ r_total, r @ t_total + t
    return r_total, t_total


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", choices=sorted(PRESETS), default="paper")
    ap.add_argument("--what", choices=["forward", "train", "procedure"], default="procedure")
    ap.add_argument("--points", type=int, default=717)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    model = RGM(**PRESETS[args.preset])
    x, y, gt = pair(args.points)
    xt, yt = (torch.tensor(a, dtype=torch.float32)[None] for a in (x, y))
    gtt = torch.tensor(gt, dtype=torch.float32)[None]
    seconds = []
    for _ in range(args.reps + 1):
        start = time.perf_counter()
        if args.what == "train":
            model.train()
            model.zero_grad()
            loss_bce(model(xt, yt), gtt).backward()
        else:
            model.eval()
            with torch.no_grad():
                if args.what == "forward":
                    model(xt, yt)
                else:
                    procedure(model, x, y)
        seconds.append(time.perf_counter() - start)
    seconds = seconds[1:]
    print(json.dumps({
        "implementation": "pytorch-reference",
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "preset": args.preset,
        "what": args.what,
        "points": args.points,
        "reps": args.reps,
        "median_s": sorted(seconds)[len(seconds) // 2],
        "seconds": seconds,
        "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }))


if __name__ == "__main__":
    main()
