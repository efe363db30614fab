//! Profile B's step-pulse outputs stand-ins (TIM1 CH1, TIM4 CH1).

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use super::drum_pwm::{DrumDrive, DRIVER_ENABLE};

/// Stand-ins for the step-pulse timers of profile B (rate, U16F16 Hz bits).
pub(super) static FEED_STEP_BITS: AtomicU32 = AtomicU32::new(0);
pub(super) static PLANT_STEP_BITS: AtomicU32 = AtomicU32::new(0);

/// Profile B's two step-pulse outputs (stand-ins for TIM1 CH1 and TIM4 CH1)
/// and the drivers' enable.
pub struct Steppers {
    _drum: DrumDrive,
    _feed: Tim4Pins,
}

/// TIM4 and its pins' stand-in (TIM4 is not emulated): machine B's feeding
/// step output or machine A's ground wheel, as the settings choose.
pub struct Tim4Pins;

impl Steppers {
    /// Takes over the drum PWM's timer for step pulses (profile B).
    pub fn new(drum: DrumDrive, feed: Tim4Pins) -> Self {
        FEED_STEP_BITS.store(0, Relaxed);
        PLANT_STEP_BITS.store(0, Relaxed);
        Self {
            _drum: drum,
            _feed: feed,
        }
    }

    /// Sets both pulse rates (U16F16 Hz) and the drivers' enable.
    pub fn set(
        &mut self,
        feed: kinematics::units::Hertz,
        plant: kinematics::units::Hertz,
        enabled: bool,
    ) {
        DRIVER_ENABLE.store(enabled, Relaxed);
        let (feed, plant) = if enabled {
            (feed.to_bits(), plant.to_bits())
        } else {
            (0, 0)
        };
        FEED_STEP_BITS.store(feed, Relaxed);
        PLANT_STEP_BITS.store(plant, Relaxed);
    }
}
