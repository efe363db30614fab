//! The work switch: a contact that says the planting unit is down (in the
//! ground, planting) or up (lifted at the headland, on the road).
//!
//! Wiring (both machines, real board PB11, a 5 V tolerant pin): a contact
//! to ground that **closes when the unit is down**, with the pin's internal
//! pull-up. So a closed contact reads low = down, and an open contact, a
//! broken wire or an unplugged connector read high = **up**: the safe side,
//! the drum rests instead of planting into the air.
//!
//! The contact is sampled by the control task every period (it is not an
//! emergency input: no interrupt) and debounced here in both directions: a
//! new level is taken only after it has read the same for
//! [`WORK_SWITCH_DEBOUNCE_US`]. At power-on the switch reads up until the
//! contact has proven closed.
//!
//! ```
//! use supervisor::work_switch::{WorkChange, WorkSwitch, WORK_SWITCH_DEBOUNCE_US};
//!
//! let mut ws = WorkSwitch::new();
//! assert!(!ws.is_down());
//! // Closed for 20 ms: not yet (30 ms debounce); 30 ms: down.
//! assert_eq!(ws.sample(true, 10_000), None);
//! assert_eq!(ws.sample(true, 10_000), None);
//! assert_eq!(ws.sample(true, 10_000), Some(WorkChange::Lowered));
//! assert!(ws.is_down());
//! // A 10 ms bounce open changes nothing.
//! assert_eq!(ws.sample(false, 10_000), None);
//! assert_eq!(ws.sample(true, 10_000), None);
//! assert!(ws.is_down());
//! // Open for the debounce time: up.
//! assert_eq!(ws.sample(false, WORK_SWITCH_DEBOUNCE_US), Some(WorkChange::Lifted));
//! ```

/// How long a new level must hold before it is taken, µs. A lever or
/// proximity switch on the planting unit's frame bounces for a few ms; the
/// unit takes about a second to go up or down, so 30 ms (three control
/// periods) cost nothing in placement (4 mm at 0.5 km/h) and filter the
/// bounce and the frame's vibration.
pub const WORK_SWITCH_DEBOUNCE_US: u32 = 30_000;

/// A debounced change of the work switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WorkChange {
    /// The unit went down: planting resumes.
    Lowered,
    /// The unit went up: the drum ramps to rest, the count pauses.
    Lifted,
}

/// The work switch's debounced state (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct WorkSwitch {
    /// The debounced state: the unit is down.
    down: bool,
    /// How long the raw level has differed from `down`, µs (saturating).
    differs_for_us: u32,
}

impl WorkSwitch {
    /// At power-on: up (not planting) until the contact proves closed.
    pub const fn new() -> Self {
        Self {
            down: false,
            differs_for_us: 0,
        }
    }

    /// One look at the contact (`closed`: the pin reads low), `elapsed_us`
    /// after the previous one; the change, once the new level has held for
    /// [`WORK_SWITCH_DEBOUNCE_US`].
    pub fn sample(&mut self, closed: bool, elapsed_us: u32) -> Option<WorkChange> {
        if closed == self.down {
            self.differs_for_us = 0;
            return None;
        }
        self.differs_for_us = self.differs_for_us.saturating_add(elapsed_us);
        if self.differs_for_us < WORK_SWITCH_DEBOUNCE_US {
            return None;
        }
        self.down = closed;
        self.differs_for_us = 0;
        Some(if closed {
            WorkChange::Lowered
        } else {
            WorkChange::Lifted
        })
    }

    /// The debounced state: the planting unit is down.
    pub fn is_down(&self) -> bool {
        self.down
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::arithmetic_side_effects)]
    use super::*;
    use proptest::prelude::*;

    /// Reference: the debounced level is the last raw level that held for
    /// at least the debounce time without a break (computed over the whole
    /// history, independently of the state machine).
    fn reference(samples: &[(bool, u32)]) -> std::vec::Vec<bool> {
        let mut out = std::vec::Vec::new();
        let mut state = false;
        for i in 0..samples.len() {
            // The run of equal levels ending at i, and its duration.
            let level = samples[i].0;
            let mut held = 0u64;
            let mut j = i;
            loop {
                if samples[j].0 != level {
                    break;
                }
                held += u64::from(samples[j].1);
                if j == 0 {
                    break;
                }
                j -= 1;
            }
            if level != state && held >= u64::from(WORK_SWITCH_DEBOUNCE_US) {
                state = level;
            }
            out.push(state);
        }
        out
    }

    proptest! {
        /// Any sequence of raw levels and sample intervals: the state machine
        /// follows the reference, and reports exactly its changes.
        #[test]
        fn matches_the_reference(samples in proptest::collection::vec((any::<bool>(), 1u32..25_000), 0..200)) {
            let want = reference(&samples);
            let mut ws = WorkSwitch::new();
            let mut before = false;
            for (i, &(closed, dt)) in samples.iter().enumerate() {
                let change = ws.sample(closed, dt);
                prop_assert_eq!(ws.is_down(), want[i], "sample {}", i);
                let expected = match (before, want[i]) {
                    (false, true) => Some(WorkChange::Lowered),
                    (true, false) => Some(WorkChange::Lifted),
                    _ => None,
                };
                prop_assert_eq!(change, expected);
                before = want[i];
            }
        }
    }

    /// A broken wire (open for ever) never reads down.
    #[test]
    fn an_open_contact_never_reads_down() {
        let mut ws = WorkSwitch::new();
        for _ in 0..1000 {
            assert_eq!(ws.sample(false, 10_000), None);
            assert!(!ws.is_down());
        }
    }

    /// A contact bouncing every period never changes the state either way.
    #[test]
    fn a_bouncing_contact_changes_nothing() {
        let mut ws = WorkSwitch::new();
        for i in 0..100 {
            assert_eq!(ws.sample(i % 2 == 0, 10_000), None);
        }
        assert!(!ws.is_down());
        for _ in 0..3 {
            ws.sample(true, 10_000);
        }
        assert!(ws.is_down());
        for i in 0..100 {
            assert_eq!(ws.sample(i % 2 == 0, 20_000), None);
        }
        assert!(ws.is_down());
    }
}
