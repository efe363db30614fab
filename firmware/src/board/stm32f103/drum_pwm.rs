//! The drum motor's PWM (TIM1 CH1 on PA8, 20 kHz) with the driver's enable (PB12) and direction (PB13).

use super::*;

/// Drum motor PWM (TIM1 CH1) with the driver's enable and direction pins.
pub struct DrumDrive {
    pub(super) tim: TIM1,
    pub(super) enable: PB12<Output<PushPull>>,
    pub(super) _direction: PB13<Output<PushPull>>,
}

/// TIM1 auto-reload value: 72 MHz / 20 kHz − 1.
pub(super) const DRUM_ARR: u16 = (TIMER_CLOCK_HZ / DRUM_PWM_HZ - 1) as u16;

impl DrumDrive {
    pub(super) fn new(
        tim: TIM1,
        mut enable: PB12<Output<PushPull>>,
        mut direction: PB13<Output<PushPull>>,
    ) -> Self {
        enable.set_low();
        direction.set_low();
        // PWM mode 1 on CH1 (RM0008 §14.4); TIM1 is owned by this struct.
        // ARR (§14.4.12) is non-zero before the update and the counter
        // start: a null ARR blocks the counter.
        tim.psc().write(|w| w.psc().set(0));
        tim.arr().write(|w| w.arr().set(DRUM_ARR));
        tim.ccr1().write(|w| w.ccr().set(0));
        // CCMR1 (§14.4.7): OC1M = 110 (PWM mode 1), OC1PE = 1 (preload).
        tim.ccmr1_output()
            .write(|w| w.oc1m().pwm_mode1().oc1pe().enabled());
        // CCER (§14.4.9): CC1E = 1, active high.
        tim.ccer().write(|w| w.cc1e().set_bit());
        // BDTR (§14.4.18): MOE = 1, OSSI = OSSR = 1 (off state = driven to
        // OIS1 = low, not released), no break, no lock.
        tim.bdtr()
            .write(|w| w.moe().set_bit().ossr().set_bit().ossi().set_bit());
        // EGR UG (§14.4.6): PSC, ARR and CCR1 into their shadows.
        tim.egr().write(|w| w.ug().set_bit());
        // CR1 (§14.4.1): ARPE = 1, CEN = 1.
        tim.cr1().write(|w| w.arpe().set_bit().cen().set_bit());
        Self {
            tim,
            enable,
            _direction: direction,
        }
    }

    /// Compare value that gives 100 % duty (ARR + 1).
    pub const fn period(&self) -> u16 {
        DRUM_ARR + 1
    }

    /// Sets the compare value (duty = `ccr / period()`), clamped to the period.
    pub fn set_compare(&mut self, ccr: u16) {
        let ccr = ccr.min(self.period());
        // TIM1_CCR1 (RM0008 §14.4.14), preloaded (OC1PE): applies at the
        // next update, within one 50 µs PWM period. (Stopping does not rely
        // on it: `set_enabled(false)` drops PB12 at once.)
        self.tim.ccr1().write(|w| w.ccr().set(ccr));
    }

    /// Switches the motor driver on or off; off also zeroes the duty.
    pub fn set_enabled(&mut self, on: bool) {
        if on {
            self.enable.set_high();
        } else {
            self.set_compare(0);
            self.enable.set_low();
        }
    }
}
