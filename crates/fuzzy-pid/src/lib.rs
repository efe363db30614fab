//! Fixed-point fuzzy self-tuning PID for the drum speed of the transplanter
//! (SPEC §5), with a lookup-table variant and a conventional fixed-gain PID
//! behind the same [`Controller`].
//!
//! * Sign convention: **`e = target − measured`** (positive error = drum too
//!   slow), `ec = e[k] − e[k−1]` in r/min per sample.
//! * Signals are drum speed in r/min, in [`I16F16`] (range ±32768, resolution
//!   1.5·10⁻⁵ r/min). Gains are `I16F16` too; sums of products are accumulated in
//!   `i64`. No division happens in a step with the default product AND (see
//!   [`fuzzy`]); the lookup-table step never divides.
//! * Discrete-time gains (`Ts` = 10 ms): `Kp` is r/min of output per r/min of
//!   error; `Ki` is **per sample** (the integral grows by `Ki·e` every step, so
//!   the continuous gain is `Ki/Ts`: `Ki0 = 0.1` ⇒ 10 s⁻¹, `Ti = Kp/Ki·Ts = 0.2 s`);
//!   `Kd` is **per sample** too (it multiplies the filtered change of the
//!   measurement per sample, like `ec`: the continuous `Td = Kd/Kp·Ts`).
//! * The output is `feedforward + trim`, clamped to the output limits
//!   (`[0, 44.7]` r/min by default).
//!
//! ```
//! use fuzzy_pid::{Config, I16F16};
//!
//! // The paper's 7×7 fuzzy PID with Kp0 = 2, Ki0 = 0.1, Kd0 = 0.05.
//! let mut pid = Config::default().build()?;
//! pid.start();
//! // Target 20 r/min, drum at 18 r/min, kinematic feed-forward 20 r/min.
//! let out = pid.step(I16F16::from_num(20), I16F16::from_num(18), I16F16::from_num(20));
//! // e = 2 r/min → fuzzy 0.24, 24 % of the way from ZO to PS; ec = 0 on the
//! // first step. Rules (ZO, ZO) and (PS, ZO) fire with 0.76 and 0.24:
//! // ΔKp = 0.24·(NS = −5/3) = −0.4, ΔKi = 0.24·(PS = 1.25/3) = 0.1,
//! // ΔKd = 0.76·(NS = −2.5/3) = −0.633, so Kp = 1.6, Ki = 0.2, Kd = 0 (clamped)
//! // and out = 20 + 1.6·2 + 0.2·2 = 23.6 r/min.
//! let s = pid.status();
//! assert!((s.gains.kp.to_num::<f64>() - 1.6).abs() < 1e-3);
//! assert!((s.gains.ki.to_num::<f64>() - 0.2).abs() < 1e-3);
//! assert_eq!(s.gains.kd, I16F16::ZERO);
//! assert!((out.to_num::<f64>() - 23.6).abs() < 1e-3);
//! // The output never leaves [0, 44.7] r/min.
//! let out = pid.step(I16F16::from_num(40), I16F16::from_num(0), I16F16::from_num(40));
//! assert_eq!(out, I16F16::lit("44.7"));
//! # Ok::<(), fuzzy_pid::Error>(())
//! ```
#![no_std]
#![cfg_attr(not(test), forbid(unsafe_code))]

#[cfg(test)]
extern crate std;

pub mod fuzzy;
pub mod pid;
#[cfg(any(test, feature = "reference"))]
pub mod reference;
pub mod rules;

#[cfg(test)]
mod tests;

pub use fixed::types::I16F16;
pub use fuzzy::{AndOperator, FuzzyConfig, FuzzyTuner, LutTuner};
pub use pid::{
    AntiWindup, AnyController, AnySchedule, Config, Controller, DirectSchedule, GainSchedule,
    LutController, Mode, Saturation, Schedule, Status,
};
pub use rules::{GainOutput, RuleBase, RuleBaseSize};

/// Configuration errors reported by the `new`/`build` constructors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// A rule base must have 2 to 7 sets per input.
    RuleBaseSize(usize),
    /// A rule consequent label outside `−3..=3`.
    RuleLabel {
        /// The table.
        output: GainOutput,
        /// Row (e set, 0 = NB).
        row: usize,
        /// Column (ec set, 0 = NB).
        col: usize,
        /// The offending label.
        label: i8,
    },
    /// An input basic domain outside `[0.01, 500]`.
    InputDomain,
    /// An output range not in `(0, 1000]`.
    OutputRange(GainOutput),
    /// Output limits with `min ≥ max`.
    OutputLimits,
    /// A negative base gain.
    NegativeGain,
    /// Derivative filter coefficient outside `(0, 1]`.
    DerivativeFilter,
    /// Back-calculation gain outside `[0, 1]`.
    BackCalculation,
    /// The schedule does not fit the controller type: [`Config::build`] holds
    /// a conventional or direct fuzzy tuner only (use
    /// [`Config::build_lut`] or [`Config::build_any`] for
    /// [`Schedule::Lookup`]), [`Config::build_lut`] a lookup table only.
    LookupSchedule,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::RuleBaseSize(n) => write!(f, "rule base must have 2 to 7 sets, not {n}"),
            Self::RuleLabel {
                output,
                row,
                col,
                label,
            } => write!(
                f,
                "{output} rule ({row}, {col}) has label {label}, outside -3..=3"
            ),
            Self::InputDomain => f.write_str("input domain must lie in [0.01, 500]"),
            Self::OutputRange(o) => write!(f, "{o} range must lie in (0, 1000]"),
            Self::OutputLimits => f.write_str("output minimum must be below the maximum"),
            Self::NegativeGain => f.write_str("base gains must not be negative"),
            Self::DerivativeFilter => f.write_str("derivative filter must lie in (0, 1]"),
            Self::BackCalculation => f.write_str("back-calculation gain must lie in [0, 1]"),
            Self::LookupSchedule => {
                f.write_str("schedule needs another controller type (build, build_lut, build_any)")
            }
        }
    }
}

impl core::error::Error for Error {}

/// Three PID gains (or their fuzzy corrections ΔKp, ΔKi, ΔKd), `I16F16`.
/// `ki` and `kd` are per sample (see the crate documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Gains {
    /// Proportional gain (r/min per r/min).
    pub kp: I16F16,
    /// Integral gain, per sample.
    pub ki: I16F16,
    /// Derivative gain, per sample.
    pub kd: I16F16,
}

impl Gains {
    /// All zero.
    pub const ZERO: Self = Self {
        kp: I16F16::ZERO,
        ki: I16F16::ZERO,
        kd: I16F16::ZERO,
    };
}

/// `a·b`, rounded down and saturating: bit for bit `I16F16::saturating_mul`,
/// in one shared, non-inlined body (every inlined copy of the 64-bit
/// product and its saturation costs about 40 bytes of flash on thumbv7m).
#[inline(never)]
pub(crate) fn smul(a: I16F16, b: I16F16) -> I16F16 {
    // |a·b| < 2^62: no overflow; `>>` rounds towards −∞ as `fixed` does.
    let p = i64::from(a.to_bits()).wrapping_mul(i64::from(b.to_bits())) >> I16F16::FRAC_NBITS;
    I16F16::from_bits(i32::try_from(p).unwrap_or(if p < 0 { i32::MIN } else { i32::MAX }))
}

/// Value in thousandths, for logs (`I16F16` is not `defmt::Format`).
#[must_use]
pub fn milli(x: I16F16) -> i32 {
    let m = i64::from(x.to_bits())
        .wrapping_mul(1000)
        .wrapping_shr(I16F16::FRAC_NBITS);
    // |x| < 2^15 so |m| < 2^25: always fits.
    i32::try_from(m).unwrap_or(0)
}

#[cfg(feature = "defmt")]
impl defmt::Format for Gains {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "Gains {{ kp: {=i32}e-3, ki: {=i32}e-3, kd: {=i32}e-3 }}",
            milli(self.kp),
            milli(self.ki),
            milli(self.kd)
        );
    }
}

// RAM budget of the firmware (docs/fuzzy-pid.md): the default controller
// stays within 450 bytes on the 32-bit MCU (392 today).
#[cfg(target_pointer_width = "32")]
const _: () = assert!(core::mem::size_of::<Controller>() <= 450);
