//! Typed physical units as newtypes over unsigned fixed point.
//!
//! Every quantity that flows through the control path has its own type, so a
//! km/h value cannot be passed where m/s is expected (that is a compile error,
//! not a runtime surprise). All types are non-negative: the machine only drives
//! forwards and every quantity in the papers is a magnitude.
//!
//! | type | wraps | range | resolution |
//! |---|---|---|---|
//! | [`MetresPerSecond`] | `U8F24` | 0 … 256 m/s | 6.0e-8 m/s |
//! | [`KilometresPerHour`] | `U10F22` | 0 … 1024 km/h | 2.4e-7 km/h |
//! | [`RevPerMin`] | `U12F20` | 0 … 4096 r/min | 9.5e-7 r/min |
//! | [`Metres`] | `U12F20` | 0 … 4096 m | 0.95 µm |
//! | [`Seconds`] | `U16F16` | 0 … 65536 s | 15 µs |
//! | [`Hertz`] | `U16F16` | 0 … 65536 Hz | 1.5e-5 Hz |
//! | [`PerMinute`] | `U16F16` | 0 … 65536 /min | 1.5e-5 /min |
//! | [`Coefficient`] | `U2F30` | 0 … 4 | 9.3e-10 |
//! | [`Duty`] | `U1F31` | 0 … 2 (used 0 … 1) | 4.7e-10 |
//! | [`Ticks`] | `u32` | 0 … 2³² µs (wrapping) | 1 µs (1 MHz timer) |
//!
//! Conversions to and from `f64` exist for host tools (parsing, printing); the
//! firmware builds values from integers ([`Metres::from_mm`], …) or from the
//! raw bits it stored.

use fixed::types::{U10F22, U12F20, U16F16, U1F31, U2F30, U8F24};

use crate::fx::{self, W};
use crate::Error;

macro_rules! unit {
    ($(#[$doc:meta])* $name:ident, $fix:ty, $sym:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        pub struct $name($fix);

        impl $name {
            /// Zero.
            pub const ZERO: Self = Self(<$fix>::ZERO);
            /// The largest representable value.
            pub const MAX: Self = Self(<$fix>::MAX);
            /// Unit symbol used by `Display`.
            pub const SYMBOL: &'static str = $sym;

            /// Wraps a fixed-point value.
            #[must_use]
            pub const fn from_fixed(v: $fix) -> Self {
                Self(v)
            }
            /// The fixed-point value.
            #[must_use]
            pub const fn to_fixed(self) -> $fix {
                self.0
            }
            /// From the raw bits of the fixed-point value (e.g. read back from flash).
            #[must_use]
            pub const fn from_bits(bits: u32) -> Self {
                Self(<$fix>::from_bits(bits))
            }
            /// The raw bits of the fixed-point value.
            #[must_use]
            pub const fn to_bits(self) -> u32 {
                self.0.to_bits()
            }
            /// Parses a decimal literal at compile time (panics at compile
            /// time on a bad literal; use only in `const` items).
            #[must_use]
            pub const fn lit(s: &str) -> Self {
                Self(<$fix>::lit(s))
            }
            /// From an `f64` (host tools). `None` if negative, NaN or too large.
            #[must_use]
            pub fn from_f64(v: f64) -> Option<Self> {
                <$fix>::checked_from_num(v).map(Self)
            }
            /// As `f64` (host tools, logs, tests).
            #[must_use]
            pub fn to_f64(self) -> f64 {
                self.0.to_num::<f64>()
            }
            /// `num / den` in this unit, rounded down; saturates, `None` if `den == 0`.
            #[must_use]
            pub fn from_ratio(num: u32, den: u32) -> Option<Self> {
                let bits = (u64::from(num) << Self::FRAC).checked_div(u64::from(den))?;
                Some(Self::from_bits(u32::try_from(bits).unwrap_or(u32::MAX)))
            }
            /// Value in thousandths of the unit, rounded to the nearest
            /// (halves up) and saturating: what a person reads (logs, the
            /// screen). The control path keeps the fixed-point value itself
            /// (its full precision); a value rounded down here read 1.030
            /// for a k1 of 1.030 997 and put the difference into every edge.
            #[must_use]
            pub fn to_milli(self) -> u32 {
                // Below 2^42: no overflow.
                let m = u64::from(self.to_bits())
                    .wrapping_mul(1000)
                    .wrapping_add(1 << Self::FRAC >> 1)
                    >> Self::FRAC;
                u32::try_from(m).unwrap_or(u32::MAX)
            }
            /// Saturating sum.
            #[must_use]
            pub fn saturating_add(self, rhs: Self) -> Self {
                Self(self.0.saturating_add(rhs.0))
            }
            /// Saturating difference (0 if `rhs > self`).
            #[must_use]
            pub fn saturating_sub(self, rhs: Self) -> Self {
                Self(self.0.saturating_sub(rhs.0))
            }
            /// `|self − rhs|`.
            #[must_use]
            pub fn abs_diff(self, rhs: Self) -> Self {
                if self >= rhs {
                    self.saturating_sub(rhs)
                } else {
                    rhs.saturating_sub(self)
                }
            }
            /// Fractional bits of the storage type.
            const FRAC: u32 = <$fix>::FRAC_NBITS;
            #[allow(dead_code)]
            pub(crate) fn w(self) -> W {
                fx::widen_bits(self.to_bits(), Self::FRAC)
            }
            #[allow(dead_code)]
            pub(crate) fn try_from_w(w: W) -> Result<Self, Error> {
                fx::narrow_bits(w, Self::FRAC)
                    .map(Self::from_bits)
                    .ok_or(Error::Overflow)
            }
            /// As a table abscissa (`U16F16`, rounded down, saturating): the
            /// same value as `U16F16::saturating_from_num(self.to_fixed())`,
            /// without `fixed`'s generic conversion (≈ 0.3 KB of flash).
            #[must_use]
            pub fn table_x(self) -> U16F16 {
                U16F16::from_bits(fx::narrow_bits(self.w(), 16).unwrap_or(u32::MAX))
            }
            /// Saturating at [`Self::MAX`].
            #[allow(dead_code)]
            pub(crate) fn saturating_from_w(w: W) -> Self {
                Self::from_bits(fx::narrow_bits(w, Self::FRAC).unwrap_or(u32::MAX))
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                write!(f, "{} {}", self.0, $sym)
            }
        }

        #[cfg(feature = "defmt")]
        impl defmt::Format for $name {
            fn format(&self, f: defmt::Formatter<'_>) {
                defmt::write!(f, "{=u32}e-3 {=str}", self.to_milli(), $sym);
            }
        }
    };
}

unit!(
    /// Speed in metres per second (`U8F24`).
    MetresPerSecond, U8F24, "m/s"
);
unit!(
    /// Speed in kilometres per hour (`U10F22`).
    KilometresPerHour, U10F22, "km/h"
);
unit!(
    /// Rotational speed in revolutions per minute (`U12F20`).
    RevPerMin, U12F20, "r/min"
);
unit!(
    /// Length in metres (`U12F20`, 1 µm resolution, up to 4 km).
    Metres, U12F20, "m"
);
unit!(
    /// Duration in seconds (`U16F16`), used by calibration runs.
    Seconds, U16F16, "s"
);
unit!(
    /// Frequency in hertz (`U16F16`), e.g. a step-pulse rate.
    Hertz, U16F16, "Hz"
);
unit!(
    /// Events per minute (`U16F16`), e.g. plants per minute.
    PerMinute, U16F16, "/min"
);
unit!(
    /// A dimensionless correction coefficient (`U2F30`), k1, k2, k3.
    Coefficient, U2F30, ""
);
unit!(
    /// A PWM duty cycle as a fraction 0 … 1 (`U1F31`).
    Duty, U1F31, ""
);

impl Coefficient {
    /// Exactly 1.
    pub const ONE: Self = Self(U2F30::ONE);
}

impl Duty {
    /// 100 % duty.
    pub const FULL: Self = Self(U1F31::ONE);
}

impl KilometresPerHour {
    /// Converts to m/s (`v / 3.6`, i.e. `v · 5 / 18`).
    pub fn to_mps(self) -> Result<MetresPerSecond, Error> {
        let w = fx::div_int(fx::mul_int(self.w(), 5)?, 18)?;
        MetresPerSecond::try_from_w(w)
    }
}

impl MetresPerSecond {
    /// Converts to km/h (`v · 3.6`, i.e. `v · 18 / 5`).
    pub fn to_kmh(self) -> Result<KilometresPerHour, Error> {
        let w = fx::div_int(fx::mul_int(self.w(), 18)?, 5)?;
        KilometresPerHour::try_from_w(w)
    }
}

impl Metres {
    /// From whole millimetres (HMI entry of a plant spacing).
    #[must_use]
    pub fn from_mm(mm: u32) -> Self {
        Self::from_ratio(mm, 1000).unwrap_or(Self::MAX)
    }
}

/// Time in ticks of the 1 MHz capture timer, extended to 32 bits
/// (wraps every 71.6 min; all differences use wrapping arithmetic).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ticks(pub u32);

impl Ticks {
    /// Ticks elapsed from `earlier` to `self`, modulo 2³².
    #[must_use]
    pub const fn wrapping_since(self, earlier: Ticks) -> u32 {
        self.0.wrapping_sub(earlier.0)
    }
}

impl core::fmt::Display for Ticks {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} ticks", self.0)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// What a person reads is rounded to the nearest thousandth, not cut:
    /// k1 interpolated at Low 1's monitored speed (1.030 997) reads 1.031,
    /// 0.8 (one bit below it in U2F30) 0.800, and the largest values
    /// saturate instead of wrapping. Checked against `f64` rounding over
    /// every unit's bit patterns (a sweep of 2¹⁶ values per unit).
    #[test]
    fn to_milli_rounds_to_the_nearest_thousandth() {
        assert_eq!(Coefficient::from_f64(1.030_997).unwrap().to_milli(), 1031);
        assert_eq!(Coefficient::lit("0.8").to_milli(), 800);
        assert_eq!(Coefficient::lit("0.9994").to_milli(), 999);
        assert_eq!(KilometresPerHour::lit("0.3208").to_milli(), 321);
        fn sweep(frac: u32, f: impl Fn(u32) -> u32) {
            for i in 0..=u32::from(u16::MAX) {
                let bits = i.wrapping_mul(65_537).wrapping_add(i >> 3);
                let want = (f64::from(bits) * 1000.0 / 2f64.powi(frac.cast_signed()) + 0.5).floor();
                assert_eq!(
                    f64::from(f(bits)),
                    want.min(f64::from(u32::MAX)),
                    "{bits:#x}"
                );
            }
        }
        sweep(30, |b| Coefficient::from_bits(b).to_milli());
        sweep(22, |b| KilometresPerHour::from_bits(b).to_milli());
        sweep(20, |b| RevPerMin::from_bits(b).to_milli());
        sweep(31, |b| Duty::from_bits(b).to_milli());
    }
}
