//! Encoder against driver read-back: which one is wrong.
//!
//! With both feedbacks fitted, the drum encoder's speed and the driver's
//! read-back must agree within [`MARGIN_PERMILLE`] of the larger (at least
//! [`MARGIN_FLOOR_MILLI_RPM`]) — the read-back is 20–50 ms older, and at the
//! drum's steepest set-point ramp the speed moves by less than the margin in
//! that time. Disagreeing for longer than [`HOLD_US`] raises "encoder or
//! driver speed wrong". This is what tells a stalled drum (both near zero:
//! the stall alarm) from a lost encoder (encoder zero, driver turning).
//!
//! ```
//! use drive_link::cross_check::CrossCheck;
//! let mut c = CrossCheck::new();
//! // Encoder 0 (wire cut), driver 20 r/min, checked every 10 ms: the
//! // alarm once the disagreement has lasted 500 ms (the 50th check).
//! for _ in 0..49 {
//!     assert!(!c.update(10_000, 0, 20_000));
//! }
//! assert!(c.update(10_000, 0, 20_000));
//! // 20.0 against 19.0 r/min (5 %) agrees.
//! let mut ok = CrossCheck::new();
//! assert!(!ok.update(10_000, 20_000, 19_000) && !ok.update(1_000_000, 20_000, 19_000));
//! ```

/// Relative margin, ‰ of the larger speed.
pub const MARGIN_PERMILLE: i64 = 100;
/// Absolute floor of the margin, milli-r/min (near rest).
pub const MARGIN_FLOOR_MILLI_RPM: i64 = 1_000;
/// How long a disagreement must last, µs.
pub const HOLD_US: u64 = 500_000;

/// The cross-check's state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CrossCheck {
    /// How long the two have disagreed, µs (saturating).
    disagree_us: u32,
}

impl CrossCheck {
    /// No disagreement seen.
    #[must_use]
    pub const fn new() -> Self {
        Self { disagree_us: 0 }
    }

    /// One comparison, `elapsed_us` after the last; true when the
    /// disagreement has lasted [`HOLD_US`] (counted from the first
    /// comparison that disagreed, which counts its own period).
    pub fn update(
        &mut self,
        elapsed_us: u32,
        encoder_milli_rpm: i32,
        driver_milli_rpm: i32,
    ) -> bool {
        let e = i64::from(encoder_milli_rpm);
        let d = i64::from(driver_milli_rpm);
        let larger = e.abs().max(d.abs());
        let margin = (larger.saturating_mul(MARGIN_PERMILLE) / 1000).max(MARGIN_FLOOR_MILLI_RPM);
        if e.abs_diff(d) <= margin.unsigned_abs() {
            self.disagree_us = 0;
            return false;
        }
        self.disagree_us = self.disagree_us.saturating_add(elapsed_us);
        u64::from(self.disagree_us) >= HOLD_US
    }
}
