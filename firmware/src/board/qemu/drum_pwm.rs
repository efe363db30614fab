//! The drum PWM stand-in (TIM1 CH1 and the driver enable, PB12).

use core::sync::atomic::{AtomicBool, AtomicU16, Ordering::Relaxed};

use crate::board::DRUM_PWM_HZ;

/// Stand-in for TIM1's CCR1 register.
pub(super) static DRUM_CCR: AtomicU16 = AtomicU16::new(0);

/// Stand-in for the driver enable pin.
pub(super) static DRIVER_ENABLE: AtomicBool = AtomicBool::new(false);

/// Compare value for 100 % duty, the same as the real board's TIM1 (72 MHz /
/// 20 kHz), so that the control code computes identical compare values.
pub(super) const DRUM_PERIOD: u16 = (72_000_000 / DRUM_PWM_HZ) as u16;

/// Drum PWM stand-in.
pub struct DrumDrive {
    pub(super) enabled: bool,
}

impl DrumDrive {
    /// Compare value that gives 100 % duty.
    pub const fn period(&self) -> u16 {
        DRUM_PERIOD
    }

    /// Sets the compare value (duty = `ccr / period()`), clamped to the period.
    pub fn set_compare(&mut self, ccr: u16) {
        DRUM_CCR.store(ccr.min(DRUM_PERIOD), Relaxed);
    }

    /// Switches the motor driver on or off; off also zeroes the duty.
    pub fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
        DRIVER_ENABLE.store(on, Relaxed);
        if !on {
            DRUM_CCR.store(0, Relaxed);
        }
    }

    /// The compare value and enable as the drive sees them (what a scope on
    /// PA8 and PB12 would show).
    pub fn output(&self) -> (u16, bool) {
        (DRUM_CCR.load(Relaxed), DRIVER_ENABLE.load(Relaxed))
    }
}
