//! The Cortex-M3 side: exception entry and return, the NVIC, SysTick's and
//! the SCB's registers, faults and lockup (ARMv7-M ARM B1.5, PM0056 §2.3 and
//! §4). Unicorn executes the instructions; everything an exception does is
//! done here, by the twin, between instructions.

/// Exception numbers.
pub mod exc {
    /// NMI.
    pub const NMI: u32 = 2;
    /// HardFault.
    pub const HARD_FAULT: u32 = 3;
    /// SVCall.
    pub const SVCALL: u32 = 11;
    /// PendSV.
    pub const PENDSV: u32 = 14;
    /// SysTick.
    pub const SYSTICK: u32 = 15;
    /// First external interrupt.
    pub const IRQ0: u32 = 16;
}

/// Number of external interrupts of the STM32F103 (RM0008 table 63).
pub const IRQS: usize = 68;

/// The NVIC and the SCB's exception state.
#[derive(Clone, Debug)]
pub struct Nvic {
    /// ISER bits.
    pub enabled: [u32; 3],
    /// Pending exceptions, by exception number.
    pub pending: u128,
    /// Active exceptions, innermost last.
    pub active: Vec<u32>,
    /// IPR bytes (as written; 4 bits implemented: the low nibble reads 0).
    pub ipr: [u8; IRQS],
    /// SHPR1..3 bytes for exceptions 4..15.
    pub shpr: [u8; 12],
    /// VTOR.
    pub vtor: u32,
    /// AIRCR (PRIGROUP only).
    pub aircr: u32,
    /// SCR.
    pub scr: u32,
    /// CCR. Resets to 0 on the F103's Cortex-M3 r1p1 (CPUID 0x411FC231):
    /// STKALIGN = 0, exception frames only 4-byte aligned (PM0056 §4.4.7:
    /// "Reset value: 0x0000 0000 (STM32F1 series)", 0x200 on the r2p0
    /// cores of the F2 and L1).
    pub ccr: u32,
    /// SHCSR.
    pub shcsr: u32,
    /// CFSR.
    pub cfsr: u32,
    /// HFSR.
    pub hfsr: u32,
    /// BFAR.
    pub bfar: u32,
    /// SYSRESETREQ written.
    pub reset_requested: bool,
}

impl Default for Nvic {
    fn default() -> Self {
        Self {
            enabled: [0; 3],
            pending: 0,
            active: Vec::new(),
            ipr: [0; IRQS],
            shpr: [0; 12],
            vtor: 0,
            aircr: 0,
            scr: 0,
            ccr: 0,
            shcsr: 0,
            cfsr: 0,
            hfsr: 0,
            bfar: 0,
            reset_requested: false,
        }
    }
}

/// CCR.STKALIGN (PM0056 §4.4.7): 8-byte aligned exception frames.
pub const CCR_STKALIGN: u32 = 1 << 9;

/// Priority bits implemented by the STM32F103: 4 (PM0056 §4.3.7).
pub const PRIO_MASK: u8 = 0xF0;

impl Nvic {
    /// The priority of exception `n` (lower is more urgent).
    pub fn priority(&self, n: u32) -> i32 {
        match n {
            exc::NMI => -2,
            exc::HARD_FAULT => -1,
            4..=15 => i32::from(self.shpr[(n - 4) as usize] & PRIO_MASK),
            _ => self
                .ipr
                .get((n - exc::IRQ0) as usize)
                .map_or(256, |p| i32::from(p & PRIO_MASK)),
        }
    }

    /// Whether exception `n` can be taken at all (an external interrupt
    /// must be enabled; MemManage, BusFault and UsageFault are never pended
    /// by the twin, they escalate to HardFault).
    pub fn enabled(&self, n: u32) -> bool {
        if n >= exc::IRQ0 {
            let i = n - exc::IRQ0;
            self.enabled
                .get((i / 32) as usize)
                .is_some_and(|w| w & (1 << (i % 32)) != 0)
        } else {
            true
        }
    }

    /// Sets exception `n` pending.
    pub fn set_pending(&mut self, n: u32) {
        self.pending |= 1u128 << n;
    }

    /// External interrupt `irq` pending.
    pub fn pend_irq(&mut self, irq: u32) {
        self.set_pending(exc::IRQ0 + irq);
    }

    /// Whether exception `n` is active.
    pub fn is_active(&self, n: u32) -> bool {
        self.active.contains(&n)
    }

    /// A level-sensitive line asserted: pending unless already active
    /// (it pends again when its handler returns with the line still high).
    pub fn line(&mut self, irq: u32) {
        let n = exc::IRQ0 + irq;
        if !self.is_active(n) {
            self.set_pending(n);
        }
    }

    /// The priority of what runs now, before masks (256 = thread mode).
    pub fn active_priority(&self) -> i32 {
        self.active
            .iter()
            .map(|&n| self.priority(n))
            .min()
            .unwrap_or(256)
    }

    /// Execution priority with PRIMASK, FAULTMASK and BASEPRI applied.
    pub fn execution_priority(&self, primask: bool, faultmask: bool, basepri: u8) -> i32 {
        let mut p = self.active_priority();
        let bp = basepri & PRIO_MASK;
        if bp != 0 {
            p = p.min(i32::from(bp));
        }
        if primask {
            p = p.min(0);
        }
        if faultmask {
            p = p.min(-1);
        }
        p
    }

    /// The most urgent pending, enabled exception: (number, priority).
    pub fn top_pending(&self) -> Option<(u32, i32)> {
        let mut best: Option<(u32, i32)> = None;
        let mut bits = self.pending;
        while bits != 0 {
            let n = bits.trailing_zeros();
            bits &= bits - 1;
            if !self.enabled(n) {
                continue;
            }
            let p = self.priority(n);
            if best.is_none_or(|(_, bp)| p < bp) {
                best = Some((n, p));
            }
        }
        best
    }

    /// Reads a System Control Space register (0xE000_E000..0xE000_F000),
    /// SysTick excluded.
    pub fn read(&self, a: u32) -> u32 {
        match a {
            0xE000_E100..=0xE000_E108 => self.enabled[((a - 0xE000_E100) / 4) as usize],
            0xE000_E180..=0xE000_E188 => self.enabled[((a - 0xE000_E180) / 4) as usize],
            0xE000_E200..=0xE000_E208 => {
                let w = (a - 0xE000_E200) / 4;
                (self.pending >> (16 + 32 * w)) as u32
            }
            0xE000_E280..=0xE000_E288 => {
                let w = (a - 0xE000_E280) / 4;
                (self.pending >> (16 + 32 * w)) as u32
            }
            0xE000_E300..=0xE000_E308 => {
                let w = (a - 0xE000_E300) / 4;
                let mut v = 0;
                for &n in &self.active {
                    if n >= 16 && (n - 16) / 32 == w {
                        v |= 1 << ((n - 16) % 32);
                    }
                }
                v
            }
            0xE000_E400..=0xE000_E4FF => {
                let i = (a - 0xE000_E400) as usize;
                let mut v = 0;
                for k in 0..4 {
                    v |= u32::from(self.ipr.get(i + k).map_or(0, |p| p & PRIO_MASK)) << (8 * k);
                }
                v
            }
            0xE000_ED00 => 0x411F_C231, // CPUID: Cortex-M3 r1p1
            0xE000_ED04 => {
                let active = self.active.last().copied().unwrap_or(0);
                let pend = self.top_pending().map_or(0, |(n, _)| n);
                let mut v = active | (pend << 12);
                if self.pending >> 16 != 0 {
                    v |= 1 << 22;
                }
                if self.pending & (1 << exc::SYSTICK) != 0 {
                    v |= 1 << 26;
                }
                if self.pending & (1 << exc::PENDSV) != 0 {
                    v |= 1 << 28;
                }
                if self.active.len() <= 1 {
                    v |= 1 << 11; // RETTOBASE
                }
                v
            }
            0xE000_ED08 => self.vtor,
            0xE000_ED0C => 0xFA05_0000 | (self.aircr & 0x700),
            0xE000_ED10 => self.scr,
            0xE000_ED14 => self.ccr,
            0xE000_ED18..=0xE000_ED20 => {
                let i = (a - 0xE000_ED18) as usize;
                let mut v = 0;
                for k in 0..4 {
                    v |= u32::from(self.shpr[i + k] & PRIO_MASK) << (8 * k);
                }
                v
            }
            0xE000_ED24 => self.shcsr,
            0xE000_ED28 => self.cfsr,
            0xE000_ED2C => self.hfsr,
            0xE000_ED38 => self.bfar,
            _ => 0,
        }
    }

    /// Writes a System Control Space register with `size` bytes.
    pub fn write(&mut self, a: u32, v: u32, size: usize) {
        match a {
            0xE000_E100..=0xE000_E108 => self.enabled[((a - 0xE000_E100) / 4) as usize] |= v,
            0xE000_E180..=0xE000_E188 => self.enabled[((a - 0xE000_E180) / 4) as usize] &= !v,
            0xE000_E200..=0xE000_E208 => {
                let w = (a - 0xE000_E200) / 4;
                self.pending |= u128::from(v) << (16 + 32 * w);
            }
            0xE000_E280..=0xE000_E288 => {
                let w = (a - 0xE000_E280) / 4;
                self.pending &= !(u128::from(v) << (16 + 32 * w));
            }
            0xE000_E400..=0xE000_E4FF => {
                let i = (a - 0xE000_E400) as usize;
                for k in 0..size {
                    if let Some(p) = self.ipr.get_mut(i + k) {
                        *p = (v >> (8 * k)) as u8 & PRIO_MASK;
                    }
                }
            }
            0xE000_EF00 => self.pend_irq(v & 0x1FF),
            0xE000_ED04 => {
                if v & (1 << 31) != 0 {
                    self.set_pending(exc::NMI);
                }
                if v & (1 << 28) != 0 {
                    self.set_pending(exc::PENDSV);
                }
                if v & (1 << 27) != 0 {
                    self.pending &= !(1 << exc::PENDSV);
                }
                if v & (1 << 26) != 0 {
                    self.set_pending(exc::SYSTICK);
                }
                if v & (1 << 25) != 0 {
                    self.pending &= !(1 << exc::SYSTICK);
                }
            }
            0xE000_ED08 => self.vtor = v & 0x3FFF_FF80,
            0xE000_ED0C if v >> 16 == 0x05FA => {
                self.aircr = v & 0x700;
                if v & 4 != 0 {
                    self.reset_requested = true;
                }
            }
            0xE000_ED10 => self.scr = v & 0x16,
            0xE000_ED14 => self.ccr = v & 0x31B,
            0xE000_ED18..=0xE000_ED23 => {
                let i = (a - 0xE000_ED18) as usize;
                for k in 0..size {
                    if let Some(p) = self.shpr.get_mut(i + k) {
                        *p = (v >> (8 * k)) as u8 & PRIO_MASK;
                    }
                }
            }
            0xE000_ED24 => self.shcsr = v,
            0xE000_ED28 => self.cfsr &= !v,
            0xE000_ED2C => self.hfsr &= !v,
            _ => {}
        }
    }
}
