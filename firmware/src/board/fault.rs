//! The fatal exception entries, shared by both boards: HardFault, NMI and
//! every exception or interrupt without a handler of its own. They make the
//! outputs safe on a fresh stack before anything else.

use cortex_m::peripheral::scb::VectActive;

// The fatal exception entries: HardFault, NMI and every exception or
// interrupt without a handler of its own (cortex-m-rt's `DefaultHandler`,
// which the PAC's unused interrupt vectors and the unused core exceptions
// point to). They replace cortex-m-rt's (link.x: `PROVIDE(HardFault =
// HardFault_)`, `PROVIDE(NonMaskableInt = DefaultHandler)`, `PROVIDE(
// DefaultHandler = DefaultHandler_)`, which a global definition overrides;
// `#[exception]` is not used for them because its HardFault trampoline
// and the Rust handlers it calls push onto the stack first).
//
// With flip-link the stack sits at the bottom of RAM, so a stack overflow
// faults with SP below RAM: the exception entry's own stacking fails, and
// any push in the handler would fault again (a lockup, outputs as they
// were, until the watchdog). So each entry does, without touching the
// stack: r1 = which exception, r0 = the stack pointer of the interrupted
// code (EXC_RETURN bit 2 picks MSP or PSP), MSP = `_stack_start` (the top
// of the stack region, from cortex-m-rt's link.x, 8-byte aligned), then a
// branch to `fatal_exception`, which drives the outputs safe before
// anything else. Nothing returns: the stack being reused held only frames
// that will never run again; the statics and the RTT buffer lie above it.
core::arch::global_asm!(
    ".section .text.fatal_entries, \"ax\"",
    ".global HardFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "    movs r1, #{hard}",
    "    b 1f",
    ".global NonMaskableInt",
    ".type NonMaskableInt,%function",
    ".thumb_func",
    "NonMaskableInt:",
    "    movs r1, #{nmi}",
    "    b 1f",
    ".global DefaultHandler",
    ".type DefaultHandler,%function",
    ".thumb_func",
    "DefaultHandler:",
    "    movs r1, #{other}",
    "1:",
    "    mov r0, lr",
    "    tst r0, #4",
    "    ite eq",
    "    mrseq r0, msp",
    "    mrsne r0, psp",
    "    ldr r2, =_stack_start",
    "    bic r2, r2, #7",
    "    msr msp, r2",
    "    b {entry}",
    ".ltorg",
    hard = const FAULT_HARD,
    nmi = const FAULT_NMI,
    other = const FAULT_OTHER,
    entry = sym fatal_exception,
);

/// Which entry of the asm above was taken: HardFault.
const FAULT_HARD: u32 = 0;
/// NonMaskableInt.
const FAULT_NMI: u32 = 1;
/// DefaultHandler (an unused interrupt or core exception).
const FAULT_OTHER: u32 = 2;

/// The fatal exceptions, on a fresh stack: outputs safe first, then one log
/// line, then the board's end state (the real board waits for the
/// watchdog; QEMU exits with a failure code).
///
/// - HardFault: the faulting PC from the exception frame, if the frame lies
///   inside the stack region; otherwise the stack had overflowed.
/// - NMI: the clock security system (the HSE failed: SYSCLK is back on the
///   8 MHz HSI), or another NMI source.
/// - Anything else: an interrupt or exception the firmware never enabled.
///
/// # Safety
///
/// Only entered from the asm entries above, in handler mode, never returns.
unsafe extern "C" fn fatal_exception(sp: u32, which: u32) -> ! {
    super::safe_state();
    cortex_m::interrupt::disable();
    extern "C" {
        static _stack_start: u32;
        static _stack_end: u32;
    }
    match which {
        FAULT_HARD => {
            let bottom = core::ptr::addr_of!(_stack_end) as u32;
            let top = core::ptr::addr_of!(_stack_start) as u32;
            // The exception frame: r0-r3, r12, lr, pc, xPSR (8 words).
            if sp >= bottom
                && sp.checked_add(32).is_some_and(|end| end <= top)
                && sp.is_multiple_of(4)
            {
                // SAFETY: a word inside the stack region (checked above).
                let pc = unsafe { core::ptr::read_volatile((sp + 24) as *const u32) };
                defmt::error!("HardFault at pc {=u32:#x}: outputs off", pc);
            } else {
                defmt::error!(
                    "HardFault with sp {=u32:#x} outside the stack: stack overflow, outputs off",
                    sp
                );
            }
        }
        FAULT_NMI => {
            if super::clock_failed() {
                defmt::error!("clock security: the 8 MHz crystal (HSE) failed: outputs off");
            } else {
                defmt::error!("NMI: outputs off");
            }
        }
        _ => {
            // The exception number of the active exception (IRQn + 16).
            let irq: i32 = match cortex_m::peripheral::SCB::vect_active() {
                VectActive::Interrupt { irqn } => i32::from(irqn),
                VectActive::Exception(e) => i32::from(e.irqn()),
                VectActive::ThreadMode => -16,
            };
            defmt::error!(
                "unexpected exception {=u32} (IRQ {=i32}): outputs off",
                irq.saturating_add(16).unsigned_abs(),
                irq
            );
        }
    }
    super::fatal()
}
