//! Times one way of running RGM on a 717×717 pair and prints one JSON line: the median of
//! `--reps` runs, the process's peak resident memory (VmHWM) and, for the full test-time
//! procedure, the share of each stage. One configuration per process, so that VmHWM is its own.
//!
//! ```text
//! cargo run --release -p rgm-benches --example speed -- --preset fast --what procedure \
//!     [--match-points 384] [--weights FILE] [--points 717] [--reps 5] [--precision bf16]
//! ```
//!
//! `--what`: `forward` (one evaluation-mode forward), `train` (forward in training mode, BCE
//! loss and backward; `gradient_fnv` hashes the bits of every parameter gradient after the
//! runs, so that two builds that print the same hash compute the same step bit for bit) or `procedure` (spec §4 with the paper's settings: 2 passes, cycle
//! consistency). The pair: `--points` points uniform in the unit ball, and the same points
//! rotated by (20°, 10°, 30°), moved by (0.2, −0.1, 0.3), in reverse order. Random weights unless
//! `--weights` (the cost does not depend on them, except through how many correspondences the
//! assignment sees).
//!
//! `product_gflop` is the FLOPs of the matrix products of one run (2 a multiply-add, as
//! `rgm_nn::gemm::multiply_adds` counts them) and `product_gflop_per_s` that over the median
//! time: the achieved rate to hold against the processor's peak (`benches/benches/gemm.rs`).
//!
//! `tools/speed/run.sh` runs every configuration of `docs/speed.md`.

use std::time::Instant;

use ndarray::Array2;
use rgm_benches::unit_ball_points;
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{PointCloud, RigidTransform, Vector3};
use rgm_match::Correspondences;
use rgm_model::network::{Config, Mode, Rgm, RgmCache};
use rgm_model::procedure::StageTimes;
use rgm_model::{ProcedureConfig, Registrar, RgmRegistrar};
use rgm_nn::{Compute, Parameters, Precision};

/// `n` points uniform in the unit ball and their copy at a known pose in reverse order;
/// source i is target n − 1 − i.
fn pair(n: usize) -> (PointCloud, PointCloud, Vec<(usize, usize)>) {
    let points = unit_ball_points(n, 1);
    let pose = RigidTransform::new(
        rotation_xyz_intrinsic(20f64.to_radians(), 10f64.to_radians(), 30f64.to_radians()),
        Vector3::new(0.2, -0.1, 0.3),
    );
    let target = points.iter().rev().map(|p| pose.apply(p)).collect();
    let truth = (0..n).map(|i| (i, n - 1 - i)).collect();
    (PointCloud::new(points), PointCloud::new(target), truth)
}

fn rows(cloud: &PointCloud) -> Array2<f32> {
    Array2::from_shape_fn((cloud.len(), 3), |(i, c)| cloud.points[i][c] as f32) // (N, 3)
}

/// The peak resident memory of this process in KiB (Linux; 0 elsewhere).
fn vm_hwm_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

/// FNV-1a over the bits of every parameter gradient, in the parameters' visiting order.
fn gradient_fnv(network: &Rgm<f32>) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    network.visit_params_ref("", &mut |_, p| {
        for x in p.grad.iter() {
            hash = (hash ^ u64::from(x.to_bits())).wrapping_mul(0x0100_0000_01b3);
        }
    });
    hash
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    rgm_nn::threads::flush_denormals_to_zero();
    let args: Vec<String> = std::env::args().collect();
    let preset = arg(&args, "--preset").unwrap_or_else(|| "paper".into());
    let what = arg(&args, "--what").unwrap_or_else(|| "procedure".into());
    let points: usize = arg(&args, "--points").map_or(Ok(717), |v| v.parse())?;
    let reps: usize = arg(&args, "--reps").map_or(Ok(5), |v| v.parse())?;
    let match_points: Option<usize> = arg(&args, "--match-points")
        .map(|v| v.parse())
        .transpose()?;
    let weights = arg(&args, "--weights");
    let precision: Precision =
        arg(&args, "--precision").map_or(Ok(Precision::F32), |v| v.parse())?;
    let config = Config::preset(&preset)?;
    let mut network = match &weights {
        None => Rgm::<f32>::new(config, 0)?,
        Some(file) => Rgm::load(config, file.as_ref())?,
    };
    network.set_compute(Compute::with_precision(precision));
    let (source, target, truth) = pair(points);
    let mut seconds = Vec::with_capacity(reps);
    let mut stages = Vec::new();
    let mut correspondences = 0;
    let mut gradients = "null".to_string();
    let counted_before = rgm_nn::gemm::multiply_adds();
    match what.as_str() {
        "forward" | "train" => {
            let (x, y) = (rows(&source), rows(&target));
            let gt = Correspondences::new(points, points, truth)?;
            let mut cache = RgmCache::default();
            for _ in 0..reps + 1 {
                let start = Instant::now();
                if what == "forward" {
                    network.forward(x.view(), y.view(), Mode::Eval, &mut cache)?;
                } else {
                    network.forward_backward(x.view(), y.view(), &gt, &mut cache)?;
                }
                seconds.push(start.elapsed().as_secs_f64());
            }
            if what == "train" {
                gradients = format!("\"{:016x}\"", gradient_fnv(&network));
            }
        }
        "procedure" => {
            let config = ProcedureConfig {
                match_points,
                precision,
                ..ProcedureConfig::default()
            };
            let mut registrar = RgmRegistrar::new(network, config);
            for _ in 0..reps + 1 {
                let start = Instant::now();
                let result = registrar.register(&source, &target);
                seconds.push(start.elapsed().as_secs_f64());
                correspondences = result.map_or(0, |r| r.result.inlier_count);
                stages.push(registrar.stage_times());
            }
        }
        other => return Err(format!("--what {other:?}: forward, train or procedure").into()),
    }
    // Every run computes the same products: their FLOPs (2 a multiply-add) per run.
    let product_gflop =
        2.0 * (rgm_nn::gemm::multiply_adds() - counted_before) as f64 / seconds.len() as f64 / 1e9;
    seconds.remove(0); // warm-up: buffers allocated, pages touched
    let stage_share = match stages.get(1..) {
        Some(s) if !s.is_empty() => {
            let total: f64 = s.iter().map(StageTimes::total).sum();
            let share = |f: fn(&StageTimes) -> f64| s.iter().map(f).sum::<f64>() / total;
            format!(
                r#"{{"prepare": {:.4}, "features": {:.4}, "blocks": {:.4}, "matching": {:.4}, "kabsch": {:.4}}}"#,
                share(|t| t.prepare),
                share(|t| t.features),
                share(|t| t.blocks),
                share(|t| t.matching),
                share(|t| t.kabsch)
            )
        }
        _ => "null".to_string(),
    };
    let text = |v: Option<String>| v.map_or("null".to_string(), |v| format!("{v:?}"));
    let line = format!(
        r#"{{"implementation": "rgm", "preset": {:?}, "what": {:?}, "points": {points}, "match_points": {}, "weights": {}, "reps": {reps}, "precision": "{precision}", "bf16_kernel": {:?}, "median_s": {:.4}, "seconds": {:?}, "vm_hwm_mib": {:.1}, "blas_threads": {}, "correspondences": {correspondences}, "gradient_fnv": {gradients}, "stage_share": {stage_share}, "product_gflop": {product_gflop:.4}, "product_gflop_per_s": {:.2}}}"#,
        preset,
        what,
        text(match_points.map(|m| m.to_string())).replace('"', ""),
        text(weights),
        rgm_nn::gemm::backend().unwrap_or("none"),
        median(seconds.clone()),
        seconds,
        vm_hwm_kib() as f64 / 1024.0,
        rgm_nn::threads::blas_threads(),
        product_gflop / median(seconds.clone()),
    );
    println!("{line}");
    Ok(())
}
