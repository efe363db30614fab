//! The once-per-revolution component of a gear's tooth table.
//!
//! The speed estimator learns each tooth gap's share of a revolution from
//! the gap's time against its neighbours' ([`crate::speed`], "Tooth-pitch
//! compensation"). A ripple of the gear's speed once a revolution and a
//! tooth error of the same shape read alike there, so the table's first
//! harmonic is not learnt: it wanders with the terrain. The ground distance
//! counts the learnt shares without it ([`first_harmonic_q16`]); the teeth's
//! finer errors, which the learning does see, stay.
//!
//! Integer arithmetic only: the table's cosines and sines come from a
//! rotation by 2π/z in Q30, whose base values are computed at compile time
//! ([`ROTATION_Q30`]).

/// Largest tooth count (as [`crate::speed::MAX_TEETH`]).
const MAX_TEETH: usize = crate::speed::MAX_TEETH;
/// Gears with fewer teeth keep their whole table: with three teeth or less
/// the first harmonic is most of what a table can hold.
const MIN_TEETH: usize = 4;
/// 1.0 in Q30.
const ONE_Q30: i64 = 1 << 30;

/// `(cos 2π/z, sin 2π/z)` in Q30 for z = 0 … 32 (z < 1: (1, 0)), rounded;
/// evaluated at compile time from their Taylor series.
pub const ROTATION_Q30: [(i64, i64); MAX_TEETH + 1] = rotations();

// Compile time only: f64 arithmetic, bounded loops, no panics (z ≥ 1 when
// divided).
#[allow(
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::indexing_slicing
)]
const fn rotations() -> [(i64, i64); MAX_TEETH + 1] {
    let mut out = [(ONE_Q30, 0); MAX_TEETH + 1];
    let mut z = 1;
    while z <= MAX_TEETH {
        let x = 2.0 * core::f64::consts::PI / z as f64;
        // cos x = Σ (−1)^k x^2k / (2k)!, sin x = Σ (−1)^k x^(2k+1) / (2k+1)!:
        // 40 terms reach below 10⁻¹⁶ for x ≤ 2π.
        let (mut c, mut s, mut term, mut n) = (0.0, 0.0, 1.0, 0);
        while n < 40 {
            match n % 4 {
                0 => c += term,
                1 => s += term,
                2 => c -= term,
                _ => s -= term,
            }
            n += 1;
            term = term * x / n as f64;
        }
        out[z] = (round_q30(c), round_q30(s));
        z += 1;
    }
    out
}

/// The first harmonic of a table of `offsets` (Q16 offsets of each tooth's
/// share from one pitch, the first `z` used), per tooth, Q16: the least-
/// squares fit `a·cos(2πj/z) + b·sin(2πj/z)`. Subtracting it from the
/// table leaves the rest. Its values add up to exactly 0 over the
/// revolution (the rounding's remainder is spread over the first teeth),
/// so a ground counted without it still gains one revolution per
/// revolution. All zero for fewer than four teeth.
#[must_use]
pub fn first_harmonic_q16(offsets: &[i16], z: usize) -> [i16; MAX_TEETH] {
    let mut out = [0i16; MAX_TEETH];
    if !(MIN_TEETH..=MAX_TEETH).contains(&z) || offsets.len() < z {
        return out;
    }
    let (rc, rs) = ROTATION_Q30.get(z).copied().unwrap_or((ONE_Q30, 0));
    // a = (2/z)·Σ d·cos, b = (2/z)·Σ d·sin; |d| < 2¹⁵, |cos| ≤ 2³⁰, 32
    // teeth: the sums stay below 2⁵⁰ (wrapping arithmetic cannot wrap).
    let (mut sum_c, mut sum_s) = (0i64, 0i64);
    let mut rot = Rotation::new(rc, rs);
    for &d in offsets.iter().take(z) {
        let (c, s) = rot.next();
        sum_c = sum_c.wrapping_add(i64::from(d).wrapping_mul(c));
        sum_s = sum_s.wrapping_add(i64::from(d).wrapping_mul(s));
    }
    let zi = i64::try_from(z).unwrap_or(1);
    // Q16 amplitudes: × 2 / z, then Q46 → Q16.
    let a = div_round(sum_c.wrapping_mul(2), zi.wrapping_mul(ONE_Q30));
    let b = div_round(sum_s.wrapping_mul(2), zi.wrapping_mul(ONE_Q30));
    let mut rot = Rotation::new(rc, rs);
    let mut total = 0i64;
    for slot in out.iter_mut().take(z) {
        let (c, s) = rot.next();
        // |a|, |b| < 2¹⁶: the products < 2⁴⁶.
        let v = div_round(a.wrapping_mul(c).wrapping_add(b.wrapping_mul(s)), ONE_Q30);
        let v = i16::try_from(v).unwrap_or(0);
        total = total.wrapping_add(i64::from(v));
        *slot = v;
    }
    // The rounding's remainder (a few Q16 units at most): one unit off each
    // of the first teeth, so the harmonic adds up to exactly 0.
    for slot in out.iter_mut().take(z) {
        if total == 0 {
            break;
        }
        let step = total.signum();
        *slot = slot.saturating_sub(i16::try_from(step).unwrap_or(0));
        total = total.saturating_sub(step);
    }
    out
}

/// `v` in Q30, rounded half away from zero (compile time).
#[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
const fn round_q30(v: f64) -> i64 {
    let t = v * ONE_Q30 as f64;
    if t >= 0.0 {
        (t + 0.5) as i64
    } else {
        (t - 0.5) as i64
    }
}

/// `n / d` rounded half away from zero, for the bounded values here (|n|
/// < 2⁶², 0 < `d` < 2⁴⁰).
fn div_round(n: i64, d: i64) -> i64 {
    let half = d >> 1;
    let q = if n >= 0 {
        n.wrapping_add(half).checked_div(d)
    } else {
        n.wrapping_sub(half).checked_div(d)
    };
    q.unwrap_or(0)
}

/// The unit vector at 2πj/z for j = 0, 1, …: one rotation by the base
/// angle per step, Q30 (32 steps leave an error below 2⁻²⁵).
struct Rotation {
    c: i64,
    s: i64,
    rc: i64,
    rs: i64,
}

impl Rotation {
    fn new(rc: i64, rs: i64) -> Self {
        Self {
            c: ONE_Q30,
            s: 0,
            rc,
            rs,
        }
    }

    /// The current vector, then one step on.
    fn next(&mut self) -> (i64, i64) {
        let now = (self.c, self.s);
        // |c|, |s|, |rc|, |rs| ≤ 2³⁰ (+ the rounding's few units): each
        // product < 2⁶¹, a sum of two < 2⁶² (wrapping cannot wrap).
        let c = self
            .c
            .wrapping_mul(self.rc)
            .wrapping_sub(self.s.wrapping_mul(self.rs));
        let s = self
            .s
            .wrapping_mul(self.rc)
            .wrapping_add(self.c.wrapping_mul(self.rs));
        self.c = c >> 30;
        self.s = s >> 30;
        now
    }
}

#[cfg(test)]
#[allow(
    clippy::needless_range_loop,
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss
)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// The f64 least-squares first harmonic, per tooth (the reference).
    fn reference(d: &[f64]) -> Vec<f64> {
        let z = d.len() as f64;
        let w = |j: usize| 2.0 * std::f64::consts::PI * j as f64 / z;
        let a: f64 = d
            .iter()
            .enumerate()
            .map(|(j, v)| v * w(j).cos())
            .sum::<f64>()
            * 2.0
            / z;
        let b: f64 = d
            .iter()
            .enumerate()
            .map(|(j, v)| v * w(j).sin())
            .sum::<f64>()
            * 2.0
            / z;
        (0..d.len())
            .map(|j| a * w(j).cos() + b * w(j).sin())
            .collect()
    }

    #[test]
    fn the_rotations_are_the_unit_circle_at_2_pi_over_z() {
        for z in 1..=MAX_TEETH {
            let x = 2.0 * std::f64::consts::PI / z as f64;
            let (c, s) = ROTATION_Q30[z];
            assert!(
                (c as f64 / ONE_Q30 as f64 - x.cos()).abs() < 2e-9,
                "cos z={z}"
            );
            assert!(
                (s as f64 / ONE_Q30 as f64 - x.sin()).abs() < 2e-9,
                "sin z={z}"
            );
        }
    }

    #[test]
    fn matches_the_f64_fit_on_random_tables_and_sums_to_zero() {
        // A small LCG: tables of ±4 % (±2621 Q16) on every gear size.
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for z in MIN_TEETH..=MAX_TEETH {
            for _ in 0..50 {
                let mut t = [0i16; MAX_TEETH];
                for v in t.iter_mut().take(z) {
                    x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                    *v = ((x >> 33) % 5243) as i16 - 2621;
                }
                let got = first_harmonic_q16(&t, z);
                let want = reference(&t[..z].iter().map(|&v| f64::from(v)).collect::<Vec<_>>());
                for j in 0..z {
                    assert!(
                        (f64::from(got[j]) - want[j]).abs() <= 2.0,
                        "z={z} j={j}: {} vs {}",
                        got[j],
                        want[j]
                    );
                }
                assert_eq!(got.iter().map(|&v| i32::from(v)).sum::<i32>(), 0, "z={z}");
                assert!(got[z..].iter().all(|&v| v == 0));
            }
        }
    }

    #[test]
    fn a_pure_first_harmonic_is_found_whole_and_finer_errors_are_left() {
        let z = 25;
        let mut t = [0i16; MAX_TEETH];
        for (j, v) in t.iter_mut().take(z).enumerate() {
            let w = 2.0 * std::f64::consts::PI * j as f64 / z as f64;
            // 1 % once a revolution plus an alternating ±0.5 % (the 12.5th
            // harmonic's neighbour: nothing of it is first harmonic).
            let fine = if j % 2 == 0 { 328.0 } else { -328.0 };
            *v = (655.0 * (w + 0.3).cos() + fine).round() as i16;
        }
        let h = first_harmonic_q16(&t, z);
        for j in 0..z {
            let w = 2.0 * std::f64::consts::PI * j as f64 / z as f64;
            let want = 655.0 * (w + 0.3).cos();
            // The alternating part over an odd count leaks 1/z of itself.
            assert!(
                (f64::from(h[j]) - want).abs() < 30.0,
                "j={j}: {} vs {want}",
                h[j]
            );
        }
    }

    #[test]
    fn small_gears_and_short_tables_keep_everything() {
        let t = [100i16; MAX_TEETH];
        assert_eq!(first_harmonic_q16(&t, 3), [0; MAX_TEETH]);
        assert_eq!(first_harmonic_q16(&t[..10], 25), [0; MAX_TEETH]);
        assert_eq!(first_harmonic_q16(&t, 33), [0; MAX_TEETH]);
    }
}
