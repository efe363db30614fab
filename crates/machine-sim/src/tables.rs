//! Paper A's measured slip data as piecewise-linear curves (SPEC §4).
//!
//! The gear speeds and k2 values come from [`kinematics::consts::GEAR_PRESETS`]
//! (shared, not repeated); the k3 belt table (SPEC Table 13) is not a machine
//! constant of the kinematics crate, so it lives here as the simulator's data.

use kinematics::consts::Gear;

/// SPEC Table 13: set drum speed (r/min) → measured belt coefficient k3.
pub const K3_TABLE: [(f32, f32); 5] = [
    (5.0, 0.993),
    (10.0, 0.982),
    (15.0, 0.986),
    (20.0, 0.994),
    (25.0, 0.980),
];

/// Piecewise-linear interpolation over `(x, y)` points sorted by `x`,
/// clamped to the end values outside the table.
pub(crate) fn interp(points: impl Iterator<Item = (f32, f32)> + Clone, x: f32) -> f32 {
    let mut prev: Option<(f32, f32)> = None;
    for (px, py) in points {
        match prev {
            None if x <= px => return py,
            Some((qx, qy)) if x <= px => {
                let span = px - qx;
                return if span > 0.0 {
                    qy + (py - qy) * (x - qx) / span
                } else {
                    py
                };
            }
            _ => {}
        }
        prev = Some((px, py));
    }
    prev.map_or(0.0, |(_, y)| y)
}

/// Belt coefficient k3 at drum speed `n_rpm` (Table 13, clamped at the ends).
#[must_use]
pub fn k3_at(n_rpm: f32) -> f32 {
    interp(K3_TABLE.iter().copied(), n_rpm)
}

/// Paper A Table 12's measured runs: (theoretical distance m, time s) per
/// gear, slowest first. The wheel (track rolling) speed of each run is
/// their quotient: the speed the track slip `1 − k2` was measured at
/// (SPEC §4; Low 1: 411.61 m in 4645.16 s = 0.3190 km/h).
pub const TABLE_12_RUNS: [(f64, f64); 6] = [
    (411.61, 4645.16),
    (413.92, 2823.53),
    (415.33, 1734.94),
    (418.62, 1058.82),
    (420.16, 663.59),
    (425.16, 402.23),
];

/// `(wheel speed km/h, slip 1 − k2)` per gear: Table 12's k2 at the wheel
/// speed of its own run ([`TABLE_12_RUNS`]), slowest first: where the paper
/// measured it, and where the firmware's default k2 table puts it, so that a
/// noiseless machine and the default calibration agree (Table 11's ground
/// speeds, 0.33 … 3.65 km/h, are not the wheel's).
pub const TRACK_SLIP_TABLE: [(f32, f32); 6] = [
    slip_point(0, Gear::Low1),
    slip_point(1, Gear::Low2),
    slip_point(2, Gear::Low3),
    slip_point(3, Gear::High1),
    slip_point(4, Gear::High2),
    slip_point(5, Gear::High3),
];

#[allow(clippy::indexing_slicing)]
const fn slip_point(run: usize, g: Gear) -> (f32, f32) {
    let (distance_m, time_s) = TABLE_12_RUNS[run];
    (
        (distance_m / time_s * 3.6) as f32,
        (1.0 - g.preset().k2_f64) as f32,
    )
}

/// `(wheel speed km/h, k1)` per gear (Table 11: actual speed, k1 =
/// actual / monitored), slowest first.
pub const K1_TABLE: [(f32, f32); 6] = [
    k1_point(Gear::Low1),
    k1_point(Gear::Low2),
    k1_point(Gear::Low3),
    k1_point(Gear::High1),
    k1_point(Gear::High2),
    k1_point(Gear::High3),
];

const fn k1_point(g: Gear) -> (f32, f32) {
    let p = g.preset();
    (p.actual_kmh_f64 as f32, p.k1_f64 as f32)
}

/// Paper A's speed-measurement coefficient k1 at wheel speed `v_kmh`
/// (Table 11, piecewise linear, clamped at the ends): the Hall gear reads
/// `v / k1`.
#[must_use]
pub fn k1_at(v_kmh: f32) -> f32 {
    interp(K1_TABLE.iter().copied(), v_kmh)
}

/// Track slip `s = 1 − k2` at wheel (track rolling) speed `v_kmh`: Table 12
/// over its runs' wheel speeds, piecewise linear, clamped at the ends.
#[must_use]
pub fn track_slip_at(v_kmh: f32) -> f32 {
    interp(TRACK_SLIP_TABLE.iter().copied(), v_kmh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn k3_curve_hits_the_table_and_interpolates() {
        // Table 13 points, and 12.5 r/min halfway between 0.982 and 0.986 = 0.984.
        assert!((k3_at(5.0) - 0.993).abs() < 1e-6);
        assert!((k3_at(12.5) - 0.984).abs() < 1e-6);
        assert!((k3_at(1.0) - 0.993).abs() < 1e-6, "clamped low");
        assert!((k3_at(44.7) - 0.980).abs() < 1e-6, "clamped high");
    }

    #[test]
    fn track_slip_follows_table_12() {
        // Table 12's wheel speeds, by hand: Low 1 411.61 m / 4645.16 s ·
        // 3.6 = 0.31900 km/h with k2 = 0.972 (s = 2.8 %); High 3 425.16 m /
        // 402.23 s · 3.6 = 3.80523 km/h with 0.941 (5.9 %).
        assert!((track_slip_at(0.319_00) - 0.028).abs() < 1e-6);
        assert!((track_slip_at(3.805_23) - 0.059).abs() < 1e-6);
        // Between Low 1 (0.31900, 0.028) and Low 2 (413.92 / 2823.53 · 3.6 =
        // 0.52775, 0.034): half-way, 0.423375 km/h → 0.031.
        assert!((track_slip_at(0.423_375) - 0.031).abs() < 1e-5);
        assert!((track_slip_at(0.0) - 0.028).abs() < 1e-6);
        assert!((track_slip_at(5.0) - 0.059).abs() < 1e-6);
    }
}
