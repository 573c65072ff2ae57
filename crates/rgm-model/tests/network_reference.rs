//! The network against the PyTorch reference, tensor by tensor (llm.c's `test_gpt2.c` style).
//!
//! The fixture was written by `python3 tools/reference/rgm_reference.py dump --out
//! crates/rgm-model/tests/fixtures/rgm_tiny_reference.safetensors` (f64, tiny configuration):
//! inputs, every parameter under the authors' names, C̃ of a training-mode forward, the loss,
//! every parameter gradient, the batch-norm running statistics after that step, and C̃ of an
//! evaluation-mode forward with them. No Python is needed here.

mod common;

use common::{ground_truth, matrix, with_prefix};
use ndarray::{ArrayD, Ix2};
use rgm_model::network::{Config, Element, Mode, Rgm, RgmCache};
use rgm_nn::Parameters;
use std::collections::HashMap;
use std::path::Path;

/// f64 throughout: the reference and this network agree to rounding.
const TOL: f64 = 1e-9;

fn fixture() -> HashMap<String, ArrayD<f64>> {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rgm_tiny_reference.safetensors");
    let (tensors, metadata) = rgm_nn::io::read_tensors::<f64>(&path).unwrap();
    assert_eq!(
        metadata["config"],
        r#"{"k": 4, "dgcnn": [4, 4, 8, 8], "edge": 24, "q": 16, "heads": 4, "ff": 32, "blocks": 2, "sinkhorn_iters": 20}"#
    );
    tensors
}

/// The tiny network with the reference's parameters and fresh batch-norm statistics (those the
/// reference started its training step from).
fn reference_model<T: Element>(t: &HashMap<String, ArrayD<T>>) -> Rgm<T> {
    let mut rgm = Rgm::<T>::new(Config::tiny(), 7).unwrap();
    let mut tensors = with_prefix(t, "param.");
    rgm.visit_buffers("", &mut |name, b| {
        tensors.insert(name.to_string(), b.to_owned());
    });
    rgm.load_tensors(&tensors).unwrap();
    rgm
}

/// The reference's training step: the forward in training mode on its inputs, the BCE loss
/// against its ground truth, the backward. Returns the network, the pass and the loss.
fn reference_step(t: &HashMap<String, ArrayD<f64>>) -> (Rgm<f64>, RgmCache<f64>, f64) {
    let mut rgm = reference_model(t);
    let (x, y) = (matrix(t, "input.x"), matrix(t, "input.y"));
    let gt = ground_truth(&matrix(t, "input.gt"));
    let mut cache = RgmCache::default();
    let loss = rgm
        .forward_backward(x.view(), y.view(), &gt, &mut cache)
        .unwrap();
    (rgm, cache, loss)
}

/// max |got − want| / max |want|, printed.
fn relative_difference(what: &str, got: &ArrayD<f64>, want: &ArrayD<f64>) -> f64 {
    assert_eq!(got.shape(), want.shape(), "{what}");
    let diff = got
        .iter()
        .zip(want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    let scale = want.iter().fold(0.0f64, |m, b| m.max(b.abs()));
    assert!(scale > 0.0, "{what}: the reference is all zeros");
    println!(
        "{what}: max |diff| {diff:.3e}, relative {:.3e}",
        diff / scale
    );
    diff / scale
}

#[test]
fn forward_loss_and_running_statistics_match_the_reference() {
    let t = fixture();
    let (mut rgm, mut cache, loss) = reference_step(&t);
    let (x, y) = (matrix(&t, "input.x"), matrix(&t, "input.y"));
    let c_soft = cache.c_soft().to_owned().into_dyn();
    assert!(relative_difference("C̃ (train)", &c_soft, &t["output.c_soft"]) < TOL);
    let want_loss = t["output.loss"][[0]];
    println!("loss {loss:.15} reference {want_loss:.15}");
    assert!((loss - want_loss).abs() < TOL * want_loss.abs());
    let buffers = with_prefix(&t, "buffer.");
    let mut compared = 0;
    rgm.visit_buffers("", &mut |name, b| {
        assert!(relative_difference(name, &b.to_owned(), &buffers[name]) < TOL);
        compared += 1;
    });
    assert_eq!(compared, buffers.len());
    rgm.forward(x.view(), y.view(), Mode::Eval, &mut cache)
        .unwrap();
    let c_eval = cache.c_soft().to_owned().into_dyn();
    assert!(relative_difference("C̃ (eval)", &c_eval, &t["output.c_soft_eval"]) < TOL);
}

#[test]
fn every_parameter_gradient_matches_the_reference() {
    let t = fixture();
    let (mut rgm, _, _) = reference_step(&t);
    let grads = with_prefix(&t, "grad.");
    let mut worst = (0.0f64, String::new());
    let mut compared = 0;
    rgm.visit_params("", &mut |name, p| {
        // Convolution gradients are stored (out, in, 1, 1) by the reference.
        let want = grads[name].to_shape(p.grad.raw_dim()).unwrap().to_owned();
        // The key bias of attention gets an exactly zero gradient (softmax ignores it).
        if want.iter().all(|g| g.abs() < 1e-14) {
            assert!(p.grad.iter().all(|g| g.abs() < 1e-12), "{name}: {}", p.grad);
        } else {
            let e = relative_difference(name, &p.grad.to_owned(), &want);
            if e > worst.0 {
                worst = (e, name.to_string());
            }
        }
        compared += 1;
    });
    assert_eq!(
        compared,
        grads.len(),
        "every reference gradient has a parameter"
    );
    println!("worst: {} {:.3e}", worst.1, worst.0);
    assert!(
        worst.0 < 1e-8,
        "worst gradient {} relative {:e}",
        worst.1,
        worst.0
    );
}

#[test]
fn f32_pass_stays_close_to_the_f64_reference() {
    // The compute type: the same fixture rounded to f32 (inputs and weights), one training step.
    let t = fixture();
    let t32: HashMap<String, ndarray::ArrayD<f32>> = t
        .iter()
        .map(|(k, v)| (k.clone(), v.mapv(|v| v as f32)))
        .collect();
    let mut rgm = reference_model(&t32);
    let as2 = |name: &str| t32[name].clone().into_dimensionality::<Ix2>().unwrap();
    let gt = ground_truth(&matrix(&t, "input.gt"));
    let mut cache = RgmCache::default();
    let loss = rgm
        .forward_backward(
            as2("input.x").view(),
            as2("input.y").view(),
            &gt,
            &mut cache,
        )
        .unwrap();
    let c_soft = cache.c_soft().mapv(|v| v as f64).into_dyn();
    assert!(relative_difference("C̃ (f32)", &c_soft, &t["output.c_soft"]) < 1e-5);
    let want_loss = t["output.loss"][[0]];
    assert!(
        (loss as f64 - want_loss).abs() < 1e-5 * want_loss,
        "{loss} vs {want_loss}"
    );
    let grads = with_prefix(&t, "grad.");
    let mut worst = 0.0f64;
    rgm.visit_params("", &mut |name, p| {
        let want = grads[name].to_shape(p.grad.raw_dim()).unwrap().to_owned();
        if want.iter().any(|g| g.abs() > 1e-14) {
            worst = worst.max(relative_difference(name, &p.grad.mapv(|v| v as f64), &want));
        }
    });
    println!("f32 worst gradient relative difference {worst:.3e}");
    assert!(worst < 5e-4, "{worst:e}"); // measured 4.4e-5
}
