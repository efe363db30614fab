//! The real board's release image on the twin: on the settings of either
//! machine it boots to the idle loop, and the registers after `init` are what RM0008 says they must be for the
//! board's clock tree, pins and task priorities.
//!
//! Every expected value is computed here from RM0008 / PM0056 formulas and
//! the board's documented requirements (README pin map, docs/firmware.md),
//! not read from the firmware's constants.

#[path = "support/board.rs"]
mod board;
#[path = "support/pages.rs"]
mod pages;
use twin::{CoreState, Options, Twin};

/// The machine the saved settings select (the one image runs both).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Machine {
    /// No saved record: the defaults, profile A.
    ProfileA,
    /// A saved record naming profile B.
    ProfileB,
}

/// The crystal on the board (README: 8 MHz HSE) and the clocks the board
/// runs at (docs/firmware.md: SYSCLK 72 MHz, APB1 36 MHz, APB2 72 MHz).
const HSE: f64 = 8e6;
const SYSCLK: f64 = 72e6;
const PCLK1: f64 = 36e6;
const PCLK2: f64 = 72e6;

/// The image on a fresh twin at power-on, not run yet, with the settings
/// of `image`'s machine.
fn load(image: Machine) -> Twin {
    let elf = twin::image::elf().expect("build the real-board image");
    let flash = match image {
        Machine::ProfileA => None,
        Machine::ProfileB => Some(board::flash_with(&elf, &board::profile_b())),
    };
    Twin::new(
        &elf,
        Options {
            decode_logs: false,
            flash,
            ..Options::default()
        },
    )
    .expect("load the ELF")
}

fn boot(image: Machine) -> Twin {
    let mut twin = load(image);
    // init runs with interrupts off, then the idle loop sleeps: 50 ms is
    // ample (init is ~1 ms of work plus the 2 ms HSE start-up).
    let slept = twin
        .run_until(50, |t| t.core == CoreState::Sleeping)
        .expect("run");
    assert!(slept, "{image:?} never reached the idle loop's wfi");
    twin
}

fn field(v: u32, shift: u32, bits: u32) -> u32 {
    (v >> shift) & ((1 << bits) - 1)
}

/// RM0008 §27.3.4: baud = fCK / (16 × USARTDIV); BRR holds USARTDIV × 16
/// as mantissa (12 bits) and fraction (4 bits), rounded to the nearest.
fn brr_for(fck: f64, baud: f64) -> u32 {
    let usartdiv_x16 = (fck / baud).round() as u32;
    ((usartdiv_x16 / 16) << 4) | (usartdiv_x16 % 16)
}

/// RTIC on a 4-priority-bit Cortex-M3 (PM0056 §4.3.7: the upper nibble is
/// implemented): logical priority p maps to (16 − p) << 4.
fn nvic_prio(p: u32) -> u32 {
    (16 - p) << 4
}

fn ipr(twin: &Twin, irq: u32) -> u32 {
    let word = twin.peek(0xE000_E400 + (irq & !3));
    field(word, 8 * (irq % 4), 8)
}

fn check_common(twin: &mut Twin, image: Machine) {
    // Booted without a reset or fault.
    assert_eq!(twin.resets.len(), 1, "{image:?}: resets {:?}", twin.resets);
    assert_eq!(twin.peek(0xE000_ED2C), 0, "{image:?}: HFSR after boot");
    // --- RCC (RM0008 §7.3.2): PLL from HSE, ×(72/8), SYSCLK = PLL.
    let cfgr = twin.peek(0x4002_1004);
    assert_eq!(field(cfgr, 0, 2), 0b10, "SW = PLL");
    assert_eq!(field(cfgr, 2, 2), 0b10, "SWS = PLL (switch done)");
    assert_eq!(field(cfgr, 16, 1), 1, "PLLSRC = HSE");
    assert_eq!(field(cfgr, 17, 1), 0, "PLLXTPRE = HSE not divided");
    // PLLMUL encodes ×(n + 2).
    assert_eq!(field(cfgr, 18, 4), (SYSCLK / HSE) as u32 - 2, "PLLMUL");
    // HPRE 0xxx = /1 (HCLK = SYSCLK).
    assert_eq!(field(cfgr, 7, 1), 0, "HPRE = /1");
    // PPRE: 0xx = /1, 100 = /2, 101 = /4 … (compare the bits that matter).
    let ppre_ok = |bits: u32, div: f64| {
        if div == 1.0 {
            bits & 0b100 == 0
        } else {
            bits == 0b100 + (div.log2() as u32 - 1)
        }
    };
    assert!(
        ppre_ok(field(cfgr, 8, 3), SYSCLK / PCLK1),
        "PPRE1 {cfgr:#x}"
    );
    assert!(
        ppre_ok(field(cfgr, 11, 3), SYSCLK / PCLK2),
        "PPRE2 {cfgr:#x}"
    );
    // ADCPRE (00 /2, 01 /4, 10 /6, 11 /8): the ADC clock within the
    // datasheet's 14 MHz maximum (the board does not use the ADC).
    let adc_div = [2.0, 4.0, 6.0, 8.0][field(cfgr, 14, 2) as usize];
    assert!(PCLK2 / adc_div <= 14e6, "ADCPRE /{adc_div}");
    let cr = twin.peek(0x4002_1000);
    assert_eq!(cr & (1 << 17), 1 << 17, "HSERDY");
    assert_eq!(cr & (1 << 25), 1 << 25, "PLLRDY");
    let clocks = twin.state().bus.clocks();
    assert_eq!(clocks.sysclk as f64, SYSCLK);
    assert_eq!(clocks.pclk1 as f64, PCLK1);
    assert_eq!(clocks.pclk2 as f64, PCLK2);

    // --- FLASH ACR (RM0008 §3.3.3): two wait states for 48 < SYSCLK ≤ 72 MHz;
    // the prefetch buffer on (its reset state, required with wait states).
    let acr = twin.peek(0x4002_2000);
    let latency = if SYSCLK <= 24e6 {
        0
    } else if SYSCLK <= 48e6 {
        1
    } else {
        2
    };
    assert_eq!(field(acr, 0, 3), latency, "FLASH_ACR LATENCY");
    assert_eq!(field(acr, 4, 2), 0b11, "PRFTBE and PRFTBS");

    // --- USART BRR (RM0008 §27.3.4): USART1 on PCLK2 at 115200 (the
    // touchscreen), USART2 on PCLK1 at 9600 (RS-485), README pin map.
    assert_eq!(
        twin.peek(0x4001_3808),
        brr_for(PCLK2, 115_200.0),
        "USART1 BRR"
    );
    assert_eq!(
        twin.peek(0x4000_4408),
        brr_for(PCLK1, 9_600.0),
        "USART2 BRR"
    );
    // 8N1, transmitter and receiver on, RXNE interrupt for the touchscreen.
    let cr1 = twin.peek(0x4001_380C);
    assert_eq!(
        cr1 & ((1 << 13) | (1 << 12) | (1 << 3) | (1 << 2)),
        (1 << 13) | (1 << 3) | (1 << 2)
    );
    assert_ne!(cr1 & (1 << 5), 0, "USART1 RXNEIE");

    // --- TIM2: Hall capture at 1 MHz (docs: 1 µs ticks). TIM2 runs from
    // 2 × PCLK1 because the APB1 prescaler is not 1 (RM0008 §7.2).
    let tim2_clk = if SYSCLK / PCLK1 == 1.0 {
        PCLK1
    } else {
        2.0 * PCLK1
    };
    assert_eq!(
        twin.peek(0x4000_0028),
        (tim2_clk / 1e6) as u32 - 1,
        "TIM2 PSC"
    );
    assert_eq!(
        twin.peek(0x4000_002C),
        0xFFFF,
        "TIM2 ARR: free-running 16 bits"
    );
    let ccmr1 = twin.peek(0x4000_0018);
    assert_eq!(field(ccmr1, 0, 2), 0b01, "TIM2 CC1S = TI1");
    // IC1F (RM0008 §15.4.7): N samples at fSAMPLING. The debounce must be
    // longer than 1 µs (contact bounce of an NPN switch's edge) and far
    // below the shortest Hall period (1 kHz rated: 1 ms).
    let tim2 = &twin.state().bus.tim[1];
    let filter_s = tim2.ic1_filter_clocks() as f64 / tim2_clk;
    assert!(
        (1e-6..=0.05e-3).contains(&filter_s),
        "TIM2 IC1 filter {filter_s:e} s"
    );
    let ccer = twin.peek(0x4000_0020);
    assert_eq!(
        ccer & 0b11,
        0b11,
        "TIM2 CC1E, CC1P (falling edge: NPN pulls PA0 low)"
    );
    assert_eq!(twin.peek(0x4000_000C) & 0b11, 0b11, "TIM2 DIER CC1IE, UIE");
    assert_eq!(twin.peek(0x4000_0000) & 1, 1, "TIM2 CEN");

    // --- TIM3: encoder mode 3 (RM0008 §15.3.12), both inputs mapped on
    // TI1/TI2, counting modulo 2^16.
    assert_eq!(
        twin.peek(0x4000_0408) & 7,
        0b011,
        "TIM3 SMS = encoder mode 3"
    );
    let ccmr1 = twin.peek(0x4000_0418);
    assert_eq!(field(ccmr1, 0, 2), 0b01, "TIM3 CC1S");
    assert_eq!(field(ccmr1, 8, 2), 0b01, "TIM3 CC2S");
    assert_eq!(twin.peek(0x4000_042C), 0xFFFF, "TIM3 ARR");
    assert_eq!(twin.peek(0x4000_0400) & 1, 1, "TIM3 CEN");

    // --- IWDG (RM0008 §19.3): timeout = 4·2^PR·(RLR + 1) / f_LSI. It must
    // outlast a page erase (tERASE ≤ 40 ms, datasheet) plus a control
    // period (10 ms) at the fastest LSI (60 kHz), and reset the board well
    // within half a second at the slowest (30 kHz).
    let pr = twin.peek(0x4000_3004);
    let rlr = twin.peek(0x4000_3008);
    let timeout = |f_lsi: f64| 4.0 * f64::from(1u32 << pr) * f64::from(rlr + 1) / f_lsi;
    assert!(twin.state().bus.iwdg.running, "IWDG started");
    assert!(
        timeout(60e3) > 0.050,
        "IWDG {:.1} ms at 60 kHz",
        timeout(60e3) * 1e3
    );
    assert!(
        timeout(30e3) < 0.5,
        "IWDG {:.1} ms at 30 kHz",
        timeout(30e3) * 1e3
    );

    // --- NVIC (PM0056 §4.3.7): the task map of firmware/src/main.rs:
    // USART1 (IRQ 37) at 4, TIM2 (IRQ 28) at 3; the software tasks at 2
    // and 1 run on the dispatchers CAN_RX1 (21), CAN_SCE (22), ADC1_2 (18).
    assert_eq!(ipr(twin, 37), nvic_prio(4), "USART1 priority");
    assert_eq!(ipr(twin, 28), nvic_prio(3), "TIM2 priority");
    let enabled = |irq: u32| twin.peek(0xE000_E100 + 4 * (irq / 32)) & (1 << (irq % 32)) != 0;
    for irq in [37, 28] {
        assert!(enabled(irq), "IRQ {irq} enabled");
    }
    let mut dispatch: Vec<u32> = [21, 22, 18]
        .into_iter()
        .filter(|&i| enabled(i))
        .map(|i| ipr(twin, i))
        .collect();
    dispatch.sort();
    assert!(
        dispatch.contains(&nvic_prio(2)) && dispatch.contains(&nvic_prio(1)),
        "dispatcher priorities {dispatch:x?}"
    );
    // The stop input (decision of issue 15's helpers: PB10, EXTI line 10 →
    // EXTI15_10, IRQ 40, priority 5 above every task): AFIO_EXTICR3's EXTI10
    // field selects port B (0001, RM0008 §9.4.5), the line is unmasked and
    // both edges trigger (RM0008 §10.3).
    assert!(enabled(40), "EXTI15_10 enabled");
    assert_eq!(ipr(twin, 40), nvic_prio(5), "EXTI15_10 priority");
    assert_eq!(
        field(twin.peek(0x4001_0010), 8, 4),
        0b0001,
        "EXTICR3 EXTI10 = PB"
    );
    assert_ne!(twin.peek(0x4001_0400) & (1 << 10), 0, "EXTI IMR10");
    assert_ne!(
        twin.peek(0x4001_0408) & (1 << 10),
        0,
        "EXTI RTSR10 (contact opens)"
    );
    assert_ne!(
        twin.peek(0x4001_040C) & (1 << 10),
        0,
        "EXTI FTSR10 (contact closes)"
    );
    // The two receive lines (USART1 RX on PA10 from the screen, USART2 RX
    // on PA3 from the RS-485 transceiver's RO) with the internal pull-up
    // (RM0008 §9.1.11 Table 24 "USARTx_RX: input floating / input pull-up";
    // §9.2.1 CNF = 10 with ODR = 1): an unplugged screen or a transceiver
    // whose RO is released while it sends (DE and /RE tied) reads as an
    // idle line, not as noise framed into bytes.
    assert_eq!(twin.pin('A', 10), twin::Level::PullUp, "PA10 (USART1 RX)");
    assert_eq!(twin.pin('A', 3), twin::Level::PullUp, "PA3 (USART2 RX)");
    // SysTick: 1 kHz monotonic from the core clock (PM0056 §4.5).
    assert_eq!(
        twin.peek(0xE000_E014) + 1,
        (SYSCLK / 1e3) as u32,
        "SysTick reload"
    );
    assert_eq!(
        twin.peek(0xE000_E010) & 0b111,
        0b111,
        "SysTick on, TICKINT, core clock"
    );
}

/// TIM1 CH1 on PA8 (README): profile A's 20 kHz drum PWM, PWM mode 1 with
/// preload, main output enabled.
fn check_tim1_pwm(twin: &Twin, carrier_hz: f64) {
    assert_eq!(twin.peek(0x4001_2C28), 0, "TIM1 PSC");
    assert_eq!(
        twin.peek(0x4001_2C2C),
        (PCLK2 / carrier_hz).round() as u32 - 1,
        "TIM1 ARR for {carrier_hz} Hz"
    );
    let ccmr1 = twin.peek(0x4001_2C18);
    assert_eq!(field(ccmr1, 0, 2), 0, "TIM1 CC1S = output");
    assert_eq!(field(ccmr1, 4, 3), 0b110, "TIM1 OC1M = PWM mode 1");
    assert_eq!(field(ccmr1, 3, 1), 1, "TIM1 OC1PE");
    assert_eq!(
        twin.peek(0x4001_2C20) & 0b11,
        0b01,
        "TIM1 CC1E, active high"
    );
    assert_ne!(twin.peek(0x4001_2C44) & (1 << 15), 0, "TIM1 BDTR MOE");
    assert_eq!(twin.peek(0x4001_2C00) & 0x81, 0x81, "TIM1 ARPE, CEN");
}

#[test]
fn profile_a_boots_to_idle_with_rm0008_registers() {
    let mut twin = boot(Machine::ProfileA);
    check_common(&mut twin, Machine::ProfileA);
    // Drum PWM carrier 20 kHz (docs/firmware.md: above hearing).
    check_tim1_pwm(&twin, 20e3);
    // TIM4 counts profile A's ground wheel: encoder mode 3 (RM0008
    // §15.4.3 SMS = 011), running; no output channel (CCER, §15.4.9).
    // Its full set-up: tests/tests/twin_ground_wheel.rs.
    assert_eq!(field(twin.peek(0x4000_0808), 0, 3), 0b011, "TIM4 SMS");
    assert_eq!(twin.peek(0x4000_0800) & 1, 1, "TIM4 CEN");
    assert_eq!(twin.peek(0x4000_0820), 0, "TIM4 CCER");
    // Outputs after init: drum stopped, PWM pin driven low, enable low.
    assert_eq!(twin.pin('A', 8), twin::Level::Low);
    assert_eq!(twin.pin('B', 12), twin::Level::Low);
    // The RS-485 transceiver's driver-enable (PA1) driven low — receive,
    // the bus released — also on this image without the drive link, where
    // nothing else configures it (it floated: a transceiver with DE
    // floating may drive the driver's bus).
    assert_eq!(twin.pin('A', 1), twin::Level::Low, "PA1 (RS-485 DE)");
}

#[test]
fn profile_b_boots_to_idle_with_rm0008_registers() {
    let mut twin = boot(Machine::ProfileB);
    check_common(&mut twin, Machine::ProfileB);
    // TIM4 CH1 on PB6: PWM mode 1 with preload — or, while the steppers
    // are idle, forced inactive — output enabled (RM0008 §15.4.7, §15.4.9),
    // counter enabled with ARR preload.
    let ccmr1 = twin.peek(0x4000_0818);
    assert!(
        [0b110, 0b100].contains(&field(ccmr1, 4, 3)),
        "TIM4 OC1M = PWM mode 1 or forced inactive: {ccmr1:#x}"
    );
    assert_eq!(field(ccmr1, 3, 1), 1, "TIM4 OC1PE");
    assert_eq!(twin.peek(0x4000_0820) & 0b11, 0b01, "TIM4 CC1E");
    assert_eq!(twin.peek(0x4000_0800) & 0x81, 0x81, "TIM4 ARPE, CEN");
    // Idle steppers: the step pins low, drivers disabled.
    assert_eq!(twin.pin('A', 8), twin::Level::Low);
    assert_eq!(twin.pin('B', 6), twin::Level::Low);
    assert_eq!(twin.pin('B', 12), twin::Level::Low);
    assert_eq!(twin.pin('A', 1), twin::Level::Low, "PA1 (RS-485 DE)");
}

/// RM0008 §15.4.12: "the counter is blocked while the auto-reload value is
/// null". A step timer left with ARR = 0 in force never produces the update
/// event that would load the rates written later (issue 15, item 1).
#[test]
fn profile_b_step_timers_are_not_blocked_after_init() {
    let twin = boot(Machine::ProfileB);
    for (name, i) in [("TIM1", 0), ("TIM4", 3)] {
        let t = &twin.state().bus.tim[i];
        assert_ne!(
            t.arr_act, 0,
            "{name}: ARR in force is 0 after init: the counter is blocked and preloaded rates never load"
        );
    }
}

/// The outputs are driven safe before anything else at boot, before the
/// watchdog is started too: starting it waits for the LSI to take the new
/// prescaler and reload (RM0008 §19.4.4 PVU/RVU), up to the firmware's
/// poll limit when the LSI does not run, and until the outputs are driven
/// the drum PWM, the drivers' enable and the RS-485 DE float (at reset
/// every pin is a floating input, RM0008 §9.1.1). Traced from power-on on
/// every image: the first level each output takes is Low, and it takes it
/// no later than the watchdog's start (the order was the other way round).
#[test]
fn the_outputs_are_driven_low_before_the_watchdog_starts() {
    for image in [Machine::ProfileA, Machine::ProfileB] {
        let mut twin = load(image);
        let mut outputs = vec![('A', 8), ('B', 12), ('A', 1)];
        if image == Machine::ProfileB {
            outputs.push(('B', 6));
        }
        for &(port, pin) in &outputs {
            twin.trace_pin(port, pin);
        }
        let slept = twin
            .run_until(50, |t| t.core == CoreState::Sleeping)
            .expect("run");
        assert!(slept, "{image:?} never reached the idle loop");
        let started = twin
            .state()
            .bus
            .iwdg
            .started_at
            .expect("the watchdog started");
        for (port, pin) in outputs {
            let port_index = (port as u8 - b'A') as usize;
            let log: Vec<_> = twin
                .state()
                .bus
                .pin_log
                .iter()
                .filter(|e| e.port == port_index && e.pin == pin)
                .collect();
            assert_eq!(
                log[0].level,
                twin::Level::HiZ,
                "{image:?} P{port}{pin} at reset"
            );
            let driven = log
                .iter()
                .find(|e| e.level != twin::Level::HiZ)
                .unwrap_or_else(|| panic!("{image:?} P{port}{pin} never driven: {log:?}"));
            assert_eq!(
                driven.level,
                twin::Level::Low,
                "{image:?} P{port}{pin}: first level {log:?}"
            );
            assert!(
                driven.at <= started,
                "{image:?} P{port}{pin} driven low at tick {} after the watchdog's start at tick {started}",
                driven.at
            );
        }
    }
}

/// The safe state at boot writes TIM1's (and profile B's TIM4's) compare
/// mode, compare value and break register before those timers' clocks are
/// on: the chip ignores them (RM0008 §7.3.7, §7.3.8: without its clock a
/// peripheral's registers are not written, they read 0). The outputs must
/// not need them: until `init` switches the timers on (their clock and
/// an APB reset pulse, RM0008 §7.3.4) and hands the pins to them, the GPIO
/// writes alone drive PA8, PB12, PA1 (and PB6) low. Checked from power-on
/// to the watchdog's start, while the crystal is still starting.
#[test]
fn the_boot_safe_state_holds_the_outputs_without_the_timer_writes_made_before_their_clocks() {
    const TIM1: u32 = 0x4001_2C00;
    const TIM4: u32 = 0x4000_0800;
    for image in [Machine::ProfileA, Machine::ProfileB] {
        let mut twin = load(image);
        let started = twin
            .run_until(50, |t| t.state().bus.iwdg.started_at.is_some())
            .expect("run");
        assert!(started, "{image:?}: the watchdog never started");
        let bus = &twin.state().bus;
        let mut timers = vec![("TIM1", 0, TIM1)];
        if image == Machine::ProfileB {
            timers.push(("TIM4", 3, TIM4));
        }
        for &(name, i, base) in &timers {
            assert!(
                !bus.clock_enabled(base),
                "{image:?}: {name}'s clock already on"
            );
            let t = &bus.tim[i];
            let dropped: Vec<u32> = bus
                .dropped_writes
                .iter()
                .filter(|w| w.addr & !0x3FF == base)
                .map(|w| w.addr - base)
                .collect();
            eprintln!("{image:?}: {name} writes lost before its clock: offsets {dropped:#x?}");
            // CCMR1 (0x18) and CCR1 (0x34) written by the safe state, lost.
            assert!(
                dropped.contains(&0x18) && dropped.contains(&0x34),
                "{image:?}: {name} writes before its clock: {dropped:#x?}"
            );
            assert_eq!(
                (t.ccmr[0], t.ccr[0], t.bdtr),
                (0, 0, 0),
                "{image:?}: {name} CCMR1, CCR1, BDTR hold their reset values"
            );
        }
        let mut outputs = vec![('A', 8), ('B', 12), ('A', 1)];
        if image == Machine::ProfileB {
            outputs.push(('B', 6));
        }
        for (port, pin) in outputs {
            assert_eq!(
                twin.pin(port, pin),
                twin::Level::Low,
                "{image:?} P{port}{pin} with the timers unclocked"
            );
        }
    }
}

/// Every handler is compiled to the AAPCS, which wants SP ≡ 0 (mod 8) at
/// each function entry; the core provides it for exception entry only with
/// SCB_CCR.STKALIGN set (PM0056 §4.4.7), and on the F103's Cortex-M3 r1p1
/// (CPUID 0x411FC231) that bit resets to 0 (Cortex-M3 TRM r1p1, ARM DDI
/// 0337E; ARM's ABI advisory IHI 0046B §2.3.3 asks startup code to set it).
/// Inside many of the image's functions SP is ≡ 4 (mod 8) for a few
/// instructions (`push {r4, r5, r6, r7, lr}`, 20 bytes, before the rest of
/// the frame), and on the chip an interrupt can come at any instruction.
/// The twin takes interrupts between translated blocks, so the probe makes
/// that moment: in the idle loop (which uses no stack) SP is moved down by
/// 4 and the Hall capture interrupt (TIM2) is pended; its handler must find
/// an 8-byte aligned stack. SP is put back afterwards and the board runs on.
#[test]
fn handlers_find_an_8_byte_aligned_stack_whatever_sp_the_interrupt_finds() {
    use twin::RegisterARM;
    for image in [Machine::ProfileA, Machine::ProfileB] {
        let mut twin = boot(image);
        let sp = twin.reg(RegisterARM::SP);
        assert_eq!(sp % 8, 0, "{image:?}: SP in the idle loop {sp:#x}");
        twin.set_reg(RegisterARM::SP, sp - 4).expect("SP");
        let (entries, misaligned) = {
            let st = twin.state();
            (st.exception_entries, st.frames_not_8_aligned)
        };
        twin.pend_irq(28);
        twin.run_ticks(1).expect("run");
        let (n, frame) = twin.state().last_entry.expect("an exception entry");
        assert_eq!(n, 16 + 28, "{image:?}: the TIM2 handler");
        // 20 ms more in the idle loop with that SP: SysTick and the
        // tasks' interrupts come from there too.
        twin.run_ms(20).expect("run");
        let st = twin.state();
        let (entries, misaligned) = (
            st.exception_entries - entries,
            st.frames_not_8_aligned - misaligned,
        );
        eprintln!(
            "{image:?}: idle SP {:#x}; TIM2 frame at {frame:#x}; {entries} exception entries, \
             {misaligned} of them on a stack not 8-byte aligned; CCR {:#x}",
            sp - 4,
            twin.peek(0xE000_ED14)
        );
        assert_eq!(frame % 8, 0, "{image:?}: the TIM2 handler's stack");
        assert_eq!(
            misaligned, 0,
            "{image:?}: handlers entered on a 4-byte aligned stack"
        );
        let idle = twin
            .run_until(50, |t| {
                t.core == CoreState::Sleeping && t.state().nvic.active.is_empty()
            })
            .expect("run");
        assert!(idle, "{image:?}: back in the idle loop");
        assert_eq!(
            twin.reg(RegisterARM::SP),
            sp - 4,
            "{image:?}: SP after the returns"
        );
        twin.set_reg(RegisterARM::SP, sp).expect("SP");
        twin.run_ms(20).expect("run");
        assert_eq!(twin.resets.len(), 1, "{image:?}: {:?}", twin.resets);
        assert!(!twin.lockup(), "{image:?}: locked up");
    }
}
