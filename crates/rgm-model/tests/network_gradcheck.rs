//! Whole-model gradient check: the hand-written backward of the whole network against central
//! differences in f64, on the tiny configuration and both ablation structures, in training and
//! evaluation mode. Every parameter tensor is checked at a few entries (its largest-gradient
//! entry and random ones).
//!
//! The loss is L = Σ C̃ ⊙ R for a fixed random R, so `backward` is called with dC̃ = R.

use ndarray::{Array2, ArrayD};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rgm_model::network::{Config, Edges, Mode, Rgm, RgmCache, Scoring};
use rgm_nn::Parameters;
use std::collections::HashMap;

/// Central-difference step.
const STEP: f64 = 1e-5;
/// Largest accepted |analytic − numeric| / max |analytic gradient of the tensor|.
const TOL: f64 = 1e-5;
/// The rounding noise of a central difference of this loss at this step (|L| ~ 1: f64's
/// rounding of L, about 1e-15, over STEP): entries whose gradient is a millionth of the loss scale (the query
/// and key maps of the second block) cannot be checked more finely than this in f64. A larger
/// step would cross ReLU and max-over-K kinks in the feature extractor.
const NOISE: f64 = 1e-9;
/// Random entries checked per tensor, besides its largest-gradient entry.
const SAMPLES: usize = 3;

fn uniform(shape: (usize, usize), seed: u64) -> Array2<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    Array2::from_shape_simple_fn(shape, || rng.gen_range(-1.0..1.0))
}

fn loss(rgm: &mut Rgm<f64>, x: &Array2<f64>, y: &Array2<f64>, r: &Array2<f64>, mode: Mode) -> f64 {
    let mut cache = RgmCache::default();
    rgm.forward(x.view(), y.view(), mode, &mut cache).unwrap();
    (&cache.c_soft() * r).sum()
}

/// Adds `delta` to entry `j` (memory order) of the parameter called `name`.
fn nudge(rgm: &mut Rgm<f64>, name: &str, j: usize, delta: f64) {
    rgm.visit_params("", &mut |n, mut p| {
        if n == name {
            p.value.as_slice_memory_order_mut().unwrap()[j] += delta;
        }
    });
}

fn check(config: Config, mode: Mode) {
    let what = format!("{:?}/{:?} {mode:?}", config.scoring, config.edges);
    let mut rgm = Rgm::<f64>::new(config, 11).unwrap();
    let (x, y) = (uniform((12, 3), 1), uniform((10, 3), 2));
    if mode == Mode::Eval {
        // Running statistics moved from their (0, 1) start by training passes, as in use.
        let mut cache = RgmCache::default();
        for _ in 0..10 {
            rgm.forward(x.view(), y.view(), Mode::Train, &mut cache)
                .unwrap();
        }
    }
    let r = uniform((12, 10), 3);
    let mut cache = RgmCache::default();
    rgm.forward(x.view(), y.view(), mode, &mut cache).unwrap();
    rgm.zero_grad();
    rgm.backward(r.view(), &mut cache).unwrap();
    let mut analytic: Vec<(String, ArrayD<f64>)> = Vec::new();
    rgm.visit_params("", &mut |name, p| {
        analytic.push((name.to_string(), p.grad.to_owned()))
    });
    let mut rng = StdRng::seed_from_u64(4);
    let (mut worst, mut below_noise) = ((0.0f64, String::new()), 0);
    for (name, grad) in &analytic {
        let grad = grad.as_standard_layout();
        let g = grad.as_slice().unwrap();
        let (argmax, scale) =
            g.iter().enumerate().fold(
                (0, 0.0f64),
                |(a, m), (i, v)| if v.abs() > m { (i, v.abs()) } else { (a, m) },
            );
        let mut entries = vec![argmax];
        entries.extend((0..SAMPLES).map(|_| rng.gen_range(0..g.len())));
        for &j in &entries {
            nudge(&mut rgm, name, j, STEP);
            let plus = loss(&mut rgm, &x, &y, &r, mode);
            nudge(&mut rgm, name, j, -2.0 * STEP);
            let minus = loss(&mut rgm, &x, &y, &r, mode);
            nudge(&mut rgm, name, j, STEP);
            let numeric = (plus - minus) / (2.0 * STEP);
            if scale < 1e-12 {
                // Attention key biases: the softmax ignores them, both gradients are zero.
                assert!(
                    numeric.abs() < 1e-8,
                    "{what} {name}[{j}]: numeric {numeric:e}, analytic 0"
                );
                continue;
            }
            let diff = (g[j] - numeric).abs();
            let e = diff / scale;
            assert!(
                e < TOL || diff < NOISE,
                "{what} {name}[{j}]: analytic {:e}, numeric {numeric:e}, relative {e:e}",
                g[j]
            );
            if e >= TOL {
                below_noise += 1;
            } else if e > worst.0 {
                worst = (e, format!("{name}[{j}]"));
            }
        }
    }
    println!(
        "{what}: {} tensors; worst relative error {} {:.3e}; {below_noise} entries \
         above {TOL:e} but within the noise floor",
        analytic.len(),
        worst.1,
        worst.0
    );
}

#[test]
fn tiny_network_gradients_match_central_differences() {
    check(Config::tiny(), Mode::Train);
}

#[test]
fn tiny_network_gradients_match_central_differences_in_evaluation_mode() {
    check(Config::tiny(), Mode::Eval);
}

#[test]
fn var1_structure_gradients_match_central_differences() {
    check(
        Config {
            scoring: Scoring::Var1,
            ..Config::tiny()
        },
        Mode::Train,
    );
}

#[test]
fn var2_structure_gradients_match_central_differences() {
    check(
        Config {
            edges: Edges::Full,
            ..Config::tiny()
        },
        Mode::Train,
    );
}

#[test]
fn analytic_gradients_are_not_all_zero() {
    // Guards the check above against a vacuous pass: most tensors carry a real gradient.
    let mut rgm = Rgm::<f64>::new(Config::tiny(), 11).unwrap();
    let mut cache = RgmCache::default();
    let (x, y) = (uniform((12, 3), 1), uniform((10, 3), 2));
    rgm.forward(x.view(), y.view(), Mode::Train, &mut cache)
        .unwrap();
    rgm.backward(uniform((12, 10), 3).view(), &mut cache)
        .unwrap();
    let mut nonzero = HashMap::new();
    rgm.visit_params("", &mut |name, p| {
        nonzero.insert(name.to_string(), p.grad.iter().any(|g| g.abs() > 1e-10));
    });
    let zero: Vec<_> = nonzero
        .iter()
        .filter(|(_, &nz)| !nz)
        .map(|(n, _)| n.clone())
        .collect();
    assert!(
        zero.iter().all(|n| n.ends_with("linears.1.bias")),
        "{zero:?}"
    );
}
