//! The work switch's passes and the plant count on the drum machine
//! ([`super::work`] keeps their state).

use super::work::{between, Pending, Tooth, WORK_RAMP_RPM_PER_S};
use super::*;
use crate::quality::{Indices, Quality};

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
    pub(super) fn unit_changed(&mut self, was: bool) {
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
