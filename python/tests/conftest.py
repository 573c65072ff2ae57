"""Shared fixtures: a ModelNet40 shape, known poses, and the `rgm` command for comparisons."""

import os
import pathlib
import shutil
import signal

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


def data_dir() -> pathlib.Path:
    """The ModelNet40 .npy tree: $RGM_DATA, or shared/ beside the repository (as in CI)."""
    return pathlib.Path(
        os.environ.get("RGM_DATA", REPO.parent / "shared" / "data" / "modelnet40_npy1024")
    )


@pytest.fixture(scope="session")
def data() -> pathlib.Path:
    path = data_dir()
    if not (path / "modelnet40_shape_names.txt").is_file():
        pytest.skip(f"no ModelNet40 data at {path} (set RGM_DATA)")
    return path


def shape(data: pathlib.Path, category: str, number: int) -> np.ndarray:
    """The (1024, 3) float32 points of a ModelNet40 test shape."""
    return np.load(data / category / "test" / f"{category}_{number:04d}.npy")


def pose(angles_deg, translation) -> np.ndarray:
    """The (4, 4) transform of intrinsic x-y-z rotations by `angles_deg`, then `translation`."""
    rx, ry, rz = np.radians(angles_deg)
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    matrix = np.eye(4)
    matrix[:3, :3] = x @ y @ z
    matrix[:3, 3] = translation
    return matrix


def moved(points: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """`points` (N, 3) moved by the (4, 4) `transform`, in float64."""
    return points.astype(np.float64) @ transform[:3, :3].T + transform[:3, 3]


def errors(found: np.ndarray, truth: np.ndarray):
    """(rotation angle in degrees, translation distance) between two (4, 4) transforms."""
    residual = np.linalg.inv(truth) @ found
    cos = np.clip((np.trace(residual[:3, :3]) - 1) / 2, -1, 1)
    return np.degrees(np.arccos(cos)), np.linalg.norm(found[:3, 3] - truth[:3, 3])


@pytest.fixture(scope="session")
def rgm_command():
    """The `rgm` command: $RGM_BIN (scripts/test-python.sh sets it), else `cargo run`."""
    if os.environ.get("RGM_BIN"):
        return [os.environ["RGM_BIN"]]
    if shutil.which("cargo") is None:
        pytest.skip("no rgm binary (set RGM_BIN) and no cargo to build one")
    return ["cargo", "run", "--quiet", "--manifest-path", str(REPO / "Cargo.toml"), "--bin", "rgm", "--"]


@pytest.fixture
def ctrl_c():
    """Python's own Ctrl-C handler (KeyboardInterrupt) for the test: a shell starts a background
    job with SIGINT ignored, and its children inherit that."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)
