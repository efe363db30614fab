//! Profile A's passes: the work switch (pause and resume) and the live
//! planting quality, on [`Supervisor`].
//!
//! - **Up** ([`Supervisor::set_work_switch`]`(false)`): the drum's target
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

use crate::control::{RunState, Supervisor};
use crate::quality::{Indices, Quality};

/// The rate at which the drum's target falls to rest when the unit is
/// lifted, r/min per second: from the rated 25.21 r/min in 0.1 s (the
/// drum's own time constant is 25 ms, so it follows), in which the belt
/// moves ≈ 5 mm, a tenth of a partition. Slower ramps drop more seedlings
/// into the air after the lift; the stop input's stop (PWM off, coasting) is
/// faster still but uncontrolled.
pub const WORK_RAMP_RPM_PER_S: u32 = 250;

/// The work switch's state on [`Supervisor`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Work {
    /// The last state given to [`Supervisor::set_work_switch`].
    switch_down: bool,
    /// The ramp's ceiling on the target, r/min (follows the target while
    /// down).
    cap: I16F16,
    /// After a lowering: the drum waits at rest until this ground distance
    /// (µm), or `u64::MAX` (no wait).
    hold_until_um: u64,
    /// The belt's partition count × 10⁶ and the ∫V1 dt distance (µm) after
    /// the last step, for [`Supervisor::count_plants`].
    last_step: (u64, u64),
    /// The newest Hall tooth the control steps have seen, and the one
    /// before it: the brackets of the partitions' ground stamps.
    tooth: Tooth,
    before: Tooth,
    /// The partition that left after the newest tooth, waiting for the
    /// next one. One is enough: the shortest spacing (50 mm) is two Hall
    /// pitches; when a second leaves first (the ground stands while the
    /// belt runs), the first takes its fallback.
    pending: Option<Pending>,
}

/// A Hall tooth as the control step saw it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Tooth {
    /// The supervisor's tooth count at it.
    count: u32,
    /// Its capture time, µs.
    at_us: u32,
    /// The edge-locked ground at it, nm ([`crate::phase::Phase::ground_at_edge_nm`]).
    ground_nm: u64,
    /// The gap from the tooth before it, µs (`u32::MAX`: unknown).
    gap_us: u32,
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
struct Pending {
    /// When it left, µs.
    at_us: u32,
    /// The tooth before it.
    after: Tooth,
    /// The ground it gets if the bracket turns out unusable: interpolated
    /// in its control step on ∫V1 dt, µm.
    fallback_um: u64,
}

/// The ground of a partition that left at `at_us` between the teeth `a`
/// and `b` (`a.at_us ≤ at_us ≤ b.at_us`), µm: linear in time between the
/// two edges, whose ground is exact (the Hall sensor's own calibration
/// aside). `None` when the bracket is unusable: no tooth between (same
/// count), or the gap more than twice the one before — the travel speed
/// changed within it (a stop, a start), where a straight line misplaces
/// the partition by more than ∫V1 dt does.
fn between(a: Tooth, b: Tooth, at_us: u32) -> Option<u64> {
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

impl Supervisor {
    /// Whether the planting unit counts as down: the work switch says so,
    /// or none is fitted.
    pub fn unit_down(&self) -> bool {
        self.work.switch_down || !self.settings().work_switch_fitted
    }

    /// The work switch's debounced state ([`crate::work_switch`]): `true`
    /// when the planting unit is down. Ignored (the unit counts as down)
    /// when no work switch is fitted.
    pub fn set_work_switch(&mut self, down: bool) {
        let was = self.unit_down();
        self.work.switch_down = down;
        self.unit_changed(was);
    }

    /// A pass begins or ends if the unit's state changed from `was` while
    /// running.
    fn unit_changed(&mut self, was: bool) {
        let now = self.unit_down();
        if was == now || self.run_state() != RunState::Running {
            return;
        }
        let ground = self.ground_distance_um();
        if now {
            self.quality.begin_pass(ground);
            // The contact closed 30–40 ms before the switch reads down (the
            // debounce counts from the first sample that saw it closed, up
            // to a period after the closing): 35 ms of travel, 9.72 µm per
            // m/h. The drum answers a start one lag later (its 25 ms time
            // constant and 5 ms dead time): 30 ms, 8.33 µm per m/h.
            // (u32: 100 km/h, beyond the Hall sensor's 90, is 972 222 µm.)
            let mh = self.snapshot().travel_speed_kmh_x1000.min(100_000);
            let close_um = u64::from(mh.wrapping_mul(35) / 3600);
            let lag_um = u64::from(mh.wrapping_mul(25) / 3);
            let first = u64::from(self.settings().first_plant_distance.raw()).saturating_mul(1000);
            let at = ground.saturating_sub(close_um).saturating_add(first);
            self.realign_next_plant(at);
            // The belt rests with the next partition `1 − frac` of a pitch
            // from leaving: at the spacing's ratio that is `(1 − frac)·X` of
            // ground. The drum waits until then less its lag, so that the
            // first plant lands near `at` however the lift left the belt;
            // the distance-locked loop takes up the rest. (Without the wait
            // the next partition would leave within a pitch of the
            // lowering whatever `first_plant_distance` says, and the loop's
            // bounded correction cannot hold the belt back for that long.)
            // In u32: `left` ≤ 10⁶ (a pitch × 10⁶) and X ≤ 500 mm, so
            // left · X_mm ≤ 5 · 10⁸; / 1000 gives µm.
            let left = 1_000_000u32
                .wrapping_sub(u32::try_from(self.partitions_x1e6() % 1_000_000).unwrap_or(0));
            let needs =
                u64::from(left.wrapping_mul(u32::from(self.settings().spacing.raw())) / 1000);
            let hold = at.saturating_sub(needs).saturating_sub(lag_um);
            self.work.hold_until_um = if hold > ground { hold } else { u64::MAX };
        } else {
            self.flush_pending();
            self.quality.end_pass(ground);
        }
    }

    /// The partition still waiting for a tooth takes its fallback ground
    /// (a pass ends: it belongs to it).
    pub(crate) fn flush_pending(&mut self) {
        if let Some(p) = self.work.pending.take() {
            self.quality.plant(p.fallback_um);
        }
    }

    /// The work switch fitted or not (page 6): applies at once, as a
    /// change of the switch would (a pass begins or ends).
    pub(crate) fn set_work_switch_fitted(&mut self, fitted: bool) {
        let was = self.unit_down();
        self.settings.work_switch_fitted = fitted;
        self.unit_changed(was);
    }

    /// Start: the quality figures restart; with the unit down, the first
    /// pass begins.
    pub(crate) fn start_planting(&mut self) {
        let x_um = u32::from(self.settings().spacing.raw()).saturating_mul(1000);
        self.quality.start(x_um);
        self.work.cap = I16F16::ZERO;
        self.work.pending = None;
        if self.unit_down() {
            self.quality.begin_pass(0);
        }
    }

    /// The drum target under the work switch: unchanged while the unit is
    /// down; ramping to rest at [`WORK_RAMP_RPM_PER_S`] while it is up.
    pub(crate) fn work_ramp(&mut self, target: I16F16, elapsed_us: u32) -> I16F16 {
        if self.unit_down() {
            let hold = self.work.hold_until_um;
            if hold != u64::MAX && self.ground_distance_um() < hold {
                self.work.cap = I16F16::ZERO;
                return I16F16::ZERO;
            }
            self.work.hold_until_um = u64::MAX;
            self.work.cap = target;
            return target;
        }
        // r/min per period in I16F16 bits: rate · 2¹⁶ · elapsed / 10⁶
        // (elapsed ≤ 4 periods of 10 ms: 16 384 · 40 000 < 2³²).
        let step = (WORK_RAMP_RPM_PER_S * 65_536 / 1000).saturating_mul(elapsed_us) / 1000;
        let step = I16F16::from_bits(i32::try_from(step).unwrap_or(i32::MAX));
        self.work.cap = self.work.cap.saturating_sub(step).max(I16F16::ZERO);
        target.min(self.work.cap)
    }

    /// After a control step (`partitions_x1e6`: the belt's partition count
    /// × 10⁶ now, `now_us` the step's time, `elapsed_us` since the step
    /// before): the partition that left in the step, if one did, goes to the
    /// quality figures when the unit is down, at the ground distance of the
    /// moment it left.
    ///
    /// That moment is interpolated in the step on the belt's counts; its
    /// ground, once the next Hall tooth has come, linearly in time between
    /// the two teeth around it, whose ground is exact. Not the phase loop's
    /// causal ground ([`Supervisor::plants_left`]): between teeth it is
    /// extrapolated and held at the next tooth, steps of a few mm the
    /// spacings would count; nor ∫V1 dt alone, which smooths the drum's real
    /// answer to those steps away (tests/work_switch.rs: CV 0.7 % on it
    /// against 1.32 % of the drops). The figures are live one tooth gap
    /// late (≤ 0.3 s at Low 1). ∫V1 dt, interpolated in the step, remains
    /// the fallback when the teeth cannot bracket the moment ([`between`]).
    #[inline(never)]
    pub(crate) fn count_plants(
        &mut self,
        partitions_x1e6: u64,
        teeth: (u32, Option<u32>),
        now_us: u32,
        elapsed_us: u32,
    ) {
        // The newest tooth.
        if let (count, Some(at_us)) = teeth {
            if count != self.work.tooth.count {
                let gap_us = if self.work.tooth.count == 0 {
                    u32::MAX
                } else {
                    at_us.wrapping_sub(self.work.tooth.at_us)
                };
                self.work.before = self.work.tooth;
                self.work.tooth = Tooth {
                    count,
                    at_us,
                    ground_nm: self.phase.ground_at_edge_nm(),
                    gap_us,
                };
            }
        }
        // Partitions waiting for this tooth.
        let tooth = self.work.tooth;
        if let Some(p) = self.work.pending {
            if p.after.count != tooth.count {
                self.work.pending = None;
                self.quality
                    .plant(between(p.after, tooth, p.at_us).unwrap_or(p.fallback_um));
            }
        }

        let after_um = self.distance_um;
        // Start zeroes both counts: then the step began at 0.
        let (mut before_x1e6, mut before_um) = self.work.last_step;
        if partitions_x1e6 < before_x1e6 || after_um < before_um {
            (before_x1e6, before_um) = (0, 0);
        }
        self.work.last_step = (partitions_x1e6, after_um);
        // At most one partition a step at any reachable belt speed (50 mm in
        // 10 ms is 5 m/s).
        let boundary = (before_x1e6 / 1_000_000)
            .wrapping_add(1)
            .wrapping_mul(1_000_000);
        if boundary > partitions_x1e6 || !self.unit_down() {
            return;
        }
        // A step's partitions and ground (≤ 36 mm at 3.6 m/s) fit u32;
        // `into` ≤ `dp`.
        let dp = u32::try_from(partitions_x1e6.wrapping_sub(before_x1e6)).unwrap_or(u32::MAX);
        let into = u32::try_from(boundary.wrapping_sub(before_x1e6)).unwrap_or(u32::MAX);
        let share = |span: u32| {
            u64::from(span)
                .wrapping_mul(u64::from(into))
                .checked_div(u64::from(dp))
                .unwrap_or(0)
        };
        let dd = u32::try_from(after_um.wrapping_sub(before_um)).unwrap_or(u32::MAX);
        let fallback_um = before_um.wrapping_add(share(dd));
        // `share(elapsed) ≤ elapsed`: fits u32.
        let at_us = now_us
            .wrapping_sub(elapsed_us)
            .wrapping_add(u32::try_from(share(elapsed_us)).unwrap_or(0));
        let ahead = tooth.at_us.wrapping_sub(at_us);
        if tooth.count != 0 && ahead > 0 && ahead <= elapsed_us {
            // Left before the newest tooth (it came later in this step):
            // bracketed already.
            let g = between(self.work.before, tooth, at_us).unwrap_or(fallback_um);
            self.quality.plant(g);
            return;
        }
        let wait = Pending {
            at_us,
            after: tooth,
            fallback_um,
        };
        if let Some(p) = self.work.pending.replace(wait) {
            self.quality.plant(p.fallback_um);
        }
    }

    /// The planting quality since Start and of the current pass.
    pub fn quality(&self) -> &Quality {
        &self.quality
    }

    /// The indices since Start, the pass in progress counted up to now.
    pub fn quality_since_start(&self) -> Indices {
        self.quality.since_start(self.ground_distance_um())
    }

    /// The indices of the pass in progress (or of the last one).
    pub fn quality_of_pass(&self) -> Indices {
        self.quality.pass_at(self.ground_distance_um())
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
