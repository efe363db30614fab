//! The Hall capture stand-in (TIM2): the edges come from the simulated
//! machine.

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// Stand-in for TIM2's counter, extended to 32 bits (1 MHz).
pub(super) static HALL_TIMER_NOW: AtomicU32 = AtomicU32::new(0);

/// Hall capture: edges come from [`Sensors::sample`](super::Sensors::sample) on this board.
pub struct HallCapture;

impl HallCapture {
    /// TIM2 never interrupts under QEMU.
    pub fn on_interrupt(&mut self) -> Option<crate::board::HallEdge> {
        None
    }

    /// The capture timer's time, 1 MHz, extended to 32 bits.
    pub fn now(&self) -> u32 {
        HALL_TIMER_NOW.load(Relaxed)
    }
}
