//! Core set-up: the debug freeze of the timers and watchdog, 8-byte aligned exception frames.

use super::*;

/// DBGMCU_CR (RM0008 §31.16.3), for a debug probe halting the core:
///
/// - DBG_SLEEP: the debug connection (RTT) stays alive in `wfi`.
/// - DBG_TIM1_STOP, DBG_TIM4_STOP: the step/PWM timers stop with the core.
///   TIM1 has complementary outputs, so stopping it also disables its
///   outputs "as if the MOE bit was reset" (§31.16.2), which with OSSI = 1
///   drives PA8 low; TIM4's PB6 holds its level, and no further step pulse
///   comes. Without these bits a halted core would leave the drum PWM (and
///   the steppers) running under no control.
/// - DBG_IWDG_STOP: the watchdog stops too, so that a breakpoint (or the
///   probe's halt on a HardFault) does not reset the board under the
///   debugger. The bits act only while a debugger holds the core halted; in
///   the field nothing halts it, so the watchdog keeps its full effect.
/// - TIM2 and TIM3 keep counting: TIM3 follows the machine's real motion,
///   and TIM2's time stays the machine's; a halt breaks the Hall
///   measurement either way (its overflows go unserviced).
pub(super) fn debug_freeze(dbgmcu: &pac::DBGMCU) {
    dbgmcu.cr().modify(|_, w| {
        w.dbg_sleep()
            .set_bit()
            .dbg_tim1_stop()
            .set_bit()
            .dbg_tim4_stop()
            .set_bit()
            .dbg_iwdg_stop()
            .set_bit()
    });
}

/// SCB_CCR STKALIGN (bit 9, PM0056 §4.4.7).
pub(super) const SCB_CCR_STKALIGN: u32 = 1 << 9;

/// Makes exception entry align the stacked frame, and so every handler's
/// stack, to 8 bytes (SCB_CCR STKALIGN), as the AAPCS the handlers are
/// compiled to requires. The F103's Cortex-M3 r1p1 (CPUID 0x411FC231)
/// resets the bit to 0 (Cortex-M3 TRM r1p1; ARM's ABI advisory IHI 0046B
/// asks startup code to set it), and neither cortex-m-rt nor RTIC sets it:
/// an interrupt that comes while SP is 4 mod 8 — inside the many functions
/// that push five registers before the rest of their frame — would run its
/// handler on a 4-byte aligned stack.
pub(super) fn align_exception_frames() {
    // SAFETY: a read-modify-write of SCB_CCR in `init` (interrupts off, no
    // exception active): the next exception entry uses the new alignment.
    unsafe {
        (*cortex_m::peripheral::SCB::PTR)
            .ccr
            .modify(|r| r | SCB_CCR_STKALIGN);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}
