//! Small Thumb-2 test programs for the twin's models (`tests/tests/twin_silicon.rs`):
//! a handful of Cortex-M3 instructions, encoded as the ARMv7-M Architecture
//! Reference Manual (ARM DDI 0403, chapter A7) gives them, a vector table and
//! labels. Enough to poke registers in a given order and keep what the CPU
//! read in RAM, where the test reads it back; no toolchain needed.

use std::collections::HashMap;

/// Start of the flash, where the vector table goes (RM0008 §3.4, boot from
/// main flash).
pub const FLASH: u32 = 0x0800_0000;
/// Entries of the vector table: the 16 system exceptions and the F103's 68
/// interrupts (RM0008 table 63), rounded up.
const VECTORS: usize = 96;
/// Where the code starts (after the vector table).
pub const CODE: u32 = FLASH + 4 * VECTORS as u32;

/// A core register (r0..r12, SP = 13, LR = 14).
pub type Reg = u8;
/// The stack pointer.
pub const SP: Reg = 13;
/// The link register.
pub const LR: Reg = 14;

/// A branch condition (A7.3).
#[derive(Clone, Copy, Debug)]
pub enum Cond {
    /// Z set.
    Eq = 0,
    /// Z clear.
    Ne = 1,
    /// C set (unsigned >=).
    Hs = 2,
    /// C clear (unsigned <).
    Lo = 3,
}

#[derive(Clone, Copy, Debug)]
enum Fixup {
    /// B<c> T1: 8-bit offset.
    Cond,
    /// B T2: 11-bit offset.
    Always,
}

/// A test program: code, labels, and which label each exception vector
/// points at.
#[derive(Default)]
pub struct Program {
    code: Vec<u16>,
    labels: HashMap<&'static str, usize>,
    fixups: Vec<(usize, Fixup, &'static str)>,
    vectors: Vec<(u32, &'static str)>,
}

impl Program {
    /// An empty program (its entry point is the label `"reset"`).
    pub fn new() -> Self {
        Self::default()
    }

    fn h(&mut self, hw: u16) -> &mut Self {
        self.code.push(hw);
        self
    }

    fn w(&mut self, first: u16, second: u16) -> &mut Self {
        self.h(first).h(second)
    }

    /// Places `name` here (a word-aligned address: a NOP pads).
    pub fn label(&mut self, name: &'static str) -> &mut Self {
        if !self.code.len().is_multiple_of(2) {
            self.nop();
        }
        self.labels.insert(name, self.code.len());
        self
    }

    /// Exception number `n` (16 + IRQ for an interrupt) enters at `label`.
    pub fn vector(&mut self, n: u32, label: &'static str) -> &mut Self {
        self.vectors.push((n, label));
        self
    }

    /// MOVW rd, #imm16 (T3).
    pub fn movw(&mut self, rd: Reg, imm: u16) -> &mut Self {
        let imm = u32::from(imm);
        let first = 0xF240 | ((imm >> 1) & 0x400) | ((imm >> 12) & 0xF);
        let second = ((imm << 4) & 0x7000) | (u32::from(rd) << 8) | (imm & 0xFF);
        self.w(first as u16, second as u16)
    }

    /// MOVT rd, #imm16 (T1).
    pub fn movt(&mut self, rd: Reg, imm: u16) -> &mut Self {
        let imm = u32::from(imm);
        let first = 0xF2C0 | ((imm >> 1) & 0x400) | ((imm >> 12) & 0xF);
        let second = ((imm << 4) & 0x7000) | (u32::from(rd) << 8) | (imm & 0xFF);
        self.w(first as u16, second as u16)
    }

    /// rd = value (MOVW, and MOVT when the upper half is not 0).
    pub fn li(&mut self, rd: Reg, value: u32) -> &mut Self {
        self.movw(rd, value as u16);
        if value >> 16 != 0 {
            self.movt(rd, (value >> 16) as u16);
        }
        self
    }

    /// LDR.W rt, [rn, #imm12] (T3).
    pub fn ldr(&mut self, rt: Reg, rn: Reg, off: u16) -> &mut Self {
        self.w(
            0xF8D0 | u16::from(rn),
            (u16::from(rt) << 12) | (off & 0xFFF),
        )
    }

    /// STR.W rt, [rn, #imm12] (T3).
    pub fn str(&mut self, rt: Reg, rn: Reg, off: u16) -> &mut Self {
        self.w(
            0xF8C0 | u16::from(rn),
            (u16::from(rt) << 12) | (off & 0xFFF),
        )
    }

    /// rt = the word at `addr` (r12 holds the address).
    pub fn load(&mut self, rt: Reg, addr: u32) -> &mut Self {
        self.li(12, addr).ldr(rt, 12, 0)
    }

    /// The word at `addr` = `value` (r11 holds the value, r12 the address).
    pub fn store(&mut self, addr: u32, value: u32) -> &mut Self {
        self.li(11, value).li(12, addr).str(11, 12, 0)
    }

    /// MOV rd, rm (T1: any registers, SP included).
    pub fn mov(&mut self, rd: Reg, rm: Reg) -> &mut Self {
        self.h(0x4600 | (u16::from(rd & 8) << 4) | (u16::from(rm) << 3) | u16::from(rd & 7))
    }

    /// ADDS rd, #imm8 (T2, r0..r7).
    pub fn addi(&mut self, rd: Reg, imm: u8) -> &mut Self {
        self.h(0x3000 | (u16::from(rd) << 8) | u16::from(imm))
    }

    /// SUBS rd, #imm8 (T2, r0..r7).
    pub fn subi(&mut self, rd: Reg, imm: u8) -> &mut Self {
        self.h(0x3800 | (u16::from(rd) << 8) | u16::from(imm))
    }

    /// SUBS rd, rn, rm (T1, r0..r7).
    pub fn sub(&mut self, rd: Reg, rn: Reg, rm: Reg) -> &mut Self {
        self.h(0x1A00 | (u16::from(rm) << 6) | (u16::from(rn) << 3) | u16::from(rd))
    }

    /// ORR.W rd, rn, rm (T2).
    pub fn orr(&mut self, rd: Reg, rn: Reg, rm: Reg) -> &mut Self {
        self.w(0xEA40 | u16::from(rn), (u16::from(rd) << 8) | u16::from(rm))
    }

    /// TST rn, rm (T1, r0..r7).
    pub fn tst(&mut self, rn: Reg, rm: Reg) -> &mut Self {
        self.h(0x4200 | (u16::from(rm) << 3) | u16::from(rn))
    }

    /// CMP rn, rm (T1, r0..r7).
    pub fn cmp(&mut self, rn: Reg, rm: Reg) -> &mut Self {
        self.h(0x4280 | (u16::from(rm) << 3) | u16::from(rn))
    }

    /// B<cond> label (T1, within ±256 bytes).
    pub fn b_if(&mut self, cond: Cond, label: &'static str) -> &mut Self {
        self.fixups.push((self.code.len(), Fixup::Cond, label));
        self.h(0xD000 | ((cond as u16) << 8))
    }

    /// B label (T2, within ±2 KB).
    pub fn b(&mut self, label: &'static str) -> &mut Self {
        self.fixups.push((self.code.len(), Fixup::Always, label));
        self.h(0xE000)
    }

    /// BX LR.
    pub fn ret(&mut self) -> &mut Self {
        self.h(0x4770)
    }

    /// B . (the program's end: the core spins here).
    pub fn halt(&mut self) -> &mut Self {
        self.h(0xE7FE)
    }

    /// NOP.
    pub fn nop(&mut self) -> &mut Self {
        self.h(0xBF00)
    }

    /// CPSIE i (PRIMASK = 0).
    pub fn cpsie(&mut self) -> &mut Self {
        self.h(0xB662)
    }

    /// DSB.
    pub fn dsb(&mut self) -> &mut Self {
        self.w(0xF3BF, 0x8F4F)
    }

    /// ISB.
    pub fn isb(&mut self) -> &mut Self {
        self.w(0xF3BF, 0x8F6F)
    }

    /// The flash image: the vector table (initial SP `sp`, the reset vector
    /// at `"reset"`, the others at their labels or at a `B .` after the
    /// code), then the code.
    ///
    /// # Panics
    /// On a label used but never placed, or a branch out of range (a test
    /// program's own mistake).
    pub fn build(&mut self, sp: u32) -> Vec<u8> {
        self.label("__unused");
        self.halt();
        for &(at, kind, label) in &self.fixups {
            let target = *self
                .labels
                .get(label)
                .unwrap_or_else(|| panic!("label {label} not placed"));
            // The PC reads as the instruction's address + 4.
            let off = (target as i64 - at as i64 - 2) * 2;
            self.code[at] |= match kind {
                Fixup::Cond => {
                    assert!((-256..256).contains(&off), "branch to {label} too far");
                    ((off >> 1) & 0xFF) as u16
                }
                Fixup::Always => {
                    assert!((-2048..2048).contains(&off), "branch to {label} too far");
                    ((off >> 1) & 0x7FF) as u16
                }
            };
        }
        let addr = |label: &str| {
            let at = self
                .labels
                .get(label)
                .unwrap_or_else(|| panic!("label {label} not placed"));
            (CODE + 2 * *at as u32) | 1
        };
        let mut table = vec![addr("__unused"); VECTORS];
        table[0] = sp;
        table[1] = addr("reset");
        for &(n, label) in &self.vectors {
            table[n as usize] = addr(label);
        }
        let mut image: Vec<u8> = table.iter().flat_map(|w| w.to_le_bytes()).collect();
        image.extend(self.code.iter().flat_map(|h| h.to_le_bytes()));
        image
    }
}
