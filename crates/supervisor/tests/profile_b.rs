//! Profile B's supervisor ([`BeltPlanter`]) against the machine simulator on
//! the host: the loop the firmware runs every 10 ms. The figures to beat are
//! paper B's bench (Table 2: feeding-spacing relative error 5.1 / 7.8 /
//! 11.4 %; Table 3: plant-spacing CV 7.42 / 9.34 / 13.29 % at 0.2 / 0.3 /
//! 0.4 m/s, X = 25 cm, B = 10 cm). The statistics are computed here, in
//! `f64`, from the simulator's plant events — never from the code under test.
//!
//! Feeding-spacing error, as paper B's Table 2: the relative error of the
//! *mean* spacing of the delivered seedlings against the theoretical one
//! (10.51 cm against 10 cm → 5.1 %). The simulator plants every delivered
//! seedling at the ground position of its delivery, so one belt pitch B maps
//! to one plant spacing X and `|mean(s) − X| / X` on the ground equals
//! `|mean(s)·B/X − B| / B` on the belt: the same number.
//!
//! Plant-spacing CV, as paper B's Table 3 (after JB/T 10291-2013): sample SD
//! (n − 1) over the mean of the spacings between consecutive plants, %.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::indexing_slicing,
    clippy::float_cmp
)]

use hmi_proto::screen::Command;
use kinematics::profile_b::{LinkageAction, ProfileBSettings};
use kinematics::units::{Hertz, Metres, MetresPerSecond};
use machine_sim::{Config, Event, Inputs, Machine, Profile};
use supervisor::belt::{BeltMachine, NEW_ROLL_DONE, NEW_ROLL_WHILE_RUNNING};
use supervisor::drum::{Effect, Hardware, Supervisor};
use supervisor::effect::BELT_MACHINE_ONLY;
use supervisor::planter::{
    BeltPlanter, ConfigField, Error, PlanterAlarm, PlanterState, ProfileBConfig, ProfileBHardware,
    StepperCommand, CONFIG_BYTES,
};
use supervisor::settings::{Profile as MachineProfile, Settings};

const HW: ProfileBHardware = ProfileBHardware::BOARD;

struct Rig {
    p: BeltPlanter,
    m: Machine,
    cmd: StepperCommand,
    plants: Vec<f64>,
    /// Every command, in order.
    log: Vec<StepperCommand>,
}

impl Rig {
    fn new(config: Config) -> Self {
        let cfg = ProfileBConfig::new(ProfileBSettings::default()).unwrap();
        Self {
            p: BeltPlanter::new(cfg, HW).unwrap(),
            m: config.build().unwrap(),
            cmd: StepperCommand::OFF,
            plants: Vec::new(),
            log: Vec::new(),
        }
    }

    /// One control period: the machine runs 10 ms under the last command,
    /// then the planter reads the ground encoder and the roller's turns.
    fn period(&mut self) {
        let inputs = Inputs {
            feed_step_rate_hz: self.cmd.feed_step_hz.to_f64() as f32,
            plant_step_rate_hz: self.cmd.plant_step_hz.to_f64() as f32,
            ..Inputs::default()
        };
        let plants = &mut self.plants;
        self.m.step_events(10_000, &inputs, &mut |e| {
            if let Event::Plant { ground_m, .. } = e {
                plants.push(ground_m);
            }
        });
        self.cmd = self
            .p
            .control_step(self.m.ground_encoder_count(), self.m.feed_roller_turns());
        self.log.push(self.cmd);
    }
}

fn profile_b(config: Config) -> Config {
    Config {
        profile: Profile::B,
        target_spacing_m: 0.25,
        ..config
    }
}

/// Paper B's figures at 0.2 / 0.3 / 0.4 m/s, %.
const PAPER: [(f32, f64, f64); 3] = [(0.2, 5.1, 7.42), (0.3, 7.8, 9.34), (0.4, 11.4, 13.29)];

struct Row {
    /// Feeding-spacing relative error, %.
    feed_err_pct: f64,
    /// Plant-spacing CV, %.
    cv_pct: f64,
    mean_m: f64,
    spacings: usize,
}

/// Starts the planter with the machine standing, then travels at `v` for
/// `ground_m` of ground with the default (noisy) machine; statistics over the
/// plants after the first metre (the start-up: the speed window fills and
/// the feeding motor ramps up).
fn row(v: f32, ground_m: f64, compensation: bool, seed: u64) -> Row {
    let mut rig = Rig::new(profile_b(Config {
        seed,
        ..Config::default()
    }));
    rig.p.set_radius_compensation(compensation);
    rig.p.start();
    rig.period();
    rig.m.set_travel_speed_m_s(v);
    while rig.m.ground_position_m() < ground_m + 1.0 {
        rig.period();
    }
    let (mean, sd, spacings) = spacing_stats(&rig.plants);
    Row {
        feed_err_pct: (mean - 0.25).abs() / 0.25 * 100.0,
        cv_pct: sd / mean * 100.0,
        mean_m: mean,
        spacings,
    }
}

/// Mean, sample SD (n − 1) and count of the spacings between consecutive
/// plants after the first metre (the start-up), in `f64` from the
/// simulator's plant positions.
fn spacing_stats(plants: &[f64]) -> (f64, f64, usize) {
    let s: Vec<f64> = plants
        .windows(2)
        .filter(|w| w[0] >= 1.0)
        .map(|w| w[1] - w[0])
        .collect();
    let n = s.len() as f64;
    let mean = s.iter().sum::<f64>() / n;
    let sd = (s.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    (mean, sd, s.len())
}

#[test]
fn beats_paper_b_at_02_03_04_m_s_and_the_radius_compensation_matters() {
    for (v, paper_err, paper_cv) in PAPER {
        // 30 m of row: 120 spacings at X = 25 cm (paper B measured 30 × 3).
        let on = row(v, 30.0, true, 1);
        let off = row(v, 30.0, false, 1);
        println!(
            "v = {v} m/s: with eq. 9 error {:.2} % CV {:.2} % (mean {:.4} m, {} spacings); \
             without (r for every j) error {:.2} % CV {:.2} % (mean {:.4} m); paper B {paper_err} % / {paper_cv} %",
            on.feed_err_pct, on.cv_pct, on.mean_m, on.spacings, off.feed_err_pct, off.cv_pct, off.mean_m
        );
        assert!(on.spacings >= 110, "{} spacings", on.spacings);
        assert!(
            on.feed_err_pct < paper_err,
            "{v} m/s: feeding error {:.2} % vs paper {paper_err} %",
            on.feed_err_pct
        );
        assert!(
            on.cv_pct < paper_cv,
            "{v} m/s: CV {:.2} % vs paper {paper_cv} %",
            on.cv_pct
        );
        assert!(
            off.feed_err_pct > on.feed_err_pct && off.cv_pct > on.cv_pct,
            "{v} m/s: without compensation {:.2} % / {:.2} % is not worse than {:.2} % / {:.2} %",
            off.feed_err_pct,
            off.cv_pct,
            on.feed_err_pct,
            on.cv_pct
        );
    }
}

#[test]
fn other_seeds_beat_paper_b_too() {
    // Not one lucky noise sequence: four more seeds at each speed.
    for seed in 2..6 {
        for (v, paper_err, paper_cv) in PAPER {
            let on = row(v, 30.0, true, seed);
            println!(
                "seed {seed}, {v} m/s: error {:.2} % CV {:.2} %",
                on.feed_err_pct, on.cv_pct
            );
            assert!(
                on.feed_err_pct < paper_err && on.cv_pct < paper_cv,
                "seed {seed}, {v} m/s: {:.2} % / {:.2} %",
                on.feed_err_pct,
                on.cv_pct
            );
        }
    }
}

#[test]
fn both_motors_stop_in_the_first_period_without_a_ground_count() {
    let mut rig = Rig::new(profile_b(Config::default()));
    rig.p.start();
    rig.m.set_travel_speed_m_s(0.3);
    for _ in 0..300 {
        rig.period();
    }
    assert!(rig.cmd.feed_step_hz > Hertz::lit("500"), "{:?}", rig.cmd);
    assert!(rig.cmd.plant_step_hz > Hertz::lit("200"), "{:?}", rig.cmd);
    // The distance on the screen: ground counts · π·0.25/2400 = 0.327 mm per
    // count, in whole mm; the very first read after boot only sets the
    // counter's reference (one period, 9 counts = 3 mm, lost).
    let shown = f64::from(rig.p.snapshot().distance_mm) / 1000.0;
    assert!(
        (shown - rig.m.ground_position_m()).abs() < 0.005,
        "{shown} {} {}",
        rig.m.ground_position_m(),
        rig.m.ground_encoder_count()
    );
    // Travel stops between two control steps: the next period has no count,
    // and that period's control step must stop both motors.
    let before = rig.m.ground_encoder_count();
    rig.m.stop_travel();
    rig.period();
    assert_eq!(rig.m.ground_encoder_count(), before, "the encoder stopped");
    assert_eq!(rig.cmd.feed_step_hz, Hertz::ZERO);
    assert_eq!(rig.cmd.plant_step_hz, Hertz::ZERO);
    assert!(rig.cmd.enabled, "drivers hold the motors");
    assert_eq!(rig.p.snapshot().action, LinkageAction::Stop);
    assert_eq!(rig.p.snapshot().travel_speed, MetresPerSecond::ZERO);
    for _ in 0..100 {
        rig.period();
        assert_eq!(rig.cmd.feed_step_hz, Hertz::ZERO);
        assert_eq!(rig.cmd.plant_step_hz, Hertz::ZERO);
    }
    // Travel resumes: the motors start again, within the acceleration limit.
    rig.m.resume_travel();
    for _ in 0..100 {
        rig.period();
    }
    assert!(rig.cmd.feed_step_hz > Hertz::lit("500"), "{:?}", rig.cmd);
    // Operator Stop: drivers off at the next step.
    rig.p.stop();
    rig.period();
    assert_eq!(rig.cmd, StepperCommand::OFF);
    assert_eq!(rig.p.state(), PlanterState::Stopped);
}

#[test]
fn step_rates_never_change_by_more_than_the_limit_except_to_stop() {
    // A start from standstill, speed steps of +30 % and −30 %, 60 m of roller
    // growth (many j increments), a stop and a restart.
    let mut rig = Rig::new(profile_b(Config::default()));
    rig.p.start();
    rig.m.set_travel_speed_m_s(0.3);
    for k in 0..8000 {
        match k {
            2000 => rig.m.inject_speed_step(0.3),
            3000 => rig.m.inject_speed_step(-0.3),
            4000 => rig.m.clear_speed_step(),
            5000 => rig.m.stop_travel(),
            5100 => rig.m.resume_travel(),
            _ => {}
        }
        rig.period();
    }
    let limit = HW.max_step_change_hz.to_f64();
    assert_eq!(limit, 40.0);
    let mut limited = 0;
    let mut stops = 0;
    let mut prev = StepperCommand::OFF;
    for c in &rig.log {
        for (a, b) in [
            (prev.feed_step_hz, c.feed_step_hz),
            (prev.plant_step_hz, c.plant_step_hz),
        ] {
            let d = (b.to_f64() - a.to_f64()).abs();
            if b == Hertz::ZERO {
                stops += usize::from(a != Hertz::ZERO);
            } else {
                assert!(d <= limit, "{a} → {b}");
                limited += usize::from(d == limit);
            }
        }
        prev = *c;
    }
    // The limit acted (the ramps) and the stop was immediate.
    assert!(limited > 40, "{limited} limited changes");
    assert_eq!(stops, 2, "one stop, both motors");
}

/// A synthetic ground encoder: 12 counts per 10 ms period on the 0.25 m
/// wheel with 2400 counts per turn is Vm = 12·π·0.25/2400/0.01 = π/8
/// = 0.392 699 m/s — a speed whose n1 and n2 come out round.
fn drive(p: &mut BeltPlanter, counter: &mut u16, periods: u32, per_period: u16, j: u32) {
    for _ in 0..periods {
        *counter = counter.wrapping_add(per_period);
        p.control_step(*counter, j);
    }
}

#[test]
fn n1_and_n2_by_hand() {
    let cfg = ProfileBConfig::new(ProfileBSettings::default()).unwrap();
    let mut p = BeltPlanter::new(cfg, HW).unwrap();
    // Paper B's linkage alone (eq. 4 and 9 by hand); the position lock on
    // top of it is tested below.
    p.set_position_lock(false);
    p.start();
    let mut c = 0xFFF0; // the counter wraps during the run
    drive(&mut p, &mut c, 60, 12, 0);
    let s = *p.snapshot();
    let vm = std::f64::consts::PI / 8.0;
    assert!(
        (s.travel_speed.to_f64() - vm).abs() < 1e-6,
        "{}",
        s.travel_speed
    );
    assert!((s.computed_for.to_f64() - vm).abs() < 1e-6);
    // Eq. 4: n1 = 60·β·Vm/(2π·N·X), β = 120° = 2π/3 rad, N = 2, X = 0.25 m:
    // 60·(2π/3)·(π/8)/(2π·2·0.25) = 5π = 15.708 r/min;
    // 15.708·1600/60 = 418.88 Hz.
    assert!((s.planting_speed.to_f64() - 15.707_963).abs() < 1e-3);
    assert!((s.plant_step_hz.to_f64() - 418.879).abs() < 0.01);
    // Eq. 9 at j = 0: n2 = 60·Vm·B/(2π·X·r) = 60·(π/8)·0.1/(2π·0.25·0.025)
    // = 0.75π/(0.0125π) = 60 r/min; 60·1600/60 = 1600 Hz. Stored in U12F20
    // (rounded to 2^-20 m), r = 0.024 999 6 m and B = 0.100 000 4 m: +1.9e-5
    // relative, 60.0011 r/min, 1600.03 Hz.
    assert!((s.feeding_speed.to_f64() - 60.0).abs() < 2e-3, "{s:?}");
    assert!((s.target_feed_step_hz.to_f64() - 1600.0).abs() < 0.05);
    // 60 periods at 40 Hz per period have reached it (40 periods).
    assert_eq!(s.feed_step_hz, s.target_feed_step_hz);
    // Eq. 8/9 at j = 10: r' = 0.025 + 10·0.001 = 0.035 m,
    // n2 = 0.75π/(2π·0.25·0.035) = 42.857 r/min, 1142.86 Hz (as stored,
    // h = 0.001 000 4 m, B = 0.100 000 4 m: r' = 0.035 003 7 m, n2 = 42.853
    // r/min, 1142.74 Hz).
    drive(&mut p, &mut c, 1, 12, 10);
    let s = *p.snapshot();
    assert_eq!(s.action, LinkageAction::RecomputeFeeding);
    assert_eq!(s.roller_turns, 10);
    assert!(
        (s.roller_radius.to_f64() - 0.035_003_7).abs() < 1e-6,
        "{s:?}"
    );
    assert!(
        (s.feeding_speed.to_f64() - 42.853).abs() < 1e-3,
        "{}",
        s.feeding_speed
    );
    assert!((s.target_feed_step_hz.to_f64() - 1142.74).abs() < 0.02);
    // The applied rate moves towards it 40 Hz per period.
    assert!((s.feed_step_hz.to_f64() - 1560.03).abs() < 0.02);
    // Without compensation the radius stays r and n2 stays 60 r/min.
    p.stop();
    drive(&mut p, &mut c, 1, 12, 10);
    p.set_radius_compensation(false);
    p.start();
    drive(&mut p, &mut c, 60, 12, 10);
    let s = *p.snapshot();
    assert_eq!(s.roller_radius, Metres::lit("0.025"));
    assert!((s.feeding_speed.to_f64() - 60.0).abs() < 2e-3);
}

#[test]
fn threshold_y_holds_small_changes_and_recomputes_beyond_them() {
    // One count per period is 0.0327 m/s; the window is 20 periods, so an
    // alternating 12/13 counts reads π/8 + 0.0164 m/s: within Y = 0.02.
    let cfg = ProfileBConfig::new(ProfileBSettings::default()).unwrap();
    let mut p = BeltPlanter::new(cfg, HW).unwrap();
    p.start();
    let mut c = 0;
    drive(&mut p, &mut c, 40, 12, 0);
    let v0 = p.snapshot().computed_for;
    for _ in 0..20 {
        drive(&mut p, &mut c, 1, 12, 0);
        drive(&mut p, &mut c, 1, 13, 0);
        assert_eq!(p.snapshot().action, LinkageAction::Hold);
        assert_eq!(p.snapshot().computed_for, v0);
    }
    // 13 every period: +0.0327 m/s > Y: recomputed as soon as the windowed
    // speed leaves V0 ± Y (the window then holds mostly 13s).
    let mut recomputed = 0;
    for _ in 0..20 {
        drive(&mut p, &mut c, 1, 13, 0);
        if p.snapshot().action == LinkageAction::Recompute {
            recomputed += 1;
            let v1 = p.snapshot().computed_for;
            assert!(v1.to_f64() > v0.to_f64() + 0.02, "{v1} vs {v0}");
        }
    }
    assert_eq!(recomputed, 1);
}

#[test]
fn restart_after_standstill_uses_a_fresh_window() {
    let cfg = ProfileBConfig::new(ProfileBSettings::default()).unwrap();
    let mut p = BeltPlanter::new(cfg, HW).unwrap();
    p.start();
    let mut c = 0;
    drive(&mut p, &mut c, 40, 12, 0);
    drive(&mut p, &mut c, 1, 0, 0);
    assert_eq!(p.snapshot().travel_speed, MetresPerSecond::ZERO);
    // Restart at 6 counts per period: the first reading is 6 counts over one
    // period, not diluted by the window's old periods.
    drive(&mut p, &mut c, 1, 6, 0);
    let v = p.snapshot().travel_speed.to_f64();
    assert!((v - std::f64::consts::PI / 16.0).abs() < 1e-6, "{v}");
    // The feeding motor ramps from 0 (not from its old rate).
    assert!(p.snapshot().feed_step_hz <= Hertz::lit("40"));
}

#[test]
fn absurd_speeds_stop_the_motors_and_clamped_rates_warn() {
    let cfg = ProfileBConfig::new(ProfileBSettings::default()).unwrap();
    let mut p = BeltPlanter::new(cfg, HW).unwrap();
    p.start();
    let mut c = 0;
    // 30 000 counts per 10 ms = 982 m/s: the speeds do not fit — stop.
    drive(&mut p, &mut c, 5, 30_000, 0);
    assert_eq!(p.snapshot().alarm, Some(PlanterAlarm::OutOfRange));
    assert_eq!(p.snapshot().feed_step_hz, Hertz::ZERO);
    // A low step-rate ceiling: clamped, warned.
    let hw = ProfileBHardware {
        max_step_hz: Hertz::lit("1000"),
        ..HW
    };
    let mut p = BeltPlanter::new(cfg, hw).unwrap();
    p.start();
    drive(&mut p, &mut c, 60, 12, 0);
    assert_eq!(p.snapshot().alarm, Some(PlanterAlarm::TooFast));
    assert_eq!(p.snapshot().feed_step_hz, Hertz::lit("1000"));
}

/// A fine micro-step setting (51 200 steps/rev, in range) at a normal
/// travel speed: 16 counts per period is π/6 = 0.524 m/s (1.9 km/h), where
/// n2 = 60 · (0.524 · 0.10) / (2π · 0.25 · 0.025) = 80 r/min (hand-computed,
/// as `n1_and_n2_by_hand`'s 60 r/min at 12 counts × 16/12), i.e. 68 267
/// step/s: beyond the 20 kHz the board makes, and beyond the 65 536 Hz a
/// `Hertz` holds. The motor speeds are sane (80 and 20.9 r/min), so this is
/// the step-rate ceiling's case (module docs: clamped at `max_step_hz`,
/// `TooFast`), not a broken encoder's. Before: the step rate's overflow
/// read as `OutOfRange` and stopped both motors while the tractor drove on.
#[test]
fn a_step_rate_beyond_the_hertz_range_is_clamped_not_a_stop() {
    let cfg = ProfileBConfig::new(ProfileBSettings {
        feeding_steps_per_rev: 51_200,
        ..ProfileBSettings::default()
    })
    .unwrap();
    let mut p = BeltPlanter::new(cfg, HW).unwrap();
    p.start();
    let mut c = 0;
    // 20 kHz at 40 Hz a period: 500 periods of ramp.
    drive(&mut p, &mut c, 600, 16, 0);
    let s = *p.snapshot();
    assert_eq!(s.alarm, Some(PlanterAlarm::TooFast));
    assert_eq!(s.feed_step_hz, HW.max_step_hz);
    // n1 = 5π · 16/12 r/min at 1600 steps/rev = 558.5 Hz: still planting.
    let n1_hz = 5.0 * std::f64::consts::PI * 16.0 / 12.0 * 1600.0 / 60.0;
    assert!(
        (s.plant_step_hz.to_f64() - n1_hz).abs() < 0.1,
        "{}",
        s.plant_step_hz
    );
}

#[test]
fn settings_are_validated_round_trip_and_change_only_when_stopped() {
    let d = ProfileBSettings::default();
    let cfg = ProfileBConfig::new(d).unwrap();
    assert_eq!(*cfg.settings(), d);
    let bytes = cfg.to_bytes();
    assert_eq!(bytes.len(), CONFIG_BYTES);
    assert_eq!(ProfileBConfig::from_bytes(&bytes).unwrap(), cfg);
    let bad = |s: ProfileBSettings| ProfileBConfig::new(s).unwrap_err();
    assert_eq!(
        bad(ProfileBSettings {
            plant_spacing: Metres::lit("0.05"),
            ..d
        }),
        Error::Range(ConfigField::PlantSpacing)
    );
    assert_eq!(
        bad(ProfileBSettings {
            belt_thickness: Metres::lit("0.02"),
            ..d
        }),
        Error::Range(ConfigField::BeltThickness)
    );
    assert_eq!(
        bad(ProfileBSettings {
            seedlings_clamped: 0,
            ..d
        }),
        Error::Range(ConfigField::SeedlingsClamped)
    );
    assert_eq!(
        bad(ProfileBSettings {
            threshold: MetresPerSecond::lit("0.5"),
            ..d
        }),
        Error::Range(ConfigField::Threshold)
    );
    assert_eq!(
        bad(ProfileBSettings {
            feeding_steps_per_rev: 100,
            ..d
        }),
        Error::Range(ConfigField::StepsPerRev)
    );
    let mut corrupt = bytes;
    corrupt[CONFIG_BYTES - 1] = 0;
    assert_eq!(
        ProfileBConfig::from_bytes(&corrupt).unwrap_err(),
        Error::Range(ConfigField::SeedlingsClamped)
    );
    assert_eq!(
        Error::Range(ConfigField::RollerRadius).to_string(),
        "out of range: Roller radius r: 5-200 mm"
    );
    assert!(BeltPlanter::new(
        cfg,
        ProfileBHardware {
            speed_window_periods: 0,
            ..HW
        }
    )
    .is_err());
    let mut p = BeltPlanter::new(cfg, HW).unwrap();
    p.start();
    assert_eq!(p.set_config(cfg), Err(Error::Running));
    p.stop();
    assert_eq!(p.set_config(cfg), Ok(()));
}

/// Position-locked feeding (issue 19) against paper B's speed linkage alone,
/// on a row whose travel speed steps ±20 % around 0.3 m/s every 2 s (the
/// "hills" profile): the linkage holds n2 within Y = 0.02 m/s and its 200 ms
/// speed window lags, so the belt drifts from the ground; the lock feeds
/// the lag back. Figures from the simulator's plant events and the
/// planter's own belt lag; the bound 2 mm is 0.8 % of X.
#[test]
fn position_lock_keeps_the_belt_with_the_ground_and_tightens_the_spacing() {
    let run = |lock: bool| {
        let mut rig = Rig::new(profile_b(Config {
            seed: 7,
            ..Config::default()
        }));
        rig.p.set_position_lock(lock);
        rig.p.start();
        rig.period();
        let speeds = [0.3f32, 0.36, 0.24, 0.33, 0.27, 0.36, 0.24, 0.3];
        let mut lags: Vec<i64> = Vec::new();
        let mut periods = 0u32;
        while rig.m.ground_position_m() < 31.0 {
            if periods.is_multiple_of(200) {
                rig.m
                    .set_travel_speed_m_s(speeds[(periods / 200) as usize % speeds.len()]);
            }
            rig.period();
            periods += 1;
            if rig.m.ground_position_m() > 1.0 {
                lags.push(rig.p.belt_lag_um().abs());
            }
        }
        let (mean, sd, _) = spacing_stats(&rig.plants);
        lags.sort_unstable();
        let p95 = lags[lags.len() * 95 / 100];
        let max = *lags.last().unwrap();
        (
            sd / mean * 100.0,
            (mean - 0.25).abs() / 0.25 * 100.0,
            (p95, max),
        )
    };
    let (cv_lock, err_lock, lag_lock) = run(true);
    let (cv_free, err_free, lag_free) = run(false);
    println!(
        "hills: locked CV {cv_lock:.2} % error {err_lock:.2} % belt lag p95/max {:.2}/{:.2} mm; \
         linkage alone CV {cv_free:.2} % error {err_free:.2} % belt lag p95/max {:.2}/{:.2} mm",
        lag_lock.0 as f64 / 1000.0,
        lag_lock.1 as f64 / 1000.0,
        lag_free.0 as f64 / 1000.0,
        lag_free.1 as f64 / 1000.0
    );
    // Right after a 20 % step the lag builds up for the 200 ms speed window
    // (≈ 0.2 · 0.3 m/s · 0.1 s = 6 mm of ground = 2.4 mm of belt) before the
    // lock takes it up at ≤ 10 % of the rate: bounds 6 mm (max), 3 mm (p95).
    assert!(
        lag_lock.1 <= 6_000 && lag_lock.0 <= 3_000,
        "locked belt lag {lag_lock:?} um"
    );
    assert!(
        lag_free.0 > 5 * lag_lock.0,
        "the linkage alone lags {lag_free:?} um"
    );
    assert!(cv_lock < cv_free, "CV {cv_lock:.2} % vs {cv_free:.2} %");
}

// ---------------------------------------------------------------------
// New roll (page 7 `broll`) and the roller index guard, on `BeltMachine`:
// the profile B machine the firmware runs, which counts the roller index
// pulses into `j`.

/// Profile B's machine with the default settings (position lock on, the
/// default placement).
fn belt_machine() -> BeltMachine {
    let settings = Settings {
        profile: MachineProfile::SeedlingBelt,
        ..Settings::default()
    };
    BeltMachine::new(settings, HW).unwrap()
}

/// `periods` control periods at 12 ground counts per period (Vm = π/8 m/s,
/// see [`drive`]), a roller index pulse in every `pulse_every`-th period
/// (0: none).
fn run_belt(m: &mut BeltMachine, counter: &mut u16, periods: u32, pulse_every: u32) {
    for i in 1..=periods {
        *counter = counter.wrapping_add(12);
        let pulses = u32::from(pulse_every != 0 && i % pulse_every == 0);
        m.control_step(*counter, pulses);
    }
}

/// SPEC §8 eq. 9 with eq. 8, in `f64` from the nominal defaults (X = 0.25 m,
/// B = 0.10 m, r = 25 mm, h = 1 mm, 1600 steps/rev): the feeding motor's
/// step rate `n2·steps/60`, `n2 = 60·Vm·B/(2π·X·(r + h·j))`.
fn eq9_feed_hz(vm: f64, j: u32) -> f64 {
    let (x, b, r, h, steps) = (0.25, 0.10, 0.025, 0.001, 1600.0);
    let n2 = 60.0 * vm * b / (2.0 * std::f64::consts::PI * x * (r + h * f64::from(j)));
    n2 * steps / 60.0
}

/// The bug: `j` counted from power-up and nothing reset it, so a second
/// roll started at j ≈ 42, r' = 67 mm, and was fed at 25/67 = 37 % of the
/// rate (spacing ≈ 2.7 X), the position lock with it. *New roll* with the
/// motors stopped restarts `j`, and the next run feeds at eq. 9's rate for
/// r = 25 mm. Tolerances: the linkage's target within 0.05 Hz of the `f64`
/// formula at j = 0 (the stored U12F20 settings are 1.9e-5 off: 0.03 Hz at
/// 1600 Hz) and within 0.05 % at j = 42 (h is stored 4e-4 high, r' =
/// 67.016 mm: 2.4e-4, 0.15 Hz); the rate sent, with the position lock's
/// correction, within 0.1 % once the start-up lag is taken up (measured:
/// 1600.15 Hz, a belt lag of 2 µm).
#[test]
fn new_roll_while_stopped_feeds_the_next_run_at_the_empty_roller_rate() {
    let vm = std::f64::consts::PI / 8.0;
    let mut m = belt_machine();
    let mut c = 0u16;
    // A whole roll: 42 turns, one every 0.5 s, while planting.
    assert_eq!(m.command(Command::Start), Effect::None);
    run_belt(&mut m, &mut c, 42 * 50, 50);
    let s = *m.planter().snapshot();
    assert_eq!(s.roller_turns, 42);
    assert_eq!(m.screen_status().roller_radius_dmm, 670);
    let full = eq9_feed_hz(vm, 42); // 597.0 Hz
    assert!(
        (s.target_feed_step_hz.to_f64() - full).abs() < 5e-4 * full,
        "{} vs {full}",
        s.target_feed_step_hz
    );

    // Refused while running: nothing changes.
    assert_eq!(
        m.command(Command::NewRoll),
        Effect::Message(NEW_ROLL_WHILE_RUNNING)
    );
    run_belt(&mut m, &mut c, 1, 0);
    assert_eq!(m.planter().snapshot().roller_turns, 42);
    assert_eq!(m.roller_turns(), 42);
    assert_eq!(
        m.planter().snapshot().target_feed_step_hz,
        s.target_feed_step_hz
    );

    // Stopped (the machine stands while the roll is changed): taken, and
    // the screen shows j = 0 and r at once.
    assert_eq!(m.command(Command::Stop), Effect::None);
    for _ in 0..10 {
        m.control_step(c, 0);
    }
    assert_eq!(m.command(Command::NewRoll), Effect::Message(NEW_ROLL_DONE));
    let st = m.screen_status();
    assert_eq!((st.roller_turns, st.roller_radius_dmm), (0, 250));
    assert_eq!(m.roller_turns(), 0);

    // The next run: eq. 9 at j = 0 (1600 Hz), not at j = 42 (597 Hz).
    assert_eq!(m.command(Command::Start), Effect::None);
    run_belt(&mut m, &mut c, 400, 0);
    let s = *m.planter().snapshot();
    let empty = eq9_feed_hz(vm, 0);
    assert_eq!(s.roller_turns, 0);
    assert!(
        (s.target_feed_step_hz.to_f64() - empty).abs() < 0.05,
        "{} vs {empty}",
        s.target_feed_step_hz
    );
    assert!(
        (s.feed_step_hz.to_f64() - empty).abs() < 1e-3 * empty,
        "sent {} vs {empty}",
        s.feed_step_hz
    );
    // And the position lock's belt is fed at r's radius: its lag is small.
    assert!(
        m.planter().belt_lag_um().abs() < 100,
        "{}",
        m.planter().belt_lag_um()
    );
}

/// Profile A has no belt roller: *New roll* is refused with a message and
/// changes nothing (also through `Machine`, as the firmware calls it).
#[test]
fn new_roll_is_refused_on_profile_a_and_the_messages_fit() {
    let mut a = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
    let before = a.settings().clone();
    assert_eq!(
        a.command(Command::NewRoll),
        Effect::Message(BELT_MACHINE_ONLY)
    );
    assert_eq!(a.settings(), &before);
    let mut m = supervisor::machine::Machine::DrumBelt(a);
    assert_eq!(
        m.command(Command::NewRoll),
        Effect::Message(BELT_MACHINE_ONLY)
    );
    for text in [BELT_MACHINE_ONLY, NEW_ROLL_DONE, NEW_ROLL_WHILE_RUNNING] {
        assert!(
            text.is_ascii() && text.len() <= hmi_proto::MAX_TEXT_LEN,
            "{text}"
        );
    }
}

/// The roller index input has no debounce. Each bounce used to add a
/// turn to `j` (measured before the guard: j = 4 after one turn with
/// three bounces, 200 after 100 turns each with a bounce 10 ms later).
/// The guard counts at most one pulse per `roller_index_gap_periods`
/// (4 periods on the board: half of the 80 ms turn at the 20 kHz ceiling,
/// 1600 steps/rev) and never drops a real turn, even at that ceiling.
#[test]
fn roller_index_bounces_are_not_turns() {
    let mut m = belt_machine();
    let mut c = 0u16;
    m.command(Command::Start);
    run_belt(&mut m, &mut c, 50, 0);
    // One turn: its pulse, a bounce in the next period, two in the third
    // (an overcapture reported as two), then quiet.
    for pulses in [1, 1, 0, 2, 0, 0, 0, 0] {
        c = c.wrapping_add(12);
        m.control_step(c, pulses);
    }
    assert_eq!(m.planter().snapshot().roller_turns, 1);
    // 100 turns at paper B's fastest (≈ 1 r/s, 100 periods a turn), each
    // with a bounce one period later.
    for _ in 0..100 {
        for i in 0..100 {
            c = c.wrapping_add(12);
            m.control_step(c, u32::from(i < 2));
        }
    }
    assert_eq!(m.planter().snapshot().roller_turns, 101);
    assert_eq!(m.index_pulses_ignored(), 3 + 100);
    // The board's guard: 1600 steps at 20 kHz = 80 ms a turn, half = 40 ms.
    assert_eq!(m.roller_index_gap_periods(), 4);
    // Turns at the step-rate ceiling (one every 8 periods) all count, and
    // so do pulses exactly one gap apart (4 periods).
    let before = m.planter().snapshot().roller_turns;
    run_belt(&mut m, &mut c, 8 * 50, 8);
    run_belt(&mut m, &mut c, 4 * 50, 4);
    assert_eq!(m.planter().snapshot().roller_turns, before + 100);
    assert_eq!(m.index_pulses_ignored(), 103);
    // Stopped (a roll threaded by hand), the turns still count.
    m.command(Command::Stop);
    run_belt(&mut m, &mut c, 20, 10);
    assert_eq!(m.planter().snapshot().roller_turns, before + 102);
}
