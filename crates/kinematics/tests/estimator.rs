//! The M/T estimator on synthetic Hall edge streams: 25 teeth with ±1 %
//! tooth-pitch error, ±5 µs capture jitter, 1 MHz timer with 16-bit
//! captures, wrap and interrupt latency (the capture/overflow race), 100 ms
//! updates. Reference: the exact simulated speed.
#![allow(
    clippy::unwrap_used,
    clippy::float_arithmetic,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap
)]

use kinematics::speed::{CaptureExtender, EstimatorSettings, MotionState, MtEstimator};
use kinematics::units::Ticks;
use proptest::prelude::*;

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    /// Uniform in [-1, 1).
    fn sym(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Tooth pitch errors: uniform ±1 %, closed over a revolution (sum 0).
fn pitch_errors(rng: &mut Rng) -> [f64; 25] {
    let mut e = [0.0; 25];
    for v in &mut e {
        *v = 0.01 * rng.sym();
    }
    let mean = e.iter().sum::<f64>() / 25.0;
    for v in &mut e {
        *v -= mean;
    }
    e
}

struct Run {
    /// (time s, estimate r/min, state) per update after warm-up.
    samples: Vec<(f64, f64, MotionState)>,
    truth_rpm: f64,
}

/// Simulates `secs` seconds at `kmh`, returns the samples after `warm` s.
/// Edges with `glitch_every` > 0 get an extra bounce edge 40–240 µs later.
fn simulate(
    kmh: f64,
    secs: f64,
    warm: f64,
    settings: EstimatorSettings,
    seed: u64,
    glitch_every: usize,
) -> Run {
    let mut rng = Rng(seed);
    let pitch = pitch_errors(&mut rng);
    let rev_per_s = kmh / 3.6 / (std::f64::consts::PI * 0.2);
    // Edge capture times in µs (f64), starting at a random phase.
    let mut edges: Vec<u64> = Vec::new();
    let mut angle = 0.0;
    let t0 = 1000.0 + (rng.next() % 50_000) as f64;
    let mut k = (rng.next() % 25) as usize;
    loop {
        angle += (1.0 + pitch[k % 25]) / 25.0;
        k += 1;
        let t = t0 + angle / rev_per_s * 1e6 + 5.0 * rng.sym();
        if t > secs * 1e6 {
            break;
        }
        edges.push(t.round() as u64);
        if glitch_every > 0 && edges.len().is_multiple_of(glitch_every) {
            edges.push(t.round() as u64 + 40 + rng.next() % 200);
        }
    }
    let mut est = settings.build().unwrap();
    let mut ext = CaptureExtender::new();
    let mut serviced: u64 = 0; // overflows accounted
    let mut samples = Vec::new();
    let mut next_update: u64 = 100_000;
    let mut ei = 0;
    let mut next_ovf_isr = 65_536 + rng.next() % 20;
    loop {
        let edge_isr = edges.get(ei).map(|&t| t + rng.next() % 20);
        let t_next = [edge_isr.unwrap_or(u64::MAX), next_ovf_isr, next_update]
            .into_iter()
            .min()
            .unwrap();
        if t_next as f64 > secs * 1e6 {
            break;
        }
        let happened = t_next / 65_536; // overflows that occurred by now
        if Some(t_next) == edge_isr {
            let cap = edges[ei];
            let pending = happened > serviced;
            let ticks = ext.extend((cap % 65_536) as u16, pending);
            assert_eq!(ticks.0, cap as u32, "extended capture");
            if pending {
                ext.on_overflow();
                serviced += 1;
            }
            est.push_edge(ticks);
            ei += 1;
        } else if t_next == next_ovf_isr {
            if serviced < happened {
                ext.on_overflow();
                serviced += 1;
            }
            next_ovf_isr = (happened + 1) * 65_536 + rng.next() % 20;
        } else {
            let now = ext.now((t_next % 65_536) as u16, happened > serviced);
            assert_eq!(now.0, t_next as u32, "extended now");
            let m = est.update(now);
            if t_next as f64 >= warm * 1e6 {
                samples.push((t_next as f64 / 1e6, m.gear_speed.to_f64(), m.state));
            }
            next_update += 100_000;
        }
    }
    Run {
        samples,
        truth_rpm: rev_per_s * 60.0,
    }
}

fn max_rel_error(run: &Run) -> f64 {
    let mut measured = 0;
    let mut worst: f64 = 0.0;
    for &(_, v, s) in &run.samples {
        assert!(
            matches!(
                s,
                MotionState::Measured | MotionState::Holding | MotionState::Decaying
            ),
            "unexpected state {s:?}"
        );
        if s == MotionState::Measured {
            measured += 1;
        }
        worst = worst.max((v - run.truth_rpm).abs() / run.truth_rpm);
    }
    assert!(measured > 10, "too few measurements: {measured}");
    worst
}

/// Warm-up: three revolutions (tooth learning) plus 1 s.
fn warm_for(kmh: f64) -> f64 {
    3.0 * (std::f64::consts::PI * 0.2) / (kmh / 3.6) + 1.0
}

#[test]
fn steady_speeds_within_half_a_percent() {
    for (i, kmh) in [0.3, 0.5, 0.85, 1.4, 2.2, 3.0, 4.0].into_iter().enumerate() {
        let warm = warm_for(kmh);
        let run = simulate(
            kmh,
            warm + 30.0,
            warm,
            EstimatorSettings::default(),
            0x9e37_79b9 + i as u64,
            0,
        );
        let e = max_rel_error(&run);
        eprintln!("{kmh} km/h: worst error {:.4} %", e * 100.0);
        assert!(e <= 0.005, "{kmh} km/h: worst error {:.3} %", e * 100.0);
    }
}

#[test]
fn median_of_three_also_within_half_a_percent() {
    let s = EstimatorSettings {
        median_of_3: true,
        ..EstimatorSettings::default()
    };
    for kmh in [0.3, 4.0] {
        let warm = warm_for(kmh);
        let e = max_rel_error(&simulate(kmh, warm + 20.0, warm, s, 77, 0));
        assert!(e <= 0.005, "{kmh} km/h: {:.3} %", e * 100.0);
    }
}

#[test]
fn glitches_are_rejected() {
    let warm = warm_for(1.4);
    let run = simulate(1.4, warm + 20.0, warm, EstimatorSettings::default(), 5, 3);
    let e = max_rel_error(&run);
    assert!(e <= 0.005, "with bounces: {:.3} %", e * 100.0);
}

/// Why the pitch compensation exists: without it, single gaps at 0.3 km/h
/// carry the ±1 % pitch error (and the difference of two edges' errors).
#[test]
fn without_pitch_compensation_low_speed_exceeds_the_bound() {
    let s = EstimatorSettings {
        pitch_compensation: false,
        ..EstimatorSettings::default()
    };
    let warm = warm_for(0.3);
    let e = max_rel_error(&simulate(0.3, warm + 30.0, warm, s, 11, 0));
    assert!(
        e > 0.005,
        "expected > 0.5 % without compensation, got {:.3} %",
        e * 100.0
    );
}

#[test]
fn decays_then_stops() {
    let mut est = EstimatorSettings::default().build().unwrap();
    // 10 r/min: 240 ms per tooth.
    for k in 0..30u32 {
        est.push_edge(Ticks(k * 240_000));
    }
    let last = 29 * 240_000u32;
    let m = est.update(Ticks(last + 100_000));
    assert_eq!(m.state, MotionState::Measured);
    assert!((m.gear_speed.to_f64() - 10.0).abs() < 1e-3);
    // Not overdue yet (< 240 ms): held.
    assert_eq!(
        est.update(Ticks(last + 200_000)).state,
        MotionState::Holding
    );
    // 480 ms without an edge: at most one gap in 0.48 s; the next tooth is
    // not learnt (the edges came without updates), so its gap is allowed
    // 5 % more (an unlearnt tooth may be 4 % long): 1.05/25 rev in 0.48 s
    // = 5.25 r/min.
    let m = est.update(Ticks(last + 480_000));
    assert_eq!(m.state, MotionState::Decaying);
    assert!((m.gear_speed.to_f64() - 5.25).abs() < 1e-3);
    // Monotone decay to the timeout, then 0.
    let mut prev = m.gear_speed;
    for dt in (580_000..1_500_000).step_by(100_000) {
        let m = est.update(Ticks(last + dt));
        assert!(m.gear_speed <= prev);
        prev = m.gear_speed;
    }
    let m = est.update(Ticks(last + 1_600_000));
    assert_eq!(m.state, MotionState::Stopped);
    assert_eq!(m.gear_speed.to_f64(), 0.0);
    // Restart: first edge ⇒ Starting, second ⇒ measured again.
    est.push_edge(Ticks(last + 3_000_000));
    assert_eq!(
        est.update(Ticks(last + 3_050_000)).state,
        MotionState::Starting
    );
    est.push_edge(Ticks(last + 3_200_000));
    let m = est.update(Ticks(last + 3_250_000));
    assert_eq!(m.state, MotionState::Measured);
    // One gap of 200 ms with the learned share of that tooth (uniform here): 12 r/min.
    assert!((m.gear_speed.to_f64() - 12.0).abs() < 1e-3);
}

#[test]
fn timestamps_wrap_at_2_pow_32() {
    let mut est = EstimatorSettings::default().build().unwrap();
    let start = u32::MAX - 500_000;
    for k in 0..10u32 {
        est.push_edge(Ticks(start.wrapping_add(k * 100_000)));
    }
    let m = est.update(Ticks(start.wrapping_add(950_000)));
    // 100 ms per tooth: 60/(25·0.1) = 24 r/min.
    assert!(
        (m.gear_speed.to_f64() - 24.0).abs() < 1e-3,
        "{}",
        m.gear_speed
    );
}

#[test]
fn settings_are_validated() {
    let d = EstimatorSettings::default();
    assert!(EstimatorSettings { teeth: 1, ..d }.build().is_err());
    assert!(EstimatorSettings { teeth: 33, ..d }.build().is_err());
    assert!(EstimatorSettings { timer_hz: 0, ..d }.build().is_err());
    assert!(EstimatorSettings {
        stop_timeout_ticks: 100,
        ..d
    }
    .build()
    .is_err());
    assert!(EstimatorSettings {
        glitch_shift: 0,
        ..d
    }
    .build()
    .is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn arbitrary_timestamps_never_panic(
        ops in proptest::collection::vec((any::<bool>(), any::<u32>()), 0..400),
        teeth in 2u8..=32,
        median in any::<bool>(),
        comp in any::<bool>(),
        timeout in 1_000u32..=2_000_000_000,
    ) {
        let mut est: MtEstimator = EstimatorSettings {
            teeth,
            median_of_3: median,
            pitch_compensation: comp,
            stop_timeout_ticks: timeout,
            ..EstimatorSettings::default()
        }
        .build()
        .unwrap();
        let mut ext = CaptureExtender::new();
        for (is_edge, v) in ops {
            if is_edge {
                let t = ext.extend(v as u16, v & 0x1_0000 != 0);
                let _ = est.push_edge(Ticks(v ^ t.0));
            } else {
                if v.is_multiple_of(7) {
                    ext.on_overflow();
                }
                let _ = est.update(Ticks(v));
            }
        }
    }

    #[test]
    fn increasing_edges_give_plausible_speeds(gaps in proptest::collection::vec(500u32..2_000_000, 2..200)) {
        let mut est = EstimatorSettings::default().build().unwrap();
        let mut t = 0u32;
        for g in gaps {
            t = t.wrapping_add(g);
            est.push_edge(Ticks(t));
            let m = est.update(Ticks(t.wrapping_add(10)));
            // A gear rev needs ≥ 25 edges ≥ 500 µs apart: ≤ 4800 r/min, saturated to the U12F20 max.
            prop_assert!(m.gear_speed.to_f64() < 4096.0);
        }
    }
}

/// Tooth learning must not mistake a change of speed for tooth-pitch error:
/// a perfect gear (no pitch error) at 0.5 km/h, then a 0.5 s-time-constant
/// rise of 10 % (a chassis answering more throttle). Once the speed is
/// steady again every gap is truly equal, so any estimate away from the
/// truth is a share learnt wrongly during the rise. Expected values: the
/// exact speed of the edge stream, computed here in f64.
#[test]
fn a_speed_change_is_not_learnt_as_tooth_error() {
    let mut est = EstimatorSettings::default().build().unwrap();
    let pitch = std::f64::consts::PI * 0.2 / 25.0; // m of track per edge
    let v0 = 0.5 / 3.6;
    let speed = |t: f64| {
        if t < 20.0 {
            v0
        } else {
            v0 * (1.0 + 0.1 * (1.0 - (-(t - 20.0) / 0.5).exp()))
        }
    };
    let (mut t, mut s, mut next_edge) = (0.0f64, 0.0f64, pitch);
    let dt = 1e-5;
    let mut worst_after: f64 = 0.0;
    let mut last_update = 0.0;
    while t < 40.0 {
        t += dt;
        s += speed(t) * dt;
        if s >= next_edge {
            next_edge += pitch;
            est.push_edge(Ticks((t * 1e6) as u32));
        }
        if t - last_update >= 0.1 {
            last_update = t;
            let m = est.update(Ticks((t * 1e6) as u32));
            // Speed of the gear, r/min, from the true track speed.
            let truth = speed(t) / (std::f64::consts::PI * 0.2) * 60.0;
            if t > 28.0 {
                let e = (m.gear_speed.to_f64() - truth).abs() / truth;
                worst_after = worst_after.max(e);
            }
        }
    }
    assert!(
        worst_after <= 0.001,
        "after the rise: {:.3} %",
        worst_after * 100.0
    );
}

/// Stop-and-go shorter than the stop timeout: the gap that spans the pause
/// must not make the next full-speed gap look like a glitch (found by the
/// bench's Table 15 and stop-and-go runs: 5 of 309 real edges dropped, each
/// one tooth — ≈ 25 mm — of distance lost). Edges by hand: 311 ms gaps
/// (Low 2 at 0.5 km/h), a 1.45 s pause (under the 1.5 s timeout), 311 ms
/// gaps again; and a bounce 20 ms after an edge is still a glitch.
#[test]
fn a_short_pause_does_not_turn_the_next_real_edges_into_glitches() {
    use kinematics::speed::EdgeVerdict;
    let mut est = EstimatorSettings::default().build().unwrap();
    let mut t: u32 = 0;
    let mut push = |dt: u32, est: &mut MtEstimator| {
        t = t.wrapping_add(dt);
        est.push_edge(Ticks(t))
    };
    for _ in 0..30 {
        push(311_000, &mut est);
    }
    assert_eq!(push(1_450_000, &mut est), EdgeVerdict::Accepted);
    for i in 0..10 {
        assert_eq!(
            push(311_000, &mut est),
            EdgeVerdict::Accepted,
            "edge {i} after the pause"
        );
    }
    // A contact bounce 20 ms after a real edge (1/15 of the period).
    assert_eq!(push(20_000, &mut est), EdgeVerdict::Glitch);
}

/// A contact bounce of the first edge after a stop: the machine starts
/// from rest (2 s without an edge, past the 1.5 s timeout) at 100 ms a
/// tooth (24 r/min of the 25-tooth gear: 60 / (25 × 0.1 s), by hand), and
/// the first edge bounces 1 ms later. With no period yet to judge it by,
/// the bounce was taken as a 1 ms tooth: 2400 r/min of the gear (85 km/h
/// of track) for a window, the drum commanded to its limit. From rest the
/// next tooth cannot come within 20 ms (≥ 29 ms at 1 g, docs/kinematics.md),
/// so it is a glitch; a real first gap of 30 ms still counts.
#[test]
fn a_bounce_of_the_first_edge_after_a_stop_is_a_glitch() {
    use kinematics::speed::EdgeVerdict;
    let mut est = EstimatorSettings::default().build().unwrap();
    for k in 0..20u32 {
        est.push_edge(Ticks(k * 100_000));
    }
    let t0 = 19 * 100_000 + 2_000_000;
    assert_eq!(est.push_edge(Ticks(t0)), EdgeVerdict::Restart);
    assert_eq!(est.push_edge(Ticks(t0 + 1_000)), EdgeVerdict::Glitch);
    let mut fastest = 0.0f64;
    for k in 1..=10u32 {
        let t = t0 + k * 100_000;
        assert_eq!(est.push_edge(Ticks(t)), EdgeVerdict::Accepted, "tooth {k}");
        for dt in [1_000u32, 50_000] {
            let m = est.update(Ticks(t + dt));
            fastest = fastest.max(m.gear_speed.to_f64());
        }
    }
    assert!(
        fastest <= 24.0 * 1.05,
        "gear read {fastest:.1} r/min, truth 24"
    );
    // A real first gap of 30 ms (a hard start) is a tooth.
    let t1 = t0 + 10 * 100_000 + 2_000_000;
    assert_eq!(est.push_edge(Ticks(t1)), EdgeVerdict::Restart);
    assert_eq!(est.push_edge(Ticks(t1 + 30_000)), EdgeVerdict::Accepted);
}

/// Edge times of a 25-tooth gear whose tooth `k` sits `pos_err[k]` pitches
/// off its nominal place, driven at `speed(t)` pitches per second for
/// `secs` s, integrated in 10 µs steps.
fn edges_of(speed: &dyn Fn(f64) -> f64, pos_err: &[f64; 25], secs: f64) -> Vec<u32> {
    let (mut t, mut angle, mut next) = (0.0f64, 0.0f64, 1u64);
    let mut out = Vec::new();
    let dt = 1e-5;
    while t < secs {
        t += dt;
        angle += speed(t) * dt;
        let at = next as f64 + pos_err[(next % 25) as usize];
        if angle >= at {
            out.push((t * 1e6) as u32);
            next += 1;
        }
    }
    out
}

/// RMS difference (in shares) between the estimator's learned gap shares,
/// scaled to sum to 25, and the true ones: the gap ending at edge `j` (the
/// estimator's tooth index `j mod 25`, edge 0 being the first it saw) spans
/// `1 + e[j] − e[j−1]` pitches.
fn share_error(est: &MtEstimator, pos_err: &[f64; 25], first_edge: u64) -> f64 {
    let w: Vec<f64> = est.tooth_weights().map(f64::from).collect();
    let sum: f64 = w.iter().sum();
    let mut acc = 0.0;
    for (k, wk) in w.iter().enumerate() {
        // Estimator index k ↔ physical edge first_edge + k (mod 25).
        let j = (first_edge + k as u64) % 25;
        let truth = 1.0 + pos_err[j as usize] - pos_err[((j + 24) % 25) as usize];
        acc += (wk * 25.0 / sum - truth).powi(2);
    }
    (acc / 25.0).sqrt()
}

/// The estimator after `edges`, updated every 100 ms as the firmware does.
fn learnt(edges: &[u32]) -> MtEstimator {
    let mut est = EstimatorSettings::default().build().unwrap();
    let mut t_update = 100_000u32;
    for &t in edges {
        while t > t_update {
            est.update(Ticks(t_update));
            t_update += 100_000;
        }
        est.push_edge(Ticks(t));
    }
    est
}

/// The gear's own error in shares (RMS of `e[j] − e[j−1]`): what not
/// learning leaves.
fn gear_error(pos_err: &[f64; 25]) -> f64 {
    let d: Vec<f64> = (0..25)
        .map(|j| pos_err[j] - pos_err[(j + 24) % 25])
        .collect();
    (d.iter().map(|d| d * d).sum::<f64>() / 25.0).sqrt()
}

fn position_errors(seed: u64) -> [f64; 25] {
    // ±2 % of a pitch per tooth, as the machine model's default gear.
    let mut rng = Rng(seed);
    let mut e = [0.0; 25];
    for v in &mut e {
        *v = 0.02 * rng.sym();
    }
    e
}

/// Tooth learning on a speed that never holds still: the terrain's ±3 %
/// wander over 8 s at 0.5 km/h (Low 1's pace: a revolution in 4.5 s), the
/// gear's teeth ±2 % of a pitch off. The shares must be learnt to within
/// 0.3 % RMS in 400 s (89 revolutions; measured 0.11–0.13 %). Before the curvature-gated learning
/// (the old rule learnt only while the revolution time held within 0.2 %)
/// nothing was learnt on such a speed: the error stayed the gear's own,
/// ≈ 1.6 % RMS here.
#[test]
fn tooth_shares_are_learnt_while_the_speed_wanders() {
    for seed in [3u64, 17, 29] {
        let speed = |t: f64| V0 * (1.0 + 0.03 * (2.0 * std::f64::consts::PI * t / 8.0).sin());
        let (err, _) = learnt_against_the_gear(seed, &speed);
        assert!(err <= 0.003, "seed {seed}: {:.3} % RMS", err * 100.0);
    }
}

/// 0.5 km/h in Hall tooth pitches per second (π · 0.20 m / 25 a pitch).
const V0: f64 = 0.5 / 3.6 / (std::f64::consts::PI * 0.2 / 25.0);

/// Learns the tooth shares of gear `seed` from 400 s of edges at `speed`
/// (pitches/s): the learnt shares' RMS error and the gear's own.
fn learnt_against_the_gear(seed: u64, speed: &dyn Fn(f64) -> f64) -> (f64, f64) {
    let pos_err = position_errors(seed);
    let est = learnt(&edges_of(speed, &pos_err, 400.0));
    let gear = gear_error(&pos_err);
    let err = share_error(&est, &pos_err, 1);
    println!(
        "seed {seed}: learnt shares {:.3} % RMS off (the gear's own {:.3} %)",
        err * 100.0,
        gear * 100.0
    );
    (err, gear)
}

/// On the hills profile's speed steps (±20 % through the chassis' 0.5 s time
/// constant, one every 3 s) what is learnt must not be worse than learning
/// nothing (the gear's own error). Measured: 1.33 % and 0.61 % RMS against
/// the gear's 1.98 % and 1.59 %. The ±4 % guard alone keeps the worst out
/// here; the gates' sharp check is `a_speed_change_is_not_learnt_as_tooth_error`,
/// which fails without them.
#[test]
fn speed_steps_are_not_learnt_as_tooth_error() {
    for seed in [5u64, 23] {
        // Set points from a fixed sequence of ±20 % steps every 3 s.
        let mut rng = Rng(seed ^ 0x5eed);
        let sets: Vec<f64> = (0..200).map(|_| 1.0 + 0.2 * rng.sym()).collect();
        let speed = move |t: f64| {
            let i = (t / 3.0) as usize;
            let (prev, now) = (if i == 0 { 1.0 } else { sets[i - 1] }, sets[i]);
            let since = t - i as f64 * 3.0;
            V0 * (now + (prev - now) * (-since / 0.5).exp())
        };
        let (err, gear) = learnt_against_the_gear(seed, &speed);
        assert!(
            err <= gear,
            "seed {seed}: {:.3} % vs {:.3} %",
            err * 100.0,
            gear * 100.0
        );
    }
}

/// A sensor that sticks low falls once part-way through a gap, then is
/// silent: at a steady working speed (Low 2, 180 ms a tooth, a learnt
/// perfect gear) that edge, wherever it falls in the gap (¼ … ¾ of it, where
/// the glitch rule does not drop it), must not raise the speed — it is held
/// until a next edge confirms it, and none comes. Before, it closed a
/// window of ¼ … ¾ of a gap: up to 4 × the speed, which sprinted the drum.
/// The same edge followed by the teeth again (the line released in time)
/// is dropped when the next gap does not fit it, and a real doubling of the
/// speed (two short gaps) is taken at the second edge.
#[test]
fn a_spurious_edge_at_a_steady_speed_raises_no_speed() {
    use kinematics::speed::EdgeVerdict;
    const GAP: u32 = 180_000;
    let steady = |est: &mut MtEstimator| {
        let mut t = 0u32;
        for _ in 0..200 {
            t += GAP;
            est.push_edge(Ticks(t));
            est.update(Ticks(t + 5_000));
        }
        t
    };
    let truth = 60.0 / (25.0 * 0.18); // r/min of the gear
    for share in [0.26f64, 0.4, 0.5, 0.6, 0.74] {
        let mut est = EstimatorSettings::default().build().unwrap();
        let t = steady(&mut est);
        let spurious = t + (f64::from(GAP) * share) as u32;
        assert_eq!(est.push_edge(Ticks(spurious)), EdgeVerdict::Suspect);
        let mut fastest = 0.0f64;
        for dt in (10_000..2_000_000).step_by(10_000) {
            fastest = fastest.max(est.update(Ticks(spurious + dt)).gear_speed.to_f64());
        }
        assert!(
            fastest <= truth * 1.001,
            "share {share}: {fastest} r/min, truth {truth}"
        );
        // Released in time: the next tooth comes where it was due. Up to
        // 0.44 of a gap the gap after it is more than 1¼ of its own: it was
        // spurious. From half a gap on the two gaps are as a real speed-up
        // makes them, and both count (a tooth at most: the ground is right
        // again at the next edge).
        if share > 0.44 {
            continue;
        }
        let mut est = EstimatorSettings::default().build().unwrap();
        let t = steady(&mut est);
        let before = est.accepted_edges();
        est.push_edge(Ticks(t + (f64::from(GAP) * share) as u32));
        assert_eq!(est.push_edge(Ticks(t + GAP)), EdgeVerdict::Accepted);
        assert_eq!(
            est.accepted_edges() - before,
            1,
            "share {share}: the spurious edge counted"
        );
    }
    // A real doubling: two half gaps; both edges are taken at the second.
    let mut est = EstimatorSettings::default().build().unwrap();
    let t = steady(&mut est);
    let before = est.accepted_edges();
    assert_eq!(est.push_edge(Ticks(t + GAP / 2)), EdgeVerdict::Suspect);
    assert_eq!(est.push_edge(Ticks(t + GAP)), EdgeVerdict::Accepted);
    assert_eq!(est.accepted_edges() - before, 2);
    let m = est.update(Ticks(t + GAP + 1_000));
    assert!(
        (m.gear_speed.to_f64() / (2.0 * truth) - 1.0).abs() < 0.01,
        "{}",
        m.gear_speed.to_f64()
    );
}
