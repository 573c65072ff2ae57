//! FGR's tests (beside fgr.rs, which they would take past 800 lines).

use super::*;
use rgm_geom::testing::box_surface;
use rgm_geom::KnnIndex;

fn feature(values: &[(usize, f64)]) -> Fpfh {
    let mut f = [0.0; 33];
    for &(c, v) in values {
        f[c] = v;
    }
    f
}

/// The tiled matching against a brute-force one, on features of small integers (exact
/// sums, many ties) and sizes that leave the last tile partial.
#[test]
fn mutual_matches_match_brute_force_with_ties() {
    let mut rng = StdRng::seed_from_u64(5);
    let mut random = |n: usize| -> Vec<Fpfh> {
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.gen_range(0..3) as f64))
            .collect()
    };
    let (source, target) = (random(37), random(2 * TILE + 3));
    let d2 = |a: &Fpfh, b: &Fpfh| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>();
    // The first index at the least distance, by plain scans.
    let nearest = |a: &Fpfh, others: &[Fpfh]| {
        (0..others.len()).fold(0, |best, j| {
            if d2(a, &others[j]) < d2(a, &others[best]) {
                j
            } else {
                best
            }
        })
    };
    let expected: Vec<(usize, usize)> = (0..source.len())
        .map(|i| (i, nearest(&source[i], &target)))
        .filter(|&(i, j)| nearest(&target[j], &source) == i)
        .collect();
    assert!(expected.len() > 2, "{expected:?}");
    assert_eq!(mutual_matches(&source, &target), expected);
}

#[test]
fn mutual_matches_by_hand() {
    // Source features at 0, 10, 20 on channel 0; target at 1, 2, 19 (and 30).
    // Source 0 → target 0 (d 1); target 0 → source 0: mutual.
    // Source 10 → target 1 (d 8, vs 9 to 19); target 1 (2) → source 0 (d 2): not mutual.
    // Source 20 → target 2 (19); target 2 → source 2: mutual. Target 3 (30) → source 2: not.
    let s = [
        feature(&[(0, 0.0)]),
        feature(&[(0, 10.0)]),
        feature(&[(0, 20.0)]),
    ];
    let t = [
        feature(&[(0, 1.0)]),
        feature(&[(0, 2.0)]),
        feature(&[(0, 19.0)]),
        feature(&[(0, 30.0)]),
    ];
    assert_eq!(mutual_matches(&s, &t), vec![(0, 0), (2, 2)]);
    // Ties go to the lowest index: two identical target features.
    let t = [feature(&[(5, 1.0)]), feature(&[(5, 1.0)])];
    assert_eq!(mutual_matches(&[feature(&[(5, 1.0)])], &t), vec![(0, 0)]);
}

#[test]
fn tuple_test_keeps_consistent_triples_only() {
    // Five true matches of a rigidly moved set and five wrong ones (targets shifted by one):
    // every kept match must be true (a wrong one would have to fit two others within 5% on
    // three sides).
    let target = box_surface(10, 11);
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(2), 45.0, 0.5);
    let source = target.transformed(&pose.inverse());
    let mut matches: Vec<(usize, usize)> = (0..5).map(|i| (i, i)).collect();
    matches.extend((5..10).map(|i| (i, 5 + (i - 4) % 5)));
    let config = FgrConfig::default();
    let kept = tuple_test(&source.points, &target.points, &matches, &config);
    assert!(kept.len() >= 30, "only {} kept", kept.len());
    assert_eq!(kept.len() % 3, 0);
    assert!(kept.iter().all(|&(i, j)| i == j), "{kept:?}");
    // The same seed draws the same triples.
    assert_eq!(
        kept,
        tuple_test(&source.points, &target.points, &matches, &config)
    );
}

#[test]
fn optimisation_recovers_a_pose_from_exact_matches() {
    // Exact matches (no outliers) from any starting pose: GNC converges to the true pose.
    let target = box_surface(200, 12);
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(4), 45.0, 0.5);
    let source = target.transformed(&pose.inverse());
    let matches: Vec<(usize, usize)> = (0..200).map(|i| (i, i)).collect();
    let (t, iterations, solved) = optimise(&source, &target, &matches, &FgrConfig::default());
    assert!(solved);
    assert_eq!(iterations, 64);
    let err = (t.to_matrix4() - pose.to_matrix4()).abs().max();
    assert!(err < 1e-9, "error {err:.3e}");
}

/// The tuple test as one loop, one triple at a time: what [`tuple_test`] keeps, in order.
fn tuple_test_in_one_loop(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    matches: &[(usize, usize)],
    config: &FgrConfig,
) -> Vec<(usize, usize)> {
    let n = matches.len();
    let mut rng = StdRng::seed_from_u64(config.seed);
    let mut kept = Vec::new();
    for _ in 0..100 * n {
        let triple = [0; 3].map(|_| matches[rng.gen_range(0..n)]);
        if consistent(source, target, triple, config.tuple_scale) {
            kept.extend_from_slice(&triple);
            if kept.len() >= 3 * config.maximum_tuple_count {
                break;
            }
        }
    }
    kept
}

/// A box surface of `n` points (the target), the source it is moved from by a random pose,
/// that pose, and the matches i → i with every `wrong`-th one sent elsewhere.
fn pair_with_wrong_matches(
    n: usize,
    seed: u64,
    wrong: usize,
) -> (PointCloud, PointCloud, RigidTransform, Vec<(usize, usize)>) {
    let target = box_surface(n, seed);
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(seed), 30.0, 0.3);
    let source = target.transformed(&pose.inverse());
    let matches = (0..n)
        .map(|i| (i, if i % wrong == 0 { (i * 7 + 3) % n } else { i }))
        .collect();
    (source, target, pose, matches)
}

/// `f` on a rayon pool of `threads` threads.
fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn tuple_test_keeps_what_one_loop_keeps_on_one_worker_and_two() {
    // 300 matches, every third one wrong: 30,000 triples in 59 chunks.
    let (source, target, _, matches) = pair_with_wrong_matches(300, 13, 3);
    // Every triple tested; the count reached within a chunk; the count reached at once.
    for maximum_tuple_count in [100_000, 1000, 0] {
        let config = FgrConfig {
            maximum_tuple_count,
            ..FgrConfig::default()
        };
        let expected = tuple_test_in_one_loop(&source.points, &target.points, &matches, &config);
        assert!(expected.len() >= 3, "{} kept", expected.len());
        for threads in [1, 2, 3] {
            let kept = on_threads(threads, || {
                tuple_test(&source.points, &target.points, &matches, &config)
            });
            assert_eq!(
                kept, expected,
                "{threads} threads, at most {maximum_tuple_count}"
            );
        }
    }
}

/// The Gauss–Newton steps as one loop, one match at a time: what [`gauss_newton`] computes
/// on its halves, to the bit.
fn optimise_in_one_loop(
    p: &[Vector3<f64>],
    q: &[Vector3<f64>],
    mus: &[f64],
) -> (RigidTransform, bool) {
    let mut q = q.to_vec();
    let (mut trans, mut solved) = (RigidTransform::identity(), true);
    for &mu in mus {
        let mut sum = Sums::default();
        let mut sqq = Matrix3::<f64>::zeros();
        for (pi, qi) in p.iter().zip(&q) {
            let r = pi - qi;
            let l = mu / (r.norm_squared() + mu);
            let w = l * l;
            sum.sw += w;
            sum.sq += w * qi;
            sum.sr += w * r;
            sum.srq += w * r.cross(qi);
            sqq += w * (Matrix3::from_diagonal_element(qi.norm_squared()) - qi * qi.transpose());
        }
        match sum.step(&sqq) {
            Some(delta) => {
                trans = delta.compose(&trans);
                for qi in q.iter_mut() {
                    *qi = delta.rotation * *qi + delta.translation;
                }
            }
            None => solved = false,
        }
    }
    (trans, solved)
}

#[test]
fn gauss_newton_gives_the_same_bits_as_one_loop_on_one_worker_and_two() {
    // Enough matches for two workers, a fifth of them outliers, in a unit-sphere frame.
    let (source, target, _, matches) = pair_with_wrong_matches(1500, 21, 5);
    assert!(matches.len() >= SIDE_BY_SIDE_MATCHES);
    let p: Vec<Vector3<f64>> = matches
        .iter()
        .map(|&(i, _)| source.points[i].coords)
        .collect();
    let q: Vec<Vector3<f64>> = matches
        .iter()
        .map(|&(_, j)| target.points[j].coords)
        .collect();
    let mus: Vec<f64> = (0..64).map(|i| 2.0 / 1.4f64.powi(i / 4)).collect();
    let expected = optimise_in_one_loop(&p, &q, &mus);
    for threads in [1, 2, 3] {
        let (trans, solved) = on_threads(threads, || gauss_newton(&p, &q, &mus));
        assert_eq!(
            (trans.to_matrix4(), solved),
            (expected.0.to_matrix4(), expected.1)
        );
    }
    // The steps found the pose: p = R q + t for the true matches.
    let moved = expected.0.apply(&Point3::from(q[1]));
    assert!(
        (moved.coords - p[1]).norm() < 1e-3,
        "{moved} against {}",
        p[1]
    );
}

/// Pinned from Open3D 0.20 (`open3d-cpu`), exact correspondences, no tuple test, on the
/// airplane scaled by 0.5 (so that the normalising scale, 0.5, differs from 1):
///
/// ```python
/// pts = 0.5 * np.load('.../airplane/test/airplane_0627.npy').astype(np.float64)
/// R = Rotation.from_euler('xyz', [30, 20, 10], degrees=True).as_matrix(); t = np.array([0.3, -0.2, 0.1])
/// src, tgt = (pts - t) @ R, pts  # as PointClouds s, tt
/// corr = o3d.utility.Vector2iVector(np.stack([np.arange(1024)] * 2, 1).astype(np.int32))
/// opt = FastGlobalRegistrationOption(tuple_test=False, iteration_number=k, decrease_mu=dm)
/// r = registration_fgr_based_on_correspondence(s, tt, corr, opt); T = r.transformation
/// # rotation error (deg) of T vs R, |t_T − t|, r.fitness, r.inlier_rmse
/// ```
#[test]
fn optimisation_steps_match_open3d() {
    let target = PointCloud::new(
        rgm_geom::testing::airplane()
            .points
            .iter()
            .map(|p| Point3::from(0.5 * p.coords))
            .collect(),
    );
    let rotation =
        rotation_xyz_extrinsic(30f64.to_radians(), 20f64.to_radians(), 10f64.to_radians());
    let pose = RigidTransform::new(rotation, Vector3::new(0.3, -0.2, 0.1));
    let source = target.transformed(&pose.inverse());
    let matches: Vec<(usize, usize)> = (0..1024).map(|i| (i, i)).collect();
    let index = KnnIndex::new(&target.points);
    let cases = [
        (
            1,
            true,
            7.773801947570894,
            0.041863821940794604,
            0.8095703125,
            0.014035814446269975,
        ),
        (
            2,
            true,
            0.22390158191183837,
            0.0013228126614157805,
            1.0,
            0.0007874287562105823,
        ),
        (
            2,
            false,
            0.22387625491881621,
            0.0013228671957257242,
            1.0,
            0.0007873368500457115,
        ),
        (
            3,
            true,
            0.00013361489370883206,
            5.187654157751016e-07,
            1.0,
            5.294971508789419e-07,
        ),
    ];
    for (k, decrease_mu, angle, shift, fitness, rmse) in cases {
        let config = FgrConfig {
            iteration_number: k,
            decrease_mu,
            ..FgrConfig::default()
        };
        let (t, _, _) = optimise(&source, &target, &matches, &config);
        let got_angle = pose.inverse().compose(&t).rotation_angle_deg();
        let got_shift = (t.translation - pose.translation).norm();
        assert!(
            (got_angle - angle).abs() < 1e-6,
            "k={k} μ↓={decrease_mu}: angle {got_angle} vs {angle}"
        );
        assert!(
            (got_shift - shift).abs() < 1e-9,
            "k={k} μ↓={decrease_mu}: shift {got_shift} vs {shift}"
        );
        let s = score(
            &source.points,
            &index,
            &t,
            config.maximum_correspondence_distance,
            None,
        );
        assert_eq!(s.fitness, fitness, "k={k}");
        assert!(
            (s.inlier_rmse - rmse).abs() < 1e-9,
            "k={k}: rmse {} vs {rmse}",
            s.inlier_rmse
        );
    }
}

/// Issue 14, case 8: FGR matched every point of large clouds with every other (time
/// quadratic in the points) and said nothing meanwhile.
#[test]
fn large_clouds_are_downsampled_and_scored_whole() {
    let target = box_surface(20_000, 21);
    let pose = RigidTransform::random(&mut StdRng::seed_from_u64(22), 30.0, 0.3);
    let source = target.transformed(&pose.inverse());
    let config = FgrConfig {
        max_points: 1500,
        ..FgrConfig::default()
    };
    let small = downsampled(&target, config.max_points).expect("more points than max_points");
    assert!(
        small.len() <= 1500 && small.len() > 1500 / 3,
        "{}",
        small.len()
    );
    let mut seen = Vec::new();
    let result = register_with_progress(&source, &target, &config, &mut |p| seen.push(p)).unwrap();
    // Unrefined FGR on voxel means (which differ between the two clouds' grids): within
    // 3° and 0.03 of the pose.
    let off = result.t_target_source.compose(&pose.inverse());
    let angle = ((off.rotation.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees();
    assert!(
        angle < 3.0 && off.translation.norm() < 0.03,
        "{angle}° {off:?}"
    );
    // Scored on the full clouds.
    let whole = score(
        &source.points,
        &KnnIndex::new(&target.points),
        &result.t_target_source,
        config.maximum_correspondence_distance,
        None,
    );
    assert_eq!(result.fitness, whole.fitness);
    assert!(result.fitness > 0.5, "{}", result.fitness);
    assert_eq!(seen.first().map(|p| p.step), Some("downsampling"));
    assert_eq!(seen.last().map(|p| p.done), Some(1.0));
    assert!(seen.windows(2).all(|w| w[0].done <= w[1].done));
    assert!(seen.iter().filter(|p| p.step == "matching").count() > 32);
}

#[test]
fn too_few_matches_give_the_identity() {
    // Five points give at most five matches (without the tuple test, which repeats them).
    let cloud = box_surface(5, 13);
    let config = FgrConfig {
        tuple_test: false,
        ..FgrConfig::default()
    };
    let result = register(&cloud, &cloud, &config).unwrap();
    assert_eq!(result.t_target_source, RigidTransform::identity());
    assert!(!result.converged);
    assert_eq!(result.iterations, 0);
    assert_eq!(result.fitness, 1.0);
}

#[test]
fn bad_inputs_are_errors() {
    let c = box_surface(20, 14);
    let f = vec![[0.0; 33]; 19];
    assert!(matches!(
        register_features(&c, &c, &f, &f, &FgrConfig::default()),
        Err(GeomError::LengthMismatch { .. })
    ));
    let bad = FgrConfig {
        division_factor: 1.0,
        ..FgrConfig::default()
    };
    assert!(matches!(
        register(&c, &c, &bad),
        Err(GeomError::Degenerate { .. })
    ));
    assert!(matches!(
        register(&PointCloud::default(), &c, &FgrConfig::default()),
        Err(GeomError::TooFewPoints { .. })
    ));
}
