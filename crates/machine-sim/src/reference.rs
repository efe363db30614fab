//! Host references computed from the simulated machine's own physics, for
//! tests that must not trust the firmware's arithmetic (`std` feature).

use crate::tables::K3_TABLE;

/// Belt slip k3 of the simulated belt at drum speed `n_rpm` (Table 13,
/// piecewise linear, clamped at the ends), in f64.
#[must_use]
pub fn k3_at(n_rpm: f64) -> f64 {
    let mut prev: Option<(f64, f64)> = None;
    for (x, y) in K3_TABLE.iter().map(|&(x, y)| (f64::from(x), f64::from(y))) {
        match prev {
            None if n_rpm <= x => return y,
            Some((x0, y0)) if n_rpm <= x => return y0 + (y - y0) * (n_rpm - x0) / (x - x0),
            _ => prev = Some((x, y)),
        }
    }
    prev.map_or(1.0, |(_, y)| y)
}

/// Eq. 7 on the truth: the drum speed (r/min) at which the belt drops one
/// partition per `spacing_m` of ground at `ground_m_s`. Equal frequency
/// (eq. 4): belt speed = ground speed · Lclap / Lplant; belt speed =
/// k3·π·(D2 + 2·H2)·n/60 (eq. 6). k3 depends on n: three fixed-point
/// iterations converge (the table is nearly flat).
#[must_use]
pub fn eq7_drum_speed(ground_m_s: f64, spacing_m: f64) -> f64 {
    let belt = ground_m_s * kinematics::consts::L_CLAP_F64 / spacing_m;
    let per_rpm = core::f64::consts::PI * kinematics::consts::DRUM_EFFECTIVE_DIAMETER_F64 / 60.0;
    let mut n = belt / per_rpm;
    for _ in 0..3 {
        n = belt / (k3_at(n) * per_rpm);
    }
    n
}

/// ISO 7256-1 indices of the spacings within each pass (consecutive
/// positions of one pass, m; a lift between passes is no spacing), in
/// percent: `[multiples (s ≤ 0.5 X), misses (s > 1.5 X), quality of feed
/// (the rest), precision (sample SD / mean of the quality-of-feed
/// spacings), share within ±10 % of X]`, as the streaming
/// [`SpacingAccumulator`](crate::SpacingAccumulator) defines them — the
/// drops' side of the firmware's live figures in the work-switch tests.
#[must_use]
#[allow(clippy::float_arithmetic, clippy::cast_precision_loss)]
pub fn iso_indices(passes: &[std::vec::Vec<f64>], x: f64) -> [f64; 5] {
    let s: std::vec::Vec<f64> = passes
        .iter()
        .flat_map(|p| p.iter().zip(p.iter().skip(1)).map(|(a, b)| b - a))
        .collect();
    let n = s.len() as f64;
    let share = |f: &dyn Fn(f64) -> bool| 100.0 * s.iter().filter(|&&v| f(v)).count() as f64 / n;
    let single = |v: f64| v > 0.5 * x && v <= 1.5 * x;
    let singles: std::vec::Vec<f64> = s.iter().copied().filter(|&v| single(v)).collect();
    let k = singles.len() as f64;
    let mean = singles.iter().sum::<f64>() / k;
    let sd = (singles.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
    [
        share(&|v| v <= 0.5 * x),
        share(&|v| v > 1.5 * x),
        share(&single),
        100.0 * sd / mean,
        share(&|v| (v - x).abs() <= 0.1 * x),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq7_by_hand() {
        // 0.1395 m/s at 7 cm: belt 0.099643 m/s; π·0.070/60 = 0.0036652 m/s
        // per r/min → 27.186 r/min before slip; k3 at 27 r/min = 0.980
        // (clamped) → 27.741 r/min.
        assert!((eq7_drum_speed(0.1395, 0.07) - 27.741).abs() < 0.002);
        // Table 13 interpolation: 12.5 r/min halfway 0.982 … 0.986.
        assert!((k3_at(12.5) - 0.984).abs() < 1e-6);
    }
}
