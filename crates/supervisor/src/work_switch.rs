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
//! emergency input: no interrupt) and debounced here: a new level is taken
//! only once it has read the same on every sample for
//! [`WORK_SWITCH_DEBOUNCE_US`] (closing, the unit lowered) or
//! [`WORK_LIFT_CONFIRM_US`] (opening, the unit lifted), counted from the
//! first sample that saw it: the contact may have changed at any time in
//! the period before, so that sample proves nothing yet. A contact that
//! opens for less than the lift time is the frame's vibration (a bump
//! lifts the frame for tens of milliseconds; a hitch lifts the unit for
//! seconds): the unit stays down and keeps planting. At power-on the switch
//! reads up until the contact has proven closed.
//!
//! ```
//! use supervisor::work_switch::{WorkChange, WorkSwitch, WORK_LIFT_CONFIRM_US};
//!
//! let mut ws = WorkSwitch::new();
//! assert!(!ws.is_down());
//! // Seen closed at 0, 10, 20 ms: not yet (30 ms debounce); at 30 ms: down.
//! for _ in 0..3 {
//!     assert_eq!(ws.sample(true, 10_000), None);
//! }
//! assert_eq!(ws.sample(true, 10_000), Some(WorkChange::Lowered));
//! assert!(ws.is_down());
//! // An 80 ms opening (a bump) changes nothing.
//! for _ in 0..8 {
//!     assert_eq!(ws.sample(false, 10_000), None);
//! }
//! assert_eq!(ws.sample(true, 10_000), None);
//! assert!(ws.is_down());
//! // Open for the lift time (from the first sample that saw it open): up.
//! assert_eq!(ws.sample(false, 10_000), None);
//! assert_eq!(ws.sample(false, WORK_LIFT_CONFIRM_US), Some(WorkChange::Lifted));
//! ```

/// How long a closed contact must hold before the unit counts as down, µs.
/// A lever or proximity switch on the planting unit's frame bounces for a
/// few ms; 30 ms (three control periods after the first sample that saw it
/// closed) cost 4 mm of ground at 0.5 km/h, which the first plant's
/// placement takes off (`crate::drum::work`).
pub const WORK_SWITCH_DEBOUNCE_US: u32 = 30_000;

/// How long an open contact must hold before the unit counts as lifted, µs:
/// the frame's vibration limit. A bump or a clod lifts the frame and opens
/// the contact for tens of milliseconds (80 ms measured on the machine
/// model's terms); a three-point hitch raises the unit at 0.1–0.3 m/s, so
/// a real lift keeps the contact open for seconds, and in its first 0.2 s
/// the planting shoe has risen 20–60 mm, still in the furrow of a 50–100 mm
/// deep planting. While the lift is being confirmed the drum plants on: at
/// the fastest the drum can follow (0.81 km/h at 7 cm, 2.08 km/h at 18 cm)
/// that is 45 mm or 116 mm of ground, at most one plant (docs/firmware.md,
/// "Work switch").
pub const WORK_LIFT_CONFIRM_US: u32 = 200_000;

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
    /// Whether the last sample read the other level.
    differs: bool,
    /// How long the other level has read since the first sample that saw
    /// it, µs (saturating).
    differs_for_us: u32,
}

impl WorkSwitch {
    /// At power-on: up (not planting) until the contact proves closed.
    pub const fn new() -> Self {
        Self {
            down: false,
            differs: false,
            differs_for_us: 0,
        }
    }

    /// One look at the contact (`closed`: the pin reads low), `elapsed_us`
    /// after the previous one; the change, once the new level has read on
    /// every sample for [`WORK_SWITCH_DEBOUNCE_US`] (closed) or
    /// [`WORK_LIFT_CONFIRM_US`] (open) since the first sample that saw it.
    pub fn sample(&mut self, closed: bool, elapsed_us: u32) -> Option<WorkChange> {
        if closed == self.down {
            self.differs = false;
            self.differs_for_us = 0;
            return None;
        }
        if self.differs {
            self.differs_for_us = self.differs_for_us.saturating_add(elapsed_us);
        }
        self.differs = true;
        let hold = if closed {
            WORK_SWITCH_DEBOUNCE_US
        } else {
            WORK_LIFT_CONFIRM_US
        };
        if self.differs_for_us < hold {
            return None;
        }
        self.down = closed;
        self.differs = false;
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

    /// Reference: the debounced level changes to a raw level once that
    /// level has read on every sample for at least its hold time (closed:
    /// the debounce; open: the lift time), counted from the first sample of
    /// the run that saw it (computed over the whole history, independently
    /// of the state machine).
    fn reference(samples: &[(bool, u32)]) -> std::vec::Vec<bool> {
        let mut out = std::vec::Vec::new();
        let mut state = false;
        for i in 0..samples.len() {
            // The run of equal levels ending at i, and the time from its
            // first sample to sample i.
            let level = samples[i].0;
            let mut held = 0u64;
            let mut j = i;
            while j > 0 && samples[j - 1].0 == level {
                held += u64::from(samples[j].1);
                j -= 1;
            }
            let hold = if level {
                WORK_SWITCH_DEBOUNCE_US
            } else {
                WORK_LIFT_CONFIRM_US
            };
            // A run that began before the last change counts from that change.
            if level != state && held >= u64::from(hold) && !changed_within(&out, j, i) {
                state = level;
            }
            out.push(state);
        }
        out
    }

    /// Whether the debounced state changed between samples `from` and
    /// `to` (exclusive): a run then counts only from the change.
    fn changed_within(out: &[bool], from: usize, to: usize) -> bool {
        (from.max(1)..to).any(|k| out[k] != out[k - 1])
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

    /// The documented times hold from the contact's change, not from the
    /// first sample: a contact that closes (or opens) at any moment within
    /// a 10 ms period is taken no sooner than 30 ms (200 ms) after it and
    /// no later than one period after that. Before, the first sample that
    /// saw the new level counted a whole period: a closing was taken
    /// 20 ms + ε after it, while the contact could still be bouncing.
    #[test]
    fn a_change_is_taken_no_sooner_than_its_hold_time_after_it_happened() {
        for (closing, hold) in [
            (true, WORK_SWITCH_DEBOUNCE_US),
            (false, WORK_LIFT_CONFIRM_US),
        ] {
            for phase_us in [1u32, 2_500, 5_000, 9_999] {
                let mut ws = WorkSwitch::new();
                if !closing {
                    for _ in 0..4 {
                        ws.sample(true, 10_000);
                    }
                    assert!(ws.is_down());
                }
                // The contact changes `phase_us` before the sample at 10 ms.
                let changed_at = 10_000 - phase_us;
                let mut t = 0u32;
                let taken = loop {
                    t += 10_000;
                    if ws
                        .sample(if t >= changed_at { closing } else { !closing }, 10_000)
                        .is_some()
                    {
                        break t;
                    }
                    assert!(t < 1_000_000);
                };
                let after = taken - changed_at;
                assert!(
                    after >= hold && after < hold + 10_000,
                    "closing {closing}, change {phase_us} µs before a sample: taken {after} µs after it"
                );
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
        for _ in 0..4 {
            ws.sample(true, 10_000);
        }
        assert!(ws.is_down());
        for i in 0..100 {
            assert_eq!(ws.sample(i % 2 == 0, 20_000), None);
        }
        assert!(ws.is_down());
    }
}
