//! The drum driver's RS-485 link end to end on the host (issue 17,
//! docs/drive-link.md): the supervisor, drive_link's Modbus master and the
//! virtual ZLAC8015D on a simulated half-duplex line, against the machine
//! simulator — the loop the firmware's control task (10 ms) and link task
//! run, with the line's timing to 50 µs (each frame's time on the wire at
//! the baud rate, the driver's 2 ms turnaround, the read-back sampled when
//! the driver has the request).
//!
//! Expected values come from the simulator's truth and independent
//! references: eq. 7 in f64 on the true ground speed
//! (`machine_sim::reference`), the plants the simulated belt dropped, and
//! hand-computed link timings.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap,
    clippy::indexing_slicing,
    missing_docs
)]

#[path = "support/drive_rig.rs"]
mod drive_rig;

use drive_link::link::LinkConfig;
use drive_rig::{row_70m, row_70m_placed, tracking, Rig, ROW_PLANTS};
use hmi_proto::screen::Command;
use kinematics::consts::Gear;
use machine_sim::{Config, Fault};
use supervisor::drive_link::{CommandPath, FeedbackSource};
use supervisor::drum::{Actuation, Alarm, RunState};
use supervisor::settings::Placement;

/// Read-back only (the encoder cut), Start at 8 s; the worst error vs
/// eq. 7 from `drive_rig::settle_ms` after Start for 6 s, sampled every
/// 100 ms.
fn tracks_eq7(command: CommandPath, baud: u32) -> (f64, Rig) {
    let (errors, rig) = tracking(FeedbackSource::Driver, command, baud);
    let worst = errors.iter().step_by(10).fold(0.0f64, |w, &e| w.max(e));
    assert_eq!(rig.sup.alarm(), None);
    assert_eq!(rig.sup.run_state(), RunState::Running);
    (worst, rig)
}

#[test]
fn readback_only_tracks_eq7_within_1_percent_at_both_bauds_pwm_and_modbus() {
    for baud in [9600, 115_200] {
        for command in [CommandPath::Pwm, CommandPath::Modbus] {
            let (worst, rig) = tracks_eq7(command, baud);
            let c = rig.link.counters();
            eprintln!(
                "{baud} baud, {command:?}: worst {:.3} %, replies {}, timeouts {}, crc {}, late {}",
                worst * 100.0,
                c.replies,
                c.timeouts,
                c.crc_errors,
                c.late_replies
            );
            assert!(
                worst <= 0.01,
                "{baud} baud {command:?}: worst {:.2} %",
                worst * 100.0
            );
            assert_eq!(c.timeouts, 0, "{baud} {command:?}");
        }
    }
}

#[test]
fn the_poll_period_and_readback_age_match_the_line_at_both_bauds() {
    for baud in [9600u32, 115_200] {
        let (_, rig) = tracks_eq7(CommandPath::Pwm, baud);
        // Hand formula of one speed read: request 8 chars + turnaround
        // 2 ms + reply 7 chars + the 3.5-character gap after each frame;
        // every 6th poll is a fault read of the same length.
        let ch = 11.0e6 / f64::from(baud);
        let gap = if baud > 19_200 { 1750.0 } else { 3.5 * ch };
        let one = 8.0 * ch + 2000.0 + 7.0 * ch + gap + gap;
        // Speed reads are 5 of every 6 polls: mean interval 6/5 of one.
        let every = f64::from(drive_link::link::FAULT_POLL_EVERY);
        let expected = one * every / (every - 1.0);
        let r = &rig.speed_reads;
        let measured = (r[r.len() - 1] - r[r.len() - 301]) as f64 / 300.0;
        eprintln!(
            "{baud} baud: speed poll period {:.2} ms (hand formula {:.2} ms), read-back age at use max {:.1} ms mean {:.1} ms",
            measured / 1000.0,
            expected / 1000.0,
            rig.ages.iter().map(|a| a.1).max().unwrap() as f64 / 1000.0,
            rig.ages.iter().map(|a| f64::from(a.1)).sum::<f64>() / rig.ages.len() as f64 / 1000.0
        );
        // Within 5 % (the 50 µs line step and the 1 ms link poll).
        assert!(
            (measured - expected).abs() / expected < 0.05,
            "{baud}: {measured} vs {expected}"
        );
    }
}

#[test]
fn a_70_m_row_from_the_readback_alone_gets_its_1000_plants() {
    // The full noise model (terrain, slip variation, tooth errors,
    // seedling load; seed 1), read-back only, the encoder cut, with PWM
    // and with the Modbus speed command. Issue 17 asks ±0.5 % of the plant
    // count at 9600 and at 115 200 baud; the true count is the row's
    // length over the spacing, 70 m / 7 cm = 1000 (the plants the
    // simulated belt dropped are counted, not the supervisor's count).
    //
    // The drum's true turns over the row against ∫ eq. 7 dt (f64, on the
    // true travel speed) must not be off by more than 0.12 %: the
    // encoder-fed loop on the same row is +0.06 % (bench §10 runs it:
    // `cargo xtask bench --only link`), and the read-back may add as
    // much again. Before the fix (the fuzzy tuner's Ki following the
    // held read-back's error, docs/drive-link.md "The 70 m row at 9600
    // baud") this failed: +0.40 % (9600, PWM, 1003 plants), +0.15 %
    // (115 200), +0.59 % and +0.20 % with the Modbus command (1005 and
    // 1002 plants).
    for command in [CommandPath::Pwm, CommandPath::Modbus] {
        for baud in [115_200u32, 9600] {
            let (row, _) = row_70m(FeedbackSource::Driver, command, baud);
            assert_eq!(row.first_alarm, None, "{baud} {command:?}");
            let plants = row.plants as f64;
            let error = (plants - ROW_PLANTS) / ROW_PLANTS;
            let offset = row.drum_turns / row.eq7_turns - 1.0;
            eprintln!(
                "{baud} baud, {command:?}, 70 m: {plants} plants ({:+.2} %), drum turns vs eq. 7 {:+.3} %",
                error * 100.0,
                offset * 100.0
            );
            assert!(error.abs() <= 0.005, "{baud} {command:?}: {plants} plants");
            assert!(
                offset.abs() <= 0.0012,
                "{baud} {command:?}: drum turns {:+.3} % vs eq. 7",
                offset * 100.0
            );
        }
    }
}

#[test]
fn distance_locked_rows_on_the_readback_raise_no_instability_warning() {
    // Distance-locked placement (the default) with the read-back as the
    // only feedback at 9600 baud, the slowest line, with PWM and with the
    // Modbus command: 30 rows of 70 m each (full noise model, seeds 1–30).
    // Before the phase correction was smoothed through the link
    // (`PHASE_SMOOTHING` in control.rs) the instability supervisor tripped
    // in 5 of these 60 rows (with the Modbus command seeds 1, 28 and 29,
    // seed 1 at 16.5 s; with PWM seeds 24 and 28, 1 s after Start):
    // the correction steps at every Hall edge and the loop, seeing the
    // drum 30–90 ms late, overshot them. Each row must also keep its count
    // within ±0.5 % (distance-locked rows at 7 cm lose one place at the
    // start and the Hall sensor's −0.1 %: docs/placement.md) and its phase:
    // the belt within 5.5 mm of its line from the second plant on (worst
    // measured 5.1 mm, seeds 1–30, and 5.3 mm over seeds 1–180: the Hall
    // edges every 25 mm correct the ground; 4.0 mm before the fault word
    // had its own poll turn, when a fault went unseen under the Modbus
    // command), where speed-following leaves 50–70 mm (bench §10's rig).
    for command in [CommandPath::Modbus, CommandPath::Pwm] {
        for seed in 1..=30 {
            let (row, rig) = row_70m_placed(
                FeedbackSource::Driver,
                command,
                9600,
                Placement::DistanceLocked,
                seed,
            );
            assert_eq!(row.first_alarm, None, "seed {seed}, {command:?}");
            let error = (row.plants as f64 - ROW_PLANTS) / ROW_PLANTS;
            assert!(
                error.abs() <= 0.005,
                "seed {seed}, {command:?}: {} plants",
                row.plants
            );
            assert!(
                row.worst_phase_um.abs() <= 5_500,
                "seed {seed}, {command:?}: phase {} µm",
                row.worst_phase_um
            );
            drop(rig);
        }
    }
}

/// Runs at speed with the read-back, then `inject` at 5 s; returns the rig
/// and the time (µs) of the injection.
fn running(feedback: FeedbackSource, baud: u32) -> Rig {
    let mut c = Config::noiseless();
    c.initial_gear = Some(Gear::Low2);
    let mut rig = Rig::new(c, feedback, CommandPath::Pwm, baud);
    rig.run_ms(1_000);
    rig.start();
    rig.run_ms(4_000);
    assert_eq!(rig.sup.alarm(), None);
    assert_eq!(rig.sup.run_state(), RunState::Running);
    rig
}

/// Periods until `pred`, at most `max_ms`; the firmware time it held.
fn until(rig: &mut Rig, max_ms: u32, pred: impl Fn(&Rig) -> bool) -> Option<u64> {
    for _ in 0..max_ms / 10 {
        rig.period();
        if pred(rig) {
            return Some(rig.t_us);
        }
    }
    None
}

#[test]
fn a_driver_fault_is_named_and_the_outputs_go_safe() {
    let mut rig = running(FeedbackSource::Driver, 115_200);
    let at = rig.t_us;
    // Over-current (0x0004) and over-temperature (0x0400).
    rig.drv.fault_bits = 0x0404;
    let seen = until(&mut rig, 1_000, |r| r.sup.alarm().is_some()).expect("no alarm");
    assert_eq!(
        rig.sup.alarm(),
        Some(Alarm::DriverFault(
            drive_link::profile::DriverFault::OverCurrent
        ))
    );
    let mut text = String::new();
    rig.sup.alarm().unwrap().write_text(&mut text).unwrap();
    assert_eq!(text, "Driver fault: over-current");
    assert_eq!(rig.act, Actuation::OFF);
    // Faults are read every 6th poll: within 6 polls of 6.9 ms plus a
    // control period (hand formula at 115 200 baud, as the test above).
    assert!(seen - at <= 6 * 6_900 + 10_000 + 2_000, "{} us", seen - at);
    // Acknowledged: the driver's alarm is cleared through its control word.
    rig.sup.command(Command::AcknowledgeAlarm);
    rig.run_ms(100);
    assert_eq!(rig.drv.fault_bits, 0, "clear alarm (0x06) written");
    assert_eq!(rig.sup.alarm(), None);
}

#[test]
fn a_cut_link_is_lost_within_the_retry_budget_and_recovers_on_acknowledge() {
    for baud in [9600u32, 115_200] {
        let mut rig = running(FeedbackSource::Driver, baud);
        let cut = rig.t_us;
        rig.drv.inject.silent = true;
        let alarm = until(&mut rig, 1_000, |r| r.sup.alarm().is_some()).expect("no alarm");
        assert_eq!(rig.sup.alarm(), Some(Alarm::LinkLost));
        assert_eq!(rig.act, Actuation::OFF, "outputs safe at the alarm");
        let lost = rig.lost_at.unwrap();
        // The outputs are safe at the first control step after the last
        // retry's timeout: within 10 ms (≤ 100 ms required).
        assert!(alarm - lost <= 10_000, "{} us", alarm - lost);
        // Hand formula: three attempts of (request 8 chars + reply timeout
        // + the retry gap), plus up to one poll cycle before the cut was met.
        let ch = 11.0e6 / f64::from(baud);
        let gap = if baud > 19_200 { 1750.0 } else { 3.5 * ch };
        let c = LinkConfig::for_baud(baud).unwrap();
        let timeout = f64::from(c.reply_timeout_us);
        let retry_gap = f64::from(c.retry_gap_us);
        let budget = 3.0 * (8.0 * ch + timeout + retry_gap) + (15.0 * ch + 2000.0 + 2.0 * gap);
        eprintln!(
            "{baud} baud: lost {:.1} ms after the cut (bound {:.1} ms), outputs safe {:.1} ms after",
            (lost - cut) as f64 / 1000.0,
            budget / 1000.0,
            (alarm - lost) as f64 / 1000.0
        );
        assert!(((lost - cut) as f64) <= budget + 1000.0);
        // Acknowledge while still cut: refused.
        rig.sup.command(Command::AcknowledgeAlarm);
        assert_eq!(rig.sup.alarm(), Some(Alarm::LinkLost));
        // The driver answers again: the link restores by itself, the
        // operator acknowledges, Start works.
        rig.drv.inject.silent = false;
        until(&mut rig, 500, |r| r.link.is_answering()).expect("no recovery");
        rig.run_ms(50);
        rig.sup.command(Command::AcknowledgeAlarm);
        assert_eq!(rig.sup.alarm(), None);
        rig.start();
        rig.run_ms(2_000);
        assert_eq!(rig.sup.run_state(), RunState::Running);
        assert_eq!(rig.sup.alarm(), None, "{baud} after the restart");
    }
}

/// A generic profile whose speed register the driver does not have (a
/// typo on the link page: 0x2AB0 for the ZLAC8015D's 0x20AB). The virtual
/// driver refuses each read with exception 2; after the retry budget the
/// alarm names the profile, not the wiring ("link lost" sent technicians
/// to the cable), and the outputs are safe.
#[test]
fn a_refused_speed_register_is_its_own_alarm_with_safe_outputs() {
    for baud in [9600u32, 115_200] {
        let mut rig = Rig::new(
            Config::noiseless(),
            FeedbackSource::Driver,
            CommandPath::Pwm,
            baud,
        );
        let mut settings = rig.sup.settings().clone();
        settings.drive_link.kind = supervisor::drive_link::DriverKind::Generic;
        settings.drive_link.generic.speed_feedback = 0x2AB0;
        let profile = settings.drive_link.build().unwrap().unwrap();
        rig.sup = supervisor::drum::Supervisor::new(drive_rig::HW, settings).unwrap();
        rig.link = drive_link::link::Link::new(profile, LinkConfig::for_baud(baud).unwrap());
        // From power-up (the commissioning case: the profile just saved).
        let alarm = until(&mut rig, 1_000, |r| r.sup.alarm().is_some()).expect("no alarm");
        assert_eq!(rig.sup.alarm(), Some(Alarm::LinkRefused), "{baud}");
        let mut text = String::new();
        rig.sup.alarm().unwrap().write_text(&mut text).unwrap();
        assert_eq!(text, "Driver refuses register: check profile");
        assert!(text.len() <= 40);
        assert_eq!(rig.act, Actuation::OFF, "outputs safe at the alarm");
        let lost = rig.lost_at.unwrap();
        assert!(alarm - lost <= 10_000, "{} us", alarm - lost);
        // Not acknowledged while the driver refuses.
        let effect = rig.sup.command(Command::AcknowledgeAlarm);
        assert_eq!(
            effect,
            supervisor::drum::Effect::Message("Drum driver still not answering")
        );
        assert_eq!(rig.sup.alarm(), Some(Alarm::LinkRefused));
        assert!(rig.link.counters().exceptions >= 3);
        // Start is refused while the alarm is latched.
        rig.start();
        rig.run_ms(100);
        assert_eq!(rig.act, Actuation::OFF);
        assert_eq!(rig.sup.run_state(), RunState::Stopped);
    }
}

/// The driver's speed read back with the wrong sign (its scale entered
/// negative, or the motor turning the other way): the drum turns forward
/// under the PWM while the read-back, the only feedback, says −n. Before,
/// the negative read-back counted as standstill and latched "Drum stalled
/// or encoder lost"; now "Drum turns backwards: check direction", after
/// the same stall time, outputs off.
#[test]
fn a_readback_of_the_wrong_sign_is_named_backwards() {
    for baud in [9600u32, 115_200] {
        let mut c = Config::noiseless();
        c.initial_gear = Some(Gear::Low2);
        let mut rig = Rig::new(c, FeedbackSource::Driver, CommandPath::Pwm, baud);
        let mut settings = rig.sup.settings().clone();
        settings.drive_link.generic.micro_rpm_per_count = -drive_rig::SCALE;
        let profile = settings.drive_link.build().unwrap().unwrap();
        rig.sup = supervisor::drum::Supervisor::new(drive_rig::HW, settings).unwrap();
        rig.link = drive_link::link::Link::new(profile, LinkConfig::for_baud(baud).unwrap());
        rig.run_ms(1_000);
        rig.start();
        let started = rig.t_us;
        let alarm = until(&mut rig, 2_000, |r| r.sup.alarm().is_some()).expect("no alarm");
        assert_eq!(rig.sup.alarm(), Some(Alarm::DrumBackwards), "{baud}");
        assert_eq!(rig.act, Actuation::OFF);
        // The stall time (200 ms) after the first negative read-back, which
        // takes a poll and the drum's start (≤ 300 ms at 9600 baud).
        let took = alarm - started;
        eprintln!("{baud} baud: backwards {} ms after Start", took / 1000);
        assert!((200_000..=500_000).contains(&took), "{took} us");
    }
}

#[test]
fn with_both_feedbacks_a_stall_and_a_lost_encoder_are_told_apart() {
    // A lost encoder: the driver still sees the drum turn → "encoder or
    // driver speed wrong" (after the cross-check's 500 ms), not a stall.
    let mut rig = running(FeedbackSource::Both, 115_200);
    let at = rig.t_us;
    rig.m.inject_fault(Fault::EncoderLoss);
    let seen = until(&mut rig, 2_000, |r| r.sup.alarm().is_some()).expect("no alarm");
    assert_eq!(rig.sup.alarm(), Some(Alarm::SpeedMismatch));
    assert_eq!(rig.act, Actuation::OFF);
    let mut text = String::new();
    rig.sup.alarm().unwrap().write_text(&mut text).unwrap();
    assert_eq!(text, "Encoder or driver speed wrong");
    // 500 ms of disagreement (cross_check::HOLD_US) after the read-back
    // has seen the drum turn and the encoder stop: ≤ 500 + a read-back age
    // + two periods.
    assert!(seen - at <= 500_000 + 30_000 + 20_000, "{} us", seen - at);
    assert!(seen - at >= 500_000);
    // A stalled drum: both stop → the stall alarm.
    let mut rig = running(FeedbackSource::Both, 115_200);
    rig.m.inject_fault(Fault::DrumStall);
    until(&mut rig, 2_000, |r| r.sup.alarm().is_some()).expect("no alarm");
    assert_eq!(rig.sup.alarm(), Some(Alarm::DrumStall));
    assert_eq!(rig.act, Actuation::OFF);
    // With the read-back alone, a stall is a stall.
    let mut rig = running(FeedbackSource::Driver, 9600);
    rig.m.inject_fault(Fault::DrumStall);
    until(&mut rig, 2_000, |r| r.sup.alarm().is_some()).expect("no alarm");
    assert_eq!(rig.sup.alarm(), Some(Alarm::DrumStall));
}

#[test]
fn crc_errors_and_late_replies_are_counted_and_survived() {
    for baud in [9600u32, 115_200] {
        let mut rig = running(FeedbackSource::Driver, baud);
        // Two corrupted replies in a row (the retry budget is two).
        rig.drv.inject.corrupt_replies = 2;
        rig.run_ms(500);
        // A reply 65 ms late: its answer (2 + 65 ms) starts beyond the
        // 60 ms the link allows, so the request times out; the retry waits
        // for a quiet line and the late reply is heard and taken first.
        rig.drv.inject.late_replies = 1;
        rig.drv.inject.extra_delay_us = 65_000;
        rig.run_ms(1_000);
        let c = rig.link.counters();
        eprintln!("{baud}: {c:?}");
        assert_eq!(c.crc_errors, 2);
        assert_eq!(c.losses, 0);
        assert_eq!(rig.sup.alarm(), None);
        assert_eq!(rig.sup.run_state(), RunState::Running);
        assert_eq!(c.timeouts, 1);
        // The two corrupted replies were sent again; the late one was not.
        assert_eq!((c.retries, c.late_replies), (2, 0));
    }
}
