//! The firmware's 64-bit division (`firmware/src/div64.rs`, behind
//! `__udivmoddi4`/`__divmoddi4` on the target) against the host's own `/`
//! and `%` (the x86-64 divider): the reference is independent of the code
//! under test. The file is the firmware's very source, included here.
//!
//! Cost: under 0.1 s (≈ 2.6 million pairs).

#[path = "../../firmware/src/div64.rs"]
#[allow(dead_code)]
mod div64;

use div64::{div_rem_i64, div_rem_u64};

/// A small deterministic generator (xorshift64*), so that every run checks
/// the same pairs.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A value of `bits` significant bits (0..=64), uniform below that.
    fn bits(&mut self, bits: u32) -> u64 {
        match bits {
            0 => 0,
            64 => self.next(),
            b => self.next() >> (64 - b),
        }
    }
}

fn check_u(n: u64, d: u64) {
    assert_eq!(div_rem_u64(n, d), (n / d, n % d), "{n} / {d}");
}

fn check_i(a: i64, b: i64) {
    let unsigned = |n, d| div_rem_u64(n, d);
    assert_eq!(div_rem_i64(a, b, unsigned), (a / b, a % b), "{a} / {b}");
}

/// The values where division code goes wrong: around powers of two, around
/// the 16- and 32-bit digit boundaries of the algorithm, and the extremes.
fn edges() -> Vec<u64> {
    let mut v = vec![0, 1, 2, 3, 5, 7, 10, 1000, 3600, 1_000_000, u64::MAX];
    for k in 1..64 {
        let p = 1u64 << k;
        v.extend([p - 1, p, p + 1, p | (p >> 1), p.wrapping_mul(3) / 2]);
    }
    for k in [16, 32, 48] {
        let p = 1u64 << k;
        v.extend([p - 2, p + 2, p.wrapping_mul(0xFFFF), (p - 1) << 16]);
    }
    v
}

#[test]
fn unsigned_edges_are_exact() {
    let e = edges();
    for &n in &e {
        for &d in e.iter().filter(|&&d| d != 0) {
            check_u(n, d);
        }
    }
}

#[test]
fn unsigned_random_pairs_of_every_width_are_exact() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for nb in 0..=64 {
        for db in 1..=64 {
            for _ in 0..400 {
                let n = rng.bits(nb);
                let d = rng.bits(db).max(1);
                check_u(n, d);
            }
        }
    }
}

/// Knuth's algorithm D corrects its digit estimate at most twice; these
/// divisors (top 16 bits all ones or just past a power of two) make the
/// estimate wrong most often.
#[test]
fn unsigned_correction_cases_are_exact() {
    let mut rng = Rng(7);
    for top in [0x8000u64, 0x8001, 0xFFFE, 0xFFFF] {
        for shift in 0..=16 {
            for _ in 0..2000 {
                let d = ((top << 16) | rng.bits(16)) >> shift;
                let n = rng.next();
                check_u(n, d.max(1));
            }
        }
    }
}

#[test]
fn signed_pairs_are_exact() {
    let mut rng = Rng(0xDEAD_BEEF);
    let mut values: Vec<i64> = edges()
        .iter()
        .flat_map(|&v| [v as i64, (v as i64).wrapping_neg()])
        .collect();
    values.extend([i64::MIN, i64::MAX, i64::MIN + 1, -1]);
    for &a in &values {
        for &b in values.iter().filter(|&&b| b != 0) {
            if a == i64::MIN && b == -1 {
                continue; // overflows; Rust checks it before dividing
            }
            check_i(a, b);
        }
    }
    for _ in 0..200_000 {
        let (a_width, width) = (1 + (rng.next() % 64) as u32, 1 + (rng.next() % 64) as u32);
        let a = rng.bits(a_width) as i64;
        let a = if rng.next() & 1 == 0 {
            a
        } else {
            a.wrapping_neg()
        };
        let b = rng.bits(width).max(1) as i64;
        let b = if rng.next() & 1 == 0 {
            b
        } else {
            b.wrapping_neg()
        };
        if b != 0 && !(a == i64::MIN && b == -1) {
            check_i(a, b);
        }
    }
}

/// A zero divisor never reaches these functions (Rust checks first); the
/// result is defined anyway.
#[test]
fn zero_divisor_is_defined() {
    assert_eq!(div_rem_u64(12345, 0), (u64::MAX, 12345));
}
