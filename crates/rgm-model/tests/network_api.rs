//! The network's configuration, parameter layout, weight files and input errors.

use ndarray::{Array2, ArrayD, IxDyn};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rgm_model::network::{
    Config, Edges, Mode, NetworkError, Rgm, RgmCache, Scoring, TestStatistics,
};
use rgm_nn::Parameters;
use std::collections::HashMap;

fn cloud(n: usize, seed: u64) -> Array2<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    Array2::from_shape_simple_fn((n, 3), || rng.gen_range(-1.0..1.0))
}

fn counts(config: Config) -> (usize, usize) {
    let rgm = Rgm::<f32>::new(config, 0).unwrap();
    let mut buffers = 0;
    rgm.visit_buffers_ref("", &mut |_, b| buffers += b.len());
    (rgm.num_params(), buffers)
}

/// The read-only visitors name the same tensors, of the same shapes, in the same order as the
/// mutating ones that optimisers and loading use.
#[test]
fn both_visitors_walk_the_same_tensors_in_the_same_order() {
    for preset in ["paper", "small", "fast", "tiny"] {
        let mut rgm = Rgm::<f32>::new(Config::preset(preset).unwrap(), 0).unwrap();
        let (mut read, mut written) = (Vec::new(), Vec::new());
        rgm.visit_params_ref("", &mut |name, p| {
            read.push((name.to_string(), p.value.shape().to_vec()))
        });
        rgm.visit_buffers_ref("", &mut |name, b| {
            read.push((name.to_string(), b.shape().to_vec()))
        });
        rgm.visit_params("", &mut |name, p| {
            written.push((name.to_string(), p.value.shape().to_vec()))
        });
        rgm.visit_buffers("", &mut |name, b| {
            written.push((name.to_string(), b.shape().to_vec()))
        });
        assert_eq!(read, written, "{preset}");
        assert!(read.len() > 20, "{preset}: {}", read.len());
    }
}

#[test]
fn paper_size_has_the_authors_parameter_count() {
    // The authors' checkpoints hold 25,002,889 values: 25,000,836 parameters, 2,048 running
    // statistics and 5 `num_batches_tracked` counters (not kept here).
    assert_eq!(counts(Config::paper()), (25_000_836, 2_048));
}

#[test]
fn small_and_ablation_sizes() {
    assert_eq!(counts(Config::small()).0, 6_263_236);
    assert_eq!(counts(Config::fast()).0, 1_572_324);
    // Var1 drops each block's Q×Q affinity and the two instance-norm scalars.
    let var1 = Config {
        scoring: Scoring::Var1,
        ..Config::paper()
    };
    assert_eq!(counts(var1).0, 25_000_836 - 2 * (512 * 512 + 2));
    let full = Config {
        edges: Edges::Full,
        ..Config::tiny()
    };
    let mut rgm = Rgm::<f32>::new(full, 0).unwrap();
    rgm.visit_params("", &mut |name, _| {
        assert!(!name.starts_with("gmattend"), "{name}")
    });
}

#[test]
fn presets_by_name_and_invalid_configurations() {
    assert_eq!(Config::preset("small").unwrap(), Config::small());
    assert_eq!(Config::preset("fast").unwrap(), Config::fast());
    assert!(matches!(
        Config::preset("huge"),
        Err(NetworkError::Config { .. })
    ));
    let err = Rgm::<f32>::new(
        Config {
            heads: 5,
            ..Config::tiny()
        },
        0,
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "rgm config: block 0 width 48 is not divisible by 5 heads"
    );
    assert!(Rgm::<f32>::new(
        Config {
            k: 0,
            ..Config::tiny()
        },
        0
    )
    .is_err());
}

#[test]
fn weights_round_trip_through_a_file_and_name_their_errors() {
    let dir = std::env::temp_dir().join(format!("rgm-network-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tiny.safetensors");
    let mut trained = Rgm::<f64>::new(Config::tiny(), 1).unwrap();
    let (x, y) = (cloud(12, 2), cloud(10, 3));
    let mut cache = RgmCache::default();
    trained
        .forward(x.view(), y.view(), Mode::Train, &mut cache)
        .unwrap(); // moves the running stats
    rgm_nn::io::save_params(&path, &trained).unwrap();
    let mut loaded = Rgm::<f64>::load(Config::tiny(), &path).unwrap();
    trained
        .forward(x.view(), y.view(), Mode::Eval, &mut cache)
        .unwrap();
    let want = cache.c_soft().to_owned();
    loaded
        .forward(x.view(), y.view(), Mode::Eval, &mut cache)
        .unwrap();
    assert_eq!(cache.c_soft(), want);

    let mut tensors: HashMap<String, ArrayD<f64>> = HashMap::new();
    trained.visit_params("", &mut |name, p| {
        tensors.insert(name.to_string(), p.value.to_owned());
    });
    let err = loaded.load_tensors(&tensors).unwrap_err();
    assert_eq!(
        err.to_string(),
        "weights: tensor \"pointfeaturer.bn1.running_mean\" is missing"
    );
    trained.visit_buffers("", &mut |name, b| {
        tensors.insert(name.to_string(), b.to_owned());
    });
    tensors.insert("affinity_0.A".into(), ArrayD::zeros(IxDyn(&[16, 15])));
    let err = loaded.load_tensors(&tensors).unwrap_err();
    assert_eq!(
        err.to_string(),
        "weights: tensor \"affinity_0.A\" has shape [16, 15], expected [16, 16]"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_clouds_are_errors() {
    let mut rgm = Rgm::<f64>::new(Config::tiny(), 0).unwrap();
    let mut cache = RgmCache::default();
    let err = rgm
        .forward(
            Array2::zeros((12, 2)).view(),
            cloud(10, 1).view(),
            Mode::Eval,
            &mut cache,
        )
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "rgm forward: x has shape [12, 2], expected (rows, 3)"
    );
    // Fewer points than K = 4 neighbours.
    let err = rgm
        .forward(
            cloud(12, 1).view(),
            cloud(3, 2).view(),
            Mode::Eval,
            &mut cache,
        )
        .unwrap_err();
    assert!(matches!(err, NetworkError::Geom(_)), "{err}");
    let err = rgm
        .backward(Array2::zeros((2, 2)).view(), &mut RgmCache::default())
        .unwrap_err();
    assert!(matches!(err, NetworkError::Backward { .. }), "{err}");
}

#[test]
fn cache_is_reused_across_pair_sizes() {
    // The same cache serves pairs of different sizes; results equal a fresh cache's.
    let mut rgm = Rgm::<f64>::new(Config::tiny(), 5).unwrap();
    let mut shared = RgmCache::default();
    for (n, m) in [(12, 10), (9, 14), (12, 10)] {
        let (x, y) = (cloud(n, n as u64), cloud(m, m as u64));
        rgm.forward(x.view(), y.view(), Mode::Eval, &mut shared)
            .unwrap();
        let mut fresh = RgmCache::default();
        rgm.forward(x.view(), y.view(), Mode::Eval, &mut fresh)
            .unwrap();
        assert_eq!(shared.c_soft().dim(), (n, m));
        assert_eq!(shared.c_soft(), fresh.c_soft());
    }
}

#[test]
fn cloud_test_statistics_normalise_like_training_and_keep_the_running_ones() {
    let (x, y) = (cloud(24, 1), cloud(20, 2));
    let mut trained = Rgm::<f64>::new(Config::tiny(), 3).unwrap();
    let mut cache = RgmCache::default();
    // Two training passes so the running statistics are no longer the initial 0 / 1.
    for _ in 0..2 {
        trained
            .forward(x.view(), y.view(), Mode::Train, &mut cache)
            .unwrap();
    }
    let buffers = |rgm: &mut Rgm<f64>| {
        let mut all = Vec::new();
        rgm.visit_buffers("", &mut |_, b| all.extend(b.iter().copied()));
        all
    };
    let mut cloud_stats = trained.clone();
    cloud_stats.featurer.test_statistics = TestStatistics::Cloud;
    let before = buffers(&mut cloud_stats);
    cloud_stats
        .forward(x.view(), y.view(), Mode::Eval, &mut cache)
        .unwrap();
    let c_cloud = cache.c_soft().to_owned();
    assert_eq!(
        buffers(&mut cloud_stats),
        before,
        "running statistics untouched"
    );
    // The same C̃ as a training-mode pass (which also normalises each cloud on its own).
    trained
        .clone()
        .forward(x.view(), y.view(), Mode::Train, &mut cache)
        .unwrap();
    assert_eq!(cache.c_soft(), c_cloud);
    // And not the C̃ of the running statistics.
    trained
        .forward(x.view(), y.view(), Mode::Eval, &mut cache)
        .unwrap();
    let gap = (&cache.c_soft() - &c_cloud).fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        gap > 1e-3,
        "running and cloud statistics give different C̃ ({gap})"
    );
}
