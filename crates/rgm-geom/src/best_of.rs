//! Several methods on one pair, and the result that scores best by a measure that needs no
//! ground truth: the two-way overlap of the clouds under each method's transform.
//!
//! Methods fail on different pairs (RGM's network is robust to partial overlap but reads
//! rotationally symmetric shapes ambiguously; FGR's features pin those down on full clouds but
//! fail wildly on many partial ones), so the better of two is right more often than either.
//! The score and its distance were chosen on validation pairs (`docs/training/README.md`,
//! session 6: `cargo run --release -p rgm-benches --example default_study`).

use std::time::Instant;

use rayon::prelude::*;

use crate::fgr::Progress;
use crate::registrar::{elapsed_ms, Candidate, DynRegistrar, MethodId, Registrar, Registration};
use crate::registration::{score, RegistrationResult};
use crate::thinning::{thinned, Thinning, DENSITY_POINTS};
use crate::{GeomError, KnnIndex, PointCloud, RigidTransform};

/// Distance (unit-sphere units) within which a moved point counts as overlapping the other
/// cloud in [`overlap_score`].
pub const SCORE_DISTANCE: f64 = 0.02;

/// The least [`overlap_score`] of a credible result: below it, fewer than one point in twenty of
/// each cloud lies on the other after the best transform, and the pair is reported as not
/// registered ([`Registration::doubt`]) rather than with a transform nothing supports.
pub const MIN_OVERLAP: f64 = 0.1;

/// How close the candidates' transforms (unit-sphere frame) on a dense pair's first thinning
/// must be for the next thinning to be skipped: (degrees, distance).
pub const AGREEMENT: (f64, f64) = (1.0, 0.02);

/// Share of the points of each cloud that the transform brings within [`SCORE_DISTANCE`] of
/// the other cloud, source → target plus target → source (0 to 2). Counting both ways rewards
/// an overlap that both clouds agree on, where a one-way fitness is fooled by a small cloud
/// lying anywhere on a large one.
pub fn overlap_score(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
) -> f64 {
    let there = score(&source.0.points, target.1, transform, SCORE_DISTANCE, None);
    let back = score(
        &target.0.points,
        source.1,
        &transform.inverse(),
        SCORE_DISTANCE,
        None,
    );
    there.fitness + back.fitness
}

/// Two transforms within [`AGREEMENT`] of each other: rotations less than its degrees apart,
/// and moving the frame's origin to points less than its distance apart.
pub fn agree(a: &RigidTransform, b: &RigidTransform) -> bool {
    let (degrees, distance) = AGREEMENT;
    a.inverse().compose(b).rotation_angle_deg() < degrees
        && (a.translation - b.translation).norm() < distance
}

/// Every candidate on the pair, the best by [`overlap_score`] returned (ties to the earlier
/// candidate). A pair denser than [`DENSITY_POINTS`] can be thinned many ways, none of them the
/// sampling the methods were tuned on: the candidates run on each of `thinnings` in turn, all
/// scored alike on the clouds as given, until the candidates of one thinning agree ([`agree`]),
/// which leaves nothing for the next to fix. A pair no denser runs once, as it is.
///
/// Lengths are in unit-sphere units: wrap it in [`crate::registrar::Normalised`] for pairs of
/// any size. The result is scored at `scoring_distance`; its correspondences are the source
/// points within that distance of the target.
#[derive(Debug)]
pub struct BestOf<E> {
    /// The name of the composite (`auto`).
    pub base: &'static str,
    pub candidates: Vec<Box<dyn DynRegistrar<E>>>,
    pub thinnings: Vec<Thinning>,
    pub scoring_distance: f64,
}

impl<E: 'static> Clone for BestOf<E> {
    fn clone(&self) -> Self {
        Self {
            base: self.base,
            candidates: self.candidates.clone(),
            thinnings: self.thinnings.clone(),
            scoring_distance: self.scoring_distance,
        }
    }
}

/// A candidate's outcome in the caller's frame of [`BestOf::register`]: its score, transform
/// and iterations.
type Best = (f64, RigidTransform, usize);

impl<E: From<GeomError> + ToString + Send> Registrar<E> for BestOf<E> {
    /// `base`, refined when every candidate is.
    fn id(&self) -> MethodId {
        MethodId {
            base: self.base,
            refined: !self.candidates.is_empty() && self.candidates.iter().all(|c| c.id().refined),
        }
    }

    fn register_with_progress(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let (source_index, target_index) =
            (KnnIndex::new(&source.points), KnnIndex::new(&target.points));
        let dense = source.len().max(target.len()) > DENSITY_POINTS;
        let thinnings = if dense {
            &self.thinnings[..]
        } else {
            &self.thinnings[..1.min(self.thinnings.len())]
        };
        let mut candidates = Vec::new();
        let mut best: Option<Best> = None;
        let mut chosen = None;
        for &how in thinnings {
            let (s, t) = (thinned(source, how), thinned(target, how));
            // The candidates are independent until scored: they run side by side, each on a
            // core of its own when there are cores to spare, and are scored in their order.
            let outcomes: Vec<(Result<Registration, E>, f64)> = self
                .candidates
                .par_iter_mut()
                .map(|candidate| {
                    let start = Instant::now();
                    let outcome = candidate.register(&s, &t);
                    (outcome, elapsed_ms(start))
                })
                .collect();
            let mut found = Vec::with_capacity(outcomes.len()); // this thinning's transforms
            for (candidate, (outcome, time_ms)) in self.candidates.iter().zip(outcomes) {
                let method = format!("{}{}", candidate.id(), how.suffix());
                match outcome {
                    Ok(registration) => {
                        let transform = registration.result.t_target_source;
                        found.push(transform);
                        let value = overlap_score(
                            (source, &source_index),
                            (target, &target_index),
                            &transform,
                        );
                        // Ties go to the earlier candidate, and the earlier thinning.
                        if best.is_none_or(|(b, _, _)| value > b) {
                            best = Some((value, transform, registration.result.iterations));
                            chosen = Some(candidates.len());
                        }
                        candidates.push(Candidate {
                            method,
                            t_target_source: transform,
                            score: Some(value),
                            failure: None,
                            time_ms,
                        });
                    }
                    Err(err) => candidates.push(Candidate {
                        method,
                        t_target_source: RigidTransform::identity(),
                        score: None,
                        failure: Some(err.to_string()),
                        time_ms,
                    }),
                }
            }
            if found.len() > 1 && found[1..].iter().all(|t| agree(&found[0], t)) {
                break;
            }
        }
        let Some((value, transform, iterations)) = best else {
            let why: Vec<String> = candidates
                .iter()
                .map(|c| format!("{}: {}", c.method, c.failure.as_deref().unwrap_or("?")))
                .collect();
            return Err(GeomError::AllCandidatesFailed(why.join("; ")).into());
        };
        let doubt = (value < MIN_OVERLAP).then(|| {
            let method = &candidates[chosen.expect("a best candidate is chosen")].method;
            format!(
                "the best candidate, {method}, overlaps too little (score {value:.3} < {MIN_OVERLAP}): \
                 the clouds may not overlap, or every method failed on them"
            )
        });
        let mut correspondences = Vec::new();
        let scored = score(
            &source.points,
            &target_index,
            &transform,
            self.scoring_distance,
            Some(&mut correspondences),
        );
        Ok(Registration {
            result: RegistrationResult::scored(transform, iterations, true, scored),
            correspondences,
            time_ms: elapsed_ms(start),
            candidates,
            chosen,
            doubt,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Point3, Vector3};

    #[test]
    fn transforms_agree_within_a_degree_and_a_fiftieth() {
        let turn = |deg: f64, shift: f64| {
            RigidTransform::new(
                crate::euler::rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
                Vector3::new(shift, 0.0, 0.0),
            )
        };
        let a = turn(10.0, 0.1);
        assert!(agree(&a, &turn(10.9, 0.1)));
        assert!(agree(&a, &turn(10.0, 0.119)));
        assert!(!agree(&a, &turn(11.1, 0.1)));
        assert!(!agree(&a, &turn(10.0, 0.121)));
    }

    #[test]
    fn overlap_counts_both_ways() {
        // 10 points 0.1 apart on a line, and its first 4 points.
        let line = PointCloud::new(
            (0..10)
                .map(|i| Point3::new(0.1 * i as f64, 0.0, 0.0))
                .collect(),
        );
        let part = PointCloud::new(line.points[..4].to_vec());
        let (li, pi) = (KnnIndex::new(&line.points), KnnIndex::new(&part.points));
        let identity = RigidTransform::identity();
        assert_eq!(overlap_score((&line, &li), (&line, &li), &identity), 2.0);
        // The part lies on the line (1.0), which it covers for 4 of 10 points (0.4).
        assert!((overlap_score((&part, &pi), (&line, &li), &identity) - 1.4).abs() < 1e-12);
        // Shifted by 0.05 every point is 0.05 from the other cloud: beyond 0.02.
        let shifted = RigidTransform::new(crate::Matrix3::identity(), Vector3::new(0.0, 0.05, 0.0));
        assert_eq!(overlap_score((&line, &li), (&line, &li), &shifted), 0.0);
    }
}
