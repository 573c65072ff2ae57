//! The result classes of `rgm._rgm`, `rgm.RegistrationResult` and `rgm.Candidate`: named,
//! read-only fields, a `repr`, pickling by their fields (results travel back from process
//! pools and Dask workers), and the page of a result (`to_html`, `_repr_html_`: rgm-viz's).

use std::path::PathBuf;

use numpy::{PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::{PyList, PySlice, PyTuple};
use pyo3::IntoPyObjectExt;
use rgm_model::policy::TUNED;
use rgm_model::Registration;
use rgm_registration::registrar::Candidate as GeomCandidate;
use rgm_viz::html::{
    inline_frame, InlierDistance, Page, ResultNotes, DEFAULT_POINT_BUDGET, INLINE_POINT_BUDGET,
};

use crate::{cloud, matrix_array, pairs_array, transform, value_error};

/// Python's `repr` of `value`.
fn repr<'py>(py: Python<'py>, value: impl IntoPyObject<'py>) -> PyResult<String> {
    Ok(value.into_bound_py_any(py)?.repr()?.to_string())
}

/// One candidate of the default method (``"auto"``), which runs RGM and FGR and keeps the one
/// that overlaps better.
///
/// Attributes:
///     method: ``"rgm+refine"`` or ``"fgr+refine"`` (without ``+refine`` when unrefined; with ``/cells``
///         on the second thinning of a dense pair).
///     score: the share of each cloud's points within 0.02 of the other cloud after the
///         transform (in the unit-sphere frame), source to target plus target to source: 0 to
///         2, higher is better; the highest wins. ``None`` when the method failed.
///     transformation: (4, 4) float64, target ← source (the identity when it failed).
///     failure: why the method failed, or ``None``.
#[pyclass(frozen, module = "rgm", get_all)]
pub struct Candidate {
    method: String,
    score: Option<f64>,
    transformation: Py<PyArray2<f64>>, // (4, 4)
    failure: Option<String>,
}

#[pymethods]
impl Candidate {
    #[new]
    #[pyo3(signature = (method, score, transformation, failure=None))]
    fn new(
        method: String,
        score: Option<f64>,
        transformation: Py<PyArray2<f64>>,
        failure: Option<String>,
    ) -> Self {
        Self {
            method,
            score,
            transformation,
            failure,
        }
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "Candidate(method={}, score={}, failure={})",
            repr(py, &self.method)?,
            repr(py, self.score)?,
            repr(py, &self.failure)?,
        ))
    }

    /// Pickles as its fields (results travel back from process pools and Dask workers).
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let c = slf.get();
        let fields = (
            &c.method,
            c.score,
            c.transformation.clone_ref(py),
            &c.failure,
        );
        Ok((slf.get_type().into_any(), fields.into_pyobject(py)?))
    }
}

/// The arrays of a pair's clouds: (N, 3) source and (M, 3) target, float64.
pub type CloudArrays = (Py<PyArray2<f64>>, Py<PyArray2<f64>>);

/// The outcome of registering a source cloud onto a target cloud.
///
/// Attributes:
///     transformation: (4, 4) float64 homogeneous matrix that maps source coordinates into
///         the target's frame (target ← source), ``y = R x + t``, as Open3D's
///         ``registration_*`` results.
///     rotation: the (3, 3) rotation R of ``transformation`` (a view of it).
///     translation: the (3,) translation t of ``transformation`` (a view of it).
///     fitness: share of source points the method's score counts as inliers (for a refined
///         result: source points with a target point within the finest ICP distance).
///     inlier_rmse: root mean square distance of those inliers, in the clouds' units.
///     correspondences: (K, 2) int64 (source index, target index) pairs behind the result:
///         RGM's matches of its last pass (unrefined), or the source points that the transform
///         brings within the method's scoring distance of their nearest target point.
///     time_ms: the method's own time in milliseconds (no conversion, no file reading).
///     method: the method run, as ``rgm register`` names it (``auto+refine`` by default,
///         ``rgm+refine`` for RGM refined).
///     iterations: RGM's passes plus ICP iterations, or the method's iterations.
///     converged: whether the method's convergence test stopped it.
///     candidates: the default method's candidates (RGM's, then FGR's; on a pair denser
///         than 1,024 points both again on a second thinning, ``rgm+refine/cells`` and
///         ``fgr+refine/cells``), each a Candidate with its score; empty for the other methods.
///     chosen: the method of the candidate returned, or ``None`` for the other methods.
///     registered: ``False`` when the result is not credible (the default method's best
///         candidate overlaps too little: fewer than one point in twenty of each cloud lies on
///         the other), ``reason`` says why; ``transformation`` is then the best guess, not to
///         be used as a registration.
///     reason: why ``registered`` is ``False``, or ``None``.
///
/// ``to_html(path)`` writes the registration as a page that turns in a browser; in Jupyter a
/// result shows that page inline. A result of ``register`` holds its two clouds for it (the
/// arrays themselves, not copies); other results (``register_many``'s, unpickled ones) take
/// them as arguments.
#[pyclass(frozen, module = "rgm")]
pub struct RegistrationResult {
    #[pyo3(get)]
    transformation: Py<PyArray2<f64>>, // (4, 4)
    #[pyo3(get)]
    fitness: f64,
    #[pyo3(get)]
    inlier_rmse: f64,
    #[pyo3(get)]
    correspondences: Py<PyArray2<i64>>, // (K, 2)
    #[pyo3(get)]
    time_ms: f64,
    #[pyo3(get)]
    method: String,
    #[pyo3(get)]
    iterations: usize,
    #[pyo3(get)]
    converged: bool,
    #[pyo3(get)]
    candidates: Py<PyList>, // of Candidate
    #[pyo3(get)]
    chosen: Option<String>,
    #[pyo3(get)]
    registered: bool,
    #[pyo3(get)]
    reason: Option<String>,
    /// The arrays `register` was given, for the page; `None` for other results.
    clouds: Option<CloudArrays>,
}

impl RegistrationResult {
    /// The result of `registration` by method `name`, with its correspondences `pairs`, holding
    /// the arrays of the pair's clouds when given (for its page).
    pub fn from_registration(
        py: Python<'_>,
        name: &str,
        registration: &Registration,
        pairs: &[(usize, usize)],
        clouds: Option<CloudArrays>,
    ) -> PyResult<Self> {
        let result = &registration.result;
        let candidates = registration
            .candidates
            .iter()
            .map(|c| {
                Candidate::new(
                    c.method.to_string(),
                    c.score,
                    matrix_array(py, &c.t_target_source).unbind(),
                    c.failure.clone(),
                )
            })
            .collect::<Vec<_>>();
        Ok(Self {
            transformation: matrix_array(py, &result.t_target_source).unbind(),
            fitness: result.fitness,
            inlier_rmse: result.inlier_rmse,
            correspondences: pairs_array(py, pairs).unbind(),
            time_ms: registration.time_ms,
            method: name.to_string(),
            iterations: result.iterations,
            converged: result.converged,
            candidates: PyList::new(py, candidates)?.unbind(),
            chosen: registration
                .chosen
                .map(|k| registration.candidates[k].method.to_string()),
            registered: registration.doubt.is_none(),
            reason: registration.doubt.clone(),
            clouds,
        })
    }

    /// The page of this result on `source` and `target` (the held clouds when not given),
    /// showing at most `budget` points.
    fn page(
        &self,
        py: Python<'_>,
        source: Option<PyReadonlyArray2<'_, f64>>,
        target: Option<PyReadonlyArray2<'_, f64>>,
        budget: usize,
    ) -> PyResult<String> {
        let (source, target) =
            match (source, target, &self.clouds) {
                (Some(source), Some(target), _) => {
                    (cloud(&source, "source")?, cloud(&target, "target")?)
                }
                (None, None, Some((source, target))) => (
                    cloud(&source.bind(py).readonly(), "source")?,
                    cloud(&target.bind(py).readonly(), "target")?,
                ),
                (None, None, None) => return Err(value_error(
                    "this result holds no clouds (only register's results do; register_many's, \
                     unpickled and constructed ones do not): give them, \
                     to_html(path, source, target)",
                )),
                _ => return Err(value_error("give both source and target, or neither")),
            };
        let t_target_source =
            transform(&self.transformation.bind(py).readonly(), "transformation")?;
        let candidates = self
            .candidates
            .bind(py)
            .iter()
            .map(|item| {
                let item = item.cast_into::<Candidate>()?;
                let c = item.get();
                Ok(GeomCandidate {
                    method: c.method.clone(),
                    t_target_source: transform(
                        &c.transformation.bind(py).readonly(),
                        "a candidate's transformation",
                    )?,
                    score: c.score,
                    failure: c.failure.clone(),
                    time_ms: f64::NAN, // not kept in Python: the page shows none
                })
            })
            .collect::<PyResult<Vec<_>>>()?;
        let pairs = self.correspondences.bind(py).readonly();
        let pairs = pairs.as_array(); // (K, 2)
        let correspondences = pairs
            .rows()
            .into_iter()
            .map(
                |row| match (usize::try_from(row[0]), usize::try_from(row[1])) {
                    (Ok(i), Ok(j)) => Ok((i, j)),
                    _ => Err(value_error(format!(
                        "a correspondence has a negative index: {row}"
                    ))),
                },
            )
            .collect::<PyResult<Vec<_>>>()?;
        let registration = Registration {
            result: rgm_registration::Fit {
                t_target_source,
                iterations: self.iterations,
                converged: self.converged,
                inlier_count: correspondences.len(),
                fitness: self.fitness,
                inlier_rmse: self.inlier_rmse,
            },
            correspondences,
            time_ms: self.time_ms,
            chosen: self
                .chosen
                .as_ref()
                .and_then(|name| candidates.iter().position(|c| &c.method == name)),
            candidates,
            doubt: self.reason.clone(),
        };
        let page = Page {
            title: format!("rgm.register ({})", self.method),
            source: &source,
            target: &target,
            t_target_source,
            inlier_distance: InlierDistance::of_refinement(&source, &target, &TUNED.frame),
            notes: ResultNotes::of_registration(&self.method, &registration),
            point_budget: budget,
        };
        page.to_html().map_err(value_error)
    }

    /// `transformation[rows, 3 or :3]`, a view.
    fn block<'py>(
        &self,
        py: Python<'py>,
        columns: Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let rows = PySlice::new(py, 0, 3, 1);
        self.transformation.bind(py).get_item((rows, columns))
    }
}

#[pymethods]
impl RegistrationResult {
    #[new]
    #[pyo3(signature = (
        transformation, fitness, inlier_rmse, correspondences, time_ms, method, iterations,
        converged, candidates=None, chosen=None, registered=true, reason=None
    ))]
    #[allow(clippy::too_many_arguments)] // one per field, as the dataclass it replaces took them
    fn new(
        py: Python<'_>,
        transformation: Py<PyArray2<f64>>,
        fitness: f64,
        inlier_rmse: f64,
        correspondences: Py<PyArray2<i64>>,
        time_ms: f64,
        method: String,
        iterations: usize,
        converged: bool,
        candidates: Option<Bound<'_, PyAny>>,
        chosen: Option<String>,
        registered: bool,
        reason: Option<String>,
    ) -> PyResult<Self> {
        let candidates = match candidates {
            Some(items) => PyList::new(py, items.try_iter()?.collect::<PyResult<Vec<_>>>()?)?,
            None => PyList::empty(py),
        };
        Ok(Self {
            transformation,
            fitness,
            inlier_rmse,
            correspondences,
            time_ms,
            method,
            iterations,
            converged,
            candidates: candidates.unbind(),
            chosen,
            registered,
            reason,
            clouds: None,
        })
    }

    /// The (3, 3) rotation R of ``transformation`` (a view of it).
    #[getter]
    fn rotation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.block(py, PySlice::new(py, 0, 3, 1).into_any())
    }

    /// The (3,) translation t of ``transformation`` (a view of it).
    #[getter]
    fn translation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.block(py, 3i64.into_pyobject(py)?.into_any())
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "RegistrationResult(method={}, registered={}, reason={}, fitness={}, \
             inlier_rmse={}, correspondences=<{} pairs>, iterations={}, converged={}, \
             time_ms={}, chosen={}, candidates={}, transformation={})",
            repr(py, &self.method)?,
            repr(py, self.registered)?,
            repr(py, &self.reason)?,
            repr(py, self.fitness)?,
            repr(py, self.inlier_rmse)?,
            self.correspondences.bind(py).len()?,
            self.iterations,
            repr(py, self.converged)?,
            repr(py, self.time_ms)?,
            repr(py, &self.chosen)?,
            repr(py, self.candidates.bind(py))?,
            repr(py, self.transformation.bind(py))?,
        ))
    }

    /// Writes the registration as one self-contained HTML page at `path` (no network needed to
    /// view it): the clouds before and after, the source coloured by its distance to the
    /// target, the transform and the candidates; at most `points` points in all (larger clouds
    /// thinned by stride, as the page says). `source` and `target` (float64 (N, 3)) default to
    /// the clouds `register` was given.
    #[pyo3(signature = (path, source=None, target=None, points=DEFAULT_POINT_BUDGET))]
    fn to_html(
        &self,
        py: Python<'_>,
        path: PathBuf,
        source: Option<PyReadonlyArray2<'_, f64>>,
        target: Option<PyReadonlyArray2<'_, f64>>,
        points: usize,
    ) -> PyResult<()> {
        let html = self.page(py, source, target, points)?;
        rgm_data::io::output::write_file(&path, |out| out.write_all(html.as_bytes()))
            .map_err(|err| PyOSError::new_err(format!("writing {}: {err}", path.display())))
    }

    /// The page, inline in a notebook (an iframe, at most 50,000 points); `None` (the plain
    /// repr) for a result that holds no clouds.
    fn _repr_html_(&self, py: Python<'_>) -> PyResult<Option<String>> {
        if self.clouds.is_none() {
            return Ok(None);
        }
        Ok(Some(inline_frame(&self.page(
            py,
            None,
            None,
            INLINE_POINT_BUDGET,
        )?)))
    }

    /// Pickles as its fields (results travel back from process pools and Dask workers); the
    /// clouds stay behind.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let r = slf.get();
        let fields = (
            r.transformation.clone_ref(py),
            r.fitness,
            r.inlier_rmse,
            r.correspondences.clone_ref(py),
            r.time_ms,
            &r.method,
            r.iterations,
            r.converged,
            r.candidates.clone_ref(py),
            &r.chosen,
            r.registered,
            &r.reason,
        );
        Ok((slf.get_type().into_any(), fields.into_pyobject(py)?))
    }
}
