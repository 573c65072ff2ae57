//! The checkpoint path and the test-time procedure.
//!
//! `fixtures/rgm_tiny_state_dict.safetensors` is what a converted PyTorch checkpoint looks like
//! (the authors' names, 4-D conv weights, float32), written by
//! `python3 tools/reference/rgm_reference.py export --preset tiny --points 48 --out …`, with a
//! 48×48 pair and PyTorch's evaluation-mode C̃ for it.

use std::path::PathBuf;

use ndarray::Array2;
use rgm_geom::{Point3, PointCloud};
use rgm_model::network::{Config, Mode, Rgm, RgmCache};
use rgm_model::{Method, MethodError, PipelineConfig, RgmRegistrar};

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
fn the_pipeline_uses_only_cycle_consistent_one_to_one_pairs() {
    let network = Rgm::<f32>::load(Config::tiny(), &fixture()).unwrap();
    let (source, target) = (cloud(&tensor("input.x")), cloud(&tensor("input.y")));
    let one_way = PipelineConfig {
        passes: 1,
        cycle_consistency: false,
        ..Default::default()
    };
    let both_ways = PipelineConfig {
        passes: 1,
        ..Default::default()
    };
    let outcome = |config| RgmRegistrar::new(network.clone(), config).register(&source, &target);
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
    let err = Method::rgm(Config::small(), &fixture()).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("pointfeaturer.conv1.weight") || text.contains("expected"),
        "{text}"
    );
}
