//! The twin's models against the reference manuals, with small test
//! programs (`qemu_tests::thumb`): each pokes registers in a given order and
//! keeps what the CPU read in RAM, and the test compares that with what
//! RM0008, PM0056, the Cortex-M3 r1p1 TRM and the STM32F103xB datasheet
//! (DS5319) say the chip does. No firmware image needed; each runs a few
//! milliseconds of firmware time (well under a second on the host).

use qemu_tests::thumb::{Cond, Program, SP};
use twin::{Options, Twin, RAM_BASE, RAM_SIZE, TICKS_PER_S};

/// Where the programs keep their results (word i at `RESULTS + 4 i`).
const RESULTS: u32 = RAM_BASE;
/// The core clock after reset: the 8 MHz HSI (RM0008 §7.2).
const HSI_HZ: u64 = 8_000_000;

const RCC: u32 = 0x4002_1000;
const RCC_CR: u32 = RCC;
const RCC_APB2RSTR: u32 = RCC + 0x0C;
const RCC_APB1RSTR: u32 = RCC + 0x10;
const RCC_APB2ENR: u32 = RCC + 0x18;
const RCC_APB1ENR: u32 = RCC + 0x1C;
const RCC_CSR: u32 = RCC + 0x24;
const TIM2: u32 = 0x4000_0000;
const TIM1_BDTR: u32 = 0x4001_2C44;
const USART1: u32 = 0x4001_3800;
const GPIOC_CRH: u32 = 0x4001_1004;
const AFIO_EXTICR1: u32 = 0x4001_0008;
const IWDG: u32 = 0x4000_3000;
const FLASH_OBR: u32 = 0x4002_201C;
const SYST_CSR: u32 = 0xE000_E010;
const SYST_RVR: u32 = 0xE000_E014;
const SYST_CVR: u32 = 0xE000_E018;
const SYST_CALIB: u32 = 0xE000_E01C;
const NVIC_ISER0: u32 = 0xE000_E100;
const NVIC_ISPR0: u32 = 0xE000_E200;
const SCB_CCR: u32 = 0xE000_ED14;
const DBGMCU_IDCODE: u32 = 0xE004_2000;

/// Stores `reg` into result word `i`.
fn keep(p: &mut Program, reg: u8, i: u16) {
    p.li(12, RESULTS).str(reg, 12, 4 * i);
}

/// Stores the word at `addr` into result word `i` (r0 is used).
fn keep_word(p: &mut Program, addr: u32, i: u16) {
    p.load(0, addr);
    keep(p, 0, i);
}

/// SysTick counting down from 0xFFFFFF on the core clock (PM0056 §4.5).
fn start_systick(p: &mut Program) {
    p.store(SYST_RVR, 0x00FF_FFFF)
        .store(SYST_CVR, 0)
        .store(SYST_CSR, 0b101);
}

/// Spins `n` times around a two-instruction loop (label `name`).
fn spin(p: &mut Program, n: u16, name: &'static str) {
    p.movw(1, n).label(name).subi(1, 1).b_if(Cond::Ne, name);
}

/// Runs `program` for `us` microseconds of firmware time and returns the
/// twin.
fn run(program: &mut Program, us: u64) -> Twin {
    let image = program.build(RAM_BASE + RAM_SIZE);
    let mut twin = Twin::from_program(&image, Options::default()).expect("load the program");
    twin.run_ticks(us * TICKS_PER_S / 1_000_000).expect("run");
    assert!(!twin.lockup(), "the test program locked up");
    twin
}

fn result(twin: &Twin, i: u32) -> u32 {
    twin.read_u32(RESULTS + 4 * i).expect("RAM")
}

/// Core cycles kept by [`poll_timed`] in result `i`: SysTick's 24-bit
/// down-counter, so the difference is taken modulo 2^24 (read just after
/// it is started, it still holds 0, 2^24 in effect).
fn cycles(twin: &Twin, i: u32) -> u32 {
    result(twin, i) & 0x00FF_FFFF
}

/// RM0008 §7.3.6–§7.3.8 (RCC_AHBENR, APB2ENR, APB1ENR): "When the
/// peripheral clock is not active, the peripheral register values may not
/// be readable by software and the returned value is always 0x0"; the
/// peripheral's logic has no clock, so writes are lost and a counter
/// stands still.
#[test]
fn a_peripheral_without_its_clock_ignores_writes_reads_0_and_stands_still() {
    let mut p = Program::new();
    p.label("reset")
        // TIM2 and GPIOC configured before their clocks are on.
        .store(TIM2 + 0x28, 0x1234)
        .store(TIM2 + 0x2C, 0x5678)
        .store(GPIOC_CRH, 0x3333_3333);
    keep_word(&mut p, TIM2 + 0x28, 0);
    p.store(RCC_APB1ENR, 1).store(RCC_APB2ENR, 1 << 4).dsb();
    keep_word(&mut p, TIM2 + 0x28, 1);
    keep_word(&mut p, TIM2 + 0x2C, 2);
    keep_word(&mut p, GPIOC_CRH, 3);
    p.store(TIM2 + 0x28, 0x1234);
    keep_word(&mut p, TIM2 + 0x28, 4);
    // The counter runs on the 8 MHz timer clock (PSC 0 in force, ARR
    // 0xFFFF, CEN), then its clock is switched off for ~1000 core cycles.
    p.store(TIM2 + 0x2C, 0xFFFF).store(TIM2, 1);
    keep_word(&mut p, TIM2 + 0x24, 5);
    p.store(RCC_APB1ENR, 0);
    spin(&mut p, 500, "off");
    p.store(RCC_APB1ENR, 1);
    keep_word(&mut p, TIM2 + 0x24, 6);
    // And with the clock on for as long, it counts.
    spin(&mut p, 500, "on");
    keep_word(&mut p, TIM2 + 0x24, 7);
    p.halt();
    let twin = run(&mut p, 2000);
    let r: Vec<u32> = (0..8).map(|i| result(&twin, i)).collect();
    eprintln!("results {r:#x?}");
    assert_eq!(r[0], 0, "TIM2_PSC read without its clock");
    assert_eq!(r[1], 0, "TIM2_PSC written without its clock");
    assert_eq!(r[2], 0, "TIM2_ARR written without its clock");
    assert_eq!(r[3], 0x4444_4444, "GPIOC_CRH written without its clock");
    assert_eq!(r[4], 0x1234, "TIM2_PSC written with its clock");
    let off = r[6].wrapping_sub(r[5]) & 0xFFFF;
    let on = r[7].wrapping_sub(r[6]) & 0xFFFF;
    // The loop of 500 iterations is 1000 cycles; around the switch-off
    // only the few instructions of the two RCC writes count.
    assert!(on >= 1000, "TIM2 counted {on} with its clock");
    assert!(off < 50, "TIM2 counted {off} while its clock was off");
}

/// RM0008 §7.3.4, §7.3.5 (RCC_APB2RSTR, APB1RSTR): "1: Reset TIMx", set
/// and cleared by software. A pulse returns each peripheral's registers to
/// the reset values of its chapter: TIMx PSC, ARR, CR1 and TIM1_BDTR 0
/// (§15.4, §14.4), USART BRR and CR1 0 and SR 0x00C0 (§27.6), GPIOx_CRH
/// 0x4444_4444 (§9.2.2), AFIO_EXTICR1 0 (§9.4.3). While the bit is set the
/// peripheral is held in reset: a write then is lost too.
#[test]
fn an_apb_reset_pulse_returns_the_peripherals_to_their_reset_values() {
    let regs = [
        (TIM2 + 0x28, 0x1234, 0),
        (TIM2 + 0x2C, 0x5678, 0),
        (TIM2, 0x81, 0),
        (TIM1_BDTR, 0x8C00, 0),
        (USART1 + 0x08, 0x271, 0),
        (USART1 + 0x0C, 0x200C, 0),
        (GPIOC_CRH, 0x3333_3333, 0x4444_4444),
        (AFIO_EXTICR1, 0x1111, 0),
    ];
    let mut p = Program::new();
    p.label("reset")
        .store(RCC_APB1ENR, 1)
        .store(RCC_APB2ENR, 1 | (1 << 4) | (1 << 11) | (1 << 14));
    for &(addr, value, _) in &regs {
        p.store(addr, value);
    }
    for (i, &(addr, _, _)) in regs.iter().enumerate() {
        keep_word(&mut p, addr, i as u16);
    }
    p.store(RCC_APB1RSTR, 1)
        .store(RCC_APB2RSTR, 1 | (1 << 4) | (1 << 11) | (1 << 14))
        .store(TIM2 + 0x28, 0x77)
        .store(RCC_APB1RSTR, 0)
        .store(RCC_APB2RSTR, 0);
    for (i, &(addr, _, _)) in regs.iter().enumerate() {
        keep_word(&mut p, addr, (8 + i) as u16);
    }
    keep_word(&mut p, USART1, 16);
    p.halt();
    let twin = run(&mut p, 500);
    for (i, &(addr, value, reset)) in regs.iter().enumerate() {
        let before = result(&twin, i as u32);
        let after = result(&twin, 8 + i as u32);
        eprintln!(
            "{addr:#010x}: written {value:#x}, read {before:#x}, after the reset pulse {after:#x}"
        );
        assert_eq!(before, value, "{addr:#010x} before the reset");
        assert_eq!(after, reset, "{addr:#010x} after the reset pulse");
    }
    assert_eq!(result(&twin, 16), 0xC0, "USART1_SR after the reset pulse");
}

/// Exception entry on the F103's Cortex-M3 r1p1 (CPUID 0x411FC231): CCR
/// resets to 0 (PM0056 §4.4.7: "Reset value: 0x0000 0000 (STM32F1 series)";
/// Cortex-M3 TRM r1p1, ARM DDI 0337E; only from r2p0 on does
/// STKALIGN reset to 1), so the frame is pushed where SP points, 4-byte
/// aligned; with STKALIGN set it starts on an 8-byte boundary, a padding
/// word below the old SP flagged by bit 9 of the stacked xPSR (PM0056
/// §4.4.7; ARMv7-M ARM B1.5.6). Either way SP is back where it was after
/// the return.
#[test]
fn exception_frames_are_aligned_as_ccr_stkalign_says() {
    let sp4 = RAM_BASE + 0x4FF4; // ≡ 4 (mod 8)
    let mut p = Program::new();
    p.vector(16, "irq0").label("reset");
    keep_word(&mut p, SCB_CCR, 0);
    p.li(4, RESULTS + 0x10).li(0, sp4).mov(SP, 0);
    // IRQ 0 enabled and pended: taken at once (PRIMASK is 0 after reset).
    p.store(NVIC_ISER0, 1)
        .store(NVIC_ISPR0, 1)
        .dsb()
        .isb()
        .nop();
    p.mov(0, SP);
    keep(&mut p, 0, 1);
    p.store(SCB_CCR, 1 << 9)
        .dsb()
        .store(NVIC_ISPR0, 1)
        .dsb()
        .isb()
        .nop();
    p.mov(0, SP);
    keep(&mut p, 0, 2);
    p.halt();
    // The handler keeps its SP (the frame's address) and the stacked xPSR.
    p.label("irq0")
        .mov(0, SP)
        .str(0, 4, 0)
        .ldr(1, 0, 28)
        .str(1, 4, 4)
        .addi(4, 8)
        .ret();
    let twin = run(&mut p, 200);
    let ccr = result(&twin, 0);
    let frames = [
        (result(&twin, 4), result(&twin, 5)),
        (result(&twin, 6), result(&twin, 7)),
    ];
    eprintln!(
        "CCR at reset {ccr:#x}; frames {frames:#x?}; SP after {:#x}, {:#x}",
        result(&twin, 1),
        result(&twin, 2)
    );
    assert_eq!(ccr & (1 << 9), 0, "CCR.STKALIGN at reset (r1p1)");
    assert_eq!(frames[0].0, sp4 - 32, "frame with STKALIGN = 0");
    assert_eq!(frames[0].1 & (1 << 9), 0, "xPSR bit 9 with STKALIGN = 0");
    assert_eq!(frames[1].0, sp4 - 4 - 32, "frame with STKALIGN = 1");
    assert_ne!(frames[1].1 & (1 << 9), 0, "xPSR bit 9 with STKALIGN = 1");
    assert_eq!(result(&twin, 1), sp4, "SP after the first return");
    assert_eq!(result(&twin, 2), sp4, "SP after the second return");
}

/// FLASH_OBR (PM0075, the FPEC register FLASH_OBR: reset value 0x03FF FFFC): the
/// option bytes as ST delivers the chip: no read protection, software
/// watchdog, no reset in Stop or Standby, Data0 = Data1 = 0xFF.
#[test]
fn flash_obr_reads_the_option_bytes_of_a_new_chip() {
    let mut p = Program::new();
    p.label("reset");
    keep_word(&mut p, FLASH_OBR, 0);
    p.halt();
    let twin = run(&mut p, 50);
    let obr = result(&twin, 0);
    // OPTERR 0, RDPRT 0, USER (bits 9:2) 0xFF, Data0 (17:10) 0xFF, Data1
    // (25:18) 0xFF.
    let expected = (0xFF << 2) | (0xFF << 10) | (0xFF << 18);
    assert_eq!(obr, expected, "FLASH_OBR {obr:#x}");
}

/// Polls `addr` until `mask` is clear (`until_set` false) or set, the
/// SysTick cycles it took into result `i` (modulo 2^24: see [`cycles`]),
/// the last value read into `i+1`.
fn poll_timed(p: &mut Program, addr: u32, mask: u32, until_set: bool, name: &'static str, i: u16) {
    p.load(4, SYST_CVR);
    p.li(1, mask).label(name).load(0, addr).tst(0, 1);
    p.b_if(if until_set { Cond::Eq } else { Cond::Ne }, name);
    p.load(5, SYST_CVR).sub(6, 4, 5);
    keep(p, 6, i);
    keep(p, 0, i + 1);
}

/// LSIRDY (RCC_CSR bit 1, RM0008 §7.3.10) is set once the LSI has started,
/// tSU(LSI) ≤ 85 µs after LSION (DS5319 table 25), not before.
#[test]
fn lsirdy_comes_only_after_the_lsi_start_up_time() {
    let mut p = Program::new();
    p.label("reset");
    keep_word(&mut p, RCC_CSR, 0);
    start_systick(&mut p);
    p.store(RCC_CSR, 1);
    poll_timed(&mut p, RCC_CSR, 2, true, "wait", 1);
    p.halt();
    let twin = run(&mut p, 500);
    let us = f64::from(cycles(&twin, 1)) * 1e6 / HSI_HZ as f64;
    eprintln!(
        "CSR at reset {:#x}; LSIRDY after {us:.1} µs",
        result(&twin, 0)
    );
    assert_eq!(result(&twin, 0) & 3, 0, "LSION, LSIRDY at reset");
    assert_ne!(result(&twin, 2) & 2, 0, "LSIRDY in the end");
    // The start-up time, plus one pass of the polling loop (~10 cycles).
    assert!((85.0..=85.0 + 3.0).contains(&us), "LSIRDY after {us} µs");
}

/// IWDG_SR PVU and RVU (RM0008 §19.4.4): set by a write to IWDG_PR or
/// IWDG_RLR and cleared once the value has reached the LSI domain, "takes
/// up to 5 RC 40 kHz cycles"; "Prescaler value can be updated only when
/// PVU bit is reset" (likewise RLR and RVU). The LSI runs here (the IWDG
/// started it, RM0008 §19.3).
#[test]
fn iwdg_prescaler_and_reload_updates_are_busy_for_lsi_cycles() {
    let mut p = Program::new();
    p.label("reset").store(IWDG, 0xCCCC);
    p.li(1, 2)
        .label("lsi")
        .load(0, RCC_CSR)
        .tst(0, 1)
        .b_if(Cond::Eq, "lsi");
    p.store(IWDG, 0x5555);
    start_systick(&mut p);
    p.store(IWDG + 0x04, 3).store(IWDG + 0x04, 5);
    keep_word(&mut p, IWDG + 0x0C, 0);
    poll_timed(&mut p, IWDG + 0x0C, 1, false, "pvu", 1);
    keep_word(&mut p, IWDG + 0x04, 3);
    p.store(IWDG + 0x08, 0x123);
    keep_word(&mut p, IWDG + 0x0C, 4);
    poll_timed(&mut p, IWDG + 0x0C, 2, false, "rvu", 5);
    keep_word(&mut p, IWDG + 0x08, 7);
    p.store(IWDG, 0xAAAA).halt();
    let twin = run(&mut p, 1000);
    let lsi_cycle_us = 1e6 / twin.state().bus.iwdg.lsi_hz as f64;
    let busy = |i| f64::from(cycles(&twin, i)) * 1e6 / HSI_HZ as f64 / lsi_cycle_us;
    eprintln!(
        "SR after the PR write {:#x}, PVU for {:.2} LSI cycles, PR {}; SR after the RLR write {:#x}, RVU for {:.2} LSI cycles, RLR {:#x}",
        result(&twin, 0),
        busy(1),
        result(&twin, 3),
        result(&twin, 4),
        busy(5),
        result(&twin, 7)
    );
    assert_eq!(result(&twin, 0) & 1, 1, "PVU right after the PR write");
    assert_eq!(result(&twin, 4) & 2, 2, "RVU right after the RLR write");
    for (what, i) in [("PVU", 1), ("RVU", 5)] {
        // At least one LSI edge to cross the clock domains, at most five
        // (plus one pass of the polling loop).
        let cycles = busy(i);
        // The program's own instructions around the write add up to 5 µs.
        let slack = 5.0 / lsi_cycle_us;
        assert!(
            (1.0..=5.0 + slack).contains(&cycles),
            "{what} for {cycles} LSI cycles"
        );
    }
    assert_eq!(result(&twin, 3), 3, "PR: the second write, while PVU, lost");
    assert_eq!(result(&twin, 7), 0x123, "RLR");
}

/// RCC_CR (RM0008 §7.3.1): HSEBYP is read/write, "can be written only if
/// the HSE oscillator is disabled". With the oscillator bypassed the HSE
/// needs a clock on OSC_IN; the board has a crystal there, so HSERDY never
/// comes.
#[test]
fn rcc_cr_keeps_hsebyp() {
    let mut p = Program::new();
    p.label("reset").store(RCC_CR, 0x83 | (1 << 18));
    keep_word(&mut p, RCC_CR, 0);
    p.store(RCC_CR, 0x83 | (1 << 18) | (1 << 16));
    // 3 ms, more than the crystal's 2 ms start-up.
    spin(&mut p, 12_000, "wait");
    keep_word(&mut p, RCC_CR, 1);
    // HSEBYP cannot be cleared while the HSE is on.
    p.store(RCC_CR, 0x83 | (1 << 16));
    keep_word(&mut p, RCC_CR, 2);
    p.halt();
    let twin = run(&mut p, 4000);
    let cr: Vec<u32> = (0..3).map(|i| result(&twin, i)).collect();
    eprintln!("RCC_CR {cr:#x?}");
    assert_ne!(cr[0] & (1 << 18), 0, "HSEBYP written with the HSE off");
    assert_eq!(cr[1] & (1 << 17), 0, "HSERDY with a bypassed crystal");
    assert_ne!(cr[2] & (1 << 18), 0, "HSEBYP cleared with the HSE on");
}

/// `Twin::peek` (a debugger's read) shows SysTick's current value, its
/// calibration value (PM0056 §4.5.4: TENMS = 1 ms of the 9 MHz HCLK/8
/// reference, SKEW) and DBGMCU_IDCODE (RM0008 §31.6.1: DEV_ID 0x410,
/// medium density) as the CPU reads them.
#[test]
fn peek_reads_what_the_cpu_reads() {
    let mut p = Program::new();
    p.label("reset");
    start_systick(&mut p);
    spin(&mut p, 100, "wait");
    // Stopped (ENABLE = 0): the value stays as the CPU reads it.
    p.store(SYST_CSR, 0b100);
    keep_word(&mut p, SYST_CVR, 0);
    keep_word(&mut p, SYST_CALIB, 1);
    keep_word(&mut p, DBGMCU_IDCODE, 2);
    p.halt();
    let twin = run(&mut p, 200);
    let cpu: Vec<u32> = (0..3).map(|i| result(&twin, i)).collect();
    let peek: Vec<u32> = [SYST_CVR, SYST_CALIB, DBGMCU_IDCODE]
        .iter()
        .map(|&a| twin.peek(a))
        .collect();
    eprintln!("CPU {cpu:#x?}, peek {peek:#x?}");
    assert!(
        (1..0x00FF_FFFF - 100).contains(&cpu[0]),
        "SYST_CVR after ~200 cycles: {:#x}",
        cpu[0]
    );
    assert_eq!(cpu[1] & 0x00FF_FFFF, 72_000_000 / 8 / 1000, "TENMS");
    assert_eq!(cpu[2] & 0xFFF, 0x410, "DEV_ID");
    assert_eq!(peek, cpu, "SYST_CVR, SYST_CALIB, DBGMCU_IDCODE");
}

const TIM4: u32 = 0x4000_0800;
const GPIOB_CRL: u32 = 0x4001_0C00;
const GPIOB_ODR: u32 = 0x4001_0C0C;
const AFIO_MAPR: u32 = 0x4001_0004;

/// One way of setting up TIM4's encoder interface, changed from the
/// RM0008 one in one respect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tim4Setup {
    /// RM0008 §15.3.12 with PB6/PB7 pulled-up inputs: clock on, CC1S =
    /// CC2S = 01, IC1F = IC2F = 1111, SMS = 011, ARR = 0xFFFF, CEN.
    Manual,
    /// TIM4EN never set (RCC_APB1ENR, §7.3.8): the writes are lost.
    NoClock,
    /// TIM4 held in reset (RCC_APB1RSTR TIM4RST, §7.3.5).
    HeldInReset,
    /// ARR left at its reset value 0 (§15.4.12): the counter cannot move.
    ArrAtReset,
    /// AFIO_MAPR TIM4_REMAP = 1 (§9.3.7, §9.4.2): the channels are on
    /// PD12/PD13, not PB6/PB7.
    Remapped,
    /// PB6 a push-pull output (§9.1.4: an alternate-function input wants
    /// input mode).
    Pb6Output,
    /// PB7 in analog mode (§9.1.5: the Schmitt trigger is off).
    Pb7Analog,
    /// CC1P = 1 (§15.4.9): TI1 inverted, the count runs the other way.
    Cc1pInverted,
    /// CEN never set.
    Stopped,
}

/// Runs a program that sets TIM4 up as `setup` says and halts; returns
/// the twin (the core on the reset HSI: TIM4 clocked at 8 MHz).
fn tim4_encoder(setup: Tim4Setup) -> Twin {
    use Tim4Setup::*;
    let mut p = Program::new();
    p.label("reset")
        // GPIOB and AFIO clocks (RCC_APB2ENR IOPBEN, AFIOEN, §7.3.7).
        .store(RCC_APB2ENR, (1 << 3) | 1);
    if setup != NoClock {
        p.store(RCC_APB1ENR, 1 << 2);
    }
    if setup == HeldInReset {
        p.store(RCC_APB1RSTR, 1 << 2);
    }
    p.dsb();
    // PB6/PB7: CNF = 10, MODE = 00 (input with pull), ODR = 1: up (§9.2.1).
    let mut crl = 0x8844_4444;
    if setup == Pb6Output {
        crl = 0x8244_4444;
    }
    if setup == Pb7Analog {
        crl = 0x0844_4444;
    }
    p.store(GPIOB_CRL, crl).store(GPIOB_ODR, 0xC0);
    if setup == Remapped {
        p.store(AFIO_MAPR, 1 << 12);
    }
    // CCMR1: CC1S = 01, IC1F = 1111, CC2S = 01, IC2F = 1111 (§15.4.7).
    p.store(TIM4 + 0x18, 0xF1F1);
    if setup == Cc1pInverted {
        p.store(TIM4 + 0x20, 1 << 1);
    }
    p.store(TIM4 + 0x08, 0b011);
    if setup != ArrAtReset {
        p.store(TIM4 + 0x2C, 0xFFFF);
    }
    if setup != Stopped {
        p.store(TIM4, 1);
    }
    p.halt();
    run(&mut p, 50)
}

/// `delta` quadrature counts of a wheel on PB6/PB7 over 1 ms; what TIM4
/// took and its CNT after.
fn wheel_moves(twin: &mut Twin, delta: i32) -> (i32, u32) {
    let took = twin.state_mut().bus.encoder_input(
        twin::periph::EncoderWiring::TIM4_PB6_PB7,
        delta,
        false,
        TICKS_PER_S / 1000,
    );
    (took, twin.peek(TIM4 + 0x24))
}

/// The twin's encoder interface (TIM4 on PB6/PB7, the ground wheel's)
/// counts only as RM0008 lets the chip count: a timer without its clock
/// or held in reset, ARR = 0, the channels remapped away, a pin not an
/// input or CEN = 0 count nothing; CC1P inverts the direction (DIR set,
/// and an update event then loads ARR, §15.4.6); edges closer than the
/// input filter's 8 samples at fDTS / 32 (§15.4.7: 32 µs at 8 MHz) never
/// pass it.
#[test]
fn tim4_encoder_mode_counts_only_as_rm0008_lets_the_chip_count() {
    use Tim4Setup::*;
    // 20 counts in 1 ms: each channel holds its level 100 µs.
    let mut twin = tim4_encoder(Manual);
    assert_eq!(wheel_moves(&mut twin, 20), (20, 20), "the manual's set-up");
    assert_eq!(wheel_moves(&mut twin, -5), (-5, 15), "backwards");
    assert_eq!(twin.peek(TIM4) & 0x10, 0x10, "DIR after a count down");
    for setup in [
        NoClock,
        HeldInReset,
        ArrAtReset,
        Remapped,
        Pb6Output,
        Pb7Analog,
        Stopped,
    ] {
        let mut twin = tim4_encoder(setup);
        assert_eq!(wheel_moves(&mut twin, 20), (0, 0), "{setup:?}");
    }
    let mut twin = tim4_encoder(Cc1pInverted);
    assert_eq!(wheel_moves(&mut twin, 20), (-20, 0xFFFF - 19), "CC1P");
    // UG while DIR = 1: the counter takes ARR (§15.4.6), not 0.
    let now = twin.now();
    twin.state_mut().bus.write(TIM4 + 0x14, 1, now);
    assert_eq!(twin.peek(TIM4 + 0x24), 0xFFFF, "UG counting down");
    // 100 counts in 1 ms: 20 µs a level, under the filter's 32 µs.
    let mut twin = tim4_encoder(Manual);
    assert_eq!(
        wheel_moves(&mut twin, 100),
        (0, 0),
        "faster than the filter"
    );
}
