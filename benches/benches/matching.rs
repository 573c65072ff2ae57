//! rgm-match at the paper's sizes (N = M = 717 partial, 1,024 full), in f32 as the model runs:
//! Sinkhorn forward and backward in both forms, and the linear assignment (ours against
//! pathfinding's Kuhn–Munkres on the same scores scaled to integers), on uniform scores and on a
//! Sinkhorn output close to a permutation (what the model produces).
//!
//! Run: `cargo bench -p rgm-benches --bench matching -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::Array2;
use rand::{rngs::StdRng, seq::SliceRandom, Rng, SeedableRng};
use rgm_benches::SIZES;
use rgm_match::{
    max_score_assignment, sinkhorn_backward, sinkhorn_forward, SinkhornCache, SinkhornConfig,
    SinkhornForm,
};

/// An N×N matrix uniform in [lo, hi), reproducible from `seed`.
fn uniform(n: usize, lo: f64, hi: f64, seed: u64) -> Array2<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    Array2::from_shape_simple_fn((n, n), || rng.gen_range(lo..hi))
}

fn sinkhorn(c: &mut Criterion) {
    let mut group = c.benchmark_group("sinkhorn");
    group.sample_size(10);
    for n in SIZES {
        let s = uniform(n, -3.0, 3.0, 1).mapv(|v| v as f32); // (N, N) an instance-normalised range
        let dc = uniform(n, -1.0, 1.0, 2).mapv(|v| v as f32); // (N, N)
        for form in [SinkhornForm::Log, SinkhornForm::Scaling] {
            let cfg = SinkhornConfig {
                form,
                ..SinkhornConfig::default()
            };
            let mut cache = SinkhornCache::new(n, n, &cfg);
            let mut out = Array2::<f32>::zeros((n, n)); // (N, N)
            let mut ds = Array2::<f32>::zeros((n, n)); // (N, N)
            group.bench_function(BenchmarkId::new(format!("forward_{form:?}"), n), |b| {
                b.iter(|| sinkhorn_forward(out.view_mut(), s.view(), &cfg, &mut cache).unwrap())
            });
            assert_eq!(cache.form(), form);
            group.bench_function(BenchmarkId::new(format!("backward_{form:?}"), n), |b| {
                b.iter(|| {
                    sinkhorn_backward(ds.view_mut(), dc.view(), s.view(), out.view(), &cache)
                        .unwrap()
                })
            });
        }
    }
    group.finish();
}

/// A Sinkhorn output like a trained model's: log-affinity 4 on a random permutation, noise in ±1.
fn near_permutation(n: usize, seed: u64) -> Array2<f64> {
    let mut perm: Vec<usize> = (0..n).collect();
    perm.shuffle(&mut StdRng::seed_from_u64(seed));
    let mut s = uniform(n, -1.0, 1.0, seed); // (N, N)
    for (i, &j) in perm.iter().enumerate() {
        s[[i, j]] += 4.0;
    }
    let cfg = SinkhornConfig::default();
    let mut c = Array2::zeros((n, n)); // (N, N)
    sinkhorn_forward(
        c.view_mut(),
        s.view(),
        &cfg,
        &mut SinkhornCache::new(n, n, &cfg),
    )
    .unwrap();
    c
}

fn assignment(c: &mut Criterion) {
    let mut group = c.benchmark_group("assignment");
    group.sample_size(10);
    for n in SIZES {
        for (kind, scores) in [
            ("uniform", uniform(n, 0.0, 1.0, 3)),
            ("sinkhorn", near_permutation(n, 4)),
        ] {
            group.bench_function(
                BenchmarkId::new(format!("max_score_assignment_{kind}"), n),
                |b| b.iter(|| max_score_assignment(scores.view()).unwrap()),
            );
            let ints = scores.iter().map(|&v| (v * 1e6) as i64).collect();
            let ints = pathfinding::matrix::Matrix::from_vec(n, n, ints).unwrap();
            group.bench_function(
                BenchmarkId::new(format!("pathfinding_kuhn_munkres_{kind}"), n),
                |b| b.iter(|| pathfinding::kuhn_munkres::kuhn_munkres(&ints)),
            );
        }
    }
    group.finish();
}

criterion_group!(benches, sinkhorn, assignment);
criterion_main!(benches);
