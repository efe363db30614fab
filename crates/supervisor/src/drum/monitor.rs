//! The instability supervisor: the drum's tracking error against the
//! reference model.

use fuzzy_pid::I16F16;

use super::fix::smooth;

/// Instability supervisor: the tracking error (measurement against the
/// reference model) smoothed over 0.25 s beyond 5 % of the target for more
/// than 1 s, or the unsmoothed error swinging by more than 25 % of the
/// target within each of two consecutive 0.5 s windows.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Monitor {
    /// Smoothed tracking error, r/min.
    error: I16F16,
    /// Time the smoothed error has been beyond the band, µs.
    beyond_us: u32,
    /// Extremes of the error in the current window, and its length.
    low: I16F16,
    high: I16F16,
    periods: u8,
    /// Consecutive windows with a swing beyond the limit.
    swinging: u8,
}

/// Smoothing of the monitored tracking error: `1 − e^(−10 ms / 0.25 s)`. The
/// seedlings' load (up to ±5 % at 1.5–3 Hz) is damped to about a third, so
/// it does not count as a tracking error.
pub(super) const MONITOR_ALPHA: I16F16 = I16F16::lit("0.0392");
/// The slowest target the instability supervisor judges: 3 r/min. Below it
/// the driver's dead band (3 % duty, 1.3 r/min on the design drive) and the
/// encoder's resolution (one count per 10 ms is 0.13 r/min) make 5 % of the
/// target meaningless; a tractor coming to rest passes there (test
/// `no_false_instability_warning_in_the_field_at_every_gear`: at High 1 the
/// drum sat at 1.5 r/min under a 1.15 r/min target for more than 1 s).
pub(super) const MONITOR_MIN_TARGET: I16F16 = I16F16::lit("3");
/// Band of the smoothed tracking error: 5 % of the target.
pub(super) const MONITOR_BAND: I16F16 = I16F16::lit("0.05");
/// Time beyond the band that is an instability, µs.
pub(super) const MONITOR_TIME_US: u32 = 1_000_000;
/// Swing (max − min) of the error in a window that counts as an
/// oscillation: 25 % of the target. The seedlings' load swings the speed by
/// up to 10 %; the limit cycle of a 20 ms drive on the 5 ms tuning by
/// 80 %.
pub(super) const MONITOR_SWING: I16F16 = I16F16::lit("0.25");
/// Window of the swing, periods (0.5 s at 10 ms), and how many windows in a
/// row make an oscillation (1 s).
pub(super) const MONITOR_WINDOW: u8 = 50;
pub(super) const MONITOR_WINDOWS: u8 = 2;

impl Monitor {
    /// One running period; `true` when the drum is unstable. `saturated`:
    /// the last output was 0 or 100 % duty — a drum that cannot follow
    /// (a target at `n_max` under load: the Too fast warning's business) is
    /// not a tracking error of the loop.
    pub(super) fn step(
        &mut self,
        expected: I16F16,
        measured: I16F16,
        target: I16F16,
        elapsed_us: u32,
        saturated: bool,
    ) -> bool {
        if target < MONITOR_MIN_TARGET {
            *self = Self::default();
            return false;
        }
        let dev = expected.saturating_sub(measured);
        self.error = smooth(self.error, dev, MONITOR_ALPHA);
        if !saturated && self.error.saturating_abs() > target.saturating_mul(MONITOR_BAND) {
            self.beyond_us = self.beyond_us.saturating_add(elapsed_us);
        } else {
            self.beyond_us = 0;
        }
        if self.periods == 0 {
            self.low = dev;
            self.high = dev;
        }
        self.low = self.low.min(dev);
        self.high = self.high.max(dev);
        self.periods = self.periods.saturating_add(1);
        if self.periods >= MONITOR_WINDOW {
            if self.high.saturating_sub(self.low) > target.saturating_mul(MONITOR_SWING) {
                self.swinging = self.swinging.saturating_add(1);
            } else {
                self.swinging = 0;
            }
            self.periods = 0;
        }
        self.beyond_us > MONITOR_TIME_US || self.swinging >= MONITOR_WINDOWS
    }
}
