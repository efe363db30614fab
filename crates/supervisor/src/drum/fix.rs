//! Conversions between the drum's fixed-point speeds and the units of the
//! tables, the screen and the log.

use fuzzy_pid::I16F16;
use kinematics::units::RevPerMin;

/// One step of a first-order filter: `acc + (x − acc)·alpha`, saturating.
#[inline(never)]
pub(super) fn smooth(acc: I16F16, x: I16F16, alpha: I16F16) -> I16F16 {
    acc.saturating_add(x.saturating_sub(acc).saturating_mul(alpha))
}

/// A drum speed in r/min as the tables' `RevPerMin` (I16F16 → U12F20: 4
/// more fractional bits, exact; negative as 0).
pub(super) fn fix_to_rpm(n: I16F16) -> RevPerMin {
    RevPerMin::from_bits(
        u32::try_from(n.to_bits().max(0))
            .unwrap_or(0)
            .min(u32::MAX >> 4)
            << 4,
    )
}

pub(super) fn rpm_to_fix(n: RevPerMin) -> I16F16 {
    // U12F20 → I16F16: drop 4 fractional bits (rounding down, as `fixed`'s
    // conversions); below 4096 r/min it always fits (test
    // `rpm_to_fix_is_fixeds_conversion`).
    I16F16::from_bits(i32::try_from(n.to_bits() >> 4).unwrap_or(i32::MAX))
}

/// `x × 1000`, rounded to nearest (halves up), negative values as 0:
/// computed from the raw bits in `i64`, so every `I16F16` (up to
/// 32 767.99 r/min) is reported exactly (multiplying in `I16F16` itself
/// would saturate at 32.767 r/min). Rounding (not flooring)
/// gives back the decimal a speed was set from: 25.21 r/min is
/// 1 652 163 / 65 536 = 25.210 005 in I16F16, and 25.209 995 when truncated.
pub fn milli(x: I16F16) -> u32 {
    // |bits| < 2^31, × 1000 < 2^41: no overflow; `>>` floors.
    let v = i64::from(x.to_bits())
        .saturating_mul(1000)
        .saturating_add(1 << 15)
        >> 16;
    u32::try_from(v.max(0)).unwrap_or(u32::MAX)
}

/// A speed as r/min × 256 in an `i16` (saturating at ±127.99 r/min).
pub(super) fn to_i16_x256(x: I16F16) -> i16 {
    let v = x.to_bits() >> 8;
    i16::try_from(v).unwrap_or(if v < 0 { i16::MIN } else { i16::MAX })
}

/// A speed in r/min × 100 (the screen's unit) as the nearest `I16F16`.
pub(super) fn centi_to_fix(raw: u16) -> I16F16 {
    // raw · 65 536 / 100, rounded: ≤ 65 535 · 65 536 < 2^32, fits i64.
    let bits = i64::from(raw)
        .saturating_mul(65_536)
        .saturating_add(50)
        .checked_div(100)
        .unwrap_or(0);
    I16F16::from_bits(i32::try_from(bits).unwrap_or(i32::MAX))
}
/// A ground speed measured directly (the ground wheel, `MetresPerSecond`
/// bits) as the travel speed eq. 7 takes: the gear speed that gives it with
/// k1 = k2 = 1.
pub(super) fn wheel_travel(bits: u32) -> Option<kinematics::travel::TravelSpeed> {
    use kinematics::travel;
    use kinematics::units::{Coefficient, MetresPerSecond};
    let v = MetresPerSecond::from_bits(bits);
    let gear_speed = travel::gear_speed_for(v).ok()?;
    Some(travel::TravelSpeed {
        raw_gear_speed: gear_speed,
        monitored: v.to_kmh().ok()?,
        k1: Coefficient::ONE,
        gear_speed,
        k2: Coefficient::ONE,
        travel_speed: v,
    })
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;
    use fixed::types::U16F16;
    use proptest::prelude::*;

    /// Reference: `floor(x · 1000 + 0.5)` in f64 (exact: `bits / 65536 ·
    /// 1000` has at most 41 significant bits), negative values as 0.
    fn milli_f64(bits: i32) -> u32 {
        let v = (f64::from(bits) / 65_536.0 * 1000.0 + 0.5).floor();
        if v < 0.0 {
            0
        } else {
            v as u32
        }
    }

    #[test]
    fn milli_above_32_767_r_min_is_exact() {
        // I16F16 × 1000 would saturate to 32 767.99…, so 40 r/min would
        // read 32 767.
        assert_eq!(milli(I16F16::from_num(40)), 40_000);
        assert_eq!(
            milli(I16F16::from_num(44.7)),
            milli_f64(I16F16::from_num(44.7).to_bits())
        );
        // The largest I16F16, 32 767 + 65 535/65 536 r/min, rounds up.
        assert_eq!(milli(I16F16::MAX), 32_768_000);
        assert_eq!(milli(I16F16::from_num(-1)), 0);
    }

    proptest! {
        /// The shift conversions that replace `fixed`'s generic ones give
        /// `fixed`'s results (the reference) for every representable value:
        /// drum speeds U12F20 → I16F16, k2 U2F30 → U10F22, and (machine.rs)
        /// the clamping angle's whole degrees U16F16 → u32.
        #[test]
        fn shift_conversions_are_fixeds_conversions(bits in any::<u32>()) {
            let n = RevPerMin::from_bits(bits);
            prop_assert_eq!(rpm_to_fix(n), I16F16::saturating_from_num(n.to_fixed()));
            let k2 = fixed::types::U2F30::from_bits(bits);
            prop_assert_eq!(
                fixed::types::U10F22::from_bits(k2.to_bits() >> 8),
                fixed::types::U10F22::saturating_from_num(k2)
            );
            let angle = U16F16::from_bits(bits);
            prop_assert_eq!(angle.to_bits() >> 16, angle.to_num::<u32>());
        }

        /// Every `I16F16` the supervisor can hold (the whole type, so any
        /// drum speed up to any `n_max`) against the f64 reference.
        #[test]
        fn milli_matches_f64_over_the_whole_type(bits in any::<i32>()) {
            prop_assert_eq!(milli(I16F16::from_bits(bits)), milli_f64(bits));
        }
    }
}
