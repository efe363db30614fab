//! The drum encoder (profile B: the ground wheel's), TIM3 in encoder mode on PA6/PA7.

use super::*;

/// Polled sensors: the drum encoder counter and, on machine A, the ground
/// wheel's.
pub struct Sensors {
    pub(super) tim3: TIM3,
    pub(super) ground_wheel: Option<GroundWheel>,
}

impl Sensors {
    pub(super) fn new(tim3: TIM3) -> Self {
        // Encoder mode 3 (RM0008 §15.3.12). CCMR1 (§15.4.7, input): CC1S = 01 (IC1 on TI1), CC2S = 01 (IC2 on
        // TI2), IC1F = IC2F = 0011: sampled at fCK_INT (72 MHz), N = 8, i.e.
        // a level must hold 8 samples = 111 ns to count. (The encoder's
        // fastest edges, 23.6 kHz per channel at 7080 motor r/min, are 21 µs
        // apart.)
        tim3.ccmr1_input().write(|w| {
            w.cc1s()
                .ti1()
                .ic1f()
                .fck_int_n8()
                .cc2s()
                .ti2()
                .ic2f()
                .fck_int_n8()
        });
        // CCER (§15.4.9): both polarities non-inverted, captures off.
        tim3.ccer().reset();
        // SMCR (§15.4.3): SMS = 011, encoder mode 3 (both edges of both inputs).
        tim3.smcr().write(|w| w.sms().encoder_mode_3());
        // ARR (§15.4.12) non-zero before CEN: the counter wraps at 2^16.
        tim3.arr().write(|w| w.arr().set(u16::MAX));
        tim3.cr1().write(|w| w.cen().set_bit());
        Self {
            tim3,
            ground_wheel: None,
        }
    }

    /// Machine A: TIM4 counts the ground wheel on PB6/PB7 from now on
    /// ([`GroundWheel`]); [`Sensors::sample`] reads it every period.
    pub fn with_ground_wheel(mut self, tim4: Tim4Pins) -> Self {
        self.ground_wheel = Some(GroundWheel::new(tim4));
        self
    }

    /// Reads the sensors for one control period.
    pub fn sample(&mut self, _now_ms: u32) -> SensorSample {
        SensorSample {
            drum_encoder: self.tim3.cnt().read().cnt().bits(),
            hall_edges: heapless::Vec::new(),
            ground_wheel: self.ground_wheel.as_ref().map(GroundWheel::count),
        }
    }
}
