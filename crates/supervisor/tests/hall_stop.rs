//! A stop of the tractor against a lost Hall signal (issue 16, item 5), on
//! the machine simulator with the same 10 ms loop the firmware runs.
//!
//! The rule under test (docs/firmware.md, "Faults"; docs/kinematics.md,
//! "Hall silence"): a silent Hall sensor is a lost signal only when no
//! deceleration the chassis can make (1 g of track speed, 10.5 m/s² at the
//! gear) explains the silence; otherwise the drum follows the travel speed
//! down to zero without an alarm and starts again with the edges. Expected
//! values come from an f64 form of that physics written here, from the
//! simulator's truth, and from the row length over the spacing — never from
//! the code under test.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::indexing_slicing
)]

use hmi_proto::screen::{Command, Mode, Spacing};
use kinematics::consts::Gear;
use kinematics::units::Ticks;
use machine_sim::reference::eq7_drum_speed;
use machine_sim::{Config, Fault, Inputs, Machine};
use supervisor::drum::{Actuation, Alarm, Hardware, Supervisor};
use supervisor::settings::Settings;

const HW: Hardware = Hardware::BOARD;

/// The chassis limit: 1 g of track deceleration (friction, μ = 1).
const CHASSIS_LIMIT_MM_S2: u16 = 9_810;

struct Rig {
    sup: Supervisor,
    m: Machine,
    act: Actuation,
    t_ms: u32,
    /// Capture times of the last two Hall edges.
    last_edges: [Option<u32>; 2],
    /// Latched alarms seen (each acknowledged and the drum restarted).
    latched: u32,
}

impl Rig {
    fn new(config: Config, gear: Gear, spacing_mm: u16) -> Self {
        let settings = Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(i32::from(spacing_mm)).unwrap(),
            gear,
            ..Settings::default()
        };
        Self {
            sup: Supervisor::new(HW, settings).unwrap(),
            m: Config {
                initial_gear: Some(gear),
                ..config
            }
            .build()
            .unwrap(),
            act: Actuation::OFF,
            t_ms: 0,
            last_edges: [None; 2],
            latched: 0,
        }
    }

    /// One control period: the machine runs 10 ms under the last output,
    /// then the supervisor reads it, as the firmware's control task does.
    fn period(&mut self) {
        let inputs = Inputs {
            drum_duty: f32::from(self.act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: self.act.driver_enabled,
            ..Inputs::default()
        };
        let sup = &mut self.sup;
        let edges = &mut self.last_edges;
        self.m.step(10_000, &inputs, &mut |t| {
            sup.hall_edge(Ticks(t));
            *edges = [edges[1], Some(t)];
        });
        self.act = self
            .sup
            .control_step(Ticks(self.m.capture_ticks()), self.m.drum_encoder_count());
        self.t_ms += 10;
    }

    /// A period that counts a latched alarm, acknowledges it and restarts
    /// the drum, as an operator would, so that every false alarm of a run
    /// is counted rather than only the first.
    fn period_counting_alarms(&mut self) {
        self.period();
        if self.sup.alarm().is_some_and(|a| a.is_latched()) {
            self.latched += 1;
            self.sup.command(Command::AcknowledgeAlarm);
            self.sup.command(Command::Start);
        }
    }
}

/// The stop-and-go profile of the issue: the chassis answers its command
/// with a 0.5 s time constant, travels 5 s at gear speed, is driven to rest
/// for 5 s, and so on (a stop every 10 s), on the default terrain.
fn stop_and_go(seed: u64) -> Config {
    Config {
        seed,
        track_tau_s: 0.5,
        terrain_stop_interval_s: 5.0,
        terrain_stop_duration_s: 5.0,
        terrain_stops_regular: true,
        ..Config::default()
    }
}

/// Before the fix every one of these rows latched "Hall speed signal lost"
/// at its first stop (0.6–1.2 s after it; left latched, the drum stayed
/// off for the rest of the row: 3–51 plants). Expected: no latched alarm in
/// the whole row. The plants must stay within 3 % of 70 m / spacing: each
/// stop lets the drum run on behind the chassis while the travel speed
/// decays (one gap over the time since the last edge, for the 1.5 s zero
/// speed timeout: at most one gap·(1 + ln(1.5 s/T)) of belt, ≈ 0.8 plant
/// at 7 cm), and each restart costs the two edges the estimator needs for
/// a speed; measured +1.8 … +2.3 % with the alarm acknowledged at once
/// before the fix and the same after it (docs/firmware.md).
#[test]
fn stop_and_go_rows_of_70_m_at_low_1_and_low_2_latch_no_alarm() {
    let mut failures = Vec::new();
    for gear in [Gear::Low1, Gear::Low2] {
        for spacing_mm in [70u16, 180] {
            let mut rig = Rig::new(stop_and_go(1), gear, spacing_mm);
            rig.sup.command(Command::Start);
            let g0 = rig.m.ground_position_m();
            let p0 = rig.m.plants_dropped();
            while rig.m.ground_position_m() - g0 < 70.0 {
                rig.period_counting_alarms();
            }
            let plants = f64::from(rig.m.plants_dropped() - p0);
            let expected = 70_000.0 / f64::from(spacing_mm);
            let error = (plants - expected) / expected;
            println!(
                "{gear} {spacing_mm} mm: {} latched alarms, {plants} plants of {expected:.0} ({:+.2} %), {} s",
                rig.latched,
                error * 100.0,
                rig.t_ms / 1000
            );
            if rig.latched != 0 || error.abs() > 0.03 {
                failures.push(format!("{gear} at {spacing_mm} mm"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

/// Every gear, 7 and 18 cm: stops at the chassis's physical limit (a
/// constant 1 g until rest, no lag) and the 0.5 s stop-and-go profile, six
/// stops each, on the default terrain. At 7 cm Low 3 and above, and at
/// 18 cm High 2 and High 3, are too fast for the spacing (a warning, not
/// latched). Expected: no latched alarm at all.
#[test]
fn stops_up_to_the_chassis_deceleration_limit_latch_no_alarm_at_any_gear() {
    let mut report = Vec::new();
    let mut total = 0;
    for gear in Gear::ALL {
        for spacing_mm in [70u16, 180] {
            for (name, chassis) in [
                (
                    "1 g",
                    Config {
                        track_tau_s: 0.0,
                        track_decel_limit_mm_s2: CHASSIS_LIMIT_MM_S2,
                        ..stop_and_go(u64::from(spacing_mm))
                    },
                ),
                ("tau 0.5 s", stop_and_go(7)),
            ] {
                let mut rig = Rig::new(chassis, gear, spacing_mm);
                rig.sup.command(Command::Start);
                while rig.t_ms < 60_000 {
                    rig.period_counting_alarms();
                }
                report.push(format!("{gear} {spacing_mm} mm {name}: {}", rig.latched));
                total += rig.latched;
            }
        }
    }
    println!("latched alarms per run: {report:?}");
    assert_eq!(total, 0, "{report:?}");
}

/// The latest time after the newest edge at which the next edge can come
/// when the last gap (`s_last` m) took `gap_s` and the gear's track speed
/// falls by at most `a` m/s², the next gap being `s_next` m: the machine was
/// at least at `v_e = s_last/gap − a·gap/2` at the edge and covers
/// `v_e·t − a·t²/2`; `None` when it can stop before the next tooth.
fn latest_edge_f64(gap_s: f64, a: f64, s_last: f64, s_next: f64) -> Option<f64> {
    let v_e = s_last / gap_s - a * gap_s / 2.0;
    let disc = v_e * v_e - 2.0 * a * s_next;
    (v_e > 0.0 && disc >= 0.0).then(|| (v_e - disc.sqrt()) / a)
}

/// One nominal gap of the Hall gear, m of track: π·0.20 m / 25.
const GAP_M: f64 = std::f64::consts::PI * 0.20 / 25.0;

/// High 3 (3.65 km/h) is the one gear fast enough for evidence: a Hall
/// signal lost there is latched within the documented time, and never
/// before the next edge could still come from a chassis braking at 1 g.
/// Ten losses at different phases of the default terrain, on a gear
/// without tooth errors so that the gap lengths are known here (the false
/// alarm tests above run with them). Before the fix the rule waited two
/// periods, at least 100 ms.
#[test]
fn a_hall_signal_lost_at_high_3_latches_the_alarm_within_the_documented_time() {
    let mut worst: f64 = 0.0;
    for k in 0..10u32 {
        let mut rig = Rig::new(
            Config {
                seed: u64::from(k),
                hall_pitch_error: 0.0,
                ..Config::default()
            },
            Gear::High3,
            180,
        );
        rig.sup.command(Command::Start);
        while rig.t_ms < 3_000 + k * 317 {
            rig.period();
        }
        rig.m.inject_fault(Fault::HallLoss);
        let [Some(before), Some(last)] = rig.last_edges else {
            panic!("no edges at High 3");
        };
        let gap = f64::from(last - before) * 1e-6;
        // No false alarm: the latest a 1 g stop of the track (1 g / k1′ at
        // the gear, k1′ = 0.997 at High 3, Table 11) lets the next edge come.
        let physical = latest_edge_f64(gap, 9.81 / 0.997, GAP_M, GAP_M).unwrap();
        // Detection: the rule (10.5 m/s², gaps ±5 %), plus one control
        // period, plus the capture jitter of both edges (±10 µs each).
        let documented =
            latest_edge_f64(gap, 10.5, GAP_M * 0.95, GAP_M * 1.05).unwrap() + 0.010 + 20e-6;
        while rig.sup.alarm() != Some(Alarm::HallLost) {
            rig.period();
            assert!(rig.t_ms < 5_000 + k * 317, "no alarm");
        }
        assert_eq!(rig.act, Actuation::OFF);
        let after_edge = f64::from(rig.m.capture_ticks() - last) * 1e-6;
        assert!(
            after_edge > physical && after_edge <= documented,
            "loss {k}: alarm {:.1} ms after the last edge, physical limit {:.1} ms, documented {:.1} ms",
            after_edge * 1e3,
            physical * 1e3,
            documented * 1e3
        );
        worst = worst.max(after_edge);
    }
    println!("worst detection: {:.1} ms after the last edge", worst * 1e3);
    // The documented figure (docs/firmware.md): ≤ 60 ms at High 3.
    assert!(worst <= 0.060, "{:.1} ms", worst * 1e3);
}

/// Low 2 (0.51 km/h): the chassis can stop within one gap (v²/2a = 1 mm at
/// 1 g), so a silent sensor cannot be told from a stop. Expected: no alarm;
/// the drum follows the travel speed down to rest (the estimator declares
/// standstill 1.5 s after the last edge); when the edges come back it runs
/// again at eq. 7's speed for the true ground speed within 2 %.
#[test]
fn below_the_evidence_speed_a_lost_signal_stops_the_drum_without_an_alarm_and_it_resumes() {
    let mut rig = Rig::new(Config::noiseless(), Gear::Low2, 70);
    rig.sup.command(Command::Start);
    while rig.t_ms < 3_000 {
        rig.period();
    }
    rig.m.inject_fault(Fault::HallLoss);
    let lost_at = rig.t_ms;
    while rig.t_ms < lost_at + 1_800 {
        rig.period();
        assert_eq!(rig.sup.alarm(), None);
    }
    // At rest, as after any stop (what is left of the PID's integral is
    // below the driver's start duty).
    assert!(
        rig.m.drum_speed_rpm() < 0.1,
        "drum {}",
        rig.m.drum_speed_rpm()
    );
    assert_eq!(rig.sup.snapshot().target_drum_rpm_x1000, 0);
    rig.m.clear_fault(Fault::HallLoss);
    let back = rig.t_ms;
    while rig.t_ms < back + 2_000 {
        rig.period();
    }
    let target = eq7_drum_speed(f64::from(rig.m.travel_speed_m_s()), 0.07);
    let n = f64::from(rig.m.drum_speed_rpm());
    assert!((n - target).abs() / target <= 0.02, "drum {n} vs {target}");
    assert_eq!(rig.sup.alarm(), None);
}
