//! Several methods on one pair, and the result that scores best by a measure that needs no
//! ground truth: the two-way overlap of the clouds under each method's transform.
//!
//! Methods fail on different pairs (RGM's network is robust to partial overlap but reads
//! rotationally symmetric shapes ambiguously; FGR's features pin those down on full clouds but
//! fail wildly on many partial ones), so the better of two is right more often than either.
//! The composites here run candidate methods and judge them so: [`BestOf`] side by side,
//! [`Cascade`] the cheap one first and the rest only when its result is in doubt
//! ([`crate::check::Acceptance`]); [`crate::compose::Thinned`] runs either on several thinnings of a dense
//! pair. How they score ([`crate::check::Scoring`]) is the caller's configuration.

use std::time::Instant;

use rayon::prelude::*;
use rgm_geom::{GeomError, RigidTransform};

use crate::check::{Acceptance, Judge, Scoring};
use crate::error::AllCandidatesFailed;
use crate::fit::Fit;
use crate::registrar::{
    elapsed_ms, Candidate, DynRegistrar, MethodId, Progress, Registrar, Registration,
};
use crate::Prepared;
/// What a composite's candidates found on one pair, judged by a [`Judge`].
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// Every candidate that ran, in order, each with its score on the judged pair.
    pub candidates: Vec<Candidate>,
    /// The best candidate's index in `candidates` and its iterations, when one beat the
    /// judge's `before` (ties go to the earlier).
    pub best: Option<(usize, usize)>,
    /// Whether an acceptance took the best result: nothing after it needs to run.
    pub settled: bool,
}
/// A method made of candidate methods that runs them on the clouds it is given and judges their
/// results with a [`Judge`], which may hold other clouds: the thinning around it
/// ([`crate::compose::Thinned`]) judges on the pair as given.
pub trait Composite<E>: Registrar<E> {
    /// The candidates run on `source` and `target`, judged by `judge`.
    fn run_judged(&mut self, source: &Prepared, target: &Prepared, judge: &Judge) -> Outcome;

    /// How its candidates are judged.
    fn scoring(&self) -> Scoring;
}

/// A result that wins: its score, transform, iterations, and its index among the candidates
/// (`None` when it came before them).
struct Winner {
    score: f64,
    /// Whether it passes the judge's [`Scoring::coincides`].
    coincides: bool,
    transform: RigidTransform,
    iterations: usize,
    index: Option<usize>,
}

/// The candidates of one composite's run so far and the best result.
struct Tally {
    candidates: Vec<Candidate>,
    best: Option<Winner>,
}

impl Tally {
    fn new(judge: &Judge) -> Self {
        Self {
            candidates: Vec::new(),
            best: judge.before.map(|(score, transform)| Winner {
                score,
                coincides: judge.coincides(&transform),
                transform,
                iterations: 0,
                index: None,
            }),
        }
    }

    /// `wave` run side by side on `source` and `target`, each on a core of its own when there
    /// are cores to spare, then scored in their order.
    fn run<E: ToString + Send>(
        &mut self,
        wave: &mut [Box<dyn DynRegistrar<E>>],
        source: &Prepared,
        target: &Prepared,
        judge: &Judge,
    ) {
        let outcomes: Vec<(Result<Registration, E>, f64)> = wave
            .par_iter_mut()
            .map(|candidate| {
                let start = Instant::now();
                let outcome = candidate.register_unscored(source, target, &mut |_| {});
                (outcome, elapsed_ms(start))
            })
            .collect();
        for (candidate, (outcome, time_ms)) in wave.iter().zip(outcomes) {
            let method = candidate.id().to_string();
            match outcome {
                Ok(registration) => {
                    let transform = registration.result.t_target_source;
                    let score = judge.score(&transform);
                    let coincides = judge.coincides(&transform);
                    // A result that coincides beats one that does not; ties go to the earlier
                    // candidate.
                    let beats = |b: &Winner| {
                        (coincides && !b.coincides) || (coincides == b.coincides && score > b.score)
                    };
                    if self.best.as_ref().is_none_or(beats) {
                        self.best = Some(Winner {
                            score,
                            coincides,
                            transform,
                            iterations: registration.result.iterations,
                            index: Some(self.candidates.len()),
                        });
                    }
                    self.candidates.push(Candidate {
                        method,
                        t_target_source: transform,
                        score: Some(score),
                        failure: None,
                        time_ms,
                    });
                }
                Err(err) => self.candidates.push(Candidate {
                    method,
                    t_target_source: RigidTransform::identity(),
                    score: None,
                    failure: Some(err.to_string()),
                    time_ms,
                }),
            }
        }
    }

    fn outcome(self, settled: bool) -> Outcome {
        let best = self
            .best
            .and_then(|b| b.index.map(|index| (index, b.iterations)));
        Outcome {
            candidates: self.candidates,
            best,
            settled,
        }
    }
}

impl Judge<'_> {
    /// Whether `accept` takes the best of `tally` (or of what came before), its turned share
    /// measured on the clouds the candidates ran on (`source`, `target`).
    fn takes(
        &self,
        accept: &Acceptance,
        tally: &Tally,
        source: &Prepared,
        target: &Prepared,
    ) -> bool {
        tally.best.as_ref().is_some_and(|best| {
            best.coincides && {
                let distance = self.scoring.overlap_distance;
                accept.takes(best.score, source, target, &best.transform, distance)
            }
        })
    }
}

/// A composite's id: `base`, refined as every candidate is when they are all refined alike.
fn composite_id<'c, E: 'c>(
    base: &'static str,
    candidates: impl IntoIterator<Item = &'c Box<dyn DynRegistrar<E>>>,
) -> MethodId {
    let mut refiners = candidates.into_iter().map(|c| c.id().refiner);
    let first = refiners.next().flatten();
    MethodId {
        base,
        refiner: first.filter(|_| refiners.all(|r| r == first)),
    }
}

/// The registration of a composite's `outcome` on the judged pair, unscored
/// ([`Registrar::register_unscored`]; [`Registration::fitted_within`] scores it at the judge's
/// [`Scoring::result_distance`]): the best candidate (`best`: its index among `candidates`);
/// doubted when it overlaps less than [`Scoring::min_overlap`], unless an acceptance took it
/// (`settled`: it overlapped enough where the acceptance measures, which on a pair sparser than
/// the overlap distance is a looser distance, [`Acceptance::coincides`]); an error when every
/// candidate failed.
pub fn conclude<E: From<AllCandidatesFailed>>(
    judge: &Judge,
    candidates: Vec<Candidate>,
    best: Option<(usize, usize)>,
    settled: bool,
    start: Instant,
) -> Result<Registration, E> {
    let min_overlap = judge.scoring.min_overlap;
    let Some((chosen, iterations)) = best else {
        let why: Vec<String> = candidates
            .iter()
            .map(|c| format!("{}: {}", c.method, c.failure.as_deref().unwrap_or("?")))
            .collect();
        return Err(AllCandidatesFailed(why.join("; ")).into());
    };
    let winner = &candidates[chosen];
    let (transform, value) = (winner.t_target_source, winner.score.unwrap_or(0.0));
    let doubt = (!settled && value < min_overlap).then(|| {
        let method = &winner.method;
        // As many decimals as show the score below the bound (0.0996 is not "0.100 < 0.1").
        let shown = (3..17)
            .map(|digits| format!("{value:.digits$}"))
            .find(|text| text.parse::<f64>().is_ok_and(|v| v < min_overlap))
            .unwrap_or_else(|| value.to_string());
        format!(
            "the best candidate, {method}, overlaps too little (score {shown} < {min_overlap}): \
             the clouds may not overlap, or every method failed on them"
        )
    });
    Ok(Registration {
        result: Fit::unscored(transform, iterations, true),
        correspondences: Vec::new(),
        time_ms: elapsed_ms(start),
        candidates,
        chosen: Some(chosen),
        doubt,
    })
}

/// `composite` on the pair as given, judged there, unscored.
fn register_composite<E: From<GeomError> + From<AllCandidatesFailed>>(
    composite: &mut impl Composite<E>,
    source: &Prepared,
    target: &Prepared,
) -> Result<Registration, E> {
    let start = Instant::now();
    let judge = Judge::new(source, target, composite.scoring());
    let outcome = composite.run_judged(source, target, &judge);
    conclude(
        &judge,
        outcome.candidates,
        outcome.best,
        outcome.settled,
        start,
    )
}

/// `composite` on the pair as given, judged there, its fit scored at its
/// [`Scoring::result_distance`] (a composite's [`Registrar::register_prepared`]).
fn register_scored<E: From<GeomError> + From<AllCandidatesFailed>>(
    composite: &mut impl Composite<E>,
    source: &Prepared,
    target: &Prepared,
) -> Result<Registration, E> {
    let distance = composite.scoring().result_distance;
    let found = composite.register_unscored(source, target, &mut |_| {})?;
    Ok(found.fitted_within(source, target, distance))
}

/// Every candidate on the pair, side by side, the best by [`crate::check::overlap_score`] returned (ties to
/// the earlier candidate), judged by `scoring`: wrap it in [`crate::compose::Normalised`] for
/// pairs of any size when its lengths are set for unit-sphere shapes. Its correspondences are
/// the source points within [`Scoring::result_distance`] of the target.
#[derive(Debug)]
pub struct BestOf<E> {
    /// The name of the composite (`auto`).
    pub base: &'static str,
    /// In the order they win ties.
    pub candidates: Vec<Box<dyn DynRegistrar<E>>>,
    pub scoring: Scoring,
}

impl<E: 'static> Clone for BestOf<E> {
    fn clone(&self) -> Self {
        Self {
            base: self.base,
            candidates: self.candidates.clone(),
            scoring: self.scoring,
        }
    }
}

impl<E: From<GeomError> + From<AllCandidatesFailed> + ToString + Send> Composite<E> for BestOf<E> {
    fn run_judged(&mut self, source: &Prepared, target: &Prepared, judge: &Judge) -> Outcome {
        let mut tally = Tally::new(judge);
        tally.run(&mut self.candidates, source, target, judge);
        tally.outcome(false)
    }

    fn scoring(&self) -> Scoring {
        self.scoring
    }
}

impl<E: From<GeomError> + From<AllCandidatesFailed> + ToString + Send> Registrar<E> for BestOf<E> {
    /// `base`, refined as every candidate is when they are all refined alike.
    fn id(&self) -> MethodId {
        composite_id(self.base, &self.candidates)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        register_scored(self, source, target)
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        register_composite(self, source, target)
    }
}

/// `first` alone, and `rest` (side by side) only when `accept` does not take the best result
/// so far; the best of all that ran by [`crate::check::overlap_score`] returned, as [`BestOf`] returns it.
/// The cheap method goes first: the others cost their time only on the pairs it leaves in
/// doubt.
#[derive(Debug)]
pub struct Cascade<E> {
    /// The name of the composite (`auto`).
    pub base: &'static str,
    pub first: Box<dyn DynRegistrar<E>>,
    pub rest: Vec<Box<dyn DynRegistrar<E>>>,
    /// When a result is taken as it is, and nothing after it runs.
    pub accept: Acceptance,
    pub scoring: Scoring,
}

impl<E: 'static> Clone for Cascade<E> {
    fn clone(&self) -> Self {
        Self {
            base: self.base,
            first: self.first.clone(),
            rest: self.rest.clone(),
            accept: self.accept,
            scoring: self.scoring,
        }
    }
}

impl<E: From<GeomError> + From<AllCandidatesFailed> + ToString + Send> Composite<E> for Cascade<E> {
    fn run_judged(&mut self, source: &Prepared, target: &Prepared, judge: &Judge) -> Outcome {
        let mut tally = Tally::new(judge);
        tally.run(std::slice::from_mut(&mut self.first), source, target, judge);
        let mut settled = judge.takes(&self.accept, &tally, source, target);
        if !settled && !self.rest.is_empty() {
            tally.run(&mut self.rest, source, target, judge);
            settled = judge.takes(&self.accept, &tally, source, target);
        }
        tally.outcome(settled)
    }

    fn scoring(&self) -> Scoring {
        self.scoring
    }
}

impl<E: From<GeomError> + From<AllCandidatesFailed> + ToString + Send> Registrar<E> for Cascade<E> {
    /// `base`, refined as every stage is when they are all refined alike.
    fn id(&self) -> MethodId {
        composite_id(self.base, std::iter::once(&self.first).chain(&self.rest))
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        register_scored(self, source, target)
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        register_composite(self, source, target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{agree, overlap_score, turned_share};
    use crate::testing::{Fixed, SCORING};
    use crate::RegistrationError;
    use rgm_geom::{KnnIndex, Matrix3, Point3, PointCloud, Vector3};

    #[test]
    fn transforms_agree_within_a_degree_and_a_fiftieth() {
        let turn = |deg: f64, shift: f64| {
            RigidTransform::new(
                rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
                Vector3::new(shift, 0.0, 0.0),
            )
        };
        let a = turn(10.0, 0.1);
        assert!(agree(&a, &turn(10.9, 0.1), (1.0, 0.02)));
        assert!(agree(&a, &turn(10.0, 0.119), (1.0, 0.02)));
        assert!(!agree(&a, &turn(11.1, 0.1), (1.0, 0.02)));
        assert!(!agree(&a, &turn(10.0, 0.121), (1.0, 0.02)));
    }

    #[test]
    fn best_of_runs_every_candidate_and_the_best_wins() {
        let line = PointCloud::new(
            (0..10)
                .map(|i| Point3::new(0.1 * i as f64, 0.0, 0.0))
                .collect(),
        );
        let (wrong, right, also) = (
            Fixed::new("wrong", 0.05),
            Fixed::new("right", 0.0),
            Fixed::new("also", 0.0),
        );
        let mut best_of = BestOf::<RegistrationError> {
            base: "all",
            candidates: vec![
                Box::new(wrong.clone()),
                Box::new(right.clone()),
                Box::new(also.clone()),
            ],
            scoring: SCORING,
        };
        let found = best_of.register(&line, &line).unwrap();
        let scores: Vec<Option<f64>> = found.candidates.iter().map(|c| c.score).collect();
        assert_eq!(scores, [Some(0.0), Some(2.0), Some(2.0)]);
        // The tie goes to the earlier of the two right ones.
        assert_eq!(found.chosen, Some(1));
        assert_eq!(found.result.inlier_count, 10);
        assert_eq!(found.correspondences.len(), 10);
        assert_eq!((wrong.calls(), right.calls(), also.calls()), (1, 1, 1));
        // The candidates ran unscored: only the winner's fit is scored, by the composite.
        assert_eq!(right.scored_calls(), 0);
        // Unscored, the same choice without its fit.
        let (s, t) = (Prepared::new(&line), Prepared::new(&line));
        let unscored =
            Registrar::<RegistrationError>::register_unscored(&mut best_of, &s, &t, &mut |_| {})
                .unwrap();
        assert_eq!(unscored.chosen, Some(1));
        assert_eq!(
            unscored.result.t_target_source,
            found.result.t_target_source
        );
        assert_eq!(unscored.result.inlier_count, 0);
        assert!(unscored.correspondences.is_empty());
        assert!(found.doubt.is_none());
        // Only the wrong one: a result that overlaps nothing is doubted, not dropped.
        best_of.candidates.truncate(1);
        let found = best_of.register(&line, &line).unwrap();
        assert_eq!(found.chosen, Some(0));
        assert!(found
            .doubt
            .unwrap()
            .starts_with("the best candidate, wrong, overlaps too little"));
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
            let mut cascade = Cascade::<RegistrationError> {
                base: "both",
                first: Box::new(first.clone()),
                rest: vec![Box::new(second.clone())],
                accept,
                scoring: SCORING,
            };
            cascade.register(&line, &line).unwrap()
        };
        let at = |score: f64| Acceptance {
            score,
            turned_share: f64::INFINITY,
            whole: (SCORING.overlap_distance, f64::INFINITY),
            coincides: None,
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
            whole: (SCORING.overlap_distance, whole),
            coincides: None,
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
            coincides: None,
        };
        let found = run(&near, &wrong, whole_at(0.04));
        assert_eq!((found.candidates.len(), found.chosen), (1, Some(0)));
        let found = run(&near, &wrong, whole_at(SCORING.overlap_distance));
        assert_eq!(found.candidates.len(), 2);
    }

    #[test]
    fn a_result_an_acceptance_took_is_not_doubted_for_its_overlap() {
        let cloud = PointCloud::new(vec![Point3::origin(); 4]);
        let prepared = Prepared::new(&cloud);
        let judge = Judge::new(&prepared, &prepared, SCORING);
        let candidate = Candidate {
            method: "sparse".into(),
            t_target_source: RigidTransform::identity(),
            score: Some(0.05),
            failure: None,
            time_ms: 0.0,
        };
        let conclude = |settled| {
            conclude::<RegistrationError>(
                &judge,
                vec![candidate.clone()],
                Some((0, 0)),
                settled,
                Instant::now(),
            )
            .unwrap()
        };
        // Below the least overlap (0.1) at the judge's distance: doubted, unless an acceptance
        // (which may measure at a looser distance on a sparse pair) took it.
        assert!(conclude(false)
            .doubt
            .unwrap()
            .contains("overlaps too little"));
        assert_eq!(conclude(true).doubt, None);
    }

    #[test]
    fn a_result_that_coincides_beats_one_that_only_lies_near_and_is_not_accepted() {
        // Issue 44, D1: 201 points 0.01 apart on a line. Lifted 0.015 off it, the line lies
        // within the overlap distance everywhere (score 2) but coincides nowhere; slid 0.5
        // along itself it overlaps three quarters (score 1.5) and coincides.
        let line = PointCloud::new(
            (0..=200)
                .map(|i| Point3::new(0.01 * i as f64, 0.0, 0.0))
                .collect(),
        );
        let mut lifted = Fixed::new("lifted", 0.0);
        lifted.transform = RigidTransform::new(Matrix3::identity(), Vector3::new(0.0, 0.015, 0.0));
        let slid = Fixed::new("slid", 0.5);
        let coinciding = Scoring {
            coincides: Some(crate::check::Coincides {
                near: 0.005,
                far: 0.08,
                least: 0.35,
            }),
            ..SCORING
        };
        for (scoring, chosen) in [(SCORING, "lifted"), (coinciding, "slid")] {
            let mut best_of = BestOf::<RegistrationError> {
                base: "both",
                candidates: vec![Box::new(lifted.clone()), Box::new(slid.clone())],
                scoring,
            };
            let found = best_of.register(&line, &line).unwrap();
            let scores: Vec<f64> = found.candidates.iter().map(|c| c.score.unwrap()).collect();
            assert!(
                (scores[0] - 2.0).abs() < 1e-9 && (scores[1] - 1.5).abs() < 0.02,
                "{scores:?}"
            );
            assert_eq!(found.candidates[found.chosen.unwrap()].method, chosen);
            // A cascade takes the lifted line at once unless it must coincide.
            let mut cascade = Cascade::<RegistrationError> {
                base: "both",
                first: Box::new(lifted.clone()),
                rest: vec![Box::new(slid.clone())],
                accept: Acceptance {
                    score: 1.0,
                    turned_share: f64::INFINITY,
                    whole: (SCORING.overlap_distance, f64::INFINITY),
                    coincides: None,
                },
                scoring,
            };
            let found = cascade.register(&line, &line).unwrap();
            assert_eq!(found.candidates[found.chosen.unwrap()].method, chosen);
        }
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
                SCORING.overlap_distance,
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
        assert_eq!(
            overlap_score((&line, &li), (&line, &li), &identity, 0.02),
            2.0
        );
        // The part lies on the line (1.0), which it covers for 4 of 10 points (0.4).
        assert!((overlap_score((&part, &pi), (&line, &li), &identity, 0.02) - 1.4).abs() < 1e-12);
        // Shifted by 0.05 every point is 0.05 from the other cloud: beyond 0.02.
        let shifted =
            RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.0, 0.05, 0.0));
        assert_eq!(
            overlap_score((&line, &li), (&line, &li), &shifted, 0.02),
            0.0
        );
    }
}
