//! `rgm._rgm`: the rgm crates behind NumPy arrays, for the Python package `rgm` (`rgm/` beside
//! this crate), which checks and documents every argument before it reaches here: arrays come
//! in as float64 (N, 3) clouds and (4, 4) transforms, strings as `String` (the limited API of
//! Python 3.9 cannot lend a `&str`).
//!
//! The GIL is released while Rust works ([`Python::detach`]), so Python threads register pairs
//! in parallel. Each call runs with denormals flushed on its thread (the network's Sinkhorn
//! underflows) and the thread's flags restored afterwards; OpenBLAS runs single-threaded unless
//! `OPENBLAS_NUM_THREADS` asks for more, as in the `rgm` command. Parallel work runs on a rayon
//! pool of this process ([`pool`]), so a process forked from one that registered (a process
//! pool's workers under Linux's default start method) registers too.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2};
use pyo3::exceptions::{PyMemoryError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyIterator};
use rgm_data::{DataError, ModelNet40, PairGenerator, Setting, Shape, Split};
use rgm_geom::{Matrix4, PairMetrics, Point3, PointCloud, RigidTransform};
use rgm_model::many_pairs;
use rgm_model::network::TestStatistics;
use rgm_model::Registrar as _;
use rgm_model::{Method, MethodError, MethodName, MethodOptions, Registration};
use rgm_nn::threads::with_denormals_flushed;

mod result;
use result::{Candidate, RegistrationResult};

/// How far from rigid a given 4×4 transform may be (as `rgm score` reads outside transforms).
const RIGID_TOLERANCE: f64 = 1e-4;

/// The rayon pool of this process, its workers flushing denormals, built on first use and again
/// in a forked child: a fork copies only the forking thread, so a child forked after a
/// registration holds the parent's pool without its workers, and its first parallel step would
/// wait for them for good. The parent's pool is forgotten in the child, not dropped (dropping it
/// would signal workers that do not exist, under locks they may have held).
fn pool() -> PyResult<Arc<rayon::ThreadPool>> {
    static POOL: Mutex<Option<(u32, Arc<rayon::ThreadPool>)>> = Mutex::new(None);
    let pid = std::process::id();
    let mut slot = POOL.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((owner, pool)) = slot.as_ref() {
        if *owner == pid {
            return Ok(pool.clone());
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .start_handler(|_| {
            rgm_nn::threads::flush_denormals_to_zero();
        })
        .build()
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start rgm's threads: {e}")))?;
    let pool = Arc::new(pool);
    std::mem::forget(slot.replace((pid, pool.clone())));
    Ok(pool)
}

fn value_error(err: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(err.to_string())
}

/// A dataset error: `OSError` when the system refused a read, `ValueError` otherwise.
fn data_error(err: DataError) -> PyErr {
    match err {
        DataError::Io { .. } => PyOSError::new_err(err.to_string()),
        other => value_error(other),
    }
}

/// The (N, 3) rows of `points` as a cloud.
fn cloud(points: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<PointCloud> {
    let rows = points.as_array(); // (N, 3)
    if rows.ncols() != 3 {
        return Err(value_error(format!(
            "{name} must have shape (N, 3), got {:?}",
            rows.shape()
        )));
    }
    Ok(PointCloud::new(
        rows.rows()
            .into_iter()
            .map(|r| Point3::new(r[0], r[1], r[2]))
            .collect(),
    ))
}

/// A cloud as an (N, 3) array.
fn points_array<'py>(py: Python<'py>, cloud: &PointCloud) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c]).into_pyarray(py)
}

/// A transform as its homogeneous (4, 4) matrix.
fn matrix_array<'py>(py: Python<'py>, t: &RigidTransform) -> Bound<'py, PyArray2<f64>> {
    let m = t.to_matrix4();
    Array2::from_shape_fn((4, 4), |(r, c)| m[(r, c)]).into_pyarray(py)
}

/// Index pairs as a (K, 2) int64 array.
fn pairs_array<'py>(py: Python<'py>, pairs: &[(usize, usize)]) -> Bound<'py, PyArray2<i64>> {
    Array2::from_shape_fn((pairs.len(), 2), |(k, c)| {
        let (i, j) = pairs[k];
        (if c == 0 { i } else { j }) as i64
    })
    .into_pyarray(py)
}

/// A (4, 4) matrix as a rigid transform, checked.
fn transform(matrix: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<RigidTransform> {
    let m = matrix.as_array();
    if m.shape() != [4, 4] {
        return Err(value_error(format!(
            "{name} must have shape (4, 4), got {:?}",
            m.shape()
        )));
    }
    let m = Matrix4::from_fn(|r, c| m[(r, c)]);
    RigidTransform::from_matrix4(&m, RIGID_TOLERANCE)
        .map_err(|e| value_error(format!("{name}: {e}")))
}

/// A registration method loaded once, for any number of pairs from any number of threads.
#[pyclass(frozen, module = "rgm._rgm")]
struct Registrar {
    /// Shared with the pool's work, which may outlive a call interrupted by Ctrl-C.
    copies: Arc<Copies>,
    /// What the method was built from, recorded in the output of many pairs.
    options: MethodOptions,
}

/// A method and the copies of it that threads register with.
struct Copies {
    /// Copied for a call that finds no idle copy.
    prototype: Method,
    /// Copies not in use, their buffers kept: one per thread that registered at the same time.
    idle: Mutex<Vec<Method>>,
}

impl Copies {
    /// A copy of the method for one thread's work, back among the idle ones when dropped (a
    /// panic while one was held leaves the list valid, so poisoning is ignored).
    fn lease(self: &Arc<Self>) -> Lease {
        let popped = self.idle().pop();
        Lease {
            method: Some(popped.unwrap_or_else(|| self.prototype.clone())),
            copies: self.clone(),
        }
    }

    fn idle(&self) -> MutexGuard<'_, Vec<Method>> {
        self.idle
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// A copy of the method lent by [`Copies::lease`].
struct Lease {
    method: Option<Method>, // Some until dropped
    copies: Arc<Copies>,
}

impl Drop for Lease {
    fn drop(&mut self) {
        if let Some(method) = self.method.take() {
            self.copies.idle().push(method);
        }
    }
}

/// One pair's registration and the (source, target) index pairs behind it.
type Registered = Result<(Registration, Vec<(usize, usize)>), MethodError>;

/// Registers `source` onto `target` with `method`, with its correspondences.
fn register_pair(method: &mut Method, source: &PointCloud, target: &PointCloud) -> Registered {
    let mut registration = method.register(source, target)?;
    let pairs = std::mem::take(&mut registration.correspondences);
    Ok((registration, pairs))
}

/// Runs `job` on the pool while this thread waits for it, GIL released, looking at Python's
/// signals ten times a second: Ctrl-C raises KeyboardInterrupt at once and sets the flag `job`
/// is given, so that it stops early (it ends in the background). `what` names the work in the
/// error of a panic.
fn on_pool<T: Send + 'static>(
    py: Python<'_>,
    what: &str,
    job: impl FnOnce(&AtomicBool) -> T + Send + 'static,
) -> PyResult<T> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let (done, mut result) = std::sync::mpsc::channel();
    pool()?.spawn(move || {
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            with_denormals_flushed(|| job(&flag))
        }));
        let _ = done.send(outcome); // the caller is gone after a Ctrl-C
    });
    let outcome = loop {
        // The receiver goes into the GIL-free closure and back (it may not be shared).
        let got;
        (result, got) = py.detach(move || {
            let got = result.recv_timeout(std::time::Duration::from_millis(100));
            (result, got)
        });
        match got {
            Ok(finished) => break finished,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                if let Err(interrupt) = py.check_signals() {
                    stop.store(true, Ordering::Relaxed);
                    return Err(interrupt);
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(PyRuntimeError::new_err(
                    "rgm's worker thread ended unexpectedly",
                ))
            }
        }
    };
    outcome.map_err(|_| PyRuntimeError::new_err(format!("{what} panicked (a bug in rgm)")))
}

/// The Python error of method `name` failing (`MemoryError` when it would need too much).
fn method_error(name: &str, err: MethodError) -> PyErr {
    let message = format!("{name} failed: {err}");
    match err {
        MethodError::TooMuchMemory { .. } => PyMemoryError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

#[pymethods]
impl Registrar {
    /// Builds the method of `rgm_model::MethodOptions` from these options (`None`: its
    /// default) and loads its weights.
    #[new]
    #[pyo3(signature = (method, refine, weights, preset, test_statistics, match_points, passes, accept))]
    #[allow(clippy::too_many_arguments)] // one per option of `rgm.Registrar`
    fn new(
        py: Python<'_>,
        method: String,
        refine: bool,
        weights: Option<PathBuf>,
        preset: Option<String>,
        test_statistics: Option<String>,
        match_points: Option<usize>,
        passes: Option<usize>,
        accept: Option<f64>,
    ) -> PyResult<Self> {
        let test_statistics = match test_statistics.as_deref() {
            None => None,
            Some("cloud") => Some(TestStatistics::Cloud),
            Some("running") => Some(TestStatistics::Running),
            Some(other) => {
                return Err(value_error(format!(
                    "unknown test_statistics {other:?} (expected \"cloud\" or \"running\")"
                )))
            }
        };
        let options = MethodOptions {
            method: method.parse().map_err(value_error)?,
            weights,
            preset,
            test_statistics,
            match_points,
            passes,
            refine,
            accept: accept.unwrap_or(MethodOptions::default().accept),
            ..MethodOptions::default()
        };
        let pool = pool()?;
        let prototype = py
            .detach(|| pool.install(|| options.build()))
            .map_err(value_error)?;
        Ok(Self {
            copies: Arc::new(Copies {
                prototype,
                idle: Mutex::new(Vec::new()),
            }),
            options,
        })
    }

    /// The method's name as `rgm register` prints it (`rgm+refine` when refined).
    #[getter]
    fn name(&self) -> String {
        self.copies.prototype.name()
    }

    /// Registers `source` onto `target` (float64, (N, 3) and (M, 3)).
    fn register(
        &self,
        py: Python<'_>,
        source: PyReadonlyArray2<'_, f64>,
        target: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<RegistrationResult> {
        // The arrays themselves, for the result's page (to_html): no copy of the points.
        let arrays = ((*source).clone().unbind(), (*target).clone().unbind());
        let (source, target) = (cloud(&source, "source")?, cloud(&target, "target")?);
        let copies = self.copies.clone();
        let name = &self.name();
        let (registration, pairs) = on_pool(py, name, move |_| {
            register_pair(
                copies.lease().method.as_mut().expect("leased"),
                &source,
                &target,
            )
        })?
        .map_err(|e| method_error(name, e))?;
        RegistrationResult::from_registration(py, name, &registration, &pairs, Some(arrays))
    }

    /// Puts every scan of `scans` (float64 (N, 3) arrays, each in its own frame) into one frame
    /// as `rgm merge` does (`rgm_registration::multiway::merge`, this method for the pairs):
    /// each scan's pose (`model ← scan`, (4, 4), or `None` unplaced), component, residual and
    /// whether one of its pairs lies on a loop,
    /// and component 0's scans merged, one point per cube of `voxel` (default: its spacing),
    /// with each point's scan.
    #[pyo3(signature = (scans, voxel=None))]
    fn merge<'py>(
        &self,
        py: Python<'py>,
        scans: Vec<PyReadonlyArray2<'py, f64>>,
        voxel: Option<f64>,
    ) -> PyResult<MergeFields<'py>> {
        if scans.len() < 2 {
            return Err(value_error(format!(
                "merge needs 2 scans or more, got {}",
                scans.len()
            )));
        }
        let clouds: Vec<PointCloud> = scans
            .iter()
            .enumerate()
            .map(|(k, scan)| cloud(scan, &format!("scan {k}")))
            .collect::<PyResult<_>>()?;
        let copies = self.copies.clone();
        let name = self.name();
        let (merged, clouds) = on_pool(py, &name, move |_| {
            let method = copies.prototype.clone();
            let config = rgm_registration::multiway::MultiwayConfig::default();
            let merged = rgm_registration::multiway::merge(&clouds, &method, &config, &|_| {});
            (merged, clouds)
        })?;
        let merged = merged.map_err(|e| method_error(&name, e))?;
        let voxel = voxel
            .or(merged.spacing.first().copied())
            .unwrap_or(f64::INFINITY);
        if voxel.is_nan() || voxel <= 0.0 {
            return Err(value_error(format!("voxel must be > 0, got {voxel}")));
        }
        let (model, labels) = merged.model(&clouds, 0, voxel);
        let poses = merged
            .poses
            .iter()
            .map(|p| p.map(|p| matrix_array(py, &p)))
            .collect();
        let labels = numpy::ndarray::Array1::from_iter(labels.iter().map(|&l| l as i64));
        Ok((
            poses,
            merged.component,
            merged.residual,
            merged.on_loop,
            points_array(py, &model),
            labels.into_pyarray(py),
        ))
    }

    /// Registers each (source, target) of the iterator `pairs` (float64 clouds) on all of the
    /// pool's threads, taking pairs as threads come free; the results in the order of
    /// `pairs` (`None` for a pair that failed) and each failed pair's (index, error).
    fn register_many(
        &self,
        py: Python<'_>,
        pairs: Bound<'_, PyIterator>,
    ) -> PyResult<(Vec<Option<RegistrationResult>>, Vec<PairError>)> {
        let name = self.name();
        let pulled = Pulled::new(pairs, None);
        let failed = pulled.error.clone();
        let kept: Arc<Mutex<Vec<Finished>>> = Arc::default();
        let into = kept.clone();
        let copies = self.copies.clone();
        on_pool(py, &name, move |stop| {
            many_pairs::register_all(
                &copies.prototype,
                pulled,
                None,
                &(),
                stop,
                |i, registered| lock(&into).push((i, registered)),
            )
        })?
        .map_err(|e| PyOSError::new_err(e.to_string()))?;
        if let Some(error) = lock(&failed).take() {
            return Err(error);
        }
        let mut done = std::mem::take(&mut *lock(&kept));
        done.sort_by_key(|(i, _)| *i);
        let mut results = Vec::with_capacity(done.len());
        let mut errors = Vec::new();
        for (i, registered) in done {
            match registered {
                Ok(mut registration) => {
                    let pairs = std::mem::take(&mut registration.correspondences);
                    results.push(Some(RegistrationResult::from_registration(
                        py,
                        &name,
                        &registration,
                        &pairs,
                        None,
                    )?));
                }
                Err(why) => {
                    results.push(None);
                    errors.push((i, why));
                }
            }
        }
        Ok((results, errors))
    }

    /// Registers the pairs of `pairs` as `register_many` does, each pair's line into the
    /// resumable JSON Lines file `output` (`rgm register --pairs --output`'s format, the pairs
    /// named `pairs[I].source` and `pairs[I].target`); pairs with a line there already are
    /// skipped. The tally (registered, not registered, failed, skipped).
    fn register_many_into(
        &self,
        py: Python<'_>,
        pairs: Bound<'_, PyIterator>,
        output: PathBuf,
    ) -> PyResult<(usize, usize, usize, usize)> {
        let name = self.name();
        let method = &self.copies.prototype;
        let settings = many_pairs::settings(&self.options, method).map_err(pairs_error)?;
        let output =
            Arc::new(many_pairs::Output::open(&output, &settings, &()).map_err(pairs_error)?);
        let done = output.done().clone();
        let pulled = Pulled::new(pairs, Some(done));
        let (failed, skipped) = (pulled.error.clone(), pulled.skipped.clone());
        let copies = self.copies.clone();
        let file = output.clone();
        let tally = on_pool(py, &name, move |stop| {
            many_pairs::register_all(
                &copies.prototype,
                pulled,
                Some(file.lines()),
                &(),
                stop,
                |_, _| {},
            )
        })?
        .map_err(pairs_error)?;
        if let Some(error) = lock(&failed).take() {
            return Err(error);
        }
        let skipped = skipped.load(Ordering::Relaxed);
        Ok((
            tally.registered,
            tally.not_registered,
            tally.failed,
            skipped,
        ))
    }
}

/// A failed pair of many: its index and why.
type PairError = (usize, String);

/// A pair of many as it finished: its index and its registration, or why it failed.
type Finished = (usize, Result<Registration, String>);

/// The error of many pairs: `OSError` for a file that could not be read or written, `ValueError` for
/// an output that is not rgm's or of other settings, or is busy.
fn pairs_error(err: many_pairs::PairsError) -> PyErr {
    match err {
        many_pairs::PairsError::Io { .. } => PyOSError::new_err(err.to_string()),
        other => value_error(other),
    }
}

/// `mutex` locked, a panic while it was held ignored (the data stays valid).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The pairs of a Python iterator as jobs of many pairs, pulled under the GIL by the thread that
/// takes the next job; the first Python error (a pair that is not two clouds) ends the
/// iteration and is kept for the caller. Pairs named in `skip` are passed over.
struct Pulled {
    pairs: Py<PyIterator>,
    next: usize,
    /// The pairs with a line already, and what they were (a pair of other clouds at the same
    /// place of the list runs again).
    skip: Option<HashMap<many_pairs::Key, many_pairs::Done>>,
    skipped: Arc<std::sync::atomic::AtomicUsize>,
    error: Arc<Mutex<Option<PyErr>>>,
}

impl Pulled {
    fn new(
        pairs: Bound<'_, PyIterator>,
        skip: Option<HashMap<many_pairs::Key, many_pairs::Done>>,
    ) -> Self {
        Self {
            pairs: pairs.unbind(),
            next: 0,
            skip,
            skipped: Arc::default(),
            error: Arc::default(),
        }
    }
}

impl Iterator for Pulled {
    type Item = many_pairs::Job;

    fn next(&mut self) -> Option<many_pairs::Job> {
        Python::attach(|py| loop {
            if lock(&self.error).is_some() {
                return None;
            }
            let index = self.next;
            let pair = match self.pairs.bind(py).clone().next()? {
                Ok(pair) => pair,
                Err(error) => {
                    *lock(&self.error) = Some(error);
                    return None;
                }
            };
            self.next += 1;
            let key = (
                format!("pairs[{index}].source"),
                format!("pairs[{index}].target"),
            );
            let clouds = pair
                .extract::<(PyReadonlyArray2<'_, f64>, PyReadonlyArray2<'_, f64>)>()
                .and_then(|(s, t)| Ok((cloud(&s, "source")?, cloud(&t, "target")?)));
            match clouds {
                Ok((source, target)) => {
                    let clouds = many_pairs::Clouds::Given { source, target };
                    let line = self.skip.as_ref().and_then(|skip| skip.get(&key));
                    if line.is_some_and(|line| line.is_of(&many_pairs::inputs(&clouds))) {
                        self.skipped.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    return Some(many_pairs::Job { index, key, clouds });
                }
                Err(error) => {
                    *lock(&self.error) = Some(error);
                    return None;
                }
            }
        })
    }
}

/// The paper's metrics (spec §5) of the predicted transform `pred` against `truth` (both (4, 4))
/// for the clouds `source` and `target`, as a dict of `rgm_geom::PairMetrics`'s fields.
#[pyfunction]
fn metrics<'py>(
    py: Python<'py>,
    pred: PyReadonlyArray2<'py, f64>,
    truth: PyReadonlyArray2<'py, f64>,
    source: PyReadonlyArray2<'py, f64>,
    target: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (pred, truth) = (transform(&pred, "pred")?, transform(&truth, "truth")?);
    let (source, target) = (cloud(&source, "source")?, cloud(&target, "target")?);
    let m = py
        .detach(|| PairMetrics::compute(&pred, &truth, &source, &target))
        .map_err(value_error)?;
    let dict = PyDict::new(py);
    dict.set_item("mae_r_deg", m.mae_r_deg)?;
    dict.set_item("mae_t", m.mae_t)?;
    dict.set_item("mie_r_deg", m.mie_r_deg)?;
    dict.set_item("mie_t", m.mie_t)?;
    dict.set_item("ccd", m.ccd)?;
    dict.set_item("chamfer", m.chamfer)?;
    dict.set_item("recall", m.recall)?;
    Ok(dict)
}

/// A merge's fields, in the order `rgm/__init__.py` reads them.
type MergeFields<'py> = (
    Vec<Option<Bound<'py, PyArray2<f64>>>>, // (S,) model ← scan, (4, 4) each
    Vec<Option<usize>>,                     // (S,) component
    Vec<Option<f64>>,                       // (S,) residual
    Vec<bool>,                              // (S,) one of its pairs on a loop
    Bound<'py, PyArray2<f64>>,              // (P, 3) component 0's merged points
    Bound<'py, numpy::PyArray1<i64>>,       // (P,) each point's scan
);

/// One benchmark pair's fields, in the order `rgm/__init__.py` reads them.
type PairFields<'py> = (
    Bound<'py, PyArray2<f64>>, // (N, 3) source
    Bound<'py, PyArray2<f64>>, // (M, 3) target
    Bound<'py, PyArray2<f64>>, // (4, 4) true transformation, target ← source
    Bound<'py, PyArray2<i64>>, // (K, 2) true correspondences
    usize,                     // category label
    String,                    // category name
    String,                    // shape name
);

/// The benchmark's pairs of one setting and split, as `rgm eval` makes them.
#[pyclass(frozen, module = "rgm._rgm")]
struct ModelNetPairs {
    /// Category names in label order. // (40,)
    categories: Vec<String>,
    /// The split's shapes in order, cut to the limit. // (P,)
    shapes: Vec<Shape>,
    generator: PairGenerator,
}

#[pymethods]
impl ModelNetPairs {
    #[new]
    #[pyo3(signature = (data_dir, setting, split, unseen, limit))]
    fn new(
        py: Python<'_>,
        data_dir: PathBuf,
        setting: String,
        split: String,
        unseen: bool,
        limit: Option<usize>,
    ) -> PyResult<Self> {
        let setting: Setting = setting.parse().map_err(value_error)?;
        let split = match split.as_str() {
            "test" => Split::Test,
            "validation" => Split::Validation,
            other => {
                return Err(value_error(format!(
                    "unknown split {other:?} (expected \"test\" or \"validation\")"
                )))
            }
        };
        let dataset = py
            .detach(|| ModelNet40::open(&data_dir))
            .map_err(data_error)?;
        let mut shapes: Vec<Shape> = dataset.split(split, unseen).into_iter().cloned().collect();
        shapes.truncate(limit.unwrap_or(usize::MAX));
        Ok(Self {
            categories: dataset.categories,
            shapes,
            generator: PairGenerator::new(setting),
        })
    }

    fn __len__(&self) -> usize {
        self.shapes.len()
    }

    /// Pair `index` (its RNG seed, as in `rgm eval` and `rgm pairs`).
    fn pair<'py>(&self, py: Python<'py>, index: usize) -> PyResult<PairFields<'py>> {
        let shapes: Vec<&Shape> = self.shapes.iter().collect();
        let pair = py
            .detach(|| self.generator.test_pair(&shapes, index))
            .map_err(data_error)?;
        let shape = shapes[index];
        Ok((
            points_array(py, &pair.source),
            points_array(py, &pair.target),
            matrix_array(py, &pair.t_target_source),
            pairs_array(py, &pair.correspondence.pairs),
            pair.label,
            self.categories.get(pair.label).cloned().unwrap_or_default(),
            shape.name.clone(),
        ))
    }
}

#[pymodule]
fn _rgm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    if std::env::var_os("OPENBLAS_NUM_THREADS").is_none() {
        rgm_nn::threads::set_blas_threads(1);
    }
    let defaults = MethodOptions::default();
    m.add("DEFAULT_METHOD", defaults.method.name())?;
    m.add("DEFAULT_REFINE", defaults.refine)?;
    m.add(
        "METHODS",
        MethodName::ALL.iter().map(|n| n.name()).collect::<Vec<_>>(),
    )?;
    m.add_class::<Registrar>()?;
    m.add_class::<RegistrationResult>()?;
    m.add_class::<Candidate>()?;
    m.add_class::<ModelNetPairs>()?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    Ok(())
}
