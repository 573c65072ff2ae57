//! L1 normalisation of a matrix along its first index: every column sums (in absolute value)
//! to 1, as `torch.nn.functional.normalize(x, p=1, dim=0)` (eps 1e-12) — the intra-graph
//! convolution's adjacency normalisation (spec §2.3).

use crate::error::{check_shape, check_shapes};
use crate::{Result, Scalar};
use ndarray::{Array1, ArrayView2, ArrayViewMut2, Zip};

/// PyTorch's `F.normalize` default floor of the norm.
pub const L1_EPS: f64 = 1e-12;

/// What [`l1_normalize_columns_backward`] needs: each column's divisor.
#[derive(Clone, Debug, Default)]
pub struct L1NormalizeCache<T> {
    pub denom: Array1<T>, // (C), max(Σ_r |inp[r, c]|, eps)
}

/// `out[r, c] = inp[r, c] / max(Σ_r' |inp[r', c]|, 1e-12)`. A zero column stays zero (no NaN),
/// as in PyTorch. `out`, `inp`: (R, C).
pub fn l1_normalize_columns_forward<T: Scalar>(
    mut out: ArrayViewMut2<'_, T>,
    inp: ArrayView2<'_, T>,
    cache: &mut L1NormalizeCache<T>,
) -> Result<()> {
    check_shape(
        "l1_normalize_columns forward",
        "out",
        out.shape(),
        inp.shape(),
    )?;
    let eps = T::from_f64(L1_EPS);
    if cache.denom.len() != inp.ncols() {
        cache.denom = Array1::zeros(inp.ncols());
    }
    cache.denom.fill(T::zero());
    for row in inp.rows() {
        Zip::from(&mut cache.denom)
            .and(&row)
            .for_each(|s, &x| *s += x.abs());
    }
    cache.denom.mapv_inplace(|s| s.max(eps));
    for (mut y, x) in out.rows_mut().into_iter().zip(inp.rows()) {
        Zip::from(&mut y)
            .and(&x)
            .and(&cache.denom)
            .for_each(|y, &x, &s| *y = x / s);
    }
    Ok(())
}

/// Differentiates `y = x / s`, `s = Σ_r |x_r|` per column: where `s > eps`,
/// `dx_r = (dy_r − sign(x_r) Σ_r' dy_r' y_r') / s`; where the floor is active (`s ≤ eps`, a zero
/// column) `s` is the constant eps and `dx = dy / eps`, PyTorch's gradient there too.
/// `dinp`, `dout`: (R, C); `out` is the forward's output.
pub fn l1_normalize_columns_backward<T: Scalar>(
    mut dinp: ArrayViewMut2<'_, T>,
    dout: ArrayView2<'_, T>,
    inp: ArrayView2<'_, T>,
    out: ArrayView2<'_, T>,
    cache: &L1NormalizeCache<T>,
) -> Result<()> {
    check_shapes(
        "l1_normalize_columns backward",
        inp.shape(),
        &[
            ("out", out.shape()),
            ("dinp", dinp.shape()),
            ("dout", dout.shape()),
        ],
    )?;
    check_shape(
        "l1_normalize_columns backward",
        "inp",
        &inp.shape()[1..],
        &[cache.denom.len()],
    )?;
    let eps = T::from_f64(L1_EPS);
    let mut dot = Array1::zeros(inp.ncols()); // (C), Σ_r dy_r y_r
    for (g, y) in dout.rows().into_iter().zip(out.rows()) {
        Zip::from(&mut dot)
            .and(&g)
            .and(&y)
            .for_each(|s, &g, &y| *s += g * y);
    }
    for ((mut d, g), x) in dinp.rows_mut().into_iter().zip(dout.rows()).zip(inp.rows()) {
        Zip::from(&mut d)
            .and(&g)
            .and(&x)
            .and(&cache.denom)
            .and(&dot)
            .for_each(|d, &g, &x, &s, &dot| {
                let sign = if x > T::zero() {
                    T::one()
                } else if x < T::zero() {
                    -T::one()
                } else {
                    T::zero()
                };
                let floored = s <= eps;
                *d += if floored { g / s } else { (g - sign * dot) / s };
            });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradcheck::{assert_gradients, ix2, uniform};
    use ndarray::{array, Array2, ArrayD};

    fn run(x: &Array2<f64>) -> (Array2<f64>, L1NormalizeCache<f64>) {
        let (mut y, mut cache) = (Array2::zeros(x.dim()), L1NormalizeCache::default());
        l1_normalize_columns_forward(y.view_mut(), x.view(), &mut cache).unwrap();
        (y, cache)
    }

    #[test]
    fn columns_sum_to_one_and_a_zero_column_stays_zero() {
        let x = array![[1.0, 0.0, -1.0], [3.0, 0.0, 3.0]];
        let (y, _) = run(&x);
        assert_eq!(y, array![[0.25, 0.0, -0.25], [0.75, 0.0, 0.75]]);
        // The zero column's gradient is dy / eps (PyTorch's too), finite.
        let (y, cache) = run(&x);
        let mut dx = Array2::zeros((2, 3));
        l1_normalize_columns_backward(
            dx.view_mut(),
            array![[0.0, 1e-12, 0.0], [0.0, -2e-12, 0.0]].view(),
            x.view(),
            y.view(),
            &cache,
        )
        .unwrap();
        assert_eq!(dx.column(1), array![1.0, -2.0]);
    }

    #[test]
    fn backward_matches_finite_differences() {
        // Entries away from 0 (|x| ≥ 0.1) keep every sign fixed under the step.
        let x = uniform(&[5, 4], 81).mapv(|v: f64| if v.abs() < 0.1 { v + 0.2 } else { v });
        assert_gradients(
            "l1_normalize_columns",
            1e-6,
            &[x],
            &mut |i: &[ArrayD<f64>]| run(&ix2(&i[0])).0.into_dyn(),
            &mut |i, dout| {
                let x = ix2(&i[0]);
                let (y, cache) = run(&x);
                let mut dx = Array2::zeros(x.dim());
                l1_normalize_columns_backward(
                    dx.view_mut(),
                    ix2(dout).view(),
                    x.view(),
                    y.view(),
                    &cache,
                )
                .unwrap();
                vec![dx.into_dyn()]
            },
        );
    }
}
