//! What every registration method returns, and Open3D's way of scoring a transform.

use nalgebra::Point3;
use rayon::prelude::*;

use rgm_geom::{KnnIndex, RigidTransform};

/// What one algorithm found on a pair: its transform, and how well the source fits the target
/// under it (Open3D's `RegistrationResult`). A [`crate::Registration`] carries one, with the
/// correspondences, the time and a composite's candidates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    /// The estimated transform mapping source coordinates into the target frame.
    pub t_target_source: RigidTransform,
    /// Iterations run (transform updates).
    pub iterations: usize,
    /// True when the method's convergence test stopped it before its iteration limit.
    pub converged: bool,
    /// Source points (moved by `t_target_source`) with a target point closer than the scoring
    /// distance.
    pub inlier_count: usize,
    /// `inlier_count / source points` (Open3D's fitness).
    pub fitness: f64,
    /// Root mean square distance over the inliers; 0 without inliers (Open3D's inlier_rmse).
    pub inlier_rmse: f64,
}

/// Open3D's score of a transform (`GetRegistrationResultAndCorrespondences`): each source point,
/// moved by `transform`, is paired with its nearest target point when that is strictly closer
/// than `max_distance`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Score {
    /// Number of source points paired.
    pub inlier_count: usize,
    /// `inlier_count / source points`; 0 for an empty source.
    pub fitness: f64,
    /// `sqrt(Σ d² / inlier_count)`; 0 without inliers.
    pub inlier_rmse: f64,
}

/// Scores `transform` and, when `pairs` is given, fills it with the (source, target) index pairs.
pub fn score(
    source: &[Point3<f64>],
    target: &KnnIndex,
    transform: &RigidTransform,
    max_distance: f64,
    mut pairs: Option<&mut Vec<(usize, usize)>>,
) -> Score {
    if let Some(p) = pairs.as_deref_mut() {
        p.clear();
    }
    let mut found = Vec::new(); // (N,)
    nearest_each(source, target, transform, max_distance, &mut found);
    let mut count = 0;
    let mut sum_d2 = 0.0;
    for (i, &nearest) in found.iter().enumerate() {
        if let Some((j, d)) = nearest {
            count += 1;
            sum_d2 += d * d;
            if let Some(p) = pairs.as_deref_mut() {
                p.push((i, j));
            }
        }
    }
    Score {
        inlier_count: count,
        fitness: if source.is_empty() {
            0.0
        } else {
            count as f64 / source.len() as f64
        },
        inlier_rmse: if count == 0 {
            0.0
        } else {
            (sum_d2 / count as f64).sqrt()
        },
    }
}

/// Points searched per piece of work in [`nearest_each`]: a fixed number, so that the pieces
/// are the same on any number of threads, and small, so that a cloud of a few hundred points
/// makes enough pieces for the threads to share evenly.
pub(crate) const NEAREST_BLOCK: usize = 64;

/// `found[i]`: the nearest point of `target` strictly closer than `max_distance` to
/// `source[i]` moved by `transform`, as (index, distance). Where `found` holds an answer for
/// `source` already (an earlier iteration's, under a transform near this one), each search
/// starts from it ([`KnnIndex::nearest_within_from`]): the same answers, sooner.
pub(crate) fn nearest_each(
    source: &[Point3<f64>],
    target: &KnnIndex,
    transform: &RigidTransform,
    max_distance: f64,
    found: &mut Vec<Option<(usize, f64)>>, // (N,)
) {
    // No state of its own: a slice of nothing, which allocates nothing.
    let mut none = vec![(); source.len()];
    nearest_each_by(source, transform, found, &mut none, |moved, earlier, _| {
        search_from(target, moved, max_distance, earlier)
    });
}

/// [`KnnIndex::nearest_within`], from an earlier answer where there is one.
pub(crate) fn search_from(
    target: &KnnIndex,
    query: &Point3<f64>,
    max_distance: f64,
    earlier: Option<(usize, f64)>,
) -> Option<(usize, f64)> {
    match earlier {
        Some((guess, _)) => target.nearest_within_from(query, max_distance, guess),
        None => target.nearest_within(query, max_distance),
    }
}

/// `found[i] = nearest(moved, earlier, &mut state[i])` for each point of `source` moved by
/// `transform`, where `earlier` is `found[i]` as it was when `found` held an answer for each
/// point already (else `None`), and `state[i]` is the point's own (`state` as long as
/// `source`). Blocks of points are searched side by side on rayon's pool, each point's search
/// its own, so the result is the same on any number of threads.
pub(crate) fn nearest_each_by<S: Send>(
    source: &[Point3<f64>],
    transform: &RigidTransform,
    found: &mut Vec<Option<(usize, f64)>>, // (N,)
    state: &mut [S],                       // (N,)
    nearest: impl Fn(&Point3<f64>, Option<(usize, f64)>, &mut S) -> Option<(usize, f64)> + Sync,
) {
    if found.len() != source.len() {
        found.clear();
        found.resize(source.len(), None);
    }
    found
        .par_chunks_mut(NEAREST_BLOCK)
        .zip(state.par_chunks_mut(NEAREST_BLOCK))
        .zip(source.par_chunks(NEAREST_BLOCK))
        .for_each(|((found, state), points)| {
            for ((answer, state), p) in found.iter_mut().zip(state).zip(points) {
                *answer = nearest(&transform.apply(p), *answer, state);
            }
        });
}

/// Of `source`'s points moved by `transform`: how many have a point of `target` strictly closer
/// than `near`, and how many closer than `far` (`near` at most `far`) — the counts
/// [`nearest_each`] would give, each search ending at the first point it needs
/// ([`KnnIndex::any_within`]), in its blocks side by side: the same counts on any number of
/// threads.
pub(crate) fn count_within(
    source: &[Point3<f64>],
    target: &KnnIndex,
    transform: &RigidTransform,
    near: f64,
    far: f64,
) -> (usize, usize) {
    let near = near.min(far);
    source
        .par_chunks(NEAREST_BLOCK)
        .map(|points| {
            let (mut within_near, mut within_far) = (0, 0);
            for p in points {
                let moved = transform.apply(p);
                if target.any_within(&moved, near) {
                    within_near += 1;
                    within_far += 1;
                } else if near < far && target.any_within(&moved, far) {
                    within_far += 1;
                }
            }
            (within_near, within_far)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// The share of `source`'s points moved by `transform` that have a point of `target` strictly
/// closer than `distance`: [`score`]'s fitness, counted with [`count_within`]; 0 for no points.
pub(crate) fn share_within(
    source: &[Point3<f64>],
    target: &KnnIndex,
    transform: &RigidTransform,
    distance: f64,
) -> f64 {
    if source.is_empty() {
        return 0.0;
    }
    count_within(source, target, transform, distance, distance).0 as f64 / source.len() as f64
}

impl Fit {
    /// A result for `transform` not scored: no inliers, fitness and RMSE 0 (what
    /// [`crate::Registrar::register_unscored`] may hand back, its caller scoring a transform of
    /// its own).
    pub fn unscored(t_target_source: RigidTransform, iterations: usize, converged: bool) -> Self {
        Self {
            t_target_source,
            iterations,
            converged,
            inlier_count: 0,
            fitness: 0.0,
            inlier_rmse: 0.0,
        }
    }

    /// A result for `transform` with its Open3D score.
    pub fn scored(
        t_target_source: RigidTransform,
        iterations: usize,
        converged: bool,
        score: Score,
    ) -> Self {
        Self {
            t_target_source,
            iterations,
            converged,
            inlier_count: score.inlier_count,
            fitness: score.fitness,
            inlier_rmse: score.inlier_rmse,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::{fgr, icp, refine};
    use nalgebra::{Matrix3, Vector3};
    use rand::{rngs::StdRng, SeedableRng};
    use rand_distr::{Distribution, Normal};
    use rgm_geom::testing::airplane;
    use rgm_geom::{PointCloud, Result};

    /// The cloud moved by `pose`, with the protocol's jitter (σ 0.01 clipped at 0.05) and its
    /// point order reversed (no index correspondence survives).
    fn moved_and_jittered(
        cloud: &PointCloud,
        pose: &RigidTransform,
        rng: &mut StdRng,
    ) -> PointCloud {
        let noise = Normal::new(0.0f64, 0.01).expect("a valid σ");
        let mut jitter = || noise.sample(rng).clamp(-0.05, 0.05);
        let mut points: Vec<Point3<f64>> = cloud
            .points
            .iter()
            .map(|p| pose.apply(p) + Vector3::new(jitter(), jitter(), jitter()))
            .collect();
        points.reverse();
        PointCloud::new(points)
    }

    /// small_gicp's accuracy check, run over every method: for seeded poses, registering the
    /// source onto the target and the target onto the source both land within 2.5° and 0.2 of
    /// the truth. Returns the worst (rotation °, translation) seen.
    fn check_both_directions(
        method: impl Fn(&PointCloud, &PointCloud) -> Result<Fit>,
        max_angle_deg: f64,
        max_translation: f64,
        seeds: std::ops::Range<u64>,
    ) -> (f64, f64) {
        let target = airplane();
        let mut worst: (f64, f64) = (0.0, 0.0);
        for seed in seeds {
            let mut rng = StdRng::seed_from_u64(seed);
            let g = RigidTransform::random(&mut rng, max_angle_deg, max_translation);
            let source = moved_and_jittered(&target, &g, &mut rng);
            let gt = g.inverse(); // maps the source onto the target
            for (from, to, truth) in [(&source, &target, gt), (&target, &source, g)] {
                let t = method(from, to).expect("registration").t_target_source;
                let residual = truth.inverse().compose(&t);
                let (angle, shift) = (residual.rotation_angle_deg(), residual.translation.norm());
                assert!(
                    angle < 2.5 && shift < 0.2,
                    "seed {seed}: error {angle:.3}°, {shift:.4}"
                );
                worst = (worst.0.max(angle), worst.1.max(shift));
            }
        }
        worst
    }

    #[test]
    fn degenerate_clouds_give_finite_results_not_panics() {
        let line: Vec<Point3<f64>> = (0..50)
            .map(|i| Point3::new(0.02 * i as f64, 0.0, 0.0))
            .collect();
        let clouds = [
            vec![Point3::new(0.1, 0.2, 0.3)],
            vec![Point3::new(0.1, 0.2, 0.3); 3],
            vec![Point3::new(0.1, 0.2, 0.3); 200],
            line,
        ];
        for points in clouds {
            let cloud = PointCloud::new(points);
            let results = [
                icp::register(&cloud, &cloud, &icp::IcpConfig::default()).unwrap(),
                fgr::register(&cloud, &cloud, &fgr::FgrConfig::default()).unwrap(),
                refine::refine(
                    &cloud,
                    &cloud,
                    &RigidTransform::identity(),
                    &refine::RefineConfig::default(),
                )
                .unwrap(),
            ];
            for r in results {
                let m = r.t_target_source.to_matrix4();
                assert!(
                    m.iter().all(|v| v.is_finite()),
                    "{} points: {m}",
                    cloud.len()
                );
                assert!(r.fitness.is_finite() && r.inlier_rmse.is_finite());
            }
        }
    }

    #[test]
    fn icp_from_small_perturbations_is_accurate_both_ways() {
        let worst = check_both_directions(
            |s, t| icp::register(s, t, &icp::IcpConfig::default()),
            10.0,
            0.05,
            0..5,
        );
        println!("ICP worst error: {:.3}°, {:.4}", worst.0, worst.1);
    }

    #[test]
    fn fgr_from_protocol_poses_is_accurate_both_ways() {
        let worst = check_both_directions(
            |s, t| fgr::register(s, t, &fgr::FgrConfig::default()),
            45.0,
            0.5,
            0..5,
        );
        println!("FGR worst error: {:.3}°, {:.4}", worst.0, worst.1);
    }

    #[test]
    fn score_by_hand() {
        // Source shifted by +0.1 x lands at 0.1, 1.1 and 5.1 on the x axis: 0.1 from targets 0
        // and 1, while 5.1 is far from all. With max distance 0.15: 2 of 3 inliers, rmse 0.1.
        let source = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(5.0, 0.0, 0.0),
        ];
        let target = vec![
            Point3::new(0.2, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 3.0, 0.0),
        ];
        let t = RigidTransform::new(Matrix3::identity(), Vector3::new(0.1, 0.0, 0.0));
        let mut pairs = Vec::new();
        let s = score(&source, &KnnIndex::new(&target), &t, 0.15, Some(&mut pairs));
        assert_eq!(s.inlier_count, 2);
        assert!((s.fitness - 2.0 / 3.0).abs() < 1e-15);
        assert!((s.inlier_rmse - 0.1).abs() < 1e-12);
        assert_eq!(pairs, vec![(0, 0), (1, 1)]);
        // With max distance 0.05 nothing is paired: fitness and rmse are 0, not NaN.
        let none = score(&source, &KnnIndex::new(&target), &t, 0.05, None);
        assert_eq!(
            none,
            Score {
                inlier_count: 0,
                fitness: 0.0,
                inlier_rmse: 0.0
            }
        );
    }

    /// The airplane (target, indexed) and a copy of it moved by a pose `g` of up to 20° and
    /// 0.2 drawn from `seed`, jittered and reversed (source): (target, g, source, index).
    fn airplane_pair(seed: u64) -> (PointCloud, RigidTransform, PointCloud, KnnIndex) {
        let target = airplane();
        let mut rng = StdRng::seed_from_u64(seed);
        let g = RigidTransform::random(&mut rng, 20.0, 0.2);
        let source = moved_and_jittered(&target, &g, &mut rng);
        let index = KnnIndex::new(&target.points);
        (target, g, source, index)
    }

    #[test]
    fn counts_within_are_the_nearest_searches_counts() {
        // 1,024 jittered points against the airplane: pairs near, far and out of reach.
        let (_, g, source, index) = airplane_pair(11);
        let mut found = Vec::new();
        nearest_each(&source.points, &index, &g.inverse(), 0.03, &mut found);
        let near = found.iter().flatten().filter(|&&(_, d)| d < 0.01).count();
        let far = found.iter().flatten().count();
        assert!(0 < near && near < far && far < source.len(), "{near} {far}");
        let counts = count_within(&source.points, &index, &g.inverse(), 0.01, 0.03);
        assert_eq!(counts, (near, far));
        let share = share_within(&source.points, &index, &g.inverse(), 0.03);
        assert_eq!(
            share,
            score(&source.points, &index, &g.inverse(), 0.03, None).fitness
        );
        assert_eq!(share_within(&[], &index, &g, 0.03), 0.0);
    }

    #[test]
    fn scores_and_refinements_are_the_same_bits_on_one_and_two_threads() {
        // 1,024 points: several blocks of nearest-point searches, spread over the pool.
        let (target, g, source, index) = airplane_pair(7);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut pairs = Vec::new();
                let scored = score(&source.points, &index, &g.inverse(), 0.05, Some(&mut pairs));
                let refined = refine::refine(
                    &source,
                    &target,
                    &RigidTransform::identity(),
                    &refine::RefineConfig::default(),
                )
                .unwrap();
                (scored, pairs, refined)
            })
        };
        let one = run(1);
        assert!(one.0.inlier_count > 500, "{:?}", one.0);
        assert_eq!(one, run(2));
    }
}
