//! Kinematics of the transplanter (SPEC §2–4 and §8), `no_std`, fixed point,
//! no heap and no reachable panics.
//!
//! * [`consts`]: machine constants and gear presets (typed and `f64`).
//! * [`units`]: typed units (m/s, km/h, r/min, metres, ticks, …).
//! * [`speed`]: M-method, [`speed::CaptureExtender`], [`speed::MtEstimator`].
//! * [`harmonic`]: the once-per-revolution part of a learnt tooth table.
//! * [`travel`]: k1/k2 correction, travel speed V1, [`travel::Calibration`].
//! * [`drum`]: target drum speed, duty, CCR and the feasibility limit.
//! * [`table`]: validated piecewise-linear coefficient tables and their bytes.
//! * [`calib`]: k1, k2, k3 calibration procedures.
//! * [`profile_b`]: seedling-belt feeding/planting kinematics and linkage.
//!
//! Firmware flow (profile A): capture ISR → `CaptureExtender::extend` →
//! `MtEstimator::push_edge`; control task → `MtEstimator::update` →
//! `travel::travel_speed` → `DrumPlan::target` → PWM CCR.
#![no_std]
#![cfg_attr(not(test), forbid(unsafe_code))]

#[cfg(test)]
extern crate std;

pub mod calib;
pub mod consts;
pub mod drum;
mod fx;
pub mod harmonic;
pub mod profile_b;
pub mod speed;
pub mod table;
pub mod travel;
pub mod units;
pub mod wheel;

/// `⌊a·b / 2^shift⌋` from the exact 128-bit product (four 32 × 32-bit
/// multiplies, no `u128` arithmetic on the MCU), or `None` when it does not
/// fit in 64 bits; `shift` < 64. For callers that carry a coefficient's
/// full U2F30 precision through a product wider than 64 bits.
///
/// ```
/// // 25 132 741.23 nm (one Hall pitch, Q8) × k1·k2 = 1.001 809 (Q30).
/// let q30 = (1.001_809_f64 * (1u64 << 30) as f64) as u64;
/// let nm_q8 = kinematics::mul_shr(6_433_981_755, q30, 30).unwrap();
/// assert_eq!(nm_q8 >> 8, 25_178_206);
/// assert_eq!(kinematics::mul_shr(u64::MAX, u64::MAX, 63), None);
/// ```
#[must_use]
pub fn mul_shr(a: u64, b: u64, shift: u32) -> Option<u64> {
    fx::mul_q(a, b, shift)
}

/// Errors of the kinematic computations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// An intermediate or final value does not fit its fixed-point type.
    Overflow,
    /// A divisor was zero (zero spacing, zero time, zero n_max, …).
    DivisionByZero,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Overflow => f.write_str("value out of fixed-point range"),
            Error::DivisionByZero => f.write_str("division by zero"),
        }
    }
}

impl core::error::Error for Error {}
