//! The board layer: everything that touches pins, clocks and peripherals.
//!
//! Two boards implement the same interface, chosen by a cargo feature:
//!
//! | item | `board-stm32f103` (default) | `board-qemu` |
//! |---|---|---|
//! | clock | 72 MHz from an 8 MHz HSE | QEMU `netduino2`'s fixed 120 MHz (SysTick too) |
//! | touchscreen | USART1 PA9/PA10, 115200 8N1 | USART1 (emulated at the F205's address, real bytes) |
//! | Hall sensor | TIM2 CH1 input capture on PA0, 1 MHz | the simulated machine's edges |
//! | drum PWM | TIM1 CH1 on PA8, 20 kHz | a compare "register" read by the model |
//! | drum encoder | TIM3 encoder mode, PA6/PA7 | the simulated machine's counter |
//! | logs | defmt over RTT | defmt over semihosting |
//!
//! The control code above this module sees only [`Board`], [`DrumDrive`],
//! [`Sensors`], [`HallCapture`] and the free functions [`safe_state`],
//! [`drivers_enabled`], [`fatal`] and [`run_limit_ms`].

mod fault;
mod screen_tx;
pub use screen_tx::{kick as kick_screen_tx, HmiTx};

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
pub const HARDWARE: supervisor::drum::Hardware = supervisor::drum::Hardware {
    encoder_counts_per_drum_rev: DRUM_ENCODER_COUNTS_PER_REV,
    control_period_us: 10_000,
    pwm_arr: (72_000_000 / DRUM_PWM_HZ - 1) as u16,
};

/// Most Hall edges one [`Sensors::sample`] can return (the Hall sensor is
/// rated 1 kHz, so at most 10 in a 10 ms control period).
pub const MAX_EDGES_PER_SAMPLE: usize = 10;

/// One Hall edge from the capture interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HallEdge {
    /// Capture timestamp, 32-bit, in 1 µs ticks.
    pub stamp: u32,
    /// The capture hardware lost one or more edges before this one (TIM2's
    /// overcapture flag): the interval ending here is not a tooth period.
    pub after_lost: bool,
}

/// What the control task reads every period.
pub struct SensorSample {
    /// Drum encoder counter (free-running, wraps at 2¹⁶).
    pub drum_encoder: u16,
    /// Hall edges, as 32-bit capture timestamps in [`HALL_TIMER_HZ`] ticks, that
    /// did not come through the capture interrupt (only the QEMU board's
    /// simulated machine produces these; the real board's edges arrive in
    /// [`HallCapture::on_interrupt`]).
    pub hall_edges: heapless::Vec<u32, MAX_EDGES_PER_SAMPLE>,
    /// Machine A: the ground wheel's encoder counter (wraps at 2¹⁶), `None`
    /// where the board does not read one.
    pub ground_wheel: Option<u16>,
}

/// The settings store's two 1 KB pages (both boards).
pub const SETTINGS_FLASH_BYTES: u32 = 2 * 1024;
/// Erase unit of the settings flash (the F103's page).
pub const SETTINGS_PAGE_BYTES: u32 = 1024;

/// Errors of the settings flash, on either board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// Outside the settings pages, or misaligned.
    OutOfBounds,
    /// Programming a half-word that is not erased (the F103's PGERR).
    NotErased,
    /// The flash controller (real board) or the host file (QEMU) failed.
    Device,
}

impl embedded_storage::nor_flash::NorFlashError for FlashError {
    fn kind(&self) -> embedded_storage::nor_flash::NorFlashErrorKind {
        match self {
            Self::OutOfBounds => embedded_storage::nor_flash::NorFlashErrorKind::OutOfBounds,
            Self::NotErased | Self::Device => embedded_storage::nor_flash::NorFlashErrorKind::Other,
        }
    }
}

/// Checks an access of `len` bytes at `offset` against the pages a board's
/// settings flash reaches (`windows`) and the write unit `align` (1 for
/// reads, 2 for half-word programs); returns its end.
pub fn check_flash_access(
    offset: u32,
    len: usize,
    align: u32,
    windows: &[core::ops::Range<u32>],
) -> Result<u32, FlashError> {
    let len = u32::try_from(len).map_err(|_| FlashError::OutOfBounds)?;
    let end = offset.checked_add(len).ok_or(FlashError::OutOfBounds)?;
    let inside = windows.iter().any(|w| w.start <= offset && end <= w.end);
    if !inside || !offset.is_multiple_of(align) || !len.is_multiple_of(align) {
        return Err(FlashError::OutOfBounds);
    }
    Ok(end)
}

/// Checks an erase of the pages `[from, to)` against `windows`.
pub fn check_flash_erase(
    from: u32,
    to: u32,
    windows: &[core::ops::Range<u32>],
) -> Result<(), FlashError> {
    let inside = windows.iter().any(|w| w.start <= from && to <= w.end);
    if !from.is_multiple_of(SETTINGS_PAGE_BYTES)
        || !to.is_multiple_of(SETTINGS_PAGE_BYTES)
        || !inside
        || from > to
    {
        return Err(FlashError::OutOfBounds);
    }
    Ok(())
}

/// Firmware time in µs: the monotonic's milliseconds and SysTick's count
/// within the current one (a pending SysTick means a millisecond more).
pub fn now_us64() -> u64 {
    use cortex_m::peripheral::{SCB, SYST};
    loop {
        let ms = crate::uptime_ms();
        let reload = SYST::get_reload();
        let current = SYST::get_current();
        let pending = SCB::is_pendst_pending();
        if crate::uptime_ms() != ms {
            continue;
        }
        let into = reload.saturating_sub(current).saturating_mul(1000) / reload.saturating_add(1);
        let ms = u64::from(ms) + u64::from(pending);
        return ms * 1000 + u64::from(into);
    }
}
