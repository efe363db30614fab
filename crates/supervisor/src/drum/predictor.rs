//! The travel speed between Hall edges: the last estimate extrapolated
//! along its slope.

use kinematics::speed::{MotionState, TravelMeasurement};
use kinematics::units::{RevPerMin, Ticks};

/// Bridges the Hall sensor's sparse updates (one edge every 170 ms at Low 2)
/// by extrapolating the gear speed along its last slope.
///
/// The M/T estimate describes the middle of its window, which by the next
/// control period is already half a tooth period (plus the time since the
/// edge) old; while the tractor accelerates the drum would lag by that age
/// times the acceleration. The slope between the last two estimates, applied
/// over the estimate's age, removes most of that lag. The correction is
/// bounded (±10 % of the estimate, and never beyond two tooth periods of
/// age) so that one bad edge cannot run away; at standstill or after a
/// restart it is zero.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Predictor {
    /// Last estimate (U12F20 bits) and the time its window's middle
    /// represents (ticks).
    pub(super) last: Option<(i64, u32)>,
    /// Slope: change of the estimate (bits) over that many ticks.
    pub(super) slope: (i64, i64),
    /// Mean tooth period of the last window, ticks.
    pub(super) period: u32,
    /// The last window's gaps read noisy
    /// ([`kinematics::speed::TravelMeasurement::noisy`]).
    pub(super) noisy: bool,
}

impl Predictor {
    /// The last two windows show the tractor slowing down: the newer one
    /// more than 10 % below the one before (the terrain's own changes stay
    /// within a few percent a gap; a chassis coming to rest with τ 0.5 s
    /// loses 30–45 % a gap at Low 1–2). A late edge is then expected.
    pub(super) fn slowing(&self) -> bool {
        let Some((v, _)) = self.last else {
            return false;
        };
        let (dv, _) = self.slope;
        dv < 0 && dv.saturating_mul(-10) > v
    }

    pub(super) fn predict(&mut self, m: &TravelMeasurement, now: Ticks) -> RevPerMin {
        match m.state {
            MotionState::Measured if m.edges > 0 => {
                // A fresh window: its middle is `since_edge + window/2` ago.
                let v = i64::from(m.gear_speed.to_bits());
                let center = now
                    .0
                    .wrapping_sub(m.since_edge_ticks)
                    .wrapping_sub(m.window_ticks / 2);
                if let Some((v0, t0)) = self.last {
                    let dt = i64::from(center.wrapping_sub(t0));
                    // A change beyond what unlearnt teeth make (each gap
                    // ±4 %: two differ by at most 8 %; a start from rest
                    // changes by tens of %) is the speed's.
                    let b0 = u32::try_from(v0).unwrap_or(0);
                    let real = m.gear_speed.to_bits().abs_diff(b0) > b0 / 25;
                    // The slope only between two windows whose teeth are
                    // learnt, or for a real change: otherwise it is the
                    // tooth errors', which the extrapolation multiplied.
                    let clean = !m.noisy && !self.noisy;
                    let (trend, trend_ticks) = m.trend;
                    self.slope = if dt > 0 && (clean || real) {
                        (v.saturating_sub(v0), dt)
                    } else if trend_ticks > 0 && dt > 0 {
                        // The speed changes beyond what the teeth make (the
                        // estimator's change between two adjacent runs of
                        // gaps): the slope between the windows, kept to the
                        // trend's sign and at most its size (the trend
                        // describes the runs' middles, further back).
                        let (dv, tt) = (v.saturating_sub(v0), i64::from(trend_ticks));
                        let trend = i64::from(trend);
                        if dv.signum() != trend.signum() {
                            (0, 1)
                        } else if dv.saturating_mul(tt).abs() <= trend.saturating_mul(dt).abs() {
                            (dv, dt)
                        } else {
                            (trend, tt)
                        }
                    } else if !m.noisy && self.noisy {
                        // The first window after the teeth were learnt:
                        // the last slope goes on.
                        self.slope
                    } else {
                        (0, 1)
                    };
                }
                self.noisy = m.noisy;
                self.last = Some((v, center));
                self.period = m.window_ticks.checked_div(m.edges).unwrap_or(0);
            }
            MotionState::Measured | MotionState::Holding | MotionState::Decaying => {}
            MotionState::Stopped | MotionState::Starting => {
                *self = Self::default();
                return m.gear_speed;
            }
        }
        let Some((v, center)) = self.last else {
            return m.gear_speed;
        };
        let age =
            i64::from(now.0.wrapping_sub(center)).min(i64::from(self.period).saturating_mul(2));
        let (dv, dt) = self.slope;
        // `max`/`min` rather than `clamp`: the bounds are not constant, and
        // `clamp` would carry a (never taken) panic with formatted values.
        let bound = v.checked_div(10).unwrap_or(0).max(0);
        let step = dv
            .saturating_mul(age)
            .checked_div(dt)
            .unwrap_or(0)
            .max(bound.saturating_neg())
            .min(bound);
        let bits = v.saturating_add(step).clamp(0, i64::from(u32::MAX));
        let predicted = RevPerMin::from_bits(u32::try_from(bits).unwrap_or(0));
        if m.state == MotionState::Decaying {
            // Overdue edge: the estimator's bound (one gap over the elapsed
            // time) caps the estimate; it is no estimate of its own (above
            // a smoothed value it would raise it).
            predicted.min(m.gear_speed)
        } else {
            predicted
        }
    }
}
