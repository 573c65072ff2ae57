//! The wrappers that compose registrars without knowing what they wrap: [`Refined`] (its
//! transform improved by a [`Refiner`]), [`Normalised`] (the pair centred and scaled into the
//! unit-sphere frame, for a registrar or a refiner), [`AtResolution`] (a last refinement of a
//! dense pair only, at its own point spacing), [`RefinedWhereNear`] (that refinement before a
//! cascade judges a nearly right result), [`UpTo`] (a method of its own for tiny clouds),
//! [`OnFirstUse`] (a method made only when a pair needs it) and [`Named`] (a composition under
//! the name users chose it by).

use std::fmt;
use std::sync::Arc;
use std::time::Instant;

use rgm_geom::frame::{FrameRule, NearPair, Normalisation};
use rgm_geom::{GeomError, PointCloud, RigidTransform};

use crate::check::{Check, CoincidesAtSpacing};
use crate::fit::Fit;
use crate::methods::refine::RefineConfig;
use crate::prepared::{indexed_pair, Prepared};
use crate::refiner::{AtSpacing, Refiner};
use crate::registrar::{elapsed_ms, MethodId, Progress, Registrar, Registration};
use crate::thinning::Density;

/// `inner`, then `refiner` from its transform, on the clouds `inner` was given: named
/// `inner`'s name `+` the refiner's. The result is the refiner's (scored as it scores); the
/// iterations add up; `inner`'s candidates and doubt are kept.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined<R, F = RefineConfig> {
    pub inner: R,
    pub refiner: F,
}

impl<R, F> Refined<R, F> {
    /// `inner` refined by `refiner`.
    pub fn new(inner: R, refiner: F) -> Self {
        Self { inner, refiner }
    }
}

impl<E: From<GeomError>, R: Registrar<E>, F: Refiner> Registrar<E> for Refined<R, F> {
    fn id(&self) -> MethodId {
        MethodId {
            refiner: Some(self.refiner.name()),
            ..self.inner.id()
        }
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let coarse = self.inner.register_prepared(source, target, progress)?;
        let fine = self
            .refiner
            .refine(source, target, &coarse.result.t_target_source)?;
        Ok(Registration {
            result: Fit {
                iterations: coarse.result.iterations + fine.result.iterations,
                ..fine.result
            },
            correspondences: fine.correspondences,
            time_ms: elapsed_ms(start),
            candidates: coarse.candidates,
            chosen: coarse.chosen,
            doubt: coarse.doubt.or(fine.doubt),
        })
    }
}

/// `inner` on the pair in the unit-sphere frame by `rule` ([`Normalisation::of_pair`]), far
/// outliers ([`FrameRule::near`]) left out; the result is given back in the caller's frame:
/// transforms undone, correspondences indexing the clouds as given, RMSE in the caller's units,
/// fitness counting the far outliers as source points without a partner. It wraps a
/// [`Registrar`] or a [`Refiner`] (whose starting transform is taken into the frame first).
#[derive(Clone, Debug, PartialEq)]
pub struct Normalised<R> {
    pub inner: R,
    pub rule: FrameRule,
}

impl<R> Normalised<R> {
    /// `inner` in the frame `rule` gives.
    pub fn new(inner: R, rule: FrameRule) -> Self {
        Self { inner, rule }
    }

    /// `run` on the pair in its unit-sphere frame, given the frame; its registration given back
    /// in the caller's frame.
    fn in_frame<E>(
        rule: &FrameRule,
        source: &PointCloud,
        target: &PointCloud,
        run: impl FnOnce(&Prepared, &Prepared, &Normalisation) -> Result<Registration, E>,
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let near = NearPair::of(source, target, rule);
        let (fs, ft) = near.moved(); // (N', 3), (M', 3)
        let (frame, source_near, target_near) = (near.frame, near.source.0, near.target.0);
        let mut found = run(&Prepared::new(&fs), &Prepared::new(&ft), &frame)?;
        let result = &mut found.result;
        result.t_target_source = frame.undo(&result.t_target_source);
        result.inlier_rmse *= frame.scale;
        if !source.is_empty() {
            result.fitness *= fs.len() as f64 / source.len() as f64;
        }
        for (i, j) in &mut found.correspondences {
            (*i, *j) = (source_near[*i], target_near[*j]);
        }
        for candidate in &mut found.candidates {
            candidate.t_target_source = frame.undo(&candidate.t_target_source);
        }
        found.time_ms = elapsed_ms(start);
        Ok(found)
    }
}

impl<E: From<GeomError>, R: Registrar<E>> Registrar<E> for Normalised<R> {
    fn id(&self) -> MethodId {
        self.inner.id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let inner = &mut self.inner;
        Self::in_frame(&self.rule, source, target, |fs, ft, _| {
            inner.register_prepared(fs, ft, progress)
        })
    }
}

impl<F: Refiner> Refiner for Normalised<F> {
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    fn refine(
        &self,
        source: &Prepared,
        target: &Prepared,
        initial: &RigidTransform,
    ) -> rgm_geom::Result<Registration> {
        Self::in_frame(&self.rule, source, target, |fs, ft, frame| {
            self.inner.refine(fs, ft, &frame.redo(initial))
        })
    }
}

/// `inner`, then, on a pair denser than `density`, `refiner` from its transform
/// (by default [`AtSpacing`]: point-to-plane stages at the clouds' own point spacing, finer than
/// the coarse refinement `inner` ran); named as `inner`, whose last refinement this completes.
/// A pair no denser (the density the methods were tuned at) is returned as `inner` found it:
/// its noise may exceed its spacing, and stages finer than the coarse ones would fit the noise.
#[derive(Clone, Debug, PartialEq)]
pub struct AtResolution<R, F = AtSpacing> {
    pub inner: R,
    pub refiner: F,
    pub density: Density,
}

impl<E: From<GeomError>, R: Registrar<E>, F: Refiner> Registrar<E> for AtResolution<R, F> {
    fn id(&self) -> MethodId {
        self.inner.id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        if !self.density.is_exceeded_by(source.len(), target.len()) {
            return self.inner.register_prepared(source, target, progress);
        }
        // The refinement scores its own transform.
        let found = self.inner.register_unscored(source, target, progress)?;
        refined_further(&self.refiner, found, source, target, start)
    }
}

/// `found` refined by `refiner` from its transform, its candidates and doubt kept, its
/// iterations added up, timed from `start`.
fn refined_further<E: From<GeomError>, F: Refiner>(
    refiner: &F,
    found: Registration,
    source: &Prepared,
    target: &Prepared,
    start: Instant,
) -> Result<Registration, E> {
    let fine = refiner.refine(source, target, &found.result.t_target_source)?;
    Ok(Registration {
        result: Fit {
            iterations: found.result.iterations + fine.result.iterations,
            converged: found.result.converged && fine.result.converged,
            ..fine.result
        },
        correspondences: fine.correspondences,
        time_ms: elapsed_ms(start),
        doubt: found.doubt.or(fine.doubt),
        ..found
    })
}

/// `inner`, then `refiner` from its transform only where `near` takes it (a pose that nearly
/// coincides with the target at the pair's point spacing); named as `inner`. A cascade that asks
/// a result to coincide at a finer spacing than a coarse refinement reaches (a dense scan's)
/// then judges a nearly right result at the pair's resolution, while a pose far from the truth
/// (a room's wrong pose; any pose of scan-line sweeps, which `near` never takes) costs no
/// refinement before it is turned down. With [`AtSpacing`] as the refiner, an [`AtResolution`]
/// around the cascade finds the winner refined already ([`Prepared::refinement`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RefinedWhereNear<R, F = AtSpacing> {
    pub inner: R,
    pub refiner: F,
    pub near: CoincidesAtSpacing,
}

impl<R, F: Refiner> RefinedWhereNear<R, F> {
    /// `found` refined when `near` takes it, as it was otherwise.
    fn refined_if_near<E: From<GeomError>>(
        &self,
        found: Registration,
        source: &Prepared,
        target: &Prepared,
        start: Instant,
    ) -> Result<Registration, E> {
        if !self
            .near
            .takes(source, target, &found.result.t_target_source)
        {
            return Ok(found);
        }
        refined_further(&self.refiner, found, source, target, start)
    }
}

impl<E: From<GeomError>, R: Registrar<E>, F: Refiner> Registrar<E> for RefinedWhereNear<R, F> {
    fn id(&self) -> MethodId {
        self.inner.id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let found = self.inner.register_prepared(source, target, progress)?;
        self.refined_if_near(found, source, target, start)
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let found = self.inner.register_unscored(source, target, progress)?;
        self.refined_if_near(found, source, target, start)
    }
}

/// `small` on a pair of at most `points` points per cloud, `other` on any other pair: tiny
/// clouds (a few markers) need a method of their own ([`crate::methods::triplets`]), which cannot run on
/// large ones. Named as `other`, the method a pair usually gets.
#[derive(Clone, Debug, PartialEq)]
pub struct UpTo<S, R> {
    pub points: usize,
    pub small: S,
    pub other: R,
}

impl<E, S: Registrar<E>, R: Registrar<E>> Registrar<E> for UpTo<S, R> {
    fn id(&self) -> MethodId {
        self.other.id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.one_for(source, target)
            .register_prepared(source, target, progress)
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.one_for(source, target)
            .register_unscored(source, target, progress)
    }
}

impl<S, R> UpTo<S, R> {
    /// `small` or `other`, whichever registers this pair.
    fn one_for<E>(&mut self, source: &Prepared, target: &Prepared) -> &mut dyn Registrar<E>
    where
        S: Registrar<E>,
        R: Registrar<E>,
    {
        if source.len().max(target.len()) <= self.points {
            &mut self.small
        } else {
            &mut self.other
        }
    }
}

/// `inner` under the base name `base` (its refiner kept): a composition that users choose by a
/// name of its own (`scene`) is reported by that name, not by the part that usually runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Named<R> {
    pub base: &'static str,
    pub inner: R,
}

impl<E, R: Registrar<E>> Registrar<E> for Named<R> {
    fn id(&self) -> MethodId {
        MethodId {
            base: self.base,
            ..self.inner.id()
        }
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.inner.register_prepared(source, target, progress)
    }
}

/// The method `make` returns, made when it first registers a pair: a composite that may never
/// run it (the cascade's network, when it accepts FGR's result) does not pay for making it.
/// A failure to make it is the registration's error, and the next registration tries again.
/// Copies share `make` and each keep what they made.
pub struct OnFirstUse<R, E> {
    id: MethodId,
    make: Arc<dyn Fn() -> Result<R, E> + Send + Sync>,
    made: Option<R>,
}

impl<R, E> OnFirstUse<R, E> {
    /// The method named `id` (which must be what the method `make` returns is named), not yet
    /// made.
    pub fn new(id: MethodId, make: impl Fn() -> Result<R, E> + Send + Sync + 'static) -> Self {
        Self {
            id,
            make: Arc::new(make),
            made: None,
        }
    }

    /// The method, if a registration has made it.
    pub fn made(&self) -> Option<&R> {
        self.made.as_ref()
    }
}

impl<R: Clone, E> Clone for OnFirstUse<R, E> {
    fn clone(&self) -> Self {
        Self {
            id: self.id,
            make: self.make.clone(),
            made: self.made.clone(),
        }
    }
}

impl<R: fmt::Debug, E> fmt::Debug for OnFirstUse<R, E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OnFirstUse")
            .field("id", &self.id)
            .field("made", &self.made)
            .finish_non_exhaustive()
    }
}

impl<E, R: Registrar<E>> Registrar<E> for OnFirstUse<R, E> {
    fn id(&self) -> MethodId {
        self.id
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let method = match &mut self.made {
            Some(method) => method,
            None => self.made.insert((self.make)()?),
        };
        method.register_prepared(source, target, progress)
    }
}

/// `inner`, its result doubted when `check` doubts it (a result `inner` doubts already keeps its
/// own reason). Named as `inner`.
#[derive(Clone, Debug, PartialEq)]
pub struct Checked<R, C> {
    pub inner: R,
    pub check: C,
}

impl<E: From<GeomError>, R: Registrar<E>, C: Check> Registrar<E> for Checked<R, C> {
    fn id(&self) -> MethodId {
        self.inner.id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let mut found = self.inner.register_prepared(source, target, progress)?;
        if found.doubt.is_none() {
            indexed_pair(source, target);
            found.doubt = self.check.doubt(source, target, &found);
        }
        found.time_ms = elapsed_ms(start);
        Ok(found)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::Coincides;
    use crate::methods::fgr::FgrConfig;
    use crate::methods::icp::IcpConfig;
    use crate::methods::refine::{RefineConfig, ResolutionConfig};
    use crate::registrar::DynRegistrar;
    use crate::testing::{Fixed, AT_SPACING, DENSITY, FRAME};
    use crate::RegistrationError;
    use rgm_geom::testing::{airplane, box_surface};
    use rgm_geom::{Matrix3, Point3, Vector3};

    /// 200 points on a twisted curve, and the same points moved by 5° and 0.02.
    fn curve_pair() -> (PointCloud, PointCloud) {
        let source = PointCloud::new(
            (0..200)
                .map(|i| {
                    let s = i as f64 / 200.0;
                    Point3::new((7.0 * s).cos(), (5.0 * s).sin(), s * s)
                })
                .collect(),
        );
        let pose = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, 5f64.to_radians()),
            Vector3::new(0.02, 0.0, 0.0),
        );
        let target = source.transformed(&pose);
        (source, target)
    }

    #[test]
    fn on_first_use_makes_its_method_once_and_only_when_a_pair_needs_it() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let made = Arc::new(AtomicUsize::new(0));
        let count = made.clone();
        let fails = Arc::new(std::sync::atomic::AtomicBool::new(true));
        let failing = fails.clone();
        let mut lazy = OnFirstUse::new(MethodId::plain("fgr"), move || {
            count.fetch_add(1, Ordering::SeqCst);
            if failing.load(Ordering::SeqCst) {
                Err(GeomError::Degenerate {
                    op: "make",
                    why: "not yet".into(),
                })
            } else {
                Ok(FgrConfig::default())
            }
        });
        // Named and copied without being made.
        assert_eq!(Registrar::<GeomError>::id(&lazy).to_string(), "fgr");
        let _copy = lazy.clone();
        assert_eq!(made.load(Ordering::SeqCst), 0);
        let (source, target) = curve_pair();
        // A failure to make it is the registration's error; the next one tries again.
        let err = lazy.register(&source, &target).unwrap_err();
        assert!(err.to_string().contains("not yet"), "{err}");
        assert!(lazy.made().is_none());
        fails.store(false, Ordering::SeqCst);
        let first = lazy.register(&source, &target).unwrap();
        let second = lazy.register(&source, &target).unwrap();
        assert_eq!(made.load(Ordering::SeqCst), 2);
        // The same result as the method made directly.
        let direct =
            Registrar::<GeomError>::register(&mut FgrConfig::default(), &source, &target).unwrap();
        assert_eq!(first.result.t_target_source, direct.result.t_target_source);
        assert_eq!(second.result.t_target_source, direct.result.t_target_source);
    }

    /// Issue 44, D2: ICP or FGR that find nothing hand back a transform no point supports; it
    /// is doubted (not registered), refined or not.
    #[test]
    fn a_single_method_that_finds_no_overlap_is_doubted() {
        let (source, target) = curve_pair();
        let far = target.transformed(&RigidTransform::new(
            rgm_geom::Matrix3::identity(),
            Vector3::new(100.0, 0.0, 0.0),
        ));
        let found =
            Registrar::<GeomError>::register(&mut IcpConfig::default(), &source, &far).unwrap();
        assert_eq!(found.result.t_target_source, RigidTransform::identity());
        assert!(found.correspondences.is_empty());
        let doubt = found.doubt.expect("doubted");
        assert!(
            doubt.starts_with("0 source points lie within 0.1 of the target"),
            "{doubt}"
        );
        let mut refined = Refined::new(IcpConfig::default(), RefineConfig::default());
        let found = Registrar::<GeomError>::register(&mut refined, &source, &far).unwrap();
        assert!(found.doubt.is_some());
        // The same methods on the pair they register are not doubted.
        let found = Registrar::<GeomError>::register(&mut refined, &source, &target).unwrap();
        assert!(found.doubt.is_none(), "{:?}", found.doubt);
    }

    #[test]
    fn only_a_nearly_coinciding_result_is_refined_first_and_the_refinement_after_keeps_it() {
        // 8,000 points on a box (spacing ≈ 0.008): a result 0.015 off along the diagonal lies
        // about a spacing off every face, one 0.2 off about 14.
        let dense = box_surface(8000, 3);
        let at_spacing = AtSpacing {
            coarser_than: 0.05,
            scoring_distance: 0.02,
            config: ResolutionConfig::default(),
        };
        let near = CoincidesAtSpacing {
            coincides: Coincides {
                near: 4.0,
                ..AT_SPACING.coincides
            },
            ..AT_SPACING
        };
        let diagonal = Vector3::new(1.0, 1.0, 1.0).normalize();
        for (shift, is_near) in [(0.015, true), (0.2, false)] {
            let off = RigidTransform::new(Matrix3::identity(), diagonal * shift);
            let mut fixed = Fixed::new("fixed", 0.0);
            fixed.transform = off;
            let mut first = RefinedWhereNear {
                inner: fixed,
                refiner: at_spacing.clone(),
                near,
            };
            let (source, target) = (Prepared::new(&dense), Prepared::new(&dense));
            let found = Registrar::<RegistrationError>::register_unscored(
                &mut first,
                &source,
                &target,
                &mut |_| {},
            )
            .unwrap();
            // What the refinement alone makes of the result, on a pair of its own.
            let (alone_source, alone_target) = (Prepared::new(&dense), Prepared::new(&dense));
            let alone = at_spacing
                .refine(&alone_source, &alone_target, &off)
                .unwrap();
            let t = found.result.t_target_source;
            if is_near {
                assert_eq!(t, alone.result.t_target_source, "{shift}");
                assert!(t.translation.norm() < 1e-3, "{shift}: {t:?}");
                assert_eq!(found.result.iterations, alone.result.iterations);
            } else {
                assert_eq!(t, off, "{shift}");
                assert_eq!(found.result.iterations, 0);
            }
            // Around it, the winner is refined once: a refined one is kept as it was, with no
            // further iteration.
            let mut around = AtResolution {
                inner: first,
                refiner: at_spacing.clone(),
                density: DENSITY,
            };
            let (source, target) = (Prepared::new(&dense), Prepared::new(&dense));
            let last = Registrar::<RegistrationError>::register(&mut around, &source, &target)
                .unwrap()
                .result;
            assert_eq!(
                last.t_target_source, alone.result.t_target_source,
                "{shift}"
            );
            assert_eq!(last.iterations, alone.result.iterations, "{shift}");
        }
    }

    #[test]
    fn at_resolution_asks_a_dense_pair_s_inner_method_for_its_transform_alone() {
        let fixed = Fixed::new("fixed", 0.0);
        let mut at_resolution = AtResolution {
            inner: fixed.clone(),
            refiner: RefineConfig::default(),
            density: DENSITY,
        };
        // Dense: the refinement scores its own transform, so the inner one is not scored.
        let dense = box_surface(3000, 1);
        let found =
            Registrar::<RegistrationError>::register(&mut at_resolution, &dense, &dense).unwrap();
        assert_eq!((fixed.calls(), fixed.scored_calls()), (1, 0));
        assert_eq!(found.result.inlier_count, 3000);
        assert_eq!(found.correspondences.len(), 3000);
        // No denser than `density`: returned as the inner method scored it.
        let sparse = box_surface(500, 2);
        Registrar::<RegistrationError>::register(&mut at_resolution, &sparse, &sparse).unwrap();
        assert_eq!((fixed.calls(), fixed.scored_calls()), (2, 1));
    }

    #[test]
    fn names_compose() {
        let fgr = FgrConfig::default();
        assert_eq!(Registrar::<GeomError>::id(&fgr).to_string(), "fgr");
        let refined = Refined::new(fgr, RefineConfig::default());
        assert_eq!(
            Registrar::<GeomError>::id(&refined).to_string(),
            "fgr+refine"
        );
        let normalised = Normalised::new(refined, FRAME);
        assert_eq!(
            Registrar::<GeomError>::id(&normalised).to_string(),
            "fgr+refine"
        );
        assert_eq!(
            Registrar::<GeomError>::id(&IcpConfig::default()).to_string(),
            "icp"
        );
    }

    /// A new refinement is one type and one line where methods are composed: named by the
    /// composition, started from the inner method's transform, its result the registration's.
    #[test]
    fn a_new_refiner_is_one_type_and_one_line() {
        /// Records the transform it starts from and hands back the identity.
        #[derive(Default)]
        struct Reset {
            started_from: std::sync::Mutex<Option<RigidTransform>>,
        }
        impl Refiner for Reset {
            fn name(&self) -> &'static str {
                "reset"
            }
            fn refine(
                &self,
                _: &Prepared,
                _: &Prepared,
                initial: &RigidTransform,
            ) -> rgm_geom::Result<Registration> {
                *self.started_from.lock().unwrap() = Some(*initial);
                let result = Fit {
                    t_target_source: RigidTransform::identity(),
                    iterations: 1,
                    converged: true,
                    inlier_count: 0,
                    fitness: 0.0,
                    inlier_rmse: 0.0,
                };
                Ok(Registration::single(result, Vec::new(), Instant::now()))
            }
        }
        let (source, target) = curve_pair();
        let mut method = Refined::new(FgrConfig::default(), Reset::default());
        assert_eq!(Registrar::<GeomError>::id(&method).to_string(), "fgr+reset");
        let found = Registrar::<GeomError>::register(&mut method, &source, &target).unwrap();
        let fgr = Registrar::<GeomError>::register(&mut FgrConfig::default(), &source, &target)
            .unwrap()
            .result;
        let started_from = method.refiner.started_from.lock().unwrap().unwrap();
        assert_eq!(started_from, fgr.t_target_source);
        assert_eq!(found.result.t_target_source, RigidTransform::identity());
        assert_eq!(found.result.iterations, fgr.iterations + 1);
        // Point-to-point ICP as a refiner: `fgr+p2p`, and it lands on the true pose.
        let mut method = Refined::new(FgrConfig::default(), IcpConfig::default());
        assert_eq!(Registrar::<GeomError>::id(&method).to_string(), "fgr+p2p");
        let found = Registrar::<GeomError>::register(&mut method, &source, &target).unwrap();
        let angle = found.result.t_target_source.rotation_angle_deg();
        assert!((angle - 5.0).abs() < 0.01, "{angle}°");
    }

    #[test]
    fn correspondences_are_the_pairs_behind_the_inlier_count() {
        let (source, target) = curve_pair();
        let refine = RefineConfig::default();
        let methods: [(Box<dyn DynRegistrar<GeomError>>, f64); 3] = [
            (
                Box::new(IcpConfig::default()),
                IcpConfig::default().max_correspondence_distance,
            ),
            (
                Box::new(FgrConfig::default()),
                FgrConfig::default().maximum_correspondence_distance,
            ),
            (
                Box::new(Refined::new(FgrConfig::default(), refine.clone())),
                refine.finest_distance(),
            ),
        ];
        for (mut method, max_distance) in methods {
            let name = method.id();
            let found = method.register(&source, &target).unwrap();
            let pairs = &found.correspondences;
            assert_eq!(pairs.len(), found.result.inlier_count, "{name}");
            assert!(pairs.len() > 100, "{name}: {}", pairs.len());
            for &(i, j) in pairs {
                let d = (found.result.t_target_source.apply(&source.points[i]) - target.points[j])
                    .norm();
                assert!(d < max_distance, "{name}: {d}");
            }
        }
    }

    #[test]
    fn normalised_registers_a_pair_at_any_scale_and_gives_it_back_in_the_callers_frame() {
        // The airplane at 1,000 times its size, far from the origin, turned by 10°: FGR's
        // unit-sphere radii fit it only in the normalised frame.
        let shape = airplane();
        let big = PointCloud::new(
            shape
                .points
                .iter()
                .map(|p| Point3::from(p.coords * 1000.0 + Vector3::new(5e3, -2e3, 1e3)))
                .collect(),
        );
        let pose = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.1, -0.05, 10f64.to_radians()),
            Vector3::new(30.0, 0.0, -20.0),
        );
        let target = big.transformed(&pose);
        let mut method = Normalised::new(
            Refined::new(FgrConfig::default(), RefineConfig::default()),
            FRAME,
        );
        let found: Registration =
            Registrar::<GeomError>::register(&mut method, &big, &target).unwrap();
        let t = found.result.t_target_source;
        let angle = t.inverse().compose(&pose).rotation_angle_deg();
        assert!(angle < 0.01, "{angle}°");
        assert!((t.translation - pose.translation).norm() < 1.0, "{t:?}");
        // Fitness counts every source point; the RMSE is in the caller's units (the clouds
        // coincide: well below a point spacing of the big airplane, tens of units).
        assert!(found.result.fitness > 0.99, "{}", found.result.fitness);
        assert!(
            found.result.inlier_rmse < 1.0,
            "{}",
            found.result.inlier_rmse
        );
        for &(i, j) in &found.correspondences {
            assert!((t.apply(&big.points[i]) - target.points[j]).norm() < 40.0);
        }
        assert_eq!(found.correspondences.len(), found.result.inlier_count);
    }
}
