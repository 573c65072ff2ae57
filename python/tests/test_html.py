"""A result's page: `to_html(path)` and the inline view in Jupyter (`_repr_html_`)."""

import base64
import html
import json
import pickle
import re

import numpy as np
import pytest

import rgm
from conftest import moved, pose, shape

TURN = pose((0, 0, 15), (0.1, 0.0, -0.05))


def helix(n: int) -> np.ndarray:
    """(n, 3) float64 points of a helix that widens: no symmetry for ICP to slide along."""
    a = np.linspace(0, 6 * np.pi, n)
    return np.stack([np.cos(a) * (1 + 0.1 * a), np.sin(a), 0.05 * a], axis=1)


def page_data(page: str) -> dict:
    """The JSON data of a page."""
    found = re.search(r'<script id="rgm-data" type="application/json">(.*?)</script>', page, re.S)
    assert found, "the page holds no data"
    return json.loads(found.group(1))


def points(field: str) -> np.ndarray:
    """A base64 field of little-endian f32 rows as (N, 3)."""
    return np.frombuffer(base64.b64decode(field), dtype="<f4").reshape(-1, 3)


def test_to_html_writes_the_pair_and_its_result(tmp_path):
    source = helix(3000)
    target = moved(source, TURN)
    result = rgm.register(source, target, method="icp")
    path = tmp_path / "pair.html"
    result.to_html(path)
    data = page_data(path.read_text())
    assert data["method"] == result.method
    assert data["source"]["points"] == 3000 and data["source"]["shown"] == 3000
    assert data["target"]["points"] == 3000
    np.testing.assert_allclose(np.array(data["transform"]), result.transformation)
    # The source in the page's frame: its shape kept exactly (distances scale together).
    shown = points(data["source"]["xyz"]).astype(np.float64)
    assert shown.shape == (3000, 3) and np.abs(shown).max() <= 1 + 1e-6
    ratio = np.linalg.norm(shown[0] - shown[-1]) / np.linalg.norm(source[0] - source[-1])
    np.testing.assert_allclose(
        np.linalg.norm(shown[10] - shown[2000]) / np.linalg.norm(source[10] - source[2000]),
        ratio,
        rtol=1e-5,
    )
    # ICP finds the turn here, so nearly every source point lies on the target.
    inlier = np.frombuffer(base64.b64decode(data["inlier"]), dtype=np.uint8)
    assert inlier.shape == (3000,) and inlier.mean() > 0.95


def test_the_budget_thins_and_the_page_says_so(tmp_path):
    source = helix(30_000)
    target = moved(source, TURN)
    result = rgm.register(source, target, method="icp")
    result.to_html(tmp_path / "small.html", points=1000)
    data = page_data((tmp_path / "small.html").read_text())
    assert (data["source"]["shown"], data["target"]["shown"]) == (500, 500)
    assert data["budget"] == 1000
    assert points(data["target"]["xyz"]).shape == (500, 3)


def test_the_inline_view_is_an_iframe_of_the_page_within_the_inline_budget():
    source = helix(60_000)
    target = moved(source, TURN)
    result = rgm.register(source, target, method="icp")
    inline = result._repr_html_()
    assert inline.startswith("<iframe srcdoc=")
    srcdoc = html.unescape(re.search(r'srcdoc="([^"]*)"', inline).group(1))
    data = page_data(srcdoc)
    assert data["source"]["shown"] + data["target"]["shown"] == 50_000
    assert len(inline) < 1_200_000  # about 17 bytes a point


def test_a_result_without_clouds_takes_them_or_says_why(tmp_path):
    source = helix(500)
    target = moved(source, TURN)
    result = pickle.loads(pickle.dumps(rgm.register(source, target, method="icp")))
    assert result._repr_html_() is None  # Jupyter shows the repr instead
    with pytest.raises(ValueError, match="holds no clouds"):
        result.to_html(tmp_path / "p.html")
    with pytest.raises(ValueError, match="both source and target"):
        result.to_html(tmp_path / "p.html", source=source)
    result.to_html(tmp_path / "p.html", source=source, target=target)
    assert page_data((tmp_path / "p.html").read_text())["target"]["points"] == 500
    with pytest.raises(OSError):
        result.to_html(tmp_path / "no" / "such" / "folder.html", source=source, target=target)


def test_the_default_methods_page_shows_its_candidates(data, tmp_path):
    airplane = shape(data, "airplane", 627).astype(np.float64)
    result = rgm.register(airplane, moved(airplane, pose((20, 10, 30), (0.2, -0.1, 0.3))))
    result.to_html(tmp_path / "auto.html")
    page = page_data((tmp_path / "auto.html").read_text())
    assert [c["method"] for c in page["candidates"]] == [c.method for c in result.candidates]
    taken = [c["method"] for c in page["candidates"] if c["chosen"]]
    assert taken == [result.chosen]
    # RGM's own matches are drawn only for RGM unrefined.
    assert page["correspondences"]["total"] == 0
    alone = rgm.register(airplane, moved(airplane, pose((20, 10, 30), (0.2, -0.1, 0.3))),
                         method="rgm", refine=False)
    alone.to_html(tmp_path / "rgm.html")
    lines = page_data((tmp_path / "rgm.html").read_text())["correspondences"]
    assert lines["total"] == len(alone.correspondences) > 0
    assert points(lines["source"]).shape == (lines["shown"], 3)
