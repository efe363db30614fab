//! Drive identification and the controller scheduled from it, on model
//! drives of the machine simulator (issue 16 item 3). Expected values are
//! the simulator's own parameters (its `Config`), never the code under test.
#![allow(
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
