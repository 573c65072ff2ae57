//! Which pairs to register. Every pair of S scans is S·(S−1)/2 registrations, and of an
//! object's or a room's scans most pairs share little (on the Stanford bunny 23 of 45, each
//! costing more than a pair that registers, as the method tries every stage before it doubts).
//! So the pairs are registered in rounds, each round's choice made from the poses the pairs so
//! far give ([`Plan`]):
//!
//! - a pair of scans in one component whose poses show them overlapping is registered (a
//!   loop closure to confirm them), the most overlapping first, until each scan has a few
//!   trusted pairs; one whose poses show them apart is not ([`super::EdgeStatus::Skipped`]);
//! - a scan not yet *confirmed* — in no consistent cycle of three, so its pose rests on one
//!   edge that nothing checks, or on none — is tried against a few more scans each round (those
//!   its unchecked pose shows nearest to overlapping first, then the others in the given order),
//!   until it is confirmed or every pair of it is tried; so a scan that overlaps nothing, or a scan placed by one wrong edge, is tried
//!   against every other and left unplaced rather than placed on a guess;
//! - while the scans form more than one component, every scan is tried against the other
//!   components' scans the same way, so that separate groups are separate only once every
//!   pair across them failed.
//!
//! The rounds stop when a round has nothing to register.

use rgm_geom::{Point3, RigidTransform};

use super::graph::{self, Edge, Tolerance};
use crate::check::overlap_score;
use crate::Prepared;

/// How [`super::merge`] chooses the pairs it registers.
#[derive(Clone, Debug, PartialEq)]
pub enum PairChoice {
    /// Every pair.
    All,
    /// In rounds, from the poses the pairs registered so far give (the module documentation).
    Predicted(OverlapPrior),
}

impl Default for PairChoice {
    fn default() -> Self {
        Self::Predicted(OverlapPrior::default())
    }
}

/// The settings of [`PairChoice::Predicted`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverlapPrior {
    /// A pair of one component is registered when, at the poses found so far, its
    /// [`overlap_score`] (0 to 2) within [`Self::distance_spacings`] reaches this. Default 0.8:
    /// on the Stanford bunny's and dragon's thinned scans at their true poses, every pair the
    /// default method trusted scored at least 0.98 and 0.92, and 21 of the bunny's 45 pairs and
    /// 59 of the dragon's 105 score under 0.8 (`docs/multiway.md`).
    pub min_score: f64,
    /// The overlap is counted within this many point spacings of the scans the pairs are
    /// registered on (default 3: the spanning tree's poses are good to about a degree).
    pub distance_spacings: f64,
    /// Pairs a scan not yet confirmed is tried in per round, those of the pairs chosen by
    /// overlap included (default 3).
    pub partners: usize,
    /// A scan with this many trusted pairs takes no more pairs chosen by overlap, the most
    /// overlapping chosen first (default 8: on the Stanford scans a scan has 4–5 on average;
    /// without a bound, 50 views of an object that each overlap most of the others would
    /// register nearly all 1,225 pairs).
    pub closures: usize,
}

impl Default for OverlapPrior {
    fn default() -> Self {
        Self {
            min_score: 0.8,
            distance_spacings: 3.0,
            partners: 3,
            closures: 8,
        }
    }
}

/// The graph of the pairs registered so far, as the next round's choice sees it.
pub struct Plan<'s, 'c> {
    scans: &'s [Prepared<'c>],
    /// Each scan's point spacing (of the clouds in `scans`). // (S,)
    spacing: &'s [f64],
    component: Vec<Option<usize>>, // (S,)
    /// `model ← scan` in its component's frame (the spanning tree's). // (S,)
    poses: Vec<Option<RigidTransform>>,
    /// In a consistent cycle of three. // (S,)
    confirmed: Vec<bool>,
    /// Trusted pairs of each scan (after the loop-consistency check). // (S,)
    used: Vec<usize>,
}

impl<'s, 'c> Plan<'s, 'c> {
    /// The plan of `edges` (the pairs registered so far, in any order) on `scans` (the clouds
    /// the pairs are registered on, each of point spacing `spacing`).
    pub fn new(
        scans: &'s [Prepared<'c>],
        spacing: &'s [f64],
        edges: &[Edge],
        centroids: &[Point3<f64>],
        sizes: &[f64],
        tolerance: &Tolerance,
    ) -> Self {
        let count = scans.len();
        let mut edges = edges.to_vec();
        edges.sort_by_key(|e| (e.target, e.source));
        graph::reject_inconsistent(&mut edges, centroids, sizes, tolerance);
        let (support, _) = graph::triangle_support(&edges, centroids, sizes, tolerance);
        let mut confirmed = vec![false; count];
        let mut used = vec![0; count];
        for (e, &support) in edges.iter().zip(&support) {
            if e.is_used() {
                used[e.target] += 1;
                used[e.source] += 1;
                if support > 0 {
                    confirmed[e.target] = true;
                    confirmed[e.source] = true;
                }
            }
        }
        let component = graph::components(&edges, count);
        let mut poses = vec![None; count];
        for c in 0..component.iter().flatten().max().map_or(0, |c| c + 1) {
            let members: Vec<usize> = (0..count).filter(|&s| component[s] == Some(c)).collect();
            let (_, found) = graph::spanning_tree_poses(&edges, &members, count);
            for s in members {
                poses[s] = found[s];
            }
        }
        Self {
            scans,
            spacing,
            component,
            poses,
            confirmed,
            used,
        }
    }

    /// Why pair `(a, b)` would not be registered next: the poses place the two apart, or the
    /// two have [`OverlapPrior::closures`] trusted pairs already.
    pub fn skip_reason(&self, a: usize, b: usize, prior: &OverlapPrior) -> String {
        match self.predicted(a, b, prior) {
            Some(score) if score >= prior.min_score => format!(
                "the other pairs' poses overlap the two by {score:.2} (of 2), but scan {} has \
                 {} trusted pairs already",
                if self.used[a] >= self.used[b] { a } else { b },
                self.used[a].max(self.used[b])
            ),
            score => format!(
                "the other pairs' poses overlap the two by {:.2} (of 2), under {}",
                score.unwrap_or(0.0),
                prior.min_score
            ),
        }
    }

    /// The [`overlap_score`] of scans `a` and `b` at their poses, when they are in one
    /// component.
    pub fn predicted(&self, a: usize, b: usize, prior: &OverlapPrior) -> Option<f64> {
        if self.component[a].is_none() || self.component[a] != self.component[b] {
            return None;
        }
        let (pa, pb) = (self.poses[a]?, self.poses[b]?);
        let distance = prior.distance_spacings * self.spacing[a].max(self.spacing[b]);
        Some(overlap_score(
            self.scans[b].indexed(),
            self.scans[a].indexed(),
            &pa.inverse().compose(&pb),
            distance,
        ))
    }

    /// The next round's pairs `(a, b)`, `a < b`, none of them `tried` (`tried[a * S + b]`), in
    /// order; empty when the rounds are over.
    pub fn next(&self, tried: &[bool], prior: &OverlapPrior) -> Vec<(usize, usize)> {
        let count = self.scans.len();
        let untried = |a: usize, b: usize| !tried[a.min(b) * count + a.max(b)];
        let mut chosen = vec![false; count * count]; // (S * S,) by (low, high)
        let mut per_scan = vec![0usize; count]; // (S,) chosen pairs of each scan
        let mut choose = |a: usize, b: usize, per_scan: &mut [usize]| {
            let slot = &mut chosen[a.min(b) * count + a.max(b)];
            if !*slot {
                *slot = true;
                per_scan[a] += 1;
                per_scan[b] += 1;
            }
        };
        // Pairs the poses show overlapping, the most overlapping first, while their scans
        // have room for more trusted pairs.
        let mut apart = vec![None; count * count]; // (S * S,) predicted scores under the bar
        let mut overlapping = Vec::new(); // (score, a, b)
        for a in 0..count {
            for b in a + 1..count {
                if !untried(a, b) {
                    continue;
                }
                match self.predicted(a, b, prior) {
                    Some(score) if score >= prior.min_score => overlapping.push((score, a, b)),
                    Some(score) => apart[a * count + b] = Some(score),
                    None => {}
                }
            }
        }
        overlapping.sort_by(|x, y| y.0.total_cmp(&x.0).then((x.1, x.2).cmp(&(y.1, y.2))));
        for (_, a, b) in overlapping {
            let room = |s: usize, per_scan: &[usize]| self.used[s] + per_scan[s] < prior.closures;
            if room(a, &per_scan) && room(b, &per_scan) {
                choose(a, b, &mut per_scan);
            }
        }
        // Scans still to confirm, and every scan while there are other components: a few more
        // pairs each. A scan placed but not confirmed tries first the scans of its component
        // that its (unchecked) pose shows nearest to overlapping; then come the scans of other
        // components and unplaced ones, nearest in the given order first.
        let groups = self.component.iter().flatten().max().map_or(0, |c| c + 1);
        for s in 0..count {
            if self.confirmed[s] && groups <= 1 {
                continue;
            }
            let mut partners: Vec<(usize, f64, usize)> = (0..count)
                .filter(|&t| t != s && untried(s, t))
                .filter_map(|t| {
                    let ring = (t + count - s) % count;
                    let ring = ring.min(count - ring);
                    let apart = apart[s.min(t) * count + s.max(t)];
                    if self.component[s].is_none() || self.component[s] != self.component[t] {
                        Some((1, ring as f64, t))
                    } else {
                        apart
                            .filter(|_| !self.confirmed[s])
                            .map(|score| (0, -score, t))
                    }
                })
                .collect();
            partners.sort_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)).then(x.2.cmp(&y.2)));
            for (_, _, t) in partners {
                if per_scan[s] >= prior.partners {
                    break;
                }
                choose(s, t, &mut per_scan);
            }
        }
        (0..count)
            .flat_map(|a| (a + 1..count).map(move |b| (a, b)))
            .filter(|&(a, b)| chosen[a * count + b])
            .collect()
    }
}
