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

/// When `rgm register`'s default takes its cheap candidate (FGR) without running the network
/// ([`BestOf::accept`]): the cheapest on validation pairs that kept the recall and the share off
/// by more than 45° of running both within 0.1 points
/// (`docs/training/default-study/cascade-1980-validation.md`).
pub const ACCEPT: Acceptance = Acceptance {
    score: 0.55,
    turned_share: 0.3,
    whole: (WHOLE_DISTANCE, WHOLE_OVERLAP),
};

/// The distance (unit-sphere units) of [`ACCEPT`]'s whole overlap: the bound of the benchmark's
/// jitter (σ = 0.01 per coordinate, clipped at 0.05), within which a noisy cloud's points still
/// lie on the other cloud.
pub const WHOLE_DISTANCE: f64 = 0.05;

/// The least overlap at [`WHOLE_DISTANCE`] (0 to 2) that [`ACCEPT`] takes as whole: the least
/// that changes no partial validation pair's course, far above any wrong result's
/// (`docs/training/default-study/cascade-whole-overlap.md`).
pub const WHOLE_OVERLAP: f64 = 1.98;

/// When a cascade's result is good enough to end it ([`BestOf::accept`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Acceptance {
    /// The least [`overlap_score`] taken.
    pub score: f64,
    /// The largest [`turned_share`] taken: above it the shape overlaps itself turned about an
    /// axis (a lamp, a box), the overlap cannot tell its pose, and the later candidates run.
    pub turned_share: f64,
    /// (distance, least overlap): a result whose [`overlap_score_at`] that distance reaches the
    /// overlap is taken whatever its turned share. Clouds that lie wholly on each other (full
    /// scans of one object) leave a turned pose nothing to fit better, while noise, which
    /// lowers the overlap at [`SCORE_DISTANCE`] far more than at a looser distance, would
    /// otherwise make a right result look as doubtful as a symmetric shape's.
    pub whole: (f64, f64),
}

impl Acceptance {
    /// Nothing is good enough: every candidate runs.
    pub const NEVER: Self = Self {
        score: f64::INFINITY,
        turned_share: 0.0,
        whole: (SCORE_DISTANCE, f64::INFINITY),
    };

    /// Whether `transform`, which scores `score` on the pair, ends the cascade; its
    /// [`turned_share`] is measured on `source` and `target` with their trees, the pair as the
    /// candidates saw it (at most a few thousand points, whatever the pair's density).
    pub fn takes(
        &self,
        score: f64,
        source: (&PointCloud, &KnnIndex),
        target: (&PointCloud, &KnnIndex),
        transform: &RigidTransform,
    ) -> bool {
        let (distance, whole) = self.whole;
        score >= self.score
            && (overlap_score_at(source, target, transform, distance) >= whole
                || turned_share(source, target, transform) <= self.turned_share)
    }
}

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
    overlap_score_at(source, target, transform, SCORE_DISTANCE)
}

/// [`overlap_score`] with points counted within `distance` instead of [`SCORE_DISTANCE`].
pub fn overlap_score_at(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
    distance: f64,
) -> f64 {
    let there = score(&source.0.points, target.1, transform, distance, None);
    let back = score(
        &target.0.points,
        source.1,
        &transform.inverse(),
        distance,
        None,
    );
    there.fitness + back.fitness
}

/// How little `transform`'s overlap tells the shape's pose: the best [`overlap_score`] of the
/// source first turned by a quarter, a half or three quarters about one of its principal axes
/// (through its centroid), as a share of `transform`'s own. Near 1 or above, a pose turned
/// about that axis fits as well, as for a symmetric shape.
pub fn turned_share(
    source: (&PointCloud, &KnnIndex),
    target: (&PointCloud, &KnnIndex),
    transform: &RigidTransform,
) -> f64 {
    let score = overlap_score(source, target, transform);
    if source.0.len() < 3 || score <= 0.0 {
        return f64::INFINITY;
    }
    let centre = source.0.centroid();
    let mut covariance = crate::Matrix3::zeros();
    for p in &source.0.points {
        let d = p - centre;
        covariance += d * d.transpose();
    }
    let axes = covariance.symmetric_eigen().eigenvectors; // (3, 3), one axis a column
    let mut best: f64 = 0.0;
    for axis in axes.column_iter() {
        let axis = nalgebra::Unit::new_normalize(axis.into_owned());
        for quarters in 1..4 {
            let turn = nalgebra::Rotation3::from_axis_angle(
                &axis,
                quarters as f64 * std::f64::consts::FRAC_PI_2,
            )
            .into_inner();
            // About the centroid: p ↦ c + R (p − c).
            let about = RigidTransform::new(turn, centre.coords - turn * centre.coords);
            best = best.max(overlap_score(source, target, &transform.compose(&about)));
        }
    }
    best / score
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
/// With an [`Acceptance`] of a finite score it is a cascade: the first candidate runs alone, and
/// the others only when its result is not taken.
///
/// Lengths are in unit-sphere units: wrap it in [`crate::registrar::Normalised`] for pairs of
/// any size. The result is scored at `scoring_distance`; its correspondences are the source
/// points within that distance of the target.
#[derive(Debug)]
pub struct BestOf<E> {
    /// The name of the composite (`auto`).
    pub base: &'static str,
    /// In the order they run and win ties: the cheap one first in a cascade.
    pub candidates: Vec<Box<dyn DynRegistrar<E>>>,
    pub thinnings: Vec<Thinning>,
    pub scoring_distance: f64,
    /// When a result is taken as it is, and nothing after it runs; [`Acceptance::NEVER`] runs
    /// every candidate, side by side.
    pub accept: Acceptance,
}

impl<E: 'static> Clone for BestOf<E> {
    fn clone(&self) -> Self {
        Self {
            base: self.base,
            candidates: self.candidates.clone(),
            thinnings: self.thinnings.clone(),
            scoring_distance: self.scoring_distance,
            accept: self.accept,
        }
    }
}

/// A candidate's outcome in the caller's frame of [`BestOf::register`]: its score, transform
/// and iterations.
type Best = (f64, RigidTransform, usize);

impl<E: From<GeomError> + ToString + Send> Registrar<E> for BestOf<E> {
    /// `base`, refined as every candidate is when they are all refined alike.
    fn id(&self) -> MethodId {
        let mut refiners = self.candidates.iter().map(|c| c.id().refiner);
        let first = refiners.next().flatten();
        MethodId {
            base: self.base,
            refiner: first.filter(|_| refiners.all(|r| r == first)),
        }
    }

    fn register_with_progress(
        &mut self,
        source: &PointCloud,
        target: &PointCloud,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let (source_index, target_index) = rayon::join(
            || KnnIndex::new(&source.points),
            || KnnIndex::new(&target.points),
        );
        let dense = source.len().max(target.len()) > DENSITY_POINTS;
        let thinnings = if dense {
            &self.thinnings[..]
        } else {
            &self.thinnings[..1.min(self.thinnings.len())]
        };
        // The candidates that run together: all of them, or in a cascade the first alone and
        // then the rest.
        let n = self.candidates.len();
        let split = if self.accept.score.is_finite() {
            n.min(1)
        } else {
            n
        };
        let mut candidates = Vec::new();
        let mut best: Option<Best> = None;
        let mut chosen = None;
        'thinnings: for &how in thinnings {
            let (s, t) = rayon::join(|| thinned(source, how), || thinned(target, how));
            // The thinned pair's trees, built once a dense pair's result is worth testing; a
            // pair that is not thinned has its own already.
            let thinned_trees = std::cell::OnceCell::new();
            let mut found = Vec::with_capacity(n); // this thinning's transforms
            for wave in [0..split, split..n] {
                if wave.is_empty() {
                    continue;
                }
                // The candidates of a wave are independent until scored: they run side by
                // side, each on a core of its own when there are cores to spare, and are
                // scored in their order.
                let outcomes: Vec<(Result<Registration, E>, f64)> = self.candidates[wave.clone()]
                    .par_iter_mut()
                    .map(|candidate| {
                        let start = Instant::now();
                        let outcome = candidate.register(&s, &t);
                        (outcome, elapsed_ms(start))
                    })
                    .collect();
                for (candidate, (outcome, time_ms)) in self.candidates[wave].iter().zip(outcomes) {
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
                let taken = best.is_some_and(|(b, found, _)| {
                    b >= self.accept.score && {
                        let (si, ti) = if dense {
                            let (si, ti) = thinned_trees.get_or_init(|| {
                                (KnnIndex::new(&s.points), KnnIndex::new(&t.points))
                            });
                            (si, ti)
                        } else {
                            (&source_index, &target_index)
                        };
                        self.accept.takes(b, (&s, si), (&t, ti), &found)
                    }
                });
                if taken {
                    break 'thinnings;
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

    /// A method that answers every pair with one transform, and counts its calls.
    #[derive(Clone)]
    struct Fixed {
        name: &'static str,
        transform: RigidTransform,
        calls: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    }

    impl Fixed {
        fn new(name: &'static str, shift: f64) -> Self {
            Self {
                name,
                transform: RigidTransform::new(
                    crate::Matrix3::identity(),
                    Vector3::new(shift, 0.0, 0.0),
                ),
                calls: Default::default(),
            }
        }

        fn calls(&self) -> usize {
            self.calls.load(std::sync::atomic::Ordering::SeqCst)
        }
    }

    impl Registrar<GeomError> for Fixed {
        fn id(&self) -> MethodId {
            MethodId::plain(self.name)
        }

        fn register_with_progress(
            &mut self,
            _: &PointCloud,
            _: &PointCloud,
            _: &mut dyn FnMut(Progress),
        ) -> Result<Registration, GeomError> {
            self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            let result = RegistrationResult {
                t_target_source: self.transform,
                iterations: 0,
                converged: true,
                inlier_count: 0,
                fitness: 0.0,
                inlier_rmse: 0.0,
            };
            Ok(Registration::single(result, Vec::new(), Instant::now()))
        }
    }

    #[test]
    fn a_cascade_runs_the_rest_only_below_its_threshold() {
        // 10 points 0.1 apart on a line, registered onto themselves: the identity overlaps
        // fully (score 2), a shift of 0.05 not at all (score 0).
        let line = PointCloud::new(
            (0..10)
                .map(|i| Point3::new(0.1 * i as f64, 0.0, 0.0))
                .collect(),
        );
        let run = |first: &Fixed, second: &Fixed, accept: Acceptance| {
            let mut best_of = BestOf::<GeomError> {
                base: "both",
                candidates: vec![Box::new(first.clone()), Box::new(second.clone())],
                thinnings: vec![Thinning::Voxels],
                scoring_distance: SCORE_DISTANCE,
                accept,
            };
            best_of.register(&line, &line).unwrap()
        };
        let at = |score: f64| Acceptance {
            score,
            turned_share: f64::INFINITY,
            whole: (SCORE_DISTANCE, f64::INFINITY),
        };
        // A first result at the threshold is taken; the second never runs.
        let (right, wrong) = (Fixed::new("right", 0.0), Fixed::new("wrong", 0.05));
        let found = run(&right, &wrong, at(2.0));
        assert_eq!((found.candidates.len(), found.chosen), (1, Some(0)));
        assert_eq!(found.candidates[0].score, Some(2.0));
        assert_eq!((right.calls(), wrong.calls()), (1, 0));
        // Below it the second runs, and the better wins.
        let found = run(&wrong, &right, at(0.6));
        let names: Vec<&str> = found.candidates.iter().map(|c| c.method.as_str()).collect();
        assert_eq!((names, found.chosen), (vec!["wrong", "right"], Some(1)));
        assert_eq!(found.result.t_target_source, right.transform);
        // Never accepting runs both, however well the first does.
        let found = run(&right, &wrong, Acceptance::NEVER);
        assert_eq!((found.candidates.len(), found.chosen), (2, Some(0)));
        assert_eq!((right.calls(), wrong.calls()), (3, 2));
        // A line turned by half a turn about an axis across it is the same line: its pose is
        // not told by the overlap, and a cascade that asks for a low turned share goes on.
        let symmetric = |whole: f64| Acceptance {
            score: 2.0,
            turned_share: 0.5,
            whole: (SCORE_DISTANCE, whole),
        };
        let found = run(&right, &wrong, symmetric(f64::INFINITY));
        assert_eq!((found.candidates.len(), found.chosen), (2, Some(0)));
        // Unless the result overlaps wholly: then no turn can fit better, and it is taken.
        let found = run(&right, &wrong, symmetric(2.0));
        assert_eq!((found.candidates.len(), found.chosen), (1, Some(0)));
        // A result 0.03 off along the line, as noise leaves one, overlaps not at all at the
        // score's distance and wholly at 0.04: taken by a whole overlap measured there alone.
        let near = Fixed::new("near", 0.03);
        let whole_at = |distance: f64| Acceptance {
            score: 0.0,
            turned_share: 0.0,
            whole: (distance, 1.95),
        };
        let found = run(&near, &wrong, whole_at(0.04));
        assert_eq!((found.candidates.len(), found.chosen), (1, Some(0)));
        let found = run(&near, &wrong, whole_at(SCORE_DISTANCE));
        assert_eq!(found.candidates.len(), 2);
    }

    #[test]
    fn a_symmetric_shape_overlaps_itself_turned_and_an_irregular_one_does_not() {
        let share = |points: Vec<Point3<f64>>| {
            let cloud = PointCloud::new(points);
            let index = KnnIndex::new(&cloud.points);
            turned_share(
                (&cloud, &index),
                (&cloud, &index),
                &RigidTransform::identity(),
            )
        };
        // A box's corners: half a turn about any of its axes maps the box onto itself.
        let mut corners = Vec::new();
        for x in [-0.5, 0.5] {
            for y in [-0.3, 0.3] {
                for z in [-0.2, 0.2] {
                    corners.push(Point3::new(x, y, z));
                }
            }
        }
        assert!((share(corners) - 1.0).abs() < 1e-12);
        // Three arms of different lengths along the axes: no turn fits a point.
        let arms: Vec<Point3<f64>> = (1..=10)
            .flat_map(|i| {
                let d = 0.05 * i as f64;
                [
                    Point3::new(d, 0.0, 0.0),
                    Point3::new(0.0, 0.5 * d, 0.0),
                    Point3::new(0.0, 0.0, 0.25 * d),
                ]
            })
            .collect();
        assert!(share(arms) < 0.2);
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
