//! The outputs' safe state and the stop input's response.

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use super::clocks::now_us;
use super::drum_pwm::{DRIVER_ENABLE, DRUM_CCR};
use super::steppers::{FEED_STEP_BITS, PLANT_STEP_BITS};

/// Truth: when the simulated contact opened, and when [`stop_outputs`] made
/// the outputs safe after it (µs of firmware time).
pub(super) static STOP_OPENED_US: AtomicU32 = AtomicU32::new(0);
pub(super) static STOP_SAFE_US: AtomicU32 = AtomicU32::new(0);

/// The stop input's response (see the real board's): zeroes the PWM and
/// step stand-ins and the enable, and notes the time for the simulator's
/// truth line.
pub fn stop_outputs() {
    safe_state();
    STOP_SAFE_US.store(now_us(), Relaxed);
}

/// Whether the drivers' enable stand-in is on (the settings task erases
/// flash only while it is off).
pub fn drivers_enabled() -> bool {
    DRIVER_ENABLE.load(Relaxed)
}

/// Zeroes the PWM and step stand-ins and the enable (the model coasts the
/// drum down; the steppers stop).
pub fn safe_state() {
    DRUM_CCR.store(0, Relaxed);
    FEED_STEP_BITS.store(0, Relaxed);
    PLANT_STEP_BITS.store(0, Relaxed);
    DRIVER_ENABLE.store(false, Relaxed);
}
