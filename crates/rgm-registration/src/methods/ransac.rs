//! RANSAC on FPFH correspondences, for scene-scale pairs (rooms, streets): the global step of
//! Open3D's `registration_ransac_based_on_feature_matching` tutorial pipeline, with every length
//! a multiple of the pair's own point spacing.
//!
//! 1–3. The pair thinned, its FPFH features and their matches ([`crate::methods::feature_matches`]).
//! 4. Hypotheses: three matches drawn at random; kept only when each side of their triangle
//!    agrees between the clouds within [`RansacConfig::edge_similarity`] (the correspondence
//!    check, which rejects most wrong draws before any fit) and the Kabsch fit of the three
//!    brings each within the inlier distance of its partner (the distance check); then scored
//!    by the matches it brings within that distance. Draws run in fixed chunks, each from its
//!    own seeded generator, so the result is the same on any number of threads.
//! 5. Each chunk's best judged by [`Matched::fitness`]; the best of them refitted on its
//!    inliers (Kabsch) until they stop changing, then refined ([`crate::methods::feature_matches`]).
//!
//! FGR's graduated non-convexity follows the bulk of the matches; on a room most matches are
//! wrong (floors and walls look alike everywhere) and the bulk can lie at a wrong pose, where a
//! consensus count still finds the few right ones.

use nalgebra::Point3;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rayon::prelude::*;
use rgm_geom::{kabsch, GeomError, PointCloud, Result, RigidTransform};

use crate::fit::Fit;
use crate::methods::feature_matches::{
    inliers_of, refitted, register_matched, Matched, MatchingConfig,
};
use crate::registrar::{MethodId, Progress, Registrar, Registration};
use crate::Prepared;

pub use crate::methods::feature_matches::Consensus;

/// The method's name ([`crate::registrar::MethodId`]).
pub const NAME: &str = "ransac";

/// Draws per chunk: a chunk's draws come from one generator seeded by the chunk's index.
const CHUNK: usize = 1024;

/// Chunks run side by side before the draws made so far are weighed against
/// [`RansacConfig::confidence`]: a fixed wave, so that where the draws stop does not depend on
/// the threads.
const WAVE: usize = 8;

/// Settings of [`register`]: the matching's ([`MatchingConfig`]) and the draws'. The defaults
/// are Open3D's tutorial settings (edges within 0.9, 100,000 draws, confidence 0.999).
#[derive(Clone, Debug, PartialEq)]
pub struct RansacConfig {
    pub matching: MatchingConfig,
    /// The least ratio of a drawn triangle's side in one cloud to the same side in the other
    /// (default 0.9).
    pub edge_similarity: f64,
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
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self {
            matching: MatchingConfig::default(),
            edge_similarity: 0.9,
            draws: 100_000,
            confidence: 0.999,
            refits: 5,
            seed: 0,
        }
    }
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
    if !(config.edge_similarity > 0.0 && config.edge_similarity <= 1.0) {
        return Err(GeomError::Degenerate {
            op: OP,
            why: format!(
                "edge_similarity must be in (0, 1], got {}",
                config.edge_similarity
            ),
        });
    }
    register_matched(OP, source, target, &config.matching, |matched: &Matched| {
        let squared = matched.distance * matched.distance;
        let (winners, hypotheses) = chunk_winners(&matched.from, &matched.to, squared, config);
        let fitness: Vec<f64> = winners
            .par_iter()
            .map(|(_, t)| matched.fitness(t))
            .collect();
        let best = (0..winners.len()).fold(None, |best: Option<usize>, w| match best {
            Some(b) if fitness[b] >= fitness[w] => best,
            _ => Some(w),
        });
        let Some(best) = best else {
            return Err(no_hypothesis(OP, matched.from.len()));
        };
        Ok(refitted(
            &matched.from,
            &matched.to,
            winners[best].1,
            squared,
            config.refits,
            hypotheses,
        ))
    })
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

/// RANSAC on FPFH matches ([`register`]).
impl<E: From<GeomError>> Registrar<E> for RansacConfig {
    /// `ransac+refine`: its last step is point-to-plane ICP ([`MatchingConfig::refinement`]), so a
    /// composite of it and candidates refined by [`crate::methods::refine`] is named as refined too.
    fn id(&self) -> MethodId {
        self.matching.method_id(NAME)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> std::result::Result<Registration, E> {
        MatchingConfig::registration(|| register_prepared(source, target, self))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::far_pose as pose;
    use rgm_geom::testing::uniform_cube;

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

    /// A room registered at its own scale and at 1,024 times it
    /// ([`crate::testing::assert_registers_a_room_at_any_scale`]).
    #[test]
    fn a_dense_scene_is_registered_at_any_scale() {
        let config = RansacConfig {
            matching: MatchingConfig {
                max_points: 1500,
                ..MatchingConfig::default()
            },
            draws: 10_000,
            ..RansacConfig::default()
        };
        crate::testing::assert_registers_a_room_at_any_scale(|s, t| {
            register(s, t, &config).unwrap()
        });
    }
}
