//! rgm-nn's heavy ops at RGM's sizes (N = 717 partial, 1,024 full; K = 20; H = 4), in f32 as
//! the model runs, next to the machine's single-precision GEMM peak. Throughput is FLOP/s
//! (criterion's "elem/s" = FLOP/s) for the GEMM-bound ops and rows·channels/s for the others.
//!
//! Run: `cargo bench -p rgm-benches --bench nn -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ndarray::linalg::general_mat_mul;
use ndarray::Array2;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rgm_benches::SIZES;
use rgm_nn::{
    edge_features_forward, gram_forward, l1_normalize_columns_forward, max_k_backward,
    max_k_forward, softmax_rows_forward, AttentionCache, BatchNorm, BatchNormCache, Compute,
    L1NormalizeCache, LayerNorm, LayerNormCache, Linear, MaxKCache, MultiHeadAttention,
};

const K: usize = 20;
const H: usize = 4;

/// A (rows, cols) f32 matrix uniform in [-1, 1), reproducible from `seed`.
fn uniform(rows: usize, cols: usize, seed: u64) -> Array2<f32> {
    let mut rng = StdRng::seed_from_u64(seed);
    Array2::from_shape_simple_fn((rows, cols), || rng.gen_range(-1.0..1.0))
}

/// The GEMM peak reference: square sgemm through the same BLAS path the ops use.
fn sgemm(c: &mut Criterion) {
    let mut group = c.benchmark_group("sgemm");
    group.sample_size(10);
    for n in [1024, 2048] {
        let (a, b) = (uniform(n, n, 1), uniform(n, n, 2)); // (n, n) each
        let mut out = Array2::<f32>::zeros((n, n)); // (n, n)
        group.throughput(Throughput::Elements(2 * (n as u64).pow(3)));
        group.bench_function(BenchmarkId::from_parameter(n), |bench| {
            bench.iter(|| general_mat_mul(1.0, &a, &b, 0.0, &mut out))
        });
    }
    group.finish();
}

/// The 1×1 convolutions of the feature extractor (rows N·K or N) and the transformer's C×C maps.
fn linear(c: &mut Criterion) {
    let mut group = c.benchmark_group("linear");
    group.sample_size(10);
    let n = 1024;
    for (rows, c_in, c_out, bias) in [
        (n * K, 64, 64, false),
        (n * K, 128, 256, false),
        (n, 512, 512, false),
        (n, 1024, 1024, true),
    ] {
        let lin = Linear::<f32>::new(c_in, c_out, bias, &mut StdRng::seed_from_u64(3));
        let mut lin_b = lin.clone();
        let inp = uniform(rows, c_in, 4); // (R, C_in)
        let dout = uniform(rows, c_out, 5); // (R, C_out)
        let mut out = Array2::<f32>::zeros((rows, c_out)); // (R, C_out)
        let mut dinp = Array2::<f32>::zeros((rows, c_in)); // (R, C_in)
        let flops = 2 * (rows * c_in * c_out) as u64;
        let id = format!("{rows}x{c_in}->{c_out}");
        group.throughput(Throughput::Elements(flops));
        group.bench_function(BenchmarkId::new("forward", &id), |b| {
            b.iter(|| {
                lin.forward(out.view_mut(), inp.view(), Compute::default())
                    .unwrap()
            })
        });
        group.throughput(Throughput::Elements(2 * flops));
        group.bench_function(BenchmarkId::new("backward", &id), |b| {
            b.iter(|| {
                lin_b
                    .backward(dinp.view_mut(), dout.view(), inp.view(), Compute::default())
                    .unwrap()
            })
        });
    }
    group.finish();
}

/// Self-attention of the edge generator: C = 1,024 (block 1) and 512 (block 2), H = 4.
fn attention(c: &mut Criterion) {
    let mut group = c.benchmark_group("attention");
    group.sample_size(10);
    for n in SIZES {
        for ch in [1024, 512] {
            let mut mha =
                MultiHeadAttention::<f32>::new(ch, H, &mut StdRng::seed_from_u64(6)).unwrap();
            let x = uniform(n, ch, 7); // (N, C)
            let dout = uniform(n, ch, 8); // (N, C)
            let mut out = Array2::<f32>::zeros((n, ch)); // (N, C)
            let mut dx = Array2::<f32>::zeros((n, ch)); // (N, C)
            let mut cache = AttentionCache::default();
            // 4 C×C maps + scores + weighted values; the backward is twice that.
            let flops = (8 * n * ch * ch + 4 * n * n * ch) as u64;
            let id = format!("N{n}_C{ch}");
            group.throughput(Throughput::Elements(flops));
            group.bench_function(BenchmarkId::new("forward", &id), |b| {
                b.iter(|| {
                    mha.forward(
                        out.view_mut(),
                        x.view(),
                        x.view(),
                        &mut cache,
                        Compute::default(),
                    )
                    .unwrap()
                })
            });
            group.throughput(Throughput::Elements(2 * flops));
            mha.forward(
                out.view_mut(),
                x.view(),
                x.view(),
                &mut cache,
                Compute::default(),
            )
            .unwrap(); // fills the cache
            group.bench_function(BenchmarkId::new("backward", &id), |b| {
                b.iter(|| {
                    mha.backward(
                        dx.view_mut(),
                        None,
                        dout.view(),
                        x.view(),
                        x.view(),
                        &mut cache,
                        Compute::default(),
                    )
                    .unwrap()
                })
            });
        }
    }
    group.finish();
}

/// The normalisations: layer norm on (N, 1,024), batch norm on (N·K, 64) and (N·K, 256).
fn norms(c: &mut Criterion) {
    let mut group = c.benchmark_group("norms");
    group.sample_size(10);
    let n = 1024;
    let (rows, ch) = (n, 1024);
    let mut ln = LayerNorm::<f32>::new(ch);
    let (x, dout) = (uniform(rows, ch, 9), uniform(rows, ch, 10)); // (N, C) each
    let (mut out, mut dx, mut cache) = (
        Array2::<f32>::zeros((rows, ch)),
        Array2::<f32>::zeros((rows, ch)),
        LayerNormCache::default(),
    );
    group.throughput(Throughput::Elements((rows * ch) as u64));
    group.bench_function(BenchmarkId::new("layer_norm_forward", rows), |b| {
        b.iter(|| ln.forward(out.view_mut(), x.view(), &mut cache).unwrap())
    });
    ln.forward(out.view_mut(), x.view(), &mut cache).unwrap(); // fills the cache
    group.bench_function(BenchmarkId::new("layer_norm_backward", rows), |b| {
        b.iter(|| {
            ln.backward(dx.view_mut(), dout.view(), x.view(), &cache)
                .unwrap()
        })
    });
    for ch in [64, 256] {
        let rows = n * K;
        let mut bn = BatchNorm::<f32>::new(ch);
        let (x, dout) = (uniform(rows, ch, 11), uniform(rows, ch, 12)); // (N·K, C) each
        let (mut out, mut dx, mut cache) = (
            Array2::<f32>::zeros((rows, ch)),
            Array2::<f32>::zeros((rows, ch)),
            BatchNormCache::default(),
        );
        group.throughput(Throughput::Elements((rows * ch) as u64));
        group.bench_function(
            BenchmarkId::new("batch_norm_forward", format!("{rows}x{ch}")),
            |b| {
                b.iter(|| {
                    bn.forward(out.view_mut(), x.view(), true, &mut cache)
                        .unwrap()
                })
            },
        );
        bn.forward(out.view_mut(), x.view(), true, &mut cache)
            .unwrap(); // fills the cache
        group.bench_function(
            BenchmarkId::new("batch_norm_backward", format!("{rows}x{ch}")),
            |b| {
                b.iter(|| {
                    bn.backward(dx.view_mut(), dout.view(), x.view(), &cache)
                        .unwrap()
                })
            },
        );
    }
    group.finish();
}

/// The DGCNN input stage: edge gather (N, 3) → (N·K, 6), and max over K of (N·K, 64).
fn edge_and_max(c: &mut Criterion) {
    let mut group = c.benchmark_group("edge_max");
    group.sample_size(10);
    for n in SIZES {
        let x = uniform(n, 3, 13); // (N, 3)
        let mut rng = StdRng::seed_from_u64(14);
        let idx = Array2::from_shape_simple_fn((n, K), || rng.gen_range(0..n)); // (N, K)
        let mut edges = Array2::<f32>::zeros((n * K, 6)); // (N·K, 6)
        group.throughput(Throughput::Elements((n * K * 6) as u64));
        group.bench_function(BenchmarkId::new("edge_gather", n), |b| {
            b.iter(|| edge_features_forward(edges.view_mut(), x.view(), idx.view()).unwrap())
        });
        let feat = uniform(n * K, 64, 15); // (N·K, 64)
        let dmax = uniform(n, 64, 16); // (N, 64)
        let (mut max, mut dfeat, mut cache) = (
            Array2::<f32>::zeros((n, 64)),
            Array2::<f32>::zeros((n * K, 64)),
            MaxKCache::default(),
        );
        group.throughput(Throughput::Elements((n * K * 64) as u64));
        group.bench_function(BenchmarkId::new("max_k_forward", n), |b| {
            b.iter(|| max_k_forward(max.view_mut(), feat.view(), K, &mut cache).unwrap())
        });
        max_k_forward(max.view_mut(), feat.view(), K, &mut cache).unwrap(); // fills the cache
        group.bench_function(BenchmarkId::new("max_k_backward", n), |b| {
            b.iter(|| max_k_backward(dfeat.view_mut(), dmax.view(), K, &cache).unwrap())
        });
    }
    group.finish();
}

/// The soft adjacency of one cloud: scores T Tᵀ/√C, row softmax, L1 normalisation of the columns.
fn adjacency(c: &mut Criterion) {
    let mut group = c.benchmark_group("adjacency");
    group.sample_size(10);
    let ch = 512;
    for n in SIZES {
        let t = uniform(n, ch, 17); // (N, C)
        let (mut scores, mut soft, mut adj) = (
            Array2::<f32>::zeros((n, n)),
            Array2::<f32>::zeros((n, n)),
            Array2::<f32>::zeros((n, n)),
        ); // (N, N) each
        let mut cache = L1NormalizeCache::default();
        let alpha = 1.0 / (ch as f32).sqrt();
        group.throughput(Throughput::Elements((2 * n * n * ch) as u64));
        group.bench_function(BenchmarkId::new("gram", n), |b| {
            b.iter(|| gram_forward(scores.view_mut(), t.view(), alpha, Compute::default()).unwrap())
        });
        group.throughput(Throughput::Elements((n * n) as u64));
        group.bench_function(BenchmarkId::new("softmax_rows", n), |b| {
            b.iter(|| softmax_rows_forward(soft.view_mut(), scores.view()).unwrap())
        });
        group.bench_function(BenchmarkId::new("l1_normalize_columns", n), |b| {
            b.iter(|| {
                l1_normalize_columns_forward(adj.view_mut(), soft.view(), &mut cache).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    sgemm,
    linear,
    attention,
    norms,
    edge_and_max,
    adjacency
);
criterion_main!(benches);
