//! The drum driver's RS-485 link in QEMU (docs/drive-link.md).
//!
//! The QEMU board's USART2 talks to a virtual ZLAC8015D on the host
//! (`qemu_tests::drive`), which reads the simulated drum's true speed
//! behind paper A's 118:1 gearbox and, on the Modbus command path, drives
//! it. The settings (format 5) come from a flash file written here with the
//! supervisor's own store. Expected values: eq. 7 in f64 on the simulator's
//! true ground speed (`machine_sim::reference`), the simulator's plant
//! count, hand-computed link timings — never the firmware's own numbers.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::path::PathBuf;
use std::time::Duration;

use machine_sim::reference::eq7_drum_speed;
use qemu_tests::{log_time_ms, sim_samples, Bench, BootOptions, SimSample};
use supervisor::drive_link::{CommandPath, DriveLinkSettings, DriverKind, FeedbackSource};
use supervisor::settings::Settings;

#[path = "support/pages.rs"]
mod pages;

/// A flash file holding `settings` (a saved format-5 record).
fn flash_with(name: &str, settings: &Settings) -> PathBuf {
    let path = std::env::temp_dir().join(format!("drive-link-{name}-{}.bin", std::process::id()));
    std::fs::write(&path, pages::pages_with(settings)).unwrap();
    path
}

/// Speed-Adaptive, 7 cm, Low 2, with the drive link as given.
fn settings(feedback: FeedbackSource, command: CommandPath, baud: u32) -> Settings {
    let mut s = Settings {
        gear: kinematics::consts::Gear::Low2,
        // See crates/supervisor/tests/drive_link.rs: distance-locked
        // placement oscillates on the read-back's delay.
        placement: supervisor::settings::Placement::SpeedFollowing,
        drive_link: DriveLinkSettings {
            feedback,
            command,
            kind: DriverKind::Zlac8015d,
            ..DriveLinkSettings::default()
        },
        ..Settings::default()
    };
    s.drive_link.generic.baud = baud;
    // The virtual driver's motor is geared 20:1 (qemu_tests::drive).
    s.drive_link.generic.micro_rpm_per_count = 5000;
    s
}

fn boot(name: &str, s: &Settings, baud: u32, scenario: &[&str], run_ms: u32) -> (Bench, PathBuf) {
    let flash = flash_with(name, s);
    let options = BootOptions {
        run_ms: Some(run_ms),
        flash: Some(flash.clone()),
        scenario: scenario.iter().map(|w| w.to_string()).collect(),
        drive_baud: Some(baud),
        echo_logs: std::env::var_os("ECHO").is_some(),
        ..BootOptions::default()
    };
    let mut bench = Bench::boot(&options).expect("boot QEMU");
    assert!(
        bench
            .pump_until(Duration::from_secs(10), |s| s.page() == 1)
            .unwrap(),
        "the screen never reached the mode page"
    );
    (bench, flash)
}

/// Pumps to `t_ms` of firmware time (lock-step: exactly, whatever the
/// host's load).
fn pump_to(bench: &mut Bench, t_ms: u32) {
    let now = bench.fw.now_ms().expect("lock-step");
    if t_ms > now {
        bench
            .pump(Duration::from_millis(u64::from(t_ms - now)))
            .unwrap();
    }
}

/// Pumps to the end of the run; the log and the virtual driver's
/// transactions.
fn run_to_end(mut bench: Bench) -> (Vec<String>, Vec<qemu_tests::drive::Transaction>) {
    let deadline = std::time::Instant::now() + Duration::from_secs(600);
    while std::time::Instant::now() < deadline {
        bench.pump(Duration::from_millis(500)).unwrap();
        if bench.fw.logs().iter().any(|l| l.contains("run limit of")) {
            break;
        }
    }
    let (log, unmatched) = bench
        .fw
        .drive()
        .map(|d| (d.log.clone(), d.unmatched))
        .unwrap_or_default();
    // Every request the firmware sent met its end in the truth records (a
    // busy host must not drop one).
    assert_eq!(
        unmatched, 0,
        "requests without their end, or ends without their request"
    );
    let (status, logs) = bench.fw.wait_exit(Duration::from_secs(60)).unwrap();
    assert!(status.success(), "QEMU: {status}");
    (logs, log)
}

/// At `at_ms` of firmware time: Speed-Adaptive and Start, then to the end
/// of the run; the log (the flash file removed).
fn start_adaptive_and_run(mut bench: Bench, at_ms: u32, flash: &std::path::Path) -> Vec<String> {
    pump_to(&mut bench, at_ms);
    bench.tap("badapt").unwrap();
    bench.tap("bstart").unwrap();
    let (logs, _) = run_to_end(bench);
    let _ = std::fs::remove_file(flash);
    logs
}

/// No alarm in the log.
fn assert_no_alarm(logs: &[String]) {
    assert!(
        !logs.iter().any(|l| l.contains("alarm: ")),
        "an alarm: {:?}",
        logs.iter().find(|l| l.contains("alarm: "))
    );
}

fn time_of(logs: &[String], needle: &str) -> u32 {
    logs.iter()
        .find(|l| l.contains(needle))
        .and_then(|l| log_time_ms(l))
        .unwrap_or_else(|| panic!("no log line with {needle:?}"))
}

/// Worst relative error of the true drum speed against eq. 7 on the true
/// ground speed, over `from..=to` ms.
fn worst_tracking(samples: &[SimSample], from: u32, to: u32) -> (f64, u32) {
    let mut worst = (0.0, 0);
    for s in samples.iter().filter(|s| s.t_ms >= from && s.t_ms <= to) {
        let target = eq7_drum_speed(s.ground_m_s, 0.07);
        let err = (s.drum_rpm - target).abs() / target;
        if err > worst.0 {
            worst = (err, s.t_ms);
        }
    }
    worst
}

/// Read-back only (no encoder), PWM or Modbus command: the drum tracks
/// eq. 7 within 1 % once settled (2 s after Start; 3 s for the Modbus
/// command at 9600 baud, whose Start overshoots: docs/drive-link.md).
fn tracks_eq7(name: &str, command: CommandPath, baud: u32) -> f64 {
    let s = settings(FeedbackSource::Driver, command, baud);
    // Noiseless machine at Low 2 whose chassis pulls away with a 2.5 s
    // time constant (as the encoder's test in profile_a.rs); the encoder
    // is cut at boot (`enc_loss=1`): the read-back is the only feedback.
    let (bench, flash) = boot(
        name,
        &s,
        baud,
        &["gear=2", "noise=0", "tau=2500", "enc_loss=1"],
        17_000,
    );
    let logs = start_adaptive_and_run(bench, 8_000, &flash);
    assert!(logs
        .iter()
        .any(|l| l.contains("sim: encoder loss injected")));
    let start = time_of(&logs, "drum: Running");
    assert_no_alarm(&logs);
    let settle = if command == CommandPath::Modbus && baud == 9600 {
        3_000
    } else {
        2_000
    };
    let samples = sim_samples(&logs);
    let (worst, at) = worst_tracking(&samples, start + settle, start + settle + 5_500);
    let log_path = std::env::temp_dir().join(format!("{name}-{}.log", std::process::id()));
    if worst > 0.01 {
        let _ = std::fs::write(&log_path, logs.join("\n"));
    }
    eprintln!("{name}: worst {:.3} %", worst * 100.0);
    assert!(
        worst <= 0.01,
        "worst {:.2} % at {at} ms (start {start} ms), log {}",
        worst * 100.0,
        log_path.display()
    );
    worst
}

#[test]
fn readback_only_tracks_eq7_within_1_percent_at_9600_and_115200_and_with_the_modbus_command() {
    // The Modbus command at 9600 baud failed here before the read-back's
    // age allowance followed the baud rate (DriveLinkSettings::
    // readback_max_age_us): a read-back 100+ ms old was dropped, the drum
    // measured at 0 for a period, the command jumped +51 % (41.9 r/min for
    // 27.7) and the instability warning tripped at 15.6 s.
    for (baud, command) in [
        (9600, CommandPath::Pwm),
        (115_200, CommandPath::Pwm),
        (115_200, CommandPath::Modbus),
        (9600, CommandPath::Modbus),
    ] {
        tracks_eq7(&format!("rb-{command:?}-{baud}"), command, baud);
    }
}

/// Row length, m: 70 m / 7 cm = 1000 plants.
const ROW_M: f64 = 70.0;

/// Issue 17's 70 m row with the read-back as the only drum feedback:
/// Speed-Adaptive, 7 cm, Low 2, in the default distance-locked placement
/// (the tracking tests above use speed-following, whose drum follows eq. 7
/// alone), with the full noise model (terrain, slip variation, tooth
/// errors, seedling load: profile_a.rs's 70 m row on the encoder) and the
/// encoder cut at boot. Expected: 70 m / 7 cm = 1000 plants within ±0.5 %,
/// counted by the simulator (its true ground position and the plants its
/// belt dropped, `sim:` lines every 100 ms, so ± one sample ≈ 14 mm) from
/// the first sample after "drum: Running" to the one 70 m further on, and
/// no alarm (before the phase correction was smoothed through the link,
/// the instability warning tripped in 6 of 80 such rows on the host rig:
/// `PHASE_SMOOTHING` in crates/supervisor/src/control.rs). About 510 s of
/// machine time (Low 2 makes about 0.137 m/s on this terrain), about a
/// minute here in lock-step.
fn row_70m(name: &str, command: CommandPath, baud: u32) {
    let mut s = settings(FeedbackSource::Driver, command, baud);
    s.placement = supervisor::settings::Placement::DistanceLocked;
    let (bench, flash) = boot(name, &s, baud, &["gear=2", "enc_loss=1"], 548_000);
    let logs = start_adaptive_and_run(bench, 8_000, &flash);
    assert!(logs
        .iter()
        .any(|l| l.contains("sim: encoder loss injected")));
    assert_no_alarm(&logs);
    let start = time_of(&logs, "drum: Running");
    let samples = sim_samples(&logs);
    let first = samples
        .iter()
        .find(|s| s.t_ms >= start)
        .expect("samples after Start");
    let end = samples
        .iter()
        .find(|s| s.ground_m - first.ground_m >= ROW_M)
        .expect("the row reached 70 m");
    let plants = f64::from(end.plants - first.plants);
    let expected = (ROW_M / 0.07).round();
    let error = (plants - expected) / expected;
    eprintln!(
        "{name}: {plants} plants of {expected} ({:+.2} %) in {:.0} s",
        error * 100.0,
        f64::from(end.t_ms - first.t_ms) / 1000.0
    );
    assert!(
        error.abs() <= 0.005,
        "{plants} plants of {expected} ({:+.2} %)",
        error * 100.0
    );
}

#[test]
fn a_70_m_row_on_the_readback_with_pwm_at_9600_baud_gets_its_1000_plants() {
    row_70m("row-pwm-9600", CommandPath::Pwm, 9600);
}

#[test]
fn a_70_m_row_on_the_readback_with_pwm_at_115200_baud_gets_its_1000_plants() {
    row_70m("row-pwm-115200", CommandPath::Pwm, 115_200);
}

#[test]
fn a_70_m_row_on_the_readback_with_the_modbus_command_at_9600_baud_gets_its_1000_plants() {
    row_70m("row-modbus-9600", CommandPath::Modbus, 9600);
}

#[test]
fn a_70_m_row_on_the_readback_with_the_modbus_command_at_115200_baud_gets_its_1000_plants() {
    row_70m("row-modbus-115200", CommandPath::Modbus, 115_200);
}

/// Runs read-back only at `baud` to 11 s (Start at 2 s), does `act` on the
/// virtual driver, runs to 14 s; the log, and the firmware time of the act.
fn fault_run(
    name: &str,
    baud: u32,
    scenario: &[&str],
    act: impl FnOnce(&mut qemu_tests::drive::DriveBench),
) -> (Vec<String>, u32) {
    let s = settings(FeedbackSource::Driver, CommandPath::Pwm, baud);
    let mut words = vec!["gear=2", "noise=0", "enc_loss=1"];
    words.extend_from_slice(scenario);
    let (mut bench, flash) = boot(name, &s, baud, &words, 14_000);
    pump_to(&mut bench, 2_000);
    bench.tap("badapt").unwrap();
    bench.tap("bstart").unwrap();
    pump_to(&mut bench, 11_000);
    let at_ms = {
        let mut d = bench.fw.drive().unwrap();
        act(&mut d);
        d.now_us / 1000
    };
    let (logs, _) = run_to_end(bench);
    let _ = std::fs::remove_file(&flash);
    (logs, at_ms)
}

/// The first `sim:` sample at or after `t_ms` and its compare value.
fn ccr_after(logs: &[String], t_ms: u32) -> (u32, u32) {
    sim_samples(logs)
        .iter()
        .find(|s| s.t_ms >= t_ms)
        .map(|s| (s.t_ms, s.ccr))
        .expect("a sim sample")
}

#[test]
fn an_injected_driver_fault_gives_its_named_alarm_and_safe_outputs() {
    // Over-current (0x0004) from 11 s.
    let (logs, at) = fault_run("fault", 115_200, &[], |d| d.driver.fault_bits = 0x0004);
    let alarm = time_of(&logs, "alarm: DriverFault(OverCurrent)");
    eprintln!("fault at {at} ms, alarm at {alarm} ms");
    // The fault word is read every 6th poll (6 × 9.3 ms at 115 200 baud),
    // plus the gate's period and a control period.
    let every = u32::from(drive_link::link::FAULT_POLL_EVERY);
    assert!(
        alarm >= at && alarm - at <= every * 10 + 20 + 10,
        "{at} -> {alarm}"
    );
    let (t, ccr) = ccr_after(&logs, alarm + 1);
    assert_eq!(ccr, 0, "PWM at {t} ms");
}

#[test]
fn a_cut_link_is_lost_within_the_retry_budget_with_safe_outputs() {
    let (logs, at) = fault_run("cut", 115_200, &[], |d| d.driver.inject.silent = true);
    let lost = time_of(&logs, "drive link: lost: no reply after the retries");
    let alarm = time_of(&logs, "alarm: LinkLost");
    eprintln!("cut at {at} ms, lost at {lost} ms, alarm at {alarm} ms");
    // Hand formula at 115 200 baud with the default timing: 3 × (request
    // 0.77 ms + reply timeout 62.61 ms + retry gap 20 ms) + one poll cycle
    // 9.3 ms = 259.4 ms, + 10 ms of the gate.
    let c = drive_link::link::LinkConfig::for_baud(115_200).unwrap();
    let attempt_ms = f64::from(c.failed_attempt_us()) / 1000.0;
    let bound = (3.0 * attempt_ms + 9.3 + 10.0).ceil() as u32;
    assert!(
        lost >= at && lost - at <= bound,
        "cut {at} -> lost {lost}, bound {bound}"
    );
    // Outputs safe at the next control step (≤ 100 ms required).
    assert!(alarm - lost <= 10, "lost {lost} -> alarm {alarm}");
    let (t, ccr) = ccr_after(&logs, alarm + 1);
    assert_eq!(ccr, 0, "PWM at {t} ms");
}

/// A generic profile naming a speed register the driver does not have
/// (0x2AB0 typed for the ZLAC8015D's 0x20AB): the virtual driver refuses
/// each read with exception 2. From power-up the log names the request
/// and the exception, and the screen's alarm page says to check the
/// profile, not the wiring; within the retry budget, outputs off.
#[test]
fn a_refused_register_is_named_on_the_screen_and_in_the_log() {
    let mut s = settings(FeedbackSource::Driver, CommandPath::Pwm, 115_200);
    s.drive_link.kind = DriverKind::Generic;
    s.drive_link.generic.speed_feedback = 0x2AB0;
    let (mut bench, flash) = boot("refused", &s, 115_200, &["gear=2", "noise=0"], 3_500);
    pump_to(&mut bench, 2_000);
    let text = bench.screen.text("talarm").map(str::to_owned);
    let page = bench.screen.page();
    // OK while the driver still refuses: the supervisor keeps the alarm
    // ("Drum driver still not answering"). The screen had already left
    // page 5 for the page before (docs/hmi.md, page 5), and no page leads
    // back to it: the alarm page must come back, saying why (it stayed on
    // page 1 with Start refused, "Acknowledge the alarm first").
    bench.tap("bok").unwrap();
    pump_to(&mut bench, 2_600);
    let page_after_ok = bench.screen.page();
    let text_after_ok = bench.screen.text("talarm").map(str::to_owned);
    let (logs, _) = run_to_end(bench);
    let _ = std::fs::remove_file(&flash);
    let lost = time_of(
        &logs,
        "drive link: lost: the driver refuses function 3 on register 0x2ab0 (exception 2)",
    );
    let alarm = time_of(&logs, "alarm: LinkRefused");
    eprintln!("refused: lost at {lost} ms, alarm at {alarm} ms");
    // Three attempts at 115 200 baud (each < 4 ms: request, 2 ms turnaround,
    // exception reply, gap) after the first poll.
    assert!(lost <= 1_000, "{lost}");
    assert!(
        alarm >= lost && alarm - lost <= 10,
        "lost {lost} -> alarm {alarm}"
    );
    assert_eq!(page, hmi_proto::screen::Page::Alarm.id());
    assert_eq!(
        text.as_deref(),
        Some("Driver refuses register: check profile")
    );
    assert!(!logs.iter().any(|l| l.contains("alarm: LinkLost")));
    let (t, ccr) = ccr_after(&logs, alarm + 1);
    assert_eq!(ccr, 0, "PWM at {t} ms");
    assert_eq!(page_after_ok, hmi_proto::screen::Page::Alarm.id());
    assert_eq!(
        text_after_ok.as_deref(),
        Some("Drum driver still not answering")
    );
    assert!(!logs.iter().any(|l| l.contains("alarm acknowledged")));
}

#[test]
fn a_stalled_drum_gives_the_stall_alarm_from_the_readback() {
    let (logs, _) = fault_run("stall", 9600, &["stall=11000"], |_| {});
    let alarm = time_of(&logs, "alarm: DrumStall");
    eprintln!("stall at 11000 ms, alarm at {alarm} ms");
    // The stall is seen when the read-back (≤ 100 ms old) has shown 0 for
    // 200 ms (the stall time).
    assert!(
        alarm > 11_000 && alarm <= 11_000 + 200 + 100 + 30,
        "{alarm}"
    );
    let (t, ccr) = ccr_after(&logs, alarm + 1);
    assert_eq!(ccr, 0, "PWM at {t} ms");
}

#[test]
fn crc_errors_and_late_replies_are_survived() {
    let (logs, _) = fault_run("crc", 115_200, &[], |d| {
        d.driver.inject.corrupt_replies = 2;
        d.driver.inject.late_replies = 1;
        d.driver.inject.extra_delay_us = 25_000;
    });
    assert!(
        !logs
            .iter()
            .any(|l| l.contains("alarm: ") || l.contains("drive link: lost")),
        "{:?}",
        logs.iter()
            .find(|l| l.contains("alarm: ") || l.contains("lost"))
    );
    let last = sim_samples(&logs).last().copied().unwrap();
    assert!(last.ccr > 0 && last.drum_rpm > 20.0, "{last:?}");
}
