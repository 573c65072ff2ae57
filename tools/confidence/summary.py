"""Per kind of pair: how many results are right, and how many right and wrong ones `rgm
register` reported as registered (docs/confidence.md), from features.py's output.

    python tools/confidence/summary.py FEATURES.json [FEATURES.json ...]
"""
import collections, json, sys

table = collections.defaultdict(collections.Counter)
for path in sys.argv[1:]:
    for r in json.load(open(path)):
        row = table[r["kind"]]
        row["pairs"] += 1
        row["right"] += r["right"]
        row[("right" if r["right"] else "wrong") + (" registered" if r["reg"] else " doubted")] += 1
        row["time_ms"] += r["time_ms"]
columns = ["pairs", "right", "right registered", "right doubted", "wrong registered", "wrong doubted"]
print("| kind | " + " | ".join(columns) + " | mean time (ms) |")
print("|---|" + "---:|" * (len(columns) + 1))
for kind, row in table.items():
    print(f"| {kind} | " + " | ".join(str(row[c]) for c in columns) + f" | {row['time_ms'] / row['pairs']:.0f} |")
