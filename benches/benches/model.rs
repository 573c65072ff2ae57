//! The RGM network on one 717×717 pair (points in the unit ball), in f32, for the `paper` and
//! `fast` presets: the forward pass at test time (running statistics), a training pass
//! (forward in training mode, BCE loss, backward) and the full test-time procedure of spec §4
//! (2 passes, cycle consistency; features computed once per cloud), the latter also as rgm
//! ships it (`fast`, matching on 384 of the points). Random weights: the cost does not depend on
//! them (Sinkhorn always runs its 20 rounds; random weights leave every row an inlier, the
//! assignment's costliest case). `docs/speed.md` has the numbers and the peak memory.
//!
//! Run: `cargo bench -p rgm-benches --bench model -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::Array2;
use rgm_benches::unit_ball_points;
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{PointCloud, RigidTransform, Vector3};
use rgm_match::Correspondences;
use rgm_model::network::{Config, Mode, Rgm, RgmCache};
use rgm_model::{ProcedureConfig, Registrar, RgmRegistrar};

/// Points per cloud: the partial setting's crop of 1,024.
const N: usize = 717;

/// A (N, 3) f32 cloud.
fn rows(cloud: &PointCloud) -> Array2<f32> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c] as f32)
}

/// N points in the unit ball and their copy at a known pose in reverse order (source i is
/// target N − 1 − i).
fn pair() -> (PointCloud, PointCloud) {
    let points = unit_ball_points(N, 1);
    let pose = RigidTransform::new(
        rotation_xyz_intrinsic(20f64.to_radians(), 10f64.to_radians(), 30f64.to_radians()),
        Vector3::new(0.2, -0.1, 0.3),
    );
    let target = points.iter().rev().map(|p| pose.apply(p)).collect();
    (PointCloud::new(points), PointCloud::new(target))
}

fn network(c: &mut Criterion) {
    rgm_nn::threads::flush_denormals_to_zero();
    let (source, target) = pair();
    let (x, y) = (rows(&source), rows(&target)); // (N, 3) each
    let gt = Correspondences::new(N, N, (0..N).map(|i| (i, N - 1 - i)).collect()).unwrap();
    let mut group = c.benchmark_group("rgm_717");
    group.sample_size(10);
    for (name, config) in [("fast", Config::fast()), ("paper", Config::paper())] {
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
        let matched: &[(&str, Option<usize>)] = if name == "fast" {
            &[("fast", None), ("fast_match384", Some(384))]
        } else {
            &[("paper", None)]
        };
        for &(label, match_points) in matched {
            let config = ProcedureConfig {
                match_points,
                ..ProcedureConfig::default()
            };
            let mut registrar = RgmRegistrar::new(rgm.clone(), config);
            group.bench_function(BenchmarkId::new("procedure", label), |bench| {
                bench.iter(|| registrar.register(&source, &target).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, network);
criterion_main!(benches);
