//! The drive link against an independent Modbus RTU slave: the ZLAC8015D
//! of `tests/peers/zlac8015d` (pymodbus 3.16.1, written from ZLTECH's RS485
//! Communication Instruction V1.06) on a `socat` pty pair, the master and
//! the supervisor (the code the firmware runs) on a simulated RS-485 line in
//! virtual time (`support/peer.rs`): answer times 0–50 ms, CRC errors,
//! dropped replies, noise bursts, exceptions, a fault under the speed
//! command, the clear after it, the speed resolution and the maximum speed.
//!
//! Judged in virtual time only; the peer's replies are awaited in real
//! time with a generous limit. Cost: about 9 000 request/reply exchanges
//! with the peer, a few seconds on an idle machine (docs/drive-link.md).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap,
    clippy::indexing_slicing,
    missing_docs
)]

#[path = "support/peer.rs"]
mod peer;

use drive_link::link::{Event, Link, LossCause, SetupFault, FAULT_POLL_EVERY};
use drive_link::profile::DriverFault;
use drive_link::timing::{frame_time_us, silent_interval_us};
use hmi_proto::screen::{Command, DrumSpeed, Mode};
use kinematics::units::Ticks;
use peer::{Faults, Line, Peer};
use serde_json::json;
use supervisor::drive_link::{
    CommandPath, DriveLinkSettings, DriverKind, FeedbackSource, LinkSample, ReadBack,
};
use supervisor::drum::{Actuation, Alarm, Hardware, RunState, Supervisor};
use supervisor::settings::Settings;

/// The tests' gearbox: 20:1 behind the ZLAC8015D (0.1 r/min of the motor
/// per feedback count: 100 000 / 20 = 5000 µr/min of the drum).
const SCALE: i32 = 5000;

/// The link settings: a ZLAC8015D behind 20:1 at `baud`, the read-back as
/// the feedback, the speed commanded over Modbus, the default timing.
fn link_settings(baud: u32) -> DriveLinkSettings {
    let mut s = DriveLinkSettings {
        feedback: FeedbackSource::Driver,
        command: CommandPath::Modbus,
        kind: DriverKind::Zlac8015d,
        ..DriveLinkSettings::default()
    };
    s.generic.baud = baud;
    s.generic.micro_rpm_per_count = SCALE;
    s
}

fn link(baud: u32) -> Link {
    let (profile, config) = link_settings(baud).config().unwrap().unwrap();
    Link::new(profile, config)
}

/// A line to a fresh peer (motor lag `lag_ms`, its 0x2022 set to
/// `resolution` before the master starts).
fn line(baud: u32, lag_ms: u32, resolution: u16, seed: u64) -> Line {
    let mut peer = Peer::start(lag_ms);
    if resolution != 1 {
        peer.cmd(json!({"cmd": "set", "reg": "0x2022", "value": resolution}));
    }
    let mut l = Line::new(link(baud), baud, peer, seed);
    l.resolution = resolution;
    l
}

/// One transaction of a speed read at `baud` with an answer time of
/// `delay_us`: request 8 characters, answer, reply 7 characters, the two
/// 3.5-character silences.
fn transaction_us(baud: u32, delay_us: u64) -> u64 {
    u64::from(frame_time_us(baud, 15).unwrap())
        + delay_us
        + 2 * u64::from(silent_interval_us(baud).unwrap())
}

/// Runs the master alone (no supervisor) with a speed command that moves
/// every 10 ms, until `transactions` requests have gone out.
fn run_commanded(l: &mut Line, transactions: u32) {
    l.link.control(drive_link::link::ControlAction::Enable);
    let mut k = 0i32;
    while l.stats.requests < transactions {
        // 15.000 … 34.99 drum r/min in steps of 37 milli-r/min.
        l.set_speed_command(Some(15_000 + (k * 37) % 20_000));
        l.run_for(10_000);
        k += 1;
    }
}

/// The peer's own view: the offline time written from the settings, and
/// never tripped (the driver never stopped itself for want of requests).
fn assert_peer_online(l: &mut Line, what: &str) {
    let offline = l.peer.cmd(json!({"cmd": "get", "reg": "0x2000"}));
    assert_eq!(
        offline["value"],
        json!(drive_link::link::LinkTiming::DEFAULT.offline_time_ms),
        "{what}: 0x2000"
    );
    let st = l.peer.cmd(json!({"cmd": "state"}));
    assert_eq!(st["offline_stop"], json!(false), "{what}: {st}");
}

fn assert_clean(l: &Line, what: &str) {
    let c = l.link.counters();
    assert_eq!(c.losses, 0, "{what}: link lost: {c:?} {:?}", l.stats);
    assert!(!l.link.is_lost(), "{what}");
    assert_eq!(l.stats.collisions, 0, "{what}: {:?}", l.stats);
    assert_eq!(l.peer.silences, 0, "{what}: the peer did not answer");
    assert!(
        l.mismatches.is_empty(),
        "{what}: {} mismatches, first {:?}",
        l.mismatches.len(),
        l.mismatches.first()
    );
}

/// Answer times 0, 10, 25, 40 and 50 ms at 9600 and 115 200 baud, 120
/// transactions each: no timeout, no loss, every speed command written as
/// the drum speed × 20 (r/min of the motor, rounded), every read-back the
/// peer's register over the gearbox, and the peer's read-back its
/// acknowledged target (lag 0).
#[test]
fn answer_times_up_to_50_ms_lose_nothing_and_every_value_is_exact() {
    for baud in [9600, 115_200] {
        for delay_ms in [0u64, 10, 25, 40, 50] {
            let mut l = line(baud, 0, 1, 7 + delay_ms);
            l.check_target = true;
            l.faults.delay_us = delay_ms * 1000;
            run_commanded(&mut l, 120);
            let what = format!("{baud} baud, answer {delay_ms} ms");
            assert_clean(&l, &what);
            assert_peer_online(&mut l, &what);
            let c = l.link.counters();
            assert_eq!((c.timeouts, c.retries), (0, 0), "{what}: {c:?}");
            assert!(
                l.stats.commands >= 20 && l.stats.readbacks >= 20,
                "{what}: {:?}",
                l.stats
            );
            assert!(l.stats.readbacks_vs_target >= 20, "{what}: {:?}", l.stats);
            eprintln!(
                "{what}: {} transactions in {:.2} s ({:.1} ms each, {:.1} by hand for a read), {} commands and {} read-backs exact, no loss",
                l.stats.requests,
                l.now as f64 / 1e6,
                l.now as f64 / 1e3 / f64::from(l.stats.requests),
                transaction_us(baud, delay_ms * 1000) as f64 / 1e3,
                l.stats.commands,
                l.stats.readbacks
            );
        }
    }
}

/// 1 % of the replies with a bit flipped, 0.5 % dropped, 2 % preceded by a
/// noise burst and a gap, at both baud rates, answer times 10 and 50 ms,
/// 2000 transactions each: no loss, every value exact, and a noise burst
/// costs no attempt (the retries are at most the corrupted and dropped
/// replies).
#[test]
fn crc_errors_drops_and_noise_bursts_lose_nothing() {
    for baud in [9600, 115_200] {
        for delay_ms in [10u64, 50] {
            let mut l = line(baud, 0, 1, 0x5EED + baud as u64 + delay_ms);
            l.faults = Faults {
                delay_us: delay_ms * 1000,
                crc: 100,
                drop: 50,
                noise: 200,
            };
            run_commanded(&mut l, 2000);
            let what = format!("{baud} baud, answer {delay_ms} ms, errors");
            assert_clean(&l, &what);
            assert_peer_online(&mut l, &what);
            let s = l.stats;
            assert!(
                s.crc_injected > 0 && s.dropped > 0 && s.noise_bursts > 0,
                "{what}: {s:?}"
            );
            let c = l.link.counters();
            assert!(
                c.retries <= s.crc_injected + s.dropped,
                "{what}: {c:?} {s:?}"
            );
            eprintln!(
                "{what}: {} transactions, {} CRC errors, {} dropped, {} noise bursts injected; master: {} CRC/noise frames, {} timeouts, {} retries, 0 losses",
                s.requests, s.crc_injected, s.dropped, s.noise_bursts, c.crc_errors, c.timeouts, c.retries
            );
        }
    }
}

/// A Modbus exception for one request is retried and survived; one for
/// every read of the speed register loses the link within the retry
/// budget, named (function 3, register 0x20AB, the code), and it comes
/// back when the peer answers again.
#[test]
fn exceptions_are_retried_then_named() {
    for baud in [9600, 115_200] {
        let mut l = line(baud, 0, 1, 3);
        run_commanded(&mut l, 40);
        // Server device busy (6) for the speed register, for one request.
        l.peer
            .cmd(json!({"cmd": "exception", "function": 3, "reg": "0x20AB", "code": 6}));
        let exceptions = l.stats.exceptions;
        while l.stats.exceptions == exceptions {
            l.run_for(1000);
        }
        l.peer.cmd(json!({"cmd": "clear_exceptions"}));
        let more = l.stats.requests + 40;
        run_commanded(&mut l, more);
        assert_clean(&l, &format!("{baud}: one exception"));
        assert!(l.link.counters().exceptions >= 1);
        // Illegal data address (2) from now on.
        l.peer
            .cmd(json!({"cmd": "exception", "function": 3, "reg": "0x20AB", "code": 2}));
        let from = l.now;
        while !l.link.is_lost() {
            l.run_for(1000);
            assert!(l.now - from < 2_000_000, "{baud}: never lost");
        }
        assert_eq!(
            l.link.loss_cause(),
            Some(LossCause::Refused {
                function: 3,
                register: 0x20AB,
                code: 2
            })
        );
        eprintln!(
            "{baud} baud: exception 2 on every speed read: lost {:.1} ms later, named (function 3, register 0x20ab, code 2)",
            (l.now - from) as f64 / 1e3
        );
        l.peer.cmd(json!({"cmd": "clear_exceptions"}));
        l.run_for(500_000);
        assert!(
            l.events.iter().any(|(_, e)| *e == Event::Restored),
            "{baud}"
        );
        assert!(l.link.acknowledge());
    }
}

/// The given-speed resolution 0x2022 set to 10 (0.1 r/min) in the peer: the
/// master reads it and writes 10 × the counts (each checked), the peer's
/// target is the drum speed × 20 and its read-back exact. Set to 11 (the
/// manual's range is 1–10; the peer's `set` takes any value) the master
/// refuses the driver by name and writes no command.
#[test]
fn resolution_10_is_honoured_and_11_refused_with_its_reason() {
    for baud in [9600, 115_200] {
        let mut l = line(baud, 0, 10, 11);
        l.check_target = true;
        run_commanded(&mut l, 120);
        // The last command held until it is written.
        l.run_for(300_000);
        assert_clean(&l, &format!("{baud}: resolution 10"));
        assert!(l.stats.commands >= 20);
        let st = l.peer.cmd(json!({"cmd": "state"}));
        let target = st["left"]["target_rpm"].as_f64().unwrap();
        let commanded = f64::from(l.command_milli.unwrap()) / 1000.0 * 20.0;
        assert!(
            (target - commanded).abs() <= 0.05,
            "{baud}: peer target {target} r/min, commanded {commanded}"
        );
        eprintln!(
            "{baud} baud, 0x2022 = 10: {} commands written at 0.1 r/min and {} read-backs exact; the peer's target {target} r/min for {commanded:.2}",
            l.stats.commands, l.stats.readbacks
        );
    }
    let mut peer = Peer::start(0);
    peer.cmd(json!({"cmd": "set", "reg": "0x2022", "value": 11}));
    let mut l = Line::new(link(115_200), 115_200, peer, 5);
    run_commanded(&mut l, 40);
    assert_eq!(
        l.link.loss_cause(),
        Some(LossCause::Setup(SetupFault::Resolution(11)))
    );
    assert_eq!(l.stats.commands, 0, "no command to a driver refused");
    // The maximum speed 0x2008 = 800: the drum's 44.7 r/min needs 894 motor
    // r/min through 20:1: refused by name.
    let mut peer = Peer::start(0);
    peer.cmd(json!({"cmd": "set", "reg": "0x2008", "value": 800}));
    let mut l = Line::new(link(9600), 9600, peer, 6);
    run_commanded(&mut l, 20);
    assert_eq!(
        l.link.loss_cause(),
        Some(LossCause::Setup(SetupFault::MaxSpeed {
            driver: 800,
            needed: 894
        }))
    );
}

/// The supervisor on the line: fixed 20 r/min drum, the read-back as the
/// feedback, the speed commanded over Modbus.
struct Machine {
    sup: Supervisor,
    line: Line,
    act: Actuation,
    enabled: Option<bool>,
}

impl Machine {
    fn new(baud: u32, seed: u64) -> Self {
        let settings = Settings {
            mode: Mode::Fixed,
            fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
            drive_link: link_settings(baud),
            ..Settings::default()
        };
        Self {
            sup: Supervisor::new(Hardware::BOARD, settings).unwrap(),
            // The peer's motor follows with a 100 ms lag.
            line: line(baud, 100, 1, seed),
            act: Actuation::OFF,
            enabled: None,
        }
    }

    /// One control period (what the firmware's control task does).
    fn period(&mut self) {
        self.line.run_for(10_000);
        let link = &self.line.link;
        let now = self.line.now;
        self.sup.set_link_sample(LinkSample {
            speed: link.speed().map(|s| ReadBack {
                drum_milli_rpm: s.drum_milli_rpm,
                age_us: (now - s.sampled_at_us) as u32,
            }),
            lost: link.is_lost(),
            setup: None,
            refused: matches!(link.loss_cause(), Some(LossCause::Refused { .. })),
            answering: link.is_answering(),
            fault_word: link.fault_word(),
            fault_reads: link.counters().fault_reads,
        });
        self.act = self.sup.control_step(Ticks(now as u32), 0);
        // main.rs `link_apply`.
        let on = self.act.driver_enabled;
        if self.sup.take_driver_clear() {
            self.line
                .link
                .control(drive_link::link::ControlAction::ClearAlarm);
            self.enabled = None;
        } else if self.enabled != Some(on) {
            self.line.link.control(if on {
                drive_link::link::ControlAction::Enable
            } else {
                drive_link::link::ControlAction::Disable
            });
            self.enabled = Some(on);
        }
        let command = if on {
            self.sup.bus_speed_command()
        } else {
            None
        };
        self.line.set_speed_command(command);
    }

    fn until(&mut self, max_ms: u32, pred: impl Fn(&Self) -> bool) -> Option<u64> {
        for _ in 0..max_ms / 10 {
            self.period();
            if pred(self) {
                return Some(self.line.now);
            }
        }
        None
    }

    fn running_under_command(&mut self) {
        self.sup.command(Command::Start);
        let ok = self.until(3000, |m| {
            m.sup.run_state() == RunState::Running
                && m.line.command_milli.is_some_and(|c| c > 10_000)
                && m.line
                    .link
                    .speed()
                    .is_some_and(|s| s.drum_milli_rpm > 15_000)
        });
        assert!(ok.is_some(), "the drum never ran: {:?}", self.sup.alarm());
    }
}

/// A fault set in the peer (0x20A5 = over-current) while the drum runs
/// under the Modbus speed command, at 10 phases: the named alarm and the
/// outputs off (PWM 0, enable low, no bus command) within the fault word's
/// poll period (6 polls) + its reply + a control period — and within 3 poll
/// periods of 6 transactions. Then the operator's acknowledgement must
/// bring the clear (0x200E = 6) to the driver, in 50 of 50 tries at each
/// baud rate, whatever the phase of the clear against the enable state
/// that follows it (the control word queue).
#[test]
fn a_fault_under_the_command_is_alarmed_in_time_and_cleared_50_of_50() {
    for baud in [9600, 115_200] {
        let mut m = Machine::new(baud, 29);
        let mut worst_us = 0u64;
        let mut cleared = 0;
        for k in 0..50u64 {
            m.running_under_command();
            // A phase within the poll cycle.
            m.line.run_for((k * 1_777) % 20_000);
            m.line
                .peer
                .cmd(json!({"cmd": "set", "reg": "0x20A5", "value": 4}));
            let set = m.line.now;
            let seen = m
                .until(2000, |m| m.sup.alarm().is_some())
                .expect("no alarm");
            assert_eq!(
                m.sup.alarm(),
                Some(Alarm::DriverFault(DriverFault::OverCurrent)),
                "{baud}"
            );
            assert_eq!(m.act, Actuation::OFF, "{baud}: outputs at the alarm");
            assert_eq!(m.sup.bus_speed_command(), None);
            worst_us = worst_us.max(seen - set);
            // Acknowledged at a phase of its own; the clear must reach the
            // driver.
            m.line.run_for((k * 733) % 10_000);
            m.line.peer.cmd(json!({"cmd": "log"}));
            m.sup.command(Command::AcknowledgeAlarm);
            let _ = m.until(400, |m| m.line.link.fault_word() == 0);
            let log = m.line.peer.cmd(json!({"cmd": "log"}));
            let clear_written = log["requests"].as_array().unwrap().iter().any(|r| {
                r["function"] == json!(6)
                    && r["address"] == json!("0x200E")
                    && r["values"] == json!([6])
                    && r["exception"].is_null()
            });
            let word = m.line.peer.cmd(json!({"cmd": "get", "reg": "0x20A5"}));
            if clear_written && word["value"] == json!(0) && m.sup.alarm().is_none() {
                cleared += 1;
            }
        }
        let every = u64::from(FAULT_POLL_EVERY);
        let tx = transaction_us(baud, 0);
        // 6 polls, the fault read's reply (7 characters and the silence),
        // one control period.
        let bound = every * tx + transaction_us(baud, 0) + 10_000;
        assert!(
            worst_us <= bound,
            "{baud}: alarm {worst_us} µs after the fault, bound {bound}"
        );
        assert!(worst_us <= 3 * every * tx);
        assert_eq!(cleared, 50, "{baud} baud: clears that reached the driver");
        assert_clean(&m.line, &format!("{baud}: faults"));
        eprintln!(
            "{baud} baud: fault under the command -> 'Driver fault: over-current', PWM 0 within {:.1} ms (worst of 50; poll period {} polls = {:.1} ms: {:.2} of them); clear reached the driver {cleared} of 50",
            worst_us as f64 / 1e3,
            every,
            (every * tx) as f64 / 1e3,
            worst_us as f64 / (every * tx) as f64
        );
    }
}
