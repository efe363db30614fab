//! The board layer: everything that touches pins, clocks and peripherals.
//!
//! Two boards implement the same interface, chosen by a cargo feature:
//!
//! | item | `board-stm32f103` (default) | `board-qemu` |
//! |---|---|---|
//! | clock | 72 MHz from an 8 MHz HSE | HSI; SysTick at QEMU's fixed 24 MHz |
//! | touchscreen | USART1 PA9/PA10, 115200 8N1 | USART1 (emulated, real bytes) |
//! | Hall sensor | TIM2 CH1 input capture on PA0, 1 MHz | the simulated machine's edges |
//! | drum PWM | TIM1 CH1 on PA8, 20 kHz | a compare "register" read by the model |
//! | drum encoder | TIM3 encoder mode, PA6/PA7 | the simulated machine's counter |
//! | logs | defmt over RTT | defmt over semihosting |
//!
//! The control code above this module sees only [`Board`], [`DrumDrive`],
//! [`Sensors`], [`HallCapture`] and the free functions [`safe_state`],
//! [`fatal`] and [`run_limit_ms`].

#[cfg(feature = "board-qemu")]
mod qemu;
#[cfg(feature = "board-qemu")]
pub use qemu::*;

#[cfg(not(feature = "board-qemu"))]
mod stm32f103;
#[cfg(not(feature = "board-qemu"))]
pub use stm32f103::*;

/// Drum PWM carrier frequency (TIM1). 20 kHz is above hearing and well within
/// what a BLDC driver's PWM speed input accepts.
pub const DRUM_PWM_HZ: u32 = 20_000;

/// Drum encoder counts per drum revolution: a 100-line encoder on the motor
/// shaft read in ×4 quadrature (400 counts per motor turn) behind the 118:1
/// gearbox.
pub const DRUM_ENCODER_COUNTS_PER_REV: u32 = 400 * 118;

/// The board facts the supervisor needs.
pub const HARDWARE: supervisor::control::Hardware = supervisor::control::Hardware {
    encoder_counts_per_drum_rev: DRUM_ENCODER_COUNTS_PER_REV,
    control_period_us: 10_000,
    pwm_arr: (72_000_000 / DRUM_PWM_HZ - 1) as u16,
};

/// Most Hall edges one [`Sensors::sample`] can return (the Hall sensor is
/// rated 1 kHz, so at most 10 in a 10 ms control period).
pub const MAX_EDGES_PER_SAMPLE: usize = 10;

/// What the control task reads every period.
pub struct SensorSample {
    /// Drum encoder counter (free-running, wraps at 2¹⁶).
    pub drum_encoder: u16,
    /// Hall edges, as 32-bit capture timestamps in [`HALL_TIMER_HZ`] ticks, that
    /// did not come through the capture interrupt (only the QEMU board's
    /// simulated machine produces these; the real board's edges arrive in
    /// [`HallCapture::on_interrupt`]).
    pub hall_edges: heapless::Vec<u32, MAX_EDGES_PER_SAMPLE>,
}
