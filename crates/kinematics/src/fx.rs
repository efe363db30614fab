//! Internal fixed-point helpers: every computation widens to [`W`] (`u64`
//! holding unsigned Q32.32 bits: 0 … 4.3e9, resolution 2.3e-10) and narrows
//! back to the storage type with a checked conversion. No operator here can
//! panic.
//!
//! The arithmetic is plain `u64` integer arithmetic in a few shared,
//! non-inlined helpers ([`mul_q`], [`div_q`], [`div_wide`]) that compute the
//! exact 128-bit intermediate from 32-bit partial products and a
//! shift-subtract division, so that a formula is a handful of calls rather
//! than inlined 64-bit overflow-checked sequences (and no `u128` division:
//! on thumbv7m every one of those is expanded inline). All results are
//! rounded down (towards −∞), as the `fixed` crate's `U32F32` operations
//! that they replace: the values are bit for bit the same.

use crate::Error;

/// The working type: unsigned Q32.32 bits (`U32F32`).
pub(crate) type W = u64;

/// Fractional bits of [`W`].
pub(crate) const FRAC: u32 = 32;

/// 1.0 in [`W`].
pub(crate) const ONE: W = 1 << FRAC;

/// π with the precision of [`W`] (rounded to nearest, as `U32F32::lit`).
pub(crate) const PI: W = fixed::types::U32F32::lit("3.14159265358979323846").to_bits();

/// `⌊a·b / 2^32⌋` at compile time (for constants only: `u128` is fine there).
#[allow(clippy::cast_possible_truncation, clippy::arithmetic_side_effects)]
pub(crate) const fn const_mul(a: W, b: W) -> W {
    ((a as u128 * b as u128) >> FRAC) as u64
}

/// `⌊a·2^32 / b⌋` at compile time (for constants only; `b` must not be 0).
#[allow(clippy::cast_possible_truncation, clippy::arithmetic_side_effects)]
pub(crate) const fn const_div(a: W, b: W) -> W {
    (((a as u128) << FRAC) / b as u128) as u64
}

const LOW: u64 = 0xffff_ffff;

/// The full 128-bit product `a·b` as `(high, low)` 64-bit halves, from four
/// 32×32→64 multiplies (one `UMULL` each on Cortex-M3).
fn wide_mul(a: u64, b: u64) -> (u64, u64) {
    let (a1, a0) = (a >> 32, a & LOW);
    let (b1, b0) = (b >> 32, b & LOW);
    // Each partial product of two 32-bit halves is below 2^64.
    let p00 = a0.wrapping_mul(b0);
    let p01 = a0.wrapping_mul(b1);
    let p10 = a1.wrapping_mul(b0);
    let p11 = a1.wrapping_mul(b1);
    // Below 3·2^32: no carry is lost.
    let mid = (p00 >> 32).wrapping_add(p01 & LOW).wrapping_add(p10 & LOW);
    let lo = (mid << 32) | (p00 & LOW);
    // The true product is below 2^128, so the high half cannot wrap.
    let hi = p11
        .wrapping_add(p01 >> 32)
        .wrapping_add(p10 >> 32)
        .wrapping_add(mid >> 32);
    (hi, lo)
}

/// `⌊(hi·2^64 + lo) / d⌋`, or `None` if `d == 0` or the quotient does not
/// fit in 64 bits. Restoring shift-subtract division (64 steps) unless the
/// numerator fits in 64 bits (one `u64` division).
#[inline(never)]
pub(crate) fn div_wide(hi: u64, lo: u64, d: u64) -> Option<u64> {
    if hi >= d {
        // Quotient ≥ 2^64 (or d == 0).
        return None;
    }
    if hi == 0 {
        return lo.checked_div(d);
    }
    let mut r = hi;
    let mut q = 0u64;
    let mut bits = lo;
    for _ in 0..64 {
        // r < d throughout; 2r + bit may exceed 2^64, the carry says so.
        let carry = r >> 63 != 0;
        r = (r << 1) | (bits >> 63);
        bits <<= 1;
        q <<= 1;
        if carry || r >= d {
            r = r.wrapping_sub(d);
            q |= 1;
        }
    }
    Some(q)
}

/// `⌊a·b / 2^shift⌋` for `shift < 64`, or `None` if it does not fit in 64 bits.
#[inline(never)]
pub(crate) fn mul_q(a: u64, b: u64, shift: u32) -> Option<u64> {
    let (hi, lo) = wide_mul(a, b);
    if shift == 0 {
        return (hi == 0).then_some(lo);
    }
    let shift = shift & 63;
    if hi >> shift != 0 {
        return None;
    }
    Some((lo >> shift) | (hi << 64u32.wrapping_sub(shift)))
}

/// `⌊a·2^shift / b⌋` for `shift < 64`, or `None` if `b == 0` or it does not
/// fit in 64 bits.
pub(crate) fn div_q(a: u64, b: u64, shift: u32) -> Option<u64> {
    let shift = shift & 63;
    let hi = if shift == 0 {
        0
    } else {
        a >> 64u32.wrapping_sub(shift)
    };
    div_wide(hi, a << shift, b)
}

/// `⌊a·b / c⌋` with the exact 128-bit product, or `None` if `c == 0` or the
/// quotient does not fit in 64 bits.
pub(crate) fn mul_div(a: u64, b: u64, c: u64) -> Option<u64> {
    let (hi, lo) = wide_mul(a, b);
    div_wide(hi, lo, c)
}

/// Whether `a·b < c·d`, from the exact 128-bit products.
pub(crate) fn mul_lt(a: u64, b: u64, c: u64, d: u64) -> bool {
    wide_mul(a, b) < wide_mul(c, d)
}

/// Q32 product, [`Error::Overflow`] if it does not fit.
#[inline(never)]
pub(crate) fn mul(a: W, b: W) -> Result<W, Error> {
    mul_q(a, b, FRAC).ok_or(Error::Overflow)
}

/// Q32 quotient, [`Error::DivisionByZero`] or [`Error::Overflow`].
#[inline(never)]
pub(crate) fn div(a: W, b: W) -> Result<W, Error> {
    if b == 0 {
        return Err(Error::DivisionByZero);
    }
    div_q(a, b, FRAC).ok_or(Error::Overflow)
}

/// `a·b` for an integer `b`, [`Error::Overflow`] if it does not fit.
pub(crate) fn mul_int(a: W, b: u64) -> Result<W, Error> {
    a.checked_mul(b).ok_or(Error::Overflow)
}

/// `a / b` for an integer `b` (rounded down), [`Error::DivisionByZero`] if `b == 0`.
pub(crate) fn div_int(a: W, b: u64) -> Result<W, Error> {
    a.checked_div(b).ok_or(Error::DivisionByZero)
}

/// `a + b`, [`Error::Overflow`] if it does not fit.
pub(crate) fn add(a: W, b: W) -> Result<W, Error> {
    a.checked_add(b).ok_or(Error::Overflow)
}

/// Widens storage bits with `frac` fractional bits (≤ 32) into [`W`] (exact).
pub(crate) fn widen_bits(bits: u32, frac: u32) -> W {
    u64::from(bits) << (FRAC.wrapping_sub(frac) & 63)
}

/// Narrows [`W`] to storage bits with `frac` fractional bits (≤ 32), rounded
/// down; `None` if the value does not fit in 32 bits.
pub(crate) fn narrow_bits(w: W, frac: u32) -> Option<u32> {
    u32::try_from(w >> (FRAC.wrapping_sub(frac) & 63)).ok()
}

#[cfg(test)]
mod tests {
    #![allow(
        clippy::arithmetic_side_effects,
        clippy::cast_possible_truncation,
        clippy::unwrap_used
    )]
    use super::*;
    use proptest::prelude::*;

    fn ref_mul(a: u64, b: u64, s: u32) -> Option<u64> {
        u64::try_from((u128::from(a) * u128::from(b)) >> s).ok()
    }

    fn ref_div(a: u64, b: u64, s: u32) -> Option<u64> {
        (u128::from(a) << s)
            .checked_div(u128::from(b))
            .and_then(|q| u64::try_from(q).ok())
    }

    #[test]
    fn edges() {
        assert_eq!(mul_q(u64::MAX, u64::MAX, 0), None);
        assert_eq!(mul_q(u64::MAX, 1, 0), Some(u64::MAX));
        assert_eq!(mul_q(u64::MAX, u64::MAX, 63), None);
        assert_eq!(div_q(1, 0, 32), None);
        assert_eq!(div_q(0, 0, 0), None);
        assert_eq!(div_q(u64::MAX, 1, 1), None);
        assert_eq!(div_q(u64::MAX, 2, 1), Some(u64::MAX));
        assert_eq!(div_wide(1, 0, u64::MAX), Some(1));
        assert_eq!(mul_div(u64::MAX, u64::MAX, u64::MAX), Some(u64::MAX));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]
        #[test]
        fn mul_and_div_match_u128(a in any::<u64>(), b in any::<u64>(), s in 0u32..64,
                                  sa in 0u32..64, sb in 0u32..64) {
            let (a, b) = (a >> sa, b >> sb);
            prop_assert_eq!(mul_q(a, b, s), ref_mul(a, b, s));
            prop_assert_eq!(div_q(a, b, s), ref_div(a, b, s));
            let c = b >> (s / 2);
            let want = (u128::from(a) * u128::from(b))
                .checked_div(u128::from(c))
                .and_then(|q| u64::try_from(q).ok());
            prop_assert_eq!(mul_div(a, b, c), want);
            prop_assert_eq!(
                mul_lt(a, b, c, s.into()),
                u128::from(a) * u128::from(b) < u128::from(c) * u128::from(s)
            );
        }
    }
}
