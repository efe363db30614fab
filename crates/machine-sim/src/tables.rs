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

/// `(wheel speed km/h, slip 1 − k2)` per gear, built at compile time from
/// the shared presets (Table 11 speeds, Table 12 k2), slowest first.
pub const TRACK_SLIP_TABLE: [(f32, f32); 6] = [
    slip_point(Gear::Low1),
    slip_point(Gear::Low2),
    slip_point(Gear::Low3),
    slip_point(Gear::High1),
    slip_point(Gear::High2),
    slip_point(Gear::High3),
];

const fn slip_point(g: Gear) -> (f32, f32) {
    let p = g.preset();
    (p.actual_kmh_f64 as f32, (1.0 - p.k2_f64) as f32)
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
/// over the gears' Table 11 speeds, piecewise linear, clamped at the ends.
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
        // Low 1 at 0.33 km/h: k2 = 0.972 → s = 2.8 %; High 3 at 3.65 km/h: 5.9 %.
        assert!((track_slip_at(0.33) - 0.028).abs() < 1e-6);
        assert!((track_slip_at(3.65) - 0.059).abs() < 1e-6);
        // Between Low 1 (0.33, 0.028) and Low 2 (0.52, 0.034): at 0.425 → 0.031.
        assert!((track_slip_at(0.425) - 0.031).abs() < 1e-6);
        assert!((track_slip_at(0.0) - 0.028).abs() < 1e-6);
    }
}
