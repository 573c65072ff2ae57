//! One shape for every registration method: a [`Registrar`] maps a source cloud onto a target
//! cloud and returns a [`Registration`]. The methods of [`crate::methods`] implement it, and the
//! wrappers and composites of [`crate::compose`] compose registrars without knowing what they
//! wrap ([`crate::compose::Refined`], [`crate::compose::Normalised`], [`crate::compose::BestOf`],
//! ...).
//!
//! The trait is generic over its error so that methods above this crate (the RGM network)
//! compose with the classical ones here: every registrar of this crate works with any error
//! type that a [`rgm_geom::GeomError`] converts into.

use std::fmt;
use std::time::Instant;

use rgm_geom::{PointCloud, RigidTransform};

use crate::fit::{score, Fit, Score};
use crate::Prepared;

/// What users call a method: its base name and the refiner its transform went through, spelled
/// `base` or `base+refiner` (`fgr+refine`) in the command line, the tables, the Python package
/// and JSON. The wrappers compose it: [`crate::compose::Refined`] names its refiner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MethodId {
    /// The method without refinement (`icp`, `fgr`, `rgm`, `auto`).
    pub base: &'static str,
    /// The [`crate::refiner::Refiner::name`] of its refinement, if it is refined.
    pub refiner: Option<&'static str>,
}

impl MethodId {
    /// The method `base`, not refined.
    pub const fn plain(base: &'static str) -> Self {
        Self {
            base,
            refiner: None,
        }
    }
}

impl fmt::Display for MethodId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.refiner {
            Some(refiner) => write!(f, "{}+{refiner}", self.base),
            None => f.write_str(self.base),
        }
    }
}

/// One method's outcome inside a composite ([`crate::compose::BestOf`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// The method that made it ([`MethodId`], with `/cells` when it ran on the
    /// [`crate::thinning::Thinning::Cells`] version of a dense pair).
    pub method: String,
    /// Its transform, in the caller's frame.
    pub t_target_source: RigidTransform,
    /// Its score ([`crate::check::overlap_score`]); the highest wins. `None` when the method
    /// failed.
    pub score: Option<f64>,
    /// Why the method failed, if it did.
    pub failure: Option<String>,
    /// Wall time of the method on the pair, in milliseconds.
    pub time_ms: f64,
}

/// What a registrar found on one pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// The transform, its iterations and inlier statistics.
    pub result: Fit,
    /// The (source index, target index) pairs behind `result.inlier_count`: the method's own
    /// matches (RGM's last hard correspondences), or the source points the transform brings
    /// within the scoring distance of their nearest target point (Open3D's correspondence set).
    pub correspondences: Vec<(usize, usize)>,
    /// Wall time of the method alone (no file reading), in milliseconds.
    pub time_ms: f64,
    /// A composite's candidates, each with its score (empty for a single method), and the index
    /// of the one returned.
    pub candidates: Vec<Candidate>,
    pub chosen: Option<usize>,
    /// Why the result is not to be trusted, when it is not (the best candidate overlaps too
    /// little, [`crate::check::Scoring::min_overlap`], or a check doubts it): the caller
    /// reports the pair as not registered, with this reason.
    pub doubt: Option<String>,
}

impl Registration {
    /// A single method's registration of `result` on `source` and `target`, its correspondences
    /// the source points that `result`'s transform brings within `max_distance` of `target`,
    /// timed from `start`; doubted when fewer than 3 are (a result no overlap supports: ICP or
    /// FGR that found nothing hands back the transform it started from).
    pub fn scored_within(
        result: Fit,
        source: &PointCloud,
        target: &Prepared,
        max_distance: f64,
        start: Instant,
    ) -> Self {
        let (_, correspondences) =
            pairs_within(source, target, &result.t_target_source, max_distance);
        let doubt = (correspondences.len() < MIN_CORRESPONDENCES).then(|| {
            format!(
                "{} source points lie within {max_distance} of the target under the result \
                 (fewer than {MIN_CORRESPONDENCES}): the method found no overlap",
                correspondences.len()
            )
        });
        Self {
            doubt,
            ..Self::single(result, correspondences, start)
        }
    }

    /// This registration with its fit scored: the source points its transform brings within
    /// `max_distance` of `target` ([`score`]) and their pairs, its iterations and convergence
    /// kept.
    pub fn fitted_within(self, source: &PointCloud, target: &Prepared, max_distance: f64) -> Self {
        let Fit {
            t_target_source,
            iterations,
            converged,
            ..
        } = self.result;
        let (scored, correspondences) =
            pairs_within(source, target, &t_target_source, max_distance);
        Self {
            result: Fit::scored(t_target_source, iterations, converged, scored),
            correspondences,
            ..self
        }
    }

    /// A single method's registration, timed from `start`.
    pub fn single(result: Fit, correspondences: Vec<(usize, usize)>, start: Instant) -> Self {
        Self {
            result,
            correspondences,
            time_ms: elapsed_ms(start),
            candidates: Vec::new(),
            chosen: None,
            doubt: None,
        }
    }
}

/// [`score`] of `source` moved by `transform` onto `target` within `max_distance`, with the
/// (source, target) index pairs behind it. // (P,)
fn pairs_within(
    source: &PointCloud,
    target: &Prepared,
    transform: &RigidTransform,
    max_distance: f64,
) -> (Score, Vec<(usize, usize)>) {
    let mut pairs = Vec::new();
    let scored = score(
        &source.points,
        target.index(),
        transform,
        max_distance,
        Some(&mut pairs),
    );
    (scored, pairs)
}

/// The fewest correspondences of a credible single method's result: fewer do not pin down a
/// rigid transform.
pub const MIN_CORRESPONDENCES: usize = 3;

/// Milliseconds since `start`.
pub fn elapsed_ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

/// Where a registration is: a step and the fraction of the work done (FGR's steps, as
/// [`crate::methods::fgr::register_with_progress`] reports them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// `downsampling`, `features`, `matching`, `optimising` or `scoring` (on the full clouds,
    /// after a downsampling), then `done`.
    pub step: &'static str,
    /// From 0 to 1.
    pub done: f64,
}

/// A registration method: the transform that maps `source` onto `target`.
pub trait Registrar<E> {
    /// The method's name.
    fn id(&self) -> MethodId;

    /// Registers `source` onto `target`, telling `progress` where it is (methods that take
    /// long on large clouds report; others say nothing). What a stage makes of the clouds (their
    /// trees, normals) stays with them for the stages after it: a wrapper hands its inner method
    /// the clouds it was given, or clouds it prepared itself when it changes them.
    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E>;

    /// [`Self::register_prepared`] for a caller that reads only the transform, iterations,
    /// candidates and doubt, and scores a transform of its own (a refinement after it, a
    /// composite judging its candidates): a composite then leaves its fit unscored
    /// ([`Fit::unscored`], no correspondences), for on a dense pair that fit is a search of every
    /// source point. Any other method registers in full.
    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.register_prepared(source, target, progress)
    }

    /// Registers `source` onto `target`, telling `progress` where it is.
    fn register_with_progress(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.register_prepared(&Prepared::new(source), &Prepared::new(target), progress)
    }

    /// Registers `source` onto `target`.
    fn register(&mut self, source: &PointCloud, target: &PointCloud) -> Result<Registration, E> {
        self.register_with_progress(source, target, &mut |_| {})
    }
}

/// A [`Registrar`] behind a pointer: cloneable and sendable to other threads, so that a
/// composite can hold methods of different types and a caller can give each thread its own copy.
pub trait DynRegistrar<E>: Registrar<E> + Send + Sync {
    /// A copy of this registrar in a new box.
    fn clone_box(&self) -> Box<dyn DynRegistrar<E>>;
}

impl<E, R: Registrar<E> + Clone + Send + Sync + 'static> DynRegistrar<E> for R {
    fn clone_box(&self) -> Box<dyn DynRegistrar<E>> {
        Box::new(self.clone())
    }
}

impl<E: 'static> Clone for Box<dyn DynRegistrar<E>> {
    fn clone(&self) -> Self {
        (**self).clone_box()
    }
}

impl<E> fmt::Debug for dyn DynRegistrar<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Registrar({})", self.id())
    }
}

impl<E> Registrar<E> for Box<dyn DynRegistrar<E>> {
    fn id(&self) -> MethodId {
        (**self).id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        (**self).register_prepared(source, target, progress)
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        (**self).register_unscored(source, target, progress)
    }
}
