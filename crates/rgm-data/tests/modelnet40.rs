//! The loader, splits and pairs on the real ModelNet40 `.npy` tree: `$RGM_DATA`, or
//! `../shared/data/modelnet40_npy1024` beside the repository.

use std::path::PathBuf;

use rgm_data::{Correspondence, ModelNet40, PairGenerator, Setting, Shape, Split};

fn open() -> ModelNet40 {
    let dir = std::env::var_os("RGM_DATA").map_or_else(
        || {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../../shared/data/modelnet40_npy1024")
        },
        PathBuf::from,
    );
    ModelNet40::open(&dir)
        .unwrap_or_else(|e| panic!("ModelNet40 at {} (set RGM_DATA): {e}", dir.display()))
}

#[test]
fn real_dataset_splits_pairs_and_ground_truth() {
    let data = open();
    assert_eq!(data.categories.len(), 40);
    assert_eq!(
        (data.official_train.len(), data.official_test.len()),
        (9843, 2468)
    );
    assert_eq!(data.categories[0], "airplane");
    assert_eq!(data.official_test[0].name, "airplane_0627");
    let sizes = |unseen| {
        [Split::Train, Split::Validation, Split::Test].map(|s| data.split(s, unseen).len())
    };
    assert_eq!(sizes(false), [7863, 1980, 2468]);
    assert_eq!(sizes(true), [4085, 1029, 1266]);

    let test: Vec<&Shape> = data.split(Split::Test, false);
    let pairs = |setting| -> Vec<rgm_data::Pair> {
        let generator = PairGenerator::new(setting);
        (0..100)
            .map(|i| generator.test_pair(&test, i).unwrap())
            .collect()
    };
    let mean_matched = |pairs: &[rgm_data::Pair]| {
        pairs
            .iter()
            .map(|p| p.correspondence.matched_source_fraction())
            .sum::<f64>()
            / pairs.len() as f64
    };

    for pair in pairs(Setting::Clean) {
        assert_eq!(pair.correspondence.pairs.len(), 1024);
        let moved = pair.source.transformed(&pair.t_target_source);
        for &(i, j) in &pair.correspondence.pairs {
            assert!((moved.points[i] - pair.target.points[j]).norm() < 1e-9);
        }
    }

    let partial = pairs(Setting::Partial);
    for pair in &partial {
        assert_eq!((pair.source.len(), pair.target.len()), (717, 717));
        let c = &pair.correspondence;
        assert_eq!(
            Correspondence::new(c.n_source, c.n_target, c.pairs.clone()).unwrap(),
            *c
        );
        let moved = pair.source.transformed(&pair.t_target_source);
        for &(i, j) in &c.pairs {
            assert!((moved.points[i] - pair.target.points[j]).norm() < 0.1);
        }
    }
    // Pinned from `data_stats` (docs/data.md): rand 0.8 StdRng streams, spec §1 order.
    assert!(
        (mean_matched(&partial) - 0.6697).abs() < 1e-4,
        "{}",
        mean_matched(&partial)
    );
    let noise = pairs(Setting::Noise);
    assert!(
        (mean_matched(&noise) - 0.9243).abs() < 1e-4,
        "{}",
        mean_matched(&noise)
    );
}
