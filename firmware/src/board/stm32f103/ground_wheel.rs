//! Machine A's ground wheel: its quadrature encoder on TIM4 in encoder mode 3, PB6/PB7.
//!
//! The pins and the timer (RM0008 rev. 21, STM32F103xB datasheet):
//!
//! - TIM4_CH1 is PB6 and TIM4_CH2 is PB7 with AFIO_MAPR TIM4_REMAP = 0
//!   (§9.3.7, TIM4 alternate function remapping; §9.4.2 AFIO_MAPR bit 12).
//!   That is the reset value, and the board never writes a remap (its one
//!   AFIO use is EXTI10's port selection, AFIO_EXTICR3). The remapped pins
//!   (PD12/PD13) do not exist on the 64-pin RB. USART1 and I2C1 share PB6/PB7
//!   only when remapped or enabled: USART1 stays on PA9/PA10 (USART1_REMAP = 0)
//!   and I2C1 is not used.
//! - PB6 and PB7 are 5 V tolerant (datasheet, pin definitions table, "FT"),
//!   so a 5 V encoder (or a 5 V external pull-up) may drive them.
//! - Inputs with the internal pull-up (§9.1.4: an alternate function input
//!   needs the pin in input mode, "floating, pull-up or pull-down"; §9.2.1
//!   CNF = 10, MODE = 00, with ODR = 1 for up). An open-collector (NPN)
//!   wheel sensor then needs no resistor of its own, a push-pull one simply
//!   overrides the 30–50 kΩ, and a cut wire or an unplugged sensor reads a
//!   steady high on both channels: no count, never noise counted as ground,
//!   so the travel source's checks see a wheel that does not turn.
//! - Input filter IC1F = IC2F = 1111 (§15.4.7): sampled at fDTS / 32 with
//!   N = 8, fDTS = fCK_INT = 72 MHz (CR1 CKD = 00, §15.4.1): a level must
//!   hold 8 × 32 / 72 MHz = 3.56 µs to count. The product's wheel (2400
//!   counts a turn on 250 mm, 3056 counts/m) makes a count every 327 µs at
//!   High 3 (1.01 m/s); the finest wheel the settings accept (20 000
//!   counts/m) one every 25 µs at 2 m/s: 7 times the filter. The strongest
//!   filter at CKD = 00 rejects the ringing of a long cable and the drum
//!   PWM's 20 kHz edges coupled into it.
//! - Encoder mode 3 (§15.3.12, SMCR SMS = 011, §15.4.3): every edge of both
//!   channels counts, up or down with the other channel's level: ×4
//!   quadrature, the wheel's 600 lines give 2400 counts a turn. CC1S = 01,
//!   CC2S = 01 (TI1FP1 on TI1, TI2FP2 on TI2), polarities non-inverted
//!   (CCER CC1P = CC2P = 0, §15.4.9; the settings' direction turns a
//!   reversed wheel around), ARR = 0xFFFF (§15.4.12: the counter wraps at
//!   2¹⁶; at reset ARR is 0 and the counter would not move).
//!
//! The counter is read once a control period (a wrap needs 65 536 counts
//! in 10 ms). No interrupt, no capture.

use super::*;

/// TIM4 and its pins as the reset left them: machine B's feeding-motor
/// STEP output (PB6, TIM4 CH1) and its direction pins, or machine A's
/// ground wheel (PB6/PB7, TIM4 CH1/CH2). The settings choose in `init`.
pub struct Tim4Pins {
    pub(super) tim: pac::TIM4,
    pub(super) pb6: stm32f1xx_hal::gpio::PB6,
    pub(super) pb7: stm32f1xx_hal::gpio::PB7,
    pub(super) pb14: stm32f1xx_hal::gpio::PB14,
    pub(super) pb15: stm32f1xx_hal::gpio::PB15,
    pub(super) crl: stm32f1xx_hal::gpio::Cr<'B', false>,
    pub(super) crh: stm32f1xx_hal::gpio::Cr<'B', true>,
}

/// The ground wheel's encoder: TIM4 counting PB6/PB7 (module docs).
pub struct GroundWheel {
    tim: pac::TIM4,
    _a: stm32f1xx_hal::gpio::PB6<Input<PullUp>>,
    _b: stm32f1xx_hal::gpio::PB7<Input<PullUp>>,
}

impl GroundWheel {
    /// Takes TIM4 and PB6/PB7 for the wheel: the pins, then the timer. (PB6
    /// leaves the boot's safe-state low for the pull-up; a count its rise
    /// may make comes before the first reading, which the odometer takes as
    /// its reference, not as ground.)
    pub(super) fn new(mut pins: Tim4Pins) -> Self {
        let a = pins.pb6.into_pull_up_input(&mut pins.crl);
        let b = pins.pb7.into_pull_up_input(&mut pins.crl);
        let tim = pins.tim;
        // TIM4's clock is on and the timer out of reset (`Timer::new` in
        // `init`, RCC_APB1ENR TIM4EN, §7.3.8). CR1 (§15.4.1) stays at its
        // reset value until CEN below: CKD = 00, counter stopped.
        // CCMR1 (§15.4.7, input): CC1S = 01, CC2S = 01, IC1F = IC2F = 1111.
        tim.ccmr1_input().write(|w| {
            w.cc1s()
                .ti1()
                .ic1f()
                .fdts_div32_n8()
                .cc2s()
                .ti2()
                .ic2f()
                .fdts_div32_n8()
        });
        // CCER (§15.4.9): both polarities non-inverted, captures off.
        tim.ccer().reset();
        // SMCR (§15.4.3): SMS = 011, encoder mode 3.
        tim.smcr().write(|w| w.sms().encoder_mode_3());
        // ARR (§15.4.12) before CEN: the counter wraps at 2¹⁶.
        tim.arr().write(|w| w.arr().set(u16::MAX));
        tim.cr1().write(|w| w.ckd().div1().cen().set_bit());
        Self { tim, _a: a, _b: b }
    }

    /// The counter now (TIMx_CNT, §15.4.10).
    pub fn count(&self) -> u16 {
        self.tim.cnt().read().cnt().bits()
    }
}

/// Whether TIM4 counts the ground wheel (SMCR SMS = 011, encoder mode 3,
/// §15.4.3), read from the timer itself: then it has no step output to
/// stop, PB6 is the wheel's input, and an update event (EGR UG, §15.4.6)
/// would reset its count (§15.3.12: the counter is the wheel's position).
/// A timer whose clock is off reads 0 (not the wheel's).
#[inline(always)]
pub(super) fn tim4_counts_the_wheel() -> bool {
    // SAFETY: a read of TIM4_SMCR, no side effect.
    unsafe { (*pac::TIM4::ptr()).smcr().read().sms().is_encoder_mode_3() }
}
