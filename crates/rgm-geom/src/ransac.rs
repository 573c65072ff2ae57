//! RANSAC on FPFH correspondences, for scene-scale pairs (rooms, streets): the global step of
//! Open3D's `registration_ransac_based_on_feature_matching` tutorial pipeline, with every length
//! a multiple of the pair's own point spacing.
//!
//! 1. Thinning: both clouds voxel-averaged with one voxel, the finest that leaves at most
//!    [`RansacConfig::max_points`] in each (features of the two clouds compare only at one
//!    density); the spacing is the thinned pair's median nearest-neighbour distance.
//! 2. Features: PCA normals and FPFH ([`crate::fpfh::features`]) at radii in spacings.
//! 3. Matching: each source point's nearest target point in feature space
//!    ([`crate::fgr::nearest_matches`]), or only the mutual ones ([`RansacConfig::mutual`]).
//! 4. Hypotheses: three matches drawn at random; kept only when each side of their triangle
//!    agrees between the clouds within [`RansacConfig::edge_similarity`] (the correspondence
//!    check, which rejects most wrong draws before any fit) and the Kabsch fit of the three
//!    brings each within the inlier distance of its partner (the distance check); then scored
//!    by the matches it brings within that distance. Draws run in fixed chunks, each from its
//!    own seeded generator, so the result is the same on any number of threads.
//! 5. The best hypothesis refitted on its inliers (Kabsch) until they stop changing.
//!
//! FGR's graduated non-convexity follows the bulk of the matches; on a room most matches are
//! wrong (floors and walls look alike everywhere) and the bulk can lie at a wrong pose, where a
//! consensus count still finds the few right ones.

use nalgebra::{Point3, Vector3};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rayon::prelude::*;
use std::time::Instant;

use crate::fgr::{mutual_matches, nearest_matches, Progress};
use crate::fpfh::{features, FpfhConfig};
use crate::icp::check_clouds;
use crate::normals::NormalsConfig;
use crate::refine::{median_spacing, refine_at_resolution, ResolutionConfig};
use crate::registrar::{MethodId, Registrar, Registration};
use crate::registration::score;
use crate::registration::Fit;
use crate::{kabsch, GeomError, PointCloud, Prepared, Result, RigidTransform};

/// The method's name ([`crate::registrar::MethodId`]).
pub const NAME: &str = "ransac";

/// Draws per chunk: a chunk's draws come from one generator seeded by the chunk's index.
const CHUNK: usize = 1024;

/// Chunks run side by side before the draws made so far are weighed against
/// [`RansacConfig::confidence`]: a fixed wave, so that where the draws stop does not depend on
/// the threads.
const WAVE: usize = 8;

/// Settings of [`register`]. Lengths are in point spacings of the thinned pair; the defaults
/// are Open3D's tutorial settings (normals at 2 voxels, FPFH at 5, inliers within 1.5, edges
/// within 0.9, 100,000 draws) with its voxel read as one spacing.
#[derive(Clone, Debug, PartialEq)]
pub struct RansacConfig {
    /// Each cloud is thinned to at most this many points (default 5,000).
    pub max_points: usize,
    /// Normals' neighbourhood radius, in spacings (default 2), at most 30 neighbours.
    pub normal_spacings: f64,
    /// FPFH's neighbourhood radius, in spacings (default 5), at most 100 neighbours.
    pub feature_spacings: f64,
    /// A match is an inlier of a transform that brings it within this many spacings
    /// (default 1.5).
    pub inlier_spacings: f64,
    /// The least ratio of a drawn triangle's side in one cloud to the same side in the other
    /// (default 0.9).
    pub edge_similarity: f64,
    /// Match only mutual nearest features (default false: each source point's nearest target
    /// feature, as Open3D's tutorial; the mutual filter leaves too few right matches on rooms).
    pub mutual: bool,
    /// Triples drawn, at most (default 100,000).
    pub draws: usize,
    /// The draws stop, after a wave of chunks, once they make it this likely that one of them
    /// was three inliers of the best hypothesis found (Open3D's `confidence`, default 0.999): a
    /// scan pair whose matches are mostly right needs a few hundred, a room all of them.
    pub confidence: f64,
    /// Refits of the best hypothesis on its inliers, at most (default 5).
    pub refits: usize,
    /// Seed of the draws (default 0).
    pub seed: u64,
    /// The final point-to-plane stages on the thinned pair, from the consensus
    /// ([`refine_at_resolution`], in the thinned target's spacings; default 4, 2).
    pub refinement: ResolutionConfig,
    /// Points sampled to measure the spacing (default 2,000).
    pub spacing_sample: usize,
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self {
            max_points: 5000,
            normal_spacings: 2.0,
            feature_spacings: 5.0,
            inlier_spacings: 1.5,
            edge_similarity: 0.9,
            mutual: false,
            draws: 100_000,
            confidence: 0.999,
            refits: 5,
            seed: 0,
            refinement: ResolutionConfig::default(),
            spacing_sample: 2000,
        }
    }
}

/// What [`consensus`] found: the transform and the matches within the inlier distance of it.
#[derive(Clone, Debug, PartialEq)]
pub struct Consensus {
    pub t_target_source: RigidTransform,
    /// Indices into the matches given.
    pub inliers: Vec<usize>,
    /// Hypotheses that passed both checks and were scored.
    pub hypotheses: usize,
}

/// Registers `source` onto `target` by RANSAC on FPFH matches of the thinned pair (steps 1–5 of
/// the module). The result is scored on the thinned pair at the inlier distance.
pub fn register(source: &PointCloud, target: &PointCloud, config: &RansacConfig) -> Result<Fit> {
    register_prepared(&Prepared::new(source), &Prepared::new(target), config)
}

/// [`register`] on prepared clouds, whose trees serve when they are small enough to be used
/// whole.
pub fn register_prepared(
    source: &Prepared,
    target: &Prepared,
    config: &RansacConfig,
) -> Result<Fit> {
    const OP: &str = "ransac::register";
    check_clouds(OP, source, target)?;
    if !(config.edge_similarity > 0.0 && config.edge_similarity <= 1.0) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!(
                "edge_similarity must be in (0, 1], got {}",
                config.edge_similarity
            ),
        });
    }
    let thinned = thinned_pair(source, target, config.max_points)
        .map(|(s, t)| (Prepared::new(s), Prepared::new(t)));
    let (small_source, small_target) = match &thinned {
        Some((s, t)) => (s, t),
        None => (source, target),
    };
    let (source_index, target_index) =
        rayon::join(|| small_source.index(), || small_target.index());
    let spacing = median_spacing(&small_source.points, source_index, config.spacing_sample).max(
        median_spacing(&small_target.points, target_index, config.spacing_sample),
    );
    if !(spacing > 0.0) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: "the clouds' points coincide: no spacing to measure lengths by".into(),
        });
    }
    let normals = NormalsConfig {
        radius: config.normal_spacings * spacing,
        max_nn: 30,
    };
    let fpfh = FpfhConfig {
        radius: config.feature_spacings * spacing,
        max_nn: 100,
    };
    let (source_features, target_features) = rayon::join(
        || features(&small_source.points, source_index, &normals, &fpfh), // (N', 33)
        || features(&small_target.points, target_index, &normals, &fpfh), // (M', 33)
    );
    let matches = if config.mutual {
        mutual_matches(&source_features, &target_features)
    } else {
        nearest_matches(&source_features, &target_features)
    };
    let from: Vec<Point3<f64>> = matches
        .iter()
        .map(|&(i, _)| small_source.points[i])
        .collect(); // (C, 3)
    let to: Vec<Point3<f64>> = matches
        .iter()
        .map(|&(_, j)| small_target.points[j])
        .collect(); // (C, 3)
    let distance = config.inlier_spacings * spacing;
    if from.len() < 3 {
        return Err(GeomError::TooFewPoints {
            op: OP,
            needed: 3,
            got: from.len(),
        });
    }
    let squared = distance * distance;
    let (winners, hypotheses) = chunk_winners(&from, &to, squared, config);
    // Each chunk's winner judged by the share of the thinned source it brings within the
    // inlier distance: on a scene the right matches are few, and a wrong pose that many
    // matches of look-alike floor agree with lays little of one room on the other.
    let fitness: Vec<f64> = winners
        .par_iter()
        .map(|(_, t)| score(&small_source.points, target_index, t, distance, None).fitness)
        .collect();
    let best = (0..winners.len()).fold(None, |best: Option<usize>, w| match best {
        Some(b) if fitness[b] >= fitness[w] => best,
        _ => Some(w),
    });
    let Some(best) = best else {
        return Err(no_hypothesis(OP, from.len()));
    };
    let found = refitted(
        &from,
        &to,
        winners[best].1,
        squared,
        config.refits,
        hypotheses,
    );
    let (transform, iterations) = refine_at_resolution(
        small_source,
        small_target,
        target_index,
        &found.t_target_source,
        f64::INFINITY,
        &config.refinement,
    )?;
    let scored = score(
        &small_source.points,
        target_index,
        &transform,
        distance,
        None,
    );
    Ok(Fit::scored(
        transform,
        found.hypotheses + iterations,
        true,
        scored,
    ))
}

/// The transform most matches `from[c] → to[c]` agree with within `distance`, by RANSAC on
/// triples with the correspondence and distance checks (steps 4–5 of the module). An error
/// when fewer than 3 matches are given or no triple passes the checks.
pub fn consensus(
    from: &[Point3<f64>],
    to: &[Point3<f64>],
    distance: f64,
    config: &RansacConfig,
) -> Result<Consensus> {
    const OP: &str = "ransac::consensus";
    if from.len() != to.len() {
        return Err(GeomError::LengthMismatch {
            op: OP,
            left: from.len(),
            right: to.len(),
        });
    }
    if from.len() < 3 {
        return Err(GeomError::TooFewPoints {
            op: OP,
            needed: 3,
            got: from.len(),
        });
    }
    let squared = distance * distance;
    let (winners, hypotheses) = chunk_winners(from, to, squared, config);
    // The most inliers; ties to the earlier chunk, whatever the threads.
    let best = winners.iter().fold(
        None,
        |best: Option<&(usize, RigidTransform)>, w| match best {
            Some(b) if b.0 >= w.0 => best,
            _ => Some(w),
        },
    );
    let Some(&(_, transform)) = best else {
        return Err(no_hypothesis(OP, from.len()));
    };
    Ok(refitted(
        from,
        to,
        transform,
        squared,
        config.refits,
        hypotheses,
    ))
}

fn no_hypothesis(op: &'static str, matches: usize) -> GeomError {
    GeomError::Degenerate {
        op,
        why: format!(
            "no triple of the {matches} matches passed the correspondence and distance checks"
        ),
    }
}

/// Each chunk's best hypothesis, as (inliers, transform), in chunk order, and the hypotheses
/// scored in all; the chunks run in waves of [`WAVE`] until the draws reach `config.draws` or
/// [`draws_needed`] for the best hypothesis so far.
fn chunk_winners(
    from: &[Point3<f64>],
    to: &[Point3<f64>],
    squared: f64,
    config: &RansacConfig,
) -> (Vec<(usize, RigidTransform)>, usize) {
    let chunks = config.draws.div_ceil(CHUNK);
    // Per chunk: (inliers, hypotheses scored, transform) of its best hypothesis.
    let mut per_chunk: Vec<(usize, usize, Option<RigidTransform>)> = Vec::with_capacity(chunks);
    while per_chunk.len() < chunks {
        let wave = per_chunk.len()..(per_chunk.len() + WAVE).min(chunks);
        per_chunk.par_extend(
            wave.into_par_iter()
                .map(|c| chunk_winner(from, to, squared, config, c)),
        );
        let best = per_chunk.iter().map(|c| c.0).max().unwrap_or(0);
        let drawn = (per_chunk.len() * CHUNK).min(config.draws);
        if drawn as f64 >= draws_needed(best as f64 / from.len() as f64, config.confidence) {
            break;
        }
    }
    let hypotheses = per_chunk.iter().map(|c| c.1).sum();
    let winners = per_chunk
        .into_iter()
        .filter_map(|(count, _, t)| t.map(|t| (count, t)))
        .collect();
    (winners, hypotheses)
}

/// Chunk `c`'s best hypothesis: (inliers, hypotheses scored, transform).
fn chunk_winner(
    from: &[Point3<f64>],
    to: &[Point3<f64>],
    squared: f64,
    config: &RansacConfig,
    c: usize,
) -> (usize, usize, Option<RigidTransform>) {
    // The seed in the high bits: another seed draws from other generators, not shifted ones.
    let mut rng = StdRng::seed_from_u64(config.seed << 32 ^ c as u64);
    let draws = CHUNK.min(config.draws - c * CHUNK);
    let mut best = (0, 0, None);
    for _ in 0..draws {
        let Some(t) = hypothesis(from, to, &mut rng, squared, config.edge_similarity) else {
            continue;
        };
        best.1 += 1;
        let count = inliers_of(from, to, &t, squared).count();
        if count > best.0 {
            (best.0, best.2) = (count, Some(t));
        }
    }
    best
}

/// Draws after which one of them was three inliers with probability `confidence`, when a share
/// `inliers` of the matches are (infinite when none is).
fn draws_needed(inliers: f64, confidence: f64) -> f64 {
    let all_three = inliers.powi(3);
    if all_three <= 0.0 {
        return f64::INFINITY;
    }
    if all_three >= 1.0 {
        return 0.0;
    }
    (1.0 - confidence).ln() / (1.0 - all_three).ln()
}

/// `transform` refitted (Kabsch) on the matches within √`squared` of it, at most `refits`
/// times, while they do not shrink.
fn refitted(
    from: &[Point3<f64>],
    to: &[Point3<f64>],
    mut transform: RigidTransform,
    squared: f64,
    refits: usize,
    hypotheses: usize,
) -> Consensus {
    let mut inliers: Vec<usize> = inliers_of(from, to, &transform, squared).collect();
    for _ in 0..refits {
        let a: Vec<Point3<f64>> = inliers.iter().map(|&c| from[c]).collect(); // (I, 3)
        let b: Vec<Point3<f64>> = inliers.iter().map(|&c| to[c]).collect(); // (I, 3)
        let Ok(refit) = kabsch(&a, &b, &vec![1.0; a.len()]) else {
            break;
        };
        let next: Vec<usize> = inliers_of(from, to, &refit, squared).collect();
        if next.len() < inliers.len() {
            break;
        }
        transform = refit;
        if next == inliers {
            break;
        }
        inliers = next;
    }
    Consensus {
        t_target_source: transform,
        inliers,
        hypotheses,
    }
}

/// The indices of the matches that `t` brings within √`squared` of their partners.
fn inliers_of<'a>(
    from: &'a [Point3<f64>],
    to: &'a [Point3<f64>],
    t: &'a RigidTransform,
    squared: f64,
) -> impl Iterator<Item = usize> + 'a {
    (0..from.len()).filter(move |&c| (t.apply(&from[c]) - to[c]).norm_squared() < squared)
}

/// The Kabsch fit of three matches drawn with `rng`, when their triangle's sides agree between
/// the clouds within `similarity` and the fit brings each within √`squared` of its partner.
fn hypothesis(
    from: &[Point3<f64>],
    to: &[Point3<f64>],
    rng: &mut StdRng,
    squared: f64,
    similarity: f64,
) -> Option<RigidTransform> {
    let n = from.len();
    let a = rng.gen_range(0..n);
    let b = rng.gen_range(0..n);
    let c = rng.gen_range(0..n);
    if a == b || b == c || a == c {
        return None;
    }
    let side = |p: &[Point3<f64>], i: usize, j: usize| (p[i] - p[j]).norm();
    for (i, j) in [(a, b), (b, c), (c, a)] {
        let (s, t) = (side(from, i, j), side(to, i, j));
        if s < similarity * t || t < similarity * s {
            return None;
        }
    }
    let (p, q) = ([from[a], from[b], from[c]], [to[a], to[b], to[c]]);
    let t = kabsch(&p, &q, &[1.0; 3]).ok()?;
    p.iter()
        .zip(&q)
        .all(|(p, q)| (t.apply(p) - q).norm_squared() < squared)
        .then_some(t)
}

/// Both clouds voxel-averaged with one voxel, the finest of a ladder that leaves at most
/// `max_points` in each; `None` for a pair already that small.
fn thinned_pair(
    source: &PointCloud,
    target: &PointCloud,
    max_points: usize,
) -> Option<(PointCloud, PointCloud)> {
    let max_points = max_points.max(8);
    if source.len() <= max_points && target.len() <= max_points {
        return None;
    }
    let (lo, hi) = source.points.iter().chain(&target.points).fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(&p.coords), hi.sup(&p.coords)),
    );
    let extent = (hi - lo).max();
    if !(extent > 0.0) {
        return Some((
            PointCloud::new(vec![source.points[0]]),
            PointCloud::new(vec![target.points[0]]),
        ));
    }
    // A surface of side `extent` fills about (extent / voxel)² cubes: start finer than that and
    // grow the voxel by the square root of how many times too many points are left.
    let mut voxel = extent / (max_points as f64).sqrt() / 1.25;
    loop {
        let (s, t) = rayon::join(
            || source.voxel_downsampled(voxel),
            || target.voxel_downsampled(voxel),
        );
        let most = s.len().max(t.len());
        if most <= max_points {
            return Some((s, t));
        }
        voxel *= (most as f64 / max_points as f64).sqrt().max(1.05);
    }
}

/// RANSAC on FPFH matches ([`register`]).
impl<E: From<GeomError>> Registrar<E> for RansacConfig {
    /// `ransac+icp`: its last step is point-to-plane ICP ([`RansacConfig::refinement`]), so a
    /// composite of it and candidates refined by [`crate::refine`] is named as refined too.
    fn id(&self) -> MethodId {
        MethodId {
            base: NAME,
            refiner: (!self.refinement.spacings.is_empty()).then_some(crate::refine::NAME),
        }
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> std::result::Result<Registration, E> {
        let start = Instant::now();
        let result = register_prepared(source, target, self)?;
        Ok(Registration::single(result, Vec::new(), start))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform_cube;

    fn pose() -> RigidTransform {
        RigidTransform::new(
            crate::euler::rotation_xyz_intrinsic(0.7, -2.1, 2.9),
            Vector3::new(0.4, -1.3, 2.0),
        )
    }

    fn assert_near(found: &RigidTransform, truth: &RigidTransform, degrees: f64, distance: f64) {
        let angle = found.inverse().compose(truth).rotation_angle_deg();
        let shift = (found.translation - truth.translation).norm();
        assert!(angle < degrees && shift < distance, "{angle}° {shift} off");
    }

    /// 60 right matches among 140 wrong ones (70 % outliers): the consensus is the pose, its
    /// inliers exactly the right matches.
    #[test]
    fn consensus_recovers_a_pose_from_mostly_wrong_matches() {
        let mut rng = StdRng::seed_from_u64(3);
        let from = uniform_cube(200, &mut rng);
        let truth = pose();
        let wrong = uniform_cube(140, &mut rng);
        let to: Vec<Point3<f64>> = from
            .iter()
            .enumerate()
            .map(|(c, p)| {
                if c < 60 {
                    truth.apply(p)
                } else {
                    wrong[c - 60]
                }
            })
            .collect();
        let config = RansacConfig {
            draws: 20_000,
            ..RansacConfig::default()
        };
        let found = consensus(&from, &to, 0.01, &config).unwrap();
        assert_near(&found.t_target_source, &truth, 1e-6, 1e-6);
        assert_eq!(found.inliers, (0..60).collect::<Vec<_>>());
    }

    #[test]
    fn the_draws_needed_follow_the_inlier_share() {
        // 0.999 confidence: 6 draws at 90 % inliers, 6,905 at 10 %, none without an inlier.
        assert_eq!(draws_needed(0.9, 0.999).ceil(), 6.0);
        assert_eq!(draws_needed(0.1, 0.999).ceil(), 6905.0);
        assert_eq!(draws_needed(0.0, 0.999), f64::INFINITY);
        assert_eq!(draws_needed(1.0, 0.999), 0.0);
    }

    #[test]
    fn consensus_refuses_too_few_matches() {
        let p = [Point3::origin(), Point3::new(1.0, 0.0, 0.0)];
        let err = consensus(&p, &p, 0.1, &RansacConfig::default()).unwrap_err();
        assert!(
            matches!(err, GeomError::TooFewPoints { got: 2, .. }),
            "{err}"
        );
    }

    /// A dense scene: a floor, two walls, a box on the floor and a slanted board, sampled at
    /// random (the source) and again, moved (the target).
    fn room(n: usize, seed: u64) -> PointCloud {
        let mut rng = StdRng::seed_from_u64(seed);
        let points = (0..n)
            .map(|_| {
                let (u, v): (f64, f64) = (rng.gen(), rng.gen());
                match rng.gen_range(0..5) {
                    0 => Point3::new(4.0 * u, 3.0 * v, 0.0),
                    1 => Point3::new(4.0 * u, 0.0, 2.5 * v),
                    2 => Point3::new(0.0, 3.0 * u, 2.5 * v),
                    3 => Point3::new(1.5 + 0.6 * u, 1.0 + 0.4 * v, 0.5),
                    _ => Point3::new(3.0 + 0.5 * u, 2.0 + 0.8 * v, 0.3 + 0.6 * u),
                }
            })
            .collect();
        PointCloud::new(points)
    }

    /// The scene registered at its own scale and at 1,024 times it: the same pose (the
    /// translation scaled), since every length follows the point spacing. A power of two
    /// scales every coordinate exactly, so the two runs draw and match alike (the refinement's
    /// sums round apart a little).
    #[test]
    fn a_dense_scene_is_registered_at_any_scale() {
        let truth = pose();
        let config = RansacConfig {
            max_points: 1500,
            draws: 10_000,
            ..RansacConfig::default()
        };
        let source = room(6000, 1);
        let target = room(6000, 2).transformed(&truth);
        let found = register(&source, &target, &config).unwrap();
        assert_near(&found.t_target_source, &truth, 0.3, 0.01);
        let scale = |c: &PointCloud| PointCloud::new(c.points.iter().map(|p| p * 1024.0).collect());
        let big = register(&scale(&source), &scale(&target), &config).unwrap();
        let big_truth = RigidTransform::new(truth.rotation, truth.translation * 1024.0);
        assert_near(&big.t_target_source, &big_truth, 0.3, 10.24);
        let angle = big
            .t_target_source
            .inverse()
            .compose(&found.t_target_source)
            .rotation_angle_deg();
        assert!(angle < 1e-3, "{angle}° between the scales");
    }
}
