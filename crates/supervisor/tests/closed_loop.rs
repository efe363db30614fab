//! The supervisor against the machine simulator on the host: the same loop
//! the firmware runs every 10 ms, without the RTOS. Expected values come from
//! an independent f64 form of eq. 7 on the simulator's *true* ground speed
//! and the belt slip of Table 13, never from the code under test.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::indexing_slicing
)]

use hmi_proto::screen::{Command, DrumSpeed, Mode, Spacing};
use kinematics::consts::Gear;
use kinematics::units::Ticks;
use machine_sim::reference::eq7_drum_speed;
use machine_sim::{Config, Fault, Inputs, Machine};
use supervisor::drum::{Actuation, Alarm, Hardware, RunState, Supervisor};
use supervisor::settings::Settings;

const HW: Hardware = Hardware::BOARD;

struct Rig {
    sup: Supervisor,
    m: Machine,
    act: Actuation,
    t_ms: u32,
}

impl Rig {
    fn new(config: Config, settings: Settings) -> Self {
        Self {
            sup: Supervisor::new(HW, settings).unwrap(),
            m: config.build().unwrap(),
            act: Actuation::OFF,
            t_ms: 0,
        }
    }

    /// One control period: the machine runs 10 ms under the last output,
    /// then the supervisor reads it, exactly as the firmware's control task.
    fn period(&mut self) {
        self.period_of(10_000);
    }

    /// A control period released `us` after the previous one (the task's
    /// release jitters; the machine runs on regardless).
    fn period_of(&mut self, us: u32) {
        let inputs = Inputs {
            drum_duty: f32::from(self.act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: self.act.driver_enabled,
            ..Inputs::default()
        };
        let sup = &mut self.sup;
        self.m.step(us, &inputs, &mut |t| sup.hall_edge(Ticks(t)));
        self.act = self
            .sup
            .control_step(Ticks(self.m.capture_ticks()), self.m.drum_encoder_count());
        self.t_ms += us / 1000;
    }

    fn run_ms(&mut self, ms: u32) {
        for _ in 0..ms / 10 {
            self.period();
        }
    }
}

fn adaptive(spacing_mm: u16) -> Settings {
    Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(i32::from(spacing_mm)).unwrap(),
        gear: Gear::Low2,
        ..Settings::default()
    }
}

fn low2(config: Config) -> Config {
    Config {
        initial_gear: Some(Gear::Low2),
        ..config
    }
}

/// A tracked chassis: its speed answers a change of load or throttle with a
/// time constant of `tau` seconds rather than jumping.
fn chassis(config: Config, tau: f32) -> Config {
    Config {
        track_tau_s: tau,
        ..config
    }
}

#[test]
fn speed_adaptive_7cm_low2_settles_within_half_a_second_and_follows_a_10_percent_disturbance() {
    // Noiseless machine (no pitch error, jitter or terrain), so that the
    // errors are the controller's and the estimator's; a ±10 % change of
    // travel speed through the chassis's 2.5 s time constant (a load or
    // throttle change: at most 4.4 %/s). The Hall gear sees one edge every
    // 177 ms at Low 2, so the drum learns of a change up to 177 ms late; a
    // change faster than ≈ 5 %/s cannot be followed within 1 % by any
    // controller on this sensor (docs/firmware.md; the benchmark reports the
    // faster case).
    let mut rig = Rig::new(chassis(low2(Config::noiseless()), 2.5), adaptive(70));
    // Let the tractor reach speed and the estimator learn the gear's teeth.
    rig.run_ms(10_000);
    assert_eq!(
        rig.sup.command(Command::Start),
        supervisor::drum::Effect::None
    );
    let start = rig.t_ms;
    let mut worst_after_settle: f64 = 0.0;
    let mut worst_disturbed: f64 = 0.0;
    while rig.t_ms - start < 34_000 {
        rig.period();
        let t = rig.t_ms - start;
        match t {
            2_000 => rig.m.inject_speed_step(0.10),
            10_000 | 26_000 => rig.m.clear_speed_step(),
            18_000 => rig.m.inject_speed_step(-0.10),
            _ => {}
        }
        let target = eq7_drum_speed(f64::from(rig.m.travel_speed_m_s()), 0.07);
        let err = (f64::from(rig.m.drum_speed_rpm()) - target).abs() / target;
        if (500..2_000).contains(&t) {
            worst_after_settle = worst_after_settle.max(err);
        }
        if t >= 2_000 {
            worst_disturbed = worst_disturbed.max(err);
        }
    }
    assert!(
        worst_after_settle <= 0.01,
        "after 0.5 s: {:.3} %",
        worst_after_settle * 100.0
    );
    assert!(
        worst_disturbed <= 0.01,
        "through ±10 %: {:.3} %",
        worst_disturbed * 100.0
    );
}

#[test]
fn fixed_mode_holds_20_rpm_within_half_a_percent() {
    let settings = Settings {
        mode: Mode::Fixed,
        fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
        ..Settings::default()
    };
    // The full noise model: seedling load ±5 % per partition, speed ripple.
    let mut rig = Rig::new(Config::default(), settings);
    rig.sup.command(Command::Start);
    rig.run_ms(3_000);
    let (mut sum, mut n) = (0.0, 0.0);
    for _ in 0..500 {
        rig.period();
        // The reported speed (smoothed over ≈ 0.5 s), as the screen shows it.
        let reported = f64::from(rig.sup.snapshot().actual_drum_rpm_x1000) / 1000.0;
        assert!((reported - 20.0).abs() <= 0.1, "reported {reported}");
        sum += f64::from(rig.m.drum_speed_rpm());
        n += 1.0;
    }
    // And the drum itself, on average over those 5 s.
    let mean = sum / n;
    assert!((mean - 20.0).abs() <= 0.1, "true mean {mean}");
}

/// A drive twice as fast as the drum model assumes (motor lag 12.5 ms instead
/// of 25 ms; a different motor or a lighter belt). With paper A's ΔKp range
/// (±5) the 7×7 tuner raised Kp to ≈ 5 at overspeed and the drum oscillated
/// between ≈ 13 and 34 r/min without end (docs/PERFORMANCE.md §1,
/// robustness); the product's narrowed range must settle. Expected: the
/// set 20 r/min, every 10 ms mean of the true drum speed within ±5 % (the
/// seedlings' load ripple alone is ±5 % droop, mostly absorbed by the loop).
#[test]
fn fixed_mode_settles_on_a_drive_twice_as_fast_as_the_model() {
    let settings = Settings {
        mode: Mode::Fixed,
        fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
        ..Settings::default()
    };
    let nominal = Config::default();
    let fast = Config {
        motor_tau_s: nominal.motor_tau_s * 0.5,
        ..nominal
    };
    let mut rig = Rig::new(fast, settings);
    rig.sup.command(Command::Start);
    rig.run_ms(3_000);
    let (mut lowest, mut highest, mut sum) = (f64::MAX, f64::MIN, 0.0);
    for _ in 0..200 {
        let turns = rig.m.drum_turns();
        rig.period();
        let mean_rpm = (rig.m.drum_turns() - turns) * 6_000.0;
        lowest = lowest.min(mean_rpm);
        highest = highest.max(mean_rpm);
        sum += mean_rpm;
    }
    assert!(
        lowest >= 19.0 && highest <= 21.0,
        "10 ms means {lowest:.2} … {highest:.2} r/min"
    );
    assert!((sum / 200.0 - 20.0).abs() <= 0.1, "mean {}", sum / 200.0);
}

/// Control periods released late and early by a millisecond or two (a busy
/// CPU; QEMU's SysTick under a loaded host, where this was found as an
/// intermittent 2–4 % drum-speed kick in the Speed-Adaptive QEMU test): the
/// drum must not see the jitter. Each period lasts 8, 11, 9 or 12 ms in
/// turn (mean 10 ms). Expected: as on the exact schedule, the true drum
/// speed within 1 % of eq. 7 (f64) on the simulator's true ground speed;
/// dividing the encoder counts by the nominal 10 ms instead reads ±20 %
/// speed swings and fails this.
#[test]
fn a_jittered_control_schedule_does_not_disturb_the_drum() {
    // The speed loop alone (speed-following placement): distance-locked
    // placement moves the drum speed on purpose to hold the phase (by up to
    // 1.04 % here, on the Hall extrapolation's error at each edge), which
    // is not what this test is about; tests/placement.rs covers it.
    let settings = Settings {
        placement: supervisor::settings::Placement::SpeedFollowing,
        ..adaptive(70)
    };
    let mut rig = Rig::new(chassis(low2(Config::noiseless()), 2.5), settings);
    rig.run_ms(10_000);
    rig.sup.command(Command::Start);
    let start = rig.t_ms;
    let mut worst: f64 = 0.0;
    for k in 0u32.. {
        let us = [8_000, 11_000, 9_000, 12_000][(k % 4) as usize];
        rig.period_of(us);
        let t = rig.t_ms - start;
        if t >= 10_000 {
            break;
        }
        if t >= 500 {
            let target = eq7_drum_speed(f64::from(rig.m.travel_speed_m_s()), 0.07);
            let err = (f64::from(rig.m.drum_speed_rpm()) - target).abs() / target;
            worst = worst.max(err);
        }
    }
    assert!(worst <= 0.01, "worst {:.3} %", worst * 100.0);
}

#[test]
fn a_row_of_70_m_gets_its_plant_count_within_half_a_percent() {
    // Theoretical count: 70 m / 0.07 m = 1000 plants in one row. The belt runs
    // from standstill with the tractor (start before moving).
    let mut rig = Rig::new(low2(Config::default()), adaptive(70));
    rig.m.stop_travel();
    rig.run_ms(200);
    rig.sup.command(Command::Start);
    rig.m.resume_travel();
    rig.m.reset_metrics();
    let g0 = rig.m.ground_position_m();
    let p0 = rig.m.plants_dropped();
    while rig.m.ground_position_m() - g0 < 70.0 {
        rig.period();
    }
    let plants = rig.m.plants_dropped() - p0;
    let error = (f64::from(plants) - 1000.0) / 1000.0;
    assert!(
        error.abs() <= 0.005,
        "{plants} plants, {:.2} %",
        error * 100.0
    );
}

#[test]
fn a_stalled_drum_stops_the_pwm_and_latches_an_alarm() {
    let mut rig = Rig::new(low2(Config::noiseless()), adaptive(70));
    rig.run_ms(3_000);
    rig.sup.command(Command::Start);
    rig.run_ms(1_000);
    assert!(rig.act.ccr > 0);
    rig.m.inject_fault(Fault::DrumStall);
    let injected = rig.t_ms;
    while rig.act.ccr != 0 {
        rig.period();
        assert!(rig.t_ms - injected <= 300, "no reaction");
    }
    // Detection needs > 200 ms without counts (the definition); the
    // PWM drops in the period that detects it.
    let reaction = rig.t_ms - injected;
    assert!((200..=220).contains(&reaction), "{reaction} ms");
    assert_eq!(rig.sup.alarm(), Some(Alarm::DrumStall));
    assert!(!rig.act.driver_enabled);
    // Latched: clearing the jam does not restart the drum, Start is refused.
    rig.m.clear_fault(Fault::DrumStall);
    rig.run_ms(500);
    assert_eq!(rig.act, Actuation::OFF);
    rig.sup.command(Command::Start);
    assert_eq!(rig.sup.run_state(), RunState::Stopped);
    rig.sup.command(Command::AcknowledgeAlarm);
    assert_eq!(rig.sup.alarm(), None);
    rig.sup.command(Command::Start);
    rig.run_ms(500);
    assert!(rig.act.ccr > 0);
}

// A lost Hall signal: tests/hall_stop.rs (at Low 2 a silence cannot be
// told from a stop any more; the alarm needs evidence, High 3 only).

#[test]
fn a_normal_stop_of_the_tractor_stops_the_drum_without_an_alarm() {
    // The chassis coasts to a stop with a 0.5 s time constant: 72 mm from
    // Low 2, so its last tooth passes at ≈ 0.18 km/h, below the 0.25 km/h
    // from which a silent sensor counts as lost.
    let mut rig = Rig::new(chassis(low2(Config::noiseless()), 0.5), adaptive(70));
    rig.run_ms(8_000);
    rig.sup.command(Command::Start);
    rig.run_ms(1_000);
    rig.m.stop_travel();
    rig.run_ms(3_000);
    assert_eq!(rig.sup.alarm(), None, "a stop is not a fault");
    assert!(
        rig.m.drum_speed_rpm() < 0.5,
        "drum {}",
        rig.m.drum_speed_rpm()
    );
}

#[test]
fn too_fast_for_the_spacing_shows_the_allowed_maximum_and_holds_n_max() {
    // 7 cm allows ≈ 0.81 km/h (kinematics docs); High 1 runs at 1.40 km/h.
    let mut rig = Rig::new(
        Config {
            initial_gear: Some(Gear::High1),
            ..Config::noiseless()
        },
        adaptive(70),
    );
    rig.run_ms(8_000);
    rig.sup.command(Command::Start);
    rig.run_ms(2_000);
    match rig.sup.alarm() {
        Some(Alarm::TooFast { max_kmh_x100 }) => assert!((78..=84).contains(&max_kmh_x100)),
        other => panic!("{other:?}"),
    }
    let n = f64::from(rig.m.drum_speed_rpm());
    assert!((n - 44.7).abs() < 0.5, "drum {n}");
}

#[test]
fn the_k2_calibration_on_the_screen_measures_the_track_slip() {
    // Low 1, with the simulator's Table 12 slip (2.82 % at Low 1) and its
    // k1 under-reading. The operator starts the count, drives, stops it, and
    // enters the taped ground distance; k2 = taped / wheel-turn distance.
    let mut rig = Rig::new(
        Config {
            initial_gear: Some(Gear::Low1),
            ..Config::noiseless()
        },
        adaptive(70),
    );
    rig.run_ms(3_000);
    rig.sup.command(Command::CalibrationStart);
    let g0 = rig.m.ground_position_m();
    let w0 = rig.m.wheel_turns();
    rig.run_ms(120_000);
    rig.sup.command(Command::CalibrationStop);
    let ground_cm = ((rig.m.ground_position_m() - g0) * 100.0).round() as i32;
    // Expected from the simulator's truth: ground / (wheel turns · π·0.20 m).
    let expected_k2 = (rig.m.ground_position_m() - g0)
        / ((rig.m.wheel_turns() - w0) * std::f64::consts::PI * 0.20);
    let d = hmi_proto::screen::CalibrationDistance::new(ground_cm).unwrap();
    assert_eq!(
        rig.sup.command(Command::CalibrationActualDistance(d)),
        supervisor::drum::Effect::None
    );
    let status = rig.sup.screen_status();
    let k2 = f64::from(status.calibration_result_x1000) / 1000.0;
    // The firmware counts wheel turns as Hall edges / 25, and the simulated
    // Hall gear reads low by k1 (Table 11: 1.031 at Low 1), so the measured
    // k2 carries k1 too, as the paper's procedure on the same sensor does.
    // Tolerance: one Hall edge in the ≈ 425 of this 10.7 m run (0.24 %).
    let k1 = 1.031;
    assert!(
        (k2 - expected_k2 * k1).abs() <= 0.003,
        "k2 {k2} vs {:.4}",
        expected_k2 * k1
    );
    assert_eq!(
        rig.sup.command(Command::CalibrationAccept),
        supervisor::drum::Effect::SettingsChanged
    );
}

#[test]
fn saving_is_refused_while_the_drum_runs() {
    let mut rig = Rig::new(low2(Config::noiseless()), adaptive(70));
    rig.run_ms(1_000);
    rig.sup.command(Command::Start);
    assert!(matches!(
        rig.sup.command(Command::SaveSettings),
        supervisor::drum::Effect::Message(_)
    ));
    rig.sup.command(Command::Stop);
    assert_eq!(
        rig.sup.command(Command::SaveSettings),
        supervisor::drum::Effect::Save
    );
}

#[test]
fn the_too_fast_alarm_text_shows_the_allowed_maximum() {
    let mut text = heapless::String::<40>::new();
    Alarm::TooFast { max_kmh_x100: 81 }
        .write_text(&mut text)
        .unwrap();
    assert_eq!(text.as_str(), "Too fast: max 0.81 km/h");
    text.clear();
    Alarm::TooFast { max_kmh_x100: 208 }
        .write_text(&mut text)
        .unwrap();
    assert_eq!(text.as_str(), "Too fast: max 2.08 km/h");
    text.clear();
    Alarm::TooFast { max_kmh_x100: 5 }
        .write_text(&mut text)
        .unwrap();
    assert_eq!(text.as_str(), "Too fast: max 0.05 km/h");
    // Hand-written: three integer digits, a zero inside, zero itself.
    for (v, shown) in [(65_535, "655.35"), (1_000, "10.00"), (0, "0.00")] {
        text.clear();
        Alarm::TooFast { max_kmh_x100: v }
            .write_text(&mut text)
            .unwrap();
        assert_eq!(text.as_str(), format!("Too fast: max {shown} km/h"));
    }
}

#[test]
fn the_k1_calibration_makes_the_shown_travel_speed_the_taped_one() {
    // Low 1 in the simulator: the Hall gear reads low by 3.1 % and the track
    // slips 2.8 %. An uncalibrated machine (all coefficients 1) shows the
    // monitored speed: 0.33/1.031 = 0.320 km/h against a true 0.33·0.972 =
    // 0.321 km/h… so take Low 3, where they do not cancel: 0.85/0.966 = 0.880
    // shown against 0.85·0.963 = 0.819 true (+7.5 %). One k1 run over a taped
    // course corrects it.
    use hmi_proto::screen::CalibrationKind;
    let uncalibrated = Settings {
        calibration: kinematics::travel::Calibration::identity(),
        ..adaptive(70)
    };
    let mut rig = Rig::new(
        Config {
            initial_gear: Some(Gear::Low3),
            ..Config::noiseless()
        },
        uncalibrated,
    );
    rig.run_ms(30_000);
    let truth = f64::from(rig.m.travel_speed_m_s()) * 3600.0;
    let before = f64::from(rig.sup.snapshot().travel_speed_kmh_x1000);
    assert!(
        (before - truth).abs() / truth > 0.05,
        "before {before} m/h, truth {truth:.1}"
    );
    rig.sup
        .command(Command::SelectCalibration(CalibrationKind::SpeedK1));
    rig.sup.command(Command::CalibrationStart);
    let g0 = rig.m.ground_position_m();
    rig.run_ms(120_000);
    rig.sup.command(Command::CalibrationStop);
    let taped_cm = ((rig.m.ground_position_m() - g0) * 100.0).round() as i32;
    let d = hmi_proto::screen::CalibrationDistance::new(taped_cm).unwrap();
    assert_eq!(
        rig.sup.command(Command::CalibrationActualDistance(d)),
        supervisor::drum::Effect::None
    );
    let k1 = f64::from(rig.sup.screen_status().calibration_result_x1000) / 1000.0;
    // k1 = true / monitored = 0.963 · 0.966 = 0.930 (Tables 11, 12 at Low 3).
    assert!((k1 - 0.930).abs() <= 0.004, "k1 {k1}");
    assert_eq!(
        rig.sup.command(Command::CalibrationAccept),
        supervisor::drum::Effect::SettingsChanged
    );
    rig.run_ms(5_000);
    // The truth: the simulator's ground speed, km/h × 1000.
    let truth = f64::from(rig.m.travel_speed_m_s()) * 3600.0;
    let shown = f64::from(rig.sup.snapshot().travel_speed_kmh_x1000);
    assert!(
        (shown - truth).abs() / truth <= 0.003,
        "shown {shown} m/h, truth {truth:.1}"
    );
}

#[test]
fn the_k3_calibration_measures_the_belt_slip_of_table_13() {
    // Fixed mode at 20 r/min: the simulator's belt slips as Table 13 says
    // (k3 = 0.994 at 20 r/min). The operator marks the belt at Start run and
    // Stop run and tapes the length between the marks.
    use hmi_proto::screen::CalibrationKind;
    let settings = Settings {
        mode: Mode::Fixed,
        fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
        ..Settings::default()
    };
    let mut rig = Rig::new(Config::noiseless(), settings);
    rig.sup.command(Command::Start);
    rig.run_ms(2_000);
    rig.sup
        .command(Command::SelectCalibration(CalibrationKind::BeltK3));
    rig.sup.command(Command::CalibrationStart);
    let (b0, n0) = (rig.m.belt_position_m(), rig.m.drum_turns());
    rig.run_ms(60_000);
    rig.sup.command(Command::CalibrationStop);
    let belt_m = rig.m.belt_position_m() - b0;
    let turns = rig.m.drum_turns() - n0;
    let d = hmi_proto::screen::CalibrationDistance::new((belt_m * 100.0).round() as i32).unwrap();
    rig.sup.command(Command::CalibrationActualDistance(d));
    let k3 = f64::from(rig.sup.screen_status().calibration_result_x1000) / 1000.0;
    // Expected from the truth: belt length / (drum turns · π·0.070 m).
    let expected = belt_m / (turns * std::f64::consts::PI * 0.070);
    assert!((k3 - expected).abs() <= 0.002, "k3 {k3} vs {expected:.4}");
    assert!(
        (expected - 0.994).abs() <= 0.003,
        "the simulator's Table 13 value"
    );
    assert_eq!(
        rig.sup.command(Command::CalibrationAccept),
        supervisor::drum::Effect::SettingsChanged
    );
}

#[test]
fn k2_then_k1_make_the_shown_travel_speed_true_on_a_machine_that_slips_twice_the_paper() {
    // High 1 on a machine whose tracks slip twice Table 12's: the paper's
    // tables then over-read the ground speed. The operator runs k2, then
    // k1 (docs/hmi.md page 4); afterwards the shown travel speed must be
    // the simulator's true ground speed. Expected values from the
    // simulator's truth: k2 = ground / (Hall edges · π·0.20 m / 25), and k1
    // takes what k2 leaves (≈ 1 for the same steady speed).
    use hmi_proto::screen::CalibrationKind;
    let mut rig = Rig::new(
        Config {
            initial_gear: Some(Gear::High1),
            track_slip_scale: 2.0,
            ..Config::noiseless()
        },
        Settings {
            gear: Gear::High1,
            ..adaptive(200)
        },
    );
    rig.run_ms(5_000);
    let truth = f64::from(rig.m.travel_speed_m_s()) * 3600.0;
    let before = f64::from(rig.sup.snapshot().travel_speed_kmh_x1000);
    assert!(
        (before - truth) / truth > 0.03,
        "before {before} m/h, truth {truth:.1}"
    );
    let edge_m = std::f64::consts::PI * 0.20 / 25.0;
    let mut k2 = 0.0;
    for kind in [CalibrationKind::SlipK2, CalibrationKind::SpeedK1] {
        rig.sup.command(Command::SelectCalibration(kind));
        rig.sup.command(Command::CalibrationStart);
        let (g0, e0) = (rig.m.ground_position_m(), rig.m.hall_edges());
        rig.run_ms(25_000);
        rig.sup.command(Command::CalibrationStop);
        let ground = rig.m.ground_position_m() - g0;
        let edges = f64::from(rig.m.hall_edges() - e0);
        let d =
            hmi_proto::screen::CalibrationDistance::new((ground * 100.0).round() as i32).unwrap();
        rig.sup.command(Command::CalibrationActualDistance(d));
        let k = f64::from(rig.sup.screen_status().calibration_result_x1000) / 1000.0;
        let expected = match kind {
            CalibrationKind::SlipK2 => ground / (edges * edge_m),
            _ => ground / (edges * edge_m * k2),
        };
        // Whole edges at each end of the run, three decimals on the screen.
        let tolerance = expected * 2.0 / edges + 0.0015;
        assert!(
            (k - expected).abs() <= tolerance,
            "{kind:?}: {k} vs {expected:.4} ± {tolerance:.4}"
        );
        if kind == CalibrationKind::SlipK2 {
            k2 = k;
        }
        assert_eq!(
            rig.sup.command(Command::CalibrationAccept),
            supervisor::drum::Effect::SettingsChanged
        );
    }
    rig.run_ms(5_000);
    let truth = f64::from(rig.m.travel_speed_m_s()) * 3600.0;
    let shown = f64::from(rig.sup.snapshot().travel_speed_kmh_x1000);
    assert!(
        (shown - truth).abs() / truth <= 0.005,
        "shown {shown} m/h, truth {truth:.1} (before {before})"
    );
}

#[test]
fn a_drum_at_40_r_min_is_reported_as_40_and_counts_plants_with_k3_at_40() {
    // Issue 16 item 4. Failed before the fix: the target read 32.767 r/min
    // (32 767 in the log, 32.76 on the screen) and the plant count used k3
    // interpolated at 32.767 r/min (0.98 + 7.767 · 0.12/15 = 1.042) instead
    // of the hand-set 1.100 at 40 r/min: 5 % too few plants.
    use hmi_proto::screen::{CalibrationCoefficient, CalibrationKind};
    let settings = Settings {
        mode: Mode::Fixed,
        fixed_drum_speed: DrumSpeed::new(4000).unwrap(),
        ..Settings::default()
    };
    let mut rig = Rig::new(Config::noiseless(), settings);
    // k3 = 1.100 by hand at the Fixed-mode drum speed (40 r/min), page 4.
    rig.sup
        .command(Command::SelectCalibration(CalibrationKind::BeltK3));
    rig.sup.command(Command::SetCalibrationCoefficient(
        CalibrationCoefficient::new(1100).unwrap(),
    ));
    // The k3 table as an f64 reference: Table 13 (kinematics PAPER_K3) and
    // the point set above, linear between points, constant beyond the ends.
    let points = [
        (5.0, 0.993),
        (10.0, 0.982),
        (15.0, 0.986),
        (20.0, 0.994),
        (25.0, 0.980),
        (40.0, 1.100),
    ];
    let k3 = |n: f64| -> f64 {
        if n <= points[0].0 {
            return points[0].1;
        }
        for w in points.windows(2) {
            let ((x0, y0), (x1, y1)) = (w[0], w[1]);
            if n <= x1 {
                return y0 + (y1 - y0) * (n - x0) / (x1 - x0);
            }
        }
        points[points.len() - 1].1
    };
    rig.sup.command(Command::Start);
    // Plants as the firmware's formula gives them on the simulator's true
    // drum speed: Σ Δturns · k3(n) · π·0.070 m / 0.05 m.
    let mut expected = 0.0;
    let mut turns = rig.m.drum_turns();
    for _ in 0..2_000 {
        rig.period();
        let now = rig.m.drum_turns();
        expected += (now - turns) * k3(f64::from(rig.m.drum_speed_rpm()));
        turns = now;
    }
    expected *= std::f64::consts::PI * 0.070 / 0.05;
    let snap = rig.sup.snapshot();
    assert_eq!(snap.target_drum_rpm_x1000, 40_000);
    assert_eq!(rig.sup.screen_status().target_drum_rpm_x100, 4000);
    // Actual: the smoothed measurement against the simulator's drum.
    let truth = f64::from(rig.m.drum_speed_rpm());
    let actual = f64::from(snap.actual_drum_rpm_x1000) / 1000.0;
    assert!(
        (actual - truth).abs() <= 0.005 * truth,
        "{actual} vs {truth}"
    );
    assert!(actual > 39.5, "{actual}");
    // 20 s at 40 r/min: 13.3 turns · 4.398 · 1.1 ≈ 64.5 plants; the count
    // is floored, and the measured speed smooths over 0.5 s: within 1.
    let plants = f64::from(snap.plants);
    assert!(
        (plants - expected).abs() <= 1.0,
        "{plants} plants vs {expected:.2}"
    );
}

#[test]
fn a_drum_encoder_wired_backwards_runs_once_reversed_on_the_screen() {
    // Issue 15 item 5. A/B swapped: TIM3 counts down while the drum turns
    // forward (the simulator's counter, negated).
    let settings = Settings {
        mode: Mode::Fixed,
        fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
        ..Settings::default()
    };
    let run = |reversed: bool| {
        let mut rig = Rig::new(Config::noiseless(), settings.clone());
        if reversed {
            // Page 6 `benc`.
            rig.sup.command(Command::SetDrumEncoderReversed(true));
        }
        rig.sup.command(Command::Start);
        let mut stalled_at = None;
        for step in 1..=400u32 {
            let inputs = Inputs {
                drum_duty: f32::from(rig.act.ccr) / f32::from(HW.pwm_arr + 1),
                driver_enabled: rig.act.driver_enabled,
                ..Inputs::default()
            };
            let sup = &mut rig.sup;
            rig.m
                .step(10_000, &inputs, &mut |t| sup.hall_edge(Ticks(t)));
            let swapped = 0u16.wrapping_sub(rig.m.drum_encoder_count());
            rig.act = rig.sup.control_step(Ticks(rig.m.capture_ticks()), swapped);
            if stalled_at.is_none() && rig.sup.alarm().is_some() {
                stalled_at = Some(step * 10);
            }
        }
        (
            stalled_at,
            rig.m.drum_speed_rpm(),
            rig.sup.snapshot(),
            rig.sup.alarm(),
        )
    };
    // Before (the setting off, as every machine was before it existed): the
    // drum turns, the supervisor reads no forward motion and stops it after
    // the documented 200 ms (the first period past it: 210 ms), with the
    // alarm that names the cause (since 2026-11-24; "Drum stalled or
    // encoder lost" before, which sent technicians looking for a jam).
    let (stalled_at, _, _, alarm) = run(false);
    assert_eq!(stalled_at, Some(210));
    assert_eq!(alarm, Some(Alarm::DrumBackwards));
    // Reversed on the screen: the drum runs and holds 20 r/min (±0.5 %,
    // the simulator's true speed) and the screen shows it after 4 s (the
    // shown speed is smoothed with τ = 0.5 s: e^-8 of the step is left).
    let (stalled_at, drum, snap, _) = run(true);
    assert_eq!(stalled_at, None);
    assert!((f64::from(drum) - 20.0).abs() <= 0.1, "{drum} r/min");
    assert!(
        (f64::from(snap.actual_drum_rpm_x1000) - 20_000.0).abs() <= 100.0,
        "{} shown",
        snap.actual_drum_rpm_x1000
    );
}

/// Start while the tractor is still pulling away: a noiseless machine at
/// Low 2 whose chassis reaches its speed through a 2.5 s lag from
/// power-up, Start 2 s after power-up (the teeth not learnt yet, the speed
/// still rising by 5–10 %/s). Expected: from 2 s after Start for 4 s the
/// true drum speed within 1 % of eq. 7 (f64) on the true ground speed, as
/// when Start comes after the pull-away
/// (`speed_adaptive_7cm_low2_settles_within_half_a_second_...`).
#[test]
fn a_start_while_the_tractor_pulls_away_tracks_within_1_percent() {
    let mut rig = Rig::new(chassis(low2(Config::noiseless()), 2.5), adaptive(70));
    rig.run_ms(2_000);
    rig.sup.command(Command::Start);
    let start = rig.t_ms;
    let (mut worst, mut at): (f64, u32) = (0.0, 0);
    while rig.t_ms - start < 6_000 {
        rig.period();
        let t = rig.t_ms - start;
        let target = eq7_drum_speed(f64::from(rig.m.travel_speed_m_s()), 0.07);
        let err = (f64::from(rig.m.drum_speed_rpm()) - target).abs() / target;
        if t >= 2_000 && err > worst {
            (worst, at) = (err, t);
        }
    }
    println!("worst {:.2} % at {at} ms", worst * 100.0);
    assert!(worst <= 0.01, "worst {:.2} % at {at} ms", worst * 100.0);
}
