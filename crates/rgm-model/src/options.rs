//! A registration method chosen by name and options, as plain data. The `rgm` command and the
//! Python package both take these from their users and build the [`Method`] here, so that the
//! two run the same method with the same defaults: [`MethodOptions::default`] is what
//! `rgm register` runs when given no option. Every composition of registrars that users can
//! name is written here, in [`MethodOptions::build`]:
//!
//! | name | composition |
//! |---|---|
//! | `icp` | `Checked<IcpConfig, InFrame<REFINED_CHECKS>>` (its own refinement, checked in the unit-sphere frame) |
//! | `fgr`, `fgr+refine` | `Normalised<Checked<FgrConfig, unrefined_checks()>>`, `Normalised<Checked<Refined<FgrConfig>, REFINED_CHECKS>>` |
//! | `rgm`, `rgm+refine` | [`Normalised`]`<Checked<RgmRegistrar, unrefined_checks()>>`, `Normalised<Checked<Refined<RgmRegistrar>, REFINED_CHECKS>>` |
//! | `auto` | `Normalised<Checked<Thinned<Cascade { first: FgrConfig, rest: [Normalised<RgmRegistrar>] }>, unrefined_checks()>>` |
//! | `auto+refine` | `Normalised<Checked<AtResolution<Thinned<Cascade { first: Refined<FgrConfig>, rest: [Refined<Normalised<RgmRegistrar>>] }>, AtSpacing>, REFINED_CHECKS>>` |
//!
//! (`BestOf[first, rest]` in place of the `Cascade` when `accept` takes nothing; inside the
//! `Normalised`, `UpTo { points: 32, small: TripletConfig, .. }` sends a pair of a few points to
//! [`rgm_registration::methods::triplets`]; with `+refine`, a pair denser than the training clouds (a scan, a room)
//! goes through `Cascade { first: the Thinned composite, rest: [Sc2Config] }` judged by
//! [`SCENE_ACCEPT`]: second-order compatibility on the pair's own FPFH matches,
//! [`rgm_registration::methods::sc2`], where the object cascade's result does not coincide with the target at
//! the pair's spacing.)
//!
//! [`Checked`] doubts a result whose overlap is not one where the clouds coincide, or that a
//! rival pose fits nearly as well ([`REFINED_CHECKS`]): refined results, ICP's (refined by its
//! nature) and, since issue 59, unrefined ones too (`--no-refine`, the paper's protocol), which
//! must also lie near where the refinement takes them ([`unrefined_checks`]): an unrefined result
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

use rgm_geom::frame::FrameRule;
use rgm_registration::check::{
    Acceptance, Coincides, CoincidesAtSpacing, InFrame, Precise, Scoring, SelfFit, Unambiguous,
};
use rgm_registration::compose::{
    AtResolution, BestOf, Cascade, Checked, Named, Normalised, OnFirstUse, Refined, Thinned, UpTo,
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
                SCORING.overlap_distance
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

/// The unit-sphere frame the default's methods run in ([`Normalised`]): a point farther from
/// its cloud's median than 12 times the median distance from it is a far outlier (no ModelNet40
/// shape has one: `docs/geom.md`, "Far outliers"); a pair within 2 of the origin whose larger
/// cloud reaches 0.3–1.7 from its centroid is in the frame already and left as it is: a ModelNet40
/// shape reaches 1, a 70 % crop of it 0.80–1.11 (10th and 90th percentiles over 400 training
/// shapes), the larger of a partial pair's two crops 0.356–1.424 over all 2,468 test pairs and
/// 0.347–1.32 over the 1,980 validation pairs (two crops of an elongated shape can both be
/// short), and the benchmark's pairs (one cloud moved by at most 0.5 per axis, jitter at most
/// 0.05) lie within 1.95 of the origin. Scaled up into the sphere, a short pair's jitter grew
/// with it, and the coincidence check doubted 32 of its 37 right results
/// (`docs/confidence.md`, "Short pairs").
pub const FRAME: FrameRule = FrameRule {
    far_outlier: 12.0,
    within: 2.0,
    extent: (0.3, 1.7),
};

/// How the default's composites judge their candidates (unit-sphere units): a point within
/// 0.02 of the other cloud overlaps it, and a best result overlapping less than 0.1 (fewer than
/// one point in twenty of each cloud on the other) is reported as not registered; chosen on
/// validation pairs (`docs/training/README.md`, the default study). The chosen result is scored
/// at the overlap distance too, or at its refinement's finest ([`scoring`]).
pub const SCORING: Scoring = Scoring {
    overlap_distance: 0.02,
    min_overlap: 0.1,
    result_distance: 0.02,
    coincides: None,
};

/// How close the candidates' transforms on a dense pair's first thinning must be for the next
/// thinning to be skipped: (degrees, distance in unit-sphere units).
pub const AGREEMENT: (f64, f64) = (1.0, 0.02);

/// [`SCORING`], when the candidates are refined: the chosen result scored at `refine`'s finest
/// distance, and a candidate that does not coincide with the other cloud ([`COINCIDES`])
/// ranked below those that do.
pub fn scoring(refine: Option<&RefineConfig>) -> Scoring {
    Scoring {
        result_distance: refine.map_or(SCORING.result_distance, RefineConfig::finest_distance),
        coincides: refine.map(|_| COINCIDES),
        ..SCORING
    }
}

/// When `rgm register`'s default takes its cheap candidate (FGR) without running the network
/// ([`Cascade::accept`](rgm_registration::compose::Cascade::accept)): the cheapest on validation pairs that kept the recall and the share off
/// by more than 45° of running both within 0.1 points
/// (`docs/training/default-study/cascade-1980-validation.md`).
pub const ACCEPT: Acceptance = Acceptance {
    score: 0.55,
    turned_share: 0.3,
    whole: (WHOLE_DISTANCE, WHOLE_OVERLAP),
    coincides: None,
};

/// The distance (unit-sphere units) of [`ACCEPT`]'s whole overlap: the bound of the benchmark's
/// jitter (σ = 0.01 per coordinate, clipped at 0.05), within which a noisy cloud's points still
/// lie on the other cloud.
pub const WHOLE_DISTANCE: f64 = 0.05;

/// The least overlap at [`WHOLE_DISTANCE`] (0 to 2) that [`ACCEPT`] takes as whole: the least
/// that changes no partial validation pair's course, far above any wrong result's
/// (`docs/training/default-study/cascade-whole-overlap.md`).
pub const WHOLE_OVERLAP: f64 = 1.98;

/// How a refined result of the default or of `rgm+refine` must coincide with the other cloud where
/// it overlaps it, in the unit-sphere frame: the least that kept every right result of 198
/// validation pairs registered and doubted all but a few wrong ones on pairs at 10 % overlap
/// (`docs/confidence.md`).
pub const COINCIDES: Coincides = Coincides {
    near: 0.02,
    far: 0.08,
    least: 0.35,
};

/// The same on a dense pair, in point spacings: midway between the right results of the
/// Stanford and redkitchen pairs and the wrong ones of part-of-the-whole crops, non-overlapping
/// scans and slid rooms (`docs/confidence.md`).
/// It applies to pairs denser than [`TRAINING_DENSITY`] whose points spread over surfaces: a
/// ratio of the median distance to the 16th nearest neighbour to the nearest's below 5 (2.0–3.5
/// measured on the Stanford scans, the redkitchen fragments and the merged bunny; 7.5 on both
/// sweeps of the LiDAR pair, whose points lie along scan lines; `docs/confidence.md`).
pub const COINCIDES_AT_SPACING: CoincidesAtSpacing = CoincidesAtSpacing {
    coincides: Coincides {
        near: 1.5,
        far: 16.0,
        least: 0.5,
    },
    density: TRAINING_DENSITY,
    scan_lines: 5.0,
};

/// How a refined result must coincide: [`COINCIDES`], then [`COINCIDES_AT_SPACING`].
pub const REFINED_COINCIDES: (Coincides, CoincidesAtSpacing) = (COINCIDES, COINCIDES_AT_SPACING);

/// No rival pose of a refined result may fit nearly as well and coincide: a rival overlapping
/// at least 0.75 of the result's overlap, midway between the right validation results' rivals
/// (at most 0.60, one symmetric shape's turned pose aside) and the wrong results' that
/// [`REFINED_COINCIDES`] left registered (at least 0.89); candidates within 5° and 0.05 are
/// one pose (`docs/confidence.md`). Overlaps are counted at [`SCORING`]'s distance.
pub const UNAMBIGUOUS: Unambiguous<(Coincides, CoincidesAtSpacing)> = Unambiguous {
    share: 0.75,
    distance: SCORING.overlap_distance,
    apart: (5.0, 0.05),
    rivals_pass: REFINED_COINCIDES,
    self_fit: SELF_FIT,
};

/// A cloud fits itself turned when 90 % of its points, turned, lie within their distance to
/// their 4th nearest neighbour of it (about two spacings), looked for beyond the half turns where
/// two spreads are within 0.8 of each other, on clouds whose neighbourhoods' median flatness is
/// below 0.1 (surfaces: 0.00–0.04 measured on a cube, a box and ModelNet40's airplane; lattices
/// 0.13–0.15). A cube of 2,048 points fits itself at 0.94, a 1,024-point one at 0.89 (issue 59,
/// E4; docs/confidence.md).
pub const SELF_FIT: SelfFit = SelfFit {
    within: 1.0,
    share: 0.9,
    near_equal: 0.8,
    flat: 0.1,
};

/// The type of [`REFINED_CHECKS`].
pub type RefinedChecks = (
    (Coincides, CoincidesAtSpacing),
    Unambiguous<(Coincides, CoincidesAtSpacing)>,
);

/// The checks of a refined result: [`REFINED_COINCIDES`], then [`UNAMBIGUOUS`].
pub const REFINED_CHECKS: RefinedChecks = (REFINED_COINCIDES, UNAMBIGUOUS);

/// The type of [`unrefined_checks`].
pub type UnrefinedChecks = (RefinedChecks, Precise);

/// The checks of an unrefined result (`--no-refine`): [`REFINED_CHECKS`], then [`Precise`]: the
/// refinement (`RefineConfig::default`, on at most 2,048 points of each cloud) must move it by
/// less than 5° and 0.05, the 5° at which issue 59 counts a result wrong (E3: 5 of 40 partial
/// test pairs trusted 5.6–174° off before; docs/confidence.md).
pub fn unrefined_checks() -> UnrefinedChecks {
    (
        REFINED_CHECKS,
        Precise {
            refine: RefineConfig::default(),
            within: (5.0, 0.05),
            points: 2048,
        },
    )
}

/// When the default takes the object cascade's result on a dense pair without running the
/// scene stage after it: an overlap score of at least [`ACCEPT`]'s, whatever its
/// turned share (a room overlaps itself turned about the vertical as a box does, and the
/// measure on a dense pair costs more than it tells there), and clouds that coincide at their
/// point spacing ([`COINCIDES_AT_SPACING`]; a room slid along its floor overlaps well).
pub const SCENE_ACCEPT: Acceptance = Acceptance {
    score: ACCEPT.score,
    turned_share: f64::INFINITY,
    whole: (WHOLE_DISTANCE, f64::INFINITY),
    coincides: Some(COINCIDES_AT_SPACING),
};

/// The overlap distance (unit-sphere units) at which the scene stage's cascade judges its
/// results, a quarter of [`SCORING`]'s: a scene fills the unit sphere with far more detail than
/// an object. On the LiDAR pair (a 50 m sweep) 0.02 is a metre, within which a 0.2 m slide along
/// the road overlapped as well as the right pose (1.9806 against 1.9795) and was chosen on 3 of
/// its 7 turns; at 0.005 the right pose won on all 7, and the redkitchen and Stanford pairs kept
/// their transforms (docs/baselines.md, "Scenes: the scene stage's judge").
pub const SCENE_OVERLAP_DISTANCE: f64 = 0.005;

/// The scene stage's global estimator ([`Sc2Config`]): it registered all 12 redkitchen dev
/// pairs where RANSAC (Open3D's tutorial settings) registered 10 or 11, at any of the seeds,
/// mates, compatibilities and lengths tried (docs/baselines.md, "Scenes: second-order
/// compatibility").
pub fn scene_stage() -> Sc2Config {
    Sc2Config::default()
}

/// Points matched per cloud with given weights unless `match_points` says otherwise: the paper
/// trains on 1,024-point clouds, and the network's memory grows with the square of the points.
pub const WEIGHTS_MATCH_POINTS: usize = 1024;

/// Points the built-in model matches per cloud as the cascade's second stage unless
/// `match_points` says otherwise. Fewer than its training size, because the network is most of
/// the cascade's time on the pairs where it runs; chosen on validation pairs as the most points
/// that keep the default's mean time under Open3D's
/// (docs/training/default-study/cascade-network-stage.md).
pub const CASCADE_MATCH_POINTS: usize = 256;

/// A method and its options; `None` leaves an option at the method's own default.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodOptions {
    /// The method (FGR and RGM as a cascade by default).
    pub method: MethodName,
    /// RGM weights (for `rgm` and `auto`): a safetensors file with the authors' parameter
    /// names; `None`: the model built into rgm ([`crate::weights::builtin_method`]).
    pub weights: Option<PathBuf>,
    /// The network sizes `weights` were trained with ([`Config::preset`]; `paper` when `None`).
    pub preset: Option<String>,
    /// Batch-norm statistics for `weights` (`running` when `None`, as for the authors'
    /// weights; the built-in model has its own).
    pub test_statistics: Option<TestStatistics>,
    /// RGM matches on at most this many random points of each cloud; 0: every point. When
    /// `None`: the built-in model's training size ([`CASCADE_MATCH_POINTS`] in `auto`), or
    /// [`WEIGHTS_MATCH_POINTS`] with `weights`.
    pub match_points: Option<usize>,
    /// RGM's passes (2 when `None`, as in the paper).
    pub passes: Option<usize>,
    /// RGM's matrix products: f32 (the default), or bf16 where the processor has AMX or
    /// AVX-512 BF16 ([`Precision`]).
    pub precision: Precision,
    /// Refine the transform of RGM or FGR (both, for `auto`) with [`rgm_registration::methods::refine`]
    /// ([`Method::refined`]); on by default, as in `rgm register` (the paper's protocol, and
    /// `rgm eval`, turn it off). ICP is its own refinement and ignores it.
    pub refine: bool,
    /// `auto` takes FGR's result without running the network when it scores at least this
    /// ([`rgm_registration::check::overlap_score`], 0 to 2) and overlaps wholly or does not fit as
    /// well turned ([`ACCEPT`]); `f64::INFINITY` runs both on every pair.
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
            accept: ACCEPT.score,
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
                    check: REFINED_CHECKS,
                    rule: FRAME,
                },
            }),
            // FGR's lengths are set for unit-sphere shapes: the pair is moved into that frame
            // first, as the network's is, and its refined result checked there.
            (MethodName::Fgr, None) => Method::new(Normalised::new(
                Checked {
                    inner: FgrConfig::default(),
                    check: unrefined_checks(),
                },
                FRAME,
            )),
            (MethodName::Fgr, Some(refine)) => Method::new(Normalised::new(
                Checked {
                    inner: Refined::new(FgrConfig::default(), refine),
                    check: REFINED_CHECKS,
                },
                FRAME,
            )),
            (MethodName::Rgm, None) => Method::new(Normalised::new(
                Checked {
                    inner: self.build_rgm()?,
                    check: unrefined_checks(),
                },
                FRAME,
            )),
            (MethodName::Rgm, Some(refine)) => Method::new(Normalised::new(
                Checked {
                    inner: Refined::new(self.build_rgm()?, refine),
                    check: REFINED_CHECKS,
                },
                FRAME,
            )),
            (MethodName::Auto | MethodName::Scene, refine) => {
                let accept = Acceptance {
                    score: self.accept,
                    ..ACCEPT
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
        if !cascade && self.accept != ACCEPT.score {
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
    /// for the built-in model with no `match_points`, [`CASCADE_MATCH_POINTS`] per cloud.
    fn build_cascade_rgm(&self) -> Result<RgmRegistrar, MethodError> {
        let mut registrar = self.build_rgm()?;
        registrar.config.cycle_consistency = false;
        if self.weights.is_none() && self.match_points.is_none() {
            registrar.config.match_points = Some(CASCADE_MATCH_POINTS);
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
                registrar.config.match_points = Some(WEIGHTS_MATCH_POINTS);
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
    /// ([`SCENE_ACCEPT`]): `rgm register`'s default.
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
    let rgm = Normalised::new(rgm, FRAME);
    let fgr = FgrConfig::default();
    let scoring = scoring(refine.as_ref());
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
            agreement: AGREEMENT,
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
    let composite: Box<dyn DynRegistrar<MethodError>> = match refine {
        None => Box::new(Checked {
            inner: composite,
            check: unrefined_checks(),
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
                            first: composite,
                            rest: vec![Box::new(scene_stage())],
                            accept: SCENE_ACCEPT,
                            scoring: Scoring {
                                overlap_distance: SCENE_OVERLAP_DISTANCE,
                                ..scoring
                            },
                        })
                            as Box<dyn DynRegistrar<MethodError>>,
                        DenseStage::SceneOnly => Box::new(scene_stage()),
                    },
                },
                refiner: AtSpacing {
                    coarser_than: scoring.result_distance,
                    scoring_distance: scoring.result_distance,
                    config: ResolutionConfig::default(),
                },
                density: TRAINING_DENSITY,
            },
            check: REFINED_CHECKS,
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
        FRAME,
    ))
}

#[cfg(test)]
mod tests;
