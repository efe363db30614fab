//! Distance-locked placement (issue 19) against the machine simulator: the
//! first plant at its place and no drift after a speed step, and the
//! speed-following mode failing the same assertions. The places come from
//! the simulator's own truth (its ground position at each Hall edge and at
//! each drop), never from the code under test; the measured-ground figures
//! use the supervisor's reported events only to pair them with the plan
//! `place_n = first + (n − 1)·X`, whose numbers are written here.
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
use machine_sim::{Config, Event, Inputs};
use supervisor::drum::{Actuation, Hardware, Supervisor};
use supervisor::settings::{Placement, Settings};

const HW: Hardware = Hardware::BOARD;
/// One Hall pitch at k1 = k2 = 1, m: π·0.20 / 25.
const EDGE_M: f64 = std::f64::consts::PI * 0.20 / 25.0;

struct Run {
    /// True ground of each drop, m from the ground at the first Hall edge
    /// after Start.
    drops: Vec<f64>,
    /// (time s, measured ground µm) of each partition event.
    events: Vec<(f64, u64)>,
}

/// A row at Low 2 from rest: the drum is started with the tractor; at
/// `step_s` the travel speed steps by `step` (chassis τ 0.5 s).
fn run(placement: Placement, spacing_mm: u16, step_s: f64, step: f32, secs: f64) -> Run {
    let cfg = Config {
        seed: 7,
        initial_gear: Some(Gear::Low2),
        plant_scatter_m: 0.0,
        track_tau_s: 0.5,
        target_spacing_m: f32::from(spacing_mm) / 1000.0,
        ..Config::default()
    };
    let mut m = cfg.build().unwrap();
    let settings = Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(i32::from(spacing_mm)).unwrap(),
        gear: Gear::Low2,
        placement,
        ..Settings::default()
    };
    let mut sup = Supervisor::new(HW, settings).unwrap();
    let mut act = Actuation::OFF;
    m.stop_travel();
    let mut origin = None;
    let mut drops = Vec::new();
    let mut events = Vec::new();
    let mut t = 0.0;
    let mut started = false;
    let mut stepped = false;
    for k in 0..((secs + 0.2) * 100.0) as u32 {
        if k == 20 {
            sup.command(Command::Start);
            m.resume_travel();
            started = true;
        }
        if started && !stepped && t >= step_s + 0.2 {
            m.inject_speed_step(step);
            stepped = true;
        }
        let inputs = Inputs {
            drum_duty: f32::from(act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: act.driver_enabled,
            ..Inputs::default()
        };
        let g0 = m.ground_position_m();
        let t0 = m.capture_ticks();
        let mut first_edge = None;
        m.step_events(10_000, &inputs, &mut |e| match e {
            Event::HallEdge(ticks) => {
                if first_edge.is_none() {
                    first_edge = Some(ticks);
                }
                sup.hall_edge(Ticks(ticks));
            }
            Event::Plant { ground_m, .. } => drops.push(ground_m),
        });
        let g1 = m.ground_position_m();
        if started && origin.is_none() {
            if let Some(ticks) = first_edge {
                // The ground at the edge, interpolated within the period.
                let f = f64::from(ticks.wrapping_sub(t0)) / 10_000.0;
                origin = Some(g0 + f * (g1 - g0));
            }
        }
        act = sup.control_step(Ticks(m.capture_ticks()), m.drum_encoder_count());
        t += 0.01;
        events.extend(sup.plants_left().map(|e| (t, e.ground_distance_um)));
    }
    let o = origin.unwrap();
    Run {
        drops: drops.iter().map(|d| d - o).collect(),
        events,
    }
}

fn report(r: &Run, x: f64) -> (f64, f64, f64) {
    // The documented first place: X + one Hall pitch after the first edge
    // (docs/placement.md); the true pitch differs from the nominal by
    // k1·k2 ≈ 1 % (0.25 mm).
    let first = x + EDGE_M;
    let first_err = (r.drops[0] - first) * 1000.0;
    let worst_true = r
        .drops
        .iter()
        .enumerate()
        .map(|(n, d)| ((d - first - n as f64 * x) * 1000.0).abs())
        .fold(0.0, f64::max);
    let worst_measured = r
        .events
        .iter()
        .enumerate()
        .map(|(n, (_, g))| (*g as f64 / 1e3 - (first + n as f64 * x) * 1000.0).abs())
        .fold(0.0, f64::max);
    (first_err, worst_true, worst_measured)
}

/// Issue 19's targets: the first plant within ±3 mm of its place, every
/// plant's phase against the measured ground within 5 mm, through a +20 %
/// speed step at 10 s (chassis τ 0.5 s), 7 cm at Low 2 from rest, landing
/// scatter off. Speed-following fails the same assertion (its start lag and
/// the step's lag stay in the row): the test can fail.
#[test]
fn distance_locked_first_plant_at_its_place_and_no_drift_after_a_speed_step() {
    let mut fails = Vec::new();
    for placement in [Placement::DistanceLocked, Placement::SpeedFollowing] {
        let r = run(placement, 70, 10.0, 0.2, 20.0);
        let (first, worst_true, worst_measured) = report(&r, 0.07);
        println!(
            "{placement:?}: first {first:+.2} mm, worst true {worst_true:.2} mm, \
             worst measured {worst_measured:.2} mm, {} plants",
            r.drops.len()
        );
        // 20 s at 0.5 km/h, then +20 %: about 2.9 m, 40 plants at 7 cm.
        assert!(
            r.drops.len() > 35,
            "{placement:?}: {} plants",
            r.drops.len()
        );
        let ok = first.abs() <= 3.0 && worst_measured <= 5.0 && worst_true <= 5.0;
        if placement == Placement::DistanceLocked {
            assert!(ok, "{placement:?}");
        } else {
            fails.push(!ok);
        }
    }
    assert_eq!(fails, [true], "speed-following should miss the targets");
}

/// The ground distance through stops: the tractor of the stop-and-go
/// profile (rest for 2 s every 10 s, chassis τ 0.5 s) pulls away from a
/// crawl with a gap shorter than ¼ of the last one, which the speed
/// estimator drops as a glitch; the distance must still count that tooth.
/// Without `DISTANCE_EDGE_MIN_GAP_US` it lost up to one tooth (25 mm) per
/// stop: measured 6982 mm against 7068 mm true after 60 s at Low 2 (this
/// test failed by 86 mm), and still 7007 mm (61 mm short) with the
/// estimator's glitch reference bounded (kinematics, commit aa1e4a8). Expected: the simulator's true
/// ground since the first Hall edge, within 30 mm (the k1·k2 tables against
/// the model's slip: −0.13 % in bench §8, 9 mm of 7 m; plus one tooth's
/// extrapolation at most at a stop).
#[test]
fn the_ground_distance_keeps_every_tooth_through_stops() {
    let cfg = Config {
        seed: 8000,
        initial_gear: Some(Gear::Low2),
        plant_scatter_m: 0.0,
        ..Config::default()
    }
    .stop_and_go();
    let mut m = cfg.build().unwrap();
    let settings = Settings {
        gear: Gear::Low2,
        ..Settings::default()
    };
    let mut sup = Supervisor::new(HW, settings).unwrap();
    let mut act = Actuation::OFF;
    sup.command(Command::Start);
    let mut origin = None;
    // 60.5 s: stops at 10, 22, 34, 46 and 58 s, 2 s each; moving again.
    for _ in 0..6050 {
        let inputs = Inputs {
            drum_duty: f32::from(act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: act.driver_enabled,
            ..Inputs::default()
        };
        let (g0, t0) = (m.ground_position_m(), m.capture_ticks());
        let mut first = None;
        m.step_events(10_000, &inputs, &mut |e| {
            if let Event::HallEdge(t) = e {
                first.get_or_insert(t);
                sup.hall_edge(Ticks(t));
            }
        });
        if origin.is_none() {
            if let Some(t) = first {
                let f = f64::from(t.wrapping_sub(t0)) / 10_000.0;
                origin = Some(g0 + f * (m.ground_position_m() - g0));
            }
        }
        act = sup.control_step(Ticks(m.capture_ticks()), m.drum_encoder_count());
    }
    let truth = (m.ground_position_m() - origin.unwrap()) * 1000.0;
    let measured = sup.ground_distance_um() as f64 / 1000.0;
    println!("true {truth:.1} mm, measured {measured:.1} mm");
    assert!(truth > 6000.0, "{truth}");
    assert!((measured - truth).abs() <= 30.0, "{measured} vs {truth}");
}

/// Between two Hall edges the measured ground moves on at the speed of the
/// last tooth gap (the M/T estimate), not at the predictor's speed carried
/// along its slope: with the gear's ±2 % tooth errors that slope is mostly
/// noise (bench §9: hills p95 spacing at 7 cm 2.96 → 2.72 %). Identity
/// calibration (k1 = k2 = 1): one edge is π·0.20 m / 25 = 25 132.741 µm.
/// Edges at 0 (the origin), 200, 380 and 540 ms: the last gap is 160 ms, so
/// 80 ms later the ground is 3 edges + 25.132 741 mm · 80/160 = 75 398.2 +
/// 12 566.4 = 87 964.6 µm (the travel speed passes through an integer m/h:
/// 565.5 → 565 or 566 m/h, ±11 µm over 80 ms). The predictor's slope
/// (139.6 → 157.1 mm/s over 170 ms, carried 160 ms, capped at +10 %) would
/// put it at 13.8 mm past the edge: 1.3 mm further.
#[test]
fn between_edges_the_ground_moves_at_the_last_gaps_speed() {
    let settings = Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(70).unwrap(),
        gear: Gear::Low2,
        placement: Placement::DistanceLocked,
        calibration: kinematics::travel::Calibration::identity(),
        ..Settings::default()
    };
    let mut sup = Supervisor::new(HW, settings).unwrap();
    sup.command(Command::Start);
    let mut encoder = 0u16;
    for t_ms in 0..=620u32 {
        if t_ms % 10 != 0 {
            continue;
        }
        if [0, 200, 380, 540].contains(&t_ms) {
            sup.hall_edge(Ticks(t_ms * 1000));
        }
        // The drum turns (no stall alarm); the belt does not matter here.
        encoder = encoder.wrapping_add(50);
        sup.control_step(Ticks(t_ms * 1000), encoder);
    }
    let g = sup.ground_distance_um() as f64;
    assert!((g - 87_964.6).abs() <= 12.0, "{g}");
}
