//! Profile B's two step-pulse outputs: the planting motor on TIM1 CH1 (PA8), the feeding motor on TIM4 CH1 (PB6), the directions on PB14/PB15.

use super::*;

/// Timer settings for a square wave of `rate` (U16F16 Hz) from 72 MHz:
/// `(PSC, ARR)`, the finest prescaler that keeps ARR within 16 bits; `None`
/// for 0 Hz (or a rate below 0.14 Hz).
pub(super) fn step_timing(rate_bits: u32) -> Option<(u16, u16)> {
    if rate_bits == 0 {
        return None;
    }
    for psc in [0u32, 71, 7199] {
        // ARR + 1 = clk / (PSC + 1) / f, f = bits / 65536.
        let ticks = (u64::from(TIMER_CLOCK_HZ / (psc + 1)) << 16) / u64::from(rate_bits);
        if (2..=65_536).contains(&ticks) {
            return Some((psc as u16, (ticks - 1) as u16));
        }
    }
    None
}

/// Programs a timer's CH1 for step pulses at `rate` (50 % duty), or off.
///
/// - Off: OC1M = 100, forced inactive: the output goes low at once (RM0008
///   §14.4.7 / §15.4.7: OC1M is not preloaded), not at the next update,
///   which at a slow step rate can be seconds away.
/// - From off: PSC, ARR and CCR1, PWM mode 1, then UG (§15.4.6): the
///   shadows load together, the counter restarts at 0 and the first pulse
///   starts now.
/// - A change while pulsing: PSC, ARR (ARPE = 1) and CCR1 (OC1PE = 1) are
///   all preloaded, but an update between two of the three writes would
///   start a period with some old and some new values. UDIS = 1 while
///   writing (§15.4.1: no update event, the shadows keep their values; the
///   counter still wraps on the old ARR), then UDIS = 0: the first update
///   after that loads all three together. The current pulse finishes on the
///   old values, so a change takes effect within one old period.
macro_rules! set_step_rate {
    ($tim:expr, $rate_bits:expr) => {{
        let tim = &$tim;
        match step_timing($rate_bits) {
            Some((psc, arr)) => {
                // Register fields from RM0008 §15.4 (see above); the timer is
                // owned by the caller.
                if tim.ccmr1_output().read().oc1m().is_pwm_mode1() {
                    // CR1 (§15.4.1): ARPE, UDIS, CEN.
                    tim.cr1()
                        .write(|w| w.arpe().set_bit().udis().set_bit().cen().set_bit());
                    tim.psc().write(|w| w.psc().set(psc));
                    tim.arr().write(|w| w.arr().set(arr));
                    tim.ccr1().write(|w| w.ccr().set(arr / 2 + 1));
                    tim.cr1().write(|w| w.arpe().set_bit().cen().set_bit());
                } else {
                    tim.psc().write(|w| w.psc().set(psc));
                    tim.arr().write(|w| w.arr().set(arr));
                    tim.ccr1().write(|w| w.ccr().set(arr / 2 + 1));
                    // CCMR1 (§15.4.7): OC1M = 110 (PWM mode 1), OC1PE = 1.
                    tim.ccmr1_output()
                        .write(|w| w.oc1m().pwm_mode1().oc1pe().enabled());
                    tim.egr().write(|w| w.ug().set_bit());
                }
            }
            None => {
                // CCMR1: OC1M = 100 (forced inactive), OC1PE = 1.
                tim.ccmr1_output()
                    .write(|w| w.oc1m().force_inactive().oc1pe().enabled());
            }
        }
    }};
}

impl Tim4Pins {
    /// Profile B: the step output, idle, and the direction pins, forward
    /// (PB7 stays in its reset state).
    pub(super) fn into_feed_step(mut self) -> FeedStep {
        let feed_dir = self.pb14.into_push_pull_output(&mut self.crh);
        let plant_dir = self.pb15.into_push_pull_output(&mut self.crh);
        let feed_step = FeedStep::new(self.tim, feed_dir, plant_dir);
        let _step_pin = self.pb6.into_alternate_push_pull(&mut self.crl);
        feed_step
    }
}

/// Profile B's feeding-motor step output, TIM4 CH1 on PB6, with both
/// motors' direction pins (forward = low).
pub struct FeedStep {
    pub(super) tim: pac::TIM4,
    pub(super) _feed_dir: stm32f1xx_hal::gpio::PB14<Output<PushPull>>,
    pub(super) _plant_dir: stm32f1xx_hal::gpio::PB15<Output<PushPull>>,
}

impl FeedStep {
    pub(super) fn new(
        tim: pac::TIM4,
        mut feed_dir: stm32f1xx_hal::gpio::PB14<Output<PushPull>>,
        mut plant_dir: stm32f1xx_hal::gpio::PB15<Output<PushPull>>,
    ) -> Self {
        feed_dir.set_low();
        plant_dir.set_low();
        // Register fields from RM0008 §15.4; TIM4 is owned by this struct. ARR (§15.4.12) must be non-zero before the update and
        // the counter start: "the counter is blocked while the auto-reload
        // value is null", and with it every later preload (PSC, ARR, CCR1)
        // would wait for an update that never comes. The idle values (PSC 0,
        // ARR 0xFFFF) are replaced by `set_step_rate!` when pulses start.
        tim.psc().write(|w| w.psc().set(0));
        tim.arr().write(|w| w.arr().set(u16::MAX));
        tim.ccr1().write(|w| w.ccr().set(0));
        // CCMR1 (§15.4.7): OC1M = 100 (forced inactive: no pulses), OC1PE = 1.
        tim.ccmr1_output()
            .write(|w| w.oc1m().force_inactive().oc1pe().enabled());
        // CCER (§15.4.9): CC1E = 1, active high.
        tim.ccer().write(|w| w.cc1e().set_bit());
        // EGR UG (§15.4.6), then CR1 (§15.4.1): ARPE = 1, CEN = 1.
        tim.egr().write(|w| w.ug().set_bit());
        tim.cr1().write(|w| w.arpe().set_bit().cen().set_bit());
        Self {
            tim,
            _feed_dir: feed_dir,
            _plant_dir: plant_dir,
        }
    }
}

/// Profile B's two step outputs: the planting motor on TIM1 CH1 (PA8, the
/// drum PWM pin of profile A) and the feeding motor on TIM4 CH1 (PB6); the
/// drivers share the enable on PB12.
pub struct Steppers {
    pub(super) drum: DrumDrive,
    pub(super) feed: FeedStep,
}

impl Steppers {
    /// Takes over the drum PWM's timer for step pulses (profile B), forced
    /// inactive (no pulses) until a rate is set.
    pub fn new(drum: DrumDrive, feed: Tim4Pins) -> Self {
        set_step_rate!(drum.tim, 0);
        Self {
            drum,
            feed: feed.into_feed_step(),
        }
    }

    /// Sets both pulse rates (U16F16 Hz) and the drivers' enable.
    pub fn set(
        &mut self,
        feed: kinematics::units::Hertz,
        plant: kinematics::units::Hertz,
        enabled: bool,
    ) {
        let (feed, plant) = if enabled {
            (feed.to_bits(), plant.to_bits())
        } else {
            (0, 0)
        };
        set_step_rate!(self.feed.tim, feed);
        set_step_rate!(self.drum.tim, plant);
        if enabled {
            self.drum.enable.set_high();
        } else {
            self.drum.enable.set_low();
        }
    }
}
