//! The pose graph as data: scans are nodes, pairwise registrations edges (`t_target_source`,
//! a weight, a status). Which edges to trust (loop consistency), which scans hang together
//! (components) and the first poses (a maximum spanning tree of the weights) are found here;
//! how the poses are then solved is [`super::pose_graph`]'s.

use rgm_geom::{Point3, RigidTransform};

/// Why an edge is or is not in the pose graph.
#[derive(Clone, Debug, PartialEq)]
pub enum EdgeStatus {
    /// Trusted, and kept by every check.
    Used,
    /// The pairwise method failed on the pair (its error).
    Failed(String),
    /// The pairwise method did not trust its result (its [`crate::Registration::doubt`]).
    Doubted(String),
    /// In cycles of three, none of them consistent ([`reject_inconsistent`]).
    Inconsistent(String),
    /// Far from the poses the rest of the graph agreed on (pruned after a solve).
    Outlier(String),
    /// Not registered: the poses found from the other pairs show the two scans overlapping too
    /// little, or both have enough trusted pairs ([`super::prior`]).
    Skipped(String),
}

/// One pairwise registration: scan `source` mapped onto scan `target`.
#[derive(Clone, Debug, PartialEq)]
pub struct Edge {
    pub target: usize,
    pub source: usize,
    /// Maps `source`'s points into `target`'s frame.
    pub t_target_source: RigidTransform,
    /// The registration's confidence, in [0, 1] (its fitness: the share of the source's points
    /// on the target under it); the spanning tree and the solver weigh edges by it.
    pub weight: f64,
    pub status: EdgeStatus,
}

impl Edge {
    pub fn is_used(&self) -> bool {
        self.status == EdgeStatus::Used
    }

    /// How far poses `model ← target` and `model ← source` disagree with the edge:
    /// `T_ts⁻¹ · P_t⁻¹ · P_s`, the identity where they agree (in the source's frame).
    pub fn disagreement(&self, target: &RigidTransform, source: &RigidTransform) -> RigidTransform {
        self.t_target_source
            .inverse()
            .compose(&target.inverse())
            .compose(source)
    }

    /// The edge read from `from` to the other scan: that scan and the transform `from ← other`.
    fn towards(&self, from: usize) -> (usize, RigidTransform) {
        if from == self.target {
            (self.source, self.t_target_source)
        } else {
            (self.target, self.t_target_source.inverse())
        }
    }
}

/// How far a transform that should be the identity is from it, in a scan's frame: its rotation
/// angle (degrees) and how far it moves the scan's centroid, as a share of the scan's size.
/// Measured at the centroid, the shift does not depend on where the scanner's origin lies.
pub fn deviation(transform: &RigidTransform, centroid: &Point3<f64>, size: f64) -> (f64, f64) {
    let shift = (transform.apply(centroid) - centroid).norm();
    (transform.rotation_angle_deg(), shift / size)
}

/// The largest deviation from the identity a consistent loop (or a solved edge) may show.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Degrees (default 3: a cycle of three right pairwise results of the Stanford scans
    /// composes to well under 1°, and a wrong result is off by tens of degrees).
    pub angle_deg: f64,
    /// Share of the scans' size (default 0.03).
    pub shift: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Self {
            angle_deg: 3.0,
            shift: 0.03,
        }
    }
}

impl Tolerance {
    pub fn admits(&self, (angle, shift): (f64, f64)) -> bool {
        angle <= self.angle_deg && shift <= self.shift
    }
}

/// Marks [`EdgeStatus::Inconsistent`] every used edge that lies in cycles of three (three used
/// edges) but in no consistent one: one whose composed transform is the identity within
/// `tolerance`. An edge in no cycle at all is kept: nothing contradicts it. A wrong edge
/// between right ones makes its cycles inconsistent; a scan of another object that the method
/// was fooled on twice or more makes every cycle through it inconsistent, its right-looking
/// edges too; a right edge whose every cycle passes through a wrong one is lost with it (its scan
/// may then be left unplaced, never placed wrong). `centroids` (S,) of the scans in their own
/// frames, `sizes` (S,) their bounding-box diagonals; a cycle is measured in the frame of its
/// first scan.
pub fn reject_inconsistent(
    edges: &mut [Edge],
    centroids: &[Point3<f64>],
    sizes: &[f64],
    tolerance: &Tolerance,
) {
    let (support, cycles) = triangle_support(edges, centroids, sizes, tolerance);
    for (k, e) in edges.iter_mut().enumerate() {
        if e.is_used() && support[k] == 0 && cycles[k] > 0 {
            e.status = EdgeStatus::Inconsistent(format!(
                "in {} cycle{} of three, none of them consistent",
                cycles[k],
                if cycles[k] == 1 { "" } else { "s" }
            ));
        }
    }
}

/// For every edge, the consistent cycles of three used edges it lies in and all the cycles it
/// lies in (both 0 for an edge not used); as [`reject_inconsistent`] measures them. // (E,), (E,)
pub fn triangle_support(
    edges: &[Edge],
    centroids: &[Point3<f64>],
    sizes: &[f64],
    tolerance: &Tolerance,
) -> (Vec<usize>, Vec<usize>) {
    let scans = centroids.len();
    // by_pair[a * S + b]: the used edge between scans a and b, either way.
    let mut by_pair: Vec<Option<usize>> = vec![None; scans * scans]; // (S * S,)
    for (k, e) in edges.iter().enumerate().filter(|(_, e)| e.is_used()) {
        by_pair[e.target * scans + e.source] = Some(k);
        by_pair[e.source * scans + e.target] = Some(k);
    }
    let edge = |a: usize, b: usize| by_pair[a * scans + b];
    let mut support = vec![0usize; edges.len()]; // (E,) consistent triangles of each edge
    let mut cycles = vec![0usize; edges.len()]; // (E,) triangles of each edge
                                                // Each triangle a < b < c once: is a ← b ← c ← a the identity?
    for a in 0..scans {
        for b in a + 1..scans {
            let Some(ab) = edge(a, b) else { continue };
            for c in b + 1..scans {
                let (Some(bc), Some(ca)) = (edge(b, c), edge(c, a)) else {
                    continue;
                };
                let a_from_b = edges[ab].towards(a).1;
                let b_from_c = edges[bc].towards(b).1;
                let c_from_a = edges[ca].towards(c).1;
                let round = a_from_b.compose(&b_from_c).compose(&c_from_a);
                let consistent = tolerance.admits(deviation(&round, &centroids[a], sizes[a]));
                for k in [ab, bc, ca] {
                    cycles[k] += 1;
                    support[k] += usize::from(consistent);
                }
            }
        }
    }
    (support, cycles)
}

/// The root of `a`'s set in the union-find forest `root`, halving the path on the way.
fn find(root: &mut [usize], mut a: usize) -> usize {
    while root[a] != a {
        root[a] = root[root[a]];
        a = root[a];
    }
    a
}

/// Whether each scan has a used edge on a loop of used edges (its two scans still linked
/// without it). A placed scan that has none hangs on edges no other path checks: a pair the
/// method trusted wrongly would place it wrong, and neither the cycles of three nor the pose
/// graph could tell. // (S,)
pub fn on_loops(edges: &[Edge], scans: usize) -> Vec<bool> {
    let used: Vec<&Edge> = edges.iter().filter(|e| e.is_used()).collect();
    let mut on_loop = vec![false; scans];
    for (k, e) in used.iter().enumerate() {
        let mut root: Vec<usize> = (0..scans).collect(); // (S,) union-find parents
        for (_, other) in used.iter().enumerate().filter(|(j, _)| *j != k) {
            let (a, b) = (find(&mut root, other.target), find(&mut root, other.source));
            root[a.max(b)] = a.min(b);
        }
        if find(&mut root, e.target) == find(&mut root, e.source) {
            on_loop[e.target] = true;
            on_loop[e.source] = true;
        }
    }
    on_loop
}

/// The component of every scan under the used edges, numbered from 0 by size (largest first,
/// ties by lowest scan); `None` for a scan with no used edge.
pub fn components(edges: &[Edge], scans: usize) -> Vec<Option<usize>> {
    let mut root: Vec<usize> = (0..scans).collect(); // (S,) union-find parents
    let mut linked = vec![false; scans];
    for e in edges.iter().filter(|e| e.is_used()) {
        let (a, b) = (find(&mut root, e.target), find(&mut root, e.source));
        root[a.max(b)] = a.min(b);
        linked[e.target] = true;
        linked[e.source] = true;
    }
    let roots: Vec<usize> = (0..scans).map(|s| find(&mut root, s)).collect();
    let mut groups: Vec<(usize, usize)> = Vec::new(); // (root, size), first scan order
    for s in (0..scans).filter(|&s| linked[s]) {
        match groups.iter_mut().find(|g| g.0 == roots[s]) {
            Some(g) => g.1 += 1,
            None => groups.push((roots[s], 1)),
        }
    }
    groups.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    (0..scans)
        .map(|s| {
            linked[s]
                .then(|| groups.iter().position(|g| g.0 == roots[s]))
                .flatten()
        })
        .collect()
}

/// First poses of the scans of one component (`members`, its scans): the maximum spanning tree
/// of the used edges' weights, walked from its reference scan (the one with the most weight on
/// its used edges), whose frame is the model's. Returns the reference and `model ← scan` for
/// every scan (`None` outside the component).
pub fn spanning_tree_poses(
    edges: &[Edge],
    members: &[usize],
    scans: usize,
) -> (usize, Vec<Option<RigidTransform>>) {
    let inside = |s: usize| members.contains(&s);
    let mut used: Vec<&Edge> = edges
        .iter()
        .filter(|e| e.is_used() && inside(e.target) && inside(e.source))
        .collect();
    let mut strength = vec![0.0; scans]; // (S,) weight on each scan's used edges
    for e in &used {
        strength[e.target] += e.weight;
        strength[e.source] += e.weight;
    }
    let reference = *members
        .iter()
        .max_by(|&&a, &&b| strength[a].total_cmp(&strength[b]).then(b.cmp(&a)))
        .expect("a component has scans");
    // Prim's tree from the reference: the heaviest edge that reaches a new scan, each time.
    used.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    let mut poses: Vec<Option<RigidTransform>> = vec![None; scans];
    poses[reference] = Some(RigidTransform::identity());
    loop {
        let next = used
            .iter()
            .find_map(|e| match (poses[e.target], poses[e.source]) {
                (Some(t), None) => Some((e.source, t.compose(&e.t_target_source))),
                (None, Some(s)) => Some((e.target, s.compose(&e.t_target_source.inverse()))),
                _ => None,
            });
        match next {
            Some((scan, pose)) => poses[scan] = Some(pose),
            None => break,
        }
    }
    (reference, poses)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::euler::rotation_xyz_intrinsic;
    use rgm_geom::Vector3;

    fn turn(deg: f64, x: f64) -> RigidTransform {
        RigidTransform::new(
            rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
            Vector3::new(x, 0.0, 0.0),
        )
    }

    /// An edge `target ← source` made of the true poses (model ← scan), times `error`.
    fn edge(poses: &[RigidTransform], target: usize, source: usize, error: RigidTransform) -> Edge {
        Edge {
            target,
            source,
            t_target_source: poses[target]
                .inverse()
                .compose(&poses[source])
                .compose(&error),
            weight: 0.5,
            status: EdgeStatus::Used,
        }
    }

    #[test]
    fn a_scan_on_bridges_alone_is_on_no_loop() {
        // A ring 0-1-2-3-0, scan 4 hanging on 3 alone, 5 on 4; 6 linked by a doubted edge only.
        let poses: Vec<RigidTransform> = (0..7).map(|k| turn(30.0 * k as f64, 0.1)).collect();
        let mut edges: Vec<Edge> = [(0, 1), (1, 2), (2, 3), (0, 3), (3, 4), (4, 5), (5, 6)]
            .iter()
            .map(|&(a, b)| edge(&poses, a, b, turn(0.0, 0.0)))
            .collect();
        edges[6].status = EdgeStatus::Doubted("not trusted".into());
        assert_eq!(
            on_loops(&edges, 7),
            [true, true, true, true, false, false, false]
        );
        // Closing 4 and 5 onto the ring puts them on a loop too.
        edges.push(edge(&poses, 1, 5, turn(0.0, 0.0)));
        assert_eq!(
            on_loops(&edges, 7),
            [true, true, true, true, true, true, false]
        );
    }

    #[test]
    fn a_wrong_edge_in_a_clique_is_found_by_its_triangles_and_the_others_are_kept() {
        let poses: Vec<RigidTransform> = (0..5).map(|k| turn(40.0 * k as f64, 0.1)).collect();
        let mut edges = Vec::new();
        for a in 0..5 {
            for b in a + 1..5 {
                let error = if (a, b) == (1, 3) {
                    turn(25.0, 0.05)
                } else {
                    turn(0.3, 0.001)
                };
                edges.push(edge(&poses, a, b, error));
            }
        }
        let centroids = vec![Point3::new(0.1, 0.2, 0.0); 5];
        reject_inconsistent(&mut edges, &centroids, &[1.0; 5], &Tolerance::default());
        for e in &edges {
            let wrong = (e.target, e.source) == (1, 3);
            assert_eq!(!e.is_used(), wrong, "{e:?}");
        }
    }

    #[test]
    fn components_spanning_tree_and_a_lone_scan() {
        let poses: Vec<RigidTransform> = (0..6).map(|k| turn(30.0 * k as f64, 0.2)).collect();
        let exact = RigidTransform::identity();
        let mut edges = vec![
            edge(&poses, 0, 1, exact),
            edge(&poses, 1, 2, exact),
            edge(&poses, 3, 4, exact),
            // A doubted edge links nothing: scan 5 stays alone.
            Edge {
                status: EdgeStatus::Doubted("no overlap".into()),
                ..edge(&poses, 4, 5, exact)
            },
        ];
        edges[1].weight = 0.9; // scan 1 has the most weight: the reference of 0–2
        assert_eq!(
            components(&edges, 6),
            vec![Some(0), Some(0), Some(0), Some(1), Some(1), None]
        );
        let (reference, found) = spanning_tree_poses(&edges, &[0, 1, 2], 6);
        assert_eq!(reference, 1);
        assert_eq!(found[3], None);
        for s in 0..3 {
            // model ← scan in the reference's frame: poses[1]⁻¹ · poses[s].
            let truth = poses[1].inverse().compose(&poses[s]);
            let off = truth.inverse().compose(&found[s].unwrap());
            assert!(off.rotation_angle_deg() < 1e-9 && off.translation.norm() < 1e-12);
        }
    }
}
