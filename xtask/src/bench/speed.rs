//! Item 2: travel-speed measurement, paper A's M-method against the
//! product's M/T estimator, on the simulated Hall gear.

use kinematics::speed::{m_method_gear_speed, m_method_window, EstimatorSettings};
use kinematics::units::Ticks;
use machine_sim::{Config, Inputs};

use crate::Result;

/// Travel speeds of the sweep, km/h.
pub const SPEEDS_KMH: [f64; 7] = [0.3, 0.5, 0.85, 1.4, 2.2, 3.0, 4.0];
/// Update period of every method, ms.
pub const UPDATE_MS: u32 = 100;
/// Warm-up before measuring (the M/T estimator learns the tooth errors), ms.
pub const WARMUP_MS: u32 = 20_000;
/// Steady measuring time, ms.
pub const MEASURE_MS: u32 = 30_000;
/// After the measuring time, a +10 % step; followed for this long, ms.
pub const AFTER_STEP_MS: u32 = 6_000;
/// Seed of the machine.
pub const SEED: u64 = 2;

/// The methods compared.
pub const METHODS: [&str; 3] = [
    "M-method, 100 ms window (eq. 1–2)",
    "M-method, 1 s window, sliding",
    "M/T (product estimator)",
];

/// Results of one method at one speed.
#[derive(Clone, Copy, Default)]
pub struct MethodResult {
    /// Mean |error| relative to the truth, %.
    pub mean_err_pct: f64,
    /// Max |error|, %.
    pub max_err_pct: f64,
    /// Time from a +10 % step until the estimate stays within 1 % of the
    /// truth, s (`None`: not within the observed time).
    pub latency_s: Option<f64>,
}

/// Runs one speed: returns a result per method.
pub fn run(kmh: f64) -> Result<[MethodResult; 3]> {
    let cfg = Config {
        seed: SEED,
        // The truth must be steady: sensor noise on (tooth pitch error 2 %,
        // capture jitter ±10 µs), terrain off; the Hall gear turns exactly
        // with the track (k1 under-reading off) so the truth is the track.
        terrain_amplitude: 0.0,
        terrain_step_amplitude: 0.0,
        terrain_step_interval_s: 0.0,
        hall_k1_scale: 0.0,
        ..Config::default()
    };
    let mut m = cfg.build().map_err(|e| format!("machine: {e}"))?;
    #[allow(clippy::cast_possible_truncation)]
    m.set_travel_speed_m_s((kmh / 3.6) as f32);
    let mut est = EstimatorSettings::default()
        .build()
        .map_err(|e| format!("estimator: {e}"))?;
    let w100 = m_method_window(7199, 999, 72_000_000).map_err(|e| format!("{e:?}"))?;
    let w1000 = m_method_window(7199, 9999, 72_000_000).map_err(|e| format!("{e:?}"))?;
    let circumference = std::f64::consts::PI * 0.20;
    let mut edges: Vec<u32> = Vec::new();
    let inputs = Inputs::default();
    let total = WARMUP_MS + MEASURE_MS + AFTER_STEP_MS;
    let mut t = 0u32;
    let mut sums = [0.0f64; 3];
    let mut maxes = [0.0f64; 3];
    let mut n = 0u32;
    // Per method: the last update time at which the estimate was outside 1 %.
    let mut last_out: [Option<u32>; 3] = [None; 3];
    let step_at = WARMUP_MS + MEASURE_MS;
    while t < total {
        if t == step_at {
            m.inject_speed_step(0.10);
        }
        m.step(UPDATE_MS * 1000, &inputs, &mut |c| {
            edges.push(c);
            est.push_edge(Ticks(c));
        });
        t += UPDATE_MS;
        let now = m.capture_ticks();
        let truth = f64::from(m.wheel_speed_m_s()) / circumference * 60.0;
        let count_since = |window_us: u32| -> u32 {
            let c = edges
                .iter()
                .rev()
                .take_while(|&&e| now.wrapping_sub(e) < window_us)
                .count();
            u32::try_from(c).unwrap_or(u32::MAX)
        };
        let m100 = m_method_gear_speed(count_since(100_000), w100, 25)
            .map_err(|e| format!("{e:?}"))?
            .to_f64();
        let m1000 = m_method_gear_speed(count_since(1_000_000), w1000, 25)
            .map_err(|e| format!("{e:?}"))?
            .to_f64();
        let mt = est.update(Ticks(now)).gear_speed.to_f64();
        let errs = [m100, m1000, mt].map(|v| (v - truth).abs() / truth * 100.0);
        if (WARMUP_MS..step_at).contains(&t) || t == step_at {
            for (i, e) in errs.iter().enumerate() {
                sums[i] += e;
                maxes[i] = maxes[i].max(*e);
            }
            n += 1;
        }
        if t > step_at {
            for (i, e) in errs.iter().enumerate() {
                if *e > 1.0 {
                    last_out[i] = Some(t);
                }
            }
        }
        // Keep only the last second of edges.
        if edges.len() > 4096 {
            edges.drain(..2048);
        }
    }
    let mut out = [MethodResult::default(); 3];
    for i in 0..3 {
        out[i] = MethodResult {
            mean_err_pct: sums[i] / f64::from(n.max(1)),
            max_err_pct: maxes[i],
            latency_s: match last_out[i] {
                // The first update after the step is `UPDATE_MS` later.
                None => Some(f64::from(UPDATE_MS) / 1000.0),
                Some(t) if t + UPDATE_MS > total => None,
                Some(t) => Some(f64::from(t + UPDATE_MS - step_at) / 1000.0),
            },
        };
    }
    Ok(out)
}

/// Item 2 of the document.
pub fn section(doc: &mut String) -> Result {
    use std::fmt::Write as _;
    let _ = write!(
        doc,
        "## 2. Travel speed measurement: M-method vs M/T\n\n\
         The simulated Hall gear (25 teeth, one edge per 25.13 mm of track, tooth pitch error \
         ±2 %, capture jitter ±10 µs, seed {SEED}) at steady track speeds, terrain disturbance \
         off so that the truth is steady, the gear turning exactly with the track (k1 off: this \
         compares the methods, not the calibration). Every method is updated every {UPDATE_MS} ms. \
         *M-method* = paper A eq. 1–2, pulses counted in a window `t = (PSC+1)(ARR1+1)/72 MHz` \
         (`kinematics::speed::m_method_window/m_method_gear_speed`): the {UPDATE_MS} ms window \
         (PSC 7199, ARR1 999) and a 1 s window (ARR1 9999) slid every {UPDATE_MS} ms. *M/T* = the \
         product's `MtEstimator` (edges timestamped at 1 MHz, tooth errors learnt). After {w} s of \
         warm-up, errors over {meas} s (|estimate − truth| / truth, per update); then a +10 % step \
         of the track speed: *latency* = time from the step until the estimate stays within 1 % \
         of the new speed (to the update period).\n\n\
         | km/h | edges/s |",
        w = WARMUP_MS / 1000,
        meas = MEASURE_MS / 1000
    );
    for m in METHODS {
        let _ = write!(doc, " {m}: mean / max error %, latency s |");
    }
    doc.push_str("\n|---|---|---|---|---|\n");
    let mut all = Vec::new();
    for kmh in SPEEDS_KMH {
        let r = run(kmh)?;
        all.push((kmh, r));
        let edges = kmh / 3.6 / (std::f64::consts::PI * 0.20 / 25.0);
        let _ = write!(doc, "| {kmh:.2} | {edges:.1} |");
        for x in r {
            let lat = x
                .latency_s
                .map_or_else(|| "> 6".to_string(), |s| format!("{s:.1}"));
            let _ = write!(
                doc,
                " {:.2} / {:.2}, {lat} |",
                x.mean_err_pct, x.max_err_pct
            );
        }
        doc.push('\n');
    }
    let first = all.first().ok_or("no speeds")?;
    let mt_max = all
        .iter()
        .map(|(_, r)| r[2].max_err_pct)
        .fold(0.0f64, f64::max);
    let mt_lat = all
        .iter()
        .map(|(_, r)| r[2].latency_s.unwrap_or(f64::INFINITY))
        .fold(0.0f64, f64::max);
    let m1_ok_from = all
        .iter()
        .find(|(_, r)| r[1].max_err_pct <= 1.0)
        .map_or_else(
            || "no speed of the sweep".to_string(),
            |(v, _)| format!("{v:.2} km/h"),
        );
    let _ = write!(
        doc,
        "\nReading. Paper A measures with the M-method; at its working speeds the Hall gear \
         gives 3–6 edges per second, so a window of 100 ms holds 0 or 1 edge and the estimate \
         jumps between 0 and 24 r/min ({:.0} % mean error at {:.2} km/h). Even a 1 s window \
         (one edge = 2.4 r/min of gear speed) leaves {:.1} % mean error at {:.2} km/h, its \
         largest error stays above 1 % up to {m1_ok_from} (first speed within 1 %), and it \
         cannot settle within 1 % after a step below that. Paper A hides part of this in its k1 \
         table (Table 11: corrections of 1–3 %, which a quantised measurement makes \
         speed-dependent). The product's M/T estimator times the edges at 1 µs and learns the \
         tooth pitch errors: at most {mt_max:.2} % error at every speed, and within 1 % of a \
         new speed after at most {mt_lat:.1} s — at 0.3 km/h one edge period (0.3 s) plus the \
         update period. This is where the product is clearly ahead of the paper; the limit \
         left is the sensor itself (docs/firmware.md: one edge every 177 ms at Low 2).\n\n",
        first.1[0].mean_err_pct, first.0, first.1[1].mean_err_pct, first.0,
    );
    Ok(())
}
