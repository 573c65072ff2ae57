"""rgm.metrics and rgm.modelnet_pairs: the paper's metrics by hand, and the same pairs as the
`rgm pairs` command writes."""

import json
import subprocess

import numpy as np
import pytest

import rgm
from conftest import shape


def rotation_z(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_metrics_by_hand(data):
    source = shape(data, "airplane", 627)
    t = np.array([0.1, 0.0, -0.2])
    target = source.astype(np.float64) + t
    # The truth itself: no error, every point on its twin.
    exact = rgm.metrics(np.eye(3), t, np.eye(3), t, source, target)
    assert exact == rgm.Metrics(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, True)
    # 5° about z: Euler angles (0, 0, 5°), so MAE(R) = 5/3° (no recall) and MIE(R) = 5°.
    off = rgm.metrics(rotation_z(5), t, np.eye(3), t, source, target)
    assert off.mae_r_deg == pytest.approx(5 / 3, abs=1e-9)
    assert off.mie_r_deg == pytest.approx(5, abs=1e-9)
    assert (off.mae_t, off.mie_t, off.recall) == (0.0, 0.0, False)
    assert 0 < off.ccd <= 0.2 and off.chamfer > 0
    # A translation off by (0.03, 0, 0): MAE(t) = 0.01, MIE(t) = 0.03, still recalled.
    shifted = rgm.metrics(np.eye(3), t + [0.03, 0, 0], np.eye(3), t, source, target)
    assert shifted.mae_t == pytest.approx(0.01) and shifted.mie_t == pytest.approx(0.03)
    assert shifted.recall


def test_metrics_refuse_what_is_not_a_transform(data):
    source = shape(data, "airplane", 627)
    for args, says in [
        ((2 * np.eye(3), np.zeros(3), np.eye(3), np.zeros(3)), "pred: "),
        ((np.eye(3), np.zeros(2), np.eye(3), np.zeros(3)), "t_pred must be a numeric array of shape (3,)"),
        ((np.eye(3), np.zeros(3), np.full((3, 3), np.nan), np.zeros(3)), "R_gt (shape (3, 3)) has a NaN"),
    ]:
        with pytest.raises(ValueError) as err:
            rgm.metrics(*args, source, source)
        assert says in str(err.value), err.value
    with pytest.raises(ValueError, match="^target must have shape"):
        rgm.metrics(np.eye(3), np.zeros(3), np.eye(3), np.zeros(3), source, source[:, :2])


def test_modelnet_pairs_are_the_pairs_of_the_rgm_command(data, rgm_command, tmp_path):
    pairs = rgm.modelnet_pairs(data, setting="partial", limit=3)
    assert len(pairs) == 3 and len(pairs[0:2]) == 2
    out = tmp_path / "pairs"
    subprocess.run(
        rgm_command + ["pairs", "--setting", "partial", "--limit", "3", "--out", str(out), "--data", str(data)],
        check=True,
        capture_output=True,
    )
    written = json.loads((out / "pairs.json").read_text())["pairs"]
    for pair, entry in zip(pairs, written):
        assert (pair.index, pair.shape, pair.label) == (entry["index"], entry["shape"], entry["label"])
        assert pair.category == entry["shape"].rsplit("_", 1)[0]
        np.testing.assert_array_equal(pair.transformation, np.array(entry["t_target_source"]))
        np.testing.assert_array_equal(pair.correspondences, np.array(entry["correspondences"]))
        # Partial: 717 of 1,024 points each; the truth brings matched points within 0.1.
        assert pair.source.shape == pair.target.shape == (717, 3)
        i, j = pair.correspondences.T
        moved = pair.source[i] @ pair.rotation.T + pair.translation
        assert np.linalg.norm(moved - pair.target[j], axis=1).max() < 0.1
        # Scored against itself, the truth is perfect.
        assert rgm.metrics(pair.rotation, pair.translation, pair.rotation, pair.translation, pair.source, pair.target).recall
    # The same pair every time; iteration and negative indices reach the same pairs.
    again = list(pairs)
    np.testing.assert_array_equal(again[2].source, pairs[-1].source)
    with pytest.raises(IndexError):
        pairs[3]


def test_modelnet_pairs_name_what_is_wrong(data, tmp_path):
    with pytest.raises(ValueError, match="unknown setting `crop`"):
        rgm.modelnet_pairs(data, setting="crop")
    with pytest.raises(ValueError, match='unknown split "train"'):
        rgm.modelnet_pairs(data, split="train")
    with pytest.raises(ValueError, match="neither a ModelNet40 .npy tree"):
        rgm.modelnet_pairs(tmp_path)
