//! The controller's stop input: a normally closed contact to ground, pulled
//! up, so that an open contact, a broken wire or an unplugged connector all
//! read as *stop* (fail-safe).
//!
//! The hardware side (board layer) switches the outputs off in the pin's
//! interrupt, within microseconds of the edge, and calls [`StopLatch::trip`];
//! this type holds what follows, for both machines:
//!
//! - **Open** is taken at once, without debouncing: stopping is always the
//!   safe direction, and a bounce only repeats it.
//! - The stop is **latched**: the machine stays stopped, with the alarm, until
//!   the contact has read closed for [`CLOSED_DEBOUNCE_US`] *and* the
//!   operator presses Start ([`StopLatch::start`]). Closing the contact alone
//!   never restarts anything.
//! - At power-on the contact is unproven: it must read closed for the
//!   debounce time before Start is accepted (a machine switched on with the
//!   stop pressed, or with the wire cut, does not start).
//!
//! ```
//! use supervisor::stop_input::{StopLatch, StopChange, CLOSED_DEBOUNCE_US};
//!
//! let mut stop = StopLatch::new();
//! // Power-on with the contact closed: 20 ms of 10 ms periods prove it.
//! assert_eq!(stop.sample(false, 10_000), None);
//! assert!(stop.start().is_err());
//! assert_eq!(stop.sample(false, 10_000), None);
//! assert!(stop.start().is_ok());
//! // The contact opens (the interrupt tripped the latch): latched at once.
//! stop.trip();
//! assert_eq!(stop.sample(true, 10_000), Some(StopChange::Opened));
//! assert!(stop.is_latched());
//! // Closed again: still latched until Start, and Start waits for the
//! // debounce time.
//! assert_eq!(stop.sample(false, 10_000), None);
//! assert!(stop.start().is_err());
//! assert_eq!(stop.sample(false, CLOSED_DEBOUNCE_US), Some(StopChange::Closed));
//! assert!(stop.is_latched());
//! assert!(stop.start().is_ok());
//! assert!(!stop.is_latched());
//! ```

/// How long the contact must read closed before Start is accepted, µs. A
/// mushroom-head stop switch bounces for 1–10 ms; 20 ms covers it twice.
pub const CLOSED_DEBOUNCE_US: u32 = 20_000;

/// What changed at a [`StopLatch::sample`], for the log and the screen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StopChange {
    /// The contact opened (or was seen open by the interrupt): outputs off,
    /// alarm latched.
    Opened,
    /// The contact has read closed for the debounce time: Start is possible.
    Closed,
}

/// Why Start is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StopInputError {
    /// The stop contact is open (or was closed for less than the debounce
    /// time).
    Open,
}

impl StopInputError {
    /// The screen's text (ASCII, at most 40 characters).
    pub const fn message(self) -> &'static str {
        match self {
            Self::Open => "Stop input open: close it, then Start",
        }
    }
}

impl core::fmt::Display for StopInputError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.message())
    }
}

/// The stop input's state (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StopLatch {
    /// The machine must stay stopped (set on open, cleared by Start).
    latched: bool,
    /// The contact has read closed for the debounce time.
    closed: bool,
    /// How long it has read closed, µs (saturating).
    closed_for_us: u32,
    /// The interrupt saw it open since the last sample.
    tripped: bool,
    /// An opening not yet reported by [`sample`](Self::sample).
    unreported: bool,
}

impl Default for StopLatch {
    fn default() -> Self {
        Self::new()
    }
}

impl StopLatch {
    /// At power-on: not latched (no alarm), but the contact is unproven, so
    /// Start waits until it has read closed for [`CLOSED_DEBOUNCE_US`].
    pub const fn new() -> Self {
        Self {
            latched: false,
            closed: false,
            closed_for_us: 0,
            tripped: false,
            unreported: false,
        }
    }

    /// The interrupt saw the contact open (it has switched the outputs off).
    pub fn trip(&mut self) {
        self.tripped = true;
    }

    /// One look at the contact (`open`: the pin reads high), `elapsed_us`
    /// after the previous one.
    pub fn sample(&mut self, open: bool, elapsed_us: u32) -> Option<StopChange> {
        if open || core::mem::take(&mut self.tripped) {
            self.closed_for_us = 0;
            self.closed = false;
            if !self.latched {
                self.latched = true;
                self.unreported = true;
            }
        } else {
            self.closed_for_us = self.closed_for_us.saturating_add(elapsed_us);
            if !self.closed && self.closed_for_us >= CLOSED_DEBOUNCE_US {
                self.closed = true;
                if self.latched {
                    return Some(StopChange::Closed);
                }
            }
        }
        core::mem::take(&mut self.unreported).then_some(StopChange::Opened)
    }

    /// The machine must be stopped and its outputs off.
    pub fn is_latched(&self) -> bool {
        self.latched || self.tripped
    }

    /// The contact is proven closed.
    pub fn is_closed(&self) -> bool {
        self.closed && !self.tripped
    }

    /// The operator pressed Start: allowed (and the latch released) only
    /// with the contact proven closed.
    pub fn start(&mut self) -> Result<(), StopInputError> {
        if self.is_closed() {
            self.latched = false;
            Ok(())
        } else {
            Err(StopInputError::Open)
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::arithmetic_side_effects)]
    use super::*;

    /// A bouncing contact: any open sample, even one among closed ones,
    /// latches; the debounce restarts at each bounce.
    #[test]
    fn a_bounce_restarts_the_debounce_and_never_releases_the_latch() {
        let mut s = StopLatch::new();
        for _ in 0..3 {
            s.sample(false, 10_000);
        }
        assert!(s.start().is_ok());
        assert_eq!(s.sample(true, 10_000), Some(StopChange::Opened));
        // Bouncing closed/open every 10 ms for 100 ms: never closed.
        for i in 0..10 {
            assert_eq!(s.sample(i % 2 == 1, 10_000), None);
            assert!(s.start().is_err(), "bounce {i}");
            assert!(s.is_latched());
        }
        // Closed for 10 ms: not yet; 20 ms: yes (CLOSED_DEBOUNCE_US).
        s.sample(false, 10_000);
        assert!(s.start().is_err());
        assert_eq!(s.sample(false, 10_000), Some(StopChange::Closed));
        assert!(s.is_latched(), "closing alone restarts nothing");
        assert!(s.start().is_ok());
        assert!(!s.is_latched());
    }

    /// An opening seen only by the interrupt (shorter than a sample period)
    /// still latches.
    #[test]
    fn a_short_opening_seen_only_by_the_interrupt_latches() {
        let mut s = StopLatch::new();
        s.sample(false, 30_000);
        assert!(s.start().is_ok());
        s.trip();
        assert!(s.is_latched(), "latched from the interrupt on");
        assert!(
            s.start().is_err(),
            "no Start between the trip and the sample"
        );
        assert_eq!(s.sample(false, 10_000), Some(StopChange::Opened));
        assert!(s.is_latched());
    }

    /// Power-on with the wire cut: Start refused, no matter how long.
    #[test]
    fn power_on_with_the_contact_open_never_starts() {
        let mut s = StopLatch::new();
        assert_eq!(s.sample(true, 10_000), Some(StopChange::Opened));
        for _ in 0..1000 {
            assert_eq!(s.sample(true, 10_000), None);
            assert_eq!(s.start(), Err(StopInputError::Open));
        }
    }
}
