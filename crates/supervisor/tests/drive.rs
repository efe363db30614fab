//! Drive identification and the controller scheduled from it, on model
//! drives of the machine simulator (issue 16 item 3). Expected values are
//! the simulator's own parameters (its `Config`), never the code under test.
#![allow(
    clippy::panic,
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap,
    clippy::indexing_slicing
)]

use machine_sim::{Config, Inputs, Machine};
use supervisor::drive::{Identifier, IdentifyState};

const COUNTS_PER_REV: f64 = 400.0 * 118.0;

/// A model drive: gain × `g`, τ × `t`, dead time `dead_ms`, belt empty
/// (no seedling load), the simulator's default speed ripple and noise.
fn drive(g: f32, t: f32, dead_ms: u8) -> Config {
    let c = Config::default();
    Config {
        n_max_rpm: c.n_max_rpm * g,
        motor_tau_s: c.motor_tau_s * t,
        transport_delay_ms: dead_ms,
        load_droop: 0.0,
        ..c
    }
}

/// Runs the identifier alone against `m` (as the supervisor does: duty
/// applied at the step, the period's encoder speed measured at the next).
fn identify(m: &mut Machine) -> IdentifyState {
    let mut id = Identifier::new(10_000);
    id.start();
    let mut last = m.drum_encoder_count();
    let mut measured = 0i32;
    for _ in 0..800 {
        let duty = id.step(measured);
        let Some(permille) = duty else { break };
        let inputs = Inputs {
            drum_duty: f32::from(permille) / 1000.0,
            driver_enabled: true,
            ..Inputs::default()
        };
        m.step(10_000, &inputs, &mut |_| {});
        let c = m.drum_encoder_count();
        let counts = f64::from(c.wrapping_sub(last));
        last = c;
        measured = (counts * 6000.0 / COUNTS_PER_REV * 65536.0) as i32;
    }
    id.state()
}

/// Gains × 0.7, 1, 1.3; τ × 0.35, 1, 3 (8.75, 25, 75 ms); dead time 0, 5,
/// 20, 40, 60 ms: 45 drives, a different noise seed each.
fn grid() -> Vec<(f32, f32, u8)> {
    let mut v = Vec::new();
    for g in [0.7f32, 1.0, 1.3] {
        for t in [0.35f32, 1.0, 3.0] {
            for d in [0u8, 5, 20, 40, 60] {
                v.push((g, t, d));
            }
        }
    }
    v
}

#[test]
fn identification_recovers_gain_tau_and_dead_time_within_10_percent() {
    // Tolerances (issue 16 item 3): each parameter within 10 % of the
    // simulator's; the dead time within 10 % or 1 ms, whichever is larger
    // (10 % of a zero dead time is nothing, and the measurement's time
    // base is 10 ms periods).
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for (i, (g, t, d)) in grid().into_iter().enumerate() {
        let cfg = Config {
            seed: 1600 + i as u64,
            ..drive(g, t, d)
        };
        let mut m = cfg.build().unwrap();
        let IdentifyState::Done(model) = identify(&mut m) else {
            panic!("g {g} t {t} d {d}: no model");
        };
        let n = f64::from(model.n_max_x100()) / 100.0;
        let tau = f64::from(model.tau_x10_ms()) / 10.0;
        let dead = f64::from(model.dead_time_x10_ms()) / 10.0;
        let n_err = (n / f64::from(cfg.n_max_rpm) - 1.0).abs();
        let tau_err = (tau / (f64::from(cfg.motor_tau_s) * 1000.0) - 1.0).abs();
        let dead_err = (dead - f64::from(d)).abs();
        println!("g {g} t {t} d {d}: n_max {n:.2}, tau {tau:.1} ms, dead {dead:.1} ms");
        assert!(n_err <= 0.10, "g {g} t {t} d {d}: n_max {n}");
        assert!(tau_err <= 0.10, "g {g} t {t} d {d}: tau {tau}");
        assert!(
            dead_err <= (0.1 * f64::from(d)).max(1.0),
            "g {g} t {t} d {d}: dead time {dead}"
        );
        worst = (
            worst.0.max(n_err),
            worst.1.max(tau_err),
            worst.2.max(dead_err),
        );
    }
    println!(
        "worst: n_max {:.1} %, tau {:.1} %, dead time {:.1} ms",
        worst.0 * 100.0,
        worst.1 * 100.0,
        worst.2
    );
}

mod closed {
    use super::*;
    use hmi_proto::screen::{Command, DrumSpeed, Mode};
    use kinematics::units::Ticks;
    use supervisor::drum::{Actuation, Effect, Hardware, RunState, Supervisor};
    use supervisor::settings::Settings;

    pub const HW: Hardware = Hardware::BOARD;

    pub struct Rig {
        pub sup: Supervisor,
        pub m: Machine,
        pub act: Actuation,
    }

    impl Rig {
        pub fn new(cfg: Config, settings: Settings) -> Self {
            Self {
                sup: Supervisor::new(HW, settings).unwrap(),
                m: cfg.build().unwrap(),
                act: Actuation::OFF,
            }
        }

        /// One control period; returns the true mean drum speed over it.
        pub fn period(&mut self) -> f64 {
            let inputs = Inputs {
                drum_duty: f32::from(self.act.ccr) / f32::from(HW.pwm_arr + 1),
                driver_enabled: self.act.driver_enabled,
                ..Inputs::default()
            };
            let sup = &mut self.sup;
            let t0 = self.m.drum_turns();
            self.m
                .step(10_000, &inputs, &mut |t| sup.hall_edge(Ticks(t)));
            self.act = self
                .sup
                .control_step(Ticks(self.m.capture_ticks()), self.m.drum_encoder_count());
            (self.m.drum_turns() - t0) * 6000.0
        }
    }

    /// Identification on the screen's commands, then Save.
    pub fn identify_and_save(rig: &mut Rig) {
        assert_eq!(
            rig.sup.command(Command::IdentifyDrive),
            Effect::Message(supervisor::drum::IDENTIFY_MESSAGE)
        );
        assert_eq!(rig.sup.run_state(), RunState::Identifying);
        let mut periods = 0;
        while rig.sup.run_state() == RunState::Identifying {
            rig.period();
            periods += 1;
            assert!(periods < 800, "identification did not end");
        }
        let IdentifyState::Done(model) = rig.sup.identify_state() else {
            panic!("{:?}", rig.sup.identify_state());
        };
        // Shown on page 9 before it is saved.
        let shown = rig.sup.screen_status();
        assert_eq!(
            (
                shown.drive_n_max_x100,
                shown.drive_tau_x10_ms,
                shown.drive_dead_time_x10_ms,
                shown.drive_identification
            ),
            (
                model.n_max_x100(),
                model.tau_x10_ms(),
                model.dead_time_x10_ms(),
                2
            )
        );
        // Save: the model goes into the settings (persisted by the
        // firmware on `Effect::Save`) and into the controller.
        assert_eq!(rig.sup.command(Command::AcceptDriveModel), Effect::Save);
        assert_eq!(rig.sup.settings().drive, model);
    }

    pub fn fixed(centi: i32) -> Settings {
        Settings {
            mode: Mode::Fixed,
            fixed_drum_speed: DrumSpeed::new(centi).unwrap(),
            ..Settings::default()
        }
    }
}

/// Speed figures of a run at `sp` r/min from period `from` on: the 10 ms
/// means' extremes and the extremes of the partition mean (the mean over
/// one partition's passage, 60 / (4.398 · n) s: the speed that sets the
/// plant spacing, free of the seedlings' per-partition load ripple), and
/// when the partition mean last left ±2 %.
struct Figures {
    min: f64,
    max: f64,
    pmin: f64,
    pmax: f64,
    settled_s: Option<f64>,
}

fn figures(speeds: &[f64], sp: f64, from: usize) -> Figures {
    // Partition period in 10 ms periods: 60 / (π·0.070/0.05 · n) / 0.01.
    let w = (60.0 / (std::f64::consts::PI * 0.070 / 0.05 * sp) / 0.01).round() as usize;
    let pm: Vec<f64> = (0..speeds.len() - w)
        .map(|i| speeds[i..i + w].iter().sum::<f64>() / w as f64)
        .collect();
    let late = &speeds[from..];
    let plate = &pm[from.min(pm.len())..];
    let last_out = pm.iter().rposition(|n| (n - sp).abs() > 0.02 * sp);
    Figures {
        min: late.iter().copied().fold(f64::MAX, f64::min),
        max: late.iter().copied().fold(f64::MIN, f64::max),
        pmin: plate.iter().copied().fold(f64::MAX, f64::min),
        pmax: plate.iter().copied().fold(f64::MIN, f64::max),
        // The window ending at the last period outside the band.
        settled_s: match last_out {
            None => Some(w as f64 * 0.01),
            Some(i) if i + 1 >= pm.len() => None,
            Some(i) => Some((i + w + 1) as f64 * 0.01),
        },
    }
}

#[test]
fn identified_drives_settle_with_a_seedling_load_of_10_percent() {
    // Every drive of the identification grid: identified on the screen
    // (belt empty), saved, then 10 s in Fixed mode at 25.21 r/min with the
    // seedlings' load at 10 % (the simulator's `load_droop`: the speed
    // droops 0–10 % as each partition passes, 1.85 Hz here).
    //
    // Settled: the partition mean within ±2 % of the set point from 2 s on
    // (it never leaves it again) and no sustained oscillation: the 10 ms
    // means swing by at most 15 % of the set point in the last 5 s (the
    // load alone swings the open-loop drum by 10 %; the limit cycle of
    // issue 16 by 80 %). No warning, no fallback.
    use closed::*;
    use hmi_proto::screen::Command;
    let sp = 25.21;
    let mut worst: (f64, f64, f64) = (0.0, 0.0, 0.0);
    for (i, (g, t, d)) in grid().into_iter().enumerate() {
        let base = Config {
            seed: 1700 + i as u64,
            ..drive(g, t, d)
        };
        let mut rig = Rig::new(base, fixed(2521));
        identify_and_save(&mut rig);
        let loaded = Config {
            load_droop: 0.10,
            ..base
        };
        let mut rig = Rig::new(loaded, rig.sup.settings().clone());
        rig.sup.command(Command::Start);
        let speeds: Vec<f64> = (0..1000).map(|_| rig.period()).collect();
        let f = figures(&speeds, sp, 500);
        let case = format!("g {g} t {t} d {d}");
        println!(
            "{case}: partition mean {:+.2}..{:+.2} %, settled {:?} s, 10 ms {:+.1}..{:+.1} %",
            (f.pmin / sp - 1.0) * 100.0,
            (f.pmax / sp - 1.0) * 100.0,
            f.settled_s,
            (f.min / sp - 1.0) * 100.0,
            (f.max / sp - 1.0) * 100.0
        );
        let settled = f.settled_s.unwrap_or(f64::MAX);
        assert!(settled <= 2.0, "{case}: settled {settled} s");
        assert!(
            (f.max - f.min) <= 0.15 * sp,
            "{case}: swing {} .. {}",
            f.min,
            f.max
        );
        assert_eq!(rig.sup.alarm(), None, "{case}");
        assert!(!rig.sup.in_fallback(), "{case}");
        let pdev = (f.pmin / sp - 1.0).abs().max((f.pmax / sp - 1.0).abs());
        worst = (
            worst.0.max(pdev),
            worst.1.max(settled),
            worst.2.max((f.max - f.min) / sp),
        );
    }
    println!(
        "worst: partition mean {:.2} %, settled {:.2} s, 10 ms swing {:.1} %",
        worst.0 * 100.0,
        worst.1,
        worst.2 * 100.0
    );
}

#[test]
fn a_misidentified_drive_raises_the_instability_warning_and_falls_back() {
    // Deliberately wrong models: the default (5 ms dead time, 25 ms) on
    // drives with 20, 25 and 60 ms of dead time, and a slow, prompt model
    // (75 ms, no dead time) on a fast, late drive (8.75 ms, 60 ms). With
    // the 10 % seedling load, Fixed 25.21 r/min.
    use closed::*;
    use hmi_proto::screen::Command;
    use supervisor::drive::DriveModel;
    use supervisor::drum::{Alarm, DRUM_UNSTABLE_TEXT};
    let sp = 25.21;
    for (name, real, model) in [
        (
            "20 ms drive, default model",
            drive(1.0, 1.0, 20),
            DriveModel::DEFAULT,
        ),
        (
            "25 ms drive, default model",
            drive(1.0, 1.0, 25),
            DriveModel::DEFAULT,
        ),
        (
            "60 ms drive, default model",
            drive(1.0, 1.0, 60),
            DriveModel::DEFAULT,
        ),
        (
            "8.75 ms + 60 ms drive, 75 ms + 0 ms model",
            drive(1.0, 0.35, 60),
            DriveModel::new(4470, 750, 0).unwrap(),
        ),
    ] {
        let cfg = Config {
            load_droop: 0.10,
            ..real
        };
        let settings = supervisor::settings::Settings {
            drive: model,
            ..fixed(2521)
        };
        let mut rig = Rig::new(cfg, settings);
        rig.sup.command(Command::Start);
        let mut speeds = Vec::new();
        let mut warned_at = None;
        for i in 0..1000 {
            speeds.push(rig.period());
            if warned_at.is_none() && rig.sup.alarm() == Some(Alarm::DrumUnstable) {
                warned_at = Some(i + 1);
                assert!(rig.sup.in_fallback());
            }
        }
        // Before the fallback the loop limit-cycles (issue 16: 16–36 r/min
        // at 20 ms): a swing of more than 25 % of the set point.
        let first = &speeds[20..warned_at.unwrap_or(1000).min(1000)];
        let (lo, hi) = (
            first.iter().copied().fold(f64::MAX, f64::min),
            first.iter().copied().fold(f64::MIN, f64::max),
        );
        println!("{name}: {lo:.1}..{hi:.1} r/min, warned after {warned_at:?} periods");
        assert!(hi - lo > 0.25 * sp, "{name}: no limit cycle to catch");
        // The warning within 1.5 s of Start, named on the screen.
        let at = warned_at.unwrap_or(usize::MAX);
        assert!(at <= 150, "{name}: warned after {at} periods");
        let mut text = String::new();
        Alarm::DrumUnstable.write_text(&mut text).unwrap();
        assert_eq!(text, DRUM_UNSTABLE_TEXT);
        assert!(text.len() <= 40);
        // The conservative mode settles: partition mean within ±2 % and the
        // 10 ms swing at most 15 % in the last 5 s; the drum keeps running.
        let f = figures(&speeds, sp, 500);
        println!(
            "{name}: after the fallback, partition mean {:+.2}..{:+.2} %, 10 ms {:+.1}..{:+.1} %",
            (f.pmin / sp - 1.0) * 100.0,
            (f.pmax / sp - 1.0) * 100.0,
            (f.min / sp - 1.0) * 100.0,
            (f.max / sp - 1.0) * 100.0
        );
        assert!(f.pmin >= 0.98 * sp && f.pmax <= 1.02 * sp, "{name}");
        assert!(f.max - f.min <= 0.15 * sp, "{name}");
        assert_eq!(rig.sup.run_state(), supervisor::drum::RunState::Running);
    }
}

#[test]
fn no_false_instability_warning_in_the_field_at_every_gear() {
    // The instability supervisor must stay quiet on a correct model: the
    // default drive (the simulator's default), Speed-Adaptive at every gear
    // (7 cm at Low 1–3, 20 cm at High 1–3), the simulator's default terrain
    // and noise, a 0.5 s chassis time constant, the seedlings' load at 10 %,
    // a start from standstill, a stop and a restart of the tractor: 20 s
    // each. Failed before two rules of the supervisor: a tractor coming to
    // rest left the drum at 1.5 r/min under a 1.15 r/min target (judged
    // only from 3 r/min now), and High 3 at 20 cm holds the drum at n_max
    // under the load, short of the target (not judged while the output is
    // at 100 %: the Too fast warning says it).
    use closed::*;
    use hmi_proto::screen::{Command, Mode, Spacing};
    use kinematics::consts::Gear;
    use supervisor::drum::Alarm;
    for (i, gear) in Gear::ALL.into_iter().enumerate() {
        let spacing_mm = if i < 3 { 70 } else { 200 };
        let cfg = Config {
            seed: 1800 + i as u64,
            initial_gear: Some(gear),
            track_tau_s: 0.5,
            load_droop: 0.10,
            ..Config::default()
        };
        let settings = supervisor::settings::Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(spacing_mm).unwrap(),
            gear,
            ..supervisor::settings::Settings::default()
        };
        let mut rig = Rig::new(cfg, settings);
        rig.m.stop_travel();
        for _ in 0..50 {
            rig.period();
        }
        rig.sup.command(Command::Start);
        rig.m.resume_travel();
        for k in 0..2000 {
            if k == 800 {
                rig.m.stop_travel();
            }
            if k == 1200 {
                rig.m.resume_travel();
            }
            rig.period();
            assert_ne!(
                rig.sup.alarm(),
                Some(Alarm::DrumUnstable),
                "{gear:?} at {k}"
            );
        }
        assert!(!rig.sup.in_fallback(), "{gear:?}");
    }
}

/// Stop during the identification: it ends as aborted, the drum stays off,
/// and the controller is back for the next Start (rebuilt by the next
/// control step, not inside the Stop's command): Fixed 20.00 r/min is held
/// within ±2 % of the partition mean 3 s after Start.
#[test]
fn a_stop_during_identification_aborts_it_and_the_next_start_runs_the_drum() {
    use closed::*;
    use hmi_proto::screen::Command;
    use supervisor::drum::{Effect, RunState};
    let mut rig = Rig::new(drive(1.0, 0.025, 5), fixed(2000));
    assert_eq!(
        rig.sup.command(Command::IdentifyDrive),
        Effect::Message(supervisor::drum::IDENTIFY_MESSAGE)
    );
    for _ in 0..30 {
        rig.period();
    }
    assert_eq!(rig.sup.run_state(), RunState::Identifying);
    rig.sup.command(Command::Stop);
    assert_eq!(rig.sup.run_state(), RunState::Stopped);
    assert_eq!(
        rig.sup.identify_state(),
        IdentifyState::Failed(supervisor::drive::IdentifyError::Aborted)
    );
    for _ in 0..10 {
        rig.period();
        assert_eq!(rig.act.ccr, 0, "the drum stays off after the Stop");
    }
    assert_eq!(rig.sup.command(Command::Start), Effect::None);
    let speeds: Vec<f64> = (0..500).map(|_| rig.period()).collect();
    let f = figures(&speeds, 20.0, 300);
    assert!(
        f.pmin >= 19.6 && f.pmax <= 20.4,
        "partition mean {:.2}..{:.2} r/min",
        f.pmin,
        f.pmax
    );
}
