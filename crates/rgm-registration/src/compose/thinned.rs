//! [`Thinned`], a composite run on several thinnings of a dense pair, judged on the pair as given.

use std::time::Instant;

use rgm_geom::{GeomError, RigidTransform};

use crate::check::{agree, Judge};
use crate::compose::{conclude, Composite};
use crate::error::AllCandidatesFailed;
use crate::prepared::Prepared;
use crate::registrar::{MethodId, Progress, Registrar, Registration};
use crate::thinning::{thinned, Density, Thinning};

/// A composite on a pair denser than `density` thinned each of `thinnings` ways in turn, its
/// candidates judged on the pair as given: a dense pair can be thinned many ways, none of them
/// the sampling the methods were tuned on. The next thinning runs unless the composite's
/// acceptance took a result ([`crate::compose::Outcome::settled`]) or the candidates of this one
/// agree within `agreement` ([`agree`]), which leaves nothing for the next to fix. A pair no
/// denser runs once, as it is. The best of every thinning wins (ties to the earlier); a
/// candidate's name carries its thinning ([`Thinning::suffix`]).
#[derive(Clone, Debug)]
pub struct Thinned<C> {
    pub inner: C,
    pub thinnings: Vec<Thinning>,
    pub density: Density,
    /// (degrees, distance) within which candidates agree.
    pub agreement: (f64, f64),
}

impl<E, C> Registrar<E> for Thinned<C>
where
    E: From<GeomError> + From<AllCandidatesFailed>,
    C: Composite<E>,
{
    fn id(&self) -> MethodId {
        self.inner.id()
    }

    /// Scored at the composite's [`crate::check::Scoring::result_distance`].
    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let distance = self.inner.scoring().result_distance;
        let found = self.register_unscored(source, target, progress)?;
        Ok(found.fitted_within(source, target, distance))
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        let start = Instant::now();
        let judge = Judge::new(source, target, self.inner.scoring());
        let dense = self.density.is_exceeded_by(source.len(), target.len());
        let thinnings = if dense {
            &self.thinnings[..]
        } else {
            &self.thinnings[..1.min(self.thinnings.len())]
        };
        let mut candidates = Vec::new();
        // (score, transform, iterations, index in `candidates`) of the best so far.
        let mut best: Option<(f64, RigidTransform, usize, usize)> = None;
        let mut settled = false;
        for &how in thinnings {
            // A cloud no denser than `density` is used as it is, its tree shared.
            let thin = |cloud: &Prepared| thinned(cloud, how, self.density).map(Prepared::new);
            let (s, t) = rayon::join(|| thin(source), || thin(target));
            let (s, t) = (s.as_ref().unwrap_or(source), t.as_ref().unwrap_or(target));
            let judge = Judge {
                before: best.map(|(score, transform, ..)| (score, transform)),
                ..judge
            };
            let outcome = self.inner.run_judged(s, t, &judge);
            if let Some((i, iterations)) = outcome.best {
                let winner = &outcome.candidates[i];
                let score = winner.score.expect("a winner is scored");
                best = Some((
                    score,
                    winner.t_target_source,
                    iterations,
                    candidates.len() + i,
                ));
            }
            let found: Vec<RigidTransform> = outcome
                .candidates
                .iter()
                .filter(|c| c.score.is_some())
                .map(|c| c.t_target_source)
                .collect();
            candidates.extend(outcome.candidates.into_iter().map(|mut c| {
                c.method.push_str(how.suffix());
                c
            }));
            let agreeing = |t| agree(&found[0], t, self.agreement);
            settled = outcome.settled;
            if settled || found.len() > 1 && found[1..].iter().all(agreeing) {
                break;
            }
        }
        let chosen = best.map(|(_, _, iterations, index)| (index, iterations));
        conclude(&judge, candidates, chosen, settled, start)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::Acceptance;
    use crate::compose::{BestOf, Cascade};
    use crate::testing::{Fixed, DENSITY, SCORING};
    use crate::RegistrationError;
    use rgm_geom::testing::box_surface;

    fn thinned_best_of(candidates: &[&Fixed]) -> Thinned<BestOf<RegistrationError>> {
        Thinned {
            inner: BestOf {
                base: "both",
                candidates: candidates
                    .iter()
                    .map(|&c| Box::new(c.clone()) as _)
                    .collect(),
                scoring: SCORING,
            },
            thinnings: vec![Thinning::Voxels, Thinning::Cells],
            density: DENSITY,
            agreement: (1.0, 0.02),
        }
    }

    #[test]
    fn a_dense_pair_runs_on_the_next_thinning_until_the_candidates_agree() {
        let dense = box_surface(3000, 1);
        let (right, wrong) = (Fixed::new("right", 0.0), Fixed::new("wrong", 0.3));
        // They disagree: both thinnings run, each on thinned clouds, judged on the dense pair.
        let found = thinned_best_of(&[&right, &wrong])
            .register(&dense, &dense)
            .unwrap();
        let names: Vec<&str> = found.candidates.iter().map(|c| c.method.as_str()).collect();
        assert_eq!(names, ["right", "wrong", "right/cells", "wrong/cells"]);
        assert_eq!(found.candidates[0].score, Some(2.0));
        assert_eq!(found.chosen, Some(0));
        assert_eq!(found.result.inlier_count, 3000);
        for (s, t) in right.seen() {
            assert!(s <= DENSITY.points && t <= DENSITY.points, "{s} {t}");
        }
        // They agree: the first thinning is enough.
        let (a, b) = (Fixed::new("a", 0.0), Fixed::new("b", 0.001));
        let found = thinned_best_of(&[&a, &b]).register(&dense, &dense).unwrap();
        assert_eq!(found.candidates.len(), 2);
        // A pair no denser runs once, as it is.
        let sparse = box_surface(500, 2);
        let found = thinned_best_of(&[&right, &wrong])
            .register(&sparse, &sparse)
            .unwrap();
        assert_eq!(found.candidates.len(), 2);
        assert_eq!(right.seen().last(), Some(&(500, 500)));
    }

    #[test]
    fn a_result_the_cascade_takes_ends_the_thinnings() {
        let dense = box_surface(3000, 1);
        let (right, never_run) = (Fixed::new("right", 0.0), Fixed::new("later", 0.3));
        let mut thinned = Thinned {
            inner: Cascade::<RegistrationError> {
                base: "cascade",
                first: Box::new(right.clone()),
                rest: vec![Box::new(never_run.clone())],
                accept: Acceptance {
                    score: 1.9,
                    turned_share: f64::INFINITY,
                    whole: (SCORING.overlap_distance, f64::INFINITY),
                    coincides: None,
                },
                scoring: SCORING,
            },
            thinnings: vec![Thinning::Voxels, Thinning::Cells],
            density: DENSITY,
            agreement: (1.0, 0.02),
        };
        let found = thinned.register(&dense, &dense).unwrap();
        assert_eq!(found.candidates.len(), 1);
        assert_eq!((right.calls(), never_run.calls()), (1, 0));
        assert_eq!(
            Registrar::<RegistrationError>::id(&thinned).to_string(),
            "cascade"
        );
    }
}
