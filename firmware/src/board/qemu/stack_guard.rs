//! The guard below RAM: a stack overflow faults on this machine too.
//!
//! With flip-link the stack sits at the bottom of RAM, so an overflow runs
//! below 0x2000_0000. On the real board an access there is a bus fault, and
//! the HardFault entry reports the overflow (`board/fault.rs`). QEMU's
//! `netduino2` is flagged to ignore bus errors
//! (`ignore_memory_transaction_failures`): a store below RAM is dropped and
//! a load reads zero, and only an exception entry that cannot push its frame
//! faults. Measured without the guard: an overflowing control task ran on
//! 0.9 MB below RAM until the next SysTick; with the interrupts off, as in
//! `init`, the run hung. One MPU region (ARMv7-M PMSA) makes everything from
//! 0x1000_0000 up to RAM no-access: the first store below RAM raises a
//! MemManage fault, which escalates to HardFault (its own handler is not
//! enabled), and the same entry reports the overflow.

use cortex_m::peripheral::MPU;

/// The guard region: 256 MB below RAM (0x1000_0000–0x1FFF_FFFF; nothing
/// the firmware uses lies there), aligned to its size as PMSAv7 requires.
const GUARD_BASE: u32 = 0x1000_0000;
/// RASR.SIZE: the region is 2^(SIZE + 1) bytes.
const GUARD_SIZE_FIELD: u32 = 27;
/// RASR: XN (no instruction fetch), AP = 0b000 (no access), SIZE, ENABLE.
const GUARD_RASR: u32 = (1 << 28) | (GUARD_SIZE_FIELD << 1) | 1;
/// MPU_CTRL: PRIVDEFENA (the default memory map everywhere else), ENABLE.
/// HFNMIENA stays clear: the fault handlers run without the MPU.
const MPU_CTRL_ON: u32 = (1 << 2) | 1;

/// Sets up the guard. Called first in `init`.
pub fn enable() {
    // SAFETY: the MPU's registers are always mapped; nothing else in the
    // firmware uses the MPU (RTIC does not), and `init` runs once, with
    // interrupts off. The region only forbids addresses outside memory.
    unsafe {
        let mpu = &*MPU::PTR;
        mpu.rnr.write(0);
        mpu.rbar.write(GUARD_BASE);
        mpu.rasr.write(GUARD_RASR);
        mpu.ctrl.write(MPU_CTRL_ON);
    }
    // The new map applies to the accesses after this.
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}
