//! Profile A's passes: the work switch (pause and resume) and the live
//! planting quality, on [`Supervisor`](super::Supervisor).
//!
//! - **Up** ([`Supervisor::set_work_switch`](super::Supervisor::set_work_switch)`(false)`): the drum's target
//!   ramps to rest at [`WORK_RAMP_RPM_PER_S`] — a controlled stop under the
//!   speed loop, not the stop input's (outputs off, the drum coasts) — and
//!   the pass ends: its quality joins the totals, partitions that still
//!   leave during the ramp are not counted in the quality figures, and the
//!   belt, at rest, adds no plants to the count. The drum stays *Running*
//!   (no Start needed to resume).
//! - **Down** (`true`): a new pass begins at the ground distance of that
//!   moment, the next partition is asked to leave
//!   [`Settings::first_plant_distance`](crate::settings::Settings::first_plant_distance)
//!   further on (`realign_next_plant`), and the drum follows its target
//!   again.
//! - **No work switch fitted** (the default,
//!   [`Settings::work_switch_fitted`](crate::settings::Settings::work_switch_fitted)
//!   off): the unit counts as always down; a pass runs from Start to Stop.
//!
//! The quality figures ([`crate::quality`]) take every partition that left
//! with the unit down, at the ground distance of that moment.

use fuzzy_pid::I16F16;

/// The rate at which the drum's target falls to rest when the unit is
/// lifted, r/min per second: from the rated 25.21 r/min in 0.1 s (the
/// drum's own time constant is 25 ms, so it follows), in which the belt
/// moves ≈ 5 mm, a tenth of a partition. Slower ramps drop more seedlings
/// into the air after the lift; the stop input's stop (PWM off, coasting) is
/// faster still but uncontrolled.
pub const WORK_RAMP_RPM_PER_S: u32 = 250;

/// The work switch's state on [`Supervisor`](super::Supervisor).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Work {
    /// The last state given to [`Supervisor::set_work_switch`](super::Supervisor::set_work_switch).
    pub(super) switch_down: bool,
    /// The ramp's ceiling on the target, r/min (follows the target while
    /// down).
    pub(super) cap: I16F16,
    /// After a lowering: the drum waits at rest until this ground distance
    /// (µm), or `u64::MAX` (no wait).
    pub(super) hold_until_um: u64,
    /// The belt's partition count × 10⁶ and the ∫V1 dt distance (µm) after
    /// the last step, for [`Supervisor::count_plants`](super::Supervisor::count_plants).
    pub(super) last_step: (u64, u64),
    /// The newest Hall tooth the control steps have seen, and the one
    /// before it: the brackets of the partitions' ground stamps.
    pub(super) tooth: Tooth,
    pub(super) before: Tooth,
    /// The partition that left after the newest tooth, waiting for the
    /// next one. One is enough: the shortest spacing (50 mm) is two Hall
    /// pitches; when a second leaves first (the ground stands while the
    /// belt runs), the first takes its fallback.
    pub(super) pending: Option<Pending>,
}

/// A Hall tooth as the control step saw it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Tooth {
    /// The supervisor's tooth count at it.
    pub(super) count: u32,
    /// Its capture time, µs.
    pub(super) at_us: u32,
    /// The edge-locked ground at it, nm ([`crate::phase::Phase::ground_at_edge_nm`]).
    pub(super) ground_nm: u64,
    /// The gap from the tooth before it, µs (`u32::MAX`: unknown).
    pub(super) gap_us: u32,
}

impl Tooth {
    const NONE: Self = Self {
        count: 0,
        at_us: 0,
        ground_nm: 0,
        gap_us: u32::MAX,
    };
}

/// A partition that left after `after`, waiting for the next tooth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Pending {
    /// When it left, µs.
    pub(super) at_us: u32,
    /// The tooth before it.
    pub(super) after: Tooth,
    /// The ground it gets if the bracket turns out unusable: interpolated
    /// in its control step on ∫V1 dt, µm.
    pub(super) fallback_um: u64,
}

/// The ground of a partition that left at `at_us` between the teeth `a`
/// and `b` (`a.at_us ≤ at_us ≤ b.at_us`), µm: linear in time between the
/// two edges, whose ground is exact (the Hall sensor's own calibration
/// aside). `None` when the bracket is unusable: no tooth between (same
/// count), or the gap more than twice the one before — the travel speed
/// changed within it (a stop, a start), where a straight line misplaces
/// the partition by more than ∫V1 dt does.
pub(super) fn between(a: Tooth, b: Tooth, at_us: u32) -> Option<u64> {
    let gap = b.at_us.wrapping_sub(a.at_us);
    let into = at_us.wrapping_sub(a.at_us);
    if b.count == a.count || into > gap || gap / 2 > a.gap_us {
        return None;
    }
    // dg ≤ a few teeth (< 2³²·nm per step at any reachable speed) ×
    // into ≤ gap < 2³²: the product < 2⁶⁴ while dg < 2³² nm (4.3 m).
    let dg = b
        .ground_nm
        .checked_sub(a.ground_nm)?
        .min(u64::from(u32::MAX));
    let g = dg
        .wrapping_mul(u64::from(into))
        .checked_div(u64::from(gap))?;
    Some(a.ground_nm.wrapping_add(g) / 1000)
}

impl Work {
    /// Up (a fitted switch must prove closed first).
    pub const fn new() -> Self {
        Self {
            switch_down: false,
            cap: I16F16::ZERO,
            hold_until_um: u64::MAX,
            last_step: (0, 0),
            tooth: Tooth::NONE,
            before: Tooth::NONE,
            pending: None,
        }
    }
}

impl Default for Work {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tooth(count: u32, at_us: u32, ground_mm: u64, gap_us: u32) -> Tooth {
        Tooth {
            count,
            at_us,
            ground_nm: ground_mm.saturating_mul(1_000_000),
            gap_us,
        }
    }

    #[test]
    fn a_partition_between_two_teeth_takes_the_straight_line_between_them() {
        // Teeth 25.133 mm apart (the Hall pitch, EDGE_NM in phase.rs)
        // 180 ms apart; a partition 60 ms after the first is a third of the
        // way: 100 mm + 25 133 µm / 3 = 108 377.67 µm (hand-computed).
        let a = Tooth {
            count: 4,
            at_us: 1_000_000,
            ground_nm: 100_000_000,
            gap_us: 180_000,
        };
        let b = Tooth {
            count: 5,
            at_us: 1_180_000,
            ground_nm: 125_133_000,
            gap_us: 180_000,
        };
        assert_eq!(between(a, b, 1_060_000), Some(108_377));
        // At the teeth themselves: their own ground.
        assert_eq!(between(a, b, 1_000_000), Some(100_000));
        assert_eq!(between(a, b, 1_180_000), Some(125_133));
        // Two teeth in one control step: the line spans both (at half the
        // time, half of 2 × 25 mm).
        let c = tooth(6, 1_360_000, 150, 180_000);
        let a2 = tooth(4, 1_000_000, 100, 180_000);
        assert_eq!(between(a2, c, 1_180_000), Some(125_000));
        // Across the 32-bit wrap of the µs clock (71.6 min): the same.
        let off = u32::MAX - 50_000;
        let aw = Tooth {
            at_us: a.at_us.wrapping_add(off),
            ..a
        };
        let bw = Tooth {
            at_us: b.at_us.wrapping_add(off),
            ..b
        };
        assert_eq!(
            between(aw, bw, 1_060_000u32.wrapping_add(off)),
            Some(108_377)
        );
    }

    #[test]
    fn no_straight_line_across_a_stop_or_outside_the_bracket() {
        let a = tooth(4, 1_000_000, 100, 180_000);
        // The next tooth 400 ms later: more than twice the 180 ms before, the
        // speed changed within the gap.
        assert_eq!(
            between(a, tooth(5, 1_400_000, 125, 400_000), 1_100_000),
            None
        );
        // 360 ms is twice: still a line.
        assert!(between(a, tooth(5, 1_360_000, 125, 360_000), 1_100_000).is_some());
        // No tooth between: nothing to bracket with.
        assert_eq!(between(a, a, 1_000_000), None);
        // Before the first tooth or after the second.
        let b = tooth(5, 1_180_000, 125, 180_000);
        assert_eq!(between(a, b, 999_999), None);
        assert_eq!(between(a, b, 1_180_001), None);
        // A ground that went backwards (a new Start's origin) is refused.
        assert_eq!(
            between(b, tooth(6, 1_360_000, 100, 180_000), 1_200_000),
            None
        );
    }
}
