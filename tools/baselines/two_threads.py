#!/usr/bin/env python3
"""One pair on two threads against one (issue 57): `rgm --threads T register A B` on four bunny
pairs, one process a pair, wall time from a timer around each process (its start and the
reading of both files included), T = 1 and 2, builds alternated round by round.

    python3 tools/baselines/two_threads.py [RGM ...]    # default: target/release/rgm
    ROUNDS=10 python3 tools/baselines/two_threads.py BEFORE AFTER

Stop other jobs first (the training queue: kill -STOP its pids; kill -CONT after). Prints per
build the mean over the pairs of each pair's fastest round at 1 and 2 threads and their ratio,
each pair's own, and each round's ratio with their median: on a shared machine the rounds
spread widely, so compare builds only within one run.
"""

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BUNNY = ROOT.parent / "shared" / "data" / "stanford" / "bunny"
PAIRS = [("bun000", "bun045"), ("bun045", "bun090"), ("bun000", "bun315"), ("bun180", "bun270")]


def seconds(rgm: str, threads: int, source: str, target: str) -> float:
    """Wall time of one registration process. Exit status 1 (a result rgm does not trust) is a
    registration like any other; anything else is an error."""
    files = [str(BUNNY / f"{name}.ply.gz") for name in (source, target)]
    start = time.perf_counter()
    done = subprocess.run([rgm, "--threads", str(threads), "register", *files],
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    elapsed = time.perf_counter() - start
    if done.returncode not in (0, 1):
        sys.exit(f"{rgm} on {source} -> {target}: exit status {done.returncode}")
    return elapsed


def main() -> None:
    builds = sys.argv[1:] or [str(ROOT / "target" / "release" / "rgm")]
    rounds = int(os.environ.get("ROUNDS", "5"))
    fastest: dict = {}  # (build, threads, pair) -> seconds
    per_round: dict = {}  # (build, threads, round) -> [seconds of each pair]
    for r in range(rounds):
        for build in builds:
            for threads in (1, 2):
                for pair in PAIRS:
                    s = seconds(build, threads, *pair)
                    key = (build, threads, pair)
                    fastest[key] = min(fastest.get(key, float("inf")), s)
                    per_round.setdefault((build, threads, r), []).append(s)
    for build in builds:
        one = statistics.mean(fastest[(build, 1, p)] for p in PAIRS)
        two = statistics.mean(fastest[(build, 2, p)] for p in PAIRS)
        print(f"{build}: 1 thread {one * 1e3:.1f} ms, 2 threads {two * 1e3:.1f} ms, "
              f"ratio {two / one:.3f} (each pair's fastest of {rounds} rounds)")
        for p in PAIRS:
            a, b = fastest[(build, 1, p)], fastest[(build, 2, p)]
            print(f"  {p[0]} -> {p[1]}: {a * 1e3:.0f} ms, {b * 1e3:.0f} ms, {b / a:.3f}")
        ratios = [sum(per_round[(build, 2, r)]) / sum(per_round[(build, 1, r)])
                  for r in range(rounds)]
        print("  rounds:", " ".join(f"{x:.3f}" for x in ratios),
              f"median {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
