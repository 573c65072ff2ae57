//! exp over a slice, vectorised for f32: the attention's softmax and Sinkhorn's log-sum-exp take
//! one exponential per score, enough of them that libm's scalar `expf` is a large share of the
//! test-time procedure (docs/speed.md, "A vectorised exp").
//!
//! The f32 form is Cephes' `expf` written without branches so that the compiler vectorises it:
//! n = round(x·log₂e), r = x − n·ln 2 (in two parts), e^r by a degree-7 polynomial, times 2ⁿ built
//! in the exponent bits. Within 2 ulp of the correctly rounded value for
//! x ∈ [−87.3, 88.37] (`tests::f32_is_within_two_ulp_everywhere`); below, 0 (where libm
//! gives denormals below 1.2e-38); above, +∞; NaN stays NaN. It runs with AVX-512 or AVX2 + FMA
//! where the processor has them (checked once per call), else with the baseline's SSE2.
//! [`crate::Scalar::exp_in_place`] picks it for f32 (libm for f64, which the gradient checks run).

/// Below this, e^x is denormal (< 2⁻¹²⁶): the result is 0.
const LOWEST: f32 = -87.336_55;
/// Above this, 2ⁿ would need the exponent 128: the result is +∞ (e^88.38 > f32::MAX).
const HIGHEST: f32 = 88.376_26;
const LOG2E: f32 = std::f32::consts::LOG2_E;
/// ln 2 in two parts, so that n·LN2_HI is exact for |n| ≤ 128.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
/// 1.5·2²³: adding it rounds to an integer, which then sits in the low mantissa bits.
const ROUNDER: f32 = 12_582_912.0;

/// e^x of one value; inlined into each vectorised loop below.
#[inline(always)]
fn exp_one(x: f32) -> f32 {
    let clamped = x.clamp(LOWEST, HIGHEST);
    let shifted = clamped * LOG2E + ROUNDER;
    let n = shifted - ROUNDER; // round(x·log₂e), in [−126, 127]
    let r = clamped - n * LN2_HI - n * LN2_LO; // |r| ≤ ln 2 / 2
    let mut p = 1.987_569_1e-4_f32;
    p = p * r + 1.398_2e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 0.166_666_65;
    p = p * r + 0.5;
    let er = p * r * r + r + 1.0;
    // The low bits of `shifted` hold n + 2²² + 2²³ (as an integer); (n + 127) << 23 is 2ⁿ.
    let two_n = f32::from_bits(
        (shifted
            .to_bits()
            .wrapping_sub(ROUNDER.to_bits())
            .wrapping_add(127))
            << 23,
    );
    let y = er * two_n;
    if x < LOWEST {
        0.0
    } else if x > HIGHEST {
        f32::INFINITY
    } else {
        y // NaN passes through the clamp and the arithmetic
    }
}

#[inline(always)]
fn exp_loop(xs: &mut [f32]) {
    for x in xs.iter_mut() {
        *x = exp_one(*x);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn exp_loop_avx512(xs: &mut [f32]) {
    exp_loop(xs)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn exp_loop_avx2(xs: &mut [f32]) {
    exp_loop(xs)
}

/// Replaces every value by its exponential (see the module doc for the accuracy).
pub fn exp_f32_in_place(xs: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the processor has AVX-512F (checked above).
            return unsafe { exp_loop_avx512(xs) };
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the processor has AVX2 and FMA (checked above).
            return unsafe { exp_loop_avx2(xs) };
        }
    }
    exp_loop(xs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite positive f32.
    fn ulps(a: f32, b: f32) -> u32 {
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn f32_is_within_two_ulp_everywhere() {
        // Every 97th f32 in [−87.3, 88.37] plus the ends: ~2.3 million values through each path.
        let lo = LOWEST.to_bits();
        let mut xs: Vec<f32> = (0x8000_0000..lo).step_by(97).map(f32::from_bits).collect(); // [−87.3, 0)
        xs.extend((0..HIGHEST.to_bits()).step_by(97).map(f32::from_bits)); // [0, 88.37]
        xs.extend([LOWEST, HIGHEST, 0.0, -0.0]);
        let mut ys = xs.clone();
        exp_f32_in_place(&mut ys);
        let mut scalar = xs.clone();
        exp_loop(&mut scalar);
        let mut worst = (0, 0.0f32);
        for ((&x, &y), &s) in xs.iter().zip(&ys).zip(&scalar) {
            // libm's f64 exp rounded to f32 stands in for the correctly rounded value.
            let exact = (x as f64).exp() as f32;
            if ulps(y, exact) > worst.0 {
                worst = (ulps(y, exact), x);
            }
            assert_eq!(
                y.to_bits(),
                s.to_bits(),
                "vector and scalar paths differ at {x}"
            );
        }
        assert!(worst.0 <= 2, "{} ulp at x = {}", worst.0, worst.1);
    }

    #[test]
    fn f32_ends_and_specials() {
        let mut xs = [
            -87.4,
            -1000.0,
            f32::NEG_INFINITY,
            88.4,
            1000.0,
            f32::INFINITY,
            f32::NAN,
            1.0,
        ];
        exp_f32_in_place(&mut xs);
        assert_eq!(&xs[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(&xs[3..6], &[f32::INFINITY; 3]);
        assert!(xs[6].is_nan());
        assert_eq!(xs[7], std::f32::consts::E);
    }
}
