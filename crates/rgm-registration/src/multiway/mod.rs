//! Many scans, one model: every scan of an object (or a room), each in its own frame and in any
//! order, put into one frame with no initial poses ([`merge`]).
//!
//! 1. [`pairs`]: pairs registered by the caller's method, chosen round by round from the poses
//!    the pairs so far give ([`prior`]: a pair the poses show apart is not registered); a result
//!    the method doubts, or a failure, is no edge.
//! 2. [`graph`]: wrong edges found by loop consistency (cycles of three), the scans split into
//!    components (scans in separate groups are merged each group on its own; a scan with no
//!    trusted edge is left unplaced), first poses from each component's maximum spanning tree
//!    of edge weights, its reference scan's frame the component's model frame.
//! 3. [`pose_graph`]: the poses that best agree with every used edge (Levenberg–Marquardt on
//!    SE(3), a Cauchy kernel); an edge still far from them is pruned as an outlier and the
//!    graph solved again without it.
//! 4. [`joint`]: each scan refined against the union of the others (multiway ICP at the
//!    scans' own resolution), then each scan's residual to the others.
//!
//! The method is the caller's ([`DynRegistrar`]), so this module knows nothing of networks.

pub mod graph;
pub mod joint;
pub mod pairs;
pub mod pose_graph;
pub mod prior;

#[cfg(test)]
mod tests;

use std::fmt::Display;

use rgm_geom::{GeomError, KnnIndex, Point3, PointCloud, RigidTransform};

use rgm_geom::cloud::{bounds, median};

use crate::methods::refine::median_spacing;
use crate::prepared::SPACING_SAMPLE;
use crate::{DynRegistrar, Prepared};
pub use graph::{Edge, EdgeStatus, Tolerance};
pub use joint::JointConfig;
pub use pose_graph::PoseGraphConfig;
pub use prior::{OverlapPrior, PairChoice};

/// Settings of [`merge`].
#[derive(Clone, Debug, PartialEq)]
pub struct MultiwayConfig {
    /// How far from the identity a consistent cycle of three, or a solved edge, may be.
    pub tolerance: Tolerance,
    /// The pairs are registered on the scans thinned to one point (the mean) per cube of this
    /// many times each scan's point spacing; 1 or less registers them as given (default 3:
    /// as accurate on the Stanford bunny as 1 and 2, in 28 % less time than 1, `docs/multiway.md`).
    pub pair_spacings: f64,
    /// Which pairs are registered (default: in rounds, from the poses found so far).
    pub pairs: PairChoice,
    pub pose_graph: PoseGraphConfig,
    pub joint: JointConfig,
}

impl Default for MultiwayConfig {
    fn default() -> Self {
        Self {
            tolerance: Tolerance::default(),
            pair_spacings: 3.0,
            pairs: PairChoice::default(),
            pose_graph: PoseGraphConfig::default(),
            joint: JointConfig::default(),
        }
    }
}

/// Where a merge is, for a progress display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// `done` of the `total` pairs registered.
    Pairs { done: usize, total: usize },
    /// The pose graph being solved.
    PoseGraph,
    /// Multiway ICP running.
    Joint,
}

/// What [`merge`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct MultiwayResult {
    /// `model ← scan` of each scan, in its component's model frame (that of the component's
    /// reference scan); `None` for a scan with no trusted edge. // (S,)
    pub poses: Vec<Option<RigidTransform>>,
    /// Each placed scan's component, numbered from 0 by size (largest first). // (S,)
    pub component: Vec<Option<usize>>,
    /// The reference scan of each component (its pose the identity). // (C,)
    pub references: Vec<usize>,
    /// Each placed scan's median point-to-plane distance to the other scans of its component,
    /// in the scans' units. // (S,)
    pub residual: Vec<Option<f64>>,
    /// Whether each scan has a used edge on a loop ([`graph::on_loops`]): a placed scan that
    /// has not hangs on pairs nothing else checks (two scans alone never have one). // (S,)
    pub on_loop: Vec<bool>,
    /// Every pair's registration (or why it was not registered), with whether it was used and
    /// why not. // (S·(S−1)/2,)
    pub edges: Vec<Edge>,
    /// Each component's point spacing: the median of its scans' median nearest-neighbour
    /// distances; the joint refinement's and the residuals' unit. // (C,)
    pub spacing: Vec<f64>,
}

impl MultiwayResult {
    /// The scans of component `component` in its model frame, thinned to one point (the first
    /// met, scans in order) per cube of side `voxel`, with each point's scan. // (P,), (P,)
    pub fn model(
        &self,
        scans: &[PointCloud],
        component: usize,
        voxel: f64,
    ) -> (PointCloud, Vec<u32>) {
        let mut points = Vec::new();
        let mut labels = Vec::new();
        for (s, scan) in scans.iter().enumerate() {
            let (Some(pose), Some(c)) = (self.poses[s], self.component[s]) else {
                continue;
            };
            if c == component {
                points.extend(scan.points.iter().map(|p| pose.apply(p)));
                labels.extend(std::iter::repeat_n(s as u32, scan.len()));
            }
        }
        let all = PointCloud::new(points);
        let kept = all.voxel_firsts(voxel);
        (all.select(&kept), kept.iter().map(|&i| labels[i]).collect())
    }
}

/// Puts `scans` into one frame per component with `registrar` as the pairwise method (see the
/// module documentation). Errors when a scan has fewer than 3 points or non-finite ones; a
/// pair the method fails on is only an edge left out.
pub fn merge<E>(
    scans: &[PointCloud],
    registrar: &dyn DynRegistrar<E>,
    config: &MultiwayConfig,
    progress: &(dyn Fn(Stage) + Sync),
) -> Result<MultiwayResult, E>
where
    E: From<GeomError> + Display + Send,
{
    const OP: &str = "multiway::merge";
    for (s, scan) in scans.iter().enumerate() {
        if scan.len() < 3 {
            return Err(GeomError::Degenerate {
                op: OP,
                why: format!("scan {s} has {} points; a scan needs 3", scan.len()),
            }
            .into());
        }
        if let Some(i) = scan
            .points
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(GeomError::Degenerate {
                op: OP,
                why: format!("scan {s} has a non-finite coordinate in point {i}"),
            }
            .into());
        }
    }
    // (S,) each scan's median nearest-neighbour distance
    let spacings: Vec<f64> = scans
        .iter()
        .map(|scan| median_spacing(&scan.points, &KnnIndex::new(&scan.points), SPACING_SAMPLE))
        .collect();
    // The pairs on thinned scans: the joint refinement brings back the scans' own resolution.
    let thinned = |s: usize| config.pair_spacings > 1.0 && spacings[s] > 0.0;
    let prepared: Vec<Prepared> = (0..scans.len())
        .map(|s| match thinned(s) {
            true => Prepared::new(scans[s].voxel_downsampled(config.pair_spacings * spacings[s])),
            false => Prepared::new(&scans[s]),
        })
        .collect();
    // (S,) the point spacing of the clouds the pairs run on
    let pair_spacing: Vec<f64> = (0..scans.len())
        .map(|s| match thinned(s) {
            true => config.pair_spacings * spacings[s],
            false => spacings[s],
        })
        .collect();
    let centroids: Vec<Point3<f64>> = scans.iter().map(PointCloud::centroid).collect(); // (S,)
    let sizes: Vec<f64> = scans.iter().map(diagonal).collect(); // (S,)
    let mut edges = pairs::register_pairs(
        &prepared,
        &pair_spacing,
        registrar,
        &config.pairs,
        &centroids,
        &sizes,
        &config.tolerance,
        progress,
    );
    drop(prepared);
    graph::reject_inconsistent(&mut edges, &centroids, &sizes, &config.tolerance);
    progress(Stage::PoseGraph);
    let (mut poses, references) = solve_graph(&mut edges, &centroids, &sizes, config);
    let component = graph::components(&edges, scans.len());
    // Each component at its own scans' spacing: a scan outside it changes nothing in it.
    let spacing = |c: usize| {
        let members = (0..scans.len()).filter(|&s| component[s] == Some(c));
        median(members.map(|s| spacings[s]).collect())
    };
    let spacing: Vec<f64> = (0..references.len()).map(spacing).collect(); // (C,)
    progress(Stage::Joint);
    joint::refine_jointly(
        scans,
        &mut poses,
        &component,
        &references,
        &spacing,
        &config.joint,
    )?;
    let residual = joint::residuals(scans, &poses, &component, &spacing, &config.joint);
    Ok(MultiwayResult {
        on_loop: graph::on_loops(&edges, scans.len()),
        poses,
        component,
        references,
        residual,
        edges,
        spacing,
    })
}

/// A scan's size: the diagonal of its bounding box (in its own frame).
fn diagonal(scan: &PointCloud) -> f64 {
    let (low, high) = bounds(scan.points.iter().copied());
    (high - low).norm()
}

/// Most solves of the pose graph: each after the first without the edges the one before
/// pruned.
const SOLVES: usize = 3;

/// The poses of every component's scans (spanning tree, then the pose graph), pruning as
/// [`EdgeStatus::Outlier`] the used edges the solved poses contradict and solving again without
/// them; with each component's reference scan.
fn solve_graph(
    edges: &mut [Edge],
    centroids: &[Point3<f64>],
    sizes: &[f64],
    config: &MultiwayConfig,
) -> (Vec<Option<RigidTransform>>, Vec<usize>) {
    let mut pass = 1;
    loop {
        let (poses, references) = solve_components(edges, centroids, sizes, config);
        if pass == SOLVES || !prune_outliers(edges, &poses, centroids, sizes, &config.tolerance) {
            return (poses, references);
        }
        pass += 1;
    }
}

/// Each component's poses by the pose graph from its spanning tree, and its reference scan.
fn solve_components(
    edges: &[Edge],
    centroids: &[Point3<f64>],
    sizes: &[f64],
    config: &MultiwayConfig,
) -> (Vec<Option<RigidTransform>>, Vec<usize>) {
    let scans = centroids.len();
    let component = graph::components(edges, scans);
    let count = component.iter().flatten().max().map_or(0, |c| c + 1);
    let mut poses = vec![None; scans];
    let mut references = Vec::with_capacity(count);
    for c in 0..count {
        let members: Vec<usize> = (0..scans).filter(|&s| component[s] == Some(c)).collect();
        let (reference, initial) = graph::spanning_tree_poses(edges, &members, scans);
        let radius = median(members.iter().map(|&s| sizes[s]).collect()) / 2.0;
        let solved = pose_graph::solve(
            edges,
            &members,
            reference,
            &initial,
            centroids,
            radius,
            &config.pose_graph,
        );
        for &s in &members {
            poses[s] = solved[s];
        }
        references.push(reference);
    }
    (poses, references)
}

/// Marks [`EdgeStatus::Outlier`] each used edge that `poses` do not admit within `tolerance`;
/// whether any was.
fn prune_outliers(
    edges: &mut [Edge],
    poses: &[Option<RigidTransform>],
    centroids: &[Point3<f64>],
    sizes: &[f64],
    tolerance: &Tolerance,
) -> bool {
    let mut pruned = false;
    for e in edges.iter_mut().filter(|e| e.is_used()) {
        let (Some(pt), Some(ps)) = (poses[e.target], poses[e.source]) else {
            continue;
        };
        let error = e.disagreement(&pt, &ps);
        let (angle, shift) = graph::deviation(&error, &centroids[e.source], sizes[e.source]);
        if !tolerance.admits((angle, shift)) {
            e.status = EdgeStatus::Outlier(format!(
                "{angle:.2}° and {:.2} % of the scan's size from the solved poses",
                100.0 * shift
            ));
            pruned = true;
        }
    }
    pruned
}
