//! The checkpoint path and the test-time procedure.
//!
//! `fixtures/rgm_tiny_state_dict.safetensors` is what a converted PyTorch checkpoint looks like
//! (the authors' names, 4-D conv weights, float32), written by
//! `python3 tools/reference/rgm_reference.py export --preset tiny --points 48 --out …`, with a
//! 48×48 pair and PyTorch's evaluation-mode C̃ for it.

use std::path::PathBuf;

use ndarray::Array2;
use rgm_geom::frame::Normalisation;
use rgm_geom::{Point3, PointCloud, RigidTransform, Vector3};
use rgm_match::{hard_match, MatchConfig};
use rgm_model::evaluate::evaluate_pair;
use rgm_model::network::{
    Config, Edges, FeaturerCache, Mode, Rgm, RgmCache, Scoring, TestStatistics,
};
use rgm_model::policy::TUNED;
use rgm_model::{Method, MethodError, ProcedureConfig, Registrar, RgmRegistrar};
use rgm_registration::compose::{Normalised, Refined};
use rgm_registration::methods::refine::{refine, RefineConfig};

/// RGM as `rgm register --method rgm --no-refine` runs it: in the network's frame.
fn normalised(network: Rgm<f32>, config: ProcedureConfig) -> Normalised<RgmRegistrar> {
    Normalised::new(RgmRegistrar::new(network, config), TUNED.frame)
}

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rgm_tiny_state_dict.safetensors")
}

fn tensor(name: &str) -> Array2<f32> {
    let (tensors, _) = rgm_nn::io::read_tensors::<f32>(&fixture()).unwrap();
    tensors[name].clone().into_dimensionality().unwrap()
}

fn cloud(rows: &Array2<f32>) -> PointCloud {
    PointCloud::new(
        rows.rows()
            .into_iter()
            .map(|r| Point3::new(r[0] as f64, r[1] as f64, r[2] as f64))
            .collect(),
    )
}

#[test]
fn a_pytorch_state_dict_loads_and_gives_pytorchs_c_soft() {
    let mut network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (x, y, expected) = (
        tensor("input.x"),
        tensor("input.y"),
        tensor("output.c_soft_eval"),
    );
    let mut cache = RgmCache::default();
    network
        .forward(x.view(), y.view(), Mode::Eval, &mut cache)
        .unwrap();
    let worst = cache
        .c_soft()
        .iter()
        .zip(expected.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "largest |ΔC̃| = {worst}");
}

#[test]
fn the_procedure_uses_only_cycle_consistent_one_to_one_pairs() {
    let network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (source, target) = (cloud(&tensor("input.x")), cloud(&tensor("input.y")));
    let one_way = ProcedureConfig {
        passes: 1,
        cycle_consistency: false,
        ..Default::default()
    };
    let both_ways = ProcedureConfig {
        passes: 1,
        ..Default::default()
    };
    let outcome = |config| {
        normalised(network.clone(), config)
            .register(&source, &target)
            .map(|found| found.result)
    };
    match (outcome(one_way), outcome(both_ways)) {
        (Ok(a), Ok(b)) => {
            // Cycle consistency keeps a subset of the one-way pairs.
            assert!(
                b.inlier_count <= a.inlier_count && a.inlier_count <= 48,
                "{} vs {}",
                b.inlier_count,
                a.inlier_count
            );
            assert!((b.t_target_source.rotation.determinant() - 1.0).abs() < 1e-9);
            assert!((b.fitness - b.inlier_count as f64 / 48.0).abs() < 1e-12);
        }
        // Random weights may leave too few pairs for Kabsch: then it must say so, not panic.
        (_, Err(err)) => assert!(
            matches!(
                err,
                MethodError::Geom(_) | MethodError::NoCorrespondences { .. }
            ),
            "{err}"
        ),
        (Err(err), Ok(_)) => {
            panic!("one-way matching failed where cycle-consistent matching did not: {err}")
        }
    }
}

#[test]
fn rgm_weights_of_the_wrong_size_are_a_named_error() {
    let err = rgm_model::weights::load_registrar(Config::small(), &fixture()).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("pointfeaturer.conv1.weight") || text.contains("expected"),
        "{text}"
    );
}

fn fixture_pair() -> (PointCloud, PointCloud) {
    (cloud(&tensor("input.x")), cloud(&tensor("input.y")))
}

fn assert_same_transform(a: &RigidTransform, b: &RigidTransform, tol: f64) {
    let (dr, dt) = (
        (a.rotation - b.rotation).abs().max(),
        (a.translation - b.translation).abs().max(),
    );
    assert!(dr < tol && dt < tol, "ΔR {dr}, Δt {dt}");
}

#[test]
fn features_computed_once_give_bit_identical_c_soft_both_ways() {
    let mut network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (x, y) = (tensor("input.x"), tensor("input.y"));
    let (mut fx, mut fy) = (FeaturerCache::default(), FeaturerCache::default());
    network.features(x.view(), &mut fx).unwrap();
    network.features(y.view(), &mut fy).unwrap();
    for (a, b, fa, fb) in [
        (&x, &y, &fx.features, &fy.features),
        (&y, &x, &fy.features, &fx.features),
    ] {
        let (mut plain, mut reused) = (RgmCache::default(), RgmCache::default());
        network
            .forward(a.view(), b.view(), Mode::Eval, &mut plain)
            .unwrap();
        network
            .forward_from_features(fa.view(), fb.view(), &mut reused)
            .unwrap();
        assert_eq!(plain.c_soft().dim(), (48, 48));
        assert_eq!(plain.c_soft(), reused.c_soft());
    }
}

#[test]
fn the_reverse_pass_reusing_block_0_is_bit_identical_to_running_it() {
    // Trained weights (the fixture) with transformer edges, and the same network with
    // full-connection edges (Var2) and distance scoring (Var1): the reuse must hold for each.
    let trained = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let variants = [
        trained,
        Rgm::<f32>::new(
            Config {
                edges: Edges::Full,
                ..Config::tiny()
            },
            3,
        )
        .unwrap(),
        Rgm::<f32>::new(
            Config {
                scoring: Scoring::Var1,
                ..Config::tiny()
            },
            4,
        )
        .unwrap(),
    ];
    let (x, y) = (tensor("input.x"), tensor("input.y"));
    // Unequal sizes, so a transposed shape cannot pass unnoticed.
    let y = y.slice(ndarray::s![..40, ..]).to_owned();
    for network in variants {
        let (mut fx, mut fy) = (FeaturerCache::default(), FeaturerCache::default());
        network.features(x.view(), &mut fx).unwrap();
        network.features(y.view(), &mut fy).unwrap();
        let (fx, fy) = (fx.features.view(), fy.features.view());
        let (mut forward, mut reverse) = (RgmCache::default(), RgmCache::default());
        let (mut plain_forward, mut plain_reverse) = (RgmCache::default(), RgmCache::default());
        network
            .forward_both(fx, fy, &mut forward, &mut reverse)
            .unwrap();
        network
            .forward_from_features(fx, fy, &mut plain_forward)
            .unwrap();
        network
            .forward_from_features(fy, fx, &mut plain_reverse)
            .unwrap();
        assert_eq!(reverse.c_soft().dim(), (40, 48));
        assert_eq!(plain_forward.c_soft(), forward.c_soft());
        assert_eq!(plain_reverse.c_soft(), reverse.c_soft());
        // Not merely the transpose of the forward's C̃ (Sinkhorn's rows-first order).
        assert_ne!(forward.c_soft().t(), reverse.c_soft());
    }
}

#[test]
fn no_backward_follows_a_pass_from_given_features() {
    let mut network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let x = tensor("input.x");
    let mut fx = FeaturerCache::default();
    network.features(x.view(), &mut fx).unwrap();
    let mut cache = RgmCache::default();
    network
        .forward_from_features(fx.features.view(), fx.features.view(), &mut cache)
        .unwrap();
    let dc = Array2::<f32>::ones((48, 48));
    let err = network.backward(dc.view(), &mut cache).unwrap_err();
    assert!(err.to_string().contains("forward_from_features"), "{err}");
    let narrow = Array2::<f32>::zeros((48, 3));
    let err = network
        .forward_from_features(narrow.view(), fx.features.view(), &mut cache)
        .unwrap_err();
    assert!(err.to_string().contains("[48, 3]"), "{err}");
}

#[test]
fn the_procedure_reports_the_correspondences_the_plain_network_finds() {
    // One pass, cycle consistent: the registrar (features reused) must find exactly the pairs
    // of the plain forward in both directions.
    let mut network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (x, y) = (tensor("input.x"), tensor("input.y"));
    let matching = MatchConfig {
        inlier_threshold: 0.5,
    };
    let (mut xy, mut yx) = (RgmCache::default(), RgmCache::default());
    network
        .forward(x.view(), y.view(), Mode::Eval, &mut xy)
        .unwrap();
    network
        .forward(y.view(), x.view(), Mode::Eval, &mut yx)
        .unwrap();
    let expected = hard_match(xy.c_soft(), &matching)
        .unwrap()
        .cycle_consistent(&hard_match(yx.c_soft(), &matching).unwrap())
        .unwrap();
    let (source, target) = fixture_pair();
    let config = ProcedureConfig {
        passes: 1,
        ..Default::default()
    };
    let found = normalised(network, config)
        .register(&source, &target)
        .unwrap();
    assert!(!expected.pairs().is_empty());
    assert_eq!(found.correspondences, expected.pairs());
    assert_eq!(found.result.inlier_count, expected.pairs().len());
}

#[test]
fn benchmark_pairs_are_used_as_they_are() {
    // Full clouds reach exactly 1 from their centre: every pair is in the training frame. Two
    // crops of an elongated shape can both lose its far ends (extent down to 0.36): those are
    // in it too, as the network was trained on them.
    let data =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024");
    let dataset = rgm_data::ModelNet40::open(&data).unwrap();
    let shapes = dataset.split(rgm_data::Split::Test, false);
    for (setting, at_least) in [
        (rgm_data::Setting::Clean, 1.0),
        (rgm_data::Setting::Noise, 1.0),
        (rgm_data::Setting::Partial, 1.0),
    ] {
        let generator = rgm_data::PairGenerator::new(setting);
        let indices: Vec<usize> = (0..shapes.len()).step_by(7).collect();
        let kept = indices
            .iter()
            .filter(|&&i| {
                let pair = generator.test_pair(&shapes, i).unwrap();
                Normalisation::of_pair(&pair.source, &pair.target, &TUNED.frame).is_identity()
            })
            .count();
        let share = kept as f64 / indices.len() as f64;
        assert!(
            share >= at_least,
            "{setting:?}: {kept} of {}",
            indices.len()
        );
    }
}

#[test]
fn a_pair_at_a_tenth_or_four_times_the_size_reaches_the_network_centred_alike() {
    let (source, target) = fixture_pair();
    let frames: Vec<(PointCloud, PointCloud)> = [0.1, 4.0]
        .iter()
        .map(|&k| {
            let scaled = |c: &PointCloud| PointCloud::new(c.points.iter().map(|p| p * k).collect());
            let (s, t) = (scaled(&source), scaled(&target));
            let frame = Normalisation::of_pair(&s, &t, &TUNED.frame);
            assert!(!frame.is_identity(), "×{k}");
            (frame.source(&s), frame.target(&t))
        })
        .collect();
    for (a, b) in frames[0].0.points.iter().zip(&frames[1].0.points) {
        assert!((a - b).norm() < 1e-12);
    }
    for (a, b) in frames[0].1.points.iter().zip(&frames[1].1.points) {
        assert!((a - b).norm() < 1e-12);
    }
}

/// The fixture pair, enlarged 40× and moved far from the origin, each cloud differently.
fn far_and_large(source: &PointCloud, target: &PointCloud) -> (PointCloud, PointCloud) {
    let warp = |c: &PointCloud, shift: Vector3<f64>| {
        PointCloud::new(c.points.iter().map(|p| p * 40.0 + shift).collect())
    };
    (
        warp(source, Vector3::new(100.0, -20.0, 3.0)),
        warp(target, Vector3::new(-7.0, 55.0, 12.0)),
    )
}

#[test]
fn normalisation_is_undone_on_the_transform() {
    // Exact correspondences solved in the network's frame give the caller's transform.
    let (source, _) = fixture_pair();
    let truth = RigidTransform::new(
        rgm_geom::euler::rotation_xyz_intrinsic(0.3, -0.2, 0.5),
        Vector3::new(4.0, -1.0, 2.5),
    );
    let target = source.transformed(&truth);
    let (big_source, big_target) = far_and_large(&source, &target);
    // In the caller's frame: big_target = R big_source + t_big.
    let t_big = rgm_geom::kabsch(
        &big_source.points,
        &big_target.points,
        &vec![1.0; source.len()],
    )
    .unwrap();
    let frame = Normalisation::of_pair(&big_source, &big_target, &TUNED.frame);
    assert!(!frame.is_identity());
    let (ns, nt) = (frame.source(&big_source), frame.target(&big_target));
    let farthest = ns.points.iter().chain(&nt.points).map(|p| p.coords.norm());
    assert!((farthest.fold(0.0, f64::max) - 1.0).abs() < 1e-12);
    let in_frame = rgm_geom::kabsch(&ns.points, &nt.points, &vec![1.0; source.len()]).unwrap();
    assert_same_transform(&frame.undo(&in_frame), &t_big, 1e-9);
    // And back: the caller's transform in the network's frame.
    assert_same_transform(&frame.redo(&t_big), &in_frame, 1e-9);
}

#[test]
fn far_large_clouds_register_as_their_normalised_copies() {
    let network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (source, target) = far_and_large(&fixture_pair().0, &fixture_pair().1);
    let frame = Normalisation::of_pair(&source, &target, &TUNED.frame);
    let (ns, nt) = (frame.source(&source), frame.target(&target));
    assert!(Normalisation::of_pair(&ns, &nt, &TUNED.frame).is_identity());
    let config = ProcedureConfig {
        passes: 1,
        cycle_consistency: false,
        ..Default::default()
    };
    let big = normalised(network.clone(), config.clone())
        .register(&source, &target)
        .unwrap();
    let small = RgmRegistrar::new(network, config)
        .register(&ns, &nt)
        .unwrap();
    assert_eq!(big.correspondences, small.correspondences);
    assert!(!big.correspondences.is_empty());
    assert_same_transform(
        &big.result.t_target_source,
        &frame.undo(&small.result.t_target_source),
        1e-9,
    );
}

#[test]
fn refinement_starts_from_rgms_transform() {
    let network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (source, target) = fixture_pair();
    let plain = ProcedureConfig {
        passes: 1,
        cycle_consistency: false,
        ..Default::default()
    };
    let rgm = normalised(network.clone(), plain.clone())
        .register(&source, &target)
        .unwrap()
        .result;
    let mut registrar = Normalised::new(
        Refined::new(RgmRegistrar::new(network, plain), RefineConfig::default()),
        TUNED.frame,
    );
    let both = registrar.register(&source, &target).unwrap().result;
    let expected = refine(
        &source,
        &target,
        &rgm.t_target_source,
        &RefineConfig::default(),
    )
    .unwrap();
    assert_same_transform(&both.t_target_source, &expected.t_target_source, 1e-12);
    assert_eq!(both.iterations, 1 + expected.iterations);
    // The refinement's score.
    assert_eq!(both.inlier_count, expected.inlier_count);
    assert!((both.fitness - expected.fitness).abs() < 1e-12);
    assert!((both.inlier_rmse - expected.inlier_rmse).abs() < 1e-12);
    assert!(both.inlier_rmse < rgm.inlier_rmse, "{both:?} {rgm:?}");
}

#[test]
fn a_record_refined_afterwards_is_what_the_refined_method_records() {
    // Far and large clouds: the refinement runs in the network's frame, not the caller's; a
    // far outlier in the source is left out of both as the method leaves it out.
    let network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (mut source, target) = far_and_large(&fixture_pair().0, &fixture_pair().1);
    let far = source.points[0] + Vector3::new(1e4, 0.0, 0.0);
    source.points.push(far);
    let pair = rgm_data::Pair {
        correspondence: rgm_data::Correspondence {
            n_source: source.len(),
            n_target: target.len(),
            pairs: (0..source.len().min(target.len()))
                .map(|i| (i, i))
                .collect(),
        },
        t_target_source: RigidTransform::identity(),
        source,
        target,
        shape_index: 0,
        label: 0,
    };
    let plain = ProcedureConfig {
        passes: 1,
        ..Default::default()
    };
    let plain_method = Method::new(normalised(network.clone(), plain.clone()));
    let record = evaluate_pair(&mut plain_method.clone(), 3, &pair).unwrap();
    let mut refined_method = Method::new(Normalised::new(
        Refined::new(RgmRegistrar::new(network, plain), RefineConfig::default()),
        TUNED.frame,
    ));
    let expected = evaluate_pair(&mut refined_method, 3, &pair).unwrap();
    let refined = record.refined(&pair, &RefineConfig::default()).unwrap();
    // The same refinement from the same start, up to the rounding of leaving the network's
    // frame and coming back (clouds 40 across, 100 from the origin).
    assert_same_transform(&refined.transform, &expected.transform, 1e-6);
    assert_ne!(refined.transform, record.transform);
    assert_eq!(refined.metrics.recall, expected.metrics.recall);
    assert_eq!(refined.correspondences, expected.correspondences);
    assert!(refined.time_ms >= record.time_ms);
}

#[test]
fn clouds_smaller_than_the_neighbourhood_are_a_clear_error() {
    let network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (source, target) = fixture_pair();
    let small = source.select(&[0, 1, 2, 3]); // K = 4 points, the network needs 5
    let mut registrar = RgmRegistrar::new(network, ProcedureConfig::default());
    let err = registrar.register(&source, &small).unwrap_err();
    assert_eq!(
        err.to_string(),
        "rgm: the target cloud has 4 points to match; the network needs at least 5 (K + 1)"
    );
    registrar.config.match_points = Some(3);
    let err = registrar.register(&source, &target).unwrap_err();
    assert!(matches!(
        err,
        MethodError::TooFewPoints {
            cloud: "source",
            points: 3,
            needed: 5
        }
    ));
}

#[test]
fn one_two_and_three_threads_register_to_the_same_bits() {
    // The chains, the clouds' features and each block's sides run side by side on a pool of
    // several threads; every piece is computed as on one thread. Both batch-norm statistics.
    let (source, target) = fixture_pair();
    for statistics in [TestStatistics::Running, TestStatistics::Cloud] {
        let mut network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
        network.featurer.test_statistics = statistics;
        let outcomes: Vec<_> = [1, 2, 3]
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut registrar = normalised(network.clone(), ProcedureConfig::default());
                let found = pool
                    .install(|| registrar.register(&source, &target))
                    .unwrap();
                (found.result, found.correspondences)
            })
            .into();
        assert!(!outcomes[0].1.is_empty());
        assert_eq!(outcomes[0], outcomes[1], "{statistics:?}");
        assert_eq!(outcomes[0], outcomes[2], "{statistics:?}");
    }
}
