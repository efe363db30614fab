//! The ground the Hall gear's learnt tooth table counts, against the
//! machine model's true tooth places: over the spans a plant spacing covers
//! (3 to 8 teeth at 7–18 cm), the learnt pitches must come closer to the
//! true ground than counting every tooth as a nominal pitch does.
//!
//! The model's gear has ±2 % of a pitch of position error per tooth (fixed
//! per seed) and runs on the default terrain (a ±3 % 8 s speed ripple,
//! random steps, slip noise). The estimator is the supervisor's
//! (`EstimatorSettings::default()`), fed the model's edges as the capture
//! interrupt feeds it and updated every 10 ms as the control task does.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::indexing_slicing
)]

use kinematics::consts::Gear;
use kinematics::speed::EstimatorSettings;
use kinematics::units::Ticks;
use machine_sim::{Config, Event, Inputs};

/// RMS over every start tooth of (counted − true) ground over `span`
/// consecutive gaps, pitches: for the learnt table and for nominal pitches.
fn span_errors(learnt: &[f64], truth: &[f64], span: usize) -> (f64, f64) {
    let z = truth.len();
    let (mut l2, mut n2) = (0.0, 0.0);
    for start in 0..z {
        let (mut l, mut t) = (0.0, 0.0);
        for j in 0..span {
            l += learnt[(start + j) % z];
            t += truth[(start + j) % z];
        }
        l2 += (l - t).powi(2);
        n2 += (span as f64 - t).powi(2);
    }
    ((l2 / z as f64).sqrt(), (n2 / z as f64).sqrt())
}

/// Runs the model for `secs` at `gear`, then returns the last revolution's
/// gaps: (learnt pitches, true pitches).
fn learnt_and_true(seed: u64, gear: Gear, secs: u32) -> (Vec<f64>, Vec<f64>) {
    let mut m = Config {
        seed,
        initial_gear: Some(gear),
        ..Config::default()
    }
    .build()
    .unwrap();
    let mut est = EstimatorSettings::default().build().unwrap();
    for _ in 0..secs * 100 {
        m.step_events(10_000, &Inputs::default(), &mut |e| {
            if let Event::HallEdge(t) = e {
                let _ = est.push_edge(Ticks(t));
            }
        });
        let _ = est.update(Ticks(m.capture_ticks()));
    }
    let newest = u64::from(m.hall_edges());
    let z = 25;
    let learnt: Vec<f64> = (0..z)
        .map(|back| f64::from(est.gap_pitches_q16(back)) / 65_536.0)
        .collect();
    let truth: Vec<f64> = (0..z as u64)
        .map(|back| {
            let k = newest - back;
            m.hall_edge_place_pitches(k) - m.hall_edge_place_pitches(k - 1)
        })
        .collect();
    (learnt, truth)
}

#[test]
fn the_learnt_ground_beats_nominal_pitches_over_every_spacing_span() {
    for (gear, secs) in [(Gear::Low1, 400), (Gear::Low2, 240)] {
        for seed in [41, 42, 43] {
            let (learnt, truth) = learnt_and_true(seed, gear, secs);
            for span in 1..=8 {
                let (l, n) = span_errors(&learnt, &truth, span);
                println!("{gear:?} seed {seed} span {span}: learnt {l:.4} nominal {n:.4} pitches");
                assert!(
                    l < n / 2.0,
                    "{gear:?} seed {seed}: over {span} teeth the learnt table is {l:.4} \
                     pitches RMS off the true ground, nominal pitches {n:.4}"
                );
            }
        }
    }
}
