//! The poses that best agree with the used edges: a small Levenberg–Marquardt on SE(3) with a
//! Cauchy kernel, dense normal equations (6 unknowns per scan; a merge has tens of scans, so the
//! system is at most a few hundred square).
//!
//! Each used edge `t ← s` contributes the residual of `E = T_ts⁻¹ · P_t⁻¹ · P_s` (the identity
//! when the poses `P` agree with it): its rotation vector (radians) and how far it moves
//! scan `s`'s centroid, in units of the scans' radius, so that both parts weigh alike (1 rad
//! turns a point at one radius by one radius). A pose is perturbed about its scan's centroid,
//! `P ← exp(δ) · P`, which keeps rotation and translation apart wherever the scanner's origin is.
//! Edges are weighted by their [`Edge::weight`]; the kernel makes a wrong edge that survived the
//! loop check pull little. The reference scan's pose is held (the model's frame).

use std::ops::AddAssign;

use nalgebra::{DMatrix, DVector, Matrix6, Rotation3, Vector6};
use rgm_geom::{Point3, RigidTransform, Vector3};

use super::graph::Edge;

/// Settings of [`solve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseGraphConfig {
    /// Most Levenberg–Marquardt iterations (default 50).
    pub iterations: usize,
    /// The Cauchy kernel's scale, in residual units (radians, radii; default 0.05 ≈ 3°).
    pub kernel: f64,
}

impl Default for PoseGraphConfig {
    fn default() -> Self {
        Self {
            iterations: 50,
            kernel: 0.05,
        }
    }
}

/// The rigid motion `exp(δ)` about `centre`: turn by the rotation vector `δ[0..3]`, shift by
/// `radius · δ[3..6]`.
fn perturbation(delta: &Vector6<f64>, centre: &Point3<f64>, radius: f64) -> RigidTransform {
    let rotation = Rotation3::new(Vector3::new(delta[0], delta[1], delta[2])).into_inner();
    let shift = Vector3::new(delta[3], delta[4], delta[5]) * radius;
    RigidTransform::new(rotation, centre.coords + shift - rotation * centre.coords)
}

/// The graph's fixed parts: the used edges, the scans' centroids (their own frames) and radius.
struct Problem<'a> {
    edges: Vec<&'a Edge>,
    centroids: &'a [Point3<f64>], // (S,)
    radius: f64,
}

impl Problem<'_> {
    /// Edge `e`'s residual under target pose `pt` and source pose `ps`.
    fn residual(&self, e: &Edge, pt: &RigidTransform, ps: &RigidTransform) -> Vector6<f64> {
        let error = e.disagreement(pt, ps);
        let turn = Rotation3::from_matrix_unchecked(error.rotation).scaled_axis();
        let c = self.centroids[e.source];
        let shift = (error.apply(&c) - c) / self.radius;
        Vector6::new(turn.x, turn.y, turn.z, shift.x, shift.y, shift.z)
    }

    /// Σ weight · ρ(|r|²) over the edges, ρ the Cauchy kernel of scale `c`.
    fn cost(&self, poses: &[RigidTransform], c: f64) -> f64 {
        self.edges
            .iter()
            .map(|e| {
                let r = self.residual(e, &poses[e.target], &poses[e.source]);
                e.weight * c * c * (r.norm_squared() / (c * c)).ln_1p()
            })
            .sum()
    }
}

/// The poses (`model ← scan`, the reference's held) of the scans `members` that best agree with
/// `edges`' used ones among them, from `initial` (every member's pose given; others ignored).
/// `centroids` (S,) are the scans' centroids in their own frames, `radius` the scans' radius.
pub fn solve(
    edges: &[Edge],
    members: &[usize],
    reference: usize,
    initial: &[Option<RigidTransform>],
    centroids: &[Point3<f64>],
    radius: f64,
    config: &PoseGraphConfig,
) -> Vec<Option<RigidTransform>> {
    let unknown: Vec<usize> = members
        .iter()
        .copied()
        .filter(|&s| s != reference)
        .collect();
    let mut slot = vec![None; initial.len()]; // (S,) each unknown scan's block
    for (k, &s) in unknown.iter().enumerate() {
        slot[s] = Some(k);
    }
    let problem = Problem {
        edges: edges
            .iter()
            .filter(|e| e.is_used() && initial[e.target].is_some() && initial[e.source].is_some())
            .filter(|e| members.contains(&e.target) && members.contains(&e.source))
            .collect(),
        centroids,
        radius,
    };
    let mut poses: Vec<RigidTransform> = initial
        .iter()
        .map(|p| p.unwrap_or_else(RigidTransform::identity))
        .collect();
    let n = 6 * unknown.len();
    if n == 0 || problem.edges.is_empty() {
        return initial.to_vec();
    }
    let c = config.kernel;
    let mut cost = problem.cost(&poses, c);
    let mut lambda = 1e-4;
    for _ in 0..config.iterations {
        let mut h = DMatrix::<f64>::zeros(n, n); // (6U, 6U)
        let mut g = DVector::<f64>::zeros(n); // (6U,)
        for e in &problem.edges {
            let (pt, ps) = (poses[e.target], poses[e.source]);
            let r = problem.residual(e, &pt, &ps);
            // IRLS weight of the Cauchy kernel at this residual.
            let w = e.weight / (1.0 + r.norm_squared() / (c * c));
            let jacobian = |scan: usize| -> Matrix6<f64> {
                let centre = poses[scan].apply(&centroids[scan]);
                let mut j = Matrix6::zeros();
                const H: f64 = 1e-6;
                for k in 0..6 {
                    let mut d = Vector6::zeros();
                    d[k] = H;
                    let moved = |d: &Vector6<f64>| {
                        let p = perturbation(d, &centre, radius).compose(&poses[scan]);
                        if scan == e.target {
                            problem.residual(e, &p, &ps)
                        } else {
                            problem.residual(e, &pt, &p)
                        }
                    };
                    j.set_column(k, &((moved(&d) - moved(&-d)) / (2.0 * H)));
                }
                j
            };
            let blocks: Vec<(usize, Matrix6<f64>)> = [e.target, e.source]
                .into_iter()
                .filter_map(|s| slot[s].map(|k| (k, jacobian(s))))
                .collect();
            for (a, ja) in &blocks {
                g.rows_mut(6 * a, 6).add_assign(&(ja.transpose() * r * w));
                for (b, jb) in &blocks {
                    h.view_mut((6 * a, 6 * b), (6, 6))
                        .add_assign(&(ja.transpose() * jb * w));
                }
            }
        }
        let mut improved = false;
        while lambda < 1e8 {
            let mut damped = h.clone();
            for k in 0..n {
                damped[(k, k)] += lambda * (h[(k, k)] + 1e-9);
            }
            let Some(step) = damped.cholesky().map(|ch| ch.solve(&-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let mut tried = poses.clone();
            for (k, &s) in unknown.iter().enumerate() {
                let delta = Vector6::from_iterator(step.rows(6 * k, 6).iter().copied());
                let centre = poses[s].apply(&centroids[s]);
                tried[s] = perturbation(&delta, &centre, radius).compose(&poses[s]);
            }
            let tried_cost = problem.cost(&tried, c);
            if tried_cost < cost {
                let small = step.amax() < 1e-10;
                poses = tried;
                cost = tried_cost;
                lambda = (lambda / 10.0).max(1e-12);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    initial
        .iter()
        .zip(poses)
        .map(|(given, solved)| given.map(|_| solved))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::multiway::graph::EdgeStatus;
    use rand::{rngs::StdRng, SeedableRng};

    #[test]
    fn noisy_edges_are_averaged_and_a_wrong_one_pulls_little() {
        // Exact edges give the truth; edges off by up to ±0.5° a turn about each axis give
        // poses off by less than 0.5°; one edge 30° off moves them by under 0.02°.
        assert!(ring_error(0.0, 0.0) < 1e-4);
        let noisy = ring_error(0.5, 0.0);
        assert!(noisy < 0.5, "{noisy}");
        let spoilt = ring_error(0.5, 30.0);
        assert!((spoilt - noisy).abs() < 0.02, "{spoilt} against {noisy}");
    }

    /// The worst rotation error (°) of the poses solved on a complete graph of six scans whose
    /// edges are off by up to `noise`° a turn about each axis, edge (2, 4) by `wrong`°.
    fn ring_error(noise: f64, wrong: f64) -> f64 {
        let mut rng = StdRng::seed_from_u64(3);
        let truth: Vec<RigidTransform> = (0..6)
            .map(|_| RigidTransform::random(&mut rng, 90.0, 0.5))
            .collect();
        let centroids = vec![Point3::new(0.05, -0.02, 0.1); 6];
        let mut edges = Vec::new();
        for a in 0..6 {
            for b in a + 1..6 {
                let error = if (a, b) == (2, 4) {
                    RigidTransform::random(&mut rng, wrong, 0.1 * wrong / 30.0)
                } else {
                    crate::multiway::tests::jitter(&mut rng, noise, 0.01 * noise, &centroids[b])
                };
                edges.push(Edge {
                    target: a,
                    source: b,
                    t_target_source: truth[a].inverse().compose(&truth[b]).compose(&error),
                    weight: 0.6,
                    status: EdgeStatus::Used,
                });
            }
        }
        // Start from the truth (in scan 0's frame) spoilt by 5°.
        let initial: Vec<Option<RigidTransform>> = (0..6)
            .map(|s| {
                let spoil = if s == 0 {
                    RigidTransform::identity()
                } else {
                    RigidTransform::random(&mut rng, 5.0, 0.02)
                };
                Some(spoil.compose(&truth[0].inverse().compose(&truth[s])))
            })
            .collect();
        let members: Vec<usize> = (0..6).collect();
        let config = PoseGraphConfig::default();
        let solved = solve(&edges, &members, 0, &initial, &centroids, 0.5, &config);
        assert_eq!(solved[0], initial[0]);
        (1..6)
            .map(|s| {
                let t = truth[0].inverse().compose(&truth[s]);
                let off = t.inverse().compose(&solved[s].unwrap());
                off.rotation_angle_deg()
            })
            .fold(0.0, f64::max)
    }
}
