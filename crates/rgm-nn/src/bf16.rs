//! bfloat16, the one rounding every part of rgm-nn uses: the bf16 matrix product's operands
//! ([`crate::gemm`]) and tensors stored as BF16 in weight files ([`crate::io`]). bf16 is the
//! upper half of an f32: the same exponent range, 8 significant bits.

/// `x` rounded to the nearest bfloat16 (ties to even), as its bits: the upper half of the f32
/// bits after rounding. NaN stays a quiet NaN with its sign; values beyond bf16's range round to
/// ±inf.
pub fn bf16_bits(x: f32) -> u16 {
    let bits = x.to_bits();
    if x.is_nan() {
        return ((bits >> 16) | 0x40) as u16;
    }
    // Adding 0x7FFF, plus 1 when the kept part is odd, carries into bit 16 exactly when the
    // dropped half is above one half, or one half and the kept part odd.
    let round = 0x7FFF + ((bits >> 16) & 1);
    (bits.wrapping_add(round) >> 16) as u16
}

/// The f32 whose upper half is the bfloat16 `bits` (exact).
pub fn bf16_to_f32(bits: u16) -> f32 {
    f32::from_bits(u32::from(bits) << 16)
}

/// `x` rounded to the nearest bfloat16, as an f32 (what the bf16 product multiplies).
pub fn round_to_bf16(x: f32) -> f32 {
    bf16_to_f32(bf16_bits(x))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_is_to_nearest_even() {
        let one = 1.0f32;
        let ulp = 2f32.powi(-7); // bf16's spacing at 1
        assert_eq!(bf16_bits(one), 0x3F80);
        assert_eq!(bf16_bits(-2.5), 0xC020);
        assert_eq!(bf16_bits(0.15625), 0x3E20); // 0.15625 = 1.25 · 2⁻³ is exact
                                                // Halfway between 1 (even) and 1 + ulp: down; between 1 + ulp (odd) and 1 + 2 ulp: up.
        assert_eq!(bf16_bits(one + ulp / 2.0), 0x3F80);
        assert_eq!(bf16_bits(one + 1.5 * ulp), 0x3F82);
        // Just above half: up.
        assert_eq!(bf16_bits(one + ulp / 2.0 + 2f32.powi(-20)), 0x3F81);
        assert_eq!(
            round_to_bf16(-1.0 - 3.0 * 2f32.powi(-8)),
            -1.0 - 2f32.powi(-6)
        );
        assert_eq!(bf16_bits(f32::MAX), 0x7F80); // beyond bf16's largest: +inf
        assert_eq!(round_to_bf16(f32::NEG_INFINITY), f32::NEG_INFINITY);
        assert!(round_to_bf16(f32::NAN).is_nan());
        assert_eq!(
            bf16_bits(-f32::NAN) & 0x8000,
            0x8000,
            "the sign of a NaN is kept"
        );
        assert_eq!(round_to_bf16(1e-45), 0.0);
        assert_eq!(bf16_to_f32(0x3F81), one + ulp);
    }
}
