//! `auto`, `rgm register`'s default: the candidate that overlaps better wins, a
//! result that overlaps enough spares the network, a failed candidate leaves the other, and the
//! pair's size does not matter.

use std::path::PathBuf;

use rgm_data::{ModelNet40, PairGenerator, Setting, Split};
use rgm_geom::{PairMetrics, Point3, PointCloud, RigidTransform};
use rgm_model::network::{Config, Rgm};
use rgm_model::policy::TUNED;
use rgm_model::{
    Method, MethodError, MethodOptions, ProcedureConfig, Registrar, Registration, RgmRegistrar,
};
use rgm_registration::methods::refine::RefineConfig;
use rgm_registration::AllCandidatesFailed;

/// The tiny network of `tests/fixtures` (random weights: its transforms are poor).
fn tiny_rgm() -> RgmRegistrar {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/rgm_tiny_state_dict.safetensors");
    let network = Rgm::load(Config::tiny(), &path).unwrap();
    RgmRegistrar::new(
        network,
        ProcedureConfig {
            match_points: Some(200),
            ..ProcedureConfig::default()
        },
    )
}

/// Test pair 0 of the clean setting: the same 1,024 points at another pose.
fn clean_pair() -> rgm_data::Pair {
    let data =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024");
    let dataset = ModelNet40::open(&data).unwrap();
    let shapes = dataset.split(Split::Test, false);
    PairGenerator::new(Setting::Clean)
        .test_pair(&shapes, 0)
        .unwrap()
}

/// The names of the candidates `found` ran, in order.
fn candidate_names(found: &Registration) -> Vec<&str> {
    found.candidates.iter().map(|c| c.method.as_str()).collect()
}

/// The paper's metrics of `found`'s transform on `pair`.
fn metrics_against_truth(found: &Registration, pair: &rgm_data::Pair) -> PairMetrics {
    PairMetrics::compute(
        &found.result.t_target_source,
        &pair.t_target_source,
        &pair.source,
        &pair.target,
    )
    .unwrap()
}

/// `auto+refine` with `rgm`, both candidates on every pair.
fn auto_with(rgm: RgmRegistrar) -> Method {
    let never = rgm_registration::check::Acceptance::NEVER;
    rgm_model::options::auto(
        rgm,
        Some(RefineConfig::default()),
        never,
        rgm_model::options::DenseStage::ObjectThenScene,
    )
}

/// `rgm register`'s default, but both candidates on every pair.
fn both_candidates() -> Method {
    MethodOptions {
        accept: f64::INFINITY,
        ..MethodOptions::default()
    }
    .build()
    .unwrap()
}

#[test]
fn a_first_result_that_overlaps_enough_spares_the_network() {
    // FGR registers the clean pair: its result overlaps nearly every point both ways, above
    // the default's threshold, so the network does not run.
    let pair = clean_pair();
    let mut method = MethodOptions::default().build().unwrap();
    assert_eq!(method.name(), "auto+refine");
    let found = method.register(&pair.source, &pair.target).unwrap();
    let names = candidate_names(&found);
    assert_eq!(names, ["fgr+refine"]);
    assert!(found.candidates[0].score.unwrap() > 1.9, "{found:?}");
    assert_eq!(found.chosen, Some(0));
    let metrics = metrics_against_truth(&found, &pair);
    assert!(metrics.recall && metrics.mie_r_deg < 0.05, "{metrics:?}");
    // A threshold above any score (at most 2) runs the network too.
    let mut method = MethodOptions {
        accept: 2.5,
        ..MethodOptions::default()
    }
    .build()
    .unwrap();
    let found = method.register(&pair.source, &pair.target).unwrap();
    assert_eq!(found.candidates.len(), 2);
}

#[test]
fn the_candidate_that_overlaps_better_wins() {
    // Both candidates register the clean pair; the one with the higher two-way overlap is
    // returned, scored on the clouds as given.
    let pair = clean_pair();
    let mut method = both_candidates();
    assert_eq!(method.name(), "auto+refine");
    let found = method.register(&pair.source, &pair.target).unwrap();
    let names = candidate_names(&found);
    assert_eq!(names, ["fgr+refine", "rgm+refine"]);
    let scores: Vec<f64> = found.candidates.iter().map(|c| c.score.unwrap()).collect();
    let chosen = found.chosen.unwrap();
    assert!(
        scores.iter().all(|&s| s <= scores[chosen] && s > 1.9),
        "{scores:?}"
    );
    assert_eq!(
        found.result.t_target_source,
        found.candidates[chosen].t_target_source
    );
    let metrics = metrics_against_truth(&found, &pair);
    assert!(metrics.recall && metrics.mie_r_deg < 0.05, "{metrics:?}");
    // Scored as Open3D scores ICP at the refinement's finest distance: every point.
    assert_eq!(found.result.fitness, 1.0);
    assert_eq!(found.correspondences.len(), pair.source.len());
}

#[test]
fn a_failed_candidate_leaves_the_other_and_both_failing_names_both() {
    // The tiny network needs K + 1 = 5 points: matching 4 it refuses, and FGR's result stands
    // (on 40 points: a pair of at most 32 goes to the triplet search instead).
    let pair = clean_pair();
    let few = |c: &PointCloud| PointCloud::new(c.points[..40].to_vec());
    let mut rgm = tiny_rgm();
    rgm.config.match_points = Some(4);
    let mut method = auto_with(rgm);
    let found = method
        .register(&few(&pair.source), &few(&pair.target))
        .unwrap();
    let rgm = &found.candidates[1];
    assert!(rgm.score.is_none(), "{rgm:?}");
    assert!(
        rgm.failure.as_deref().unwrap().contains("needs at least 5"),
        "{rgm:?}"
    );
    assert_eq!(found.chosen, Some(0));
    assert_eq!(
        found.result.t_target_source,
        found.candidates[0].t_target_source
    );
    // An empty target: neither can run, and both failures are named.
    let empty = PointCloud::default();
    match method.register(&few(&pair.source), &empty) {
        Err(MethodError::AllCandidatesFailed(AllCandidatesFailed(why))) => {
            assert!(
                why.contains("fgr+refine: ") && why.contains("rgm+refine: "),
                "{why}"
            );
        }
        other => panic!("expected both to fail, got {other:?}"),
    }
    // Two empty clouds (no more than the triplet search's 32 points): a clear error.
    let err = method.register(&empty, &empty).unwrap_err().to_string();
    assert!(err.contains("the source has 0 points"), "{err}");
}

#[test]
fn a_pair_at_a_quarter_and_at_twice_the_size_gets_the_same_transform() {
    // Both sizes reach the candidates as the same centred unit-sphere clouds (at half the size
    // the pair lies in the frame's window and is used as it is, as a short crop of the
    // benchmark is).
    let pair = clean_pair();
    let scaled = |c: &PointCloud, k: f64| {
        PointCloud::new(
            c.points
                .iter()
                .map(|p| Point3::from(p.coords * k))
                .collect(),
        )
    };
    let mut method = MethodOptions::default().build().unwrap();
    let mut at = |k: f64| {
        let t = method
            .register(&scaled(&pair.source, k), &scaled(&pair.target, k))
            .unwrap()
            .result
            .t_target_source;
        RigidTransform::new(t.rotation, t.translation / k)
    };
    let (quarter, double) = (at(0.25), at(2.0));
    assert!((quarter.rotation - double.rotation).abs().max() < 1e-9);
    assert!((quarter.translation - double.translation).abs().max() < 1e-9);
    let metrics =
        PairMetrics::compute(&quarter, &pair.t_target_source, &pair.source, &pair.target).unwrap();
    assert!(metrics.recall, "{metrics:?}");
}

#[test]
fn a_dense_pair_whose_methods_agree_is_thinned_once_and_refined_at_its_resolution() {
    // Each point of the clean pair made four, 0.003 apart along fixed directions: 4,096 points
    // a cloud, more than the training clouds' 1,024, so both methods run on the voxel
    // thinning; they agree on this clean pair, so the cell thinning is skipped.
    let pair = clean_pair();
    let (source, target) = (four_fold(&pair.source), four_fold(&pair.target));
    assert_eq!(source.len(), 4096);
    let mut method = both_candidates();
    let found = method.register(&source, &target).unwrap();
    let names = candidate_names(&found);
    // The scene stage runs after the object cascade: points in tight clusters of four
    // reach their 16th neighbour far beyond their nearest, as points along scan lines do, and
    // there the coincidence check takes nothing.
    assert_eq!(names, ["auto+refine", "sc2+refine"]);
    let scores: Vec<f64> = found.candidates.iter().map(|c| c.score.unwrap()).collect();
    let chosen = found.chosen.unwrap();
    assert!(scores.iter().all(|&s| s <= scores[chosen]), "{scores:?}");
    // Scored on the dense clouds: the right transform overlaps nearly every point both ways.
    assert!(scores[chosen] > 1.9, "{scores:?}");
    // The winner, refined further on the dense clouds: moved, but by little.
    let result = found.result.t_target_source;
    let winner = found.candidates[chosen].t_target_source;
    assert_ne!(result, winner);
    assert!(winner.inverse().compose(&result).rotation_angle_deg() < 1.0);
    let metrics = metrics_against_truth(&found, &pair);
    assert!(metrics.recall, "{metrics:?}");
}

/// Each point of `cloud` made four, 0.003 apart along fixed directions: a cloud four times as
/// dense as the training clouds.
fn four_fold(cloud: &PointCloud) -> PointCloud {
    let offsets = [
        (1.0, 0.0, 0.0),
        (0.0, 1.0, 0.0),
        (0.0, 0.0, 1.0),
        (-1.0, -1.0, -1.0),
    ];
    PointCloud::new(
        cloud
            .points
            .iter()
            .flat_map(|p| {
                offsets
                    .iter()
                    .map(move |&(x, y, z)| p + 0.003 * rgm_geom::Vector3::new(x, y, z))
            })
            .collect(),
    )
}

#[test]
fn scene_runs_only_the_scene_stage_on_a_dense_pair_and_is_auto_on_a_sparse_one() {
    let scene = || {
        MethodOptions {
            method: rgm_model::MethodName::Scene,
            ..MethodOptions::default()
        }
        .build()
        .unwrap()
    };
    let pair = clean_pair();
    // Dense: the scene stage alone (the default runs the object cascade first, above).
    let (source, target) = (four_fold(&pair.source), four_fold(&pair.target));
    let found = scene().register(&source, &target).unwrap();
    assert!(
        !candidate_names(&found).contains(&"auto+refine"),
        "{:?}",
        candidate_names(&found)
    );
    assert!(found.doubt.is_none(), "{:?}", found.doubt);
    assert!(metrics_against_truth(&found, &pair).recall);
    // As sparse as the training clouds: exactly the default's result.
    let sparse = scene().register(&pair.source, &pair.target).unwrap();
    let default = MethodOptions::default()
        .build()
        .unwrap()
        .register(&pair.source, &pair.target)
        .unwrap();
    assert_eq!(
        sparse.result.t_target_source,
        default.result.t_target_source
    );
    assert_eq!(candidate_names(&sparse), candidate_names(&default));
}

/// The rotation error of `found` against `truth`, in degrees, and its translation error
/// relative to the clouds' size `size`.
fn errors(found: &RigidTransform, truth: &RigidTransform, size: f64) -> (f64, f64) {
    let angle = RigidTransform::new(
        truth.rotation.transpose() * found.rotation,
        Default::default(),
    )
    .rotation_angle_deg();
    let off = (found.translation - truth.translation) / size;
    (angle, rgm_geom::length(&off))
}

/// `rgm register`'s default, RGM alone and FGR alone (each refined), as the command line builds
/// them.
fn refined_methods() -> [Method; 3] {
    let alone = |method| {
        MethodOptions {
            method,
            ..MethodOptions::default()
        }
        .build()
        .unwrap()
    };
    [
        MethodOptions::default().build().unwrap(),
        alone(rgm_model::MethodName::Rgm),
        alone(rgm_model::MethodName::Fgr),
    ]
}

#[test]
fn a_far_outlier_in_each_cloud_leaves_the_transform_right() {
    // Issue 27, case 1: one point of each cloud replaced by a stray return at 1e5 shrank the
    // pair to a dot in the network's frame (152° wrong, fitness 0.999, overlap score 1.998); at
    // 100 RGM alone failed ("kabsch: needs at least 3 points").
    let pair = clean_pair();
    for far in [100.0, 1e5, 1e9] {
        let mut source = pair.source.clone();
        source.points[17] = Point3::new(far, -far, 0.5 * far);
        let mut target = pair.target.clone();
        target.points[800] = Point3::new(-far, 0.3 * far, far);
        for mut method in refined_methods() {
            let found = method.register(&source, &target).unwrap();
            let (angle, off) = errors(&found.result.t_target_source, &pair.t_target_source, 1.0);
            assert!(
                angle < 2.0 && off < 0.02,
                "{} at {far}: {angle}° {off}",
                method.name()
            );
            // The outlier is no inlier: the fitness is at most 1,023 of 1,024.
            assert!(
                found.result.fitness <= 1023.0 / 1024.0,
                "{:?}",
                found.result
            );
            assert_eq!(found.doubt, None);
        }
    }
}

#[test]
fn a_pair_at_1e200_or_1e_minus_200_gets_the_right_transform_and_no_nan() {
    // Issue 27, case 3: at 1e200 the translation was NaN (reported with "overlap score 2.0"),
    // at 1e-200 the identity with fitness 1.0 (the truth is 38.6° away).
    let pair = clean_pair();
    for k in [1e200, 1e-200] {
        let scaled = |c: &PointCloud| {
            PointCloud::new(
                c.points
                    .iter()
                    .map(|p| Point3::from(p.coords * k))
                    .collect(),
            )
        };
        let truth = RigidTransform::new(
            pair.t_target_source.rotation,
            pair.t_target_source.translation * k,
        );
        for mut method in refined_methods() {
            let found = method
                .register(&scaled(&pair.source), &scaled(&pair.target))
                .unwrap();
            let (angle, off) = errors(&found.result.t_target_source, &truth, k);
            assert!(
                angle < 2.0 && off < 0.02,
                "{} at {k}: {angle}° {off}",
                method.name()
            );
            let r = &found.result;
            assert!(r.fitness > 0.9 && r.inlier_rmse.is_finite(), "{r:?}");
            assert!(r.inlier_rmse / k < 0.05, "{r:?}");
            assert_eq!(found.doubt, None);
        }
    }
}

#[test]
fn clouds_that_do_not_overlap_are_reported_as_not_registered() {
    // A shape and 1,024 points of noise in a cube: whatever the best transform, almost no
    // point of either lies on the other, and the result says so instead of a confident
    // transform.
    use rand::{Rng, SeedableRng};
    let pair = clean_pair();
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let noise = PointCloud::new(
        (0..1024)
            .map(|_| {
                Point3::new(
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                )
            })
            .collect(),
    );
    let mut method = MethodOptions::default().build().unwrap();
    let found = method.register(&pair.source, &noise).unwrap();
    let why = found.doubt.expect("not registered");
    assert!(why.contains("overlaps too little"), "{why}");
    let best = found.candidates[found.chosen.unwrap()].score.unwrap();
    assert!(best < TUNED.scoring.min_overlap, "{best}");
}

#[test]
fn fgr_alone_doubts_a_result_where_the_clouds_do_not_coincide() {
    // Issue 44, D1: `--method fgr` (refined) was not checked. Half of a shape registered onto
    // the other half, the two sharing no point: whatever FGR finds lays one half on the wrong
    // part of the other, which the check tells.
    let pair = clean_pair();
    let (low, high): (Vec<_>, Vec<_>) = pair.source.points.iter().partition(|p| p.x < 0.0);
    let [mut default, _, mut fgr] = refined_methods();
    assert_eq!(fgr.name(), "fgr+refine");
    for method in [&mut default, &mut fgr] {
        let found = method
            .register(
                &PointCloud::new(low.clone()),
                &PointCloud::new(high.clone()),
            )
            .unwrap();
        let why = found.doubt.expect("not registered");
        assert!(
            why.contains("coincide") || why.contains("overlaps too little"),
            "{why}"
        );
    }
}

#[test]
fn icp_doubts_the_wrong_pose_it_slides_into_and_trusts_a_right_one() {
    // Issue 44, D1: `--method icp` was not checked. A shape turned a few degrees is within
    // ICP's reach from the identity; turned a quarter it is not, and ICP settles on a wrong pose
    // where the clouds lie near each other without coinciding.
    let target = clean_pair().target;
    let centre = target.centroid().coords;
    let turned = |degrees: f64| {
        let rotation = rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, degrees.to_radians());
        RigidTransform::new(rotation, centre - rotation * centre)
    };
    let mut icp = MethodOptions {
        method: rgm_model::MethodName::Icp,
        ..MethodOptions::default()
    }
    .build()
    .unwrap();
    for (degrees, right) in [(5.0, true), (90.0, false)] {
        let pose = turned(degrees);
        let found = icp.register(&target.transformed(&pose), &target).unwrap();
        let (rotation, _) = errors(&found.result.t_target_source, &pose.inverse(), 1.0);
        assert_eq!(rotation < 1.0, right, "{degrees}°: {rotation}° off");
        assert_eq!(
            found.doubt.is_none(),
            right,
            "{degrees}°: {:?}",
            found.doubt
        );
    }
}

#[test]
fn the_network_alone_registers_a_pair_whose_chains_agree_on_two_pairs() {
    // Partial test pair 1520: the forward and reverse chains of the built-in model end with
    // only two pairs in common, which fix no pose. `rgm --no-refine` failed there ("kabsch:
    // needs at least 3 points, got 2"); the forward chain's own pairs now give the pose.
    let data =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024");
    let dataset = ModelNet40::open(&data).unwrap();
    let shapes = dataset.split(Split::Test, false);
    let pair = PairGenerator::new(Setting::Partial)
        .test_pair(&shapes, 1520)
        .unwrap();
    let mut rgm = MethodOptions {
        method: rgm_model::MethodName::Rgm,
        refine: false,
        ..MethodOptions::default()
    }
    .build()
    .unwrap();
    let found = rgm.register(&pair.source, &pair.target).unwrap();
    let (rotation, _) = errors(&found.result.t_target_source, &pair.t_target_source, 1.0);
    assert!(rotation < 10.0, "{rotation}°");
}
