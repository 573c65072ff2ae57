//! Multi-head attention (the annotated transformer's `MultiHeadedAttention`, no dropout, no
//! mask): queries from one stream, keys and values from another (the same one for
//! self-attention).

use super::linear::Linear;
use super::softmax::{softmax_backward_in_place, softmax_slice};
use crate::error::check_shape;
use crate::gemm::mat_mul;
use crate::init::Init;
use crate::param::{join_name, ParamView, ParamViewMut};
use crate::{Compute, NnError, Parameters, Result, Scalar};
use ndarray::{s, Array2, Array3, ArrayView2, ArrayViewMut2, Axis, Zip};
use rayon::prelude::*;

/// `out = concat_h(softmax_rows(Q_h K_hᵀ / √(C/H)) V_h) · Woᵀ + bo` with `Q = q_in Wqᵀ + bq`,
/// `K = kv_in Wkᵀ + bk`, `V = kv_in Wvᵀ + bv`; head h owns the contiguous channels
/// `h·C/H .. (h+1)·C/H`. Parameters are named `linears.{0,1,2,3}` (query, key, value, output)
/// as in the reference state dict.
#[derive(Clone, Debug)]
pub struct MultiHeadAttention<T: Scalar> {
    pub heads: usize, // H
    pub query: Linear<T>,
    pub key: Linear<T>,
    pub value: Linear<T>,
    pub output: Linear<T>,
}

/// Query rows per block of the attention's three steps (scores, softmax, product with V; and
/// in the backward dP, dS, dQ and the block's shares of dV and dK): 128 rows of up to 1,024
/// scores are 512 KiB, within L2. A multiple of 32, so that the backward's sums over blocks
/// have the bf16 whole products' bits.
const ROW_BLOCK: usize = 128;

/// The attention's independent pieces of work, as a parallel iterator: for each head and each
/// block of [`ROW_BLOCK`] query rows, `(head, first row, the block's rows of per_head[head]
/// (rows, Nk) when there is per_head, the block's rows of head's columns of per_row (rows, dk))`.
fn head_row_blocks<'a, T: Scalar>(
    per_head: Option<&'a mut Array3<T>>,
    per_row: &'a mut Array2<T>,
    dk: usize,
) -> impl ParallelIterator<
    Item = (
        usize,
        usize,
        Option<ArrayViewMut2<'a, T>>,
        ArrayViewMut2<'a, T>,
    ),
> {
    let mut blocks = Vec::new();
    let mut per_head = per_head.map(|p| p.outer_iter_mut());
    for (head, columns) in per_row.axis_chunks_iter_mut(Axis(1), dk).enumerate() {
        let mut scores = per_head
            .as_mut()
            .map(|p| p.next().expect("one score matrix a head"));
        let (mut columns, mut r0) = (columns, 0);
        while columns.nrows() > ROW_BLOCK {
            let (c, rest_c) = columns.split_at(Axis(0), ROW_BLOCK);
            let s = match scores {
                Some(all) => {
                    let (s, rest_s) = all.split_at(Axis(0), ROW_BLOCK);
                    scores = Some(rest_s);
                    Some(s)
                }
                None => None,
            };
            blocks.push((head, r0, s, c));
            (columns, r0) = (rest_c, r0 + ROW_BLOCK);
        }
        blocks.push((head, r0, scores, columns));
    }
    blocks.into_par_iter()
}

/// The forward's intermediates, and the backward's scratch buffers (kept to reuse memory).
#[derive(Clone, Debug, Default)]
pub struct AttentionCache<T> {
    pub q: Array2<T>,     // (Nq, C) projected queries
    pub k: Array2<T>,     // (Nk, C) projected keys
    pub v: Array2<T>,     // (Nk, C) projected values
    pub probs: Array3<T>, // (H, Nq, Nk) attention weights, rows sum to 1
    pub heads: Array2<T>, // (Nq, C) concatenated head outputs, the input of the output map
    dheads: Array2<T>,    // (Nq, C)
    dq: Array2<T>,        // (Nq, C)
    dk: Array2<T>,        // (Nk, C)
    dv: Array2<T>,        // (Nk, C)
    dscores: Array3<T>,   // (H, min(Nq, ROW_BLOCK), Nk) a block of each head's score gradients
    dsums: Array3<T>,     // (H, 2·dk, Nk) each head's dVᵀ over dKᵀ (unscaled), summed over blocks
}

fn ensure<T: Scalar>(buf: &mut Array2<T>, shape: (usize, usize)) {
    if buf.dim() != shape {
        *buf = Array2::zeros(shape);
    }
}

impl<T: Scalar> MultiHeadAttention<T> {
    /// Four `C × C` linear maps with bias, PyTorch-initialised; `c` must divide into `heads`.
    pub fn new(c: usize, heads: usize, init: &mut impl Init) -> Result<Self> {
        if heads == 0 || !c.is_multiple_of(heads) {
            return Err(NnError::InvalidArgument {
                op: "multi_head_attention",
                why: format!("C = {c} is not divisible by H = {heads}"),
            });
        }
        let mut lin = || Linear::new(c, c, true, init);
        Ok(Self {
            heads,
            query: lin(),
            key: lin(),
            value: lin(),
            output: lin(),
        })
    }

    pub fn channels(&self) -> usize {
        self.query.c_in()
    }

    /// Runs the attention. `out`: (Nq, C), `q_in`: (Nq, C), `kv_in`: (Nk, C).
    pub fn forward(
        &self,
        out: ArrayViewMut2<'_, T>,
        q_in: ArrayView2<'_, T>,
        kv_in: ArrayView2<'_, T>,
        cache: &mut AttentionCache<T>,
        compute: Compute,
    ) -> Result<()> {
        self.forward_keeping(out, q_in, kv_in, cache, true, compute)
    }

    /// [`MultiHeadAttention::forward`], keeping the attention weights (H, Nq, Nk) for a
    /// backward only when `keep`. Where no backward follows they are its largest buffer: each
    /// block of query rows then has its own for the time it takes, so that a pass touches far
    /// less fresh memory, and `cache.probs` is left empty (a backward is refused). The same
    /// bits either way.
    pub fn forward_keeping(
        &self,
        out: ArrayViewMut2<'_, T>,
        q_in: ArrayView2<'_, T>,
        kv_in: ArrayView2<'_, T>,
        cache: &mut AttentionCache<T>,
        keep: bool,
        compute: Compute,
    ) -> Result<()> {
        let (c, h) = (self.channels(), self.heads);
        let (nq, nk, dk) = (q_in.nrows(), kv_in.nrows(), c / h);
        ensure(&mut cache.q, (nq, c));
        ensure(&mut cache.k, (nk, c));
        ensure(&mut cache.v, (nk, c));
        ensure(&mut cache.heads, (nq, c));
        let probs_shape = if keep { (h, nq, nk) } else { (0, 0, 0) };
        if cache.probs.dim() != probs_shape {
            cache.probs = Array3::zeros(probs_shape);
        }
        // Without kept weights no backward follows: the three projections side by side.
        let (q, k, v) = (cache.q.view_mut(), cache.k.view_mut(), cache.v.view_mut());
        let (query, key, value) = (
            || self.query.forward(q, q_in, compute),
            || self.key.forward(k, kv_in, compute),
            || self.value.forward(v, kv_in, compute),
        );
        let (queried, (keyed, valued)) = if keep {
            (query(), (key(), value()))
        } else {
            rayon::join(query, || rayon::join(key, value))
        };
        queried.and(keyed).and(valued)?;
        let scale = T::one() / T::from_f64(dk as f64).sqrt();
        // Head by head and block by block of query rows, so that a block's score rows are
        // still in cache for their softmax and their product with V; rayon spreads the blocks
        // over the cores (each entry is computed as by whole-matrix products, on any thread).
        let (q, k, v) = (cache.q.view(), cache.k.view(), cache.v.view());
        let probs = keep.then_some(&mut cache.probs);
        head_row_blocks(probs, &mut cache.heads, dk).for_each(|(head, r0, mut kept, mut heads)| {
            let (rows, cols) = (r0..r0 + heads.nrows(), head * dk..(head + 1) * dk);
            let mut own: Array2<T>; // (rows, Nk) when the weights are not kept
            let mut p = match &mut kept {
                Some(p) => p.view_mut(),
                None => {
                    own = Array2::zeros((heads.nrows(), nk));
                    own.view_mut()
                }
            };
            mat_mul(
                scale,
                &q.slice(s![rows, cols.clone()]),
                &k.slice(s![.., cols.clone()]).t(),
                T::zero(),
                &mut p,
                compute,
            );
            for row in p.rows_mut() {
                softmax_slice(row.into_slice().expect("probs rows are contiguous"));
            }
            mat_mul(
                T::one(),
                &p,
                &v.slice(s![.., cols]),
                T::zero(),
                &mut heads,
                compute,
            );
        });
        self.output.forward(out, cache.heads.view(), compute)
    }

    /// Differentiates the attention, head by head, in reverse:
    /// `dP_h = dO_h V_hᵀ`, `dV_h += P_hᵀ dO_h`, `dS_h = softmax'(dP_h)` (row-wise
    /// `P ⊙ (dP − Σ dP ⊙ P)`), `dQ_h += dS_h K_h / √d`, `dK_h += dS_hᵀ Q_h / √d`, then the four
    /// linear backwards. `dkv_in = None` means keys and values came from `q_in` (self-attention):
    /// their gradient is added to `dq_in`. Inputs as given to forward.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &mut self,
        mut dq_in: ArrayViewMut2<'_, T>,
        dkv_in: Option<ArrayViewMut2<'_, T>>,
        dout: ArrayView2<'_, T>,
        q_in: ArrayView2<'_, T>,
        kv_in: ArrayView2<'_, T>,
        cache: &mut AttentionCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let (c, h) = (self.channels(), self.heads);
        let (nq, nk, dk) = (q_in.nrows(), kv_in.nrows(), c / h);
        check_shape(
            "multi_head_attention backward",
            "probs",
            cache.probs.shape(),
            &[h, nq, nk],
        )?;
        // dheads and dq are added into; dk and dv are written whole from the sums below.
        for (buf, shape) in [(&mut cache.dheads, (nq, c)), (&mut cache.dq, (nq, c))] {
            ensure(buf, shape);
            buf.fill(T::zero());
        }
        ensure(&mut cache.dk, (nk, c));
        ensure(&mut cache.dv, (nk, c));
        let dscores_shape = (h, ROW_BLOCK.min(nq), nk);
        if cache.dscores.dim() != dscores_shape {
            cache.dscores = Array3::zeros(dscores_shape);
        }
        if cache.dsums.dim() != (h, 2 * dk, nk) {
            cache.dsums = Array3::zeros((h, 2 * dk, nk));
        }
        cache.dsums.fill(T::zero());
        self.output
            .backward(cache.dheads.view_mut(), dout, cache.heads.view(), compute)?;
        let scale = T::one() / T::from_f64(dk as f64).sqrt();
        // Head by head (spread over the cores by rayon), block by block of query rows: the
        // block's dP, dS and dQ, then its shares of dVᵀ += dOᵀ P and dKᵀ += Qᵀ dS while its
        // weights and score gradients are still in cache, into (dk, Nk) sums whose rows the
        // products write whole. Each share is added onto the sum of the blocks before (at
        // multiples of 32 rows, alpha 1), which the bf16 products accumulate as one
        // whole-matrix product would; dK is scaled once, at the end, as the whole product's
        // write-back onto zeros does (`+ 0` turns a −0 into 0 as that does).
        let (probs, d_o) = (cache.probs.view(), cache.dheads.view());
        let (q, k, v) = (cache.q.view(), cache.k.view(), cache.v.view());
        let heads: Vec<_> = cache
            .dscores
            .outer_iter_mut()
            .zip(cache.dsums.outer_iter_mut())
            .zip(cache.dq.axis_chunks_iter_mut(Axis(1), dk))
            .zip(cache.dk.axis_chunks_iter_mut(Axis(1), dk))
            .zip(cache.dv.axis_chunks_iter_mut(Axis(1), dk))
            .enumerate()
            .collect();
        heads.into_par_iter().for_each(
            |(head, ((((mut ds_rows, sums), mut dq), mut dk_h), mut dv))| {
                let cols = s![.., head * dk..(head + 1) * dk];
                let (q, k, v, d_o) = (q.slice(cols), k.slice(cols), v.slice(cols), d_o.slice(cols));
                let (mut dv_t, mut dk_t) = sums.split_at(Axis(0), dk); // (dk, Nk) each
                for r0 in (0..nq).step_by(ROW_BLOCK) {
                    let rows = r0..(r0 + ROW_BLOCK).min(nq);
                    let p = probs.slice(s![head, rows.clone(), ..]); // (rows, Nk)
                    let (q, d_o) = (
                        q.slice(s![rows.clone(), ..]),
                        d_o.slice(s![rows.clone(), ..]),
                    );
                    let mut ds = ds_rows.slice_mut(s![..p.nrows(), ..]); // (rows, Nk)
                    mat_mul(T::one(), &d_o, &v.t(), T::zero(), &mut ds, compute);
                    for (d, y) in ds.rows_mut().into_iter().zip(p.rows()) {
                        softmax_backward_in_place(d, y);
                    }
                    let mut dq_rows = dq.slice_mut(s![rows, ..]); // (rows, dk)
                    mat_mul(scale, &ds, &k, T::one(), &mut dq_rows, compute);
                    mat_mul(T::one(), &d_o.t(), &p, T::one(), &mut dv_t, compute);
                    mat_mul(T::one(), &q.t(), &ds, T::one(), &mut dk_t, compute);
                }
                dv.assign(&dv_t.t());
                Zip::from(&mut dk_h)
                    .and(dk_t.t())
                    .for_each(|d, &sum| *d = scale * sum + T::zero());
            },
        );
        self.query
            .backward(dq_in.view_mut(), cache.dq.view(), q_in, compute)?;
        match dkv_in {
            Some(mut dkv) => {
                self.key
                    .backward(dkv.view_mut(), cache.dk.view(), kv_in, compute)?;
                self.value.backward(dkv, cache.dv.view(), kv_in, compute)
            }
            None => {
                self.key
                    .backward(dq_in.view_mut(), cache.dk.view(), kv_in, compute)?;
                self.value.backward(dq_in, cache.dv.view(), kv_in, compute)
            }
        }
    }
}

impl<T: Scalar> Parameters<T> for MultiHeadAttention<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        for (i, lin) in [&self.query, &self.key, &self.value, &self.output]
            .into_iter()
            .enumerate()
        {
            lin.visit_params_ref(&join_name(prefix, &format!("linears.{i}")), f);
        }
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        for (i, lin) in [
            &mut self.query,
            &mut self.key,
            &mut self.value,
            &mut self.output,
        ]
        .into_iter()
        .enumerate()
        {
            lin.visit_params(&join_name(prefix, &format!("linears.{i}")), f);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix1, ix2, uniform};
    use ndarray::ArrayD;
    use rand::{rngs::StdRng, SeedableRng};

    // Sizes above ndarray's BLAS cut-off (any dimension > 7), so the checks run through
    // cblas_dgemm with the per-head column slices and transposed views.
    const C: usize = 16;
    const H: usize = 4;

    /// The layer whose tensors are `params` = (Wq, bq, Wk, Wv, bv, Wo, bo). The key bias is
    /// fixed: it adds `q·bk` to a whole row of scores, which the softmax ignores, so its
    /// gradient is zero and a finite-difference check of it would compare noise with noise
    /// (`key_bias_gets_no_gradient` checks that zero).
    fn layer(params: &[ArrayD<f64>]) -> MultiHeadAttention<f64> {
        let lin =
            |w: &ArrayD<f64>, b: &ArrayD<f64>| Linear::from_values(ix2(w), Some(ix1(b))).unwrap();
        let p = params;
        let (query, key) = (lin(&p[0], &p[1]), lin(&p[2], &uniform(&[C], 999)));
        MultiHeadAttention {
            heads: 2,
            query,
            key,
            value: lin(&p[3], &p[4]),
            output: lin(&p[5], &p[6]),
        }
    }

    fn random_params(seed: u64) -> Vec<ArrayD<f64>> {
        [&[C, C][..], &[C], &[C, C], &[C, C], &[C], &[C, C], &[C]]
            .iter()
            .enumerate()
            .map(|(i, s)| uniform(s, seed + i as u64))
            .collect()
    }

    /// The gradients of the tensors `layer` takes from `params`, in the same order.
    fn grads(mha: MultiHeadAttention<f64>) -> Vec<ArrayD<f64>> {
        let b = |l: &Linear<f64>| l.bias.as_ref().unwrap().grad.clone().into_dyn();
        vec![
            mha.query.weight.grad.clone().into_dyn(),
            b(&mha.query),
            mha.key.weight.grad.clone().into_dyn(),
            mha.value.weight.grad.clone().into_dyn(),
            b(&mha.value),
            mha.output.weight.grad.clone().into_dyn(),
            b(&mha.output),
        ]
    }

    #[test]
    fn key_bias_gets_no_gradient() {
        let mut mha = layer(&random_params(300));
        let (q, kv) = (ix2(&uniform(&[3, C], 301)), ix2(&uniform(&[5, C], 302)));
        let (mut out, mut cache) = (ndarray::Array2::zeros((3, C)), AttentionCache::default());
        mha.forward(
            out.view_mut(),
            q.view(),
            kv.view(),
            &mut cache,
            Compute::default(),
        )
        .unwrap();
        let (mut dq, mut dkv) = (
            ndarray::Array2::zeros((3, C)),
            ndarray::Array2::zeros((5, C)),
        );
        let dout = ix2(&uniform(&[3, C], 303));
        mha.backward(
            dq.view_mut(),
            Some(dkv.view_mut()),
            dout.view(),
            q.view(),
            kv.view(),
            &mut cache,
            Compute::default(),
        )
        .unwrap();
        let dbk = &mha.key.bias.as_ref().unwrap().grad;
        assert!(dbk.iter().all(|g| g.abs() < 1e-14), "{dbk}");
        assert!(
            mha.query
                .bias
                .as_ref()
                .unwrap()
                .grad
                .iter()
                .any(|g| g.abs() > 1e-3),
            "the other biases do get one"
        );
    }

    #[test]
    fn one_key_means_the_value_passes_through() {
        // With a single key every query's weights are (1): out = (kv Wvᵀ + bv) Woᵀ + bo.
        let eye = ndarray::Array2::<f64>::eye(C);
        let id = || Linear::from_values(eye.clone(), Some(ndarray::Array1::zeros(C))).unwrap();
        let mha = MultiHeadAttention {
            heads: H,
            query: id(),
            key: id(),
            value: id(),
            output: id(),
        };
        let (q, kv) = (ix2(&uniform(&[2, C], 310)), ix2(&uniform(&[1, C], 311)));
        let (mut out, mut cache) = (ndarray::Array2::zeros((2, C)), AttentionCache::default());
        mha.forward(
            out.view_mut(),
            q.view(),
            kv.view(),
            &mut cache,
            Compute::default(),
        )
        .unwrap();
        assert_eq!(out.row(0), kv.row(0));
        assert_eq!(out.row(1), kv.row(0));
    }

    #[test]
    fn row_blocks_give_the_whole_matrix_attention_bit_for_bit() {
        // 150 queries: a whole block of 128 rows and one of 22; 70 keys.
        let mha = MultiHeadAttention::<f32>::new(C, H, &mut StdRng::seed_from_u64(5)).unwrap();
        let f32s = |shape: &[usize], seed| ix2(&uniform(shape, seed)).mapv(|v| v as f32);
        let (q_in, kv_in) = (f32s(&[150, C], 320), f32s(&[70, C], 321));
        let (mut out, mut cache) = (Array2::zeros((150, C)), AttentionCache::default());
        mha.forward(
            out.view_mut(),
            q_in.view(),
            kv_in.view(),
            &mut cache,
            Compute::default(),
        )
        .unwrap();
        // The same products over whole matrices, head by head.
        let project = |lin: &Linear<f32>, x: &Array2<f32>| {
            let mut y = Array2::zeros((x.nrows(), C));
            lin.forward(y.view_mut(), x.view(), Compute::default())
                .unwrap();
            y
        };
        let (q, k, v) = (
            project(&mha.query, &q_in),
            project(&mha.key, &kv_in),
            project(&mha.value, &kv_in),
        );
        let (dk, mut heads) = (C / H, Array2::zeros((150, C)));
        for head in 0..H {
            let cols = s![.., head * dk..(head + 1) * dk];
            let mut p = Array2::zeros((150, 70));
            let scale = 1.0 / (dk as f32).sqrt();
            mat_mul(
                scale,
                &q.slice(cols),
                &k.slice(cols).t(),
                0.0,
                &mut p,
                Compute::default(),
            );
            for row in p.rows_mut() {
                softmax_slice(row.into_slice().unwrap());
            }
            mat_mul(
                1.0,
                &p,
                &v.slice(cols),
                0.0,
                &mut heads.slice_mut(cols),
                Compute::default(),
            );
        }
        assert_eq!(out, project(&mha.output, &heads));
    }

    /// Checks every input and parameter gradient: cross-attention (70 queries: a whole block
    /// of [`ROW_BLOCK`] rows and a part of one; 10 keys) takes inputs `[q, kv, params..]`;
    /// self-attention (10 rows) `[x, params..]` with `dkv_in = None`.
    fn check_attention(self_attention: bool) {
        let (nq, nk) = if self_attention {
            (10, 10)
        } else {
            (ROW_BLOCK + 6, 10)
        };
        let streams = if self_attention { 1 } else { 2 };
        let mut inputs = vec![uniform(&[nq, C], 91)];
        if !self_attention {
            inputs.push(uniform(&[nk, C], 92));
        }
        inputs.extend(random_params(100));
        let run = |i: &[ArrayD<f64>]| {
            let (q, kv) = (ix2(&i[0]), ix2(&i[streams - 1]));
            let (mut out, mut cache) = (ndarray::Array2::zeros((nq, C)), AttentionCache::default());
            layer(&i[streams..])
                .forward(
                    out.view_mut(),
                    q.view(),
                    kv.view(),
                    &mut cache,
                    Compute::default(),
                )
                .unwrap();
            (out, cache)
        };
        let what = if self_attention {
            "self attention"
        } else {
            "cross attention"
        };
        assert_gradients(
            what,
            1e-6,
            &inputs,
            &mut |i| run(i).0.into_dyn(),
            &mut |i, dout| {
                let (_, mut cache) = run(i);
                let (q, kv) = (ix2(&i[0]), ix2(&i[streams - 1]));
                let mut mha = layer(&i[streams..]);
                let (mut dq, mut dkv) = (
                    ndarray::Array2::zeros((nq, C)),
                    ndarray::Array2::zeros((nk, C)),
                );
                let dkv_in = (!self_attention).then(|| dkv.view_mut());
                mha.backward(
                    dq.view_mut(),
                    dkv_in,
                    ix2(dout).view(),
                    q.view(),
                    kv.view(),
                    &mut cache,
                    Compute::default(),
                )
                .unwrap();
                let mut g = vec![dq.into_dyn()];
                if !self_attention {
                    g.push(dkv.into_dyn());
                }
                g.extend(grads(mha));
                g
            },
        );
    }

    #[test]
    fn cross_attention_backward_matches_finite_differences() {
        check_attention(false);
    }

    #[test]
    fn self_attention_backward_matches_finite_differences() {
        check_attention(true);
    }

    /// The f32 path (cblas_sgemm on the same views) agrees with f64 to single precision.
    #[test]
    fn f32_matches_f64() {
        let mha64 = MultiHeadAttention::<f64>::new(16, 4, &mut StdRng::seed_from_u64(1)).unwrap();
        let to32 = |l: &Linear<f64>| {
            Linear::from_values(
                l.weight.value.mapv(|v| v as f32),
                l.bias.as_ref().map(|b| b.value.mapv(|v| v as f32)),
            )
            .unwrap()
        };
        let mha32 = MultiHeadAttention {
            heads: 4,
            query: to32(&mha64.query),
            key: to32(&mha64.key),
            value: to32(&mha64.value),
            output: to32(&mha64.output),
        };
        let (q, kv) = (ix2(&uniform(&[9, 16], 2)), ix2(&uniform(&[10, 16], 3)));
        let (mut out64, mut out32) = (Array2::zeros((9, 16)), Array2::<f32>::zeros((9, 16)));
        mha64
            .forward(
                out64.view_mut(),
                q.view(),
                kv.view(),
                &mut AttentionCache::default(),
                Compute::default(),
            )
            .unwrap();
        let (q32, kv32) = (q.mapv(|v| v as f32), kv.mapv(|v| v as f32));
        mha32
            .forward(
                out32.view_mut(),
                q32.view(),
                kv32.view(),
                &mut AttentionCache::default(),
                Compute::default(),
            )
            .unwrap();
        let worst = out64
            .iter()
            .zip(out32.iter())
            .map(|(a, &b)| (a - b as f64).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{worst:e}");
        assert!(out64.iter().any(|v| v.abs() > 0.1), "a non-trivial output");
    }
}
