//! The pairs of scans registered by the caller's method, in rounds chosen by [`super::prior`]
//! (or every pair at once), each round side by side on rayon's pool (one copy of the method per
//! worker), each result an [`Edge`] weighted by its confidence.

use std::fmt::Display;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use rgm_geom::{Point3, RigidTransform};

use super::graph::{Edge, EdgeStatus, Tolerance};
use super::prior::{PairChoice, Plan};
use super::Stage;
use crate::{DynRegistrar, Prepared, Registrar};

/// Registers scan `b` onto scan `a` for the pairs `a < b` that `choice` picks, round by round,
/// telling `progress` each pair done; returns one edge for every pair `a < b`, in order. A
/// result the method doubts is a [`EdgeStatus::Doubted`] edge, a failure a
/// [`EdgeStatus::Failed`] one (with the method's error), a pair not registered a
/// [`EdgeStatus::Skipped`] one: none of them is trusted, and the merge goes on without them.
/// `spacing` (S,) is each scan's point spacing, `centroids` and `sizes` (S,) as
/// [`super::graph::reject_inconsistent`] takes them.
#[allow(clippy::too_many_arguments)]
pub fn register_pairs<E: Display>(
    scans: &[Prepared],
    spacing: &[f64],
    registrar: &dyn DynRegistrar<E>,
    choice: &PairChoice,
    centroids: &[Point3<f64>],
    sizes: &[f64],
    tolerance: &Tolerance,
    progress: &(dyn Fn(Stage) + Sync),
) -> Vec<Edge> {
    let count = scans.len();
    let every: Vec<(usize, usize)> = (0..count)
        .flat_map(|a| (a + 1..count).map(move |b| (a, b)))
        .collect();
    let mut tried = vec![false; count * count]; // (S * S,) by (a, b), a < b
    let mut edges: Vec<Edge> = Vec::new();
    let done = AtomicUsize::new(0);
    loop {
        let round = match choice {
            PairChoice::All if edges.is_empty() => every.clone(),
            PairChoice::All => Vec::new(),
            PairChoice::Predicted(prior) => {
                Plan::new(scans, spacing, &edges, centroids, sizes, tolerance).next(&tried, prior)
            }
        };
        if round.is_empty() {
            break;
        }
        for &(a, b) in &round {
            tried[a * count + b] = true;
        }
        let total = done.load(Ordering::Relaxed) + round.len();
        edges.extend(register_round(
            scans, registrar, &round, &done, total, progress,
        ));
    }
    if let PairChoice::Predicted(prior) = choice {
        let plan = Plan::new(scans, spacing, &edges, centroids, sizes, tolerance);
        for &(a, b) in every.iter().filter(|&&(a, b)| !tried[a * count + b]) {
            edges.push(Edge {
                target: a,
                source: b,
                t_target_source: RigidTransform::identity(),
                weight: 0.0,
                status: EdgeStatus::Skipped(plan.skip_reason(a, b, prior)),
            });
        }
    }
    edges.sort_by_key(|e| (e.target, e.source));
    edges
}

/// One round: scan `b` registered onto scan `a` for each `(a, b)` of `round`.
fn register_round<E: Display>(
    scans: &[Prepared],
    registrar: &dyn DynRegistrar<E>,
    round: &[(usize, usize)],
    done: &AtomicUsize,
    total: usize,
    progress: &(dyn Fn(Stage) + Sync),
) -> Vec<Edge> {
    round
        .par_iter()
        .map_init(
            || registrar.clone_box(),
            |method, &(target, source)| {
                let found = method.register_prepared(&scans[source], &scans[target], &mut |_| {});
                let done = done.fetch_add(1, Ordering::Relaxed) + 1;
                progress(Stage::Pairs { done, total });
                match found {
                    Ok(r) => Edge {
                        target,
                        source,
                        t_target_source: r.result.t_target_source,
                        weight: r.result.fitness,
                        status: match r.doubt {
                            None => EdgeStatus::Used,
                            Some(why) => EdgeStatus::Doubted(why),
                        },
                    },
                    Err(err) => Edge {
                        target,
                        source,
                        t_target_source: RigidTransform::identity(),
                        weight: 0.0,
                        status: EdgeStatus::Failed(err.to_string()),
                    },
                }
            },
        )
        .collect()
}
