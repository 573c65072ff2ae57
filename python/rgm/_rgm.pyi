"""Type stubs of the compiled extension ``rgm._rgm`` (arrays arrive checked, as float64)."""

from typing import Iterator, Optional

import numpy as np
import numpy.typing as npt

DEFAULT_METHOD: str
DEFAULT_REFINE: bool
METHODS: list[str]

class Registrar:
    def __init__(
        self,
        method: str,
        refine: bool,
        weights: Optional[str],
        preset: Optional[str],
        test_statistics: Optional[str],
        match_points: Optional[int],
        passes: Optional[int],
        accept: Optional[float],
    ) -> None: ...
    @property
    def name(self) -> str: ...
    def register(
        self, source: npt.NDArray[np.float64], target: npt.NDArray[np.float64]
    ) -> RegistrationResult: ...
    def register_many(
        self, pairs: Iterator[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]
    ) -> tuple[list[Optional[RegistrationResult]], list[tuple[int, str]]]: ...
    def merge(
        self, scans: list[npt.NDArray[np.float64]], voxel: Optional[float]
    ) -> tuple[
        list[Optional[npt.NDArray[np.float64]]],  # (S,) model ← scan, (4, 4) each
        list[Optional[int]],  # (S,) component
        list[Optional[float]],  # (S,) residual
        npt.NDArray[np.float64],  # (P, 3) component 0's merged points
        npt.NDArray[np.int64],  # (P,) each point's scan
    ]: ...
    def register_many_into(
        self, pairs: Iterator[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]], output: str
    ) -> tuple[int, int, int, int]: ...

class Candidate:
    method: str
    score: Optional[float]
    transformation: npt.NDArray[np.float64]  # (4, 4), target ← source
    failure: Optional[str]
    def __init__(
        self,
        method: str,
        score: Optional[float],
        transformation: npt.NDArray[np.float64],
        failure: Optional[str] = None,
    ) -> None: ...

class RegistrationResult:
    transformation: npt.NDArray[np.float64]  # (4, 4), target ← source
    fitness: float
    inlier_rmse: float
    correspondences: npt.NDArray[np.int64]  # (K, 2)
    time_ms: float
    method: str
    iterations: int
    converged: bool
    candidates: list[Candidate]
    chosen: Optional[str]
    registered: bool
    reason: Optional[str]
    def __init__(
        self,
        transformation: npt.NDArray[np.float64],
        fitness: float,
        inlier_rmse: float,
        correspondences: npt.NDArray[np.int64],
        time_ms: float,
        method: str,
        iterations: int,
        converged: bool,
        candidates: Optional[list[Candidate]] = None,
        chosen: Optional[str] = None,
        registered: bool = True,
        reason: Optional[str] = None,
    ) -> None: ...
    @property
    def rotation(self) -> npt.NDArray[np.float64]: ...  # (3, 3)
    @property
    def translation(self) -> npt.NDArray[np.float64]: ...  # (3,)
    def to_html(
        self,
        path: str,
        source: Optional[npt.NDArray[np.float64]] = None,  # (N, 3)
        target: Optional[npt.NDArray[np.float64]] = None,  # (M, 3)
        points: int = 200000,
    ) -> None: ...
    def _repr_html_(self) -> Optional[str]: ...

class ModelNetPairs:
    def __init__(
        self, data_dir: str, setting: str, split: str, unseen: bool, limit: Optional[int]
    ) -> None: ...
    def __len__(self) -> int: ...
    def pair(
        self, index: int
    ) -> tuple[
        npt.NDArray[np.float64],  # (N, 3) source
        npt.NDArray[np.float64],  # (M, 3) target
        npt.NDArray[np.float64],  # (4, 4) true transformation
        npt.NDArray[np.int64],  # (K, 2) true correspondences
        int,  # label
        str,  # category
        str,  # shape name
    ]: ...

def metrics(
    pred: npt.NDArray[np.float64],
    truth: npt.NDArray[np.float64],
    source: npt.NDArray[np.float64],
    target: npt.NDArray[np.float64],
) -> dict[str, float]: ...
