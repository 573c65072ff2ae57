"""Type stubs of the compiled extension ``rgm._rgm`` (arrays arrive checked, as float64)."""

from typing import Optional

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
    ) -> None: ...
    @property
    def name(self) -> str: ...
    def register(
        self, source: npt.NDArray[np.float64], target: npt.NDArray[np.float64]
    ) -> tuple[
        npt.NDArray[np.float64],  # (4, 4) transformation, target ← source
        float,  # fitness
        float,  # inlier RMSE
        npt.NDArray[np.int64],  # (K, 2) correspondences
        float,  # time in milliseconds
        int,  # iterations
        bool,  # converged
        list[
            tuple[str, Optional[float], npt.NDArray[np.float64], Optional[str]]
        ],  # candidates: method, score, (4, 4) transformation, failure
        Optional[str],  # the chosen candidate's method
        Optional[str],  # why the result is not credible (not registered)
    ]: ...

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
