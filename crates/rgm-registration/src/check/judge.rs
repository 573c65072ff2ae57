//! How a composite judges its candidates and when it trusts the best: its configuration
//! ([`Scoring`], [`Acceptance`]) and the [`Judge`] that scores results on the pair as the
//! caller gave it.

use rgm_geom::RigidTransform;

use super::coincidence::{sampled_overlap, Coincides, CoincidesAtSpacing};
use super::overlap::{overlap_score, turned_share};
use crate::prepared::{indexed_pair, Prepared};

/// How a composite judges its candidates without ground truth and when it trusts the best:
/// configuration, its values chosen where methods are composed (on the pairs they were tuned
/// on). Lengths in the clouds' units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scoring {
    /// Within it a moved point counts as overlapping the other cloud ([`overlap_score`]).
    pub overlap_distance: f64,
    /// The least [`overlap_score`] of a credible result: below it the pair is reported as not
    /// registered ([`crate::Registration::doubt`]) rather than with a transform nothing supports,
    /// unless an acceptance took the result ([`crate::compose::conclude`]).
    pub min_overlap: f64,
    /// The distance at which the chosen result is scored and its correspondences found.
    pub result_distance: f64,
    /// How a candidate's result must coincide with the other cloud where it overlaps it: one
    /// that does not ranks below every one that does, whatever their overlap, and ends no
    /// cascade. `None`: candidates are ranked by overlap alone (results not yet refined, which
    /// coincide less).
    pub coincides: Option<Coincides>,
}

/// When a cascade's result is good enough to end it ([`crate::compose::Cascade::accept`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Acceptance {
    /// The least [`overlap_score`] taken.
    pub score: f64,
    /// The largest [`turned_share`] taken: above it the shape overlaps itself turned about an
    /// axis (a lamp, a box), the overlap cannot tell its pose, and the later candidates run.
    /// Infinite: any, and neither it nor the whole overlap is measured.
    pub turned_share: f64,
    /// (distance, least overlap): a result whose [`overlap_score`] at that distance reaches the
    /// overlap is taken whatever its turned share. Clouds that lie wholly on each other (full
    /// scans of one object) leave a turned pose nothing to fit better, while noise, which
    /// lowers the overlap at [`Scoring::overlap_distance`] far more than at a looser distance,
    /// would otherwise make a right result look as doubtful as a symmetric shape's.
    pub whole: (f64, f64),
    /// A check the result must pass too (the coincidence of a dense pair at its point
    /// spacing): a result that overlaps enough without coinciding is not taken, and the later
    /// candidates run. Where it applies, the score is measured no finer than its near distance
    /// ([`sampled_overlap`]): under a right pose a point lies up to about a spacing from the
    /// other cloud's nearest, so a pair sparser than the overlap distance would otherwise count
    /// its overlap short.
    pub coincides: Option<CoincidesAtSpacing>,
}

impl Acceptance {
    /// Nothing is good enough: every candidate runs.
    pub const NEVER: Self = Self {
        score: f64::INFINITY,
        turned_share: 0.0,
        whole: (0.0, f64::INFINITY),
        coincides: None,
    };

    /// Whether `transform`, which scores `score` on the pair, ends the cascade; its
    /// [`turned_share`] at `overlap_distance` is measured on `source` and `target` with their
    /// trees, the pair as the candidates saw it (at most a few thousand points, whatever the
    /// pair's density).
    pub fn takes(
        &self,
        score: f64,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
        overlap_distance: f64,
    ) -> bool {
        let (distance, whole) = self.whole;
        let (searched_source, searched_target) = indexed_pair(source, target);
        // Measured on a sample of each cloud, as the coincidence is: on a dense pair the whole
        // clouds' score is a search of every point.
        let at_spacing = self.coincides.and_then(|check| {
            let near = check.coincides.near * check.spacing(source, target)?;
            (near > overlap_distance).then(|| sampled_overlap(source, target, transform, near))
        });
        at_spacing.unwrap_or(score) >= self.score
            && (self.turned_share == f64::INFINITY
                || source.pair_score(target, transform, distance, || {
                    overlap_score(searched_source, searched_target, transform, distance)
                }) >= whole
                || turned_share(
                    searched_source,
                    searched_target,
                    transform,
                    overlap_distance,
                ) <= self.turned_share)
            && self
                .coincides
                .is_none_or(|check| check.takes(source, target, transform))
    }
}
/// The pair a composite's candidates are judged on (the clouds as its caller gave them) and the
/// best result an earlier stage found there. The candidates may run on a thinned version of the
/// pair ([`crate::compose::Thinned`]); they are scored on this one.
pub struct Judge<'a> {
    pub source: &'a Prepared<'a>,
    pub target: &'a Prepared<'a>,
    pub scoring: Scoring,
    /// The best (score, transform) found before: a candidate wins only by beating it, and an
    /// acceptance weighs it as a result of this stage.
    pub before: Option<(f64, RigidTransform)>,
}

impl<'a> Judge<'a> {
    /// A judge on `source` and `target` by `scoring`, with nothing found before; their trees
    /// are built (side by side), as every score needs them.
    pub fn new(source: &'a Prepared<'a>, target: &'a Prepared<'a>, scoring: Scoring) -> Self {
        indexed_pair(source, target);
        Self {
            source,
            target,
            scoring,
            before: None,
        }
    }

    /// `transform`'s [`overlap_score`] on the judged pair, made once per registration
    /// ([`Prepared::pair_score`]): a composite nested in another judges its result on the same
    /// pair as the outer one does.
    pub fn score(&self, transform: &RigidTransform) -> f64 {
        let distance = self.scoring.overlap_distance;
        self.source
            .pair_score(self.target, transform, distance, || {
                overlap_score(
                    self.source.indexed(),
                    self.target.indexed(),
                    transform,
                    distance,
                )
            })
    }

    /// Whether `transform` passes the scoring's [`Scoring::coincides`] on the judged pair
    /// (always, when it has none).
    pub fn coincides(&self, transform: &RigidTransform) -> bool {
        self.scoring
            .coincides
            .is_none_or(|check| check.holds(self.source, self.target, transform))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::AT_SPACING;
    use rgm_geom::testing::box_surface;

    #[test]
    fn a_dense_pair_s_overlap_is_measured_no_finer_than_its_spacing() {
        // Two samplings of one box, 8,000 points each (spacing ≈ 0.008): under the identity a
        // point lies about a spacing from the other sampling's nearest, beyond 0.002 nearly
        // always.
        let (a, b) = (box_surface(8000, 1), box_surface(8000, 2));
        let (source, target) = (Prepared::new(&a), Prepared::new(&b));
        let identity = RigidTransform::identity();
        let fine = 0.002;
        let (searched_source, searched_target) = indexed_pair(&source, &target);
        let score = overlap_score(searched_source, searched_target, &identity, fine);
        assert!(score < 0.2, "{score}");
        let accept = |coincides| Acceptance {
            score: 1.5,
            turned_share: f64::INFINITY,
            whole: (fine, f64::INFINITY),
            coincides,
        };
        assert!(accept(Some(AT_SPACING)).takes(score, &source, &target, &identity, fine));
        assert!(!accept(None).takes(score, &source, &target, &identity, fine));
    }
}
