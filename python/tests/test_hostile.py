"""Issue 27's Python cases: a process pool forked after a registration, Ctrl-C during one, a far
outlier, clouds without overlap, and the docs of the default."""

import json
import multiprocessing
import os
import pathlib
import signal
import threading
import time
import weakref

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


def test_ctrl_c_interrupts_a_registration_at_once(airplane, ctrl_c):
    # Case 11: KeyboardInterrupt came only when the call ended (21.6 s later). A dense pair
    # (2,000 copies of each point, jittered: 1,000 were done in under a second on two cores)
    # keeps the default method busy for seconds; Ctrl-C 0.2 s into it ends the call long before
    # the registration would have.
    rng = np.random.default_rng(0)
    dense = np.repeat(airplane.astype(np.float64), 2000, axis=0) + rng.normal(0, 0.003, (2000 * len(airplane), 3))
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


def test_register_many_keeps_the_results_of_the_pairs_that_did_not_fail(airplane):
    # Issue 44, D8: one failing pair among many raised, and every result was lost.
    registrar = rgm.Registrar(method="rgm", refine=False)
    good = (airplane, moved(airplane, KNOWN))
    with pytest.raises(rgm.PairsError) as raised:
        registrar.register_many([good, (airplane[:5], airplane[:5]), good])
    assert isinstance(raised.value, RuntimeError)
    results, failed = raised.value.results, raised.value.errors
    assert results[1] is None and [i for i, _ in failed] == [1]
    assert "needs at least" in failed[0][1]
    alone = registrar.register(*good).transformation
    for result in (results[0], results[2]):
        np.testing.assert_array_equal(result.transformation, alone)


def test_register_many_takes_a_generator_pair_by_pair(airplane):
    # D8: a generator was collected whole before the first pair ran (every cloud in memory at
    # once). Each yielded cloud is counted while it lives.
    alive = [0, 0]  # now, most at once

    def gone():
        alive[0] -= 1

    def pairs(count):
        for k in range(count):
            source = moved(airplane, pose((k, 0, 0), (0, 0, 0)))
            target = moved(airplane, KNOWN)
            for cloud in (source, target):
                alive[0] += 1
                weakref.finalize(cloud, gone)
            alive[1] = max(alive[1], alive[0])
            yield source, target

    results = rgm.Registrar(method="icp").register_many(pairs(40))
    assert len(results) == 40
    # The pair being handed over and the generator's own last pair, on any number of cores
    # (all 80 clouds, collected whole).
    assert alive[1] <= 4, alive


def test_register_many_writes_and_resumes_rgm_s_json_lines(airplane, tmp_path):
    # D8: register_many writes the resumable file of `rgm register --pairs --output`.
    registrar = rgm.Registrar(method="icp")
    pairs = [(airplane, moved(airplane, pose((5 * k, 0, 0), (0, 0, 0)))) for k in range(3)]
    output = tmp_path / "out.jsonl"
    assert registrar.register_many(pairs[:2], output=output) == {
        "registered": 2, "not_registered": 0, "failed": 0, "skipped": 0}
    assert registrar.register_many(iter(pairs), output=output) == {
        "registered": 1, "not_registered": 0, "failed": 0, "skipped": 2}
    header, *lines = [json.loads(line) for line in output.read_text().splitlines()]
    assert header["rgm_many_pairs"] == 1 and header["settings"]["method"] == "icp"
    assert sorted(line["source"] for line in lines) == [f"pairs[{k}].source" for k in range(3)]
    for line in lines:
        k = int(line["source"][6])
        expected = registrar.register(*pairs[k]).transformation
        np.testing.assert_allclose(line["transform"], expected, atol=1e-12)
    # Another method's file, and a file that is not rgm's, are refused and left as they are.
    before = output.read_text()
    with pytest.raises(ValueError, match="its results were made with method \"icp\""):
        rgm.Registrar(method="fgr").register_many(pairs, output=output)
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    with pytest.raises(ValueError, match="notes.txt:1: not an output of rgm's pair lists"):
        registrar.register_many(pairs, output=notes)
    assert (output.read_text(), notes.read_text()) == (before, "my notes")


def test_names_of_before_issue_58_still_work(airplane, tmp_path):
    # Issue 58: rgm.BatchError is rgm.PairsError for one release, and a register_many file
    # written before it (header "rgm_batch", the method named fgr+icp) resumes, its header
    # rewritten as today's.
    assert rgm.BatchError is rgm.PairsError
    registrar = rgm.Registrar(method="fgr")
    pairs = [(airplane, moved(airplane, pose((5 * k, 0, 0), (0, 0, 0)))) for k in range(2)]
    output = tmp_path / "out.jsonl"
    assert registrar.register_many(pairs, output=output)["failed"] == 0
    header, rest = output.read_text().split("\n", 1)
    assert '"method":"fgr+refine"' in header and '"rgm_many_pairs":1' in header, header
    old = header.replace("rgm_many_pairs", "rgm_batch").replace("fgr+refine", "fgr+icp")
    rest = rest.replace("fgr+refine", "fgr+icp")
    output.write_text(old + "\n" + rest)
    assert registrar.register_many(pairs, output=output)["skipped"] == 2
    assert output.read_text() == header + "\n" + rest


def test_options_are_what_they_say(airplane):
    # Issue 44's Python minor cases: accept in the repr and in rgm.register, refine a bool only,
    # big-endian float64 clouds taken as they are.
    assert repr(rgm.Registrar(accept=0.5)) == "rgm.Registrar(method='auto', refine=True, accept=0.5)"
    for call in (lambda: rgm.Registrar(refine="no"), lambda: rgm.register(airplane, airplane, refine="no")):
        with pytest.raises(TypeError, match="refine must be True or False, got 'no'"):
            call()
    target = moved(airplane, KNOWN)
    both = rgm.register(airplane, target, accept=float("inf"), match_points=64)
    assert [c.score is not None for c in both.candidates] == [True, True]
    native = rgm.register(airplane, target, method="icp")
    swapped = rgm.register(airplane.astype(">f8"), target.astype(">f8"), method="icp")
    np.testing.assert_array_equal(swapped.transformation, native.transformation)


def _weights_scaled(source: pathlib.Path, target: pathlib.Path, factor: float) -> None:
    """`source`'s safetensors weights (BF16 or F32), every tensor times `factor` (a power of
    two, exact in both), written to `target`."""
    raw = source.read_bytes()
    size = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8 : 8 + size])
    data = bytearray(raw[8 + size :])
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        start, end = entry["data_offsets"]
        chunk = bytes(data[start:end])
        if entry["dtype"] == "BF16":
            values = (np.frombuffer(chunk, dtype="<u2").astype("<u4") << 16).view("<f4")
            scaled = ((values * np.float32(factor)).view("<u4") >> 16).astype("<u2")
            data[start:end] = scaled.tobytes()
        elif entry["dtype"] == "F32":
            data[start:end] = (np.frombuffer(chunk, dtype="<f4") * np.float32(factor)).tobytes()
    target.write_bytes(raw[: 8 + size] + bytes(data))


def test_weights_rewritten_at_the_same_path_are_loaded_again(airplane, tmp_path):
    # Issue 59, E9: the network was cached by the path string, so after the file at PATH was
    # rewritten, register(weights=PATH) gave the old weights' results, silently.
    builtin = pathlib.Path(__file__).resolve().parents[2] / "crates/rgm-model/weights/partial-fast.safetensors"
    path = tmp_path / "model.safetensors"
    path.write_bytes(builtin.read_bytes())
    source = moved(airplane, KNOWN)
    first = rgm.register(source, airplane, method="rgm", refine=False, weights=path, preset="fast")
    _weights_scaled(builtin, tmp_path / "next.safetensors", 0.5)
    os.replace(tmp_path / "next.safetensors", path)
    again = rgm.register(source, airplane, method="rgm", refine=False, weights=path, preset="fast")
    fresh = rgm.Registrar(method="rgm", refine=False, weights=path, preset="fast").register(source, airplane)
    # The halved network still finds the pose, from other matches: its fitness tells them apart.
    assert again.fitness != first.fitness
    assert again.fitness == fresh.fitness
    np.testing.assert_array_equal(again.transformation, fresh.transformation)
