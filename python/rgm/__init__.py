"""rgm: robust point-cloud registration (RGM, CVPR 2021), with NumPy arrays in and out.

Register two clouds (float32 or float64 arrays of shape (N, 3))::

    import rgm
    result = rgm.register(source, target)
    result.transformation        # (4, 4) float64, maps the source onto the target

``rgm.register`` runs what the ``rgm register`` command runs, with the same defaults: the RGM
network with the model built into rgm and FGR, each refined by ICP on the full clouds, and the
result that overlaps better (``result.candidates`` holds both, with their scores). ``rgm.Registrar``
loads a method once for many pairs (``Registrar.register_many`` runs a list of them on all
cores); ``rgm.metrics`` and ``rgm.modelnet_pairs`` give the paper's metrics and the benchmark's
pairs, to evaluate any method on exactly rgm's pairs.

The work runs in Rust with the GIL released: Python threads register pairs in parallel, Ctrl-C
interrupts a registration at once, and a ``Registrar`` pickles (as its settings) for process
pools of any start method (a process forked after a registration starts its own threads).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Iterable, Iterator, List, Optional, Tuple, Union, overload

import numpy as np

from . import _rgm

__all__ = [
    "BatchError",
    "BenchmarkPair",
    "Candidate",
    "DEFAULT_METHOD",
    "METHODS",
    "MergeResult",
    "Metrics",
    "ModelNetPairs",
    "PairsError",
    "Registrar",
    "RegistrationResult",
    "merge",
    "metrics",
    "modelnet_pairs",
    "register",
]

__version__ = "0.1.0"

#: The method ``rgm register`` and ``rgm.register`` run when none is named.
DEFAULT_METHOD: str = _rgm.DEFAULT_METHOD
#: The names ``method`` accepts.
METHODS: tuple = tuple(_rgm.METHODS)

PathLike = Union[str, "os.PathLike[str]"]


def _points(name: str, value: object) -> np.ndarray:
    """``value`` as a C-contiguous float64 (N, 3) array, or a ValueError naming ``name``."""
    if not isinstance(value, np.ndarray):
        raise ValueError(
            f"{name} must be a NumPy array of shape (N, 3) and dtype float32 or float64, "
            f"got {type(value).__name__}"
        )
    # Either byte order: a big-endian array is converted below.
    if value.dtype.kind != "f" or value.dtype.itemsize not in (4, 8) or value.ndim != 2 or value.shape[1] != 3:
        raise ValueError(
            f"{name} must have shape (N, 3) and dtype float32 or float64, "
            f"got shape {value.shape} and dtype {value.dtype}"
        )
    if value.shape[0] == 0:
        raise ValueError(f"{name} has no point (shape {value.shape}, dtype {value.dtype})")
    finite = np.isfinite(value).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        raise ValueError(
            f"{name} (shape {value.shape}, dtype {value.dtype}) has a NaN or infinite "
            f"coordinate in row {row}: {value[row].tolist()}"
        )
    return np.ascontiguousarray(value, dtype=np.float64)


def _flag(name: str, value: object) -> bool:
    """``value`` if it is a bool (NumPy's too), else a TypeError: a string such as ``"no"``
    is true to ``bool``, and would silently mean yes."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _matrix(name: str, value: object, shape: tuple) -> np.ndarray:
    """``value`` as a C-contiguous finite float64 array of ``shape``, or a ValueError."""
    array = np.asarray(value)
    if array.dtype.kind not in "fiu" or array.shape != shape:
        raise ValueError(
            f"{name} must be a numeric array of shape {shape}, "
            f"got shape {array.shape} and dtype {array.dtype}"
        )
    if not np.isfinite(array).all():
        raise ValueError(f"{name} (shape {array.shape}) has a NaN or infinite entry")
    return np.ascontiguousarray(array, dtype=np.float64)


def _homogeneous(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = translation
    return matrix


#: One candidate of the default method: ``method``, ``score``, ``transformation``, ``failure``
#: (``help(rgm.Candidate)`` says what each holds).
Candidate = _rgm.Candidate

#: What ``register`` returns: ``transformation`` (with its ``rotation`` and ``translation``),
#: ``fitness``, ``inlier_rmse``, ``correspondences``, ``time_ms``, ``method``, ``iterations``,
#: ``converged``, ``candidates``, ``chosen``, ``registered`` and ``reason``
#: (``help(rgm.RegistrationResult)`` says what each holds). It pickles, so results travel back
#: from process pools and Dask workers.
RegistrationResult = _rgm.RegistrationResult


class PairsError(RuntimeError):
    """Some pairs of ``Registrar.register_many`` failed; the others' results are kept.

    (``rgm.BatchError``, its name before issue 58, is the same class, kept for one release.)

    Attributes:
        results: one entry per pair, in the order of the pairs: its RegistrationResult, or
            ``None`` for a pair that failed.
        errors: ``(index, message)`` of each failed pair, in order.
    """

    def __init__(self, results: list, errors: list) -> None:
        index, message = errors[0]
        super().__init__(
            f"pair {index}: {message} ({len(errors)} of {len(results)} pairs failed; the "
            "exception's .results holds every pair's result, None where it failed, and "
            ".errors each failed pair's (index, message))"
        )
        self.results = results
        self.errors = errors


#: ``PairsError``'s name before issue 58 (a list of pairs was called a batch, the word now kept
#: for training's mini-batches): the same class, kept for one release.
BatchError = PairsError


class Registrar:
    """A registration method loaded once, to register many pairs.

    Building one loads the method's network (for RGM); ``register`` then runs it on any
    number of pairs, from any number of threads at once (the GIL is released while it works,
    and each thread gets its own copy of the network's buffers); ``register_many`` runs a
    list of pairs on all cores. A Registrar pickles as its settings: unpickled in another
    process (a process pool's or a Dask worker), it loads its network there, once per process.

    Args:
        method: ``"auto"`` (FGR, and RGM where FGR's result overlaps too little, each
            refined, the better by its overlap score),
            ``"rgm"`` (the RGM network), ``"fgr"`` (Fast Global Registration on FPFH features)
            or ``"icp"`` (point-to-point ICP from the identity). Default: the method of
            ``rgm register`` (``rgm.DEFAULT_METHOD``, ``"auto"``).
        refine: refine the transform of RGM or FGR (both, with ``"auto"``) by ICP on the full
            clouds (trimmed point-to-plane with pairs closer than 0.2, then 0.1, then 0.05, and
            point-to-point at 0.05, then 0.03; RGM and auto measure them in the unit-sphere
            frame, FGR alone in the clouds' units). On by default, as in ``rgm register``;
            ``False`` gives the method's own transform, as the paper's tables do. ICP is its own
            refinement and ignores it.
        weights: RGM and auto only: a safetensors file of weights with the authors' parameter names
            (made by ``rgm train``, or converted from the authors' PyTorch model). Default: the
            model built into rgm.
        preset: RGM or auto with ``weights`` only: the network sizes they were trained with,
            ``"paper"`` (default), ``"small"``, ``"fast"`` or ``"tiny"``.
        test_statistics: RGM or auto with ``weights`` only: the batch-norm statistics at test time,
            ``"cloud"`` for weights trained by ``rgm train`` or ``"running"`` (default) for the
            authors' weights.
        match_points: RGM and auto only: match on at most this many randomly drawn points of each cloud
            (a fixed seed, so a pair always gives the same result) and apply the transform to
            the full clouds; 0 matches on every point (memory grows with the square of the
            points; a request beyond the machine's free memory raises). Default: every point for
            the built-in model (256 as ``auto``'s second stage); 1,024 with ``weights``.
        passes: RGM and auto only: passes of network, matching and Kabsch, each on the source moved by
            the passes before. Default: 2, as in the paper.
        accept: auto only: take FGR's result without running the network when its overlap
            score (both clouds' share of points on the other, 0 to 2) reaches this;
            ``float("inf")`` runs both methods on every pair. Default: that of ``rgm register``.

    Raises:
        ValueError: an unknown method, preset or test_statistics; an RGM option with another
            method; a weight file that cannot be read or does not fit the preset (the message
            names the file).
        TypeError: ``refine`` that is not True or False (``"no"`` would mean yes).
    """

    def __init__(
        self,
        method: str = DEFAULT_METHOD,
        refine: bool = _rgm.DEFAULT_REFINE,
        weights: Optional[PathLike] = None,
        preset: Optional[str] = None,
        test_statistics: Optional[str] = None,
        match_points: Optional[int] = None,
        passes: Optional[int] = None,
        accept: Optional[float] = None,
    ) -> None:
        self._settings = (
            str(method),
            _flag("refine", refine),
            None if weights is None else os.fspath(weights),
            preset,
            test_statistics,
            None if match_points is None else int(match_points),
            None if passes is None else int(passes),
            None if accept is None else float(accept),
        )
        if match_points is not None and int(match_points) < 0:
            raise ValueError(f"match_points must be at least 0, got {match_points}")
        if passes is not None and int(passes) < 1:
            raise ValueError(f"passes must be at least 1, got {passes}")
        self._native = _rgm.Registrar(*self._settings)

    @property
    def name(self) -> str:
        """The method's name as ``rgm register`` prints it (``auto+refine`` by default)."""
        return self._native.name

    def register(self, source: np.ndarray, target: np.ndarray) -> RegistrationResult:
        """The rigid transform that maps ``source`` onto ``target``.

        Args:
            source: the cloud to move, a float32 or float64 NumPy array of shape (N, 3).
            target: the cloud to move it onto, float32 or float64, shape (M, 3). Clouds of
                any size and scale work: RGM moves both into its unit-sphere frame with one
                common scale, and reports the transform in the clouds' own units.

        Returns:
            A RegistrationResult; ``transformation`` is target ← source.

        Raises:
            ValueError: an argument that is not a float32/float64 array of shape (N, 3), or
                that holds NaN or infinity (the message names it, its shape and dtype).
            RuntimeError: the method found no transform (e.g. too few points for RGM's
                neighbour graph, or no correspondence survived).
            MemoryError: RGM would need more memory than this process may take (free memory,
                ``ulimit -v``, cgroup limit), checked before it starts; fewer ``match_points``
                fit.
        """
        source = _points("source", source)
        target = _points("target", target)
        return self._native.register(source, target)

    def register_many(
        self,
        pairs: Iterable[Tuple[np.ndarray, np.ndarray]],
        output: Optional[PathLike] = None,
    ) -> Union[List[RegistrationResult], dict]:
        """``register`` on each (source, target) of ``pairs``, on all cores at once.

        The pairs run in parallel on rgm's threads (one per core) with the GIL released; each
        result is the one ``register`` gives for its pair alone. ``pairs`` may be any
        iterable, a generator too: pairs are taken from it as threads come free, so only the
        pairs being registered are held at once. Ctrl-C interrupts at once.

        Args:
            pairs: (source, target) pairs of clouds, each as ``register`` takes them.
            output: a JSON Lines file to write instead of returning results: one line per
                pair, as ``rgm register --pairs --output`` writes them (after a header line
                that records the settings), the pairs named ``pairs[I].source`` and
                ``pairs[I].target`` by their index. Resumable: a later call with the same
                file and settings skips the pairs with a line there (a failed pair's line
                is done again). A file that is not rgm's, one of other settings, or one
                another run is writing is refused (ValueError) and left as it is.

        Returns:
            A list of RegistrationResult, in the order of ``pairs``; with ``output``, the
            tally ``{"registered": n, "not_registered": n, "failed": n, "skipped": n}``.

        Raises:
            ValueError: a pair that is not two clouds, or a cloud that ``register`` refuses
                (the message names the pair's index: ``pairs[3] target ...``); pairs before it
                are registered (and written to ``output``).
            PairsError: a RuntimeError, when the method found no transform for some pairs:
                its message names the first (``pair 3: rgm+refine failed: ...``), its
                ``results`` holds every pair's result (``None`` where it failed) and its
                ``errors`` each failed pair's (index, message). With ``output``, failed pairs
                are lines with their ``"error"`` instead.
            OSError: ``output`` cannot be read or written.
        """

        def checked():
            for index, pair in enumerate(pairs):
                try:
                    source, target = pair
                except (TypeError, ValueError):
                    raise ValueError(
                        f"pairs[{index}] must be a (source, target) pair of clouds, "
                        f"got {type(pair).__name__}"
                    ) from None
                yield (_points(f"pairs[{index}] source", source), _points(f"pairs[{index}] target", target))

        if output is not None:
            counts = self._native.register_many_into(checked(), os.fspath(output))
            return dict(zip(("registered", "not_registered", "failed", "skipped"), counts))
        results, errors = self._native.register_many(checked())
        if errors:
            raise PairsError(results, errors)
        return results

    def __reduce__(self):
        # Unpickled through the cache of rgm.register: a process pool's worker loads the
        # network once, however many tasks carry the Registrar.
        return (_cached_registrar, self._settings)

    def __repr__(self) -> str:
        names = ("method", "refine", "weights", "preset", "test_statistics", "match_points", "passes", "accept")
        given = ", ".join(f"{n}={v!r}" for n, v in zip(names, self._settings) if v is not None)
        return f"rgm.Registrar({given})"


def _file_identity(path: Optional[str]):
    """What tells one weights file from another at the same path: its resolved path, device,
    inode, size and modification time (``None`` for the built-in model, or a missing file,
    which Registrar then reports)."""
    if path is None:
        return None
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=8)
def _registrar(settings, weights_identity) -> Registrar:
    """The Registrar of ``settings``, built once per distinct settings and weights file: a
    file rewritten at the same path is loaded again, not served from the cache."""
    return Registrar(*settings)


def _cached_registrar(*settings) -> Registrar:
    """The cached Registrar of ``settings`` (the third is the weights path)."""
    return _registrar(settings, _file_identity(settings[2]))


def register(
    source: np.ndarray,
    target: np.ndarray,
    method: str = DEFAULT_METHOD,
    refine: bool = _rgm.DEFAULT_REFINE,
    weights: Optional[PathLike] = None,
    preset: Optional[str] = None,
    test_statistics: Optional[str] = None,
    match_points: Optional[int] = None,
    passes: Optional[int] = None,
    accept: Optional[float] = None,
) -> RegistrationResult:
    """The rigid transform that maps ``source`` onto ``target``, as ``rgm register`` finds it.

    With no option this runs exactly what ``rgm register SRC TGT`` runs (both take their
    defaults from one place in rgm): the RGM network with the model built into rgm and FGR,
    each refined by ICP on the full clouds, and the result that overlaps better
    (``result.candidates`` holds both). The method is loaded once per distinct set of options
    and reused by later calls; ``rgm.Registrar`` does the same explicitly.

    Args:
        source: the cloud to move, a float32 or float64 NumPy array of shape (N, 3),
            C-contiguous or not.
        target: the cloud to move it onto, float32 or float64, shape (M, 3). Clouds of any
            size and scale work: RGM moves both into its unit-sphere frame with one common
            scale, and reports the transform in the clouds' own units.
        method: ``"auto"`` (FGR, and RGM where FGR's result is doubtful, the better by its
            overlap score), ``"rgm"``,
            ``"fgr"`` or ``"icp"``. Default: the method of ``rgm register``
            (``rgm.DEFAULT_METHOD``, ``"auto"``).
        refine: refine the transform of RGM or FGR (both, with ``"auto"``) by ICP on the full
            clouds (``rgm register``'s default); ``False`` gives the method's own transform,
            as the paper's tables do. ICP ignores it.
        weights: RGM and auto only: a safetensors weight file (``rgm train`` makes them; the authors'
            PyTorch weights convert to one). Default: the model built into rgm.
        preset: RGM or auto with ``weights`` only: their network sizes, ``"paper"`` (default),
            ``"small"``, ``"fast"`` or ``"tiny"``.
        test_statistics: RGM or auto with ``weights`` only: batch-norm statistics at test time,
            ``"cloud"`` for weights from ``rgm train``, ``"running"`` (default) for the
            authors' weights.
        match_points: RGM and auto only: match on at most this many random points of each cloud
            (fixed seed); 0: every point. Default: every point for the built-in model (256 in
            ``auto``), 1,024 with ``weights``.
        passes: RGM and auto only: passes of network, matching and Kabsch. Default: 2.
        accept: auto only: take FGR's result without running the network when its overlap
            score (0 to 2) reaches this; ``float("inf")`` runs both on every pair. Default:
            that of ``rgm register``.

    Returns:
        A RegistrationResult: ``transformation`` ((4, 4) float64, target ← source),
        ``fitness``, ``inlier_rmse``, ``correspondences`` ((K, 2) int64), ``time_ms``, and
        ``registered`` (``False``, with a ``reason``, when no candidate is credible).

    Raises:
        ValueError: a cloud that is not a float32/float64 (N, 3) array or holds NaN or
            infinity (the message names the argument, its shape and dtype); an option that
            does not fit the method, or weights that cannot be loaded.
        TypeError: ``refine`` that is not True or False.
        RuntimeError: the method found no transform for this pair.

    Example::

        >>> result = rgm.register(source, target)
        >>> aligned = source @ result.rotation.T + result.translation
    """
    registrar = _cached_registrar(
        method,
        _flag("refine", refine),
        None if weights is None else os.fspath(weights),
        preset,
        test_statistics,
        None if match_points is None else int(match_points),
        None if passes is None else int(passes),
        None if accept is None else float(accept),
    )
    return registrar.register(source, target)


@dataclass(frozen=True)
class MergeResult:
    """Every scan of an object in one frame, as ``rgm merge`` puts them (``rgm.merge``).

    Attributes:
        poses: per scan, in the order given, its (4, 4) float64 pose model ← scan, or ``None``
            for a scan no trusted pair links (left unplaced rather than forced in).
        registered: per scan, whether it was placed.
        component: per placed scan, its group (0 the largest): scans in separate groups are
            merged each in its own frame; ``None`` when unplaced.
        residual: per placed scan, the median point-to-plane distance of its points to the
            other scans of its component, in the scans' units.
        on_loop: per scan, whether one of its trusted pairs lies on a loop of trusted pairs; a
            placed scan without one hangs on pairs nothing else checks (two scans never have one).
        points: (P, 3) float64, component 0's scans in its frame, one point per ``voxel`` cube.
        scan_index: (P,) int64, the scan each of ``points`` comes from.
    """

    poses: list
    registered: list
    component: list
    residual: list
    on_loop: list
    points: np.ndarray
    scan_index: np.ndarray


def merge(scans, voxel: Optional[float] = None, method: str = "scene") -> MergeResult:
    """Puts every scan of ``scans`` (each in its own frame, any order) into one frame, as
    ``rgm merge`` does: pairs registered by ``method`` (``rgm merge``'s, ``"scene"``, by
    default) in rounds chosen from the poses the pairs so far give, wrong pairs found by
    cycles of three that do not close, a pose graph, then each scan refined against the others
    (docs/multiway.md).

    Args:
        scans: a list of float32 or float64 (N, 3) arrays, at least 2.
        voxel: the merged cloud keeps one point per cube of this side. Default: the scans'
            point spacing (the median distance from a point to its nearest neighbour).
        method: the pairwise method (``rgm.METHODS``), refined as ``rgm register`` refines.

    Returns:
        A MergeResult.

    Raises:
        ValueError: fewer than 2 scans, or a scan that is not a float (N, 3) array or holds
            NaN or infinity (the message names it).
        RuntimeError: a scan of fewer than 3 points (the message gives its index).
    """
    arrays = [_points(f"scans[{k}]", scan) for k, scan in enumerate(scans)]
    registrar = _cached_registrar(method, _rgm.DEFAULT_REFINE, None, None, None, None, None, None)
    poses, component, residual, on_loop, points, scan_index = registrar._native.merge(
        arrays, None if voxel is None else float(voxel)
    )
    return MergeResult(
        poses=list(poses),
        registered=[p is not None for p in poses],
        component=list(component),
        residual=list(residual),
        on_loop=list(on_loop),
        points=points,
        scan_index=scan_index,
    )


@dataclass(frozen=True)
class Metrics:
    """The paper's metrics of one registered pair (spec §5 of rgm).

    Attributes:
        mae_r_deg: mean absolute error of the xyz Euler angles, degrees (anisotropic, DCP's,
            with no wrap-around).
        mae_t: mean absolute error of the translation over the 3 axes.
        mie_r_deg: angle of R_gtᵀ R_pred, degrees (isotropic, RPM-Net's).
        mie_t: ‖t_pred − t_gt‖.
        ccd: clipped Chamfer distance as RGM's code computes it (distances clipped at 0.1,
            source moved by the prediction, mean both ways).
        chamfer: mean squared nearest distances both ways, unclipped.
        recall: MAE(R) < 1° and MAE(t) < 0.1.
    """

    mae_r_deg: float
    mae_t: float
    mie_r_deg: float
    mie_t: float
    ccd: float
    chamfer: float
    recall: bool


def metrics(
    R_pred: np.ndarray,
    t_pred: np.ndarray,
    R_gt: np.ndarray,
    t_gt: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
) -> Metrics:
    """The paper's metrics of a predicted transform against the truth, as ``rgm eval`` scores.

    Args:
        R_pred: (3, 3) predicted rotation, target ← source (orthonormal within 1e-4).
        t_pred: (3,) predicted translation.
        R_gt: (3, 3) true rotation (``BenchmarkPair.rotation``).
        t_gt: (3,) true translation (``BenchmarkPair.translation``).
        source: the source cloud as given to the method, (N, 3) float32 or float64.
        target: the target cloud, (M, 3) float32 or float64.

    Returns:
        Metrics: MAE and MIE of rotation and translation, CCD, Chamfer distance, recall.

    Raises:
        ValueError: a wrongly shaped or non-finite argument, or a rotation that is not one.
    """
    pred = _homogeneous(
        _matrix("R_pred", R_pred, (3, 3)), _matrix("t_pred", np.ravel(t_pred), (3,))
    )
    truth = _homogeneous(_matrix("R_gt", R_gt, (3, 3)), _matrix("t_gt", np.ravel(t_gt), (3,)))
    values = _rgm.metrics(pred, truth, _points("source", source), _points("target", target))
    return Metrics(**values)


@dataclass(frozen=True, eq=False)
class BenchmarkPair:
    """One ModelNet40 benchmark pair with its ground truth, as ``rgm eval`` registers it.

    Attributes:
        index: the pair's index in its split (also its random seed).
        source: (N, 3) float64, the moved (and for noise/partial, cropped and jittered) source.
        target: (M, 3) float64 target.
        transformation: (4, 4) float64 true transform target ← source.
        correspondences: (K, 2) int64 true (source index, target index) pairs (exact for
            clean; rebuilt from distances for noise and partial).
        label: category label (0–39).
        category: category name (``airplane``).
        shape: the shape's name (``airplane_0627``).
    """

    index: int
    source: np.ndarray
    target: np.ndarray
    transformation: np.ndarray
    correspondences: np.ndarray
    label: int
    category: str
    shape: str

    @property
    def rotation(self) -> np.ndarray:
        """The (3, 3) true rotation."""
        return self.transformation[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        """The (3,) true translation."""
        return self.transformation[:3, 3]


class ModelNetPairs(Sequence):
    """The benchmark's pairs of one setting and split: a sequence of BenchmarkPair.

    Made by ``rgm.modelnet_pairs``. ``len()`` gives the number of pairs; indexing and
    iteration make each pair on demand (the same pair for the same index, every time).
    """

    def __init__(self, native: "_rgm.ModelNetPairs") -> None:
        self._native = native

    def __len__(self) -> int:
        return len(self._native)

    @overload
    def __getitem__(self, index: int) -> BenchmarkPair: ...

    @overload
    def __getitem__(self, index: slice) -> list: ...

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = int(index)
        if index < 0:
            index += len(self)
        if not 0 <= index < len(self):
            raise IndexError(f"pair index out of range for {len(self)} pairs")
        source, target, truth, pairs, label, category, shape = self._native.pair(index)
        return BenchmarkPair(index, source, target, truth, pairs, label, category, shape)

    def __iter__(self) -> Iterator[BenchmarkPair]:
        for index in range(len(self)):
            yield self[index]


def modelnet_pairs(
    data_dir: PathLike,
    setting: str = "partial",
    split: str = "test",
    limit: Optional[int] = None,
    unseen: bool = False,
) -> ModelNetPairs:
    """The ModelNet40 benchmark pairs that ``rgm eval`` and ``rgm pairs`` use.

    Pair ``i`` is made from the split's shape ``i`` with a random generator seeded by ``i``
    (the paper's protocol, spec §1 of rgm), so every method, run and tool sees the same
    pairs: register them with any method and score it with ``rgm.metrics``.

    Args:
        data_dir: the ModelNet40 ``.npy`` tree (with ``modelnet40_shape_names.txt``) or the
            HDF5 release ``modelnet40_ply_hdf5_2048``.
        setting: ``"clean"`` (same points, random pose), ``"noise"`` (Gaussian jitter) or
            ``"partial"`` (each cloud cropped to 70 % by a random plane, then jittered).
        split: ``"test"`` (the official test split, every table of the paper) or
            ``"validation"`` (the last 20 % of the training split, per category).
        limit: use only the first ``limit`` pairs.
        unseen: test on the unseen categories (labels 20–39) only.

    Returns:
        ModelNetPairs, a sequence of BenchmarkPair (loading the dataset takes a few seconds).

    Raises:
        OSError: the folder or a file cannot be read.
        ValueError: an unknown setting or split, or a folder that is not ModelNet40.
    """
    if limit is not None and int(limit) < 0:
        raise ValueError(f"limit must be at least 0, got {limit}")
    native = _rgm.ModelNetPairs(
        os.fspath(data_dir),
        setting,
        split,
        bool(unseen),
        None if limit is None else int(limit),
    )
    return ModelNetPairs(native)
