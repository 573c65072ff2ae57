//! The RGM network on one 717×717 partial pair (points in the unit ball), in f32: the forward
//! pass at test time (running statistics) and a training pass (forward in training mode, BCE
//! loss, backward), for the `small` and `paper` presets. Random weights: the cost does not
//! depend on them (Sinkhorn always runs its 20 rounds).
//!
//! Run: `cargo bench -p rgm-benches --bench model -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::Array2;
use rgm_benches::unit_ball_points;
use rgm_match::Correspondences;
use rgm_model::network::{Config, Mode, Rgm, RgmCache};

/// Points per cloud: the partial setting's crop of 1,024.
const N: usize = 717;

/// A (N, 3) f32 cloud in the unit ball, reproducible from `seed`.
fn cloud(seed: u64) -> Array2<f32> {
    let points = unit_ball_points(N, seed);
    Array2::from_shape_fn((N, 3), |(i, c)| points[i][c] as f32)
}

fn network(c: &mut Criterion) {
    rgm_nn::threads::flush_denormals_to_zero();
    let (x, y) = (cloud(1), cloud(2));
    // Ground truth: the first 500 points matched one to one, the rest outliers.
    let gt = Correspondences::new(N, N, (0..500).map(|i| (i, i)).collect()).unwrap();
    let mut group = c.benchmark_group("rgm_717");
    group.sample_size(10);
    for (name, config) in [("small", Config::small()), ("paper", Config::paper())] {
        let mut rgm = Rgm::<f32>::new(config, 0).unwrap();
        let mut cache = RgmCache::default();
        group.bench_function(BenchmarkId::new("forward_eval", name), |bench| {
            bench.iter(|| {
                rgm.forward(x.view(), y.view(), Mode::Eval, &mut cache)
                    .unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("forward_backward_train", name), |bench| {
            bench.iter(|| {
                rgm.forward_backward(x.view(), y.view(), &gt, &mut cache)
                    .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, network);
criterion_main!(benches);
