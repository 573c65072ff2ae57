"""rgm.merge on three thinned Stanford bunny scans, each moved into a frame of its own: placed
as the `.conf` ground truth places them (after the one motion between the two frames), and the
merged cloud labelled by scan; a scan of another object left unplaced."""

import gzip

import numpy as np
import pytest

import rgm
from conftest import REPO, pose

STANFORD = REPO.parent / "shared" / "data" / "stanford"


def read_scan(path):
    """The vertices of a Stanford ASCII PLY (gzip), every 8th kept (≈ 5,000 points)."""
    with gzip.open(path, "rt") as f:
        lines = f.read().splitlines()
    end = lines.index("end_header")
    count = next(int(l.split()[2]) for l in lines[:end] if l.startswith("element vertex"))
    rows = [l.split()[:3] for l in lines[end + 1 : end + 1 + count]]
    return np.asarray(rows, dtype=np.float64)[::8]


def conf_poses(path):
    """name -> (4, 4) world <- scan (p_world = R(q)^T p + t)."""
    poses = {}
    for line in path.read_text().splitlines():
        t = line.split()
        if not t or t[0] != "bmesh":
            continue
        x, y, z, w = map(float, t[5:9])
        r = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = r.T, [float(v) for v in t[2:5]]
        poses[t[1]] = m
    return poses


def apply(m, p):
    return p @ m[:3, :3].T + m[:3, 3]


def angle_deg(m):
    return float(np.degrees(np.arccos(np.clip((np.trace(m[:3, :3]) - 1) / 2, -1, 1))))


def test_three_bunny_scans_are_placed_as_the_truth_and_a_dragon_scan_is_not():
    bunny = STANFORD / "bunny"
    if not (bunny / "bun.conf").is_file():
        pytest.skip(f"no Stanford scans at {bunny}")
    truth = conf_poses(bunny / "bun.conf")
    names = ["bun000.ply", "bun045.ply", "bun315.ply"]
    scans, world_from_input = [], []
    for k, name in enumerate(names):
        motion = pose([40 * (k + 1), 25 * (k + 1), 60 * (k + 1)], [0.05 * k, -0.1, 0.02])
        scans.append(apply(motion, read_scan(bunny / (name + ".gz"))))
        world_from_input.append(truth[name] @ np.linalg.inv(motion))
    dragon = read_scan(STANFORD / "dragon_stand" / "dragonStandRight_0.ply.gz")
    result = rgm.merge(scans + [dragon])
    assert result.registered == [True, True, True, False]
    assert result.on_loop == [True, True, True, False]
    assert result.poses[3] is None and result.component[3] is None
    # The frames differ by one motion: that of scan 0's. Every scan within 1° and 1 mm of it.
    world_from_model = world_from_input[0] @ np.linalg.inv(result.poses[0])
    for k in range(3):
        off = np.linalg.inv(world_from_input[k]) @ world_from_model @ result.poses[k]
        centroid = scans[k].mean(0)
        shift = np.linalg.norm(apply(off, centroid[None])[0] - centroid)
        assert angle_deg(off) < 1.0 and shift < 0.001, (k, angle_deg(off), shift)
        assert result.residual[k] < 0.0005
    # The merged cloud: points of the three scans only, each labelled.
    assert result.points.shape == (len(result.scan_index), 3)
    assert set(result.scan_index.tolist()) == {0, 1, 2}


def test_too_few_scans_and_bad_arrays_are_refused_by_name():
    with pytest.raises(ValueError, match="2 scans"):
        rgm.merge([np.zeros((10, 3))])
    with pytest.raises(ValueError, match=r"scans\[1\]"):
        rgm.merge([np.zeros((10, 3)), np.zeros((10, 2))])
