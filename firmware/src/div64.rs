//! 64-bit division for the compiler's `u64`/`i64` `/` and `%`, compact:
//! the arithmetic behind [`crate::board`]'s `mem`'s `__udivmoddi4` and `__divmoddi4`,
//! which take the place of `compiler_builtins`' (≈ 1 KB of speed-tuned
//! code, `u64_div_rem`).
//!
//! Exact for every operand pair (host test `tests/tests/div64.rs` against
//! the host's own division). A divisor that fits 32 bits (every divisor in
//! this firmware's arithmetic but the rare wide ones) takes two hardware
//! divisions and Knuth's algorithm D in base 2^16: a few dozen
//! instructions, like `compiler_builtins`' code; a wider one, restoring
//! binary long division (at most 33 steps, its quotient fits 33 bits).
//! Pure and safe, so that the host test can include this very file.

/// `(n / d, n % d)`. `d = 0` gives `(u64::MAX, n)` (never asked: Rust
/// checks for a zero divisor before it divides).
#[must_use]
#[inline(always)]
pub fn div_rem_u64(n: u64, d: u64) -> (u64, u64) {
    let (nh, nl) = ((n >> 32) as u32, n as u32);
    match u32::try_from(d) {
        Ok(0) => (u64::MAX, n),
        Ok(d) => {
            // The high word by the hardware divider, then the remainder
            // and the low word: a 64-by-32 division whose quotient fits
            // 32 bits (rh < d).
            let (qh, rh) = (nh / d, nh % d);
            let (ql, r) = div_2by1(rh, nl, d);
            ((u64::from(qh) << 32) | u64::from(ql), u64::from(r))
        }
        Err(_) if n < d => (0, n),
        Err(_) => {
            // d ≥ 2^32, n ≥ d: the quotient has at most 33 bits. Restoring
            // binary long division from d shifted under n's top bit (the
            // shift loses nothing: d has at least as many leading zeros).
            let shift = d.leading_zeros() - n.leading_zeros();
            let mut d = d << shift;
            let (mut q, mut r) = (0u64, n);
            for _ in 0..=shift {
                q <<= 1;
                if r >= d {
                    r -= d;
                    q |= 1;
                }
                d >>= 1;
            }
            (q, r)
        }
    }
}

/// `(u1·2^32 + u0) / v` and the remainder, for `u1 < v` (so that the
/// quotient fits 32 bits): Knuth's algorithm D in base 2^16 with the
/// hardware's 32-bit divider (H. S. Warren, *Hacker's Delight*, 2nd ed.,
/// §9-4, `divlu`).
#[inline(always)]
fn div_2by1(u1: u32, u0: u32, v: u32) -> (u32, u32) {
    const B: u32 = 1 << 16;
    // Normalise: v's top bit set (v > u1 ≥ 0, so v ≠ 0).
    let s = v.leading_zeros();
    let v = v << s;
    let (vn1, vn0) = (v >> 16, v & 0xFFFF);
    // u1 < v, so u1 << s loses no bit; `checked_shr` covers s = 0.
    let un32 = (u1 << s) | u0.checked_shr(32 - s).unwrap_or(0);
    let un10 = u0 << s;
    let (un1, un0) = (un10 >> 16, un10 & 0xFFFF);
    let q1 = digit(un32, un1, vn1, vn0);
    let un21 = un32
        .wrapping_mul(B)
        .wrapping_add(un1)
        .wrapping_sub(q1.wrapping_mul(v));
    let q0 = digit(un21, un0, vn1, vn0);
    let r = un21
        .wrapping_mul(B)
        .wrapping_add(un0)
        .wrapping_sub(q0.wrapping_mul(v));
    ((q1 << 16) | q0, r >> s)
}

/// One quotient digit (base 2^16) of Knuth's algorithm D: the estimate
/// `un / vn1`, corrected down at most twice.
#[inline(always)]
fn digit(un: u32, un_next: u32, vn1: u32, vn0: u32) -> u32 {
    const B: u32 = 1 << 16;
    let mut q = un / vn1;
    let mut rhat = un - q * vn1;
    // `q < B` is checked first, so q·vn0 < 2^32; rhat < B, so
    // rhat·B + un_next < 2^32.
    while q >= B || q * vn0 > rhat * B + un_next {
        q -= 1;
        rhat += vn1;
        if rhat >= B {
            break;
        }
    }
    q
}

/// `(a / b, a % b)` truncating towards zero, the remainder with the sign of
/// `a` (Rust's and C's `/` and `%`), from the unsigned division `div_u` of
/// the magnitudes. `i64::MIN / -1` wraps to `i64::MIN` (never asked: Rust
/// checks for that overflow before it divides).
#[must_use]
#[allow(clippy::cast_possible_wrap)]
pub fn div_rem_i64(a: i64, b: i64, div_u: impl FnOnce(u64, u64) -> (u64, u64)) -> (i64, i64) {
    let (q, r) = div_u(a.unsigned_abs(), b.unsigned_abs());
    let (q, r) = (q as i64, r as i64);
    (
        if (a ^ b) < 0 { q.wrapping_neg() } else { q },
        if a < 0 { r.wrapping_neg() } else { r },
    )
}
