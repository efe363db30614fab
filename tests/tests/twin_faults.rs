//! The real board's safe states on the twin (issue 15): faults injected as a
//! debug probe would inject them, the pins watched as a scope would watch
//! them.
//!
//! Safe state (docs/firmware.md, decisions of issue 15): PA8 (drum PWM /
//! planting step) driven low — not floating — and PB12 (driver enable) low.
//!
//! How each fault is injected (a probe halts the core, changes registers,
//! resumes):
//! - panic: the PC is set to the image's `#[panic_handler]`
//!   (`rust_begin_unwind`), as if a `panic!` had been reached where the core
//!   was;
//! - HardFault: the PC is set beyond the 20 KB of SRAM (0x2000_5000): the
//!   instruction fetch is a bus error, escalated to HardFault;
//! - stack overflow: SP is set 16 bytes above the stack's bottom (flip-link
//!   puts it at the start of RAM, 0x2000_0000) and an enabled interrupt
//!   (TIM2) is pended: its exception entry stacks below RAM.

use twin::plant::Wiring;
use twin::RegisterARM;
use twin::{CoreState, External, Level, Options, ResetCause, Twin, TICKS_PER_S};

const US: u64 = TICKS_PER_S / 1_000_000;

fn boot_a(options: Options) -> Twin {
    let elf = twin::image::elf().expect("build the real-board image");
    let mut twin = Twin::new(&elf, options).expect("load the ELF");
    let machine = machine_sim::Config {
        initial_gear: Some(kinematics::consts::Gear::ALL[1]),
        ..machine_sim::Config::noiseless()
    }
    .build()
    .expect("machine");
    twin.attach_plant(machine, Wiring::ProfileA);
    twin.connect_screen();
    assert!(
        twin.run_until_screen(3000, |s| s.page() == 1).unwrap(),
        "the screen never reached the mode page"
    );
    twin
}

/// Profile A with the drum running in Fixed mode (PWM on PA8, PB12 high).
fn running_drum() -> Twin {
    let mut twin = boot_a(Options::default());
    twin.tap("bfixed").unwrap();
    twin.tap("bstart").unwrap();
    twin.run_ms(500).unwrap();
    assert_eq!(twin.pin('B', 12), Level::High, "the drum driver is enabled");
    assert!(twin.state().bus.tim[0].ccr_act[0] > 0, "the drum PWM runs");
    twin
}

/// Firmware time from now until PA8 and PB12 are both driven low and stay
/// so (checked every µs for 200 µs, four PWM periods), within 5 ms; `None`
/// if that never happens before a reset.
fn time_to_safe(twin: &mut Twin) -> Option<f64> {
    let t0 = twin.now();
    let resets = twin.resets.len();
    while twin.now() - t0 < 5_000 * US {
        if twin.pin('A', 8) == Level::Low && twin.pin('B', 12) == Level::Low {
            let at = twin.now();
            let mut held = true;
            for _ in 0..200 {
                twin.run_ticks(US).unwrap();
                if twin.pin('A', 8) != Level::Low || twin.pin('B', 12) != Level::Low {
                    held = false;
                    break;
                }
            }
            if held {
                return Some((at - t0) as f64 / US as f64);
            }
        }
        twin.run_ticks(US).unwrap();
        if twin.resets.len() != resets {
            return None;
        }
    }
    None
}

fn assert_safe(twin: &mut Twin, what: &str) {
    let t = time_to_safe(twin);
    let pins = (twin.pin('A', 8), twin.pin('B', 12));
    eprintln!(
        "{what}: safe pins after {t:?} µs (core {:?}, PA8/PB12 {pins:?})",
        twin.core
    );
    let t = t.unwrap_or_else(|| {
        panic!(
            "{what}: PA8/PB12 not both driven low within 5 ms: {pins:?}, core {:?}",
            twin.core
        )
    });
    // Immediately: well within one PWM period … a tenth of a control period.
    assert!(t <= 1000.0, "{what}: {t} µs to safe pins");
    // And they stay safe until the watchdog resets the board.
    for _ in 0..50 {
        twin.run_ms(1).unwrap();
        if twin.resets.len() > 1 {
            break;
        }
        assert_eq!(twin.pin('A', 8), Level::Low, "{what}: PA8 later");
        assert_eq!(twin.pin('B', 12), Level::Low, "{what}: PB12 later");
    }
}

#[test]
fn panic_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    let (handler, _) = twin
        .symbol_like(&["rust_begin_unwind"])
        .expect("the panic handler");
    // r0 = &PanicInfo: any readable RAM (the real board does not read it).
    twin.set_reg(RegisterARM::R0, twin::RAM_BASE + 0x1000)
        .unwrap();
    twin.jump(handler).unwrap();
    assert_safe(&mut twin, "panic");
}

#[test]
fn hardfault_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    // Fetch from beyond SRAM (0x2000_0000 + 20 KB): a bus error.
    twin.jump(twin::RAM_BASE + twin::RAM_SIZE).unwrap();
    assert_safe(&mut twin, "HardFault");
}

#[test]
fn stack_overflow_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    let (stack_end, _) = twin.symbol("_stack_end").expect("flip-link's stack bottom");
    twin.set_reg(RegisterARM::SP, stack_end + 16).unwrap();
    twin.pend_irq(28); // TIM2, enabled at priority 3
    twin.core = CoreState::Running;
    assert_safe(&mut twin, "stack overflow");
}

/// An enabled interrupt without a handler of its own (WWDG, IRQ 0, enabled
/// and pended by the probe) ends in the default handler.
#[test]
fn an_unused_interrupt_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    twin.state_mut().nvic.enabled[0] |= 1;
    twin.pend_irq(0);
    assert_safe(&mut twin, "unused interrupt");
}

/// NMI (the probe sets ICSR.NMIPENDSET; on the board the clock security
/// system raises it when the crystal fails).
#[test]
fn an_nmi_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    twin.state_mut().nvic.set_pending(2);
    assert_safe(&mut twin, "NMI");
}

/// The crystal fails while the drum runs (decision of issue 15: the clock
/// security system is on; its NMI drives the outputs safe and ends in the
/// fatal state). Without CSS the core loses its clock with the PWM as it
/// was.
#[test]
fn a_crystal_failing_while_running_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    twin.fail_crystal();
    assert_safe(&mut twin, "crystal failure");
}

/// A probe halts the core while the drum runs (issue 15 item 7): with
/// DBGMCU_CR DBG_TIM1_STOP (and TIM4's) the counter stops and TIM1's outputs
/// are disabled as on a break (RM0008 §31.16.3): PA8 must not go on
/// pulsing, and must not float with the driver enabled.
#[test]
fn a_debug_halt_stops_the_drum_pwm() {
    let mut twin = running_drum();
    twin.debug_halt(true);
    let mut levels = Vec::new();
    for _ in 0..200 {
        twin.run_ticks(US).unwrap();
        levels.push(twin.pin('A', 8));
    }
    let enable = twin.pin('B', 12);
    twin.debug_halt(false);
    let pulsing = levels.windows(2).any(|w| w[0] != w[1]);
    eprintln!(
        "debug halt: PA8 {:?}…, PB12 {enable:?}, pulsing {pulsing}",
        &levels[..3]
    );
    assert!(!pulsing, "PA8 goes on pulsing while the core is halted");
    assert!(
        levels[0] == Level::Low || enable == Level::Low,
        "PA8 {:?} with the driver enabled ({enable:?})",
        levels[0]
    );
}

/// Hall edges captured while TIM2's interrupt cannot run (the probe masks
/// it for half a second, NVIC_ICER): the second capture sets CC1OF (RM0008
/// §15.4.5); the firmware must count the lost edges (issue 15 item 6).
#[test]
fn hall_overcaptures_are_counted() {
    let mut twin = running_drum();
    let edges0 = twin.plant.as_ref().unwrap().edges_delivered;
    twin.state_mut().nvic.enabled[0] &= !(1 << 28);
    twin.run_ms(500).unwrap();
    twin.state_mut().nvic.enabled[0] |= 1 << 28;
    twin.run_ms(1500).unwrap();
    let edges = twin.plant.as_ref().unwrap().edges_delivered - edges0;
    let over = twin.state().bus.tim[1].overcaptures;
    let lost = twin.static_u32("HALL_EDGES_LOST");
    eprintln!("Hall: {edges} edges, {over} overcaptures, firmware counted {lost:?} lost");
    assert!(over > 0, "the test produced no overcapture ({edges} edges)");
    assert!(
        lost.is_some_and(|n| n > 0),
        "the firmware did not count the lost Hall edges: {lost:?}"
    );
}

/// The stop input (PB10, a normally-closed contact to ground with the
/// internal pull-up): the contact opens while the drum runs.
#[test]
fn opening_the_stop_contact_drives_pa8_and_pb12_low() {
    let mut twin = running_drum();
    twin.set_external('B', 10, External::Open);
    assert_safe(&mut twin, "stop input");
    // Closing the contact again does not restart the drum by itself.
    twin.set_external('B', 10, External::Low);
    twin.run_ms(200).unwrap();
    assert_eq!(twin.pin('B', 12), Level::Low, "latched until Start");
}

/// The control task's dispatcher: the enabled one of RTIC's dispatchers
/// (CAN_RX1 21, CAN_SCE 22, ADC1_2 18) at priority 2, (16 − 2) << 4
/// (PM0056 §4.2.7).
fn control_dispatcher(twin: &Twin) -> u32 {
    [21u32, 22, 18]
        .into_iter()
        .find(|&irq| {
            let ipr = (twin.peek(0xE000_E400 + (irq & !3)) >> (8 * (irq % 4))) & 0xFF;
            ipr == (16 - 2) << 4
        })
        .expect("a dispatcher at priority 2")
}

/// IWDG timeout from its registers (RM0008 §19.3): 4·2^PR·(RLR + 1) / LSI.
fn iwdg_timeout_s(twin: &Twin, lsi_hz: f64) -> f64 {
    let pr = twin.peek(0x4000_3004);
    let rlr = twin.peek(0x4000_3008);
    4.0 * f64::from(1u32 << pr) * f64::from(rlr + 1) / lsi_hz
}

/// From a run page: the settings page, Save, confirmed on the screen.
fn save(twin: &mut Twin) {
    twin.tap("bback").unwrap();
    twin.tap("bset").unwrap();
    twin.tap("bsave").unwrap();
    assert!(
        twin.run_until_screen(3000, |s| s.text("tmsg") == Some("Settings saved"))
            .unwrap(),
        "save not confirmed: {:?}",
        twin.screen
            .as_ref()
            .and_then(|s| s.text("tmsg").map(str::to_string))
    );
}

fn boots(logs: &[String]) -> usize {
    logs.iter()
        .filter(|l| l.contains("boot: transplanter"))
        .count()
}

#[test]
fn a_stopped_control_task_gets_the_board_reset_by_the_watchdog_and_it_comes_back_stopped_on_its_saved_settings(
) {
    let mut twin = boot_a(Options::default());
    // Saved settings that differ from the defaults: Fixed mode.
    twin.tap("bfixed").unwrap();
    save(&mut twin);
    twin.tap("bback").unwrap();
    twin.tap("bfixed").unwrap();
    twin.tap("bstart").unwrap();
    // A status line (1 Hz) of the running machine.
    twin.run_ms(1100).unwrap();
    assert_eq!(twin.pin('B', 12), Level::High, "running");
    let before = twin.log_lines("status: uptime");
    let mode = before
        .last()
        .and_then(|l| l.split(" ms, ").nth(1))
        .and_then(|r| r.split_whitespace().next())
        .expect("mode in the status line")
        .to_string();
    // The probe disables the control task's dispatcher: it never runs again.
    let irq = control_dispatcher(&twin);
    twin.state_mut().nvic.enabled[(irq / 32) as usize] &= !(1 << (irq % 32));
    let t0 = twin.now();
    let timeout = iwdg_timeout_s(&twin, twin.state().bus.iwdg.lsi_hz as f64);
    let reset = twin
        .run_until(2000, |t| {
            t.resets.iter().any(|r| r.1 == ResetCause::Watchdog)
        })
        .unwrap();
    assert!(reset, "no watchdog reset within 2 s");
    let t1 = twin
        .resets
        .iter()
        .find(|r| r.1 == ResetCause::Watchdog)
        .unwrap()
        .0;
    let dt = (t1 - t0) as f64 / TICKS_PER_S as f64;
    eprintln!(
        "watchdog reset {:.1} ms after the control task stopped (timeout {:.1} ms)",
        dt * 1e3,
        timeout * 1e3
    );
    // The last feed was at most one control period (10 ms) before the stop.
    assert!(
        dt <= timeout + 1e-4 && dt >= timeout - 0.010 - 1e-4,
        "{dt} s vs {timeout} s"
    );
    // Back: stopped, on the saved settings.
    twin.run_ms(1500).unwrap();
    let logs = twin.logs();
    assert_eq!(boots(&logs), 2, "booted twice");
    let after_boot: Vec<&String> = logs
        .iter()
        .skip_while(|l| !l.contains("boot: transplanter"))
        .skip(1)
        .skip_while(|l| !l.contains("boot: transplanter"))
        .collect();
    assert!(
        after_boot
            .iter()
            .any(|l| l.contains("settings: loaded record")),
        "the saved record was loaded after the reset"
    );
    assert!(!after_boot.iter().any(|l| l.contains("defaults in use")));
    let status = after_boot
        .iter()
        .rev()
        .find(|l| l.contains("status: uptime"))
        .expect("status after the reset");
    assert!(
        status.contains(&format!(" {mode} Stopped")),
        "{status} (mode {mode})"
    );
    assert_eq!(twin.pin('B', 12), Level::Low);
}

#[test]
fn hse_never_ready_keeps_the_outputs_safe_and_the_watchdog_retries() {
    let elf = twin::image::elf().expect("build the real-board image");
    let mut twin = Twin::new(
        &elf,
        Options {
            hse_dead: true,
            ..Options::default()
        },
    )
    .unwrap();
    let mut unsafe_samples = Vec::new();
    for ms in 0..1500u64 {
        twin.run_ms(1).unwrap();
        let since_reset = twin.now() - twin.resets.last().unwrap().0;
        // From 1 ms after each reset (the pins float in the reset state
        // until the first instructions drive them).
        if since_reset >= TICKS_PER_S / 1000 {
            // PWM, enable, and the RS-485 transceiver's driver-enable
            // (PA1: low releases the driver's bus).
            let pins = (twin.pin('A', 8), twin.pin('B', 12), twin.pin('A', 1));
            if pins != (Level::Low, Level::Low, Level::Low) && unsafe_samples.len() < 5 {
                unsafe_samples.push((ms, pins));
            }
        }
    }
    let wd = twin
        .resets
        .iter()
        .filter(|r| r.1 == ResetCause::Watchdog)
        .count();
    eprintln!("HSE dead: {wd} watchdog resets in 1.5 s; unsafe samples {unsafe_samples:?}");
    assert!(
        unsafe_samples.is_empty(),
        "outputs not safe: {unsafe_samples:?}"
    );
    assert!(wd >= 1, "the board never reset to retry the crystal");
}

#[test]
fn usart1_overrun_is_counted_and_the_link_recovers() {
    let mut twin = boot_a(Options::default());
    twin.tap("bfixed").unwrap();
    twin.tap("bback").unwrap();
    twin.tap("bset").unwrap();
    // Save (a page erase stalls the CPU for tERASE) while the line is busy:
    // bytes arrive faster than they can be read.
    twin.tap("bsave").unwrap();
    for _ in 0..100 {
        // A `sendme` answer (0x66 page) over and over: valid frames,
        // naming the page shown (6, settings). (A screen answering page 1
        // here would say page 1 is shown, and the operator's next touch on
        // page 6 would be ignored as another page's: docs/hmi.md §3.)
        let burst: Vec<u8> = [0x66u8, 0x06, 0xFF, 0xFF, 0xFF].repeat(12);
        twin.send_serial(0, &burst);
        twin.run_ms(5).unwrap();
    }
    let ore = twin.state().bus.usart[0].overruns;
    let counted = twin
        .static_u32("HMI_RX_ERRORS")
        .expect("stats::HMI_RX_ERRORS");
    eprintln!("overruns on the line {ore}, counted by the firmware {counted}");
    assert!(ore > 0, "the test produced no overrun");
    assert!(counted > 0, "the firmware did not count the overrun");
    // The link recovers: the save is confirmed and Start works.
    assert!(
        twin.run_until_screen(3000, |s| s.text("tmsg") == Some("Settings saved"))
            .unwrap(),
        "save confirmed"
    );
    twin.tap("bback").unwrap();
    twin.tap("bfixed").unwrap();
    twin.tap("bstart").unwrap();
    assert!(
        twin.run_until(1000, |t| t.pin('B', 12) == Level::High)
            .unwrap(),
        "Start after the overrun"
    );
}

/// The Stop's press on a flooded line while the firmware writes a page
/// change: the operator leaves page 2 with the drum running, taps
/// *Settings* on page 1 (the MCU writes page 6 and its values: 175 bytes,
/// 15 ms of line), and the screen answers every write with `1A FF FF FF`
/// (a screen file whose names are wrong), back to back, 40 frames before
/// and after the Stop's press (page 2's `bstop`, taken from any page).
/// The drum must stop within a control period or two of the press; no
/// received byte may be dropped. Before, the hmi task waited on the
/// transmitter for the whole page change: the 64-byte receive queue
/// overflowed under the flood, the press was lost, and the drum ran on
/// until the Stop's release.
#[test]
fn a_stop_press_on_a_flooded_line_during_a_page_change_stops_the_drum() {
    let mut twin = running_drum();
    twin.tap("bback").unwrap();
    twin.run_ms(300).unwrap();
    assert_eq!(twin.pin('B', 12), Level::High, "the drum runs on page 1");
    let dropped_before = twin.static_u32("HMI_RX_DROPPED").unwrap_or(0);
    let flood = [0x1Au8, 0xFF, 0xFF, 0xFF].repeat(40);
    // `bset` (page 1, id 4) released: the MCU shows page 6.
    let mut burst = vec![0x65, 0x01, 0x04, 0x00, 0xFF, 0xFF, 0xFF];
    burst.extend_from_slice(&flood);
    burst.extend_from_slice(&[0x65, 0x02, 0x04, 0x01, 0xFF, 0xFF, 0xFF]);
    burst.extend_from_slice(&flood);
    let t0 = twin.now();
    twin.send_serial(0, &burst);
    // The press's last stop bit, at 10 bits a byte.
    let char_ticks = TICKS_PER_S * 10 / 115_200;
    let press_end = t0 + (7 + 160 + 7) * char_ticks;
    let stopped = twin
        .run_until(300, |t| t.pin('B', 12) == Level::Low)
        .unwrap();
    let after_ms = (twin.now().saturating_sub(press_end)) as f64 * 1000.0 / TICKS_PER_S as f64;
    let dropped = twin.static_u32("HMI_RX_DROPPED").unwrap_or(0) - dropped_before;
    eprintln!(
        "drum disabled {after_ms:.1} ms after the Stop's press; {dropped} received bytes dropped"
    );
    assert!(stopped, "the drum ran on ({dropped} bytes dropped)");
    assert!(after_ms <= 25.0, "{after_ms:.1} ms");
    assert_eq!(dropped, 0);
}
