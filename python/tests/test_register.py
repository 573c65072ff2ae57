"""rgm.register and rgm.Registrar: known poses recovered, inputs checked, threads and processes
agreeing with serial calls, and the same transform as the `rgm register` command."""

import concurrent.futures
import json
import multiprocessing
import pickle
import subprocess
import threading
import time

import numpy as np
import pytest

import rgm
from conftest import errors, moved, pose, shape

# A pose within the benchmark's range (at most 45° per axis, 0.5 per axis).
KNOWN = pose((20, 10, 30), (0.2, -0.1, 0.3))


@pytest.fixture(scope="module")
def airplane(data):
    return shape(data, "airplane", 627)


@pytest.fixture(scope="module")
def registrar():
    return rgm.Registrar()


def test_the_default_recovers_a_known_pose(airplane, registrar):
    target = moved(airplane, KNOWN)
    result = rgm.register(airplane, target)
    assert result.method == "auto+refine" == registrar.name
    assert result.transformation.shape == (4, 4) and result.transformation.dtype == np.float64
    angle, shift = errors(result.transformation, KNOWN)
    assert angle < 1.0 and shift < 0.01, (angle, shift)
    np.testing.assert_array_equal(result.rotation, result.transformation[:3, :3])
    np.testing.assert_array_equal(result.translation, result.transformation[:3, 3])
    # The same pair through a Registrar, and in float32: the same numbers up to the rounding
    # of the target to float32.
    again = registrar.register(airplane, target)
    np.testing.assert_array_equal(again.transformation, result.transformation)
    single = registrar.register(airplane, target.astype(np.float32))
    np.testing.assert_allclose(single.transformation, result.transformation, atol=1e-4)
    # Refined: the fitness is the refinement's (source points within 0.03 of the target).
    assert 0.9 < result.fitness <= 1.0 and 0 < result.inlier_rmse < 0.03
    assert result.time_ms > 0 and result.iterations > 2 and result.converged
    # FGR's result overlaps well and fits no turned pose as well: the network does not run.
    assert [c.method for c in result.candidates] == ["fgr+refine"] and result.chosen == "fgr+refine"
    # accept=inf runs both: both scored (two-way overlap, at most 2), the winner named.
    both = rgm.Registrar(accept=float("inf")).register(airplane, target)
    assert [c.method for c in both.candidates] == ["fgr+refine", "rgm+refine"]
    assert all(1.5 < c.score <= 2.0 and c.failure is None for c in both.candidates)
    assert both.chosen in ("fgr+refine", "rgm+refine")
    # The source points within 0.03 of their nearest target point after the transform.
    pairs = result.correspondences
    assert pairs.dtype == np.int64 and pairs.ndim == 2 and pairs.shape[1] == 2
    assert len(pairs) == round(result.fitness * len(airplane))
    assert pairs.min() >= 0 and pairs.max() < 1024
    distances = np.linalg.norm(
        moved(airplane[pairs[:, 0]], result.transformation) - target[pairs[:, 1]], axis=1
    )
    assert distances.max() < 0.03


def test_strided_and_fortran_arrays_give_the_same_result(airplane, registrar):
    target = moved(airplane, KNOWN)
    expected = registrar.register(airplane, target).transformation
    wide = np.zeros((len(airplane), 6))
    wide[:, ::2] = airplane  # a view with a stride of 2 columns
    for source in (wide[:, ::2], np.asfortranarray(airplane)):
        assert not source.flags.c_contiguous
        found = registrar.register(source, np.asfortranarray(target)).transformation
        np.testing.assert_array_equal(found, expected)


def test_classical_methods_and_options(airplane):
    target = moved(airplane, KNOWN)
    fgr = rgm.register(airplane, target, method="fgr", refine=False)
    assert fgr.method == "fgr"
    angle, shift = errors(fgr.transformation, KNOWN)
    assert angle < 0.1 and shift < 1e-3, (angle, shift)
    # FGR's correspondences: the source points within its scoring distance (0.025) after the
    # transform; on this exact copy, nearly all of them.
    distances = np.linalg.norm(
        moved(airplane[fgr.correspondences[:, 0]], fgr.transformation)
        - target[fgr.correspondences[:, 1]],
        axis=1,
    )
    assert distances.max() < 0.025 and len(distances) == round(fgr.fitness * len(airplane))
    # ICP ignores refinement; one pass of RGM on 200 points is still RGM.
    assert rgm.register(airplane, target, method="icp").method == "icp"
    small = rgm.register(
        airplane, target, method="rgm", passes=1, match_points=200, refine=False
    )
    assert small.method == "rgm" and small.iterations == 1 and small.candidates == []
    # RGM's matches of its last pass, one to one, on 200 of the 1,024 points each.
    pairs = small.correspondences
    assert 3 <= len(pairs) <= 200
    assert len(np.unique(pairs[:, 0])) == len(pairs) == len(np.unique(pairs[:, 1]))


@pytest.mark.parametrize(
    "bad, says",
    [
        ([[0.0, 0.0, 0.0]] * 30, "got list"),
        (np.zeros((30, 2)), "shape (30, 2) and dtype float64"),
        (np.zeros((30, 3, 1)), "shape (30, 3, 1) and dtype float64"),
        (np.zeros(90), "shape (90,) and dtype float64"),
        (np.zeros((30, 3), dtype=np.int64), "shape (30, 3) and dtype int64"),
        (np.zeros((30, 3), dtype=np.float16), "shape (30, 3) and dtype float16"),
        (np.zeros((0, 3)), "has no point (shape (0, 3), dtype float64)"),
    ],
)
@pytest.mark.parametrize("argument", ["source", "target"])
def test_bad_clouds_are_value_errors_naming_the_argument(airplane, bad, says, argument):
    clouds = {"source": airplane, "target": airplane}
    clouds[argument] = bad
    with pytest.raises(ValueError) as err:
        rgm.register(clouds["source"], clouds["target"])
    assert str(err.value).startswith(argument) and says in str(err.value), err.value


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_non_finite_coordinates_are_value_errors(airplane, value, dtype):
    target = airplane.astype(dtype)
    target[17, 1] = value
    with pytest.raises(ValueError) as err:
        rgm.register(airplane, target)
    message = str(err.value)
    assert message.startswith("target (shape (1024, 3), dtype ") and str(np.dtype(dtype)) in message
    assert "row 17" in message, message


def test_options_that_do_not_fit_are_value_errors(tmp_path):
    for kwargs, says in [
        ({"method": "gicp"}, 'unknown method "gicp" (expected one of icp, fgr, rgm, auto, scene)'),
        ({"method": "fgr", "passes": 1}, "apply to the rgm, auto and scene methods only"),
        ({"preset": "tiny"}, "the built-in model has its own"),
        ({"passes": 0}, "passes must be at least 1, got 0"),
        ({"match_points": -5}, "match_points must be at least 0, got -5"),
        ({"test_statistics": "batch", "weights": "w"}, 'unknown test_statistics "batch"'),
        ({"weights": tmp_path / "missing.safetensors"}, str(tmp_path / "missing.safetensors")),
    ]:
        with pytest.raises(ValueError) as err:
            rgm.Registrar(**kwargs)
        assert says in str(err.value), (kwargs, err.value)


def test_too_few_points_is_a_runtime_error_that_says_why(airplane):
    with pytest.raises(RuntimeError, match="rgm\\+refine failed: .*needs at least"):
        rgm.Registrar(method="rgm").register(airplane[:5], airplane[:5])


def _pairs(data, count):
    """`count` different (source, target, truth) pairs: test shapes under different poses."""
    pairs = []
    for k, (category, number) in enumerate([("airplane", 627), ("chair", 890), ("car", 198), ("lamp", 125)][:count]):
        points = shape(data, category, number)
        truth = pose((10 * k - 15, 25 - 5 * k, 5 * k), (0.1 * k, -0.2, 0.05 * k))
        pairs.append((points, moved(points, truth), truth))
    return pairs


def test_threads_give_the_serial_results(data, registrar):
    pairs = _pairs(data, 4)
    serial = [registrar.register(s, t) for s, t, _ in pairs]
    with concurrent.futures.ThreadPoolExecutor(max_workers=4) as pool:
        # Each pair twice, all at once, on the one Registrar.
        threaded = list(pool.map(lambda p: registrar.register(p[0], p[1]), pairs + pairs))
    for one, other in zip(serial + serial, threaded):
        np.testing.assert_array_equal(one.transformation, other.transformation)
        np.testing.assert_array_equal(one.correspondences, other.correspondences)
        assert (one.fitness, one.inlier_rmse) == (other.fitness, other.inlier_rmse)
    # The serial results are right, so the threads' are too.
    for result, (_, _, truth) in zip(serial, pairs):
        angle, shift = errors(result.transformation, truth)
        assert angle < 1.0 and shift < 0.01, (angle, shift)


def test_python_runs_while_rust_registers(airplane, registrar):
    # Held, the GIL would keep this thread from running any Python while the other thread is
    # in Rust: it could only run in the few milliseconds before the call enters Rust. Released,
    # this thread keeps running throughout, also in the middle half of the call.
    target = moved(airplane, KNOWN)
    call = {}

    def work():
        call["start"] = time.perf_counter()
        registrar.register(airplane, target)
        call["end"] = time.perf_counter()

    worker = threading.Thread(target=work)
    ticks = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
    worker.join()
    quarter = (call["end"] - call["start"]) / 4
    middle = [t for t in ticks if call["start"] + quarter < t < call["end"] - quarter]
    assert middle, f"no Python ran during the middle half of a {4 * quarter:.3f} s registration"


def test_a_registrar_pickles_as_its_settings_for_process_pools(data):
    registrar = rgm.Registrar(method="fgr", refine=False)
    copy = pickle.loads(pickle.dumps(registrar))
    assert copy.name == "fgr" and repr(copy) == repr(registrar) == "rgm.Registrar(method='fgr', refine=False)"
    pairs = _pairs(data, 2)
    serial = [registrar.register(s, t).transformation for s, t, _ in pairs]
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=2, mp_context=context) as pool:
        found = list(pool.map(registrar.register, [p[0] for p in pairs], [p[1] for p in pairs]))
    for expected, result in zip(serial, found):
        np.testing.assert_array_equal(result.transformation, expected)


def test_the_same_transform_as_the_rgm_command(airplane, rgm_command, tmp_path):
    target = moved(airplane, KNOWN)
    np.save(tmp_path / "source.npy", airplane)
    np.save(tmp_path / "target.npy", target)
    for args, kwargs in [([], {}), (["--method", "fgr"], {"method": "fgr"})]:
        out = subprocess.run(
            rgm_command + ["register", str(tmp_path / "source.npy"), str(tmp_path / "target.npy"), "--json"] + args,
            check=True,
            capture_output=True,
            text=True,
        )
        cli = json.loads(out.stdout)
        result = rgm.register(np.load(tmp_path / "source.npy"), np.load(tmp_path / "target.npy"), **kwargs)
        assert cli["method"] == result.method
        np.testing.assert_array_equal(np.array(cli["transform"]), result.transformation)
        assert (cli["fitness"], cli["inlier_rmse"]) == (result.fitness, result.inlier_rmse)
        assert cli["correspondences"] == len(result.correspondences)


def test_register_many_gives_the_one_by_one_results(data, registrar):
    pairs = _pairs(data, 4)
    serial = [registrar.register(s, t) for s, t, _ in pairs]
    # Each pair twice, all in one call.
    many = registrar.register_many([(s, t) for s, t, _ in pairs] * 2)
    assert len(many) == 8
    for one, other in zip(serial + serial, many):
        np.testing.assert_array_equal(one.transformation, other.transformation)
        np.testing.assert_array_equal(one.correspondences, other.correspondences)
        assert (one.fitness, one.inlier_rmse, one.iterations, one.chosen) == (
            other.fitness,
            other.inlier_rmse,
            other.iterations,
            other.chosen,
        )
        assert [c.score for c in one.candidates] == [c.score for c in other.candidates]
    assert registrar.register_many([]) == []
    airplane = pairs[0][0]
    with pytest.raises(ValueError, match=r"^pairs\[1\] target must have shape \(N, 3\)"):
        registrar.register_many([(airplane, airplane), (airplane, np.zeros((30, 2)))])
    with pytest.raises(ValueError, match=r"^pairs\[0\] must be a \(source, target\) pair"):
        registrar.register_many([airplane])
    with pytest.raises(rgm.PairsError, match=r"^pair 1: rgm\+refine failed: .*needs at least"):
        rgm.Registrar(method="rgm").register_many([(airplane, airplane), (airplane[:5], airplane[:5])])


def test_a_result_has_named_read_only_fields_a_repr_and_pickles(airplane, registrar):
    result = registrar.register(airplane, moved(airplane, KNOWN))
    assert isinstance(result, rgm.RegistrationResult)
    assert isinstance(result.candidates[0], rgm.Candidate)
    text = repr(result)
    assert text.startswith("RegistrationResult(method='auto+refine', registered=True, reason=None"), text
    assert f"correspondences=<{len(result.correspondences)} pairs>" in text
    assert "Candidate(method='fgr+refine', score=" in text and "transformation=array([[" in text
    with pytest.raises(AttributeError):
        result.fitness = 1.0
    copy = pickle.loads(pickle.dumps(result))
    for name in ("fitness", "inlier_rmse", "time_ms", "method", "iterations", "converged", "chosen", "registered", "reason"):
        assert getattr(copy, name) == getattr(result, name), name
    np.testing.assert_array_equal(copy.transformation, result.transformation)
    np.testing.assert_array_equal(copy.correspondences, result.correspondences)
    assert [(c.method, c.score, c.failure) for c in copy.candidates] == [
        (c.method, c.score, c.failure) for c in result.candidates
    ]
    np.testing.assert_array_equal(copy.candidates[0].transformation, result.candidates[0].transformation)
    # Built by keyword, as the dataclass it replaces was: the defaults of a method without
    # candidates.
    made = rgm.RegistrationResult(
        transformation=np.eye(4),
        fitness=0.5,
        inlier_rmse=0.01,
        correspondences=np.zeros((0, 2), dtype=np.int64),
        time_ms=1.0,
        method="icp",
        iterations=3,
        converged=True,
    )
    assert (made.candidates, made.chosen, made.registered, made.reason) == ([], None, True, None)
    np.testing.assert_array_equal(made.translation, np.zeros(3))


def test_ctrl_c_interrupts_register_many_and_the_registrar_goes_on(airplane, ctrl_c):
    import os
    import signal

    # Both candidates on every pair (accept=inf), the network on all 1,024 points: the pairs keep
    # it busy. The list doubles until one call lasts long enough to interrupt on any machine.
    registrar = rgm.Registrar(accept=float("inf"), match_points=1024)
    pairs = [(airplane, moved(airplane, pose((3 * k, -2 * k, k), (0.01 * k, 0, 0)))) for k in range(12)]
    while True:
        start = time.perf_counter()
        expected = registrar.register_many(pairs)
        whole = time.perf_counter() - start
        if whole > 1.0 or len(pairs) >= 768:
            break
        pairs = pairs + pairs
    assert whole > 1.0, f"{len(pairs)} pairs take {whole:.2f} s: too short to interrupt"
    timer = threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT))
    start = time.perf_counter()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        registrar.register_many(pairs)
    interrupted = time.perf_counter() - start
    timer.join()
    assert interrupted < whole / 2, (interrupted, whole)
    # The interrupted call's copies of the method come back unharmed.
    again = registrar.register_many(pairs[:3])
    for one, other in zip(expected, again):
        np.testing.assert_array_equal(one.transformation, other.transformation)
