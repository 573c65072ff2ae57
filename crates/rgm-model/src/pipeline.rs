//! RGM at test time (spec §4): the network's soft correspondences, inlier selection, linear
//! assignment, cycle consistency and weighted Kabsch, iterated on the moved source.
//!
//! Around it, what real inputs need: the clouds are brought into the frame the network was
//! trained in ([`Normalisation`]), large clouds are subsampled for matching (the transform
//! found applies to the full clouds), and ICP may refine the result on the full clouds.
//!
//! The local features of a cloud depend on that cloud alone at test time, so each is computed
//! once and reused: the target's for every pass, both clouds' for the reverse (Y, X) pass
//! (3 feature passes for the paper's 2 passes instead of 8). The reverse pass also reuses the
//! forward pass's block-0 edges and graph convolutions ([`Rgm::forward_reverse`]).

use std::time::Instant;

use ndarray::Array2;
use rand::{rngs::StdRng, SeedableRng};
use rgm_geom::kabsch::kabsch;
use rgm_geom::refine::{self, RefineConfig};
use rgm_geom::{Point3, PointCloud, RegistrationResult, RigidTransform, Vector3};
use rgm_match::{hard_match, Correspondences, MatchConfig};
use rgm_nn::Precision;

use crate::method::MethodError;
use crate::network::{FeaturerCache, Rgm, RgmCache};

/// Test-time settings; the defaults are the paper's.
#[derive(Clone, Debug, PartialEq)]
pub struct PipelineConfig {
    /// Passes of network → matching → Kabsch, each on the source moved by the passes before
    /// (2 in the paper's tables).
    pub passes: usize,
    /// Keep only correspondences found both from (X, Y) and from (Y, X) (on in the reference).
    pub cycle_consistency: bool,
    /// Rows and columns of C̃ whose sums exceed this are inliers (0.5).
    pub inlier_threshold: f64,
    /// Match on at most this many points of each cloud, drawn at random with a fixed seed (so a
    /// pair always gives the same result); `None` (the paper) matches on every point. A model
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
/// and the larger is at least [`Normalisation::MIN_EXTENT`] across. Any other pair is centred
/// (each cloud on its centroid) and scaled by one common factor so that the farthest point of
/// either cloud lies on the unit sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalisation {
    pub source_centre: Vector3<f64>,
    pub target_centre: Vector3<f64>,
    pub scale: f64,
}

impl Normalisation {
    /// Pairs within this radius of the origin are in the training frame.
    pub const FRAME_RADIUS: f64 = 2.0;
    /// …unless both clouds are smaller than this (largest distance from their centroid).
    pub const MIN_EXTENT: f64 = 0.25;

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
        let radius = |cloud: &PointCloud, centre: &Point3<f64>| {
            cloud
                .points
                .iter()
                .map(|p| (p - centre).norm())
                .fold(0.0, f64::max)
        };
        let (cx, cy) = (source.centroid(), target.centroid());
        let extent = radius(source, &cx).max(radius(target, &cy));
        let reach = radius(source, &Point3::origin()).max(radius(target, &Point3::origin()));
        if reach <= Self::FRAME_RADIUS && extent >= Self::MIN_EXTENT || extent == 0.0 {
            return Self::identity();
        }
        Self {
            source_centre: cx.coords,
            target_centre: cy.coords,
            scale: extent,
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
    /// The local feature extractor (the target once, the moved source every pass).
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
    source_features: FeaturerCache<f32>, // the moved matched source's features (N, C)
    target_features: FeaturerCache<f32>, // the matched target's features (M, C), once per pair
    forward: RgmCache<f32>,              // (X, Y) pass
    reverse: RgmCache<f32>,              // (Y, X) pass
    pairs: Vec<(usize, usize)>,          // the last pass's correspondences, caller's indices
    times: StageTimes,                   // of the last registration
}

/// A cloud as the network's (N, 3) f32 input.
pub(crate) fn as_rows(cloud: &PointCloud) -> Array2<f32> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c] as f32) // (N, 3)
}

impl RgmRegistrar {
    /// A registrar around `network`.
    pub fn new(network: Rgm<f32>, config: PipelineConfig) -> Self {
        Self {
            network,
            config,
            source_features: FeaturerCache::default(),
            target_features: FeaturerCache::default(),
            forward: RgmCache::default(),
            reverse: RgmCache::default(),
            pairs: Vec::new(),
            times: StageTimes::default(),
        }
    }

    /// The hard correspondences (source index, target index) of the last registration's last
    /// pass, as indices into the clouds given to [`RgmRegistrar::register`]. Empty before any
    /// registration and after a failed one.
    pub fn correspondences(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// Where the time of the last registration went.
    pub fn stage_times(&self) -> StageTimes {
        self.times
    }

    /// The hard correspondences of one pass on the moved source `x` (N, 3) and the target
    /// whose features are in `target_features`.
    fn match_pass(&mut self, x: &Array2<f32>) -> Result<Correspondences, MethodError> {
        let matching = MatchConfig {
            inlier_threshold: self.config.inlier_threshold,
        };
        let start = Instant::now();
        self.network.features(x.view(), &mut self.source_features)?;
        add_since(&mut self.times.features, start);
        let fx = self.source_features.features.view(); // (N, C)
        let fy = self.target_features.features.view(); // (M, C)
        let start = Instant::now();
        self.network
            .forward_from_features(fx, fy, &mut self.forward)?;
        if self.config.cycle_consistency {
            self.network
                .forward_reverse(&self.forward, &mut self.reverse)?;
        }
        add_since(&mut self.times.blocks, start);
        let start = Instant::now();
        let mut found = hard_match(self.forward.c_soft(), &matching)?;
        if self.config.cycle_consistency {
            let reverse = hard_match(self.reverse.c_soft(), &matching)?;
            found = found.cycle_consistent(&reverse)?;
        }
        add_since(&mut self.times.matching, start);
        Ok(found)
    }

    /// The transform that maps `source` onto `target`: the composition of every pass's
    /// Kabsch solution (then the refinement, if configured), in the caller's frame.
    /// `inlier_count` is the number of correspondences of the last pass
    /// ([`RgmRegistrar::correspondences`]); `iterations` counts the passes and the refinement's
    /// iterations. Unrefined, `inlier_rmse` is those correspondences' distance after the
    /// transform and `fitness` their share of the matched source points; refined, both are the
    /// refinement's score (the share of all source points with a target point closer than its
    /// finest distance, and their RMS distance, in the caller's units): many of the network's
    /// correspondences are wrong even when its transform is right, so their distances say little.
    pub fn register(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
    ) -> Result<RegistrationResult, MethodError> {
        self.pairs.clear();
        self.times = StageTimes::default();
        self.network.set_precision(self.config.precision);
        let start = Instant::now();
        let frame = Normalisation::of_pair(source, target);
        let (source_n, target_n) = (frame.source(source), frame.target(target));
        let source_idx = subsample(source.len(), self.config.match_points, SOURCE_SEED);
        let target_idx = subsample(target.len(), self.config.match_points, TARGET_SEED);
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
        let y_rows = as_rows(&y); // (M, 3)
        add_since(&mut self.times.prepare, start);
        let start = Instant::now();
        self.network
            .features(y_rows.view(), &mut self.target_features)?;
        add_since(&mut self.times.features, start);
        let mut total = RigidTransform::identity();
        let mut used: Vec<(usize, usize)> = Vec::new();
        for pass in 0..self.config.passes {
            let moved = x.transformed(&total);
            let found = self.match_pass(&as_rows(&moved))?;
            if found.pairs().is_empty() {
                return Err(MethodError::NoCorrespondences { pass: pass + 1 });
            }
            let src: Vec<Point3<f64>> = found
                .pairs()
                .iter()
                .map(|&(i, _)| moved.points[i])
                .collect();
            let tgt: Vec<Point3<f64>> = found.pairs().iter().map(|&(_, j)| y.points[j]).collect();
            let start = Instant::now();
            let step = kabsch(&src, &tgt, &vec![1.0; src.len()])?;
            add_since(&mut self.times.kabsch, start);
            total = step.compose(&total);
            used = found.pairs().to_vec();
        }
        let mut iterations = self.config.passes;
        let mut refined_score = None;
        if let Some(config) = &self.config.refine {
            let start = Instant::now();
            let refined = refine::refine(&source_n, &target_n, &total, config)?;
            add_since(&mut self.times.refine, start);
            total = refined.t_target_source;
            iterations += refined.iterations;
            refined_score = Some((refined.fitness, refined.inlier_rmse * frame.scale));
        }
        let total = frame.undo(&total);
        self.pairs = used
            .iter()
            .map(|&(i, j)| (source_idx[i], target_idx[j]))
            .collect();
        let (fitness, inlier_rmse) = refined_score.unwrap_or_else(|| {
            let sum_d2: f64 = self
                .pairs
                .iter()
                .map(|&(i, j)| (total.apply(&source.points[i]) - target.points[j]).norm_squared())
                .sum();
            let rmse = if self.pairs.is_empty() {
                0.0
            } else {
                (sum_d2 / self.pairs.len() as f64).sqrt()
            };
            (self.pairs.len() as f64 / x.len() as f64, rmse)
        });
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
