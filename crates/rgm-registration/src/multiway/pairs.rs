//! Every pair of scans registered by the caller's method, side by side on rayon's pool (one
//! copy of the method per worker), each result an [`Edge`] weighted by its confidence.

use std::fmt::Display;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use super::graph::{Edge, EdgeStatus};
use super::Stage;
use crate::{DynRegistrar, Prepared, Registrar};

/// Registers scan `b` onto scan `a` for every `a < b`, telling `progress` each pair done. A
/// result the method doubts is a [`EdgeStatus::Doubted`] edge, a failure a
/// [`EdgeStatus::Failed`] one (with the method's error): neither is trusted, and the merge goes
/// on without them.
pub fn register_pairs<E: Display>(
    scans: &[Prepared],
    registrar: &dyn DynRegistrar<E>,
    progress: &(dyn Fn(Stage) + Sync),
) -> Vec<Edge> {
    let jobs: Vec<(usize, usize)> = (0..scans.len())
        .flat_map(|a| (a + 1..scans.len()).map(move |b| (a, b)))
        .collect();
    let done = AtomicUsize::new(0);
    let total = jobs.len();
    jobs.par_iter()
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
                        t_target_source: rgm_geom::RigidTransform::identity(),
                        weight: 0.0,
                        status: EdgeStatus::Failed(err.to_string()),
                    },
                }
            },
        )
        .collect()
}
