//! Machine A's travel source: the Hall gear, the ground wheel, or both
//! (docs/ground-wheel.md).
//!
//! With the **ground wheel** the travel speed and the ground distance come
//! from its encoder ([`kinematics::wheel`]): a count every 0.33 mm on the
//! product's wheel instead of a Hall edge every 25 mm, and the ground itself
//! rather than the track, so the track's slip is not in them.
//!
//! With **both**, the wheel is the source and the Hall gear its cross-check:
//!
//! - **the live track slip**, `s = 1 − wheel distance / track distance`,
//!   the track's distance being the Hall gear's teeth × their learned
//!   pitches × k1 (paper A eq. 22 with the wheel in place of the taped
//!   course), over the last [`SLIP_REVOLUTIONS`] whole turns of the gear
//!   (whole turns: the teeth's spacing errors cancel), the wheel's distance
//!   taken at the same Hall edges;
//! - **a wheel that stops rolling** (lifted, blocked, clogged, or counting
//!   backwards) while the Hall gear turns: the gear gives an edge while the
//!   wheel has not counted for [`WHEEL_SILENT_US`] (it counts every 4 ms at
//!   the slowest gear). Evidence, not the Hall gear's estimated speed, which
//!   lags a stopping tractor by up to its stop timeout: a tractor at rest
//!   stops both. From then the ground goes on at the Hall gear's speed (the
//!   track's speed × (1 − the slip last measured)) from the wheel's last
//!   count, so a clod that lifts the wheel for a moment costs no distance;
//!   once the Hall gear says [`WHEEL_STOP_ALARM_NM`] of ground passed since
//!   the wheel's last count it is a warning (more than a clod lifts it for;
//!   0.41 s after the stop at the slowest gear), and the machine plants on
//!   the Hall gear until the wheel rolls again for [`WHEEL_BACK_US`];
//! - **a Hall gear that stops** while the wheel rolls: a warning once the
//!   wheel has rolled [`HALL_SILENT_PITCHES_X10`] / 10 of the gear's pitches
//!   since its last edge (the track, slipping, moves more than the ground:
//!   a turning gear gives an edge within one pitch of ground); the wheel
//!   carries on (the slip is not measured meanwhile). Counted in ground, not
//!   time, so the restart after a rest, when the wheel rolls at once and the
//!   gear's first tooth may be a whole pitch away, is no alarm.
//!
//! With the wheel **alone**, a wheel that counts backwards is a latched
//! alarm (the supervisor's), and a silent one is the "no travel pulses"
//! warning, as a silent Hall gear is with the Hall gear alone.

use hmi_proto::screen::{TravelSource, TravelSourceInUse};
use kinematics::wheel::{WheelOdometer, WheelStep};

use crate::phase::EDGE_NM;
use crate::settings::wheel::GroundWheelSettings;

/// The wheel is taken as stopped when the Hall gear gives an edge after it
/// has not counted for this long, µs.
pub const WHEEL_SILENT_US: u32 = 50_000;
/// A wheel that has not rolled while the Hall gear says this much ground
/// passed (nm, counted from the wheel's last count) raises the warning:
/// 35 mm, more than a clod lifts it for, 0.41 s at the slowest gear.
pub const WHEEL_STOP_ALARM_NM: u64 = 35_000_000;
/// A stopped wheel is trusted again after rolling this long, µs.
pub const WHEEL_BACK_US: u32 = 200_000;
/// Counts backwards, without a count forward between them, that make a
/// wheel counting backwards (33 mm on the product wheel: more than a
/// machine rolls back when it stops on a slope's clod).
pub const BACKWARD_COUNTS: u32 = 100;
/// The slowest travel speed at which one source judges the other, m/s
/// (U8F24 bits): 0.03 m/s, 0.11 km/h, a third of Low 1.
pub const MOVING_BITS: u32 = 503_316;
/// Ground the wheel may roll after the Hall gear's last edge, tenths of a
/// pitch (π·0.20 m / 25 = 25.1 mm): 1.5 pitches, 37.7 mm — 0.44 s at the
/// slowest gear (Low 1, 0.086 m/s).
pub const HALL_SILENT_PITCHES_X10: u64 = 15;
/// Gear turns the live slip is measured over.
pub const SLIP_REVOLUTIONS: usize = 3;
/// The Hall gear's teeth (one turn).
const TEETH: u32 = kinematics::consts::Z1 as u32;

/// A failure one source shows of the other, or of the wheel alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GroundFault {
    /// The wheel does not roll while the Hall gear turns.
    WheelStopped,
    /// The wheel counts backwards while the machine moves forward.
    WheelBackwards,
    /// The Hall gear is silent while the wheel rolls.
    HallStopped,
}

/// What the Hall side knows this period.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HallView {
    /// Teeth counted for the ground since boot (wrapping).
    pub teeth: u32,
    /// Their learned pitches summed, Q16 (wrapping).
    pub pitches_q16: u32,
    /// The travel speed from the Hall gear (k1 and k2), m/s U8F24; 0 at
    /// rest or unknown.
    pub travel_bits: u32,
    /// The track's speed (k1, no k2), m/s U8F24.
    pub track_bits: u32,
    /// k1 at the speed, Q30 (`None`: none known).
    pub k1_q30: Option<u64>,
    /// Time since the newest Hall edge, µs (`u32::MAX`: none yet).
    pub since_edge_us: u32,
}

/// One period of the ground from the wheel (or its stand-in).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GroundStep {
    /// The sensor in use.
    pub in_use: TravelSourceInUse,
    /// Ground this period, nm.
    pub distance_nm: u64,
    /// The travel speed to plan with, m/s U8F24.
    pub speed_bits: u32,
    /// The wheel's counts this period.
    pub wheel: WheelStep,
}

/// The travel source's state (module docs).
#[derive(Clone, Copy, Debug)]
pub struct Ground {
    odometer: WheelOdometer,
    counter: Option<u16>,
    in_use: TravelSourceInUse,
    /// Ground the Hall gear stood in for since the wheel's last count, nm.
    stood_in_nm: u64,
    rolling_us: u32,
    /// Teeth at the last step, and the wheel's ground since the newest edge.
    edge_teeth: u32,
    since_edge_nm: u64,
    /// Teeth when the wheel last counted forward.
    wheel_teeth: u32,
    back_counts: u32,
    fault: Option<GroundFault>,
    stand_in_frac: u64,
    track_nm: u64,
    wheel_nm: u64,
    last_teeth: Option<u32>,
    last_pitches_q16: u32,
    rev_teeth: u32,
    ring: [(u64, u64); SLIP_REVOLUTIONS + 1],
    ring_len: usize,
    slip_x10: Option<i16>,
}

impl Default for Ground {
    fn default() -> Self {
        Self::new()
    }
}

impl Ground {
    /// No reading yet; the Hall gear in use.
    pub const fn new() -> Self {
        Self {
            odometer: WheelOdometer::new(),
            counter: None,
            in_use: TravelSourceInUse::HallGear,
            stood_in_nm: 0,
            rolling_us: 0,
            edge_teeth: 0,
            since_edge_nm: 0,
            wheel_teeth: 0,
            back_counts: 0,
            fault: None,
            stand_in_frac: 0,
            track_nm: 0,
            wheel_nm: 0,
            last_teeth: None,
            last_pitches_q16: 0,
            rev_teeth: 0,
            ring: [(0, 0); SLIP_REVOLUTIONS + 1],
            ring_len: 0,
            slip_x10: None,
        }
    }

    /// The wheel's counter, read this period.
    pub fn wheel_count(&mut self, counter: u16) {
        self.counter = Some(counter);
    }

    /// The sensor in use after the last step.
    pub const fn in_use(&self) -> TravelSourceInUse {
        self.in_use
    }

    /// The failure seen, if any.
    pub const fn fault(&self) -> Option<GroundFault> {
        self.fault
    }

    /// The live track slip, ‰ (0.1 %): measured, both sensors turning and
    /// the wheel in use (the last value is kept for the Hall gear's stand-in,
    /// not shown).
    pub fn slip_x10(&self) -> Option<i16> {
        self.slip_x10
            .filter(|_| self.in_use == TravelSourceInUse::GroundWheel && self.fault.is_none())
    }

    /// Signed wheel counts since boot (after the direction setting).
    pub const fn wheel_counts(&self) -> i64 {
        self.odometer.total_counts()
    }

    /// Periods since the wheel's last forward count.
    pub const fn wheel_silent_periods(&self) -> u32 {
        self.odometer.silent_periods()
    }

    /// One period: `None` when the Hall gear is the source (the supervisor
    /// then measures the ground as without a wheel).
    pub fn step(
        &mut self,
        settings: &GroundWheelSettings,
        hall: &HallView,
        period_us: u32,
        elapsed_us: u32,
    ) -> Option<GroundStep> {
        let cpm = settings.counts_per_m_x1000;
        let wheel = match self.counter {
            Some(c) => self.odometer.update(c, settings.reversed, cpm),
            None => WheelStep::default(),
        };
        if !settings.source.uses_wheel() {
            self.in_use = TravelSourceInUse::HallGear;
            self.fault = None;
            self.reset_slip();
            return None;
        }
        if wheel.forward > 0 {
            self.back_counts = 0;
        } else {
            self.back_counts = self.back_counts.saturating_add(wheel.backward);
        }
        let backwards = self.back_counts >= BACKWARD_COUNTS;
        let wheel_bits = self.odometer.speed_bits(period_us, cpm);
        if settings.source == TravelSource::GroundWheel {
            self.in_use = TravelSourceInUse::GroundWheel;
            self.fault = backwards.then_some(GroundFault::WheelBackwards);
            return Some(GroundStep {
                in_use: self.in_use,
                distance_nm: wheel.distance_nm,
                speed_bits: if backwards { 0 } else { wheel_bits },
                wheel,
            });
        }
        // Both: the wheel judged by the Hall gear, and the reverse.
        let hall_moving = hall.travel_bits >= MOVING_BITS;
        let silent_us = self
            .odometer
            .silent_periods()
            .saturating_mul(period_us.max(1));
        if wheel.forward > 0 {
            self.wheel_teeth = hall.teeth;
        }
        // The gear turned (an edge) while the wheel was silent, or the
        // wheel counts backwards; once standing in, until the wheel rolls.
        let gear_turned = hall.teeth != self.wheel_teeth && silent_us >= WHEEL_SILENT_US;
        let not_rolling = hall_moving
            && (backwards
                || gear_turned
                || (self.in_use == TravelSourceInUse::HallStandIn && wheel.forward == 0));
        let stand_in_bits = self.stand_in_bits(hall);
        let mut distance_nm = wheel.distance_nm;
        if not_rolling {
            if self.in_use != TravelSourceInUse::HallStandIn {
                // From the wheel's last count: the silence before it was
                // seen is ground too.
                distance_nm = self.stand_in_nm(stand_in_bits, silent_us);
                self.reset_slip();
            } else {
                distance_nm = self.stand_in_nm(stand_in_bits, elapsed_us);
            }
            self.in_use = TravelSourceInUse::HallStandIn;
            self.stood_in_nm = self.stood_in_nm.saturating_add(distance_nm);
            self.rolling_us = 0;
            if self.stood_in_nm >= WHEEL_STOP_ALARM_NM {
                self.fault = Some(if backwards {
                    GroundFault::WheelBackwards
                } else {
                    GroundFault::WheelStopped
                });
            }
        } else if self.in_use == TravelSourceInUse::HallStandIn && hall_moving {
            // Back on the wheel once it rolls for a while; meanwhile its
            // counts are ground and the Hall gear's time is not.
            self.rolling_us = if wheel.forward > 0 {
                self.rolling_us.saturating_add(elapsed_us)
            } else {
                0
            };
            if self.rolling_us >= WHEEL_BACK_US {
                self.in_use = TravelSourceInUse::GroundWheel;
                self.stood_in_nm = 0;
                self.fault = None;
            }
        } else {
            self.in_use = TravelSourceInUse::GroundWheel;
            self.stood_in_nm = 0;
            if matches!(
                self.fault,
                Some(GroundFault::WheelStopped | GroundFault::WheelBackwards)
            ) {
                self.fault = None;
            }
        }
        // The Hall gear judged by the wheel: the ground rolled since its
        // newest edge.
        if hall.teeth != self.edge_teeth {
            self.edge_teeth = hall.teeth;
            self.since_edge_nm = 0;
        } else {
            self.since_edge_nm = self.since_edge_nm.saturating_add(wheel.distance_nm);
        }
        let hall_silent = self.since_edge_nm > EDGE_NM * HALL_SILENT_PITCHES_X10 / 10;
        if hall_silent && self.in_use == TravelSourceInUse::GroundWheel {
            self.fault = Some(GroundFault::HallStopped);
            self.reset_slip();
        } else if self.fault == Some(GroundFault::HallStopped) && !hall_silent {
            self.fault = None;
        }
        if self.in_use == TravelSourceInUse::GroundWheel && self.fault.is_none() {
            self.measure_slip(hall, wheel.distance_nm, wheel_bits);
        } else {
            self.last_teeth = None;
        }
        let speed_bits = if self.in_use == TravelSourceInUse::HallStandIn {
            stand_in_bits
        } else {
            wheel_bits
        };
        Some(GroundStep {
            in_use: self.in_use,
            distance_nm,
            speed_bits,
            wheel,
        })
    }

    /// The Hall gear's ground speed standing in for the wheel: the track's
    /// speed × (1 − the slip last measured), or the k2 table's travel speed
    /// before any.
    fn stand_in_bits(&self, hall: &HallView) -> u32 {
        match self.slip_x10 {
            Some(s) => {
                // s ∈ [−500, 999]: 1000 − s ∈ [1, 1500].
                let keep =
                    u64::from(1000u16.saturating_add_signed(s.clamp(-500, 999).wrapping_neg()));
                u32::try_from(u64::from(hall.track_bits).saturating_mul(keep) / 1000)
                    .unwrap_or(u32::MAX)
            }
            None => hall.travel_bits,
        }
    }

    /// Ground at `bits` (m/s U8F24) for `us`, nm, the fraction carried.
    fn stand_in_nm(&mut self, bits: u32, us: u32) -> u64 {
        // m/s · µs = µm; × 1000 nm; U8F24: < 2³² · 2²⁴ · 2¹⁰ = 2⁶⁶ — the
        // speed is clamped to 16 m/s and the time to 16.7 s: < 2⁶².
        let acc = u64::from(bits.min(1 << 28))
            .wrapping_mul(u64::from(us.min(1 << 24)))
            .wrapping_mul(1000)
            .wrapping_add(self.stand_in_frac);
        self.stand_in_frac = acc & 0xFF_FFFF;
        acc >> 24
    }

    fn reset_slip(&mut self) {
        self.ring_len = 0;
        self.rev_teeth = 0;
        self.last_teeth = None;
    }

    /// Adds this period to the slip's distances; at each whole gear turn,
    /// a new slip over the last [`SLIP_REVOLUTIONS`] turns.
    fn measure_slip(&mut self, hall: &HallView, wheel_nm: u64, wheel_bits: u32) {
        self.wheel_nm = self.wheel_nm.wrapping_add(wheel_nm);
        let Some(last) = self.last_teeth.replace(hall.teeth) else {
            self.last_pitches_q16 = hall.pitches_q16;
            return;
        };
        let new = hall.teeth.wrapping_sub(last);
        let pitches = u64::from(hall.pitches_q16.wrapping_sub(self.last_pitches_q16));
        self.last_pitches_q16 = hall.pitches_q16;
        if new == 0 {
            return;
        }
        let Some(k1) = hall.k1_q30 else {
            return;
        };
        // Q16 pitches × nm per pitch × k1 (Q30).
        let nm = kinematics::mul_shr(pitches.saturating_mul(EDGE_NM), k1, 46).unwrap_or(0);
        self.track_nm = self.track_nm.wrapping_add(nm);
        self.rev_teeth = self.rev_teeth.saturating_add(new);
        if self.rev_teeth < TEETH {
            return;
        }
        self.rev_teeth = self.rev_teeth.saturating_sub(TEETH);
        // The wheel at the edge: its distance now less what it rolled since.
        let since = u64::from(hall.since_edge_us.min(1 << 24));
        let back = u64::from(wheel_bits).wrapping_mul(since).wrapping_mul(1000) >> 24;
        let point = (self.track_nm, self.wheel_nm.wrapping_sub(back));
        if self.ring_len > SLIP_REVOLUTIONS {
            self.ring.copy_within(1.., 0);
            self.ring_len = SLIP_REVOLUTIONS;
        }
        if let Some(slot) = self.ring.get_mut(self.ring_len) {
            *slot = point;
            self.ring_len = self.ring_len.saturating_add(1);
        }
        if self.ring_len >= 2 {
            let (t0, w0) = self.ring[0];
            let dt = point.0.wrapping_sub(t0);
            let dw = point.1.wrapping_sub(w0);
            if let Some(r) = dw.saturating_mul(2000).checked_div(dt) {
                // 1000 − 1000·dw/dt, rounded (dw, dt < 2⁴⁴ over 3 turns).
                let ratio = i16::try_from(r.div_ceil(2).min(2000)).unwrap_or(2000);
                self.slip_x10 = Some(1000i16.wrapping_sub(ratio));
            }
        }
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
    use super::*;

    const CPM: u32 = crate::settings::wheel::NOMINAL_COUNTS_PER_M_X1000;

    /// A machine at `v` m/s with the track slipping `slip`: the wheel counts
    /// the ground, the Hall gear the track (25 teeth, π·0.20 m a turn, k1 =
    /// 1). `wheel_stops_at`/`hall_stops_at` (s) kill one of them.
    struct Rig {
        g: Ground,
        settings: GroundWheelSettings,
        t_us: u64,
        v: f64,
        slip: f64,
        ground_m: f64,
        track_m: f64,
        teeth: u32,
        last_edge_us: Option<u64>,
        wheel_stops_at: f64,
        hall_stops_at: f64,
        measured_nm: u64,
    }

    impl Rig {
        fn new(source: TravelSource, v: f64, slip: f64) -> Self {
            Self {
                g: Ground::new(),
                settings: GroundWheelSettings {
                    source,
                    ..GroundWheelSettings::default()
                },
                t_us: 0,
                v,
                slip,
                ground_m: 0.0,
                track_m: 0.0,
                teeth: 0,
                last_edge_us: None,
                wheel_stops_at: f64::INFINITY,
                hall_stops_at: f64::INFINITY,
                measured_nm: 0,
            }
        }

        fn period(&mut self) -> Option<GroundStep> {
            self.t_us += 10_000;
            let t = self.t_us as f64 / 1e6;
            self.ground_m += self.v * 0.01;
            self.track_m += self.v / (1.0 - self.slip) * 0.01;
            let pitch = core::f64::consts::PI * 0.20 / 25.0;
            while (f64::from(self.teeth) + 1.0) * pitch <= self.track_m {
                self.teeth += 1;
                if t < self.hall_stops_at {
                    let into = (self.track_m - f64::from(self.teeth) * pitch)
                        / (self.v / (1.0 - self.slip));
                    self.last_edge_us = Some(self.t_us - (into * 1e6) as u64);
                }
            }
            if t < self.wheel_stops_at {
                let counts = (self.ground_m * f64::from(CPM) / 1000.0).floor() as i64;
                self.g.wheel_count((counts.rem_euclid(65_536)) as u16);
            }
            let counted = if t < self.hall_stops_at {
                self.teeth
            } else {
                self.g.last_teeth.unwrap_or(0)
            };
            let track_bits = (self.v / (1.0 - self.slip) * f64::from(1u32 << 24)) as u32;
            let hall_on = t < self.hall_stops_at;
            let view = HallView {
                teeth: counted,
                pitches_q16: counted << 16,
                travel_bits: if hall_on {
                    (self.v * f64::from(1u32 << 24)) as u32
                } else {
                    0
                },
                track_bits: if hall_on { track_bits } else { 0 },
                k1_q30: Some(1 << 30),
                since_edge_us: self
                    .last_edge_us
                    .map_or(u32::MAX, |e| (self.t_us - e) as u32),
            };
            let s = self.g.step(&self.settings, &view, 10_000, 10_000);
            if let Some(s) = s {
                self.measured_nm += s.distance_nm;
            }
            s
        }
    }

    #[test]
    fn the_hall_gear_alone_leaves_the_ground_to_the_supervisor() {
        let mut r = Rig::new(TravelSource::HallGear, 0.1, 0.04);
        for _ in 0..100 {
            assert_eq!(r.period(), None);
        }
        assert_eq!(r.g.in_use(), TravelSourceInUse::HallGear);
    }

    #[test]
    fn the_live_slip_is_the_models_within_a_tenth_of_a_point() {
        for &(v, slip) in &[(0.086, 0.028), (0.14, 0.04), (0.45, 0.059), (0.3, 0.0)] {
            let mut r = Rig::new(TravelSource::Both, v, slip);
            // The first reading is the odometer's reference.
            r.period();
            let g0 = r.ground_m;
            for _ in 0..6000 {
                r.period();
            }
            r.ground_m -= g0;
            let got = f64::from(r.g.slip_x10().expect("measured")) / 10.0;
            assert!(
                (got - slip * 100.0).abs() <= 0.1,
                "v {v} slip {slip}: {got} %"
            );
            assert_eq!(r.g.fault(), None);
            // The ground is the wheel's, to the count.
            let err_mm = (r.measured_nm as f64 / 1e6) - r.ground_m * 1000.0;
            assert!(err_mm.abs() < 0.5, "{err_mm} mm");
        }
    }

    #[test]
    fn a_wheel_that_stops_while_the_hall_turns_is_said_within_half_a_second_and_the_hall_stands_in()
    {
        for &v in &[0.086f64, 0.14, 0.45, 1.0] {
            let mut r = Rig::new(TravelSource::Both, v, 0.04);
            r.wheel_stops_at = 20.0;
            let mut said = None;
            for _ in 0..3000 {
                r.period();
                if said.is_none() && r.g.fault() == Some(GroundFault::WheelStopped) {
                    said = Some(r.t_us as f64 / 1e6 - 20.0);
                }
            }
            let said = said.expect("said");
            assert!(said <= 0.5, "v {v}: {said} s");
            assert_eq!(r.g.in_use(), TravelSourceInUse::HallStandIn);
            // The ground went on at the Hall gear's speed × (1 − slip): the
            // stand-in's 10 s are within 1 % of the true ground.
            let err = r.measured_nm as f64 / 1e9 - r.ground_m;
            assert!(err.abs() < 0.01 * v * 10.0 + 0.002, "v {v}: {err} m");
        }
    }

    #[test]
    fn a_clod_that_lifts_the_wheel_for_200_ms_costs_no_distance_and_no_alarm() {
        let mut r = Rig::new(TravelSource::Both, 0.14, 0.04);
        for k in 0..4000 {
            let t = f64::from(k) * 0.01;
            // 200 ms of no counts every 5 s, then the wheel reads the ground
            // again minus what it missed (it did not turn).
            r.wheel_stops_at = if (t % 5.0) > 4.8 { 0.0 } else { f64::INFINITY };
            r.period();
            assert_eq!(r.g.fault(), None, "t {t}");
        }
    }

    #[test]
    fn a_hall_gear_that_stops_while_the_wheel_rolls_is_said_within_half_a_second() {
        for &v in &[0.086f64, 0.14, 0.45] {
            let mut r = Rig::new(TravelSource::Both, v, 0.0);
            r.hall_stops_at = 20.0;
            let mut said = None;
            for _ in 0..2500 {
                r.period();
                if said.is_none() && r.g.fault() == Some(GroundFault::HallStopped) {
                    said = Some(r.t_us as f64 / 1e6 - 20.0);
                }
            }
            let said = said.expect("said");
            assert!(said <= 0.5, "v {v}: {said} s");
            assert_eq!(r.g.in_use(), TravelSourceInUse::GroundWheel);
        }
    }

    #[test]
    fn a_wheel_counting_backwards_is_a_fault_of_the_wheel_alone() {
        let mut r = Rig::new(TravelSource::GroundWheel, 0.14, 0.0);
        r.settings.reversed = true;
        let mut first = None;
        for _ in 0..200 {
            let s = r.period().expect("wheel");
            assert_eq!(s.distance_nm, 0);
            if first.is_none() && r.g.fault() == Some(GroundFault::WheelBackwards) {
                first = Some(r.t_us);
            }
        }
        // 100 counts at 0.14 m/s: 0.23 s.
        assert!(first.expect("said") <= 300_000);
    }
}
