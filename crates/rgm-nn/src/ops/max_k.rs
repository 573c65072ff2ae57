//! Max over the neighbour axis: `(N*K, C)` rows grouped by point → `(N, C)`, argmax kept.

use crate::error::check_shape;
use crate::{NnError, Result, Scalar};
use ndarray::{Array2, ArrayView2, ArrayViewMut2, Zip};

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
    for p in 0..n {
        let mut best = out.row_mut(p);
        let mut arg = cache.argmax.row_mut(p);
        best.assign(&inp.row(p * k));
        arg.fill(0);
        for j in 1..k {
            let j32 = j as u32;
            // Branch-free selects, so the loop vectorises.
            Zip::from(&mut best)
                .and(&mut arg)
                .and(inp.row(p * k + j))
                .for_each(|b, a, &x| {
                    let greater = x > *b;
                    *b = if greater { x } else { *b };
                    *a = if greater { j32 } else { *a };
                });
        }
    }
    Ok(())
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
