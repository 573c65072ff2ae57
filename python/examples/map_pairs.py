"""Register many pairs at once with concurrent.futures, and score them as ``rgm eval`` does.

    python examples/map_pairs.py DATA_DIR [PAIRS]     # ModelNet40 .npy tree, e.g. ../shared/data/modelnet40_npy1024

Threads share one Registrar (rgm releases the GIL while it works); processes each unpickle
the Registrar once and load the network once. Any start method works: "spawn" (used here, the
default on macOS and Windows) starts clean processes, Linux's default "fork" copies this one
(rgm starts its threads again in each). The same ``map`` works with Dask, Ray or Spark, which
pickle the function and its arguments the same way.
"""

import concurrent.futures
import multiprocessing
import sys
import time

import numpy as np

import rgm


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    limit = int(sys.argv[2]) if len(sys.argv) > 2 else 8
    pairs = rgm.modelnet_pairs(sys.argv[1], setting="partial", limit=limit)
    sources = [pair.source for pair in pairs]
    targets = [pair.target for pair in pairs]
    # rgm register's defaults: RGM with the built-in model and FGR, each refined, the better kept
    registrar = rgm.Registrar()

    pools = {
        "threads": concurrent.futures.ThreadPoolExecutor(max_workers=2),
        "processes": concurrent.futures.ProcessPoolExecutor(
            max_workers=2, mp_context=multiprocessing.get_context("spawn")
        ),
    }
    for name, pool in pools.items():
        start = time.perf_counter()
        with pool:
            results = list(pool.map(registrar.register, sources, targets))
        seconds = time.perf_counter() - start
        scores = [
            rgm.metrics(r.rotation, r.translation, p.rotation, p.translation, p.source, p.target)
            for r, p in zip(results, pairs)
        ]
        recall = np.mean([s.recall for s in scores])
        mie = np.mean([s.mie_r_deg for s in scores])
        print(f"{name:>9}: {len(pairs)} pairs in {seconds:.1f} s, recall {recall:.0%}, "
              f"mean MIE(R) {mie:.2f}°")


if __name__ == "__main__":
    main()
