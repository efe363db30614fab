//! The drum command where the ground is smooth: the supervisor against the
//! machine simulator, as the firmware's 10 ms task drives it. The limits
//! are the product's targets (docs/kinematics.md, "Travel speed for the
//! drum"); the ground's own steps come from the simulator.
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
use machine_sim::{Config, Event, Inputs, Machine};
use supervisor::drum::{Actuation, Hardware, Supervisor};
use supervisor::settings::Settings;

const HW: Hardware = Hardware::BOARD;

struct Rig {
    sup: Supervisor,
    m: Machine,
    act: Actuation,
    plants: usize,
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
            plants: 0,
        }
    }

    /// One period; the drum target after it, r/min × 1000.
    fn period(&mut self) -> f64 {
        let inputs = Inputs {
            drum_duty: f32::from(self.act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: self.act.driver_enabled,
            ..Inputs::default()
        };
        let (sup, plants) = (&mut self.sup, &mut self.plants);
        self.m.step_events(10_000, &inputs, &mut |e| match e {
            Event::HallEdge(t) => sup.hall_edge(Ticks(t)),
            Event::Plant { .. } => *plants += 1,
        });
        self.act = self
            .sup
            .control_step(Ticks(self.m.capture_ticks()), self.m.drum_encoder_count());
        f64::from(self.sup.snapshot().target_drum_rpm_x1000)
    }
}

/// Relative steps, %, between values `lag` periods apart.
fn steps(v: &[f64], lag: usize) -> Vec<f64> {
    v.windows(lag + 1)
        .map(|w| ((w[lag] - w[0]) / w[0]).abs() * 100.0)
        .collect()
}

/// Flat ground at a steady speed (no terrain sinusoid or steps; the gear's
/// ±2 % tooth errors and 10 µs capture jitter on), the machine at its
/// gear's speed from power-up and Start after 3 s, as on the move: the drum
/// target's largest 10 ms step, from the pass's first plant for 30 m, at
/// most 2 % (the ground's own: 0). Low 1 and Low 2, 7 and 18 cm, seeds 5–7
/// and 11–22. Before, the first revolutions' single-gap tooth errors,
/// carried along their slope, stepped it by 20–26 % (measured on seeds
/// 5–7); and a gear with a gap near ±4 % of a pitch (seeds 17, 18, 21) kept
/// that tooth unlearnt behind the learning's ±4 % gate, and its nominal
/// share stepped the target by 4–11 % minutes into the run.
#[test]
fn on_flat_ground_the_drum_target_steps_at_most_2_percent() {
    let mut worst: f64 = 0.0;
    for gear in [Gear::Low1, Gear::Low2] {
        for spacing_mm in [70u16, 180] {
            for seed in [5u64, 6, 7].into_iter().chain(11..=22) {
                let flat = Config {
                    seed,
                    terrain_amplitude: 0.0,
                    terrain_step_amplitude: 0.0,
                    terrain_step_interval_s: 0.0,
                    ..Config::default()
                };
                let mut rig = Rig::new(flat, gear, spacing_mm);
                for _ in 0..300 {
                    rig.period();
                }
                rig.sup.command(Command::Start);
                let from = rig.m.ground_position_m();
                let mut targets = Vec::new();
                while rig.m.ground_position_m() - from < 30.0 {
                    let t = rig.period();
                    if rig.plants > 0 {
                        targets.push(t);
                    }
                }
                let max = steps(&targets, 1).into_iter().fold(0.0, f64::max);
                println!("{gear} {spacing_mm} mm seed {seed}: largest 10 ms step {max:.2} %");
                worst = worst.max(max);
            }
        }
    }
    assert!(worst <= 2.0, "{worst:.2} %");
}

/// The default terrain (±3 % over 8 s, ±2 % steps every 5 s on average,
/// slip noise, tooth errors, jitter; seed 3), 7 cm at Low 2, a 70 m row
/// from rest: from 20 m into the row the drum target's 100 ms steps have a
/// 95th percentile of at most 2.5 %. Before, 9.8 % (the ground's own:
/// 0.45 %): the tooth shares took hundreds of seconds to learn and the
/// predictor multiplied what was left of them.
#[test]
fn on_the_default_terrain_the_drum_target_is_as_smooth_as_the_ground_allows() {
    let mut rig = Rig::new(
        Config {
            seed: 3,
            ..Config::default()
        },
        Gear::Low2,
        70,
    );
    rig.sup.command(Command::Start);
    let (mut targets, mut ground) = (Vec::new(), Vec::new());
    while rig.m.ground_position_m() < 70.0 {
        let t = rig.period();
        if rig.m.ground_position_m() >= 20.0 {
            targets.push(t);
            ground.push(f64::from(rig.m.travel_speed_m_s()));
        }
    }
    let p95 = |v: &[f64]| {
        let mut s = steps(v, 10);
        s.sort_by(f64::total_cmp);
        s[(s.len() - 1) * 95 / 100]
    };
    let (t, g) = (p95(&targets), p95(&ground));
    println!("100 ms steps p95: drum target {t:.2} %, ground {g:.2} %");
    assert!(t <= 2.5, "{t:.2} %");
}
