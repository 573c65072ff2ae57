//! The options' tests: what the default registers, and what each option builds.

use super::*;

/// Issue 44, D12: the default registers a copy of a few markers at another pose (it
/// refused them as "may not overlap").
#[test]
fn the_default_registers_a_few_markers() {
    use rgm_geom::{Point3, PointCloud, RigidTransform, Vector3};
    let markers = PointCloud::new(vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(0.12, 0.0, 0.01),
        Point3::new(0.0, 0.2, 0.0),
        Point3::new(0.03, 0.05, 0.3),
        Point3::new(0.1, 0.1, 0.1),
        Point3::new(-0.07, 0.15, 0.02),
    ]);
    let pose = RigidTransform::new(
        rgm_geom::euler::rotation_xyz_intrinsic(0.4, -1.1, 2.5),
        Vector3::new(1.5, 0.2, -3.0),
    );
    let moved = markers.transformed(&pose);
    let mut method = MethodOptions::default().build().unwrap();
    let found = method.register(&markers, &moved).unwrap();
    assert!(found.doubt.is_none(), "{:?}", found.doubt);
    let t = found.result.t_target_source;
    assert!(t.inverse().compose(&pose).rotation_angle_deg() < 1e-6);
    assert!((t.translation - pose.translation).norm() < 1e-9);
}

#[test]
fn the_default_is_the_built_in_rgm_and_fgr_refined() {
    let options = MethodOptions::default();
    assert_eq!(options.build().unwrap().name(), "auto+refine");
    // RGM inside is the built-in model with its own settings.
    let registrar = options.build_rgm().unwrap();
    let builtin = crate::weights::builtin_registrar().unwrap();
    assert_eq!(registrar.network.config(), builtin.network.config());
    assert_eq!(registrar.config, builtin.config);
    assert_eq!(
        registrar.network.featurer.test_statistics,
        builtin.network.featurer.test_statistics
    );
    // As the cascade's second stage: one chain on fewer points, unless the user says.
    let cascade = options.build_cascade_rgm().unwrap().config;
    assert!(builtin.config.cycle_consistency && !cascade.cycle_consistency);
    assert_eq!(cascade.match_points, Some(TUNED.cascade_match_points));
    assert_ne!(
        builtin.config.match_points,
        Some(TUNED.cascade_match_points)
    );
    assert_eq!(cascade.passes, builtin.config.passes);
    let asked = MethodOptions {
        match_points: Some(500),
        ..MethodOptions::default()
    };
    assert_eq!(
        asked.build_cascade_rgm().unwrap().config.match_points,
        Some(500)
    );
}

#[test]
fn options_reach_the_method() {
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/rgm_tiny_state_dict.safetensors");
    let options = MethodOptions {
        method: MethodName::Rgm,
        weights: Some(weights),
        preset: Some("tiny".into()),
        test_statistics: Some(TestStatistics::Cloud),
        match_points: Some(30),
        passes: Some(3),
        refine: false,
        ..MethodOptions::default()
    };
    assert_eq!(options.build().unwrap().name(), "rgm");
    let registrar = options.build_rgm().unwrap();
    assert_eq!(registrar.network.config(), &Config::tiny());
    assert_eq!(
        registrar.network.featurer.test_statistics,
        TestStatistics::Cloud
    );
    assert_eq!(
        (registrar.config.match_points, registrar.config.passes),
        (Some(30), 3)
    );
    // Given weights without statistics use the running ones (the authors' weights).
    let options = MethodOptions {
        test_statistics: None,
        ..options
    };
    assert_eq!(
        options
            .build_rgm()
            .unwrap()
            .network
            .featurer
            .test_statistics,
        TestStatistics::Running
    );
    for (name, options, expected) in [
        ("fgr", MethodOptions::default(), "fgr+refine"),
        (
            "fgr",
            MethodOptions {
                refine: false,
                ..Default::default()
            },
            "fgr",
        ),
        ("icp", MethodOptions::default(), "icp"),
        ("rgm", MethodOptions::default(), "rgm+refine"),
        (
            "auto",
            MethodOptions {
                refine: false,
                ..Default::default()
            },
            "auto",
        ),
        // Named as chosen, not by its scene stage (`sc2+refine`), the part that runs on dense pairs.
        ("scene", MethodOptions::default(), "scene+refine"),
    ] {
        let options = MethodOptions {
            method: name.parse().unwrap(),
            ..options
        };
        assert_eq!(options.build().unwrap().name(), expected);
    }
}

#[test]
fn options_that_do_not_fit_the_method_are_named() {
    let fgr = MethodOptions {
        method: MethodName::Fgr,
        ..Default::default()
    };
    for (options, says) in [
        (
            MethodOptions {
                passes: Some(1),
                ..fgr.clone()
            },
            "apply to the rgm, auto and scene methods only",
        ),
        (
            MethodOptions {
                preset: Some("tiny".into()),
                ..Default::default()
            },
            "the built-in model has its own",
        ),
        (
            MethodOptions {
                passes: Some(0),
                ..Default::default()
            },
            "must be at least 1",
        ),
        (
            MethodOptions {
                weights: Some("/no/such/file.safetensors".into()),
                ..Default::default()
            },
            "/no/such/file.safetensors",
        ),
        (
            MethodOptions {
                weights: Some("w".into()),
                preset: Some("huge".into()),
                ..Default::default()
            },
            "unknown preset \"huge\"",
        ),
    ] {
        let err = options.build().unwrap_err().to_string();
        assert!(err.contains(says), "{options:?}: {err}");
    }
    let err = "gicp".parse::<MethodName>().unwrap_err().to_string();
    assert_eq!(
        err,
        "unknown method \"gicp\" (expected one of icp, fgr, rgm, auto, scene)"
    );
}
