//! Instruction counts of the control code on the Cortex-M3 ISA.
//!
//! Run by `cargo xtask bench` in `qemu-system-arm -machine netduino2
//! -icount shift=0`: every guest instruction then advances virtual time by
//! exactly 1 ns, and SysTick (on the core's clock, the machine's fixed
//! 120 MHz) counts virtual time, so one SysTick tick is 8⅓ instructions
//! (the counts do not depend on the clock). Each case runs `N` times
//! over varying inputs; the cost of the loop and of fetching the inputs,
//! measured with an empty body, is subtracted. Results are printed over
//! semihosting as `cost <name> <instructions per call ×10>` lines.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use fuzzy_pid::{Config, FuzzyConfig, FuzzyTuner, LutTuner, RuleBaseSize, Schedule, I16F16};

/// SysTick's clock, MHz: QEMU's `netduino2` runs its core at 120 MHz.
const SYSTICK_MHZ: u64 = 120;

/// Calls per case.
const N: u32 = 1024;
/// Varying inputs: drum speeds in r/min spread over and beyond the domains.
const INPUTS: usize = 64;

fn inputs() -> [(I16F16, I16F16); INPUTS] {
    let mut out = [(I16F16::ZERO, I16F16::ZERO); INPUTS];
    let mut x: u32 = 0x1234_5678;
    for slot in out.iter_mut() {
        // xorshift32
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        let a = I16F16::from_bits((x & 0x001F_FFFF) as i32); // 0..32 r/min
        let b = I16F16::from_bits(((x >> 11) & 0x001F_FFFF) as i32);
        *slot = (a, b);
    }
    out
}

/// SysTick ticks spent running `f` for `N` inputs.
fn ticks(inputs: &[(I16F16, I16F16); INPUTS], mut f: impl FnMut(I16F16, I16F16)) -> u32 {
    let start = SYST::get_current();
    for i in 0..N {
        let (a, b) = inputs[(i as usize) % INPUTS];
        f(black_box(a), black_box(b));
    }
    let end = SYST::get_current();
    // Down-counter, 24 bits.
    start.wrapping_sub(end) & 0x00FF_FFFF
}

/// Prints instructions per call ×10 (1 tick = 1000 / [`SYSTICK_MHZ`]
/// instructions).
fn report(name: &str, ticks: u32, baseline: u32) {
    let net = u64::from(ticks.saturating_sub(baseline));
    let per_call_x10 = net * 10_000 / SYSTICK_MHZ / u64::from(N);
    hprintln!("cost {} {}", name, per_call_x10);
}

/// One controller step (error, error change, gain schedule, PID, limits),
/// built and measured in its own stack frame.
#[inline(never)]
fn step_cost(
    name: &str,
    inputs: &[(I16F16, I16F16); INPUTS],
    baseline: u32,
    config: impl FnOnce() -> Config,
) {
    // Note(unwrap): the paper's configurations are valid.
    let mut pid = config().build().unwrap();
    pid.start();
    let ff = I16F16::from_num(20);
    let t = ticks(inputs, |target, measured| {
        black_box(pid.step(target, measured, ff));
    });
    report(name, t, baseline);
}

/// Fuzzy inference alone, built and measured in its own stack frame.
#[inline(never)]
fn infer_cost(name: &str, inputs: &[(I16F16, I16F16); INPUTS], baseline: u32, size: RuleBaseSize) {
    // Note(unwrap): the paper's tables are valid configuration.
    let tuner = FuzzyTuner::new(&FuzzyConfig::paper(size)).unwrap();
    let offset = I16F16::from_num(16);
    let t = ticks(inputs, |e, ec| {
        black_box(tuner.infer(e - offset, ec - offset));
    });
    report(name, t, baseline);
}

/// Lookup-table inference alone.
#[inline(never)]
fn lut_cost(name: &str, inputs: &[(I16F16, I16F16); INPUTS], baseline: u32) {
    // Note(unwrap): the paper's tables are valid configuration.
    let lut = LutTuner::new(&FuzzyConfig::paper(RuleBaseSize::Seven)).unwrap();
    let offset = I16F16::from_num(16);
    let t = ticks(inputs, |e, ec| {
        black_box(lut.infer(e - offset, ec - offset));
    });
    report(name, t, baseline);
}

/// The two big controllers the bench runs one after the other share one
/// static slot: the lookup-table controller (1.4 KB) and the product's
/// supervisor (≈ 1.9 KB), built in place (the way the figures of
/// docs/PERFORMANCE.md §5 are measured).
// Boxing is not available (no heap); the size difference is the point.
#[allow(clippy::large_enum_variant)]
enum Slot {
    Empty,
    Lut(fuzzy_pid::LutController),
    Supervisor(supervisor::drum::Supervisor),
}

/// Builds the lookup-table controller into `slot` (a frame of its own).
#[inline(never)]
fn fill_lut(slot: &mut Slot) {
    let config = Config::with_schedule(Schedule::Lookup(FuzzyConfig::paper(RuleBaseSize::Seven)));
    *slot = config.build_lut().map_or(Slot::Empty, Slot::Lut);
}

/// The lookup-table controller's step.
#[inline(never)]
fn lut_step_cost(slot: &mut Slot, inputs: &[(I16F16, I16F16); INPUTS], baseline: u32) {
    fill_lut(slot);
    let Slot::Lut(pid) = slot else {
        hprintln!("pid_step_lut_7x7: the paper's tables were rejected");
        return;
    };
    pid.start();
    let ff = I16F16::from_num(20);
    let t = ticks(inputs, |target, measured| {
        black_box(pid.step(target, measured, ff));
    });
    report("pid_step_lut_7x7", t, baseline);
}

/// Builds the product's supervisor into `slot` (a frame of its own).
#[inline(never)]
fn fill(slot: &mut Slot) {
    *slot = supervisor::drum::Supervisor::new(
        supervisor::drum::Hardware::BOARD,
        supervisor::settings::Settings::default(),
    )
    .map_or(Slot::Empty, Slot::Supervisor);
}

/// The whole control step of the product (`Supervisor::control_step`):
/// Hall estimator update, travel speed, eq. 7 target, the feed-forward and
/// fuzzy PID on the drum model, fault checks, plants and distance. Speed-
/// Adaptive, running, 7 cm, at Low 2: a Hall edge every 177 ms and 160
/// encoder counts per period (about 20 r/min), as on the machine.
#[inline(never)]
fn control_step_cost(slot: &mut Slot, baseline_per_call_x10: u64) {
    use hmi_proto::screen::Command;
    use kinematics::units::Ticks;
    // The supervisor is built in its own frame straight into the slot.
    fill(slot);
    let Slot::Supervisor(sup) = slot else {
        hprintln!("control_step: the default settings were rejected");
        return;
    };
    let mut now: u32 = 0;
    let mut next_edge: u32 = 0;
    let mut encoder: u16 = 0;
    // Warm up: the estimator needs edges and a learnt revolution.
    for _ in 0..3_000 {
        now = now.wrapping_add(10_000);
        while next_edge.wrapping_sub(now) > u32::MAX / 2 {
            sup.hall_edge(Ticks(next_edge));
            next_edge = next_edge.wrapping_add(177_000);
        }
        encoder = encoder.wrapping_add(160);
        black_box(sup.control_step(Ticks(now), encoder));
        if now == 1_000_000 {
            sup.command(Command::Start);
        }
    }
    let start = SYST::get_current();
    for _ in 0..N {
        now = now.wrapping_add(10_000);
        while next_edge.wrapping_sub(now) > u32::MAX / 2 {
            sup.hall_edge(Ticks(next_edge));
            next_edge = next_edge.wrapping_add(177_000);
        }
        encoder = encoder.wrapping_add(160);
        black_box(sup.control_step(Ticks(black_box(now)), black_box(encoder)));
    }
    let end = SYST::get_current();
    let ticks = u64::from(start.wrapping_sub(end) & 0x00FF_FFFF);
    let per_call_x10 =
        (ticks * 10_000 / SYSTICK_MHZ / u64::from(N)).saturating_sub(baseline_per_call_x10);
    hprintln!("cost control_step {}", per_call_x10);
}

/// The hmi task's heaviest wake, and more: a touch frame decoded
/// (Speed-Adaptive on page 1), the page change it makes (page 3 with its
/// settings values), the live status of that page at its widest, and every
/// byte moved out of the link (as `firmware/src/screen_line.rs` moves them
/// to the transmit ring): 379 bytes; plus the page change back to page 1
/// that sets up the next call. The link is built in a frame of its own
/// (≈ 0.7 KB).
#[inline(never)]
fn hmi_wake_cost(baseline_per_call_x10: u64) {
    use hmi_proto::hmi::Hmi;
    use hmi_proto::screen::{Page, Settings, Status};
    let mut hmi = Hmi::new(Settings::default(), "bench");
    hmi.tick(0);
    hmi.push_slice(&[0x88, 0xFF, 0xFF, 0xFF]);
    while hmi.pop_tx().is_some() {}
    while hmi.poll_event().is_some() {}
    let status = Status {
        travel_speed_kmh_x100: u16::MAX,
        target_drum_rpm_x100: u16::MAX,
        actual_drum_rpm_x100: u16::MAX,
        plants: u32::MAX,
        distance_dm: u32::MAX,
        quality_of_feed_x10: u16::MAX,
        multiples_x10: u16::MAX,
        misses_x10: u16::MAX,
        precision_cv_x10: u16::MAX,
        within_10_pct_x10: u16::MAX,
        plants_per_m_x100: u16::MAX,
        ..Status::default()
    };
    let mut moved = 0u32;
    let start = SYST::get_current();
    for i in 0..N {
        let _ = hmi.show_page(Page::Mode);
        while hmi.pop_tx().is_some() {}
        for b in [0x65, 0x01, 0x02, 0x00, 0xFF, 0xFF, 0xFF] {
            hmi.push_at(black_box(b), i);
        }
        hmi.tick(black_box(i));
        while let Some(e) = hmi.poll_event() {
            black_box(e);
        }
        let _ = hmi.write_status(black_box(&status));
        while let Some(b) = hmi.pop_tx() {
            moved = moved.wrapping_add(u32::from(black_box(b)));
        }
    }
    let end = SYST::get_current();
    black_box(moved);
    let ticks = u64::from(start.wrapping_sub(end) & 0x00FF_FFFF);
    let per_call_x10 =
        (ticks * 10_000 / SYSTICK_MHZ / u64::from(N)).saturating_sub(baseline_per_call_x10);
    hprintln!("cost hmi_wake {}", per_call_x10);
}

#[entry]
fn main() -> ! {
    // Note(unwrap): taken once at the top of the program.
    let mut cp = cortex_m::Peripherals::take().unwrap();
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00FF_FFFF);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();

    let inputs = inputs();
    let baseline = ticks(&inputs, |a, b| {
        black_box((a, b));
    });
    hprintln!("baseline {}", baseline);

    infer_cost("fuzzy_infer_3x3", &inputs, baseline, RuleBaseSize::Three);
    infer_cost("fuzzy_infer_5x5", &inputs, baseline, RuleBaseSize::Five);
    infer_cost("fuzzy_infer_7x7", &inputs, baseline, RuleBaseSize::Seven);
    lut_cost("lut_infer_7x7", &inputs, baseline);

    let fuzzy = |size| Config::with_schedule(Schedule::Fuzzy(FuzzyConfig::paper(size)));
    step_cost("pid_step_conventional", &inputs, baseline, || {
        Config::conventional(fuzzy_pid::pid::PAPER_BASE)
    });
    step_cost("pid_step_fuzzy_3x3", &inputs, baseline, || {
        fuzzy(RuleBaseSize::Three)
    });
    step_cost("pid_step_fuzzy_5x5", &inputs, baseline, || {
        fuzzy(RuleBaseSize::Five)
    });
    step_cost("pid_step_fuzzy_7x7", &inputs, baseline, Config::default);
    // Note(unwrap): taken once.
    let slot: &'static mut Slot = cortex_m::singleton!(: Slot = Slot::Empty).unwrap();
    lut_step_cost(slot, &inputs, baseline);

    // The loop overhead of `ticks` (per call ×10) stands in for the control
    // loop's own bookkeeping.
    control_step_cost(
        slot,
        u64::from(baseline) * 10_000 / SYSTICK_MHZ / u64::from(N),
    );
    hmi_wake_cost(u64::from(baseline) * 10_000 / SYSTICK_MHZ / u64::from(N));

    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
