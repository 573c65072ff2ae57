"""Mean `rgm register` time of two binaries on the same pairs, run interleaved (A, B, A, B, …)
so that a busy machine slows both alike.

    python tools/confidence/ab_time.py RGM_A RGM_B PAIRS.json KIND EVERY [-- rgm register options]

PAIRS.json is a make_pairs.py list; KIND picks its pairs (stan, room, mn, …), EVERY keeps every
EVERY-th of them.
"""
import json, subprocess, sys

args = sys.argv[1:]
extra = args[args.index("--") + 1:] if "--" in args else []
args = args[: args.index("--")] if "--" in args else args
a, b, pairs, kind, every = args
pairs = [p for p in json.load(open(pairs)) if p["kind"] == kind][:: int(every)]
total = {a: 0.0, b: 0.0}
for p in pairs:
    for binary in (a, b):
        out = subprocess.run([binary, "register", p["source"], p["target"], "--json", *extra],
                             capture_output=True, text=True).stdout
        total[binary] += json.loads(out)["time_ms"]
for binary, ms in total.items():
    print(f"{binary}: {ms / len(pairs):.0f} ms a pair over {len(pairs)} pairs")
