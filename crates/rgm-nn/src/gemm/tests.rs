use super::*;
use crate::bf16::round_to_bf16;
use ndarray::{Array2, ArrayView1};
use rand::{rngs::StdRng, Rng, SeedableRng};

/// A (rows, cols) matrix uniform in [-1, 1) (far from bf16's flushed denormals).
fn uniform(rows: usize, cols: usize, seed: u64) -> Array2<f32> {
    let mut rng = StdRng::seed_from_u64(seed);
    Array2::from_shape_simple_fn((rows, cols), || rng.gen_range(-1.0..1.0))
}

/// What `tdpbf16ps` computes on one block, read from the packed layout as the module doc
/// describes it: A slices row-major, B slices as two 16-column tiles of VNNI pairs.
/// With alpha and beta as the AMX tiles get them ([`scaled_block`]).
fn reference_block(a: &[u16], b: &[u16], out: ArrayViewMut2<f32>, alpha: f32, beta: f32) {
    let f = |bits: u16| f32::from_bits(u32::from(bits) << 16);
    let plain = |mut out: ArrayViewMut2<f32>, accumulate: bool| {
        if !accumulate {
            out.fill(0.0);
        }
        for (a, b) in a.chunks_exact(1024).zip(b.chunks_exact(1024)) {
            for (i, j) in (0..32).flat_map(|i| (0..32).map(move |j| (i, j))) {
                let b_at = |k: usize| b[(j / 16) * 512 + (k / 2) * 32 + (j % 16) * 2 + k % 2];
                out[(i, j)] += (0..32).map(|k| f(a[i * 32 + k]) * f(b_at(k))).sum::<f32>();
            }
        }
    };
    scaled_block(plain, out, alpha, beta);
}

/// Checks `got` = alpha · round(a) · round(b) + beta · c0 up to f32 accumulation: each entry
/// within (K + 2) units of roundoff of Σ|a·b| (plus beta's share) of the f64 product.
fn assert_bf16_product(
    got: ArrayView2<'_, f32>,
    product: (f32, ArrayView2<'_, f32>, ArrayView2<'_, f32>),
    accumulated: (f32, ArrayView2<'_, f32>),
) {
    assert_product_of(|x| round_to_bf16(x) as f64, got, product, accumulated);
}

/// Checks `got` = alpha · r(a) · r(b) + beta · c0 up to f32 accumulation, `r` the inputs'
/// rounding: each entry within (K + 2) units of roundoff of Σ|r(a)·r(b)| (plus beta's
/// share) of the f64 product.
fn assert_product_of(
    r: impl Fn(f32) -> f64,
    got: ArrayView2<'_, f32>,
    (alpha, a, b): (f32, ArrayView2<'_, f32>, ArrayView2<'_, f32>),
    (beta, c0): (f32, ArrayView2<'_, f32>),
) {
    let k = a.ncols();
    let (ra, rb) = (a.mapv(&r), b.mapv(&r));
    let exact = ra.dot(&rb) * alpha as f64 + c0.mapv(|x| x as f64) * beta as f64;
    let size = ra.mapv(f64::abs).dot(&rb.mapv(f64::abs)) * (alpha as f64).abs()
        + c0.mapv(|x| (x as f64).abs()) * (beta as f64).abs();
    let u = f32::EPSILON as f64 / 2.0;
    for ((ij, &g), (&e, &s)) in got.indexed_iter().zip(exact.iter().zip(&size)) {
        let tol = (k + 2) as f64 * u * s + f32::MIN_POSITIVE as f64;
        assert!(
            (g as f64 - e).abs() <= tol,
            "entry {ij:?}: got {g}, exact {e} (tolerance {tol:e}, K = {k})"
        );
    }
}

/// The (M, K, N) shapes tested: single elements, edges off every multiple of 16 and 32,
/// K = 0, and a B wider than one L2 panel.
const SHAPES: [(usize, usize, usize); 7] = [
    (1, 1, 1),
    (17, 33, 15),
    (45, 70, 100),
    (64, 64, 64),
    (100, 3, 37),
    (5, 0, 7),
    (33, 300, 500),
];

/// A bf16 product under test: `(alpha, a, b, beta, c)`.
type MatMul<'m> = dyn FnMut(f32, ArrayView2<f32>, ArrayView2<f32>, f32, ArrayViewMut2<f32>) + 'm;

/// A check of a product's result: `(got, (alpha, a, b), (beta, c0))`.
type Check = fn(
    ArrayView2<'_, f32>,
    (f32, ArrayView2<'_, f32>, ArrayView2<'_, f32>),
    (f32, ArrayView2<'_, f32>),
);

/// Every case of [`SHAPES`] through `mul`, checked as bf16 products.
fn check_cases(mul: &mut MatMul) {
    check_cases_with(mul, assert_bf16_product);
}

/// Checks `got` = alpha · a · b + beta · c0 in f32 arithmetic (see [`assert_product_of`]).
fn assert_f32_product(
    got: ArrayView2<'_, f32>,
    product: (f32, ArrayView2<'_, f32>, ArrayView2<'_, f32>),
    accumulated: (f32, ArrayView2<'_, f32>),
) {
    assert_product_of(f64::from, got, product, accumulated);
}

/// Every case of [`SHAPES`] through `mul`: plain, both operands transposed views, strided
/// views, `beta = 1` accumulation into C (as the backward passes use), and into a
/// transposed C with alpha ≠ 1; each result checked by `check`.
fn check_cases_with(mul: &mut MatMul, check: Check) {
    for (seed, &(m, k, n)) in (0u64..).step_by(8).zip(&SHAPES) {
        let (a, b) = (uniform(m, k, seed), uniform(k, n, seed + 1));
        let c0 = uniform(m, n, seed + 2);
        // (K, M) and (N, K) stored: `.t()` views with unit stride down the rows.
        let (at, bt) = (a.t().to_owned(), b.t().to_owned());
        // Every other row and every third column of larger matrices.
        let a_big = uniform(2 * m, 3 * k, seed + 3);
        let b_big = uniform(2 * k, 3 * n, seed + 4);
        let (a_str, b_str) = (a_big.slice(s![..;2, ..;3]), b_big.slice(s![..;2, ..;3]));
        let mut c = c0.clone();
        mul(1.0, a.view(), b.view(), 0.0, c.view_mut());
        check(c.view(), (1.0, a.view(), b.view()), (0.0, c0.view()));
        let mut c = c0.clone();
        mul(1.0, at.t(), bt.t(), 0.0, c.view_mut());
        check(c.view(), (1.0, a.view(), b.view()), (0.0, c0.view()));
        let mut c = c0.clone();
        mul(1.0, a_str, b_str, 0.0, c.view_mut());
        check(c.view(), (1.0, a_str, b_str), (0.0, c0.view()));
        // Accumulating into C itself (as the backward passes do): c += a · b.
        let mut c = c0.clone();
        mul(1.0, a.view(), b.view(), 1.0, c.view_mut());
        check(c.view(), (1.0, a.view(), b.view()), (1.0, c0.view()));
        // Scaled into C itself (as the attention's scores and their gradients):
        // c = 0.75 · a · b, and c = 0.75 · a · b − 0.5 · c.
        for beta in [0.0, -0.5] {
            let mut c = c0.clone();
            mul(0.75, a.view(), b.view(), beta, c.view_mut());
            check(c.view(), (0.75, a.view(), b.view()), (beta, c0.view()));
        }
        // Into a transposed destination, accumulating: c (N, M) stored, cᵀ += -0.5 · a · b.
        let mut ct = c0.t().to_owned();
        mul(-0.5, a.view(), b.view(), 1.0, ct.view_mut().reversed_axes());
        check(ct.t(), (-0.5, a.view(), b.view()), (1.0, c0.view()));
    }
}

#[test]
fn a_large_product_gives_the_same_bits_on_one_thread_and_two() {
    // Large enough to be split by rows where the AVX-512 kernel runs it.
    let a = Array2::from_shape_fn((301, 128), |(i, j)| {
        ((i * 7 + j * 13) % 23) as f32 * 0.37 - 4.1
    });
    let b = Array2::from_shape_fn((128, 257), |(i, j)| {
        ((i * 5 + j * 11) % 19) as f32 * 0.29 - 2.3
    });
    const { assert!(301 * 128 * 257 >= SIDE_BY_SIDE_MULTIPLY_ADDS) };
    let product = |threads: usize| {
        let mut c = Array2::from_elem((301, 257), 0.5f32);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| mat_mul(1.0, &a, &b, 2.0, &mut c, Compute::default()));
        c
    };
    assert_eq!(product(1), product(2));
}

#[test]
fn the_vector_packing_lays_out_what_the_one_by_one_packing_does() {
    if !bf16_available() {
        eprintln!("no AVX-512 BF16: the vector packing does not run here");
        return;
    }
    // Shapes around the 16-lane vectors and the 32-wide slices, odd K included; each
    // operand as rows-contiguous and as a transposed view.
    for (r, c) in [
        (1, 1),
        (7, 5),
        (16, 32),
        (31, 33),
        (33, 47),
        (64, 17),
        (40, 96),
    ] {
        let x = uniform(r, c, (r * 100 + c) as u64);
        let xt = x.t().to_owned();
        for v in [x.view(), xt.t()] {
            let kp = c.next_multiple_of(32); // as A (r, c)
            let mut want = vec![0u16; r.next_multiple_of(32) * kp];
            pack_a_one_by_one(v, kp, &mut want);
            let mut got = vec![7u16; 1 << 14]; // stale contents must not survive
            assert_eq!(
                pack_a(v, kp, &mut got),
                want,
                "A {r} × {c}, strides {:?}",
                v.strides()
            );
            let kp = r.next_multiple_of(32); // as B (r, c)
            let mut want = vec![0u16; c.next_multiple_of(32) * kp];
            pack_b_one_by_one(v, kp, &mut want);
            let mut got = vec![7u16; 1 << 14];
            assert_eq!(
                pack_b(v, kp, &mut got),
                want,
                "B {r} × {c}, strides {:?}",
                v.strides()
            );
        }
    }
}

#[test]
fn packing_blocking_and_write_back_give_the_bf16_product_on_every_machine() {
    check_cases(&mut |alpha, a, b, beta, c| packed_mat_mul(alpha, a, b, beta, c, reference_block));
}

/// A block function of [`packed_mat_mul`]: the reference or a kernel.
type BlockOf<'k> = Box<dyn FnMut(&[u16], &[u16], ArrayViewMut2<f32>, f32, f32) + 'k>;

/// Panics, naming `case`, unless `got` and `expected` hold the same bits.
fn assert_same_bits(got: &Array2<f32>, expected: &Array2<f32>, case: &str) {
    assert_eq!(
        got.mapv(f32::to_bits),
        expected.mapv(f32::to_bits),
        "{case}"
    );
}

/// The reference block and each kernel this processor runs, by name.
fn block_ofs() -> Vec<(&'static str, BlockOf<'static>)> {
    let mut block_ofs: Vec<(&str, BlockOf)> = vec![("reference", Box::new(reference_block))];
    if let Some(mut kernel) = kernels::Kernel::new() {
        block_ofs.push((
            "fastest kernel",
            Box::new(move |a, b, out, al, be| kernel.block(a, b, out, al, be)),
        ));
    }
    if let Some(mut kernel) = kernels::Avx512Bf16::new() {
        block_ofs.push((
            "AVX-512 BF16",
            Box::new(move |a, b, out, al, be| kernel.block(a, b, out, al, be)),
        ));
    }
    block_ofs
}

#[test]
fn a_product_and_its_transposed_product_give_the_same_bits() {
    let mut block_ofs = block_ofs();
    // The attention's Pᵀ · dO, and edges off 32: A stored column by column, so that
    // `packed_mat_mul` computes cᵀ = bᵀ · aᵀ, whose C is strided (the scratch blocks).
    for (seed, (m, k, n)) in [(0, (384, 384, 32)), (4, (45, 70, 20))] {
        let (at, b) = (uniform(k, m, seed), uniform(k, n, seed + 1));
        let c0 = uniform(m, n, seed + 2);
        let a = at.t();
        assert!(layout_work(b.t(), a.t(), c0.t()) < layout_work(a, b.view(), c0.view()));
        for (name, block_of) in &mut block_ofs {
            for (alpha, beta) in [(1.0, 0.0), (1.0, 1.0), (0.75, -0.5)] {
                let (mut swapped, mut given) = (c0.clone(), c0.clone());
                packed_mat_mul(alpha, a, b.view(), beta, swapped.view_mut(), &mut *block_of);
                packed_mat_mul_as_given(alpha, a, b.view(), beta, given.view_mut(), &mut *block_of);
                let case = format!("{name}, ({m}, {k}, {n}), alpha {alpha}, beta {beta}");
                assert_same_bits(&swapped, &given, &case);
            }
        }
    }
}

#[test]
fn a_product_summed_in_parts_along_k_gives_the_whole_products_bits() {
    // As the attention's backward sums dVᵀ and dKᵀ over blocks of 128 query rows: parts
    // of K at multiples of 32, each accumulated onto C (alpha 1, beta 1); C's edges too.
    for (name, block_of) in &mut block_ofs() {
        for (seed, (m, k, n), parts) in [(8, (32, 384, 64), 128), (12, (45, 150, 20), 64)] {
            let (a, b) = (uniform(m, k, seed), uniform(k, n, seed + 1));
            let c0 = uniform(m, n, seed + 2);
            let mut whole = c0.clone();
            packed_mat_mul(
                1.0,
                a.view(),
                b.view(),
                1.0,
                whole.view_mut(),
                &mut *block_of,
            );
            let mut summed = c0.clone();
            for k0 in (0..k).step_by(parts) {
                let part = k0..(k0 + parts).min(k);
                let (a, b) = (a.slice(s![.., part.clone()]), b.slice(s![part, ..]));
                packed_mat_mul(1.0, a, b, 1.0, summed.view_mut(), &mut *block_of);
            }
            let case = format!("{name}, ({m}, {k}, {n}) in parts of {parts}");
            assert_same_bits(&summed, &whole, &case);
        }
    }
}

#[test]
fn the_bf16_check_tells_an_f32_product_apart() {
    // The tolerance of the checks above is far below bf16's rounding: exact f32 fails it.
    let (a, b) = (uniform(40, 64, 1), uniform(64, 40, 2));
    let mut c = Array2::zeros((40, 40));
    general_mat_mul(1.0, &a, &b, 0.0, &mut c);
    let zero = Array2::zeros((40, 40));
    let caught = std::panic::catch_unwind(|| {
        assert_bf16_product(c.view(), (1.0, a.view(), b.view()), (0.0, zero.view()))
    });
    assert!(caught.is_err());
}

#[test]
fn the_kernel_detected_agrees_with_the_cpu_flags() {
    let flags = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let has = |f: &str| flags.split_whitespace().any(|w| w == f);
    // Linux lists the AMX flags only when it supports AMX (≥ 5.16, which grants it).
    let expected = if has("amx_bf16") && has("amx_tile") && cfg!(target_os = "linux") {
        Some("amx")
    } else if has("avx512_bf16") {
        Some("avx512_bf16")
    } else {
        None
    };
    assert_eq!(
        backend(),
        expected,
        "/proc/cpuinfo and the detection disagree"
    );
    assert_eq!(kernels::amx_available(), expected == Some("amx"));
}

#[test]
fn the_kernels_give_the_bf16_product_where_the_processor_has_them() {
    if !bf16_available() {
        eprintln!("no AMX, no AVX-512 BF16: no kernel runs (the packing test covers the rest)");
        return;
    }
    check_cases(&mut |alpha, a, b, beta, c| bf16_mat_mul(alpha, a, b, beta, c));
    // On another thread too: each thread sets its kernel up (AMX: its own tiles).
    std::thread::spawn(|| {
        check_cases(&mut |alpha, a, b, beta, c| bf16_mat_mul(alpha, a, b, beta, c))
    })
    .join()
    .unwrap();
    // The AVX-512 BF16 kernel also where AMX takes precedence.
    if let Some(mut kernel) = kernels::Avx512Bf16::new() {
        check_cases(&mut |alpha, a, b, beta, c| {
            packed_mat_mul(alpha, a, b, beta, c, |a, b, out, alpha, beta| {
                kernel.block(a, b, out, alpha, beta)
            })
        });
    }
}

#[test]
fn the_avx512_kernel_gives_the_f32_product_where_the_processor_has_it() {
    if !f32_avx512_available() {
        eprintln!("no AVX-512 F: the f32 kernel does not run here");
        return;
    }
    #[cfg(target_arch = "x86_64")]
    check_cases_with(
        &mut |alpha, a, b, beta, c| f32_mat_mul(alpha, a, b, beta, c),
        assert_f32_product,
    );
    // Deeper than one K panel and wider than one B panel (the kernel blocks at 256 and 512).
    #[cfg(target_arch = "x86_64")]
    {
        let (a, b, c0) = (
            uniform(130, 600, 40),
            uniform(600, 530, 41),
            uniform(130, 530, 42),
        );
        let mut c = c0.clone();
        f32_mat_mul(0.5, a.view(), b.view(), 2.0, c.view_mut());
        assert_f32_product(c.view(), (0.5, a.view(), b.view()), (2.0, c0.view()));
        // beta = 0 ignores C, even where it holds NaN.
        let mut c = Array2::from_elem((130, 530), f32::NAN);
        f32_mat_mul(1.0, a.view(), b.view(), 0.0, c.view_mut());
        assert_f32_product(c.view(), (1.0, a.view(), b.view()), (0.0, c0.view()));
    }
}

/// Each kind of [`Then`] with `bias` or `y`.
fn finishes<'a, T: Scalar>(bias: ArrayView1<'a, T>, y: ArrayView2<'a, T>) -> [Then<'a, T>; 4] {
    [
        Then::Layer {
            bias: Some(bias),
            relu: false,
        },
        Then::Layer {
            bias: Some(bias),
            relu: true,
        },
        Then::Layer {
            bias: None,
            relu: true,
        },
        Then::ReluGrad(y),
    ]
}

/// What `then` should give on `product` (= a · b), by the definitions.
fn finished<T: Scalar>(then: Then<'_, T>, product: &Array2<T>) -> Array2<T> {
    let relu = |x: T| if x > T::zero() { x } else { T::zero() };
    match then {
        Then::Layer { bias, relu: r } => {
            let with_bias = bias.map_or(product.clone(), |bias| product + &bias);
            if r {
                with_bias.mapv(relu)
            } else {
                with_bias
            }
        }
        Then::ReluGrad(y) => {
            let mut kept = product.clone();
            Zip::from(&mut kept)
                .and(y)
                .for_each(|p, &y| *p = if y > T::zero() { *p } else { T::zero() });
            kept
        }
    }
}

#[test]
fn the_write_back_finishes_give_the_bits_of_the_passes() {
    // Every shape of the bf16 tests, two panels along K (300: the ReLU and the mask on the
    // final sum), a B given transposed and a C with columns apart (the kernel's strided
    // write-back; the passes for ReLU's backward).
    let shapes = SHAPES.iter().copied().chain([(37, 300, 45)]);
    for (seed, (m, k, n)) in (100u64..).step_by(5).zip(shapes) {
        let (a, bt, bias) = (
            uniform(m, k, seed),
            uniform(n, k, seed + 1),
            uniform(1, n, seed + 2),
        );
        let y = uniform(m, n, seed + 3);
        let product = a.dot(&bt.t()); // (M, N)
                                      // What C held is ignored, even NaN.
        let nan = Array2::from_elem((m, n), f32::NAN);
        for then in finishes(bias.row(0), y.view()) {
            let mut want = nan.clone();
            then_by_passes(a.view(), bt.t(), then, want.view_mut(), Compute::default());
            let expected = finished(then, &product);
            assert!(
                want.abs_diff_eq(&expected, 1e-4),
                "({m}, {k}, {n}) {then:?}: the passes give {want}, not {expected}"
            );
            let mut got = nan.clone();
            mat_mul_then(&a, &bt.t(), then, &mut got, Compute::default());
            let bits = |c: ArrayView2<'_, f32>| c.mapv(f32::to_bits);
            assert_eq!(
                bits(got.view()),
                bits(want.view()),
                "({m}, {k}, {n}) {then:?}"
            );
            let mut got_t = nan.t().to_owned();
            mat_mul_then(
                &a,
                &bt.t(),
                then,
                &mut got_t.view_mut().reversed_axes(),
                Compute::default(),
            );
            assert_eq!(
                bits(got_t.t()),
                bits(want.view()),
                "({m}, {k}, {n}) {then:?} into a transposed C"
            );
        }
    }
    // f64 (BLAS and the passes).
    let (a, b) = (
        uniform(9, 5, 120).mapv(f64::from),
        uniform(5, 3, 121).mapv(f64::from),
    );
    let y = uniform(9, 3, 122).mapv(f64::from);
    let bias = ndarray::array![0.5, -1.0, 2.0];
    for then in finishes(bias.view(), y.view()) {
        let mut c = Array2::from_elem((9, 3), f64::NAN);
        mat_mul_then(&a, &b, then, &mut c, Compute::default());
        let want = finished(then, &a.dot(&b));
        assert!(c.abs_diff_eq(&want, 1e-12), "{then:?}: {c}");
    }
}

#[test]
fn mat_mul_is_the_f32_product_by_default_and_bf16_when_asked() {
    let (a, b) = (uniform(50, 70, 5), uniform(70, 30, 6));
    let mut blas = Array2::zeros((50, 30));
    general_mat_mul(1.0, &a, &b, 0.0, &mut blas);
    let mut f32_out = Array2::zeros((50, 30));
    mat_mul(1.0, &a, &b, 0.0, &mut f32_out, Compute::default());
    if f32_avx512_available() {
        let mut direct = Array2::zeros((50, 30));
        #[cfg(target_arch = "x86_64")]
        f32_mat_mul(1.0, a.view(), b.view(), 0.0, direct.view_mut());
        assert_eq!(
            f32_out, direct,
            "the AVX-512 kernel where the processor has it"
        );
    } else {
        assert_eq!(f32_out, blas, "BLAS elsewhere, bit for bit");
    }
    assert_f32_product(
        f32_out.view(),
        (1.0, a.view(), b.view()),
        (0.0, blas.view()),
    );
    let mut bf16_out = Array2::zeros((50, 30));
    let bf16 = Compute::with_precision(Precision::Bf16);
    mat_mul(1.0, &a, &b, 0.0, &mut bf16_out, bf16);
    // Without a bf16 kernel, bf16 is the f32 product, bit for bit (on every machine).
    let mut fallback = Array2::zeros((50, 30));
    mat_mul_f32_in(
        Precision::Bf16,
        false,
        1.0,
        a.view(),
        b.view(),
        0.0,
        fallback.view_mut(),
    );
    assert_eq!(fallback, f32_out);
    if bf16_available() {
        let mut direct = Array2::zeros((50, 30));
        bf16_mat_mul(1.0, a.view(), b.view(), 0.0, direct.view_mut());
        assert_eq!(bf16_out, direct);
        assert_ne!(bf16_out, f32_out);
    } else {
        assert_eq!(
            bf16_out, f32_out,
            "the fallback is the f32 product, bit for bit"
        );
    }
    // f64 ignores the setting.
    let (a64, b64) = (a.mapv(f64::from), b.mapv(f64::from));
    let (mut asked_bf16, mut plain) = (Array2::zeros((50, 30)), Array2::zeros((50, 30)));
    general_mat_mul(1.0, &a64, &b64, 0.0, &mut plain);
    mat_mul(1.0, &a64, &b64, 0.0, &mut asked_bf16, bf16);
    assert_eq!(asked_bf16, plain);
}
