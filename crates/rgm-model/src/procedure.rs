//! RGM at test time, the reference code's procedure (spec §4): two *chains* of passes — the
//! source moved toward the target, and the target moved toward the source — each pass the
//! network's soft correspondences, inlier selection, linear assignment and a weighted Kabsch
//! that moves the chain's cloud; then cycle consistency between the two chains' last hard
//! correspondences, and ONE weighted Kabsch of the original clouds with what survives.
//! Where fewer than three pairs survive, which fix no pose, the forward chain's own pairs are
//! used (the reference's Kabsch of two pairs is degenerate: its pose is arbitrary).
//!
//! Around it, what real inputs need: large clouds are subsampled for matching (the transform
//! found applies to the full clouds). The network expects the unit-sphere frame of its training
//! clouds: wrap the registrar in [`rgm_registration::compose::Normalised`] for pairs of any size,
//! and in [`rgm_registration::compose::Refined`] for an ICP refinement.
//!
//! The local features of a cloud depend on that cloud alone at test time, so each is computed
//! once per distinct cloud: X and Y once each, and each moved copy once (2 + 2(P − 1) feature
//! passes for P passes instead of 4P). The reverse chain's first pass (Y, X) reuses the forward
//! chain's first pass (X, Y) for block 0's edges and graph convolutions
//! ([`Rgm::forward_both`]).
//!
//! On rayon's pool, what is independent runs side by side: the two clouds' features, the two
//! chains, and inside each block the two clouds' sides. Each piece is computed as on one
//! thread, so the result is the same bits on any number of threads.

use std::time::Instant;

use ndarray::Array2;
use rand::{rngs::StdRng, SeedableRng};
use rgm_geom::kabsch::{self, kabsch};
use rgm_geom::{Point3, PointCloud, RigidTransform};
use rgm_match::{hard_match, Correspondences, MatchConfig};
use rgm_nn::{Compute, Parameters, Precision};
use rgm_registration::registrar::{MethodId, Progress, Registrar, Registration};
use rgm_registration::thinning::Density;
use rgm_registration::{Fit, Prepared};

use crate::error::MethodError;
use crate::network::{both, FeaturerCache, Rgm, RgmCache};

/// The density the network and the default's settings were tuned at: ModelNet40's 1,024 points
/// per shape in the unit sphere (717 after the partial crop). A denser pair is thinned to it,
/// first averaged over voxels of 0.035 (the training clouds' median nearest-neighbour distance is
/// 0.011–0.042).
pub const TRAINING_DENSITY: Density = Density {
    points: 1024,
    voxel: 0.035,
};

/// Test-time settings; the defaults are the paper's.
#[derive(Clone, Debug, PartialEq)]
pub struct ProcedureConfig {
    /// Passes of network → matching → Kabsch in each chain, each on the chain's cloud moved by
    /// the passes before (2 in the paper's tables).
    pub passes: usize,
    /// Run the reverse chain too and keep only the correspondences both chains end with (on in
    /// the reference); off, the forward chain's last correspondences are used alone.
    pub cycle_consistency: bool,
    /// Rows and columns of C̃ whose sums exceed this are inliers (0.5).
    pub inlier_threshold: f64,
    /// Match on at most this many points of each cloud, drawn at random with a fixed seed (so a
    /// pair always gives the same result) from the cloud thinned to [`TRAINING_DENSITY`]'s
    /// points when it is denser ([`matched_indices`]); `None` (the paper) matches on every
    /// point. A model
    /// trained on subsampled clouds matches best on as many points as it was trained on.
    pub match_points: Option<usize>,
    /// The network's matrix products: f32, or bf16 where the processor has AMX or AVX-512 BF16.
    pub precision: Precision,
}

impl Default for ProcedureConfig {
    fn default() -> Self {
        Self {
            passes: 2,
            cycle_consistency: true,
            inlier_threshold: 0.5,
            match_points: None,
            precision: Precision::F32,
        }
    }
}

/// The method's name ([`MethodId`]).
pub const NAME: &str = "rgm";

/// Seeds of the matched subsets of source and target (different, so that clouds with related
/// point orders do not get related subsets).
const SOURCE_SEED: u64 = 0;
const TARGET_SEED: u64 = 1;

/// The indices of `cloud` that RGM matches on: at most `count` (all when `None`), drawn at
/// random from `seed` after the thinning of [`TRAINING_DENSITY`] points, sorted.
pub fn matched_indices(cloud: &PointCloud, count: Option<usize>, seed: u64) -> Vec<usize> {
    let Some(count) = count else {
        return (0..cloud.len()).collect();
    };
    let thinned = cloud.farthest_point_indices(count.max(TRAINING_DENSITY.points)); // (T,)
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

/// Wall time of each stage of one registration, in seconds (summed over passes, and over the
/// two chains, which run side by side on a pool of several threads: the total can then exceed
/// the registration's wall time).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Subsampling and conversion of the clouds.
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
}

impl StageTimes {
    /// The whole registration.
    pub fn total(&self) -> f64 {
        self.prepare + self.features + self.blocks + self.matching + self.kabsch
    }
}

impl std::ops::AddAssign for StageTimes {
    fn add_assign(&mut self, other: Self) {
        self.prepare += other.prepare;
        self.features += other.features;
        self.blocks += other.blocks;
        self.matching += other.matching;
        self.kabsch += other.kabsch;
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
    /// Passes, cycle consistency, inlier threshold, subsampling, precision.
    pub config: ProcedureConfig,
    source_features: FeaturerCache<f32>, // the matched source X's features (N, C), once per pair
    target_features: FeaturerCache<f32>, // the matched target Y's features (M, C), once per pair
    forward: ChainBuffers,               // the forward chain's: X' (N, C), pass (X', Y)
    reverse: ChainBuffers,               // the reverse chain's: Y' (M, C), pass (Y', X)
    times: StageTimes,                   // of the last registration
}

/// One chain's buffers, its own so that the chains can run side by side.
#[derive(Clone, Debug, Default)]
struct ChainBuffers {
    moved_features: FeaturerCache<f32>, // the chain's moved cloud's features (N or M, C)
    pass: RgmCache<f32>,                // the chain's last pass (moved, partner)
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

/// One chain while it runs: its cloud as the passes so far moved it, and what it reads.
struct ChainRun<'a> {
    chain: Chain,
    moved: PointCloud,       // the chain's own cloud after the passes so far
    partner: &'a PointCloud, // the cloud it moves toward, which stays put
    own_features: &'a FeaturerCache<f32>, // of its own cloud unmoved (pass 0)
    partner_features: &'a FeaturerCache<f32>,
    buffers: &'a mut ChainBuffers,
    times: StageTimes,
    /// The last pass's hard correspondences (rows of the own cloud, columns of the partner).
    end: Option<Correspondences>,
}

impl ChainRun<'_> {
    /// Pass `pass` (from 0) on the chain's moved cloud: its features (after pass 0), C̃ of
    /// (moved, partner) unless `blocks_ran` already put it in the chain's buffers, its hard
    /// correspondences, and unless the pass is the last a weighted Kabsch that moves the
    /// cloud.
    fn pass(
        &mut self,
        network: &Rgm<f32>,
        config: &ProcedureConfig,
        pass: usize,
        blocks_ran: bool,
    ) -> Result<(), MethodError> {
        let buffers = &mut *self.buffers;
        if pass > 0 {
            let start = Instant::now();
            network.features(as_rows(&self.moved).view(), &mut buffers.moved_features)?;
            add_since(&mut self.times.features, start);
        }
        if !blocks_ran {
            let start = Instant::now();
            let own = if pass > 0 {
                &buffers.moved_features
            } else {
                self.own_features
            };
            network.forward_from_features(
                own.features.view(),
                self.partner_features.features.view(),
                &mut buffers.pass,
            )?;
            add_since(&mut self.times.blocks, start);
        }
        let start = Instant::now();
        let matching = MatchConfig {
            inlier_threshold: config.inlier_threshold,
        };
        let found = hard_match(buffers.pass.c_soft(), &matching)?;
        add_since(&mut self.times.matching, start);
        if found.pairs().is_empty() {
            return Err(MethodError::NoCorrespondences {
                stage: format!("pass {} of {}", pass + 1, self.chain.describe()),
            });
        }
        if pass + 1 < config.passes {
            let step = kabsch_of(&self.moved, self.partner, found.pairs(), &mut self.times)?;
            self.moved = self.moved.transformed(&step);
        }
        self.end = Some(found);
        Ok(())
    }
}

/// The weighted Kabsch of spec §4 that maps `a[i]` onto `b[j]` for each pair (i, j) (the
/// weights, H's row sums, are one per pair); its time is added to `times`.
fn kabsch_of(
    a: &PointCloud,
    b: &PointCloud,
    pairs: &[(usize, usize)],
    times: &mut StageTimes,
) -> Result<RigidTransform, MethodError> {
    let start = Instant::now();
    let (from, to): (Vec<Point3<f64>>, Vec<Point3<f64>>) = pairs
        .iter()
        .map(|&(i, j)| (a.points[i], b.points[j]))
        .unzip();
    let solved = kabsch(&from, &to, &vec![1.0; from.len()])?;
    add_since(&mut times.kabsch, start);
    Ok(solved)
}

impl RgmRegistrar {
    /// What every RGM registrar is called: the network alone, unrefined.
    pub const ID: MethodId = MethodId::plain(NAME);

    /// A registrar around `network`.
    pub fn new(network: Rgm<f32>, config: ProcedureConfig) -> Self {
        Self {
            network,
            config,
            source_features: FeaturerCache::default(),
            target_features: FeaturerCache::default(),
            forward: ChainBuffers::default(),
            reverse: ChainBuffers::default(),
            times: StageTimes::default(),
        }
    }

    /// Where the time of the last registration went.
    pub fn stage_times(&self) -> StageTimes {
        self.times
    }

    /// The registration of `source` onto `target` (spec §4), both in the network's frame: the
    /// weighted Kabsch of the matched clouds with the correspondences both chains end with.
    /// Its correspondences are those (indices into the clouds given), `inlier_count` their
    /// number, `fitness` their share of the matched source points and `inlier_rmse` their
    /// distance after the transform; `iterations` counts the passes of a chain.
    fn register_pair(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<(Fit, Vec<(usize, usize)>), MethodError> {
        self.times = StageTimes::default();
        if self.config.passes == 0 {
            return Err(MethodError::InvalidConfig {
                why: "passes must be at least 1".into(),
            });
        }
        self.network
            .set_compute(Compute::with_precision(self.config.precision));
        let start = Instant::now();
        let source_idx = matched_indices(source, self.config.match_points, SOURCE_SEED);
        let target_idx = matched_indices(target, self.config.match_points, TARGET_SEED);
        let (x, y) = (source.select(&source_idx), target.select(&target_idx));
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
        let (network, config) = (&self.network, &self.config);
        let (fx, fy) = (&mut self.source_features, &mut self.target_features);
        let (a, b) = both(
            true,
            || network.features(x_rows.view(), fx),
            || network.features(y_rows.view(), fy),
        );
        a.and(b)?;
        add_since(&mut self.times.features, start);
        // The chains advance side by side: pass 0 of the reverse chain reuses pass 0 of the
        // forward chain. Only the last pass's correspondences leave a chain.
        let cycle = config.cycle_consistency;
        let (fx, fy) = (&self.source_features, &self.target_features);
        let mut forward = ChainRun {
            chain: Chain::Forward,
            moved: x.clone(),
            partner: &y,
            own_features: fx,
            partner_features: fy,
            buffers: &mut self.forward,
            times: StageTimes::default(),
            end: None,
        };
        let mut reverse = ChainRun {
            chain: Chain::Reverse,
            moved: y.clone(),
            partner: &x,
            own_features: fy,
            partner_features: fx,
            buffers: &mut self.reverse,
            times: StageTimes::default(),
            end: None,
        };
        for pass in 0..config.passes {
            // Pass 0's blocks of both chains at once, to share block 0's graph features.
            let blocks_ran = pass == 0 && cycle;
            if blocks_ran {
                let start = Instant::now();
                network.forward_both(
                    fx.features.view(),
                    fy.features.view(),
                    &mut forward.buffers.pass,
                    &mut reverse.buffers.pass,
                )?;
                add_since(&mut self.times.blocks, start);
            }
            let (a, b) = both(
                cycle,
                || forward.pass(network, config, pass, blocks_ran),
                || {
                    if cycle {
                        reverse.pass(network, config, pass, blocks_ran)
                    } else {
                        Ok(())
                    }
                },
            );
            a.and(b)?;
        }
        self.times += forward.times;
        self.times += reverse.times;
        let Some(forward) = forward.end else {
            return Err(MethodError::InvalidConfig {
                why: "passes must be at least 1".into(),
            });
        };
        let found = match reverse.end {
            Some(reverse) => {
                let start = Instant::now();
                let kept = forward.cycle_consistent(&reverse)?;
                add_since(&mut self.times.matching, start);
                // Chains that agree on fewer pairs than fix a pose leave the forward chain's
                // own: the reference's Kabsch of two pairs is degenerate, its pose arbitrary.
                if kept.pairs().len() < kabsch::MIN_POINTS
                    && forward.pairs().len() >= kabsch::MIN_POINTS
                {
                    forward
                } else {
                    kept
                }
            }
            None => forward,
        };
        if found.pairs().is_empty() {
            return Err(MethodError::NoCorrespondences {
                stage: "cycle consistency (the two chains end with no common pair)".into(),
            });
        }
        let total = kabsch_of(&x, &y, found.pairs(), &mut self.times)?;
        let sum_d2: f64 = found
            .pairs()
            .iter()
            .map(|&(i, j)| (total.apply(&x.points[i]) - y.points[j]).norm_squared())
            .sum();
        let count = found.pairs().len();
        let result = Fit {
            t_target_source: total,
            iterations: self.config.passes,
            converged: true,
            inlier_count: count,
            fitness: count as f64 / x.len() as f64,
            inlier_rmse: (sum_d2 / count as f64).sqrt(),
        };
        let pairs = found
            .pairs()
            .iter()
            .map(|&(i, j)| (source_idx[i], target_idx[j]))
            .collect();
        Ok((result, pairs))
    }
}

/// The network alone, on clouds in its frame.
impl Registrar<MethodError> for RgmRegistrar {
    fn id(&self) -> MethodId {
        Self::ID
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, MethodError> {
        let start = Instant::now();
        let (result, pairs) = self.register_pair(source, target)?;
        Ok(Registration::single(result, pairs, start))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Config;

    /// The tiny network and 48×48 pair of `tests/fixtures` (see `tests/procedure.rs`).
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
        let config = ProcedureConfig {
            passes: 1,
            cycle_consistency: false,
            ..Default::default()
        };
        let mut whole = RgmRegistrar::new(
            network.clone(),
            ProcedureConfig {
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
        assert_eq!(a.result.t_target_source, b.result.t_target_source);
        let mapped: Vec<_> = b
            .correspondences
            .iter()
            .map(|&(i, j)| (si[i], ti[j]))
            .collect();
        assert!(!mapped.is_empty());
        assert_eq!(a.correspondences, mapped);
        assert_eq!(a.result.fitness, mapped.len() as f64 / 30.0);
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
        let mut registrar = RgmRegistrar::new(network, ProcedureConfig::default());
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
