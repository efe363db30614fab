//! A ground wheel's quadrature encoder read once a control period: the
//! distance it rolled and its speed.
//!
//! The encoder timer counts both edges of both channels (four counts a
//! pulse) and is read once a period; the odometer takes the counter's
//! difference (it wraps at 2¹⁶, so a period may hold up to ±32 767 counts:
//! 10 m at the product wheel's 3056 counts/m, far beyond any travel speed).
//!
//! **Distance.** Every forward count is a known length, `1 / counts per
//! metre`; the odometer hands the distance of each period to its caller in
//! nm with the division's remainder carried, so a row's distance is exact to
//! the count whatever its length.
//!
//! **Speed.** The counts of the newest periods over their time: the
//! shortest window of at least [`MIN_WINDOW_PERIODS`] periods holding at
//! least [`MIN_WINDOW_COUNTS`] counts, at most [`WINDOW_PERIODS`]. At the
//! product wheel and Low 1 (0.31 km/h, 2.6 counts a period) that is 25
//! periods, at 1 km/h 10; the window's count is known to ±1, so the speed to
//! ±1.6 % at the slowest gear and ±0.6 % at 1 km/h. A window without a
//! count reads 0: the wheel stands (or has lost the ground).

/// Periods the speed window holds at most.
pub const WINDOW_PERIODS: usize = 32;
/// Periods the speed window holds at least.
pub const MIN_WINDOW_PERIODS: usize = 5;
/// Counts the speed window should hold (it grows up to
/// [`WINDOW_PERIODS`] to reach them).
pub const MIN_WINDOW_COUNTS: u32 = 24;

/// One period's reading of the wheel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WheelStep {
    /// Counts forward in the period (0 when it counted backwards).
    pub forward: u32,
    /// Counts backwards in the period (0 when it counted forward).
    pub backward: u32,
    /// Ground distance of the forward counts, nm.
    pub distance_nm: u64,
}

/// The odometer (module docs).
#[derive(Clone, Copy, Debug)]
pub struct WheelOdometer {
    last: Option<u16>,
    /// Signed counts since boot (after the direction setting).
    total: i64,
    /// Forward counts per period, newest at `head`.
    window: [u16; WINDOW_PERIODS],
    head: usize,
    filled: usize,
    /// The division's remainder of the distance (count × 10¹² mod counts
    /// per metre × 1000).
    rem: u64,
    /// Periods since the last forward count (saturating).
    silent: u32,
}

impl Default for WheelOdometer {
    fn default() -> Self {
        Self::new()
    }
}

impl WheelOdometer {
    /// An odometer that has not read the counter yet.
    pub const fn new() -> Self {
        Self {
            last: None,
            total: 0,
            window: [0; WINDOW_PERIODS],
            head: 0,
            filled: 0,
            rem: 0,
            silent: u32::MAX,
        }
    }

    /// Reads the counter once a period. `reversed`: the counts run backwards
    /// when the machine moves forward (the wheel's direction setting).
    /// `counts_per_m_x1000` is the wheel's calibration (> 0). The first
    /// reading only sets the reference.
    pub fn update(&mut self, counter: u16, reversed: bool, counts_per_m_x1000: u32) -> WheelStep {
        let Some(prev) = self.last.replace(counter) else {
            // The reference: silence counts from here.
            self.silent = 0;
            return WheelStep::default();
        };
        let raw = counter.wrapping_sub(prev).cast_signed();
        let d = if reversed {
            i32::from(raw).wrapping_neg()
        } else {
            i32::from(raw)
        };
        self.total = self.total.saturating_add(i64::from(d));
        let forward = u32::try_from(d).unwrap_or(0);
        let backward = u32::try_from(d.wrapping_neg()).unwrap_or(0);
        self.head = self.head.wrapping_add(1) % WINDOW_PERIODS;
        if let Some(slot) = self.window.get_mut(self.head) {
            *slot = u16::try_from(forward).unwrap_or(u16::MAX);
        }
        self.filled = self.filled.saturating_add(1).min(WINDOW_PERIODS);
        self.silent = if forward > 0 {
            0
        } else {
            self.silent.saturating_add(1)
        };
        // forward ≤ 32 768: × 10¹² < 2⁵⁵; + rem (< 2²⁵) fits.
        let num = u64::from(forward)
            .wrapping_mul(1_000_000_000_000)
            .wrapping_add(self.rem);
        let den = u64::from(counts_per_m_x1000.max(1));
        self.rem = num.checked_rem(den).unwrap_or(0);
        WheelStep {
            forward,
            backward,
            distance_nm: num.checked_div(den).unwrap_or(0),
        }
    }

    /// Signed counts since boot, after the direction setting.
    pub const fn total_counts(&self) -> i64 {
        self.total
    }

    /// Periods since the last forward count (`u32::MAX` before any).
    pub const fn silent_periods(&self) -> u32 {
        self.silent
    }

    /// The speed over the window (module docs) in m/s as `MetresPerSecond`
    /// bits (U8F24), for periods of `period_us`.
    pub fn speed_bits(&self, period_us: u32, counts_per_m_x1000: u32) -> u32 {
        let mut sum = 0u32;
        let mut n = 0usize;
        for back in 0..self.filled {
            let i = self.head.wrapping_add(WINDOW_PERIODS).wrapping_sub(back) % WINDOW_PERIODS;
            sum = sum.saturating_add(u32::from(self.window.get(i).copied().unwrap_or(0)));
            n = back.saturating_add(1);
            if n >= MIN_WINDOW_PERIODS && sum >= MIN_WINDOW_COUNTS {
                break;
            }
        }
        // µm rolled in the window: sum < 2²¹, × 10⁹ < 2⁵¹.
        let um = u64::from(sum)
            .saturating_mul(1_000_000_000)
            .checked_div(u64::from(counts_per_m_x1000))
            .unwrap_or(0);
        // µm / µs = m/s; × 2²⁴ for U8F24 (um < 2³⁵ at 100 counts/m: < 2⁵⁹).
        let us = (n as u64).saturating_mul(u64::from(period_us));
        (um << 24)
            .checked_div(us)
            .map_or(0, |v| u32::try_from(v).unwrap_or(u32::MAX))
    }
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::arithmetic_side_effects
)]
mod tests {
    extern crate std;
    use super::*;

    const CPM: u32 = 3_055_775;

    /// A wheel rolled at `v` m/s for `periods` periods of 10 ms, the counter
    /// starting at `start` (to cross the wrap); the distance against the f64
    /// model `counts / counts-per-metre` and the speed against `v`.
    fn roll(v: f64, periods: u32, start: u16, reversed: bool) -> (WheelOdometer, u64, f64) {
        let mut o = WheelOdometer::new();
        let mut nm = 0u64;
        let cpm = f64::from(CPM) / 1000.0;
        o.update(start, reversed, CPM);
        let mut prev = 0i64;
        for k in 1..=periods {
            let counts = (v * 0.01 * f64::from(k) * cpm).floor() as i64;
            let c = if reversed { -counts } else { counts };
            let counter = (i64::from(start) + c).rem_euclid(65_536) as u16;
            let s = o.update(counter, reversed, CPM);
            assert_eq!(i64::from(s.forward), counts - prev);
            prev = counts;
            nm += s.distance_nm;
        }
        (o, nm, prev as f64 / cpm)
    }

    #[test]
    fn distance_is_counts_over_counts_per_metre_exactly_across_the_wrap() {
        for &(v, start, reversed) in &[(0.086, 0u16, false), (0.5, 65_000, false), (1.2, 100, true)]
        {
            let (o, nm, model_m) = roll(v, 30_000, start, reversed);
            // Exact to the nanometre (the remainder carried), 300 s of travel.
            assert!(
                (nm as f64 / 1e9 - model_m).abs() < 1e-9,
                "{v}: {nm} vs {model_m}"
            );
            assert!(o.total_counts() > 0);
        }
    }

    #[test]
    fn speed_is_within_the_windows_count_resolution() {
        for &v in &[0.086f64, 0.14, 0.3, 1.0, 2.0] {
            let (o, _, _) = roll(v, 200, 12_345, false);
            let got = f64::from(o.speed_bits(10_000, CPM)) / f64::from(1u32 << 24);
            // ±1 count over the window's counts (≥ 64, or 32 periods).
            let counts_in_window = (v * 0.01 * f64::from(CPM) / 1000.0 * 32.0)
                .min((MIN_WINDOW_COUNTS as f64).max(v * 0.01 * f64::from(CPM) / 1000.0 * 10.0));
            let tol = v * 1.5 / counts_in_window.max(1.0);
            assert!((got - v).abs() <= tol, "v {v}: got {got}, tol {tol}");
        }
    }

    #[test]
    fn backwards_counts_are_not_distance_and_a_still_wheel_reads_zero() {
        let mut o = WheelOdometer::new();
        o.update(1000, false, CPM);
        let s = o.update(990, false, CPM);
        assert_eq!((s.forward, s.backward, s.distance_nm), (0, 10, 0));
        assert_eq!(o.total_counts(), -10);
        // Reversed setting: the same counts are forward.
        let mut r = WheelOdometer::new();
        r.update(1000, true, CPM);
        let s = r.update(990, true, CPM);
        assert_eq!((s.forward, s.backward), (10, 0));
        for _ in 0..WINDOW_PERIODS {
            r.update(990, true, CPM);
        }
        assert_eq!(r.speed_bits(10_000, CPM), 0);
        assert_eq!(r.silent_periods(), WINDOW_PERIODS as u32);
    }
}
