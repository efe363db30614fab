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

const RCC: u32 = 0x4002_1000;
const RCC_APB2RSTR: u32 = RCC + 0x0C;
const RCC_APB1RSTR: u32 = RCC + 0x10;
const RCC_APB2ENR: u32 = RCC + 0x18;
const RCC_APB1ENR: u32 = RCC + 0x1C;
const TIM2: u32 = 0x4000_0000;
const TIM1_BDTR: u32 = 0x4001_2C44;
const USART1: u32 = 0x4001_3800;
const GPIOC_CRH: u32 = 0x4001_1004;
const AFIO_EXTICR1: u32 = 0x4001_0008;
const NVIC_ISER0: u32 = 0xE000_E100;
const NVIC_ISPR0: u32 = 0xE000_E200;
const SCB_CCR: u32 = 0xE000_ED14;

/// Stores `reg` into result word `i`.
fn keep(p: &mut Program, reg: u8, i: u16) {
    p.li(12, RESULTS).str(reg, 12, 4 * i);
}

/// Stores the word at `addr` into result word `i` (r0 is used).
fn keep_word(p: &mut Program, addr: u32, i: u16) {
    p.load(0, addr);
    keep(p, 0, i);
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
/// resets to 0 (Cortex-M3 TRM r1p1, ARM DDI 0337E; only from r2p0 on does
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
