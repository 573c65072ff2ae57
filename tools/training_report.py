#!/usr/bin/env python3
"""Writes a training run's learning curve to docs/training/NAME/curve.svg and prints a Markdown
summary of the run folder's record (config.json, state.json, log.jsonl; the run folder is
committed under runs/ while it trains and is the one copy of those files; a finished run's
folder leaves the working tree and stays in the history, from where it is written out first).

    python3 tools/training_report.py runs/partial-fast-200 partial-fast-200 > docs/training/partial-fast-200/README.md
    # a finished run, written out of the history into a scratch folder, named as it was:
    git archive a6842d0 runs/partial-fast | tar -x -C /tmp/scratch
    (cd /tmp/scratch && python3 "$OLDPWD/tools/training_report.py" runs/partial-fast partial-fast) \
        > docs/training/partial-fast/README.md

Standard library only. The numbers are the run's own log lines, unchanged.
"""

import json
import sys
from pathlib import Path


def load(run: Path):
    config = json.loads((run / "config.json").read_text())
    state = json.loads((run / "state.json").read_text())
    log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines() if line]
    return config, state, log


def svg_curve(train, val, width=640, height=300, pad=48):
    """Training loss per checkpoint and validation loss per epoch against pairs seen."""
    points = [(r["pairs_seen"], r["loss"]) for r in train] + [(r["pairs_seen"], r["loss"]) for r in val]
    xmax = max(p[0] for p in points)
    lo, hi = min(p[1] for p in points), max(p[1] for p in points)
    span = (hi - lo) or 1.0

    def xy(p):
        x = pad + (width - 2 * pad) * p[0] / xmax
        y = height - pad - (height - 2 * pad) * (p[1] - lo) / span
        return f"{x:.1f},{y:.1f}"

    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'font-family="sans-serif" font-size="12">',
        f'<rect width="{width}" height="{height}" fill="white"/>',
        f'<line x1="{pad}" y1="{height - pad}" x2="{width - pad}" y2="{height - pad}" stroke="black"/>',
        f'<line x1="{pad}" y1="{pad}" x2="{pad}" y2="{height - pad}" stroke="black"/>',
        f'<text x="{width / 2}" y="{height - 12}" text-anchor="middle">training pairs seen (max {xmax})</text>',
        f'<text x="8" y="{pad - 12}">BCE loss per pair ({lo:.3f} – {hi:.3f})</text>',
        f'<text x="{pad - 4}" y="{height - pad}" text-anchor="end">{lo:.2f}</text>',
        f'<text x="{pad - 4}" y="{pad + 4}" text-anchor="end">{hi:.2f}</text>',
        '<polyline fill="none" stroke="#1f77b4" stroke-width="1.5" points="'
        + " ".join(xy((r["pairs_seen"], r["loss"])) for r in train)
        + '"/>',
    ]
    for r in val:
        x, y = xy((r["pairs_seen"], r["loss"])).split(",")
        out.append(f'<circle cx="{x}" cy="{y}" r="4" fill="#d62728"/>')
    out.append(f'<text x="{width - pad}" y="{pad}" text-anchor="end" fill="#1f77b4">training (mean since last checkpoint)</text>')
    out.append(f'<text x="{width - pad}" y="{pad + 16}" text-anchor="end" fill="#d62728">validation (after each epoch)</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def main():
    run, name = Path(sys.argv[1]), sys.argv[2]
    config, state, log = load(run)
    dest = Path(__file__).resolve().parent.parent / "docs" / "training" / name
    dest.mkdir(parents=True, exist_ok=True)
    train = [r for r in log if r["kind"] == "train"]
    val = [r for r in log if r["kind"] == "validation"]
    (dest / "curve.svg").write_text(svg_curve(train, val))
    net = config["network"]
    print(f"# Training run `{name}`\n")
    print(f"Setting **{config['setting']}**{' (unseen categories)' if config['unseen'] else ''}, network "
          f"DGCNN {'-'.join(map(str, net['dgcnn']))}, edge {net['edge']}, Q {net['q']}, FF {net['ff']}, "
          f"K {net['k']}, L {net['blocks']}; matching on {config['match_points'] or 'all'} points per cloud; "
          f"{config['optimizer']} lr {config['lr']} (×{config['gamma']} at epochs {config['milestones']}), "
          f"batch {config['batch']}, {config['workers']} workers. Full configuration: `{run}/config.json`.\n")
    ablation = {"Full": "Var2 (no transformer: the fully connected graph without self-loops)"}.get(net.get("edges"))
    if net.get("scoring") == "Var1":
        ablation = "Var1 (no affinity matrix or instance norm: squared feature distances into the Sinkhorn)"
    if ablation:
        print(f"Ablation: **{ablation}**, spec §2.7.\n")
    if config.get("init"):
        print(f"Started from the weights `{config['init']}` (fine-tuning; `rgm train --init`), not from "
              f"the seeded initialisation: the pairs below are this run's only.\n")
    print(f"State when this page was written: {state['epoch']} epochs and {state['batch']} batches of "
          f"{config['epochs']} done, {state['pairs_seen']} training pairs seen in {state['seconds'] / 3600:.2f} h "
          f"of training and validation (`{run}/state.json`).\n")
    print("![learning curve](curve.svg)\n")
    print("## Validation after each epoch\n")
    if val:
        print("| epoch | pairs seen | pairs (sample) | loss | matching accuracy | MIE(R) ° | MIE(t) | recall "
              "| recall after refinement |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in val:
            # Validations logged before rgm measured the refined recall have none; those logged
            # before the refinement became trimmed point-to-plane ICP name no `refined_with`.
            refined = f"{100 * r['recall_refined']:.2f} %" if "recall_refined" in r else "—"
            if "recall_refined" in r and r.get("refined_with", "point_to_point_icp") == "point_to_point_icp":
                refined += " ¹"
            # Records written before `rgm train --val-sample` validated on the first shapes.
            sample = r.get("sample", "first")
            print(f"| {r['epoch'] + 1} | {r['pairs_seen']} | {r['pairs']} ({sample}) | {r['loss']:.4f} | "
                  f"{100 * r['match_accuracy']:.2f} % | {r['mie_r_deg']:.2f} | {r['mie_t']:.4f} | "
                  f"{100 * r['recall']:.2f} % | {refined} |")
        if any("recall_refined" in r and "refined_with" not in r for r in val):
            print("\n¹ Point-to-point ICP (pairs closer than 0.1, 30 iterations), rgm's refinement until "
                  "2026-11-23; the others: trimmed point-to-plane ICP, coarse to fine (`rgm_registration::methods::refine`, "
                  "what `--refine` does).")
        print("\n`first`: the first validation shapes of the split, which is ordered by category (300 of "
              "the full split are five categories, airplane to bookshelf); `spread`: shapes spread evenly "
              "over the split (`rgm train --val-sample`). Recalls on the two samples are not comparable; the "
              "first validation on a new sample becomes the run's best.")
    else:
        print("No epoch finished yet.")
    print("\n## Training loss (mean over the batches since the previous checkpoint)\n")
    print("| epoch | batch | pairs seen | lr | loss | hours |")
    print("|---|---|---|---|---|---|")
    step = max(1, len(train) // 25)
    for r in train[::step] + ([train[-1]] if train and (len(train) - 1) % step else []):
        print(f"| {r['epoch'] + 1} | {r['batch']}/{r['batches']} | {r['pairs_seen']} | {r['lr']:g} | "
              f"{r['loss']:.4f} | {r['seconds'] / 3600:.2f} |")
    print(f"\nEvery line is in `{run}/log.jsonl`. Produced by `python3 tools/training_report.py {run} {name}`.")


if __name__ == "__main__":
    main()
