//! Max over the neighbour axis: `(N*K, C)` rows grouped by point → `(N, C)`, argmax kept.

use crate::error::check_shape;
use crate::{NnError, Result, Scalar};
use ndarray::{Array2, ArrayView1, ArrayView2, ArrayViewMut2};

/// What [`max_k_backward`] needs: the winning neighbour of every output entry.
#[derive(Clone, Debug, Default)]
pub struct MaxKCache {
    pub argmax: Array2<u32>, // (N, C), values in 0..K
}

/// `out[n, c] = max_k inp[n*K + k, c]`. Ties go to the first (lowest) `k`. `out`: (N, C),
/// `inp`: (N*K, C).
pub fn max_k_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    inp: ArrayView2<'_, T>,
    k: usize,
    cache: &mut MaxKCache,
) -> Result<()> {
    let (n, c) = out.dim();
    if k == 0 || k > u32::MAX as usize {
        return Err(NnError::InvalidArgument {
            op: "max_k forward",
            why: format!("K = {k}"),
        });
    }
    check_shape("max_k forward", "inp", inp.shape(), &[n * k, c])?;
    if cache.argmax.dim() != (n, c) {
        cache.argmax = Array2::zeros((n, c));
    }
    // A point's K rows as one slice, its channels compared in chunks (see `max_of_chunk`).
    let inp = inp.as_standard_layout(); // (N*K, C)
    let groups = inp
        .as_slice()
        .expect("standard layout")
        .chunks_exact((k * c).max(1)); // N of (K, C)
    let mut best = vec![T::zero(); c]; // (C)
    for ((group, mut arg), mut out) in groups.zip(cache.argmax.rows_mut()).zip(out.rows_mut()) {
        let arg = arg.as_slice_mut().expect("standard layout"); // (C)
                                                                // LANES channels at a time in local arrays, so that the comparisons run as vector
                                                                // selects in registers; the channels past the last whole chunk one at a time.
        let whole = c - c % LANES;
        for c0 in (0..whole).step_by(LANES) {
            max_of_chunk::<T, LANES>(group, c, c0, &mut best[c0..], &mut arg[c0..]);
        }
        for c0 in whole..c {
            max_of_chunk::<T, 1>(group, c, c0, &mut best[c0..], &mut arg[c0..]);
        }
        match out.as_slice_mut() {
            Some(out) => out.copy_from_slice(&best),
            None => out.assign(&ArrayView1::from(&best[..])),
        }
    }
    Ok(())
}

/// Channels per chunk of [`max_k_forward`]: one 512-bit vector of f32.
const LANES: usize = 16;

/// The max over a point's K rows `group` (K, C) of channels `c0..c0 + W` into `best` and its
/// first winning row into `arg`; ties go to the first row.
fn max_of_chunk<T: Scalar, const W: usize>(
    group: &[T],
    c: usize,
    c0: usize,
    best: &mut [T],
    arg: &mut [u32],
) {
    let mut rows = group.chunks_exact(c).map(|row| &row[c0..c0 + W]);
    let mut b: [T; W] = rows
        .next()
        .expect("K ≥ 1 rows per point")
        .try_into()
        .expect("W values");
    let mut a = [0u32; W];
    for (j, row) in (1u32..).zip(rows) {
        for l in 0..W {
            let greater = row[l] > b[l];
            b[l] = if greater { row[l] } else { b[l] };
            a[l] = if greater { j } else { a[l] };
        }
    }
    best[..W].copy_from_slice(&b);
    arg[..W].copy_from_slice(&a);
}

/// Differentiates the max: the gradient flows to the winning neighbour only,
/// `dinp[n*K + argmax[n, c], c] += dout[n, c]`. `dinp`: (N*K, C), `dout`: (N, C).
pub fn max_k_backward<T: Scalar>(
    mut dinp: ArrayViewMut2<'_, T>,
    dout: ArrayView2<'_, T>,
    k: usize,
    cache: &MaxKCache,
) -> Result<()> {
    let (n, c) = cache.argmax.dim();
    check_shape("max_k backward", "dout", dout.shape(), &[n, c])?;
    check_shape("max_k backward", "dinp", dinp.shape(), &[n * k, c])?;
    for p in 0..n {
        for (ch, (&a, &g)) in cache
            .argmax
            .row(p)
            .iter()
            .zip(dout.row(p).iter())
            .enumerate()
        {
            let d = &mut dinp[[p * k + a as usize, ch]];
            *d += g;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, uniform};
    use ndarray::array;

    #[test]
    fn ties_go_to_the_first_neighbour() {
        // One point, K = 3, two channels: channel 0 ties between k = 0 and 2, channel 1
        // between k = 1 and 2.
        let x = array![[5.0, 1.0], [4.0, 7.0], [5.0, 7.0]];
        let (mut out, mut cache) = (Array2::zeros((1, 2)), MaxKCache::default());
        max_k_forward(out.view_mut(), x.view(), 3, &mut cache).unwrap();
        assert_eq!(out, array![[5.0, 7.0]]);
        assert_eq!(cache.argmax, array![[0, 1]]);
        let mut dx = Array2::zeros((3, 2));
        max_k_backward(dx.view_mut(), array![[2.0, 3.0]].view(), 3, &cache).unwrap();
        assert_eq!(dx, array![[2.0, 0.0], [0.0, 3.0], [0.0, 0.0]]);
    }

    #[test]
    fn the_chunks_give_the_first_maximum_of_every_channel() {
        // C = 37: two chunks of 16 and 5 single channels; values on a coarse grid, so that
        // ties are frequent.
        let (n, k, c) = (3, 7, 37);
        let x = Array2::from_shape_fn((n * k, c), |(i, j)| ((i * 13 + j * 7) % 5) as f32);
        let (mut out, mut cache) = (Array2::zeros((n, c)), MaxKCache::default());
        max_k_forward(out.view_mut(), x.view(), k, &mut cache).unwrap();
        for (p, ch) in (0..n).flat_map(|p| (0..c).map(move |ch| (p, ch))) {
            let column: Vec<f32> = (0..k).map(|j| x[[p * k + j, ch]]).collect();
            let max = column.iter().copied().fold(f32::MIN, f32::max);
            let first = column.iter().position(|&v| v == max).unwrap();
            assert_eq!(out[[p, ch]], max, "point {p}, channel {ch}");
            assert_eq!(
                cache.argmax[[p, ch]] as usize,
                first,
                "point {p}, channel {ch}"
            );
        }
    }

    #[test]
    fn any_layout_gives_the_same_max() {
        // A transposed input and a column block of a wider output (as the featurer writes its
        // node features) against standard arrays.
        let x = ix2(&uniform(&[4 * 5, 3], 22));
        let xt = x.t().to_owned(); // (3, 20) stored, viewed back as (20, 3)
        let (mut plain, mut cache) = (Array2::zeros((4, 3)), MaxKCache::default());
        max_k_forward(plain.view_mut(), x.view(), 5, &mut cache).unwrap();
        let mut wide = Array2::from_elem((4, 7), -1.0);
        let mut other = MaxKCache::default();
        max_k_forward(wide.slice_mut(ndarray::s![.., 2..5]), xt.t(), 5, &mut other).unwrap();
        assert_eq!(wide.slice(ndarray::s![.., 2..5]), plain);
        assert_eq!(other.argmax, cache.argmax);
        assert!(wide.slice(ndarray::s![.., ..2]).iter().all(|&v| v == -1.0));
        // Into a transposed output (rows with columns apart).
        let mut out_t = Array2::zeros((3, 4));
        max_k_forward(out_t.view_mut().reversed_axes(), x.view(), 5, &mut other).unwrap();
        assert_eq!(out_t.t(), plain);
    }

    #[test]
    fn backward_matches_finite_differences() {
        // Distinct random values: the max is differentiable with a margin far above the step.
        let x = uniform(&[4 * 5, 3], 21);
        let run = |x: &Array2<f64>| {
            let (mut out, mut cache) = (Array2::zeros((4, 3)), MaxKCache::default());
            max_k_forward(out.view_mut(), x.view(), 5, &mut cache).unwrap();
            (out, cache)
        };
        assert_gradients(
            "max_k",
            1e-6,
            &[x],
            &mut |i| run(&ix2(&i[0])).0.into_dyn(),
            &mut |i, dout| {
                let (_, cache) = run(&ix2(&i[0]));
                let mut dx = Array2::zeros((20, 3));
                max_k_backward(dx.view_mut(), ix2(dout).view(), 5, &cache).unwrap();
                vec![dx.into_dyn()]
            },
        );
    }
}
