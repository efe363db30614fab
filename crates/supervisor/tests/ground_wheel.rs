//! Machine A's ground wheel on the machine simulator, driven as the
//! firmware's 10 ms task drives the supervisor: a wheel that stops while the
//! Hall gear turns and the reverse (said within 0.5 s, planting goes on), a
//! wheel that counts backwards, and the calibration's refusals (nothing
//! saved). Expected values come from the simulator (its plant drops, the
//! time of the fault) and the documented limits, never from the code under
//! test.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]

use hmi_proto::screen::TravelSourceInUse;
use hmi_proto::screen::{
    CalibrationCoefficient, CalibrationDistance, CalibrationKind, Command, Mode, Spacing,
    TravelSource,
};
use kinematics::consts::Gear;
use kinematics::units::Ticks;
use machine_sim::{Config, Event, Fault, Inputs, Machine};
use supervisor::drum::{Actuation, Alarm, Effect, Hardware, RunState, Supervisor};
use supervisor::settings::wheel::{GroundWheelSettings, NOMINAL_COUNTS_PER_M_X1000};
use supervisor::settings::Settings;

const HW: Hardware = Hardware::BOARD;

struct Rig {
    sup: Supervisor,
    m: Machine,
    act: Actuation,
    t_ms: u32,
    /// Plant drops, true ground m.
    drops: Vec<f64>,
}

/// The model's wheel, calibrated: counts per metre × 1000 of its nominal
/// 250 mm and 2400 counts a turn.
fn model_counts_per_m_x1000(cfg: &Config) -> u32 {
    (f64::from(cfg.ground_encoder_counts_per_turn)
        / (std::f64::consts::PI * f64::from(cfg.ground_wheel_diameter_m))
        * 1000.0)
        .round() as u32
}

impl Rig {
    fn new(source: TravelSource, gear: Gear, spacing_mm: u16, cfg: Config) -> Self {
        let settings = Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(i32::from(spacing_mm)).unwrap(),
            gear,
            ground_wheel: GroundWheelSettings {
                source,
                counts_per_m_x1000: model_counts_per_m_x1000(&cfg),
                reversed: false,
            },
            ..Settings::default()
        };
        Self {
            sup: Supervisor::new(HW, settings).unwrap(),
            m: Config {
                initial_gear: Some(gear),
                ..cfg
            }
            .build()
            .unwrap(),
            act: Actuation::OFF,
            t_ms: 0,
            drops: Vec::new(),
        }
    }

    fn period(&mut self) {
        let inputs = Inputs {
            drum_duty: f32::from(self.act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: self.act.driver_enabled,
            ..Inputs::default()
        };
        let (sup, drops) = (&mut self.sup, &mut self.drops);
        self.m.step_events(10_000, &inputs, &mut |e| match e {
            Event::HallEdge(t) => sup.hall_edge(Ticks(t)),
            Event::Plant { ground_m, .. } => drops.push(ground_m),
        });
        self.sup.ground_wheel_count(self.m.ground_encoder_count());
        self.act = self
            .sup
            .control_step(Ticks(self.m.capture_ticks()), self.m.drum_encoder_count());
        self.t_ms += 10;
    }

    /// Runs until the true ground reaches `m` metres.
    fn run_to(&mut self, m: f64) {
        while self.m.ground_position_m() < m {
            self.period();
        }
    }

    /// Periods until `f` holds, at most `limit_ms`; the time it took, ms.
    fn until(&mut self, limit_ms: u32, f: impl Fn(&Self) -> bool) -> Option<u32> {
        let start = self.t_ms;
        while self.t_ms - start <= limit_ms {
            self.period();
            if f(self) {
                return Some(self.t_ms - start);
            }
        }
        None
    }

    fn plants_between(&self, a: f64, b: f64) -> usize {
        self.drops.iter().filter(|&&g| g >= a && g < b).count()
    }
}

/// A wheel that stops rolling (lifted, blocked, its encoder dead) while the
/// Hall gear turns: said within 0.5 s at Low 1 and Low 2, 7 and 18 cm; the
/// machine plants on on the Hall gear (the plants of the next 10 m within
/// two of 10 m / X), the drum is never stopped; once the wheel rolls again
/// the warning clears and the wheel is back in use.
#[test]
fn a_wheel_that_stops_while_the_hall_gear_turns_is_said_within_half_a_second() {
    for (gear, x_mm, seed) in [
        (Gear::Low1, 70u16, 31),
        (Gear::Low2, 70, 32),
        (Gear::Low1, 180, 33),
        (Gear::Low2, 180, 34),
    ] {
        let cfg = Config {
            seed,
            ..Config::default()
        };
        let mut r = Rig::new(TravelSource::Both, gear, x_mm, cfg);
        r.sup.command(Command::Start);
        r.run_to(30.0);
        assert_eq!(
            r.sup.snapshot().travel_source,
            TravelSourceInUse::GroundWheel
        );
        r.m.inject_fault(Fault::GroundEncoderLoss);
        let said = r
            .until(2000, |r| r.sup.alarm() == Some(Alarm::GroundWheelStopped))
            .unwrap_or_else(|| panic!("{gear:?} {x_mm}: not said, {:?}", r.sup.alarm()));
        assert!(said <= 500, "{gear:?} {x_mm}: said after {said} ms");
        eprintln!("wheel stop {gear:?} {x_mm}: said after {said} ms");
        assert_eq!(
            r.sup.snapshot().travel_source,
            TravelSourceInUse::HallStandIn
        );
        let from = r.m.ground_position_m();
        r.run_to(from + 10.0);
        let planted = r.plants_between(from, from + 10.0) as f64;
        let due = 10.0 / (f64::from(x_mm) / 1000.0);
        assert!(
            (planted - due).abs() <= 2.0,
            "{gear:?} {x_mm}: {planted} plants in 10 m on the Hall gear, {due} due"
        );
        assert_eq!(r.sup.run_state(), RunState::Running);
        r.m.clear_fault(Fault::GroundEncoderLoss);
        let back = r.until(2000, |r| r.sup.alarm().is_none());
        assert!(back.is_some(), "{gear:?} {x_mm}: the warning stays");
        assert_eq!(
            r.sup.snapshot().travel_source,
            TravelSourceInUse::GroundWheel
        );
    }
}

/// A Hall gear that stops while the wheel rolls: said within 0.5 s; the
/// wheel carries on (the plants of the next 10 m within one of 10 m / X);
/// the slip is no longer shown.
#[test]
fn a_hall_gear_that_stops_while_the_wheel_rolls_is_said_within_half_a_second() {
    for (gear, x_mm, seed) in [(Gear::Low1, 70u16, 41), (Gear::Low2, 180, 42)] {
        let cfg = Config {
            seed,
            ..Config::default()
        };
        let mut r = Rig::new(TravelSource::Both, gear, x_mm, cfg);
        r.sup.command(Command::Start);
        r.run_to(30.0);
        assert!(r.sup.snapshot().track_slip_x10.is_some(), "{gear:?}: slip");
        r.m.inject_fault(Fault::HallLoss);
        let said = r
            .until(2000, |r| r.sup.alarm() == Some(Alarm::HallGearStopped))
            .unwrap_or_else(|| panic!("{gear:?}: not said, {:?}", r.sup.alarm()));
        assert!(said <= 500, "{gear:?}: said after {said} ms");
        eprintln!("hall stop {gear:?} {x_mm}: said after {said} ms");
        let from = r.m.ground_position_m();
        r.run_to(from + 10.0);
        let planted = r.plants_between(from, from + 10.0) as f64;
        let due = 10.0 / (f64::from(x_mm) / 1000.0);
        assert!((planted - due).abs() <= 1.0, "{gear:?}: {planted} of {due}");
        assert_eq!(r.sup.snapshot().track_slip_x10, None);
        assert_eq!(r.sup.run_state(), RunState::Running);
    }
}

/// The wheel's encoder wired backwards: alone, a latched alarm that stops
/// the drum (it has no other ground); with the Hall gear, a warning and the
/// Hall gear stands in.
#[test]
fn a_wheel_counting_backwards_stops_it_alone_and_is_stood_in_for_with_both() {
    let cfg = Config {
        seed: 51,
        ground_wheel_reversed: true,
        ..Config::default()
    };
    let mut alone = Rig::new(TravelSource::GroundWheel, Gear::Low2, 70, cfg);
    alone.sup.command(Command::Start);
    let said = alone.until(3000, |r| {
        r.sup.alarm() == Some(Alarm::GroundWheelBackwards { alone: true })
    });
    assert!(said.is_some(), "{:?}", alone.sup.alarm());
    assert_eq!(alone.sup.run_state(), RunState::Stopped);
    assert!(alone.drops.is_empty());

    let mut both = Rig::new(TravelSource::Both, Gear::Low2, 70, cfg);
    both.sup.command(Command::Start);
    let said = both.until(5000, |r| {
        r.sup.alarm() == Some(Alarm::GroundWheelBackwards { alone: false })
    });
    assert!(said.is_some(), "{:?}", both.sup.alarm());
    both.run_to(10.0);
    assert_eq!(both.sup.run_state(), RunState::Running);
    assert_eq!(
        both.sup.snapshot().travel_source,
        TravelSourceInUse::HallStandIn
    );
    assert!(both.plants_between(2.0, 10.0) as f64 >= 8.0 / 0.07 - 2.0);
}

/// Page 4's calibration of the wheel: a good run stores the model's counts
/// per metre (within 0.1 %); a run without pulses, one that counted
/// backwards, and a result beyond ±20 % of the nominal wheel are refused
/// with their message and change nothing.
#[test]
fn the_wheel_calibration_takes_a_good_run_and_refuses_bad_ones() {
    // Drives `metres` at Low 2 with the drum stopped (the wheel's encoder
    // dead from the start when `dead`) and types `typed` cm (the tape's when
    // `None`); the effects of the distance and of Accept, and the settings
    // before and after.
    let run = |cfg: Config, metres: f64, typed: Option<i32>, dead: bool| {
        let mut r = Rig::new(TravelSource::HallGear, Gear::Low2, 70, cfg);
        if dead {
            r.m.inject_fault(Fault::GroundEncoderLoss);
        }
        r.sup
            .command(Command::SelectCalibration(CalibrationKind::GroundWheel));
        r.run_to(1.0);
        let before = r.sup.settings().clone();
        r.sup.command(Command::CalibrationStart);
        let g0 = r.m.ground_position_m();
        r.run_to(g0 + metres);
        r.sup.command(Command::CalibrationStop);
        let taped = ((r.m.ground_position_m() - g0) * 100.0).round() as i32;
        let effect = r.sup.command(Command::CalibrationActualDistance(
            CalibrationDistance::new(typed.unwrap_or(taped)).unwrap(),
        ));
        let accept = r.sup.command(Command::CalibrationAccept);
        (effect, accept, before, r.sup.settings().clone())
    };
    let good = Config {
        seed: 61,
        ground_wheel_diameter_error: 0.015,
        ..Config::default()
    };
    let (effect, accept, _, after) = run(good, 30.0, None, false);
    assert_eq!((effect, accept), (Effect::None, Effect::SettingsChanged));
    let truth = f64::from(model_counts_per_m_x1000(&good)) / 1.015;
    let got = f64::from(after.ground_wheel.counts_per_m_x1000);
    assert!((got / truth - 1.0).abs() < 0.001, "{got} vs {truth}");

    let refusals = [
        (
            "no pulses",
            Config {
                seed: 62,
                ..Config::default()
            },
            true,
            None,
            supervisor::drum::alarm::WHEEL_NO_PULSES_TEXT,
        ),
        (
            "backwards",
            Config {
                seed: 63,
                ground_wheel_reversed: true,
                ..Config::default()
            },
            false,
            None,
            supervisor::drum::alarm::WHEEL_BACKWARDS_RUN_TEXT,
        ),
        (
            "a wheel 20 % small",
            Config {
                seed: 64,
                ground_wheel_diameter_error: -0.2,
                ..Config::default()
            },
            false,
            None,
            supervisor::drum::alarm::WHEEL_TOLERANCE_TEXT,
        ),
        (
            "half the distance typed",
            Config {
                seed: 65,
                ..Config::default()
            },
            false,
            Some(1500),
            supervisor::drum::alarm::WHEEL_TOLERANCE_TEXT,
        ),
    ];
    for (what, cfg, dead, typed, text) in refusals {
        let (effect, accept, before, after) = run(cfg, 30.0, typed, dead);
        assert_eq!(effect, Effect::Message(text), "{what}");
        assert_ne!(accept, Effect::SettingsChanged, "{what}");
        assert_eq!(after, before, "{what}: settings changed");
    }
}

/// A coefficient typed by hand on page 4 for the wheel is its counts per
/// metre as a factor of the nominal wheel's, shown back as typed.
#[test]
fn a_wheel_factor_typed_by_hand_sets_the_counts_per_metre() {
    let mut r = Rig::new(TravelSource::Both, Gear::Low1, 70, Config::default());
    r.sup
        .command(Command::SelectCalibration(CalibrationKind::GroundWheel));
    for raw in [800, 1000, 1015, 1200] {
        let effect = r.sup.command(Command::SetCalibrationCoefficient(
            CalibrationCoefficient::new(raw).unwrap(),
        ));
        assert_eq!(effect, Effect::SettingsChanged);
        let want = (f64::from(NOMINAL_COUNTS_PER_M_X1000) * f64::from(raw) / 1000.0).round();
        assert_eq!(
            f64::from(r.sup.settings().ground_wheel.counts_per_m_x1000),
            want
        );
        assert_eq!(
            i32::from(r.sup.screen_settings().calibration_coefficient.raw()),
            raw
        );
    }
}
