//! The clock tree's start: the 8 MHz crystal (HSE) with a bounded wait.

use super::*;

/// HSE start-up bound, in cycles of the 8 MHz HSI the core runs on until
/// the PLL is up: 100 ms. The datasheet gives tSU(HSE) = 2 ms typical for an
/// 8 MHz crystal (STM32F103xB, "High-speed external user clock generated from
/// a crystal/ceramic resonator"); ST's own HAL waits 100 ms
/// (`HSE_STARTUP_TIMEOUT`). It must stay well below the watchdog's shortest
/// timeout (166 ms) so that the error is logged before the reset.
pub(super) const HSE_TIMEOUT_CYCLES: u32 = 800_000;
/// Cycles between two reads of HSERDY while waiting (125 µs at 8 MHz).
pub(super) const HSE_POLL_CYCLES: u32 = 1_000;

/// Switches the HSE on (RM0008 §7.3.1 RCC_CR HSEON, bit 16) and waits for
/// HSERDY (bit 17) at most [`HSE_TIMEOUT_CYCLES`]; false if it never came.
pub(super) fn start_hse(rcc: &pac::RCC) -> bool {
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    let mut waited = 0;
    while rcc.cr().read().hserdy().bit_is_clear() {
        if waited >= HSE_TIMEOUT_CYCLES {
            rcc.cr().modify(|_, w| w.hseon().clear_bit());
            return false;
        }
        cortex_m::asm::delay(HSE_POLL_CYCLES);
        waited += HSE_POLL_CYCLES;
    }
    true
}

/// Whether the clock security system saw the HSE fail (RM0008 §7.3.3
/// RCC_CIR CSSF, bit 7): the cause of an NMI.
pub fn clock_failed() -> bool {
    // SAFETY: a read of RCC_CIR, no side effect.
    unsafe { (*pac::RCC::ptr()).cir().read().cssf().bit_is_set() }
}
