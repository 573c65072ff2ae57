"""examples/dask_register.py: a Registrar mapped over pairs on a Dask LocalCluster of 2 worker
processes returns the transforms of the single-process path."""

import importlib.util

import numpy as np

import rgm
from conftest import REPO, moved, pose, shape


def _example():
    path = REPO / "python" / "examples" / "dask_register.py"
    spec = importlib.util.spec_from_file_location("dask_register", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_local_dask_cluster_gives_the_single_process_transforms(data):
    from distributed import Client

    example = _example()
    pairs = []
    for k, (category, number) in enumerate([("airplane", 627), ("chair", 890), ("car", 198), ("lamp", 125)]):
        points = shape(data, category, number)
        pairs.append((points, moved(points, pose((10 * k - 15, 25 - 5 * k, 5 * k), (0.1 * k, -0.2, 0.05 * k)))))
    registrar = rgm.Registrar()
    with example.local_cluster(2) as cluster, Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        found = example.register_on_cluster(client, registrar, pairs)
    assert len(found) == len(pairs)
    for (source, target), result in zip(pairs, found):
        assert isinstance(result, rgm.RegistrationResult) and result.method == "auto+refine"
        alone = registrar.register(source, target)
        np.testing.assert_array_equal(result.transformation, alone.transformation)
        np.testing.assert_array_equal(result.correspondences, alone.correspondences)
        assert [c.method for c in result.candidates] == [c.method for c in alone.candidates]
