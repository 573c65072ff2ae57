//! Sums, dot products and maxima over a slice in eight running lanes, so that they vectorise,
//! and the shifted exp-sum of a softmax row or a log-sum-exp (the attention's softmax, Sinkhorn):
//! generic over [`Scalar`], whose `exp_in_place` is [`crate::exp`]'s for f32.

use crate::Scalar;

/// `xs ← exp(xs − shift)`, returning Σ xs: a softmax row, or a log-sum-exp after its maximum.
pub fn exp_shifted_sum<T: Scalar>(xs: &mut [T], shift: T) -> T {
    xs.iter_mut().for_each(|x| *x -= shift);
    T::exp_in_place(xs);
    sum(xs)
}

/// Σ xs in eight running sums, so that the additions vectorise.
pub fn sum<T: Scalar>(xs: &[T]) -> T {
    let mut lanes = [T::zero(); 8];
    let chunks = xs.chunks_exact(8);
    let rest = chunks.remainder().iter().fold(T::zero(), |acc, &x| acc + x);
    for chunk in chunks {
        lanes
            .iter_mut()
            .zip(chunk)
            .for_each(|(lane, &x)| *lane += x);
    }
    lanes.iter().fold(rest, |acc, &lane| acc + lane)
}

/// Σ xs·ys over the shorter of the two, in eight running sums so that the products and
/// additions vectorise.
pub fn dot<T: Scalar>(xs: &[T], ys: &[T]) -> T {
    let n = xs.len().min(ys.len());
    let whole = n - n % 8;
    let mut lanes = [T::zero(); 8];
    for (x, y) in xs[..whole].chunks_exact(8).zip(ys[..whole].chunks_exact(8)) {
        for l in 0..8 {
            lanes[l] += x[l] * y[l];
        }
    }
    let rest = (whole..n).fold(T::zero(), |acc, i| acc + xs[i] * ys[i]);
    lanes.iter().fold(rest, |acc, &lane| acc + lane)
}

/// The largest of `init` and the values of `xs`, NaNs skipped (as `f32::max` skips them), in
/// eight running maxima so that the comparisons vectorise. A maximum is exact, so this is the
/// value of a single running maximum.
pub fn max<T: Scalar>(xs: &[T], init: T) -> T {
    let mut lanes = [init; 8];
    let chunks = xs.chunks_exact(8);
    let rest = chunks.remainder().iter().fold(init, |acc, &x| acc.max(x));
    for chunk in chunks {
        lanes
            .iter_mut()
            .zip(chunk)
            .for_each(|(lane, &x)| *lane = lane.max(x));
    }
    lanes.iter().fold(rest, |acc, &lane| acc.max(lane))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_of_rows_with_a_remainder() {
        // 19 values: two rounds of the eight lanes and three more; Σ k·(20 − k) over k = 1..=19.
        let xs: Vec<f64> = (1..=19).map(f64::from).collect();
        let ys: Vec<f64> = (1..=19).map(|k| f64::from(20 - k)).collect();
        let want: f64 = (1..=19).map(|k| f64::from(k * (20 - k))).sum();
        assert_eq!(dot(&xs, &ys), want);
        assert_eq!(
            dot(&xs[..3], &ys),
            19.0 + 2.0 * 18.0 + 3.0 * 17.0,
            "the shorter length"
        );
        assert_eq!(dot::<f32>(&[], &[]), 0.0);
    }

    #[test]
    fn max_is_the_running_maximum_skipping_nans() {
        // 19 values: two rounds of the eight lanes and a remainder of three; the largest in
        // a lane, then in the remainder; NaNs anywhere.
        let mut xs: Vec<f32> = (0..19).map(|i| ((i * 7) % 19) as f32 - 9.0).collect();
        xs[4] = f32::NAN;
        let serial = |xs: &[f32], init: f32| xs.iter().fold(init, |m, &x| m.max(x));
        assert_eq!(max(&xs, f32::NEG_INFINITY), 9.0);
        assert_eq!(max(&xs, f32::NEG_INFINITY), serial(&xs, f32::NEG_INFINITY));
        xs[17] = 30.0;
        assert_eq!(max(&xs, 0.0), 30.0);
        assert_eq!(max(&xs, 100.0), 100.0, "the initial value counts");
        assert_eq!(
            max(&[f32::NAN; 11], -1.0),
            -1.0,
            "all NaN: the initial value"
        );
        assert_eq!(max::<f64>(&[], f64::NEG_INFINITY), f64::NEG_INFINITY);
    }

    #[test]
    fn shifted_sum_of_a_row() {
        // exp(ln k − ln 4) over k = 1..=4 is k/4; the 11 values also cover the eight lanes'
        // remainder of 3.
        let mut xs: Vec<f64> = (1..=11).map(|k| (k as f64).ln()).collect();
        let total = exp_shifted_sum(&mut xs, 4f64.ln());
        assert!((total - 66.0 / 4.0).abs() < 1e-12, "{total}");
        assert!((xs[2] - 0.75).abs() < 1e-15, "{}", xs[2]);
        let mut ys: Vec<f32> = (1..=11).map(|k| (k as f32).ln()).collect();
        assert!((exp_shifted_sum(&mut ys, 4f32.ln()) - 16.5).abs() < 1e-5);
    }
}
