"""Issue 27's Python cases: a process pool forked after a registration, Ctrl-C during one, a far
outlier, clouds without overlap, and the docs of the default."""

import multiprocessing
import os
import pathlib
import signal
import threading
import time

import numpy as np
import pytest

import rgm
from conftest import errors, moved, pose, shape

KNOWN = pose((20, 10, 30), (0.2, -0.1, 0.3))


@pytest.fixture(scope="module")
def airplane(data):
    return shape(data, "airplane", 627)


def test_a_fork_pool_after_a_registration_registers(airplane):
    # Case 2: with Linux's default start method, every worker hung for good once the parent had
    # registered (the parent's thread pool has no threads in a forked child).
    registrar = rgm.Registrar(method="rgm", refine=False)
    pairs = [(airplane, moved(airplane, KNOWN)), (airplane, moved(airplane, pose((5, -10, 15), (0, 0.1, 0))))]
    serial = [registrar.register(s, t).transformation for s, t in pairs]
    with multiprocessing.get_context("fork").Pool(2) as pool:
        # The timeout turns a hang into a failure; leaving the block kills the workers.
        found = pool.starmap_async(registrar.register, pairs).get(timeout=600)
    for expected, result in zip(serial, found):
        np.testing.assert_array_equal(result.transformation, expected)


def test_ctrl_c_interrupts_a_registration_at_once(airplane):
    # Case 11: KeyboardInterrupt came only when the call ended (21.6 s later). A dense pair
    # (1,000 copies of each point, jittered) keeps the default method busy for seconds; Ctrl-C
    # 0.2 s into it ends the call long before the registration would have.
    rng = np.random.default_rng(0)
    dense = np.repeat(airplane.astype(np.float64), 1000, axis=0) + rng.normal(0, 0.003, (1000 * len(airplane), 3))
    target = moved(dense, KNOWN)
    registrar = rgm.Registrar()
    start = time.perf_counter()
    registrar.register(dense, target)
    whole = time.perf_counter() - start
    assert whole > 1.0, f"the registration takes {whole:.2f} s: too short to interrupt"
    timer = threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT))
    start = time.perf_counter()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        registrar.register(dense, target)
    interrupted = time.perf_counter() - start
    timer.join()
    assert interrupted < whole / 2, (interrupted, whole)


def test_a_far_outlier_leaves_the_transform_right(airplane):
    # Case 1: one stray point at 1e5 in each cloud gave a rotation 152° wrong, fitness 0.999.
    source = airplane.astype(np.float64)
    target = moved(source, KNOWN)
    source[3] = (1e5, 1e5, -1e5)
    target[500] = (-1e5, 0, 1e5)
    result = rgm.register(source, target)
    assert result.registered and result.reason is None
    angle, shift = errors(result.transformation, KNOWN)
    assert angle < 2.0 and shift < 0.02, (angle, shift)
    assert result.fitness < 1.0


def test_clouds_without_overlap_are_not_registered(airplane):
    # A 10 × 10 × 10 grid 0.2 apart lies nowhere on the airplane: reported as not registered,
    # with the reason, instead of a transform given with confidence.
    grid = np.stack(np.meshgrid(*[np.arange(10) * 0.2] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    result = rgm.register(airplane, grid)
    assert not result.registered
    assert "overlaps too little" in result.reason


def test_the_docs_name_the_default_method():
    # Case 14: help(rgm.register) and the pool example said the default was the network alone.
    assert "the RGM network with the model built into rgm and FGR" in " ".join(rgm.register.__doc__.split())
    example = pathlib.Path(__file__).resolve().parents[1] / "examples" / "map_pairs.py"
    assert "RGM with the built-in model and FGR" in example.read_text()


def test_a_registration_beyond_the_memory_raises_memory_error(airplane):
    # Case 5: the interpreter aborted instead of raising MemoryError. Every point of 60,000
    # matched would need terabytes: refused before it starts.
    big = np.repeat(airplane.astype(np.float64), 60, axis=0) + np.linspace(0, 1e-3, 60 * len(airplane))[:, None]
    with pytest.raises(MemoryError, match="would need about"):
        rgm.Registrar(method="rgm", match_points=0).register(big, big)


def _scan(name: str) -> np.ndarray:
    """The (N, 3) points of a Stanford bunny range scan (gzipped ASCII PLY), or a skip."""
    import gzip

    path = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data" / "stanford" / "bunny" / name
    if not path.is_file():
        pytest.skip(f"no Stanford scan at {path}")
    lines = gzip.open(path, "rt").read().splitlines()
    count = next(int(line.split()[2]) for line in lines if line.startswith("element vertex"))
    start = lines.index("end_header") + 1
    return np.array([[float(v) for v in line.split()[:3]] for line in lines[start : start + count]])


def test_a_far_outlier_in_a_real_scan_leaves_the_transform_right():
    # Case 1 beside a real scan: the bunny's first scan (metres, about 40,000 points) and its
    # moved copy, one stray return at 1e5 in each.
    source = _scan("bun000.ply.gz")
    truth = pose((20, 10, 30), (0.02, -0.01, 0.03))
    target = moved(source, truth)
    source[7] = (1e5, -1e5, 1e5)
    target[100] = (0, 1e5, -1e5)
    result = rgm.register(source, target)
    assert result.registered, result.reason
    angle, shift = errors(result.transformation, truth)
    assert angle < 2.0 and shift < 0.002, (angle, shift)
