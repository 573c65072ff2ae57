//! RGM at test time, the reference code's procedure (spec §4): two *chains* of passes — the
//! source moved toward the target, and the target moved toward the source — each pass the
//! network's soft correspondences, inlier selection, linear assignment and a weighted Kabsch
//! that moves the chain's cloud; then cycle consistency between the two chains' last hard
//! correspondences, and ONE weighted Kabsch of the original clouds with what survives.
//!
//! Around it, what real inputs need: the clouds are brought into the frame the network was
//! trained in ([`Normalisation`]), large clouds are subsampled for matching (the transform
//! found applies to the full clouds), and a refinement may follow on the full clouds.
//!
//! The local features of a cloud depend on that cloud alone at test time, so each is computed
//! once per distinct cloud: X and Y once each, and each moved copy once (2 + 2(P − 1) feature
//! passes for P passes instead of 4P). The reverse chain's first pass (Y, X) reuses the forward
//! chain's first pass (X, Y) for block 0's edges and graph convolutions
//! ([`Rgm::forward_reverse`]).

use std::time::Instant;

use ndarray::Array2;
use rand::{rngs::StdRng, SeedableRng};
use rgm_geom::kabsch::kabsch;
use rgm_geom::refine::{self, RefineConfig};
use rgm_geom::{Point3, PointCloud, RegistrationResult, RigidTransform, Vector3};
use rgm_match::{hard_match, Correspondences, MatchConfig};
use rgm_nn::{Parameters, Precision};

use crate::error::MethodError;
use crate::network::{FeaturerCache, Rgm, RgmCache};

/// Test-time settings; the defaults are the paper's.
#[derive(Clone, Debug, PartialEq)]
pub struct PipelineConfig {
    /// Passes of network → matching → Kabsch in each chain, each on the chain's cloud moved by
    /// the passes before (2 in the paper's tables).
    pub passes: usize,
    /// Run the reverse chain too and keep only the correspondences both chains end with (on in
    /// the reference); off, the forward chain's last correspondences are used alone.
    pub cycle_consistency: bool,
    /// Rows and columns of C̃ whose sums exceed this are inliers (0.5).
    pub inlier_threshold: f64,
    /// Match on at most this many points of each cloud, drawn at random with a fixed seed (so a
    /// pair always gives the same result) from the cloud thinned to [`DENSITY_POINTS`] when it
    /// is denser ([`matched_indices`]); `None` (the paper) matches on every point. A model
    /// trained on subsampled clouds matches best on as many points as it was trained on.
    pub match_points: Option<usize>,
    /// Refine the result with [`rgm_geom::refine`] (trimmed point-to-plane ICP) on the full
    /// clouds, in the network's frame (so distances are in unit-sphere units). `None` in the
    /// paper.
    pub refine: Option<RefineConfig>,
    /// The network's matrix products: f32, or bf16 where the processor has AMX or AVX-512 BF16.
    pub precision: Precision,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            passes: 2,
            cycle_consistency: true,
            inlier_threshold: 0.5,
            match_points: None,
            refine: None,
            precision: Precision::F32,
        }
    }
}

/// Seeds of the matched subsets of source and target (different, so that clouds with related
/// point orders do not get related subsets).
const SOURCE_SEED: u64 = 0;
const TARGET_SEED: u64 = 1;

/// How a pair is moved into the frame the network was trained in: `p' = (p − centre) / scale`,
/// each cloud about its own centre, both by one scale.
///
/// The benchmark's pairs (unit-sphere shapes, one moved by at most 0.5 per axis, jitter ≤ 0.05:
/// every point within 1.95 of the origin) are already in that frame and are left as they are:
/// the identity whenever both clouds lie within [`Normalisation::FRAME_RADIUS`] of the origin
/// and the larger cloud's extent (its largest distance from its centroid) is within
/// [`Normalisation::FRAME_EXTENT`]. Any other pair is centred (each cloud on its centroid) and
/// scaled by one common factor so that the farthest point of either cloud lies on the unit
/// sphere ([`Normalisation::centred`]): the same pair at half or twice the size reaches the
/// network as the same clouds, centred.
///
/// All of it is measured on each cloud's [`near`] points: a far outlier (a stray return of a
/// scanner) neither decides the frame nor shrinks the pair to a dot in it, and the methods
/// leave it out. Lengths are taken at any scale ([`rgm_geom::length`]): a pair at 1e200 or
/// 1e-200 reaches the network as it does at 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalisation {
    pub source_centre: Vector3<f64>,
    pub target_centre: Vector3<f64>,
    pub scale: f64,
}

/// A point farther from its cloud's coordinate-wise median than this many times the median
/// distance from it is a far outlier ([`PointCloud::near_indices`]); no ModelNet40 shape has one
/// (`docs/geom.md`, "Far outliers").
pub const FAR_OUTLIER: f64 = 12.0;

/// The indices of `cloud`'s points that are not far outliers ([`FAR_OUTLIER`]), in order.
pub fn near(cloud: &PointCloud) -> Vec<usize> {
    cloud.near_indices(FAR_OUTLIER)
}

/// The largest distance of `cloud`'s points from `centre`; 0 for an empty cloud.
fn radius(cloud: &PointCloud, centre: &Point3<f64>) -> f64 {
    cloud
        .points
        .iter()
        .map(|p| rgm_geom::length(&(p - centre)))
        .fold(0.0, f64::max)
}

impl Normalisation {
    /// Pairs within this radius of the origin are in the training frame…
    pub const FRAME_RADIUS: f64 = 2.0;
    /// …when the larger extent is in this range: a ModelNet40 shape reaches 1 from its centre,
    /// a 70 % crop of it 0.80–1.11 (10th and 90th percentiles over 400 training shapes; the
    /// larger of a test pair's two crops at most 1.38).
    pub const FRAME_EXTENT: std::ops::RangeInclusive<f64> = 0.7..=1.7;

    /// No change.
    pub fn identity() -> Self {
        Self {
            source_centre: Vector3::zeros(),
            target_centre: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// The normalisation of the pair (`source`, `target`), as described on the type.
    pub fn of_pair(source: &PointCloud, target: &PointCloud) -> Self {
        let (source, target) = (source.select(&near(source)), target.select(&near(target)));
        let extent = radius(&source, &source.centroid()).max(radius(&target, &target.centroid()));
        let reach = radius(&source, &Point3::origin()).max(radius(&target, &Point3::origin()));
        if reach <= Self::FRAME_RADIUS && Self::FRAME_EXTENT.contains(&extent) || extent == 0.0 {
            return Self::identity();
        }
        Self::centred(&source, &target)
    }

    /// Each cloud centred on its centroid, both scaled by one factor so that the farthest point
    /// of either lies on the unit sphere (no scaling for clouds of coincident points).
    pub fn centred(source: &PointCloud, target: &PointCloud) -> Self {
        let (cx, cy) = (source.centroid(), target.centroid());
        let extent = radius(source, &cx).max(radius(target, &cy));
        Self {
            source_centre: cx.coords,
            target_centre: cy.coords,
            scale: if extent > 0.0 { extent } else { 1.0 },
        }
    }

    /// Whether the pair is used as it is.
    pub fn is_identity(&self) -> bool {
        *self == Self::identity()
    }

    fn apply(cloud: &PointCloud, centre: &Vector3<f64>, scale: f64) -> PointCloud {
        PointCloud::new(cloud.points.iter().map(|p| (p - centre) / scale).collect())
    }

    /// The source in the network's frame.
    pub fn source(&self, cloud: &PointCloud) -> PointCloud {
        Self::apply(cloud, &self.source_centre, self.scale)
    }

    /// The target in the network's frame.
    pub fn target(&self, cloud: &PointCloud) -> PointCloud {
        Self::apply(cloud, &self.target_centre, self.scale)
    }

    /// The transform in the caller's frame of `t` (y' = R x' + t' in the network's frame):
    /// y = s y' + c_Y = R x + (s t' + c_Y − R c_X).
    pub fn undo(&self, t: &RigidTransform) -> RigidTransform {
        let translation =
            self.scale * t.translation + self.target_centre - t.rotation * self.source_centre;
        RigidTransform::new(t.rotation, translation)
    }

    /// The transform in the network's frame of `t` (in the caller's frame): the inverse of
    /// [`Normalisation::undo`], t' = (t − c_Y + R c_X) / s.
    pub fn redo(&self, t: &RigidTransform) -> RigidTransform {
        let translation =
            (t.translation - self.target_centre + t.rotation * self.source_centre) / self.scale;
        RigidTransform::new(t.rotation, translation)
    }
}

/// Points of a training cloud (1,024 per ModelNet40 shape; 717 after the partial crop).
/// Before the random cut to the matched points, a cloud with more points than this (and than
/// the matched points) is thinned to this many by farthest-point sampling, so that the cut sees
/// the training clouds' spacing: drawn from a dense scan, or from duplicated points, a random
/// subset holds near-coincident points that the network never saw in training.
pub const DENSITY_POINTS: usize = 1024;

/// The indices of `cloud` that RGM matches on: at most `count` (all when `None`), drawn at
/// random from `seed` after the thinning of [`DENSITY_POINTS`], sorted.
pub fn matched_indices(cloud: &PointCloud, count: Option<usize>, seed: u64) -> Vec<usize> {
    let Some(count) = count else {
        return (0..cloud.len()).collect();
    };
    let thinned = cloud.farthest_point_indices(count.max(DENSITY_POINTS)); // (T,)
    let mut picked: Vec<usize> = subsample(thinned.len(), Some(count), seed)
        .into_iter()
        .map(|k| thinned[k])
        .collect();
    picked.sort_unstable();
    picked
}

/// `count` of `len` indices, drawn at random from `seed` and sorted; all of them when
/// `count` is `None` or at least `len`.
fn subsample(len: usize, count: Option<usize>, seed: u64) -> Vec<usize> {
    match count {
        Some(count) if count < len => {
            let mut rng = StdRng::seed_from_u64(seed);
            let mut picked = rand::seq::index::sample(&mut rng, len, count).into_vec();
            picked.sort_unstable();
            picked
        }
        _ => (0..len).collect(),
    }
}

/// Wall time of each stage of one registration, in seconds (summed over passes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Normalisation, subsampling and conversion of the clouds.
    pub prepare: f64,
    /// The local feature extractor (each cloud once, and each chain's moved cloud).
    pub features: f64,
    /// The matching blocks (transformer edges, graph convolutions, affinity, Sinkhorn, cross
    /// convolution), forward and reverse.
    pub blocks: f64,
    /// Inlier selection, linear assignment and cycle consistency.
    pub matching: f64,
    /// Weighted Kabsch.
    pub kabsch: f64,
    /// ICP refinement.
    pub refine: f64,
}

impl StageTimes {
    /// The whole registration.
    pub fn total(&self) -> f64 {
        self.prepare + self.features + self.blocks + self.matching + self.kabsch + self.refine
    }
}

/// Seconds since `start`, added to `stage`.
fn add_since(stage: &mut f64, start: Instant) {
    *stage += start.elapsed().as_secs_f64();
}

/// The RGM network (f32) with its test-time settings and reusable buffers.
#[derive(Clone, Debug)]
pub struct RgmRegistrar {
    /// The network, in evaluation mode at test time.
    pub network: Rgm<f32>,
    /// Passes, cycle consistency, inlier threshold, subsampling, refinement.
    pub config: PipelineConfig,
    source_features: FeaturerCache<f32>, // the matched source X's features (N, C), once per pair
    target_features: FeaturerCache<f32>, // the matched target Y's features (M, C), once per pair
    moved_features: FeaturerCache<f32>,  // a chain's moved cloud's features (N or M, C)
    forward: RgmCache<f32>,              // the forward chain's pass (X', Y)
    reverse: RgmCache<f32>,              // the reverse chain's pass (Y', X)
    pairs: Vec<(usize, usize)>,          // the final correspondences, caller's indices
    times: StageTimes,                   // of the last registration
}

/// A cloud as the network's (N, 3) f32 input.
pub(crate) fn as_rows(cloud: &PointCloud) -> Array2<f32> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c] as f32) // (N, 3)
}

/// The two chains of spec §4.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Chain {
    /// A copy of the source X moved toward the target Y.
    Forward,
    /// A copy of the target Y moved toward the source X.
    Reverse,
}

impl Chain {
    fn describe(self) -> &'static str {
        match self {
            Chain::Forward => "the forward chain (source toward target)",
            Chain::Reverse => "the reverse chain (target toward source)",
        }
    }
}

impl RgmRegistrar {
    /// A registrar around `network`.
    pub fn new(network: Rgm<f32>, config: PipelineConfig) -> Self {
        Self {
            network,
            config,
            source_features: FeaturerCache::default(),
            target_features: FeaturerCache::default(),
            moved_features: FeaturerCache::default(),
            forward: RgmCache::default(),
            reverse: RgmCache::default(),
            pairs: Vec::new(),
            times: StageTimes::default(),
        }
    }

    /// The final hard correspondences (source index, target index) of the last registration —
    /// those both chains ended with (or the forward chain's, without cycle consistency) — as
    /// indices into the clouds given to [`RgmRegistrar::register`]. Empty before any
    /// registration and after a failed one.
    pub fn correspondences(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// Where the time of the last registration went.
    pub fn stage_times(&self) -> StageTimes {
        self.times
    }

    /// Pass `pass` (from 0) of `chain` on the chain's cloud `moved` (its own cloud after the
    /// passes before; the partner stays where it is): C̃ of (moved, partner), then its hard
    /// correspondences (rows of `moved`, columns of the partner). Pass 0 of the reverse chain
    /// is taken from pass 0 of the forward chain, which must be the last forward pass run.
    fn chain_pass(
        &mut self,
        chain: Chain,
        pass: usize,
        moved: &PointCloud,
    ) -> Result<Correspondences, MethodError> {
        if pass > 0 {
            let start = Instant::now();
            self.network
                .features(as_rows(moved).view(), &mut self.moved_features)?;
            add_since(&mut self.times.features, start);
        }
        let start = Instant::now();
        let (own, partner) = match chain {
            Chain::Forward => (&self.source_features, &self.target_features),
            Chain::Reverse => (&self.target_features, &self.source_features),
        };
        let own = if pass > 0 { &self.moved_features } else { own };
        let (fo, fp) = (own.features.view(), partner.features.view()); // (N', C), (M', C)
        let cache = match (chain, pass) {
            (Chain::Forward, _) => {
                self.network
                    .forward_from_features(fo, fp, &mut self.forward)?;
                &self.forward
            }
            (Chain::Reverse, 0) => {
                self.network
                    .forward_reverse(&self.forward, &mut self.reverse)?;
                &self.reverse
            }
            (Chain::Reverse, _) => {
                self.network
                    .forward_from_features(fo, fp, &mut self.reverse)?;
                &self.reverse
            }
        };
        add_since(&mut self.times.blocks, start);
        let start = Instant::now();
        let matching = MatchConfig {
            inlier_threshold: self.config.inlier_threshold,
        };
        let found = hard_match(cache.c_soft(), &matching)?;
        add_since(&mut self.times.matching, start);
        if found.pairs().is_empty() {
            return Err(MethodError::NoCorrespondences {
                stage: format!("pass {} of {}", pass + 1, chain.describe()),
            });
        }
        Ok(found)
    }

    /// The weighted Kabsch of spec §4 that maps `a[i]` onto `b[j]` for each pair (i, j) (the
    /// weights, H's row sums, are one per pair).
    fn kabsch_of(
        &mut self,
        a: &PointCloud,
        b: &PointCloud,
        pairs: &[(usize, usize)],
    ) -> Result<RigidTransform, MethodError> {
        let start = Instant::now();
        let (from, to): (Vec<Point3<f64>>, Vec<Point3<f64>>) = pairs
            .iter()
            .map(|&(i, j)| (a.points[i], b.points[j]))
            .unzip();
        let solved = kabsch(&from, &to, &vec![1.0; from.len()])?;
        add_since(&mut self.times.kabsch, start);
        Ok(solved)
    }

    /// The transform that maps `source` onto `target` (spec §4): the weighted Kabsch of the
    /// matched clouds with the correspondences both chains end with, then the refinement, if
    /// configured, in the caller's frame. `inlier_count` is the number of those
    /// correspondences ([`RgmRegistrar::correspondences`]); `iterations` counts the passes of a
    /// chain and the refinement's iterations. Unrefined, `inlier_rmse` is those
    /// correspondences' distance after the transform and `fitness` their share of the matched
    /// source points; refined, both are the refinement's score (the share of all source points
    /// with a target point closer than its finest distance, and their RMS distance, in the
    /// caller's units): many of the network's correspondences are wrong even when its transform
    /// is right, so their distances say little.
    pub fn register(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<RegistrationResult, MethodError> {
        self.pairs.clear();
        self.times = StageTimes::default();
        if self.config.passes == 0 {
            return Err(MethodError::InvalidConfig {
                why: "passes must be at least 1".into(),
            });
        }
        self.network.set_precision(self.config.precision);
        let start = Instant::now();
        let frame = Normalisation::of_pair(source, target);
        // The points that are not far outliers, in the network's frame: all the method sees.
        let (source_near, target_near) = (near(source), near(target));
        let source_n = frame.source(&source.select(&source_near));
        let target_n = frame.target(&target.select(&target_near));
        let source_idx = matched_indices(&source_n, self.config.match_points, SOURCE_SEED);
        let target_idx = matched_indices(&target_n, self.config.match_points, TARGET_SEED);
        let (x, y) = (source_n.select(&source_idx), target_n.select(&target_idx));
        let needed = self.network.config().k + 1;
        for (cloud, matched) in [("source", &x), ("target", &y)] {
            if matched.len() < needed {
                return Err(MethodError::TooFewPoints {
                    cloud,
                    points: matched.len(),
                    needed,
                });
            }
        }
        crate::memory::check_fits(
            self.network.config(),
            self.network.num_params(),
            (x.len(), y.len()),
            self.config.cycle_consistency,
        )?;
        let (x_rows, y_rows) = (as_rows(&x), as_rows(&y)); // (N, 3), (M, 3)
        add_since(&mut self.times.prepare, start);
        let start = Instant::now();
        self.network
            .features(x_rows.view(), &mut self.source_features)?;
        self.network
            .features(y_rows.view(), &mut self.target_features)?;
        add_since(&mut self.times.features, start);
        // The chains advance side by side: pass 0 of the reverse chain reuses pass 0 of the
        // forward chain. Only the last pass's correspondences leave a chain.
        let (mut moved_x, mut moved_y) = (x.clone(), y.clone());
        let mut ends = (None, None); // (forward chain's H (N, M), reverse chain's H (M, N))
        for pass in 0..self.config.passes {
            let last = pass + 1 == self.config.passes;
            let found = self.chain_pass(Chain::Forward, pass, &moved_x)?;
            if !last {
                let step = self.kabsch_of(&moved_x, &y, found.pairs())?;
                moved_x = moved_x.transformed(&step);
            }
            ends.0 = Some(found);
            if self.config.cycle_consistency {
                let found = self.chain_pass(Chain::Reverse, pass, &moved_y)?;
                if !last {
                    let step = self.kabsch_of(&moved_y, &x, found.pairs())?;
                    moved_y = moved_y.transformed(&step);
                }
                ends.1 = Some(found);
            }
        }
        let found = match ends {
            (Some(forward), Some(reverse)) => {
                let start = Instant::now();
                let kept = forward.cycle_consistent(&reverse)?;
                add_since(&mut self.times.matching, start);
                kept
            }
            (Some(forward), None) => forward,
            (None, _) => unreachable!("passes ≥ 1 was checked"),
        };
        if found.pairs().is_empty() {
            return Err(MethodError::NoCorrespondences {
                stage: "cycle consistency (the two chains end with no common pair)".into(),
            });
        }
        let mut total = self.kabsch_of(&x, &y, found.pairs())?;
        let mut iterations = self.config.passes;
        let mut refined_score = None;
        if let Some(config) = &self.config.refine {
            let start = Instant::now();
            let refined = refine::refine(&source_n, &target_n, &total, config)?;
            add_since(&mut self.times.refine, start);
            total = refined.t_target_source;
            iterations += refined.iterations;
            // Far outliers count as source points without a partner.
            let near_share = source_n.len() as f64 / source.len() as f64;
            refined_score = Some((
                refined.fitness * near_share,
                refined.inlier_rmse * frame.scale,
            ));
        }
        // Unrefined, the score is the final correspondences' own, taken in the network's frame
        // (squared distances at the caller's scale may overflow).
        let (fitness, inlier_rmse) = refined_score.unwrap_or_else(|| {
            let sum_d2: f64 = found
                .pairs()
                .iter()
                .map(|&(i, j)| (total.apply(&x.points[i]) - y.points[j]).norm_squared())
                .sum();
            let rmse = (sum_d2 / found.pairs().len() as f64).sqrt() * frame.scale;
            (found.pairs().len() as f64 / x.len() as f64, rmse)
        });
        let total = frame.undo(&total);
        self.pairs = found
            .pairs()
            .iter()
            .map(|&(i, j)| (source_near[source_idx[i]], target_near[target_idx[j]]))
            .collect();
        Ok(RegistrationResult {
            t_target_source: total,
            iterations,
            converged: true,
            inlier_count: self.pairs.len(),
            fitness,
            inlier_rmse,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Config;

    /// The tiny network and 48×48 pair of `tests/fixtures` (see `tests/pipeline.rs`).
    fn fixture() -> (Rgm<f32>, PointCloud, PointCloud) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/rgm_tiny_state_dict.safetensors");
        let (tensors, _) = rgm_nn::io::read_tensors::<f32>(&path).unwrap();
        let cloud = |name: &str| {
            let t = &tensors[name];
            PointCloud::new(
                t.outer_iter()
                    .map(|r| Point3::new(r[0] as f64, r[1] as f64, r[2] as f64))
                    .collect(),
            )
        };
        let network = Rgm::load(Config::tiny(), &path).unwrap();
        (network, cloud("input.x"), cloud("input.y"))
    }

    #[test]
    fn matching_a_subset_is_registering_the_subset() {
        // match_points = 30 of 48: the same transform as registering the two drawn subsets,
        // and the correspondences translated back to the full clouds' indices.
        let (network, source, target) = fixture();
        let config = PipelineConfig {
            passes: 1,
            cycle_consistency: false,
            ..Default::default()
        };
        let mut whole = RgmRegistrar::new(
            network.clone(),
            PipelineConfig {
                match_points: Some(30),
                ..config.clone()
            },
        );
        let mut part = RgmRegistrar::new(network, config);
        let (si, ti) = (
            subsample(48, Some(30), SOURCE_SEED),
            subsample(48, Some(30), TARGET_SEED),
        );
        let a = whole.register(&source, &target).unwrap();
        let b = part
            .register(&source.select(&si), &target.select(&ti))
            .unwrap();
        assert_eq!(a.t_target_source, b.t_target_source);
        let mapped: Vec<_> = part
            .correspondences()
            .iter()
            .map(|&(i, j)| (si[i], ti[j]))
            .collect();
        assert!(!mapped.is_empty());
        assert_eq!(whole.correspondences(), &mapped[..]);
        assert_eq!(a.fitness, mapped.len() as f64 / 30.0);
    }

    #[test]
    fn a_registration_beyond_the_free_memory_is_refused_before_it_starts() {
        // 200,000 points matched whole would need terabytes: refused, naming the estimate.
        let (network, source, _) = fixture();
        let big = PointCloud::new(
            (0..200_000)
                .map(|i| source.points[i % source.len()] * (1.0 + i as f64 * 1e-7))
                .collect(),
        );
        let mut registrar = RgmRegistrar::new(network, PipelineConfig::default());
        match registrar.register(&big, &big) {
            Err(MethodError::TooMuchMemory {
                points, estimate, ..
            }) => {
                assert_eq!(points, (200_000, 200_000));
                assert!(estimate > 1 << 40, "{estimate}");
            }
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    #[test]
    fn subsets_are_reproducible_sorted_and_distinct() {
        let a = subsample(1000, Some(384), SOURCE_SEED);
        assert_eq!(a, subsample(1000, Some(384), SOURCE_SEED));
        assert_eq!(a.len(), 384);
        assert!(a.windows(2).all(|w| w[0] < w[1]) && a[383] < 1000);
        assert_ne!(a, subsample(1000, Some(384), TARGET_SEED));
        assert_eq!(subsample(5, Some(384), 0), vec![0, 1, 2, 3, 4]);
        assert_eq!(subsample(3, None, 0), vec![0, 1, 2]);
    }
}
