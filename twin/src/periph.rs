//! Peripheral models of the STM32F103 (medium density), written from the
//! reference manual RM0008 (section numbers in the comments) and the
//! Cortex-M3 generic user guide (PM0056) for the system control space.
//!
//! Every model is lazy: its state is brought up to date ("advanced") to the
//! current time when the CPU touches a register or when the scheduler reaches
//! the model's next event. Time is counted in [`Ticks`] of 1/72 MHz.

use std::collections::VecDeque;

/// Time in ticks of 1/72 MHz (the twin's time base, see docs/twin.md).
pub type Ticks = u64;
/// Ticks per second.
pub const TICKS_PER_S: u64 = 72_000_000;
/// HSI and HSE (the board's 8 MHz crystal), Hz.
pub const HSI_HZ: u64 = 8_000_000;
/// The board's crystal, Hz.
pub const HSE_HZ: u64 = 8_000_000;
/// "Never" for event times.
pub const NEVER: Ticks = u64::MAX;

/// Interrupt lines of the STM32F103 used by the models (RM0008 table 63).
pub mod irq {
    /// EXTI line 0.
    pub const EXTI0: u32 = 6;
    /// ADC1_2.
    pub const ADC1_2: u32 = 18;
    /// TIM1 update.
    pub const TIM1_UP: u32 = 25;
    /// TIM1 capture compare.
    pub const TIM1_CC: u32 = 27;
    /// TIM2.
    pub const TIM2: u32 = 28;
    /// TIM3.
    pub const TIM3: u32 = 29;
    /// TIM4.
    pub const TIM4: u32 = 30;
    /// USART1.
    pub const USART1: u32 = 37;
    /// USART2.
    pub const USART2: u32 = 38;
    /// EXTI lines 15..10.
    pub const EXTI15_10: u32 = 40;
    /// RCC (clock security is on NMI).
    pub const RCC: u32 = 5;
    /// FLASH.
    pub const FLASH: u32 = 4;
}

/// Level of a pin as a scope would see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Driven high (push-pull output at 1).
    High,
    /// Driven low.
    Low,
    /// Not driven by the MCU: floating input, analog, disabled AF output,
    /// or an open-drain output at 1.
    HiZ,
    /// Input with the internal pull-up.
    PullUp,
    /// Input with the internal pull-down.
    PullDown,
}

/// What the outside world does to an input pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum External {
    /// Nothing connected.
    #[default]
    Open,
    /// Driven (or switched) high.
    High,
    /// Driven (or switched) low.
    Low,
}

/// The clock tree as configured in RCC (RM0008 §7.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Clocks {
    /// SYSCLK = HCLK (AHB prescaler applied), Hz.
    pub hclk: u64,
    /// SYSCLK before the AHB prescaler, Hz.
    pub sysclk: u64,
    /// APB1, Hz.
    pub pclk1: u64,
    /// APB2, Hz.
    pub pclk2: u64,
    /// TIM2..TIM4 kernel clock (×2 when the APB1 prescaler is not 1), Hz.
    pub tim_apb1: u64,
    /// TIM1 kernel clock, Hz.
    pub tim_apb2: u64,
}

fn ticks_per(hz: u64) -> u64 {
    (TICKS_PER_S / hz.max(1)).max(1)
}

// ---------------------------------------------------------------------------
// RCC (RM0008 §7.3)
// ---------------------------------------------------------------------------

/// Reset and clock control.
#[derive(Clone, Debug)]
pub struct Rcc {
    /// CR.
    pub cr: u32,
    /// CFGR (SWS is computed).
    pub cfgr: u32,
    /// CIR.
    pub cir: u32,
    /// APB2RSTR, APB1RSTR, AHBENR, APB2ENR, APB1ENR, BDCR.
    pub apb2rstr: u32,
    /// APB1RSTR.
    pub apb1rstr: u32,
    /// AHBENR.
    pub ahbenr: u32,
    /// APB2ENR.
    pub apb2enr: u32,
    /// APB1ENR.
    pub apb1enr: u32,
    /// BDCR.
    pub bdcr: u32,
    /// CSR (reset flags kept across system resets).
    pub csr: u32,
    /// The crystal never starts (a dead or missing HSE).
    pub hse_dead: bool,
    /// When HSEON was set.
    hse_on_at: Option<Ticks>,
    /// When PLLON was set.
    pll_on_at: Option<Ticks>,
}

/// HSE start-up time assumed for a good crystal (datasheet tSU(HSE) ≈ 2 ms).
const HSE_STARTUP: Ticks = 2 * TICKS_PER_S / 1000;
/// PLL lock time (datasheet tLOCK ≤ 200 µs).
const PLL_LOCK: Ticks = 200 * TICKS_PER_S / 1_000_000;
/// LSI start-up time, the maximum of the datasheet (DS5319 table 25,
/// tSU(LSI) ≤ 85 µs): LSIRDY is set this long after the LSI is switched on.
pub const LSI_STARTUP: Ticks = 85 * TICKS_PER_S / 1_000_000;

/// RCC_CR bits (RM0008 §7.3.1).
const CR_HSEON: u32 = 1 << 16;
const CR_HSEBYP: u32 = 1 << 18;

impl Rcc {
    fn new(csr: u32, hse_dead: bool) -> Self {
        Self {
            cr: 0x0000_0083,
            cfgr: 0,
            cir: 0,
            apb2rstr: 0,
            apb1rstr: 0,
            ahbenr: 0x14,
            apb2enr: 0,
            apb1enr: 0,
            bdcr: 0,
            csr: csr | 0x0C00_0000, // NRSTF|PORRSTF at power-on
            hse_dead,
            hse_on_at: None,
            pll_on_at: None,
        }
    }

    /// HSERDY: the crystal has started. With HSEBYP the oscillator is
    /// bypassed and OSC_IN must carry an external clock; the board has a
    /// crystal there, so nothing ever comes (RM0008 §7.2.1).
    fn hse_ready(&self, now: Ticks) -> bool {
        !self.hse_dead
            && self.cr & CR_HSEBYP == 0
            && self.hse_on_at.is_some_and(|t| now >= t + HSE_STARTUP)
    }

    fn pll_ready(&self, now: Ticks) -> bool {
        let src_ok = if self.cfgr & (1 << 16) != 0 {
            self.hse_ready(now)
        } else {
            true
        };
        src_ok && self.pll_on_at.is_some_and(|t| now >= t + PLL_LOCK)
    }

    fn cr_read(&self, now: Ticks) -> u32 {
        let mut v = self.cr & !((1 << 1) | (1 << 17) | (1 << 25));
        if self.cr & 1 != 0 {
            v |= 1 << 1;
        }
        if self.cr & (1 << 16) != 0 && self.hse_ready(now) {
            v |= 1 << 17;
        }
        if self.cr & (1 << 24) != 0 && self.pll_ready(now) {
            v |= 1 << 25;
        }
        v
    }

    /// SWS: the switch takes effect only onto a ready source.
    fn sws(&self) -> u32 {
        (self.cfgr >> 2) & 3
    }

    /// The clock tree in force.
    pub fn clocks(&self) -> Clocks {
        let sysclk = match self.sws() {
            1 => HSE_HZ,
            2 => {
                let src = if self.cfgr & (1 << 16) != 0 {
                    if self.cfgr & (1 << 17) != 0 {
                        HSE_HZ / 2
                    } else {
                        HSE_HZ
                    }
                } else {
                    HSI_HZ / 2
                };
                let mul = u64::from(((self.cfgr >> 18) & 0xF) + 2).min(16);
                src * mul
            }
            _ => HSI_HZ,
        };
        let hpre = (self.cfgr >> 4) & 0xF;
        let hdiv = if hpre < 8 {
            1
        } else {
            [2, 4, 8, 16, 64, 128, 256, 512][(hpre - 8) as usize]
        };
        let hclk = sysclk / hdiv;
        let apb = |bits: u32| if bits < 4 { 1 } else { 1 << (bits - 3) };
        let d1 = apb((self.cfgr >> 8) & 7);
        let d2 = apb((self.cfgr >> 11) & 7);
        let pclk1 = hclk / d1;
        let pclk2 = hclk / d2;
        Clocks {
            hclk,
            sysclk,
            pclk1,
            pclk2,
            tim_apb1: if d1 == 1 { pclk1 } else { pclk1 * 2 },
            tim_apb2: if d2 == 1 { pclk2 } else { pclk2 * 2 },
        }
    }

    fn update_switch(&mut self, now: Ticks) {
        let sw = self.cfgr & 3;
        let ready = match sw {
            0 => true,
            1 => self.hse_ready(now),
            2 => self.pll_ready(now),
            _ => false,
        };
        if ready {
            self.cfgr = (self.cfgr & !0xC) | (sw << 2);
        }
    }

    fn read(&mut self, off: u32, now: Ticks) -> u32 {
        self.update_switch(now);
        match off {
            0x00 => self.cr_read(now),
            0x04 => self.cfgr,
            0x08 => self.cir,
            0x0C => self.apb2rstr,
            0x10 => self.apb1rstr,
            0x14 => self.ahbenr,
            0x18 => self.apb2enr,
            0x1C => self.apb1enr,
            0x20 => self.bdcr,
            // LSIRDY is added by the bus (the IWDG also starts the LSI).
            0x24 => self.csr & !0x2,
            _ => 0,
        }
    }

    fn write(&mut self, off: u32, v: u32, now: Ticks) {
        match off {
            0x00 => {
                // HSION, HSITRIM, HSEON, HSEBYP, CSSON, PLLON; HSEBYP "can be
                // written only if the HSE oscillator is disabled" (§7.3.1).
                let old = self.cr;
                let rw = if old & CR_HSEON == 0 {
                    0x010D_00F9
                } else {
                    0x0109_00F9
                };
                self.cr = (self.cr & !rw) | (v & rw);
                if self.cr & (1 << 16) != 0 && old & (1 << 16) == 0 {
                    self.hse_on_at = Some(now);
                }
                if self.cr & (1 << 16) == 0 {
                    self.hse_on_at = None;
                }
                if self.cr & (1 << 24) != 0 && old & (1 << 24) == 0 {
                    self.pll_on_at = Some(now);
                }
                if self.cr & (1 << 24) == 0 {
                    self.pll_on_at = None;
                }
            }
            0x04 => {
                self.cfgr = (self.cfgr & 0xC) | (v & !0xC);
            }
            0x08 => {
                // Clear bits (rc_w1 in the upper half) and enables.
                let clear = (v >> 16) & 0x9F;
                self.cir = (self.cir & !clear) & !0x1F00 | (v & 0x1F00);
            }
            0x0C => self.apb2rstr = v,
            0x10 => self.apb1rstr = v,
            0x14 => self.ahbenr = v,
            0x18 => self.apb2enr = v,
            0x1C => self.apb1enr = v,
            0x20 => self.bdcr = v,
            0x24 => {
                if v & (1 << 24) != 0 {
                    self.csr &= !0xFE00_0000; // RMVF
                }
                self.csr = (self.csr & !1) | (v & 1);
            }
            _ => {}
        }
        self.update_switch(now);
    }
}

// ---------------------------------------------------------------------------
// FLASH / FPEC (RM0008 §3.3; PM0075)
// ---------------------------------------------------------------------------

/// Start of the main flash.
pub const FLASH_BASE: u32 = 0x0800_0000;
/// 128 KB (STM32F103RB).
pub const FLASH_SIZE: u32 = 128 * 1024;
/// 1 KB pages (medium density).
pub const FLASH_PAGE: u32 = 1024;
/// Datasheet maximum of a half-word program time, tPROG = 70 µs.
pub const T_PROG: Ticks = 70 * TICKS_PER_S / 1_000_000;
/// Datasheet maximum of a page erase time, tERASE = 40 ms.
pub const T_ERASE: Ticks = 40 * TICKS_PER_S / 1000;

/// A flash operation the FPEC carried out (for power-cut tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashOp {
    /// A half-word programmed at this address.
    Program(u32, u16),
    /// A page erased at this address.
    Erase(u32),
}

/// The flash memory interface.
#[derive(Clone, Debug)]
pub struct FlashCtl {
    /// ACR.
    pub acr: u32,
    /// CR.
    pub cr: u32,
    /// SR (BSY is never seen: the CPU stalls while the FPEC works).
    pub sr: u32,
    /// AR.
    pub ar: u32,
    key_step: u8,
    /// Locked until reset after a wrong key.
    key_fault: bool,
    /// Operations carried out since the twin was built.
    pub ops: u64,
    /// Cut the power when the operation with this number (0-based, counted
    /// in [`FlashCtl::ops`]) is about to happen; `after` cuts right after it.
    pub cut_at: Option<(u64, bool)>,
    /// Set when a cut fired: the twin resets at the next instruction boundary.
    pub cut_fired: bool,
    /// What the FPEC did, in order.
    pub log: Vec<FlashOp>,
}

impl FlashCtl {
    fn new() -> Self {
        Self {
            acr: 0x30,
            cr: 0x80,
            sr: 0,
            ar: 0,
            key_step: 0,
            key_fault: false,
            ops: 0,
            cut_at: None,
            cut_fired: false,
            log: Vec::new(),
        }
    }

    fn reset(&mut self) {
        let keep = (self.ops, self.cut_at, std::mem::take(&mut self.log));
        *self = Self::new();
        (self.ops, self.cut_at, self.log) = keep;
    }

    fn read(&self, off: u32) -> u32 {
        match off {
            0x00 => {
                // PRFTBS follows PRFTBE.
                (self.acr & !0x20) | if self.acr & 0x10 != 0 { 0x20 } else { 0 }
            }
            0x0C => self.sr,
            0x10 => self.cr,
            0x14 => self.ar,
            // OBR (PM0075, FLASH_OBR: reset value 0x03FF FFFC): the
            // option bytes as ST delivers the chip: RDPRT off, software
            // watchdog, no reset in Stop/Standby, Data0 = Data1 = 0xFF.
            0x1C => 0x03FF_FFFC,
            0x20 => 0xFFFF_FFFF, // WRPR: no page write-protected
            _ => 0,
        }
    }

    fn write(&mut self, off: u32, v: u32) -> Option<FlashCmd> {
        match off {
            0x00 => self.acr = v & 0x1F,
            0x04 => {
                // KEYR: KEY1 then KEY2 (RM0008 §3.3.3 / PM0075 §2.3.1).
                match (self.key_step, v) {
                    _ if self.key_fault => {}
                    (0, 0x4567_0123) => self.key_step = 1,
                    (1, 0xCDEF_89AB) if self.cr & 0x80 != 0 => {
                        self.cr &= !0x80;
                        self.key_step = 0;
                    }
                    _ => {
                        self.key_fault = true;
                        self.cr |= 0x80;
                    }
                }
            }
            0x0C => {
                // EOP, WRPRTERR, PGERR are rc_w1.
                self.sr &= !(v & 0x34);
            }
            0x10 => {
                if self.cr & 0x80 != 0 {
                    return None; // locked: writes ignored
                }
                let was = self.cr;
                self.cr = v & 0x1677;
                if v & 0x80 != 0 {
                    self.cr |= 0x80;
                }
                if v & 0x40 != 0 && self.cr & 2 != 0 && was & 0x40 == 0 {
                    self.cr &= !0x40;
                    return Some(FlashCmd::ErasePage(self.ar & !(FLASH_PAGE - 1)));
                }
                self.cr &= !0x40;
            }
            0x14 => self.ar = v,
            _ => {}
        }
        None
    }
}

/// What a register write asks the FPEC to do (carried out by the twin on
/// the flash image, with the CPU stall).
#[derive(Clone, Copy, Debug)]
pub enum FlashCmd {
    /// Erase the page at this address.
    ErasePage(u32),
}

// ---------------------------------------------------------------------------
// GPIO (RM0008 §9.2)
// ---------------------------------------------------------------------------

/// A GPIO port.
#[derive(Clone, Debug)]
pub struct Gpio {
    /// CRL, CRH.
    pub cr: [u32; 2],
    /// ODR.
    pub odr: u32,
    /// LCKR.
    pub lckr: u32,
}

impl Gpio {
    fn new() -> Self {
        Self {
            cr: [0x4444_4444; 2],
            odr: 0,
            lckr: 0,
        }
    }

    /// MODE and CNF of a pin: (mode, cnf).
    pub fn config(&self, pin: u32) -> (u32, u32) {
        let r = self.cr[(pin / 8) as usize] >> ((pin % 8) * 4);
        (r & 3, (r >> 2) & 3)
    }
}

// ---------------------------------------------------------------------------
// Timers (RM0008 §14 advanced TIM1, §15 general purpose TIM2..TIM4)
// ---------------------------------------------------------------------------

/// One of TIM1..TIM4.
#[derive(Clone, Debug)]
pub struct Timer {
    /// 1 for TIM1 (advanced), 2..4.
    pub number: u8,
    /// CR1.
    pub cr1: u32,
    /// CR2.
    pub cr2: u32,
    /// SMCR.
    pub smcr: u32,
    /// DIER.
    pub dier: u32,
    /// SR.
    pub sr: u32,
    /// CCMR1, CCMR2.
    pub ccmr: [u32; 2],
    /// CCER.
    pub ccer: u32,
    /// BDTR (TIM1 only).
    pub bdtr: u32,
    /// RCR (TIM1 only).
    pub rcr: u32,
    /// PSC preload and active.
    pub psc: u16,
    /// Active prescaler.
    pub psc_act: u16,
    /// ARR preload.
    pub arr: u16,
    /// Active auto-reload.
    pub arr_act: u16,
    /// CCR preload registers (or captured values).
    pub ccr: [u16; 4],
    /// Active compare values.
    pub ccr_act: [u16; 4],
    /// Counter.
    pub cnt: u16,
    psc_cnt: u64,
    /// Last advance.
    t: Ticks,
    frac: u64,
    /// Update events so far (one output period each in PWM).
    pub updates: u64,
    /// Rising edges of OC1 so far (PWM mode 1 with 0 < CCR1).
    pub oc1_pulses: u64,
    /// Frozen by the debug halt (DBGMCU TIMx_STOP with the core halted).
    pub halted: bool,
    /// Captures that found CC1IF still set (each sets CC1OF).
    pub overcaptures: u64,
}

impl Timer {
    fn new(number: u8) -> Self {
        Self {
            number,
            cr1: 0,
            cr2: 0,
            smcr: 0,
            dier: 0,
            sr: 0,
            ccmr: [0; 2],
            ccer: 0,
            bdtr: 0,
            rcr: 0,
            psc: 0,
            psc_act: 0,
            // RM0008 §15.4.12 / §14.4.12: ARR resets to 0.
            arr: 0,
            arr_act: 0,
            ccr: [0; 4],
            ccr_act: [0; 4],
            cnt: 0,
            psc_cnt: 0,
            t: 0,
            frac: 0,
            updates: 0,
            oc1_pulses: 0,
            halted: false,
            overcaptures: 0,
        }
    }

    fn reset(&mut self, now: Ticks) {
        let n = self.number;
        let keep = (self.updates, self.oc1_pulses, self.overcaptures);
        *self = Self::new(n);
        self.t = now;
        (self.updates, self.oc1_pulses, self.overcaptures) = keep;
    }

    /// Encoder mode (SMS = 001, 010, 011): the counter follows the inputs.
    pub fn encoder_mode(&self) -> u32 {
        let sms = self.smcr & 7;
        if (1..=3).contains(&sms) {
            sms
        } else {
            0
        }
    }

    fn running(&self) -> bool {
        self.cr1 & 1 != 0 && !self.halted && self.encoder_mode() == 0
    }

    fn oc_mode(&self, ch: usize) -> u32 {
        (self.ccmr[ch / 2] >> (4 + 8 * (ch % 2) as u32)) & 7
    }

    fn cc_input(&self, ch: usize) -> bool {
        (self.ccmr[ch / 2] >> (8 * (ch % 2) as u32)) & 3 != 0
    }

    fn oc_preload(&self, ch: usize) -> bool {
        (self.ccmr[ch / 2] >> (3 + 8 * (ch % 2) as u32)) & 1 != 0
    }

    /// The update event: preloads transferred (RM0008 §15.3.2).
    fn update_event(&mut self, set_flag: bool) {
        self.psc_act = self.psc;
        self.arr_act = self.arr;
        for ch in 0..4 {
            if !self.cc_input(ch) {
                self.ccr_act[ch] = self.ccr[ch];
            }
        }
        if set_flag && self.cr1 & 2 == 0 {
            self.sr |= 1;
        }
        self.updates += 1;
        if !self.cc_input(0) && self.oc_mode(0) == 0b110 && self.ccr_act[0] > 0 {
            self.oc1_pulses += 1;
        }
    }

    fn compare_flags(&mut self, from: u16, to: u16) {
        // Output-compare channels whose CCR lies in (from, to].
        for ch in 0..4 {
            if !self.cc_input(ch) {
                let c = self.ccr_act[ch];
                if c > from && c <= to {
                    self.sr |= 1 << (ch + 1);
                }
            }
        }
    }

    fn advance(&mut self, now: Ticks, clk_hz: u64) {
        if now <= self.t {
            return;
        }
        let elapsed = now - self.t + self.frac;
        self.t = now;
        if !self.running() || clk_hz == 0 {
            // Stopped, or no clock (RCC enable bit off, held in reset).
            self.frac = 0;
            return;
        }
        let per = ticks_per(clk_hz);
        let mut n = elapsed / per;
        self.frac = elapsed % per;
        if self.arr_act == 0 {
            // "The counter is blocked while the auto-reload value is null."
            return;
        }
        let one_pulse = self.cr1 & 8 != 0;
        loop {
            let div = u64::from(self.psc_act) + 1;
            let to_step = div - self.psc_cnt;
            let to_uev = to_step + u64::from(self.arr_act - self.cnt.min(self.arr_act)) * div;
            if n < to_uev {
                let steps = (self.psc_cnt + n) / div;
                self.psc_cnt = (self.psc_cnt + n) % div;
                let from = self.cnt;
                let to = (u64::from(self.cnt) + steps).min(0xFFFF) as u16;
                self.compare_flags(from, to);
                self.cnt = to;
                return;
            }
            n -= to_uev;
            self.psc_cnt = 0;
            let from = self.cnt;
            self.compare_flags(from, self.arr_act);
            self.cnt = 0;
            self.update_event(true);
            if one_pulse {
                self.cr1 &= !1;
                return;
            }
            if self.arr_act == 0 {
                return;
            }
            // Whole periods at once: preloads are now in force.
            let period = (u64::from(self.arr_act) + 1) * (u64::from(self.psc_act) + 1);
            let k = n / period;
            if k > 0 {
                n -= k * period;
                self.updates += k;
                if !self.cc_input(0) && self.oc_mode(0) == 0b110 && self.ccr_act[0] > 0 {
                    self.oc1_pulses += k;
                }
                self.compare_flags(0, self.arr_act);
                if self.cr1 & 2 == 0 {
                    self.sr |= 1;
                }
            }
        }
    }

    /// Time of the next update event, if the counter runs.
    fn next_update(&self, clk_hz: u64) -> Ticks {
        if !self.running() || self.arr_act == 0 || clk_hz == 0 {
            return NEVER;
        }
        let div = u64::from(self.psc_act) + 1;
        let to_uev =
            (div - self.psc_cnt) + u64::from(self.arr_act - self.cnt.min(self.arr_act)) * div;
        (self.t + to_uev * ticks_per(clk_hz)).saturating_sub(self.frac)
    }

    /// OC1REF now (PWM mode 1/2, forced levels).
    pub fn oc1_ref(&self) -> bool {
        match self.oc_mode(0) {
            0b100 => false,
            0b101 => true,
            0b110 => self.arr_act != 0 && self.cnt < self.ccr_act[0],
            0b111 => !(self.arr_act != 0 && self.cnt < self.ccr_act[0]),
            _ => false,
        }
    }

    /// CH1 output as the pin sees it when the pin is in AF mode: `None` when
    /// the timer does not drive it (RM0008 table 83 for TIM1: MOE, OSSI,
    /// OSSR, OIS1, CC1E; §15.4.9 for TIM2..TIM4: CC1E).
    pub fn ch1_output(&self) -> Option<bool> {
        let cc1e = self.ccer & 1 != 0;
        let cc1p = self.ccer & 2 != 0;
        if self.cc_input(0) {
            return None;
        }
        if self.number != 1 {
            return cc1e.then(|| self.oc1_ref() ^ cc1p);
        }
        // DBG_TIM1_STOP with the core halted: "the outputs are disabled (as
        // if during a break event)" (RM0008 §31.16.3): MOE reads as 0.
        let moe = self.bdtr & (1 << 15) != 0 && !self.halted;
        let ossi = self.bdtr & (1 << 10) != 0;
        let ois1 = self.cr2 & (1 << 8) != 0;
        if moe {
            // CC1NE is unused on this board (0): OC1 is driven iff CC1E.
            cc1e.then(|| self.oc1_ref() ^ cc1p)
        } else if ossi && cc1e {
            // Off-state: output enabled at its idle level OIS1.
            Some(ois1)
        } else {
            None
        }
    }

    /// The duty the CH1 output carries (PWM mode 1 on an enabled output),
    /// 0..1, and whether it is driven at all.
    pub fn ch1_duty(&self) -> Option<f64> {
        let cc1p = self.ccer & 2 != 0;
        let driven = self.ch1_output()?;
        let moe = self.number != 1 || self.bdtr & (1 << 15) != 0;
        if !moe || !self.running() || self.arr_act == 0 {
            return Some(if driven { 1.0 } else { 0.0 });
        }
        let period = f64::from(self.arr_act) + 1.0;
        let duty = match self.oc_mode(0) {
            0b110 => f64::from(self.ccr_act[0]).min(period) / period,
            0b111 => 1.0 - f64::from(self.ccr_act[0]).min(period) / period,
            0b101 => 1.0,
            _ => 0.0,
        };
        Some(if cc1p { 1.0 - duty } else { duty })
    }

    /// An input edge on CH1 at the current time (already advanced):
    /// capture into CCR1, CC1IF, CC1OF (RM0008 §15.3.5).
    fn capture1(&mut self) {
        if !self.cc_input(0) || self.ccer & 1 == 0 {
            return;
        }
        if self.sr & 2 != 0 {
            self.sr |= 1 << 9; // CC1OF
            self.overcaptures += 1;
        }
        self.ccr[0] = self.cnt;
        self.ccr_act[0] = self.cnt;
        self.sr |= 2;
    }

    /// The input filter delay of IC1 (IC1F, CKD), in timer clocks
    /// (RM0008 §15.4.7: N consecutive samples at fSAMPLING).
    pub fn ic1_filter_clocks(&self) -> u64 {
        self.ic_filter_clocks(0)
    }

    /// The input filter delay of channel `ch` + 1 (ICxF in CCMR1/CCMR2,
    /// CKD), in timer clocks.
    pub fn ic_filter_clocks(&self, ch: usize) -> u64 {
        let icf = (self.ccmr[ch / 2] >> (4 + 8 * (ch % 2) as u32)) & 0xF;
        let dts = 1u64 << ((self.cr1 >> 8) & 3).min(2);
        let (div, n) = match icf {
            0 => (1, 0),
            1 => (1, 2),
            2 => (1, 4),
            3 => (1, 8),
            4 => (2 * dts, 6),
            5 => (2 * dts, 8),
            6 => (4 * dts, 6),
            7 => (4 * dts, 8),
            8 => (8 * dts, 6),
            9 => (8 * dts, 8),
            10 => (16 * dts, 5),
            11 => (16 * dts, 6),
            12 => (16 * dts, 8),
            13 => (32 * dts, 5),
            14 => (32 * dts, 6),
            _ => (32 * dts, 8),
        };
        div * n
    }

    fn irq_line(&self) -> bool {
        self.dier & self.sr & 0x5F != 0
    }

    fn read(&mut self, off: u32) -> u32 {
        match off {
            0x00 => self.cr1,
            0x04 => self.cr2,
            0x08 => self.smcr,
            0x0C => self.dier,
            0x10 => self.sr,
            0x18 => self.ccmr[0],
            0x1C => self.ccmr[1],
            0x20 => self.ccer,
            0x24 => u32::from(self.cnt),
            0x28 => u32::from(self.psc),
            0x2C => u32::from(self.arr),
            0x30 => self.rcr,
            0x34..=0x40 => {
                let ch = ((off - 0x34) / 4) as usize;
                if self.cc_input(ch) && ch == 0 {
                    // Reading CCR1 in capture mode clears CC1IF.
                    self.sr &= !2;
                }
                u32::from(self.ccr[ch])
            }
            0x44 if self.number == 1 => self.bdtr,
            _ => 0,
        }
    }

    fn write(&mut self, off: u32, v: u32) {
        match off {
            0x00 => {
                // DIR is read-only in encoder mode (RM0008 §15.4.1).
                let keep = if self.encoder_mode() != 0 { 0x10 } else { 0 };
                self.cr1 = (v & 0x3FF & !keep) | (self.cr1 & keep);
            }
            0x04 => self.cr2 = v,
            0x08 => self.smcr = v,
            0x0C => self.dier = v,
            // rc_w0: writing 0 clears, 1 leaves the flag as it is.
            0x10 => self.sr &= v | !0x1E7F,
            0x14 => {
                if v & 1 != 0 {
                    // UG: counter and prescaler restart, preloads load;
                    // the counter is cleared, or takes ARR when DIR = 1 in
                    // edge-aligned mode (RM0008 §15.4.6).
                    let down = self.cr1 & 0x10 != 0 && self.cr1 & 0x60 == 0;
                    self.cnt = if down { self.arr } else { 0 };
                    self.psc_cnt = 0;
                    let urs = self.cr1 & 4 != 0;
                    self.update_event(!urs);
                }
                for ch in 0..4 {
                    if v & (2 << ch) != 0 {
                        if self.cc_input(ch) {
                            self.ccr[ch] = self.cnt;
                            self.ccr_act[ch] = self.cnt;
                        }
                        self.sr |= 2 << ch;
                    }
                }
            }
            0x18 => self.ccmr[0] = v & 0xFFFF,
            0x1C => self.ccmr[1] = v & 0xFFFF,
            0x20 => self.ccer = v & 0xFFFF,
            0x24 => self.cnt = v as u16,
            0x28 => self.psc = v as u16,
            0x2C => {
                self.arr = v as u16;
                if self.cr1 & 0x80 == 0 {
                    self.arr_act = self.arr;
                }
            }
            0x30 => self.rcr = v & 0xFF,
            0x34..=0x40 => {
                let ch = ((off - 0x34) / 4) as usize;
                if !self.cc_input(ch) {
                    self.ccr[ch] = v as u16;
                    if !self.oc_preload(ch) {
                        self.ccr_act[ch] = v as u16;
                    }
                }
            }
            0x44 if self.number == 1 => self.bdtr = v & 0xFFFF,
            _ => {}
        }
    }
}

// ---------------------------------------------------------------------------
// USART (RM0008 §27)
// ---------------------------------------------------------------------------

/// One event on a USART's line, with its exact time (recorded when
/// [`Usart::record`] is set; RM0008 §27.3.2 and §27.3.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineEvent {
    /// A byte moved into the transmit shift register: its start bit
    /// begins on TX.
    TxStart {
        /// When.
        at: Ticks,
        /// The byte.
        byte: u8,
    },
    /// A byte's stop bit ended on TX (10 bit times after its start, 11
    /// with M = 1).
    TxEnd {
        /// When.
        at: Ticks,
        /// The byte.
        byte: u8,
    },
    /// TC set: a stop bit ended with TXE = 1 (nothing waiting in TDR).
    TcSet {
        /// When.
        at: Ticks,
    },
    /// A received byte's stop bit ended: RXNE set (or ORE).
    RxEnd {
        /// When.
        at: Ticks,
        /// The byte.
        byte: u8,
    },
}

impl LineEvent {
    /// The event's time.
    pub fn at(&self) -> Ticks {
        match *self {
            LineEvent::TxStart { at, .. }
            | LineEvent::TxEnd { at, .. }
            | LineEvent::TcSet { at }
            | LineEvent::RxEnd { at, .. } => at,
        }
    }
}

/// USART1 or USART2.
#[derive(Clone, Debug)]
pub struct Usart {
    /// SR.
    pub sr: u32,
    /// Received data.
    pub rdr: u8,
    /// BRR.
    pub brr: u32,
    /// CR1, CR2, CR3.
    pub cr1: u32,
    /// CR2.
    pub cr2: u32,
    /// CR3.
    pub cr3: u32,
    /// Bytes waiting on the line (from the other end).
    pub rx_line: VecDeque<u8>,
    /// When the byte on the line finishes arriving.
    rx_next: Ticks,
    /// Transmit data register (None = empty).
    tdr: Option<u8>,
    /// Byte in the shift register and when it leaves it.
    tx_shift: Option<(u8, Ticks)>,
    /// Bytes sent to the other end.
    pub tx_out: Vec<u8>,
    /// SR was read with ORE set (first half of the clear sequence).
    sr_read_ore: bool,
    /// Overruns seen on this USART (twin-side count).
    pub overruns: u64,
    /// Record the line's events into [`Usart::line_log`] (off by default:
    /// a long run would grow it).
    pub record: bool,
    /// The line's events, in time order per direction.
    pub line_log: Vec<LineEvent>,
}

impl Usart {
    fn new() -> Self {
        Self {
            sr: 0xC0,
            rdr: 0,
            brr: 0,
            cr1: 0,
            cr2: 0,
            cr3: 0,
            rx_line: VecDeque::new(),
            rx_next: NEVER,
            tdr: None,
            tx_shift: None,
            tx_out: Vec::new(),
            sr_read_ore: false,
            overruns: 0,
            record: false,
            line_log: Vec::new(),
        }
    }

    fn reset(&mut self) {
        let out = std::mem::take(&mut self.tx_out);
        let log = std::mem::take(&mut self.line_log);
        let (overruns, record) = (self.overruns, self.record);
        *self = Self::new();
        self.tx_out = out;
        self.overruns = overruns;
        self.record = record;
        self.line_log = log;
    }

    /// An APB reset pulse (RCC_APBxRSTR): the registers back to their
    /// reset values; bytes already on their way on the RX line still come
    /// (the line is outside the chip).
    fn peripheral_reset(&mut self) {
        let line = std::mem::take(&mut self.rx_line);
        self.reset();
        self.rx_line = line;
    }

    fn log(&mut self, e: LineEvent) {
        if self.record {
            self.line_log.push(e);
        }
    }

    /// One character (start, 8 data, stop) in ticks at this BRR and PCLK.
    pub fn char_ticks(&self, pclk: u64) -> Ticks {
        let brr = u64::from(self.brr.max(16));
        let bits = if self.cr1 & (1 << 12) != 0 { 11 } else { 10 };
        brr * bits * ticks_per(pclk)
    }

    fn enabled(&self) -> bool {
        self.cr1 & (1 << 13) != 0
    }

    fn advance(&mut self, now: Ticks, pclk: u64) {
        if pclk == 0 {
            // No clock (RCC enable bit off, held in reset): nothing moves.
            return;
        }
        // Transmitter.
        while let Some((b, done)) = self.tx_shift {
            if done > now {
                break;
            }
            self.tx_out.push(b);
            self.log(LineEvent::TxEnd { at: done, byte: b });
            // The next byte (if TDR holds one) starts as this stop bit
            // ends; TXE is set as it moves into the shift register.
            self.tx_shift = self.tdr.take().map(|n| (n, done + self.char_ticks(pclk)));
            match self.tx_shift {
                Some((n, _)) => self.log(LineEvent::TxStart { at: done, byte: n }),
                None => {
                    // RM0008 §27.6.1: TC is set "if the transmission of a
                    // frame containing data is complete and if TXE is set".
                    self.sr |= 1 << 6;
                    self.log(LineEvent::TcSet { at: done });
                }
            }
            self.sr |= 1 << 7; // TXE
        }
        // Receiver.
        if !self.enabled() || self.cr1 & 4 == 0 {
            self.rx_next = NEVER;
            return;
        }
        if self.rx_next == NEVER && !self.rx_line.is_empty() {
            self.rx_next = now + self.char_ticks(pclk);
        }
        while self.rx_next <= now {
            let Some(b) = self.rx_line.pop_front() else {
                self.rx_next = NEVER;
                break;
            };
            self.log(LineEvent::RxEnd {
                at: self.rx_next,
                byte: b,
            });
            if self.sr & (1 << 5) != 0 {
                // RXNE still set: the new byte is lost, ORE (RM0008 §27.6.1).
                self.sr |= 1 << 3;
                self.overruns += 1;
            } else {
                self.rdr = b;
                self.sr |= 1 << 5;
            }
            self.rx_next = if self.rx_line.is_empty() {
                NEVER
            } else {
                self.rx_next + self.char_ticks(pclk)
            };
        }
    }

    fn next_event(&self) -> Ticks {
        self.tx_shift.map_or(NEVER, |(_, t)| t).min(self.rx_next)
    }

    fn irq_line(&self) -> bool {
        let c = self.cr1;
        let s = self.sr;
        (c & (1 << 5) != 0 && s & ((1 << 5) | (1 << 3)) != 0)
            || (c & (1 << 7) != 0 && s & (1 << 7) != 0)
            || (c & (1 << 6) != 0 && s & (1 << 6) != 0)
            || (c & (1 << 4) != 0 && s & (1 << 4) != 0)
    }

    fn read(&mut self, off: u32) -> u32 {
        match off {
            0x00 => {
                self.sr_read_ore = self.sr & 0x0F != 0;
                self.sr
            }
            0x04 => {
                // DR read clears RXNE; after an SR read it also clears the
                // error flags ORE, NE, FE, PE.
                if self.sr_read_ore {
                    self.sr &= !0x0F;
                    self.sr_read_ore = false;
                }
                self.sr &= !(1 << 5);
                u32::from(self.rdr)
            }
            0x08 => self.brr,
            0x0C => self.cr1,
            0x10 => self.cr2,
            0x14 => self.cr3,
            _ => 0,
        }
    }

    fn write(&mut self, off: u32, v: u32, now: Ticks, pclk: u64) {
        match off {
            0x00 => {
                // RXNE, TC, LBD, CTS are rc_w0.
                self.sr &= v | !0x360;
            }
            0x04 => {
                self.sr &= !(1 << 6); // TC cleared by the write (after SR read)
                if !self.enabled() || self.cr1 & 8 == 0 {
                    return;
                }
                let b = v as u8;
                if self.tx_shift.is_none() {
                    self.tx_shift = Some((b, now + self.char_ticks(pclk)));
                    self.log(LineEvent::TxStart { at: now, byte: b });
                } else {
                    self.tdr = Some(b);
                    self.sr &= !(1 << 7);
                }
            }
            0x08 => self.brr = v & 0xFFFF,
            0x0C => self.cr1 = v & 0x3FFF,
            0x10 => self.cr2 = v,
            0x14 => self.cr3 = v,
            _ => {}
        }
    }
}

// ---------------------------------------------------------------------------
// IWDG (RM0008 §19)
// ---------------------------------------------------------------------------

/// The independent watchdog. Its counter and its copies of PR and RLR live
/// in the LSI (VDD) domain: a write to PR or RLR reaches them "up to 5 RC
/// 40 kHz cycles" later, meanwhile IWDG_SR shows PVU or RVU and the
/// register cannot be written again (RM0008 §19.4.4). The twin takes the
/// five LSI cycles in full, counted from the write or from the LSI's
/// start-up (DS5319 tSU(LSI)), whichever is later.
#[derive(Clone, Debug)]
pub struct Iwdg {
    /// PR in force.
    pub pr: u32,
    /// RLR in force.
    pub rlr: u32,
    /// A PR write on its way to the LSI domain: (value, written at).
    pending_pr: Option<(u32, Ticks)>,
    /// An RLR write on its way: (value, written at).
    pending_rlr: Option<(u32, Ticks)>,
    /// Started (0xCCCC), cannot be stopped.
    pub running: bool,
    /// When it was started (the first 0xCCCC key).
    pub started_at: Option<Ticks>,
    unlocked: bool,
    /// The counter's value at `count_from`; it counts down from there, one
    /// step every 4·2^PR LSI cycles.
    count: u32,
    count_from: Ticks,
    /// When the LSI runs (after its start-up time), if it is on.
    pub lsi_ready_at: Option<Ticks>,
    /// LSI frequency, Hz (30..60 kHz on the F103; 40 kHz nominal).
    pub lsi_hz: u64,
}

/// LSI cycles a PR or RLR update takes to reach the LSI domain (RM0008
/// §19.4.4: "up to 5").
const IWDG_UPDATE_LSI_CYCLES: u64 = 5;

impl Iwdg {
    fn new(lsi_hz: u64) -> Self {
        Self {
            pr: 0,
            rlr: 0xFFF,
            pending_pr: None,
            pending_rlr: None,
            running: false,
            started_at: None,
            unlocked: false,
            count: 0xFFF,
            count_from: 0,
            lsi_ready_at: None,
            lsi_hz,
        }
    }

    fn lsi_cycle(&self) -> Ticks {
        TICKS_PER_S / self.lsi_hz.max(1)
    }

    /// One count of the counter at prescaler `pr`: 4·2^PR LSI cycles.
    fn count_ticks(&self, pr: u32) -> Ticks {
        (4u64 << pr.min(6)) * self.lsi_cycle()
    }

    /// The timeout from a reload: (RLR + 1) × 4·2^PR LSI periods.
    pub fn timeout_ticks(&self) -> Ticks {
        (u64::from(self.rlr) + 1) * self.count_ticks(self.pr)
    }

    /// When an update written at `at` reaches the LSI domain.
    fn update_done(&self, at: Ticks) -> Ticks {
        self.lsi_ready_at.map_or(NEVER, |r| {
            at.max(r) + IWDG_UPDATE_LSI_CYCLES * self.lsi_cycle()
        })
    }

    /// The counter's value at `t` (≥ `count_from`).
    fn count_at(&self, t: Ticks) -> u32 {
        let steps = t.saturating_sub(self.count_from) / self.count_ticks(self.pr);
        self.count
            .saturating_sub(steps.min(u64::from(u32::MAX)) as u32)
    }

    /// Applies the updates that have reached the LSI domain by `now`.
    fn settle(&mut self, now: Ticks) {
        loop {
            let pr_done = self.pending_pr.map(|(_, at)| self.update_done(at));
            let rlr_done = self.pending_rlr.map(|(_, at)| self.update_done(at));
            match (pr_done, rlr_done) {
                (Some(p), r) if p <= now && r.is_none_or(|r| p <= r) => {
                    // The counter goes on from where it is, at the new rate.
                    if self.running {
                        self.count = self.count_at(p);
                        self.count_from = p;
                    }
                    self.pr = self.pending_pr.take().map_or(self.pr, |(v, _)| v);
                }
                (_, Some(r)) if r <= now => {
                    self.rlr = self.pending_rlr.take().map_or(self.rlr, |(v, _)| v);
                }
                _ => return,
            }
        }
    }

    /// The LSI started (or stopped) at `ready` (its start-up included).
    pub(crate) fn set_lsi_ready(&mut self, ready: Option<Ticks>, now: Ticks) {
        self.settle(now);
        self.lsi_ready_at = ready;
    }

    /// When the counter reaches 0 (a system reset).
    pub fn expires_at(&self) -> Ticks {
        if !self.running {
            return NEVER;
        }
        let naive = self.count_from + (u64::from(self.count) + 1) * self.count_ticks(self.pr);
        match self.pending_pr {
            Some((v, at)) => {
                let done = self.update_done(at);
                if done < naive {
                    let left = u64::from(self.count_at(done)) + 1;
                    done + left * self.count_ticks(v)
                } else {
                    naive
                }
            }
            None => naive,
        }
    }

    fn write(&mut self, off: u32, v: u32, now: Ticks) {
        self.settle(now);
        let from = self.lsi_ready_at.map_or(now, |r| r.max(now));
        match off {
            0x00 => match v & 0xFFFF {
                0x5555 => self.unlocked = true,
                0xAAAA => {
                    self.count = self.rlr;
                    self.count_from = from;
                    self.unlocked = false;
                }
                0xCCCC => {
                    if !self.running {
                        // The counter starts from its reset value 0xFFF
                        // (§19.3) once the LSI runs (the bus starts it).
                        self.running = true;
                        self.started_at = Some(now);
                        self.count = 0xFFF;
                        self.count_from = from;
                    }
                    self.unlocked = false;
                }
                _ => self.unlocked = false,
            },
            // "Prescaler value can be updated only when PVU bit is reset".
            0x04 if self.unlocked && self.pending_pr.is_none() => {
                self.pending_pr = Some((v & 7, now));
            }
            0x08 if self.unlocked && self.pending_rlr.is_none() => {
                self.pending_rlr = Some((v & 0xFFF, now));
            }
            _ => {}
        }
    }

    fn read(&mut self, off: u32, now: Ticks) -> u32 {
        self.settle(now);
        match off {
            0x04 => self.pr,
            0x08 => self.rlr,
            // SR: PVU, RVU while an update is on its way.
            0x0C => {
                u32::from(self.pending_pr.is_some()) | u32::from(self.pending_rlr.is_some()) << 1
            }
            _ => 0,
        }
    }
}

// ---------------------------------------------------------------------------
// SysTick (PM0056 §4.5)
// ---------------------------------------------------------------------------

/// The SysTick timer.
#[derive(Clone, Debug, Default)]
pub struct SysTick {
    /// CSR (COUNTFLAG kept separately).
    pub ctrl: u32,
    /// RVR.
    pub load: u32,
    /// CVR at `t`.
    val: u32,
    t: Ticks,
    frac: u64,
    countflag: bool,
    /// Wraps to be turned into a pending exception.
    pub fired: bool,
}

impl SysTick {
    /// COUNTFLAG, cleared by the read (PM0056 §4.5.1).
    pub fn countflag_take(&mut self) -> bool {
        std::mem::take(&mut self.countflag)
    }

    /// CVR now (after an advance).
    pub fn val(&self) -> u32 {
        self.val
    }

    /// CSR (COUNTFLAG included, not cleared) and CVR as they are at `now`,
    /// without touching the timer (a debugger's read).
    pub fn peek(&self, now: Ticks, c: &Clocks) -> (u32, u32) {
        let mut st = self.clone();
        st.advance(now, c);
        (st.ctrl | u32::from(st.countflag) << 16, st.val)
    }

    /// CSR written: counting restarts from the current value.
    pub fn restart(&mut self, now: Ticks) {
        self.t = now;
        self.frac = 0;
    }

    /// A write to CVR clears it and COUNTFLAG.
    pub fn clear(&mut self, now: Ticks) {
        self.val = 0;
        self.countflag = false;
        self.t = now;
        self.frac = 0;
    }

    fn clk(&self, c: &Clocks) -> u64 {
        if self.ctrl & 4 != 0 {
            c.hclk
        } else {
            c.hclk / 8
        }
    }

    fn advance(&mut self, now: Ticks, c: &Clocks) {
        if now <= self.t {
            return;
        }
        let el = now - self.t + self.frac;
        self.t = now;
        if self.ctrl & 1 == 0 {
            self.frac = 0;
            return;
        }
        let per = ticks_per(self.clk(c));
        let n = el / per;
        self.frac = el % per;
        if n == 0 {
            return;
        }
        let v = u64::from(self.val);
        let period = u64::from(self.load) + 1;
        if v > 0 && n < v {
            self.val = (v - n) as u32;
            return;
        }
        // Reaching 0 sets COUNTFLAG and, with TICKINT, pends SysTick; the
        // next clock reloads RVR.
        let (zeros, r) = if v > 0 {
            (1 + (n - v) / period, (n - v) % period)
        } else {
            (n / period, n % period)
        };
        self.val = if r == 0 || self.load == 0 {
            0
        } else {
            (period - r) as u32
        };
        if zeros > 0 && self.load > 0 {
            self.countflag = true;
            if self.ctrl & 2 != 0 {
                self.fired = true;
            }
        }
    }

    fn next_event(&self, c: &Clocks) -> Ticks {
        if self.ctrl & 3 != 3 || self.load == 0 {
            return NEVER;
        }
        let per = ticks_per(self.clk(c));
        let to_zero = if self.val == 0 {
            u64::from(self.load) + 1
        } else {
            u64::from(self.val)
        };
        (self.t + to_zero * per).saturating_sub(self.frac)
    }
}

// ---------------------------------------------------------------------------
// EXTI and AFIO (RM0008 §10, §9.4)
// ---------------------------------------------------------------------------

/// EXTI.
#[derive(Clone, Debug, Default)]
pub struct Exti {
    /// IMR, EMR, RTSR, FTSR, PR.
    pub imr: u32,
    /// EMR.
    pub emr: u32,
    /// RTSR.
    pub rtsr: u32,
    /// FTSR.
    pub ftsr: u32,
    /// PR.
    pub pr: u32,
}

/// AFIO.
#[derive(Clone, Debug, Default)]
pub struct Afio {
    /// EVCR.
    pub evcr: u32,
    /// MAPR.
    pub mapr: u32,
    /// EXTICR1..4.
    pub exticr: [u32; 4],
}

// ---------------------------------------------------------------------------
// The bus: all models, address decoding and interrupt lines
// ---------------------------------------------------------------------------

/// Everything on the peripheral buses.
#[derive(Clone, Debug)]
pub struct Bus {
    /// RCC.
    pub rcc: Rcc,
    /// FLASH interface.
    pub flash: FlashCtl,
    /// GPIOA..GPIOE.
    pub gpio: [Gpio; 5],
    /// AFIO.
    pub afio: Afio,
    /// EXTI.
    pub exti: Exti,
    /// TIM1..TIM4.
    pub tim: [Timer; 4],
    /// USART1, USART2.
    pub usart: [Usart; 2],
    /// IWDG.
    pub iwdg: Iwdg,
    /// SysTick.
    pub systick: SysTick,
    /// DBGMCU_CR.
    pub dbgmcu_cr: u32,
    /// What the outside world drives onto each pin, ports A..E.
    pub external: [[External; 16]; 5],
    /// Last sampled level of each EXTI line's pin (for edge detection).
    exti_last: [bool; 16],
    /// A flash erase requested by a register write.
    pub flash_cmd: Option<FlashCmd>,
    /// Accesses to registers the twin does not model (address, write).
    pub unmodelled: Vec<(u32, bool)>,
    /// The core is halted by a (virtual) debugger.
    pub debug_halt: bool,
    /// The system clock is gone (its crystal failed without the clock
    /// security system): nothing clocked by it moves; the IWDG (LSI) runs.
    pub clock_stopped: bool,
    /// Pins whose level changes are recorded (port 0 = A, pin, last level
    /// seen); see [`Bus::trace_pin`].
    traced: Vec<(usize, u32, Level)>,
    /// The recorded level changes of the traced pins, in time order.
    pub pin_log: Vec<PinEvent>,
    /// When the LSI was switched on (by LSION or by starting the IWDG).
    lsi_on_at: Option<Ticks>,
    /// Writes the silicon ignores because the peripheral's clock is off
    /// or it is held in reset (the first [`DROPPED_WRITES_KEPT`]).
    pub dropped_writes: Vec<DroppedWrite>,
}

/// How many dropped writes [`Bus::dropped_writes`] keeps.
pub const DROPPED_WRITES_KEPT: usize = 256;

/// A write to a peripheral whose clock was off (RM0008 §7.3.6–§7.3.8) or
/// that was held in reset (§7.3.4, §7.3.5): the chip ignores it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DroppedWrite {
    /// When.
    pub at: Ticks,
    /// The register's address.
    pub addr: u32,
    /// The value written.
    pub value: u32,
}

/// A quadrature encoder's connection to a timer: the timer, its CH1/CH2
/// pins with no remap, and the AFIO_MAPR bits that must be 0 for them
/// (RM0008 §9.3.7, §9.4.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncoderWiring {
    /// Index into [`Bus::tim`] (2 = TIM3, 3 = TIM4).
    pub timer: usize,
    /// (port, pin) of CH1 and CH2 (port 0 = A).
    pub pins: [(usize, u32); 2],
    /// AFIO_MAPR bits of the timer's remap.
    pub remap_mask: u32,
}

impl EncoderWiring {
    /// TIM3 CH1/CH2 on PA6/PA7: TIM3_REMAP (MAPR bits 11:10) = 00.
    pub const TIM3_PA6_PA7: Self = Self {
        timer: 2,
        pins: [(0, 6), (0, 7)],
        remap_mask: 0b11 << 10,
    };
    /// TIM4 CH1/CH2 on PB6/PB7: TIM4_REMAP (MAPR bit 12) = 0.
    pub const TIM4_PB6_PB7: Self = Self {
        timer: 3,
        pins: [(1, 6), (1, 7)],
        remap_mask: 1 << 12,
    };
}

/// The RCC bits that clock and reset a peripheral (RM0008 §7.3.4–§7.3.8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gate {
    /// Bit n of APB1ENR and APB1RSTR.
    Apb1(u32),
    /// Bit n of APB2ENR and APB2RSTR.
    Apb2(u32),
    /// Bit n of AHBENR (no reset register on the medium-density parts).
    Ahb(u32),
}

/// The clock gate of the peripheral at `base`; `None` for those with no
/// enable bit (RCC, FLASH interface, IWDG, EXTI, the core's registers).
pub fn gate(base: u32) -> Option<Gate> {
    use Gate::*;
    Some(match base {
        addr::TIM2 => Apb1(0),
        addr::TIM3 => Apb1(1),
        addr::TIM4 => Apb1(2),
        0x4000_2C00 => Apb1(11), // WWDG
        0x4000_3800 => Apb1(14), // SPI2
        addr::USART2 => Apb1(17),
        0x4000_4800 => Apb1(18), // USART3
        0x4000_5400 => Apb1(21), // I2C1
        0x4000_5800 => Apb1(22), // I2C2
        0x4000_5C00 => Apb1(23), // USB
        0x4000_6400 => Apb1(25), // CAN
        0x4000_6C00 => Apb1(27), // BKP
        0x4000_7000 => Apb1(28), // PWR
        addr::AFIO => Apb2(0),
        0x4001_0800..=0x4001_1800 => Apb2(2 + (base - addr::GPIOA) / 0x400),
        0x4001_2400 => Apb2(9),  // ADC1
        0x4001_2800 => Apb2(10), // ADC2
        addr::TIM1 => Apb2(11),
        0x4001_3000 => Apb2(12), // SPI1
        addr::USART1 => Apb2(14),
        0x4002_0000 => Ahb(0), // DMA1
        0x4002_3000 => Ahb(6), // CRC
        _ => return None,
    })
}

/// A traced pin's level change (a GPIO register write or a reset changed
/// it; [`Bus::trace_pin`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PinEvent {
    /// When (the time of the write, see docs/twin.md: a block's end).
    pub at: Ticks,
    /// Port (0 = A).
    pub port: usize,
    /// Pin.
    pub pin: u32,
    /// The new level.
    pub level: Level,
}

/// Base addresses.
pub mod addr {
    /// TIM2.
    pub const TIM2: u32 = 0x4000_0000;
    /// TIM3.
    pub const TIM3: u32 = 0x4000_0400;
    /// TIM4.
    pub const TIM4: u32 = 0x4000_0800;
    /// IWDG.
    pub const IWDG: u32 = 0x4000_3000;
    /// USART2.
    pub const USART2: u32 = 0x4000_4400;
    /// AFIO.
    pub const AFIO: u32 = 0x4001_0000;
    /// EXTI.
    pub const EXTI: u32 = 0x4001_0400;
    /// GPIOA (B, C, D, E follow at 0x400 steps).
    pub const GPIOA: u32 = 0x4001_0800;
    /// TIM1.
    pub const TIM1: u32 = 0x4001_2C00;
    /// USART1.
    pub const USART1: u32 = 0x4001_3800;
    /// RCC.
    pub const RCC: u32 = 0x4002_1000;
    /// FLASH interface.
    pub const FLASH: u32 = 0x4002_2000;
}

/// What the machine's wiring drives onto the pins when nothing else is
/// said: the stop input's normally-closed contact on PB10 is closed (to
/// ground) — the machine is not stopped. Open it with
/// `Twin::set_external('B', 10, External::Open)`.
fn board_wiring() -> [[External; 16]; 5] {
    let mut e = [[External::Open; 16]; 5];
    e[1][10] = External::Low;
    e
}

impl Bus {
    /// The bus after a power-on reset.
    pub fn new(hse_dead: bool, lsi_hz: u64) -> Self {
        Self {
            rcc: Rcc::new(0, hse_dead),
            flash: FlashCtl::new(),
            gpio: std::array::from_fn(|_| Gpio::new()),
            afio: Afio::default(),
            exti: Exti::default(),
            tim: [Timer::new(1), Timer::new(2), Timer::new(3), Timer::new(4)],
            usart: [Usart::new(), Usart::new()],
            iwdg: Iwdg::new(lsi_hz),
            systick: SysTick::default(),
            dbgmcu_cr: 0,
            external: board_wiring(),
            exti_last: [false; 16],
            flash_cmd: None,
            unmodelled: Vec::new(),
            debug_halt: false,
            clock_stopped: false,
            traced: Vec::new(),
            pin_log: Vec::new(),
            lsi_on_at: None,
            dropped_writes: Vec::new(),
        }
    }

    /// Whether the peripheral at `base` has its clock (RM0008 §7.3.6–§7.3.8:
    /// "When the peripheral clock is not active, the peripheral register
    /// values may not be readable by software and the returned value is
    /// always 0x0"; writes are ignored).
    pub fn clock_enabled(&self, base: u32) -> bool {
        match gate(base) {
            Some(Gate::Apb1(b)) => self.rcc.apb1enr & (1 << b) != 0,
            Some(Gate::Apb2(b)) => self.rcc.apb2enr & (1 << b) != 0,
            Some(Gate::Ahb(b)) => self.rcc.ahbenr & (1 << b) != 0,
            None => true,
        }
    }

    /// Whether the peripheral at `base` is held in reset by its APBxRSTR bit.
    pub fn held_in_reset(&self, base: u32) -> bool {
        match gate(base) {
            Some(Gate::Apb1(b)) => self.rcc.apb1rstr & (1 << b) != 0,
            Some(Gate::Apb2(b)) => self.rcc.apb2rstr & (1 << b) != 0,
            _ => false,
        }
    }

    /// Whether the peripheral at `base` runs (clocked, not held in reset).
    fn active(&self, base: u32) -> bool {
        match gate(base) {
            Some(Gate::Apb1(b)) => self.apb_active(false, b),
            Some(Gate::Apb2(b)) => self.apb_active(true, b),
            Some(Gate::Ahb(b)) => self.rcc.ahbenr & (1 << b) != 0,
            None => true,
        }
    }

    /// Returns every peripheral whose APBxRSTR bit is set to its reset
    /// values (RM0008 §7.3.4, §7.3.5); it stays there while the bit is set.
    fn apply_peripheral_resets(&mut self, now: Ticks) {
        for (i, base) in [addr::TIM1, addr::TIM2, addr::TIM3, addr::TIM4]
            .into_iter()
            .enumerate()
        {
            if self.held_in_reset(base) {
                self.tim[i].reset(now);
            }
        }
        for (i, base) in [addr::USART1, addr::USART2].into_iter().enumerate() {
            if self.held_in_reset(base) {
                self.usart[i].peripheral_reset();
            }
        }
        for p in 0..5 {
            if self.held_in_reset(addr::GPIOA + 0x400 * p as u32) {
                self.gpio[p] = Gpio::new();
            }
        }
        if self.held_in_reset(addr::AFIO) {
            self.afio = Afio::default();
        }
        self.check_traced(now);
    }

    /// The LSI runs while LSION is set or the IWDG runs (RM0008 §7.2.5,
    /// §19.3: starting the IWDG starts the LSI that clocks it); `iwdg_starting` for the
    /// 0xCCCC key being written now.
    fn sync_lsi(&mut self, now: Ticks, iwdg_starting: bool) {
        let on = self.rcc.csr & 1 != 0 || self.iwdg.running || iwdg_starting;
        if !on {
            self.lsi_on_at = None;
        } else if self.lsi_on_at.is_none() {
            self.lsi_on_at = Some(now);
        }
        let ready = self.lsi_on_at.map(|t| t + LSI_STARTUP);
        self.iwdg.set_lsi_ready(ready, now);
    }

    /// LSIRDY (RCC_CSR bit 1): the LSI has run for its start-up time.
    fn lsi_ready(&self, now: Ticks) -> bool {
        self.lsi_on_at.is_some_and(|t| now >= t + LSI_STARTUP)
    }

    fn drop_write(&mut self, a: u32, v: u32, now: Ticks) {
        if self.dropped_writes.len() < DROPPED_WRITES_KEPT {
            self.dropped_writes.push(DroppedWrite {
                at: now,
                addr: a,
                value: v,
            });
        }
    }

    /// Records every change of the level of `pin` of `port` (0 = A) from
    /// now on into [`Bus::pin_log`] (the level now is the first entry).
    /// Only GPIO output pins are followed (their changes come from register
    /// writes and resets), not AF outputs.
    pub fn trace_pin(&mut self, port: usize, pin: u32, now: Ticks) {
        let level = self.pin_level(port, pin);
        self.traced.push((port, pin, level));
        self.pin_log.push(PinEvent {
            at: now,
            port,
            pin,
            level,
        });
    }

    fn check_traced(&mut self, now: Ticks) {
        for i in 0..self.traced.len() {
            let (port, pin, last) = self.traced[i];
            let level = self.pin_level(port, pin);
            if level != last {
                self.traced[i].2 = level;
                self.pin_log.push(PinEvent {
                    at: now,
                    port,
                    pin,
                    level,
                });
            }
        }
    }

    /// A system reset (IWDG, SYSRESETREQ, NRST): every peripheral back to
    /// its reset state, the reset flags in RCC_CSR kept and `flag` added.
    pub fn system_reset(&mut self, now: Ticks, csr_flag: u32) {
        let csr = (self.rcc.csr & 0xFC00_0000) | csr_flag;
        self.rcc = Rcc::new(0, self.rcc.hse_dead);
        self.rcc.csr = csr;
        self.flash.reset();
        self.gpio = std::array::from_fn(|_| Gpio::new());
        self.afio = Afio::default();
        self.exti = Exti::default();
        for t in &mut self.tim {
            t.reset(now);
        }
        for u in &mut self.usart {
            u.reset();
        }
        let lsi = self.iwdg.lsi_hz;
        self.iwdg = Iwdg::new(lsi);
        self.systick = SysTick {
            t: now,
            ..SysTick::default()
        };
        self.dbgmcu_cr = 0;
        self.clock_stopped = false;
        self.flash_cmd = None;
        self.lsi_on_at = None;
        self.check_traced(now);
    }

    /// The clock tree in force.
    pub fn clocks(&self) -> Clocks {
        self.rcc.clocks()
    }

    /// The crystal stops at `now` (RM0008 §7.2.7). With CSSON and the HSE
    /// running, the clock security system turns HSE (and a PLL fed by it)
    /// off, switches SYSCLK to the HSI if it came from them, sets CSSF,
    /// sends the failure to TIM1's break input (MOE cleared when BKE is
    /// set) and raises the NMI: returns `(nmi, false)`. Without CSSON a
    /// system clock taken from the crystal is lost: returns `(false, true)`.
    pub fn crystal_fails(&mut self, now: Ticks) -> (bool, bool) {
        self.advance(now);
        let r = &mut self.rcc;
        let was_ready = r.hse_ready(now);
        let pll_on_hse = r.cfgr & (1 << 16) != 0;
        let sws = r.sws();
        let in_use = was_ready && (sws == 1 || (sws == 2 && pll_on_hse));
        r.hse_dead = true;
        if r.cr & (1 << 19) != 0 && was_ready {
            r.cr &= !(1 << 16);
            r.hse_on_at = None;
            if pll_on_hse {
                r.cr &= !(1 << 24);
                r.pll_on_at = None;
            }
            if in_use {
                r.cfgr &= !0xF;
            }
            r.cir |= 1 << 7;
            if self.tim[0].bdtr & (1 << 12) != 0 {
                self.tim[0].bdtr &= !(1 << 15);
            }
            (true, false)
        } else {
            self.clock_stopped = in_use;
            (false, in_use)
        }
    }

    /// TIMx's kernel clock, 0 while its RCC clock is off or it is held in
    /// reset (the counter stands still).
    fn tim_clk(&self, i: usize) -> u64 {
        self.tim_clk_in(i, &self.clocks())
    }

    /// [`Bus::tim_clk`] with the clock tree given.
    fn tim_clk_in(&self, i: usize, c: &Clocks) -> u64 {
        // TIM1: APB2 bit 11; TIM2..TIM4: APB1 bits 0..2 (RM0008 §7.3.4–§7.3.8).
        let on = match i {
            0 => self.apb_active(true, 11),
            _ => self.apb_active(false, i as u32 - 1),
        };
        match (on, i) {
            (false, _) => 0,
            (true, 0) => c.tim_apb2,
            (true, _) => c.tim_apb1,
        }
    }

    /// USARTn's PCLK, 0 while its clock is off or it is held in reset.
    fn usart_clk(&self, i: usize) -> u64 {
        self.usart_clk_in(i, &self.clocks())
    }

    /// [`Bus::usart_clk`] with the clock tree given.
    fn usart_clk_in(&self, i: usize, c: &Clocks) -> u64 {
        // USART1: APB2 bit 14; USART2: APB1 bit 17.
        match i {
            0 if self.apb_active(true, 14) => c.pclk2,
            1 if self.apb_active(false, 17) => c.pclk1,
            _ => 0,
        }
    }

    /// Bit `bit` of APB2ENR (`apb2`) or APB1ENR set and of the matching
    /// reset register clear.
    fn apb_active(&self, apb2: bool, bit: u32) -> bool {
        let (en, rst) = if apb2 {
            (self.rcc.apb2enr, self.rcc.apb2rstr)
        } else {
            (self.rcc.apb1enr, self.rcc.apb1rstr)
        };
        (en & !rst) >> bit & 1 != 0
    }

    /// Brings the model behind `base` up to `now` before a register access
    /// (the others are advanced by the scheduler; a GPIO access advances
    /// all, for the AF outputs and EXTI).
    fn advance_for(&mut self, base: u32, now: Ticks) {
        match base {
            addr::TIM1 | addr::TIM2 | addr::TIM3 | addr::TIM4 => {
                let i = match base {
                    addr::TIM1 => 0,
                    addr::TIM2 => 1,
                    addr::TIM3 => 2,
                    _ => 3,
                };
                let clk = self.tim_clk(i);
                self.tim[i].advance(now, clk);
            }
            addr::USART1 | addr::USART2 => {
                let i = usize::from(base == addr::USART2);
                let clk = self.usart_clk(i);
                self.usart[i].advance(now, clk);
            }
            addr::RCC => self.rcc.update_switch(now),
            addr::FLASH | addr::IWDG | addr::AFIO | addr::EXTI => {}
            _ => self.advance(now),
        }
    }

    /// SysTick alone up to `now` (its registers are on the PPB).
    pub fn advance_systick(&mut self, now: Ticks) {
        let c = self.clocks();
        self.systick.advance(now, &c);
    }

    /// Brings every model up to `now`.
    pub fn advance(&mut self, now: Ticks) {
        if self.clock_stopped {
            return;
        }
        let c = self.clocks();
        for i in 0..4 {
            let clk = self.tim_clk_in(i, &c);
            self.tim[i].advance(now, clk);
        }
        for i in 0..2 {
            let clk = self.usart_clk_in(i, &c);
            self.usart[i].advance(now, clk);
        }
        self.systick.advance(now, &c);
        self.rcc.update_switch(now);
        self.sample_exti();
    }

    /// The earliest time at which a model raises an interrupt, finishes a
    /// byte or resets the MCU.
    pub fn next_event(&self) -> Ticks {
        if self.clock_stopped {
            return self.iwdg.expires_at();
        }
        let c = self.clocks();
        let mut t = self.iwdg.expires_at();
        for i in 0..4 {
            let tim = &self.tim[i];
            if tim.dier & 1 != 0 {
                t = t.min(tim.next_update(self.tim_clk_in(i, &c)));
            }
        }
        for (i, u) in self.usart.iter().enumerate() {
            if self.usart_clk_in(i, &c) != 0 {
                t = t.min(u.next_event());
            }
        }
        t = t.min(self.systick.next_event(&c));
        if self.rcc.cr & (1 << 16) != 0 && !self.rcc.hse_dead {
            if let Some(on) = self.rcc.hse_on_at {
                if on + HSE_STARTUP > self.systick.t {
                    t = t.min(on + HSE_STARTUP);
                }
            }
        }
        t
    }

    /// Interrupt request lines (IRQ numbers) asserted now.
    pub fn irq_lines(&self) -> Vec<u32> {
        let mut v = Vec::new();
        let t = &self.tim;
        if t[0].dier & t[0].sr & 1 != 0 {
            v.push(irq::TIM1_UP);
        }
        if t[0].dier & t[0].sr & 0x1E != 0 {
            v.push(irq::TIM1_CC);
        }
        for (i, n) in [(1, irq::TIM2), (2, irq::TIM3), (3, irq::TIM4)] {
            if t[i].irq_line() {
                v.push(n);
            }
        }
        if self.usart[0].irq_line() {
            v.push(irq::USART1);
        }
        if self.usart[1].irq_line() {
            v.push(irq::USART2);
        }
        let ex = self.exti.pr & self.exti.imr;
        for line in 0..5 {
            if ex & (1 << line) != 0 {
                v.push(irq::EXTI0 + line);
            }
        }
        if ex & 0xFC00 != 0 {
            v.push(irq::EXTI15_10);
        }
        if ex & 0x03E0 != 0 {
            v.push(23); // EXTI9_5
        }
        v
    }

    /// Level of pin `pin` of port `port` (0 = A) as a scope sees it.
    pub fn pin_level(&self, port: usize, pin: u32) -> Level {
        let g = &self.gpio[port];
        let (mode, cnf) = g.config(pin);
        let odr = g.odr & (1 << pin) != 0;
        if mode == 0 {
            return match cnf {
                2 => {
                    if odr {
                        Level::PullUp
                    } else {
                        Level::PullDown
                    }
                }
                _ => Level::HiZ,
            };
        }
        let value = match cnf {
            0 | 1 => Some(odr),
            _ => self.af_output(port, pin),
        };
        match (value, cnf & 1 != 0) {
            (None, _) => Level::HiZ,
            (Some(true), true) => Level::HiZ, // open drain released
            (Some(true), false) => Level::High,
            (Some(false), _) => Level::Low,
        }
    }

    /// The logic level an input reads (IDR), given external drive.
    pub fn input_high(&self, port: usize, pin: u32) -> bool {
        match self.pin_level(port, pin) {
            Level::High => true,
            Level::Low => false,
            lvl => match self.external[port][pin as usize] {
                External::High => true,
                External::Low => false,
                External::Open => lvl == Level::PullUp,
            },
        }
    }

    /// The alternate-function output routed to a pin (no remaps: the board
    /// uses the default mapping, AFIO_MAPR = 0).
    fn af_output(&self, port: usize, pin: u32) -> Option<bool> {
        match (port, pin) {
            (0, 8) => self.tim[0].ch1_output(),
            (1, 6) => self.tim[3].ch1_output(),
            (0, 0) => self.tim[1].ch1_output(),
            (0, 6) => self.tim[2].ch1_output(),
            (0, 9) | (0, 2) => Some(true), // USART TX idles high
            _ => None,
        }
    }

    fn sample_exti(&mut self) {
        let active = self.exti.rtsr | self.exti.ftsr;
        if active == 0 {
            return;
        }
        for line in 0..16u32 {
            if active & (1 << line) == 0 {
                continue;
            }
            let port = ((self.afio.exticr[(line / 4) as usize] >> ((line % 4) * 4)) & 0xF) as usize;
            let level = self.input_high(port.min(4), line);
            let last = self.exti_last[line as usize];
            if level != last {
                let rising = level && !last;
                if (rising && self.exti.rtsr & (1 << line) != 0)
                    || (!rising && self.exti.ftsr & (1 << line) != 0)
                {
                    self.exti.pr |= 1 << line;
                }
                self.exti_last[line as usize] = level;
            }
        }
    }

    /// A falling edge on TIM2 CH1's pin (PA0) at `now` (the Hall switch);
    /// `filter` says whether the capture is taken after the IC1F delay.
    pub fn hall_edge(&mut self, now: Ticks) {
        self.advance(now);
        if self.tim_clk(1) == 0 {
            return;
        }
        let t = &self.tim[1];
        let falling = t.ccer & 2 != 0;
        if falling {
            self.tim[1].capture1();
        }
    }

    /// A quadrature encoder on `wiring`'s pins moved by `delta` counts (×4,
    /// signed; `swapped`: its A/B wires crossed) over the last `over` ticks,
    /// with its edges evenly spaced; the timer counts them as the chip
    /// would (RM0008 §15.3.12, encoder interface mode). Returns the counts
    /// the timer took.
    ///
    /// Nothing counts unless, as on the silicon:
    ///
    /// - the timer is clocked and out of reset (RCC_APB1ENR TIMxEN,
    ///   APB1RSTR TIMxRST, §7.3.8, §7.3.5), not frozen by a debug halt, and
    ///   CR1 CEN = 1;
    /// - SMCR SMS is an encoder mode (001, 010, 011, §15.4.3), with CC1S =
    ///   01 and CC2S = 01 (TI1FP1 on TI1, TI2FP2 on TI2: the configuration
    ///   §15.3.12 gives; other selections are not modelled and count
    ///   nothing);
    /// - both pins are inputs with their input stage on (§9.1.4: an
    ///   alternate-function input wants input mode, floating or pull;
    ///   analog mode cuts the Schmitt trigger, §9.1.5; an output drives
    ///   the pin itself), and the AFIO remap routes the timer's channels to
    ///   them (§9.3.7, AFIO_MAPR §9.4.2);
    /// - each input holds its level for the IC1F/IC2F filter's N samples
    ///   (§15.4.7): edges closer than that never pass it.
    ///
    /// Modes 1 and 2 count the edges of one channel (×2); CC1P/CC2P
    /// invert an input, and an odd number of inversions (or crossed wires)
    /// counts the other way. The counter runs between 0 and ARR in force
    /// (ARR = 0, the reset value, holds it at 0, §15.4.12); CR1 DIR shows
    /// the direction of the last count, and a wrap is an update event
    /// (UIF, unless UDIS).
    pub fn encoder_input(
        &mut self,
        wiring: EncoderWiring,
        delta: i32,
        swapped: bool,
        over: Ticks,
    ) -> i32 {
        let i = wiring.timer;
        if delta == 0 || self.tim_clk(i) == 0 {
            return 0;
        }
        let routed = self.afio.mapr & wiring.remap_mask == 0;
        let inputs = wiring.pins.iter().all(|&(port, pin)| {
            let (mode, cnf) = self.gpio[port].config(pin);
            mode == 0 && (cnf == 1 || cnf == 2)
        });
        let clk = self.tim_clk(i);
        let t = &mut self.tim[i];
        let mode = t.encoder_mode();
        let ccmr = t.ccmr[0];
        let selected = ccmr & 3 == 1 && (ccmr >> 8) & 3 == 1;
        if !routed || !inputs || mode == 0 || t.cr1 & 1 == 0 || t.halted || !selected {
            return 0;
        }
        if t.arr_act == 0 {
            // "The counter is blocked while the auto-reload value is null."
            return 0;
        }
        // Each channel changes level |delta| / 2 times over `over`.
        let filter = t.ic_filter_clocks(0).max(t.ic_filter_clocks(1)) * ticks_per(clk);
        let hold = over.saturating_mul(2) / u64::from(delta.unsigned_abs());
        if hold < filter {
            return 0;
        }
        let mut d = delta;
        if mode != 3 {
            d /= 2;
        }
        let inv = (t.ccer & 2 != 0) ^ (t.ccer & 0x20 != 0) ^ swapped;
        if inv {
            d = -d;
        }
        if d == 0 {
            return 0;
        }
        // CR1 DIR (bit 4): 1 = counting down.
        if d < 0 {
            t.cr1 |= 0x10;
        } else {
            t.cr1 &= !0x10;
        }
        let period = i32::from(t.arr_act) + 1;
        let sum = i32::from(t.cnt) + d;
        let c = sum.rem_euclid(period);
        t.cnt = c as u16;
        if (sum < 0 || sum >= period) && t.cr1 & 2 == 0 {
            t.update_event(true);
        }
        d
    }

    /// Reads a peripheral register (`addr` in 0x4000_0000..0x4002_4000).
    pub fn read(&mut self, a: u32, now: Ticks) -> u32 {
        let off = a & 0x3FF;
        let base = a & !0x3FF;
        self.advance_for(base, now);
        if !self.clock_enabled(base) {
            return 0;
        }
        match base {
            addr::TIM2 => self.tim[1].read(off),
            addr::TIM3 => self.tim[2].read(off),
            addr::TIM4 => self.tim[3].read(off),
            addr::TIM1 => self.tim[0].read(off),
            addr::IWDG => self.iwdg.read(off, now),
            addr::USART2 => self.usart[1].read(off),
            addr::USART1 => self.usart[0].read(off),
            addr::AFIO => match off {
                0x00 => self.afio.evcr,
                0x04 => self.afio.mapr,
                0x08..=0x14 => self.afio.exticr[((off - 8) / 4) as usize],
                _ => 0,
            },
            addr::EXTI => match off {
                0x00 => self.exti.imr,
                0x04 => self.exti.emr,
                0x08 => self.exti.rtsr,
                0x0C => self.exti.ftsr,
                0x14 => self.exti.pr,
                _ => 0,
            },
            0x4001_0800..=0x4001_1800 => {
                let p = ((base - addr::GPIOA) / 0x400) as usize;
                match off {
                    0x00 => self.gpio[p].cr[0],
                    0x04 => self.gpio[p].cr[1],
                    0x08 => {
                        let mut idr = 0;
                        for pin in 0..16 {
                            if self.input_high(p, pin) {
                                idr |= 1 << pin;
                            }
                        }
                        idr
                    }
                    0x0C => self.gpio[p].odr,
                    0x18 => self.gpio[p].lckr,
                    _ => 0,
                }
            }
            addr::RCC => {
                let v = self.rcc.read(off, now);
                if off == 0x24 && self.lsi_ready(now) {
                    v | 0x2
                } else {
                    v
                }
            }
            addr::FLASH => self.flash.read(off),
            _ => {
                self.unmodelled.push((a, false));
                0
            }
        }
    }

    /// Writes a peripheral register.
    pub fn write(&mut self, a: u32, v: u32, now: Ticks) {
        let off = a & 0x3FF;
        let base = a & !0x3FF;
        self.advance_for(base, now);
        if !self.active(base) {
            self.drop_write(a, v, now);
            return;
        }
        let c = self.clocks();
        match base {
            addr::TIM2 => self.tim[1].write(off, v),
            addr::TIM3 => self.tim[2].write(off, v),
            addr::TIM4 => self.tim[3].write(off, v),
            addr::TIM1 => self.tim[0].write(off, v),
            addr::IWDG => {
                let starting = off == 0 && v & 0xFFFF == 0xCCCC;
                if starting {
                    self.sync_lsi(now, true);
                }
                self.iwdg.write(off, v, now);
            }
            addr::USART2 => self.usart[1].write(off, v, now, c.pclk1),
            addr::USART1 => self.usart[0].write(off, v, now, c.pclk2),
            addr::AFIO => match off {
                0x00 => self.afio.evcr = v,
                0x04 => self.afio.mapr = v,
                0x08..=0x14 => self.afio.exticr[((off - 8) / 4) as usize] = v & 0xFFFF,
                _ => {}
            },
            addr::EXTI => match off {
                0x00 => self.exti.imr = v,
                0x04 => self.exti.emr = v,
                0x08 => self.exti.rtsr = v,
                0x0C => self.exti.ftsr = v,
                0x10 => self.exti.pr |= v & self.exti.imr,
                0x14 => self.exti.pr &= !v,
                _ => {}
            },
            0x4001_0800..=0x4001_1800 => {
                let p = ((base - addr::GPIOA) / 0x400) as usize;
                let g = &mut self.gpio[p];
                match off {
                    0x00 => g.cr[0] = v,
                    0x04 => g.cr[1] = v,
                    0x0C => g.odr = v & 0xFFFF,
                    0x10 => {
                        let set = v & 0xFFFF;
                        let reset = v >> 16;
                        g.odr = (g.odr & !reset) | set;
                    }
                    0x14 => g.odr &= !(v & 0xFFFF),
                    0x18 => g.lckr = v,
                    _ => {}
                }
                self.check_traced(now);
            }
            addr::RCC => {
                // Everything up to now on the clocks, enables and resets in
                // force before the write.
                self.advance(now);
                self.rcc.write(off, v, now);
                match off {
                    0x0C | 0x10 => self.apply_peripheral_resets(now),
                    0x24 => self.sync_lsi(now, false),
                    _ => {}
                }
            }
            addr::FLASH => {
                if let Some(cmd) = self.flash.write(off, v) {
                    self.flash_cmd = Some(cmd);
                }
            }
            _ => self.unmodelled.push((a, true)),
        }
        if matches!(base, addr::AFIO | addr::EXTI | 0x4001_0800..=0x4001_1800) {
            self.sample_exti();
        }
    }
}
