//! A registration method chosen by name and options, as plain data. The `rgm` command and the
//! Python package both take these from their users and build the [`Method`] here, so that the
//! two run the same method with the same defaults: [`MethodOptions::default`] is what
//! `rgm register` runs when given no option. Every composition of registrars that users can
//! name is written here, in [`MethodOptions::build`]:
//!
//! | name | composition |
//! |---|---|
//! | `icp` | `Checked<IcpConfig, InFrame<TUNED.refined_checks()>>` (its own refinement, checked in the unit-sphere frame) |
//! | `fgr`, `fgr+refine` | `Normalised<Checked<FgrConfig, TUNED.unrefined_checks()>>`, `Normalised<Checked<Refined<FgrConfig>, TUNED.refined_checks()>>` |
//! | `rgm`, `rgm+refine` | [`Normalised`]`<Checked<RgmRegistrar, TUNED.unrefined_checks()>>`, `Normalised<Checked<Refined<RgmRegistrar>, TUNED.refined_checks()>>` |
//! | `auto` | `Normalised<Checked<Thinned<Cascade { first: FgrConfig, rest: [Normalised<RgmRegistrar>] }>, TUNED.unrefined_checks()>>` |
//! | `auto+refine` | `Normalised<Checked<AtResolution<Thinned<Cascade { first: Refined<FgrConfig>, rest: [Refined<Normalised<RgmRegistrar>>] }>, AtSpacing>, TUNED.refined_checks()>>` |
//!
//! (`BestOf[first, rest]` in place of the `Cascade` when `accept` takes nothing; inside the
//! `Normalised`, `UpTo { points: 32, small: TripletConfig, .. }` sends a pair of a few points to
//! [`rgm_registration::methods::triplets`]; with `+refine`, a pair denser than the training clouds (a scan, a room)
//! goes through `Cascade { first: RefinedWhereNear<the Thinned composite, AtSpacing>, rest: [Sc2Config] }`
//! judged by `TUNED.scene_accept` ([`crate::policy`]): second-order compatibility on the pair's own FPFH
//! matches, [`rgm_registration::methods::sc2`], where the object cascade's result does not coincide with the
//! target at the pair's spacing once refined there (when it nearly coincides, `TUNED.scene_refine_near`).)
//!
//! [`Checked`] doubts a result whose overlap is not one where the clouds coincide, or that a
//! rival pose fits nearly as well (`TUNED.refined_checks()`, [`crate::policy`]): refined results, ICP's (refined by its
//! nature) and, since issue 59, unrefined ones too (`--no-refine`, the paper's protocol), which
//! must also lie near where the refinement takes them (`TUNED.unrefined_checks()`): an unrefined result
//! that coincides may still be degrees off.
//!
//! `Refined<R>` refines with [`RefineConfig`] (`+refine`); any other [`rgm_registration::refiner::Refiner`]
//! composes the same way (`Refined::new(FgrConfig::default(), IcpConfig::default())` is
//! `fgr+p2p`).
//!
//! RGM refines in the network's frame (distances in unit-sphere units for any input); `auto`
//! runs both methods in that frame, on two thinnings of a dense pair, as a cascade: FGR first,
//! and the network only when FGR's result overlaps less than [`MethodOptions::accept`] or, short
//! of a whole overlap, fits as well turned about one of the source's axes
//! ([`rgm_registration::check::Acceptance`]); the network then runs one chain of passes, without the
//! second chain of cycle consistency, since the overlap score judges its result.

use std::path::PathBuf;
use std::str::FromStr;

use rgm_registration::check::{Acceptance, InFrame, Scoring};
use rgm_registration::compose::{
    AtResolution, BestOf, Cascade, Checked, Named, Normalised, OnFirstUse, Refined,
    RefinedWhereNear, Thinned, UpTo,
};
use rgm_registration::methods::fgr::{self, FgrConfig};
use rgm_registration::methods::icp::{self, IcpConfig};
use rgm_registration::methods::refine::{RefineConfig, ResolutionConfig};
use rgm_registration::methods::sc2::Sc2Config;
use rgm_registration::methods::triplets::TripletConfig;
use rgm_registration::refiner::AtSpacing;
use rgm_registration::registrar::{DynRegistrar, Registrar};
use rgm_registration::thinning::Thinning;

use rgm_nn::Precision;

use crate::error::MethodError;
use crate::method::Method;
use crate::network::{Config, TestStatistics};
use crate::policy::TUNED;
use crate::procedure::{self, RgmRegistrar, TRAINING_DENSITY};

/// The name of FGR and RGM as a cascade ([`MethodName::Auto`]).
pub const AUTO: &str = "auto";

/// The name of [`MethodName::Scene`].
pub const SCENE: &str = "scene";

/// The registration methods selectable by name.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MethodName {
    /// Point-to-point ICP from the identity.
    Icp,
    /// Fast Global Registration on FPFH features.
    Fgr,
    /// The RGM network: the built-in model or given weights.
    Rgm,
    /// FGR, and RGM where FGR's result may be wrong, each refined, and the better by a score
    /// without ground truth ([`rgm_registration::compose`]).
    #[default]
    Auto,
    /// `auto` with only its scene stage on pairs denser than the training clouds: `rgm merge`'s
    /// default ([`DenseStage::SceneOnly`]).
    Scene,
}

impl MethodName {
    /// Every name, in the order the command line lists them.
    pub const ALL: [Self; 5] = [Self::Icp, Self::Fgr, Self::Rgm, Self::Auto, Self::Scene];

    /// The name as users spell it (`rgm`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Icp => icp::NAME,
            Self::Fgr => fgr::NAME,
            Self::Rgm => procedure::NAME,
            Self::Auto => AUTO,
            Self::Scene => SCENE,
        }
    }

    /// What the method does, for a command line's help.
    pub fn help(self) -> String {
        match self {
            Self::Icp => "Point-to-point ICP from the identity".into(),
            Self::Fgr => "Fast Global Registration on FPFH features".into(),
            Self::Rgm => "The RGM network: the model built into rgm, or --weights".into(),
            Self::Auto => format!(
                "FGR, then RGM when FGR's result overlaps less than --accept (both clouds' \
                 share of points within {} of the other, in the unit-sphere \
                 frame) or, short of a whole overlap, fits as well turned about one of the \
                 source's axes, each refined, \
                 and the result that overlaps better: `rgm register`'s default",
                TUNED.scoring.overlap_distance
            ),
            Self::Scene => format!(
                "auto, but on clouds denser than {} points only its scene stage (second-order \
                 spatial compatibility on the pair's own FPFH matches, refined) instead of the \
                 object cascade and then the scene stage: about half the time of auto where the \
                 pair is hard, as accurate on the Stanford scans; `rgm merge`'s default, where \
                 a pair left unregistered costs one edge of many",
                TRAINING_DENSITY.points
            ),
        }
    }
}

/// The names of [`MethodName::name`] and the help of [`MethodName::help`] on a command line.
#[cfg(feature = "clap")]
impl clap::ValueEnum for MethodName {
    fn value_variants<'a>() -> &'a [Self] {
        &Self::ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()).help(self.help()))
    }
}

impl FromStr for MethodName {
    type Err = MethodError;

    fn from_str(s: &str) -> Result<Self, MethodError> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let known: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
                MethodError::InvalidOptions(format!(
                    "unknown method {s:?} (expected one of {})",
                    known.join(", ")
                ))
            })
    }
}

/// The scene stage's global estimator ([`Sc2Config`]): it registered all 12 redkitchen dev
/// pairs where RANSAC (Open3D's tutorial settings) registered 10 or 11, at any of the seeds,
/// mates, compatibilities and lengths tried (docs/baselines.md, "Scenes: second-order
/// compatibility").
pub fn scene_stage() -> Sc2Config {
    Sc2Config::default()
}

/// A method and its options; `None` leaves an option at the method's own default.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodOptions {
    /// The method (FGR and RGM as a cascade by default).
    pub method: MethodName,
    /// RGM weights (for `rgm` and `auto`): a safetensors file with the authors' parameter
    /// names; `None`: the model built into rgm ([`crate::weights::builtin_registrar`]).
    pub weights: Option<PathBuf>,
    /// The network sizes `weights` were trained with ([`Config::preset`]; `paper` when `None`).
    pub preset: Option<String>,
    /// Batch-norm statistics for `weights` (`running` when `None`, as for the authors'
    /// weights; the built-in model has its own).
    pub test_statistics: Option<TestStatistics>,
    /// RGM matches on at most this many random points of each cloud; 0: every point. When
    /// `None`: the built-in model's training size (`TUNED.cascade_match_points` in `auto`), or
    /// `TUNED.weights_match_points` with `weights` ([`crate::policy`]).
    pub match_points: Option<usize>,
    /// RGM's passes (2 when `None`, as in the paper).
    pub passes: Option<usize>,
    /// RGM's matrix products: f32 (the default), or bf16 where the processor has AMX or
    /// AVX-512 BF16 ([`Precision`]).
    pub precision: Precision,
    /// Refine the transform of RGM or FGR (both, for `auto`) with [`rgm_registration::methods::refine`]
    /// ([`Method::is_refined`]); on by default, as in `rgm register` (the paper's protocol, and
    /// `rgm eval`, turn it off). ICP is its own refinement and ignores it.
    pub refine: bool,
    /// `auto` takes FGR's result without running the network when it scores at least this
    /// ([`rgm_registration::check::overlap_score`], 0 to 2) and overlaps wholly or does not fit as
    /// well turned (`TUNED.accept`, [`crate::policy`]); `f64::INFINITY` runs both on every pair.
    pub accept: f64,
}

impl Default for MethodOptions {
    /// What `rgm register` runs when given no option.
    fn default() -> Self {
        Self {
            method: MethodName::default(),
            weights: None,
            preset: None,
            test_statistics: None,
            match_points: None,
            passes: None,
            precision: Precision::F32,
            refine: true,
            accept: TUNED.accept.score,
        }
    }
}

impl MethodOptions {
    /// The method with its weights loaded, refined when asked. Errors name the option that
    /// does not fit the method (an RGM option with ICP or FGR, a preset or statistics without
    /// weights, zero passes or points), or the weight file that failed.
    pub fn build(&self) -> Result<Method, MethodError> {
        self.check()?;
        let refine = self.refine.then(RefineConfig::default);
        Ok(match (self.method, refine) {
            // ICP runs in the caller's frame, from the identity there; its result is checked
            // in the unit-sphere frame, where the checks' lengths are set.
            (MethodName::Icp, _) => Method::new(Checked {
                inner: IcpConfig::default(),
                check: InFrame {
                    check: TUNED.refined_checks(),
                    rule: TUNED.frame,
                },
            }),
            // FGR's lengths are set for unit-sphere shapes: the pair is moved into that frame
            // first, as the network's is, and its refined result checked there.
            (MethodName::Fgr, None) => Method::new(Normalised::new(
                Checked {
                    inner: FgrConfig::default(),
                    check: TUNED.unrefined_checks(),
                },
                TUNED.frame,
            )),
            (MethodName::Fgr, Some(refine)) => Method::new(Normalised::new(
                Checked {
                    inner: Refined::new(FgrConfig::default(), refine),
                    check: TUNED.refined_checks(),
                },
                TUNED.frame,
            )),
            (MethodName::Rgm, None) => Method::new(Normalised::new(
                Checked {
                    inner: self.build_rgm()?,
                    check: TUNED.unrefined_checks(),
                },
                TUNED.frame,
            )),
            (MethodName::Rgm, Some(refine)) => Method::new(Normalised::new(
                Checked {
                    inner: Refined::new(self.build_rgm()?, refine),
                    check: TUNED.refined_checks(),
                },
                TUNED.frame,
            )),
            (MethodName::Auto | MethodName::Scene, refine) => {
                let accept = Acceptance {
                    score: self.accept,
                    ..TUNED.accept
                };
                let dense = match self.method {
                    MethodName::Scene => DenseStage::SceneOnly,
                    _ => DenseStage::ObjectThenScene,
                };
                match &self.weights {
                    // Given weights are read now, so that a bad file is an error before any
                    // pair; the built-in model cannot fail to load, and a pair whose FGR result
                    // the cascade accepts never needs it.
                    Some(_) => auto(self.build_cascade_rgm()?, refine, accept, dense),
                    None => {
                        let options = self.clone();
                        let rgm =
                            OnFirstUse::new(RgmRegistrar::ID, move || options.build_cascade_rgm());
                        auto(rgm, refine, accept, dense)
                    }
                }
            }
        })
    }

    fn check(&self) -> Result<(), MethodError> {
        let invalid = |why: &str| Err(MethodError::InvalidOptions(why.to_string()));
        let rgm_only = self.weights.is_some()
            || self.preset.is_some()
            || self.test_statistics.is_some()
            || self.match_points.is_some()
            || self.passes.is_some()
            || self.precision != Precision::F32;
        if matches!(self.method, MethodName::Icp | MethodName::Fgr) && rgm_only {
            return invalid("weights, preset, test statistics, match points, passes and precision apply to the rgm, auto and scene methods only");
        }
        if self.weights.is_none() && (self.preset.is_some() || self.test_statistics.is_some()) {
            return invalid("a preset and test statistics describe given weights; the built-in model has its own");
        }
        if self.passes == Some(0) {
            return invalid("passes must be at least 1");
        }
        let cascade = matches!(self.method, MethodName::Auto | MethodName::Scene);
        if !cascade && self.accept != TUNED.accept.score {
            return invalid("accept applies to the auto and scene methods only");
        }
        if self.method == MethodName::Scene && !self.refine {
            return invalid("the scene method refines its results; use auto for unrefined ones");
        }
        if self.accept.is_nan() || self.accept < 0.0 {
            return invalid(&format!(
                "accept must be a score of at least 0 (inf: always both), not {}",
                self.accept
            ));
        }
        Ok(())
    }

    /// The network as the cascade's second stage: one chain (the cascade's overlap score
    /// already judges the result, so cycle consistency between two chains is not needed) and,
    /// for the built-in model with no `match_points`, `TUNED.cascade_match_points` per cloud.
    fn build_cascade_rgm(&self) -> Result<RgmRegistrar, MethodError> {
        let mut registrar = self.build_rgm()?;
        registrar.config.cycle_consistency = false;
        if self.weights.is_none() && self.match_points.is_none() {
            registrar.config.match_points = Some(TUNED.cascade_match_points);
        }
        Ok(registrar)
    }

    /// The network with its weights and test-time settings.
    fn build_rgm(&self) -> Result<RgmRegistrar, MethodError> {
        let mut registrar = match &self.weights {
            Some(weights) => {
                let config = Config::preset(self.preset.as_deref().unwrap_or("paper"))?;
                let mut registrar = crate::weights::load_registrar(config, weights)?;
                registrar.network.featurer.test_statistics =
                    self.test_statistics.unwrap_or_default();
                registrar.config.match_points = Some(TUNED.weights_match_points);
                registrar
            }
            None => crate::weights::builtin_registrar()?,
        };
        if let Some(points) = self.match_points {
            registrar.config.match_points = (points > 0).then_some(points);
        }
        if let Some(passes) = self.passes {
            registrar.config.passes = passes;
        }
        registrar.config.precision = self.precision;
        Ok(registrar)
    }
}

/// What [`auto`] runs on a pair denser than the training clouds (with `refine`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DenseStage {
    /// The object cascade, then the scene stage where the cascade's result is not taken
    /// (`TUNED.scene_accept`, [`crate::policy`]): `rgm register`'s default.
    ObjectThenScene,
    /// The scene stage alone: on the Stanford bunny's and dragon's thinned scans, every pair
    /// the cascade trusted in a merge was trusted, the merged scans as accurate, and a pair
    /// costs about half as much where the cascade would doubt it (`docs/multiway.md`).
    SceneOnly,
}

/// `auto` (`auto+refine` with `refine`): FGR's candidate in the network's frame, and RGM's when
/// `accept` does not take FGR's (the network costs most of the time; both side by side when
/// `accept` takes nothing), each refined with `refine`; the better by the overlap score on two
/// thinnings of a dense pair, and the winner refined at a dense pair's own resolution.
pub fn auto<R>(
    rgm: R,
    refine: Option<RefineConfig>,
    accept: Acceptance,
    dense: DenseStage,
) -> Method
where
    R: Registrar<MethodError> + Clone + Send + Sync + 'static,
{
    let rgm = Normalised::new(rgm, TUNED.frame);
    let fgr = FgrConfig::default();
    let scoring = TUNED.scoring_refined(refine.as_ref());
    let candidates: [Box<dyn DynRegistrar<MethodError>>; 2] = match &refine {
        None => [Box::new(fgr), Box::new(rgm)],
        Some(refine) => [
            Box::new(Refined::new(fgr, refine.clone())),
            Box::new(Refined::new(rgm, refine.clone())),
        ],
    };
    fn thinned<C>(inner: C) -> Thinned<C> {
        Thinned {
            inner,
            thinnings: vec![Thinning::Voxels, Thinning::Cells],
            density: TRAINING_DENSITY,
            agreement: TUNED.agreement,
        }
    }
    let [first, second] = candidates;
    let composite: Box<dyn DynRegistrar<MethodError>> = if accept.score.is_finite() {
        Box::new(thinned(Cascade {
            base: AUTO,
            first,
            rest: vec![second],
            accept,
            scoring,
        }))
    } else {
        Box::new(thinned(BestOf {
            base: AUTO,
            candidates: vec![first, second],
            scoring,
        }))
    };
    let at_spacing = AtSpacing {
        coarser_than: scoring.result_distance,
        scoring_distance: scoring.result_distance,
        config: ResolutionConfig::default(),
    };
    let composite: Box<dyn DynRegistrar<MethodError>> = match refine {
        None => Box::new(Checked {
            inner: composite,
            check: TUNED.unrefined_checks(),
        }),
        Some(_) => Box::new(Checked {
            inner: AtResolution {
                // A pair denser than the training clouds may be a scene: the object cascade
                // first, the scene stage on the pair's own features where its result is not
                // taken.
                inner: UpTo {
                    points: TRAINING_DENSITY.points,
                    small: composite.clone(),
                    other: match dense {
                        DenseStage::ObjectThenScene => Box::new(Cascade {
                            base: AUTO,
                            first: Box::new(RefinedWhereNear {
                                inner: composite,
                                refiner: at_spacing.clone(),
                                near: TUNED.scene_refine_near,
                            }),
                            rest: vec![Box::new(scene_stage())],
                            accept: TUNED.scene_accept,
                            scoring: Scoring {
                                overlap_distance: TUNED.scene_overlap_distance,
                                ..scoring
                            },
                        })
                            as Box<dyn DynRegistrar<MethodError>>,
                        DenseStage::SceneOnly => Box::new(scene_stage()),
                    },
                },
                refiner: at_spacing,
                density: TRAINING_DENSITY,
            },
            check: TUNED.refined_checks(),
        }),
    };
    // A few markers have no neighbourhoods for features or the network: searched whole.
    let triplets = TripletConfig::default();
    Method::new(Normalised::new(
        Named {
            base: match dense {
                DenseStage::ObjectThenScene => AUTO,
                DenseStage::SceneOnly => SCENE,
            },
            inner: UpTo {
                points: triplets.max_points,
                small: triplets,
                other: composite,
            },
        },
        TUNED.frame,
    ))
}

#[cfg(test)]
mod tests;
