"""Register pairs on a Dask cluster: a Registrar mapped over pairs with dask.distributed.

    python examples/dask_register.py DATA_DIR [PAIRS]    # ModelNet40 .npy tree, e.g. ../shared/data/modelnet40_npy1024

A Registrar pickles as its settings, so Dask ships it with each task and every worker process
unpickles it into one cached Registrar, loading the network once. Results pickle too and come
back as rgm.RegistrationResult. This starts a LocalCluster of 2 worker processes of one thread
each (a registration runs on one core); on a real cluster, give Client the scheduler's address
instead. Needs ``pip install dask distributed``.
"""

import sys
import time

import numpy as np
from distributed import Client, LocalCluster

import rgm


def register_on_cluster(client, registrar, pairs):
    """``registrar.register`` on each (source, target) of ``pairs``, run by the cluster's
    workers; the results in the order of ``pairs``."""
    sources = [source for source, _ in pairs]
    targets = [target for _, target in pairs]
    # pure=False: no hashing of the clouds to name the tasks, which are all different anyway.
    futures = client.map(registrar.register, sources, targets, pure=False)
    return client.gather(futures)


def local_cluster(workers=2):
    """A LocalCluster of ``workers`` processes of one thread each, without a dashboard."""
    return LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
    )


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    limit = int(sys.argv[2]) if len(sys.argv) > 2 else 8
    pairs = rgm.modelnet_pairs(sys.argv[1], setting="partial", limit=limit)
    # rgm register's defaults: RGM with the built-in model and FGR, each refined, the better kept
    registrar = rgm.Registrar()
    with local_cluster() as cluster, Client(cluster) as client:
        start = time.perf_counter()
        results = register_on_cluster(client, registrar, [(p.source, p.target) for p in pairs])
        seconds = time.perf_counter() - start
    scores = [
        rgm.metrics(r.rotation, r.translation, p.rotation, p.translation, p.source, p.target)
        for r, p in zip(results, pairs)
    ]
    recall = np.mean([s.recall for s in scores])
    print(f"{len(pairs)} pairs on 2 Dask workers in {seconds:.1f} s, recall {recall:.0%}")


if __name__ == "__main__":
    main()
