//! Distance-locked planting: a phase loop around the drum's speed
//! loop (profile A, Speed-Adaptive).
//!
//! The speed loop (eq. 7 feed-forward + the fuzzy PID) matches the drum's
//! *speed* to the travel speed; any lag or bias of it stays in the row as a
//! position error. The phase loop knows two positions, both since Start:
//!
//! - the **ground distance** `g`: Hall edges × the calibrated distance per
//!   edge (π·0.20 m / 25 · k1 · k2 at the current speed), exact at each
//!   edge; between edges the newest edge plus the travel speed of the last
//!   M/T window (the supervisor passes the estimator's value, not the
//!   predictor's slope-carried one) × the time since it. That reaches the
//!   next edge's position exactly when the estimator calls the edge late
//!   (later than the last gap), so a late edge needs no rule of its own.
//!   Never beyond the next edge's position, never backwards. The first Hall
//!   edge after Start is the origin (`g` = 0): where the wheel stood between two teeth at Start
//!   is unknown, so counting that first edge as a whole pitch would put up to
//!   25 mm of error into every plant of the pass.
//! - the **belt position** `b`: drum encoder counts × belt per count
//!   (π·0.070 m / counts per turn) × k3 at the speed they were turned.
//!   Partition `n` leaves when `b` passes `n · Lclap` (the belt is taken to be
//!   at a partition boundary at Start, as the plant count always assumed).
//!
//! A reference line ties them: the next partition (belt boundary `b_ref`)
//! shall leave at ground `g_ref`, then one every `X`. The phase error is the
//! belt's distance from that line, `e = (b − b_ref) − (g − g_ref)·Lclap/X`
//! (positive: the belt is ahead), and the drum's set point becomes
//! `n = n_ff − e / T · 60 / (π·0.070 m)` with `T` = [`PHASE_TIME_CONSTANT_MS`]:
//! a proportional position loop whose output is a speed offset on top of the
//! feed-forward; the fuzzy PID still holds the drum on that set point.
//!
//! **Bounded recovery.** The offset is limited to +[`MAX_SPEED_UP_PCT`] %
//! and −[`MAX_SLOW_DOWN_PCT`] % of the feed-forward speed. A drum running
//! `1 + u` times the matched speed sets plants `X / (1 + u)` apart, so +10 %
//! keeps every spacing ≥ X / 1.1 = 0.909 X (the rule: no spacing below
//! 0.9 X); −33 % keeps it ≤ X / 0.67 = 1.49 X, below the 1.5 X of a miss
//! (ISO 7256-1). Before the first partition of a pass leaves there is no
//! earlier plant to crowd, so the drum may sprint up to +100 % to reach the
//! first place. At rest (feed-forward 0) there is no correction: the drum
//! waits for the ground. A rest (travel speed 0, also the first edge after
//! it, whose speed is not known yet) gives the next plant the same
//! allowance: the plant before the rest lies behind, and the belt stood
//! while the tractor moved to the first edges after it, so the restart's lag
//! is caught up before that plant rather than over many spacings at 0.91 X
//! (bench §9: stop-and-go phase p95 7.4 → 6.0 mm at 7 cm Low 1). It can
//! crowd that plant only by the phase error the belt had when the tractor
//! came to rest.
//!
//! **Holding at the boundary.** The ground is never known beyond the next
//! Hall edge's place. When the next partition's place lies beyond it (the
//! edge is late: the tractor slows, stops, or the sensor died) and the belt
//! would reach that partition's boundary within [`HOLD_LOOKAHEAD_MS`] at
//! the drum's speed, the drum is commanded to rest ([`Phase::must_hold`]):
//! the plant waits at the boundary until the edge shows the ground there,
//! and is not dropped at a place the machine may never reach. The phase
//! loop alone may only slow the drum by 33 %, and on a decaying speed the
//! belt crept past the frozen ground and dropped the plant up to 28 mm late
//! when the sensor had died while moving.
//!
//! **First plant.** Start calls [`Phase::realign`] with the place of the
//! first plant, [`first_plant_place_um`]: `X` plus one Hall pitch past the
//! origin, i.e. `X` after the second Hall edge after Start — the first point
//! at which the firmware knows the travel speed (the first M/T window
//! closes). Placing it at `X` after the origin would ask the drum to make up
//! a whole edge of lag in less than a spacing (at 7 cm and Low 2 beyond
//! `n_max`).
//!
//! All arithmetic is integer (nm, u64/i64, saturating); the ground distance
//! in nm wraps after 1.8·10¹⁰ m, 380 000 working days of 12 h at 4 km/h.

use fuzzy_pid::I16F16;

/// Track per Hall edge at k1 = k2 = 1: π·0.20 m / 25 = 25 132 741 nm.
pub const EDGE_NM: u64 = 25_132_741;
/// Belt per partition, `Lclap` = 50 mm.
pub const PARTITION_NM: u64 = 50_000_000;
/// Belt per drum turn: π·(D2 + 2·H2) = π·0.070 m = 219 911 486 nm.
pub const BELT_PER_TURN_NM: u64 = 219_911_486;
/// One Hall pitch at k1 = k2 = 1 in Q8 nm: 25 132 741.229 nm × 256,
/// rounded (π·0.20 m / 25 in f64).
pub const EDGE_NM_Q8: u64 = 6_433_981_755;
/// Belt per drum turn in Q16 nm: 219 911 485.751 nm × 65 536, rounded.
const BELT_PER_TURN_NM_Q16: u64 = 14_412_119_130_196;
/// The k1·k2 product in Q30 (U2F30 × U2F30, kept to the type's
/// precision: the tables hold k to 2⁻³⁰, and the product is cut once, at
/// 2⁻³⁰ ≈ 10⁻⁹).
pub fn k1k2_q30(k1: kinematics::units::Coefficient, k2: kinematics::units::Coefficient) -> u64 {
    // Each < 2³² (U2F30 bits): the product < 2⁶⁴.
    u64::from(k1.to_bits()).wrapping_mul(u64::from(k2.to_bits())) >> 30
}
/// Time constant of the phase loop, ms: a phase error decays as
/// `e^(−t/T)` while the correction is within its bounds. 0.5 s: five times
/// the speed loop's settling (bench §1, 0.10 s), so the two loops do not
/// fight, and short enough that a phase lost at a speed step is back within
/// 1 mm in about two spacings at Low 2 and 7 cm.
pub const PHASE_TIME_CONSTANT_MS: u64 = 500;
/// The phase loop's time constant with a fine ground sensor (the ground
/// wheel, [`Phase::set_fine_ground`]), ms: the ground is known every 0.33 mm
/// and every control period, so the loop may follow it closely (tuned on
/// bench §12).
pub const FINE_PHASE_TIME_CONSTANT_MS: u64 = 60;
/// Largest speed-up over the feed-forward with a fine ground sensor, %: the
/// +10 % bound keeps spacings from a Hall gear's 25 mm steps of measured
/// ground; a ground without steps needs the room to catch up a restart from
/// rest (bench §12, stop-and-go); spacings stay above X / 1.4 = 0.71 X, far
/// from a multiple (≤ 0.5 X).
pub const FINE_MAX_SPEED_UP_PCT: i32 = 40;
/// Largest speed-up of the drum over the feed-forward, % (no spacing below
/// X / 1.1 = 0.909 X; module docs).
pub const MAX_SPEED_UP_PCT: i32 = 10;
/// Largest slow-down of the drum below the feed-forward, % (no spacing above
/// X / 0.67 = 1.49 X; module docs).
pub const MAX_SLOW_DOWN_PCT: i32 = 33;
/// [`MAX_SPEED_UP_PCT`] and [`MAX_SLOW_DOWN_PCT`] in Q16, rounded down (the
/// bounds come out at most 0.002 % tighter).
#[allow(clippy::arithmetic_side_effects)]
const UP_Q16: i64 = (MAX_SPEED_UP_PCT as i64) * 65_536 / 100;
#[allow(clippy::arithmetic_side_effects)]
const DOWN_Q16: i64 = (MAX_SLOW_DOWN_PCT as i64) * 65_536 / 100;
/// Belt run before the origin that marks a Start on the move (the drum
/// already turning on the feed-forward), nm: 1 mm, far above an encoder
/// count's 4.7 µm and a standing drum's jitter.
const ROLLING_START_NM: u64 = 1_000_000;
/// No Hall edge for this long, µs, counts as a rest even before the
/// estimator's 1.5 s stop timeout: below 25 mm/s (0.09 km/h), a third of
/// the slowest working speed (0.30 km/h, one edge every 0.30 s); a tractor
/// crawling slower gets the first plant's allowance at every edge. A 2 s stop often ends before the timeout has run from the
/// last edge before it, and the rest's lag then deserves the same allowance
/// (bench §9: stop-and-go at Low 2 phase p95 16.6 / 15.5 → 12.0 / 8.2 mm).
const REST_US: u32 = 1_000_000;
/// How far ahead of the belt a partition boundary counts as reached, ms
/// of the drum's measured speed: a control period, the drive's dead time
/// and the drum's run-down after a zero command (τ 25 ms) with room to
/// spare ([`Phase::must_hold`]).
pub const HOLD_LOOKAHEAD_MS: u64 = 50;
/// Belt per r/min over [`HOLD_LOOKAHEAD_MS`], nm: 219 911 486 nm / 60 000 ms
/// × 50 ms = 183 260 nm.
const HOLD_NM_PER_RPM: u64 = BELT_PER_TURN_NM * HOLD_LOOKAHEAD_MS / 60_000;
/// A standing drum holds this short of the boundary, nm (the encoder's
/// jitter and a few counts of run-down: 0.5 mm).
const HOLD_MARGIN_NM: u64 = 500_000;
/// Events kept per control step: at most one partition leaves per 10 ms
/// below 150 r/min; four leave room for a step released late.
const MAX_EVENTS: usize = 4;

/// The drum speed offset per nm of phase error, I16F16 bits × 2¹⁶:
/// `2³² · 60 / (T · π·0.070 m)` = 2343.65 → 2344 (`T` = 0.4999 s).
// Note: evaluated at compile time; 60·2³²·1000 < 2⁶⁴ and the result
// (2344) fits any integer type.
#[allow(clippy::cast_possible_wrap, clippy::arithmetic_side_effects)]
const GAIN_Q16: i64 = gain_q16(PHASE_TIME_CONSTANT_MS);
/// [`GAIN_Q16`] at [`FINE_PHASE_TIME_CONSTANT_MS`].
const FINE_GAIN_Q16: i64 = gain_q16(FINE_PHASE_TIME_CONSTANT_MS);
/// [`FINE_MAX_SPEED_UP_PCT`] in Q16.
#[allow(clippy::arithmetic_side_effects)]
const FINE_UP_Q16: i64 = (FINE_MAX_SPEED_UP_PCT as i64) * 65_536 / 100;

/// `2³² · 60 / (T · π·0.070 m)` for a time constant `t_ms` (compile time).
#[allow(clippy::cast_possible_wrap, clippy::arithmetic_side_effects)]
const fn gain_q16(t_ms: u64) -> i64 {
    let g = (60u64 << 32) * 1000 / t_ms;
    ((g + BELT_PER_TURN_NM / 2) / BELT_PER_TURN_NM) as i64
}

/// A partition that left the drum, with the ground distance since Start at
/// that moment (µm).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlantEvent {
    /// Ground distance since Start, µm ([`Phase::ground_um`]).
    pub ground_distance_um: u64,
}

/// The place of the first plant after Start, µm of ground since Start:
/// one spacing plus one Hall pitch (module docs).
pub fn first_plant_place_um(spacing_mm: u16) -> u64 {
    u64::from(spacing_mm)
        .saturating_mul(1000)
        .saturating_add(EDGE_NM / 1000)
}

/// The place of the first plant after Start with a fine ground sensor (the
/// ground wheel), µm of ground since its first count: one spacing. The
/// wheel gives the travel speed within a few control periods of moving, so
/// the drum needs no Hall pitch of allowance.
pub fn first_plant_place_fine_um(spacing_mm: u16) -> u64 {
    u64::from(spacing_mm).saturating_mul(1000)
}

/// The phase loop's state (module docs).
#[derive(Clone, Copy, Debug)]
pub struct Phase {
    /// Belt per encoder count at k3 = 1, Q16 nm: precomputed per hardware
    /// ([`Phase::new`]).
    belt_q16_per_count: u64,
    /// Plant spacing, nm, and `Lclap / X` × 2²⁴ (per setting).
    x_nm: u64,
    l_over_x_q24: u64,
    /// The first Hall edge after Start passed (the origin).
    armed: bool,
    /// The supervisor's edge counter and its pitch sum (Q16) at the last
    /// step.
    edges_seen: u32,
    pitches_seen_q16: u32,
    /// One nominal pitch of ground at the last known speed (× k1·k2), Q8 nm.
    edge_q8: u64,
    /// Ground at the last edge (Q8 nm), and now (extrapolated, nm).
    ground_edges_q8: u64,
    ground_nm: u64,
    /// The next edge's place: as far as the ground can be known, nm.
    reach_nm: u64,
    /// The ground at the end of the last [`Phase::advance_belt`] (the start
    /// of this step), nm: a partition's ground is interpolated in the step.
    step_ground_nm: u64,
    /// Belt since Start, nm, and the remainder of its division.
    belt_nm: u64,
    belt_rem: u64,
    /// Partitions that left since Start.
    left: u32,
    /// The reference line: belt boundary `b_ref` leaves at ground `g_ref`.
    ref_belt_nm: u64,
    ref_ground_nm: u64,
    /// A partition left since the last realignment (the +10 % bound holds).
    pass_started: bool,
    /// The last phase error, belt nm (positive: belt ahead).
    error_nm: i64,
    /// The last step's events (ground µm).
    events: [u64; MAX_EVENTS],
    n_events: u8,
    /// The ground comes from a fine sensor (the ground wheel): the
    /// [`FINE_PHASE_TIME_CONSTANT_MS`] and [`FINE_MAX_SPEED_UP_PCT`] tuning.
    fine: bool,
    /// The next partition waits at its boundary ([`Phase::must_hold`]).
    holding: bool,
}

impl Phase {
    /// A phase loop for `counts_per_turn` encoder counts per drum turn and a
    /// spacing of `spacing_mm`.
    pub fn new(counts_per_turn: u32, spacing_mm: u16) -> Self {
        // ≤ 7.3·10¹² (< 2⁴³) for ≥ 2 counts per turn.
        let q16 = BELT_PER_TURN_NM_Q16
            .checked_div(u64::from(counts_per_turn.max(2)))
            .unwrap_or(0);
        let mut p = Self {
            belt_q16_per_count: q16,
            x_nm: 0,
            l_over_x_q24: 0,
            armed: false,
            edges_seen: 0,
            pitches_seen_q16: 0,
            edge_q8: EDGE_NM_Q8,
            ground_edges_q8: 0,
            ground_nm: 0,
            reach_nm: 0,
            step_ground_nm: 0,
            belt_nm: 0,
            belt_rem: 0,
            left: 0,
            ref_belt_nm: PARTITION_NM,
            ref_ground_nm: 0,
            pass_started: false,
            error_nm: 0,
            events: [0; MAX_EVENTS],
            n_events: 0,
            fine: false,
            holding: false,
        };
        p.set_spacing(spacing_mm);
        p
    }

    /// The ground comes from a fine sensor (the ground wheel) or from the
    /// Hall gear: the loop's tuning (module docs, "Bounded recovery").
    pub fn set_fine_ground(&mut self, fine: bool) {
        self.fine = fine;
    }

    /// A new spacing (precomputes `Lclap / X`).
    #[inline(never)]
    pub fn set_spacing(&mut self, spacing_mm: u16) {
        self.x_nm = u64::from(spacing_mm).saturating_mul(1_000_000).max(1);
        self.l_over_x_q24 = (PARTITION_NM << 24).checked_div(self.x_nm).unwrap_or(0);
    }

    /// Start: positions from zero; `edges` is the supervisor's edge
    /// counter. The caller then places the first plant ([`Phase::realign`]
    /// with [`first_plant_place_um`]).
    #[inline(never)]
    pub fn start(&mut self, edges: u32, pitches_q16: u32) {
        *self = Self {
            edges_seen: edges,
            pitches_seen_q16: pitches_q16,
            ..Self::new_like(self)
        };
    }

    fn new_like(other: &Self) -> Self {
        Self {
            armed: false,
            edges_seen: 0,
            pitches_seen_q16: 0,
            edge_q8: EDGE_NM_Q8,
            ground_edges_q8: 0,
            ground_nm: 0,
            reach_nm: 0,
            step_ground_nm: 0,
            belt_nm: 0,
            belt_rem: 0,
            left: 0,
            ref_belt_nm: PARTITION_NM,
            ref_ground_nm: 0,
            pass_started: false,
            error_nm: 0,
            events: [0; MAX_EVENTS],
            n_events: 0,
            holding: false,
            ..*other
        }
    }

    /// The next partition to leave shall leave at ground `at_um` (µm since
    /// Start), then one every `X`; a new pass (the first plant may be
    /// reached with a sprint, module docs).
    #[inline(never)]
    pub fn realign(&mut self, at_um: u64) {
        self.ref_belt_nm = self.next_boundary_nm();
        self.ref_ground_nm = at_um.saturating_mul(1000);
        self.pass_started = false;
    }

    /// Ground distance since Start, µm.
    #[inline(never)]
    pub fn ground_um(&self) -> u64 {
        self.ground_nm / 1000
    }

    /// Belt since Start, µm: the drum encoder's counts × belt per count ×
    /// k3 at the speed they were turned.
    pub fn belt_um(&self) -> u64 {
        self.belt_nm / 1000
    }

    /// Ground distance since Start at the newest Hall edge counted, nm
    /// (edge-locked, without the extrapolation since that edge).
    pub fn ground_at_edge_nm(&self) -> u64 {
        self.ground_edges_q8 >> 8
    }

    /// The last phase error in ground µm (positive: the belt is ahead of the
    /// ground, plants land short of their places).
    pub fn error_ground_um(&self) -> i64 {
        // e · X / Lclap: |e| ≤ 2⁴⁰ nm after the clamp, X ≤ 10⁹ nm / 5·10⁷.
        let x_per_l = i64::try_from(self.x_nm / 1000).unwrap_or(i64::MAX);
        self.error_nm
            .clamp(-(1 << 40), 1 << 40)
            .saturating_mul(x_per_l)
            / 50_000_000
    }

    /// A partition left since the last realignment (a Start, a lowering, a
    /// rest): the pass's first plant is down.
    pub fn pass_started(&self) -> bool {
        self.pass_started
    }

    /// The next partition's place lies beyond the next Hall edge's: the
    /// ground cannot be known there before that edge comes.
    pub fn next_place_beyond_reach(&self) -> bool {
        self.armed && self.ref_ground_nm > self.reach_nm
    }

    /// Whether the next partition must wait at its boundary: its place
    /// lies beyond the next Hall edge's (the ground is not known to reach
    /// it) and the belt, turning at `drum` r/min, came within
    /// [`HOLD_LOOKAHEAD_MS`] of the boundary (module docs, "Holding at the
    /// boundary"). Once the belt came that near, it holds until an edge
    /// shows the ground at the place or the partition left (a drum slowing
    /// down would otherwise see the boundary recede, start again and creep
    /// over it). Ask it every control period.
    pub fn must_hold(&mut self, drum: I16F16) -> bool {
        if !self.next_place_beyond_reach() {
            self.holding = false;
            return false;
        }
        if self.holding {
            return true;
        }
        let to_boundary = self.next_boundary_nm().saturating_sub(self.belt_nm);
        // r/min (I16F16 bits, < 2³¹) × belt nm per r/min over the look-ahead
        // (< 2¹⁸): < 2⁴⁹.
        let rpm_bits = u64::try_from(drum.to_bits().max(0)).unwrap_or(0);
        let ahead = rpm_bits.saturating_mul(HOLD_NM_PER_RPM) >> 16;
        self.holding = to_boundary <= ahead.saturating_add(HOLD_MARGIN_NM);
        self.holding
    }

    /// The belt position at which the next partition leaves, nm (2³²
    /// partitions of 50 mm < 2⁵⁸ nm).
    fn next_boundary_nm(&self) -> u64 {
        u64::from(self.left)
            .saturating_add(1)
            .saturating_mul(PARTITION_NM)
    }

    /// Partitions that left since Start.
    pub fn partitions_left(&self) -> u32 {
        self.left
    }

    /// The last step's events.
    pub fn events(&self) -> impl Iterator<Item = PlantEvent> + '_ {
        self.events
            .iter()
            .take(usize::from(self.n_events))
            .map(|&g| PlantEvent {
                ground_distance_um: g,
            })
    }

    /// Clears the last step's events (at the start of a control step).
    pub fn clear_events(&mut self) {
        self.n_events = 0;
    }

    /// Advances the ground: `edges` is the supervisor's edge counter and
    /// `pitches_q16` the sum of those edges' learned pitches (Q16: 65 536 a
    /// nominal pitch; the Hall gear's teeth are not evenly spaced, and the
    /// speed estimator learns each gap's share of a revolution,
    /// [`kinematics::speed::MtEstimator::newest_gap_pitches_q16`]),
    /// `next_pitch_q16` the learned pitch of the gap the gear is in now (the
    /// extrapolation stops at its end, the next edge's place),
    /// `since_edge_us` the time since the newest edge, `travel` the travel
    /// speed of the last M/T window (`MetresPerSecond` bits, U8F24; 0 at
    /// rest) and `k1k2_q30` the product of k1 and k2 at it in Q30
    /// ([`k1k2_q30`]; `None` when no speed is known: the last is kept).
    #[inline(never)]
    pub fn advance_ground(
        &mut self,
        edges: u32,
        pitches_q16: u32,
        next_pitch_q16: u32,
        since_edge_us: u32,
        travel: u32,
        k1k2_q30: Option<u64>,
    ) {
        if let Some(k) = k1k2_q30 {
            // Q8 nm × Q30 → Q8 nm. k1·k2 is taken to at most 2 (the tables
            // hold 0.8 … 1.2), so the product stays below 2⁶⁴.
            self.edge_q8 = EDGE_NM_Q8.wrapping_mul(k.min(2 << 30)) >> 30;
        }
        let new = edges.wrapping_sub(self.edges_seen);
        self.edges_seen = edges;
        let mut new_q16 = u64::from(pitches_q16.wrapping_sub(self.pitches_seen_q16));
        self.pitches_seen_q16 = pitches_q16;
        if !self.armed && new > 0 {
            // The origin: the first edge counts nothing (of several in the
            // step, the mean pitch is taken off).
            new_q16 = new_q16.saturating_sub(new_q16.checked_div(u64::from(new)).unwrap_or(0));
            self.arm();
        }
        if !self.armed {
            return;
        }
        if travel == 0 || since_edge_us > REST_US {
            // At rest ([`REST_US`]; or the first edge after it, speed not
            // known yet): the plant before the rest lies behind, so the first plant
            // after the restart gets the first plant's allowance (+100 %,
            // T/2) to absorb the lag of the restart (module docs).
            self.pass_started = false;
        }
        // Q16 pitches (at most 2¹² teeth a step) × Q8 nm per pitch (below
        // 2³⁵), cut to Q8 once per step.
        self.ground_edges_q8 = self
            .ground_edges_q8
            .saturating_add(new_q16.min(1 << 28).wrapping_mul(self.edge_q8) >> 16);
        // From the newest edge (exact) with the time since it: m/s (U8F24)
        // · µs = nm / 1000. The speed clamped to 16 m/s (58 km/h, beyond the
        // Hall switch's 1 kHz) and the time to 16.7 s (beyond any edge at a
        // speed that moves the ground) keep the product < 2⁶².
        let extra = u64::from(travel.min(1 << 28))
            .wrapping_mul(1000)
            .wrapping_mul(u64::from(since_edge_us.min(1 << 24)))
            >> 24;
        // Never past the next edge's place: the gap's own learned pitch.
        // (A pitch below 2¹⁸ in Q16 × edge_q8 below 2³⁵: below 2⁵³.)
        let next_q8 = u64::from(next_pitch_q16.min(1 << 18)).wrapping_mul(self.edge_q8) >> 16;
        let edges_nm = self.ground_edges_q8 >> 8;
        let cap = edges_nm.saturating_add(next_q8 >> 8);
        self.reach_nm = cap;
        let g = edges_nm.saturating_add(extra).min(cap);
        self.ground_nm = self.ground_nm.max(g);
    }

    /// Advances the ground by `distance_nm` measured this step by a sensor
    /// that resolves it finely (the ground wheel, docs/ground-wheel.md), at
    /// the travel speed `travel` (`MetresPerSecond` bits, 0 at rest). The
    /// first step that moves after Start is the origin (its own distance
    /// counts nothing, as the Hall gear's first edge); the next partition's
    /// place can always be reached (no edge to wait for).
    #[inline(never)]
    pub fn advance_ground_by(&mut self, distance_nm: u64, travel: u32) {
        if !self.armed {
            if distance_nm == 0 {
                return;
            }
            self.arm();
        } else {
            self.ground_nm = self.ground_nm.saturating_add(distance_nm);
        }
        if travel == 0 {
            // At rest: the first plant after it gets the first plant's
            // allowance (module docs).
            self.pass_started = false;
        }
        self.ground_edges_q8 = self.ground_nm << 8;
        self.reach_nm = u64::MAX;
    }

    /// The origin: the ground from here; a rolling Start keeps the belt's
    /// phase (module docs).
    fn arm(&mut self) {
        self.armed = true;
        if self.belt_nm > ROLLING_START_NM && !self.pass_started {
            // Started on the move: the drum ran on the feed-forward
            // before the origin. Its phase here is kept (the next
            // partition's place is where the matched belt puts it), so
            // a rolling Start neither stalls nor sprints the drum.
            let to_boundary = self.ref_belt_nm.saturating_sub(self.belt_nm);
            self.ref_ground_nm = to_boundary.saturating_mul(self.x_nm) / PARTITION_NM;
        }
    }

    /// Advances the belt by `counts` encoder counts turned at belt slip
    /// `k3` (its full U2F30 precision); records the partitions that left.
    #[inline(never)]
    pub fn advance_belt(&mut self, counts: u16, k3: kinematics::units::Coefficient) {
        // counts · k3 (Q30) < 2⁴⁸, × the Q16 belt per count (< 2⁴³), cut
        // once to Q16 nm (< 2⁶¹: 65 535 counts of 4.7 mm), remainder kept.
        let acc = kinematics::mul_shr(
            u64::from(counts).wrapping_mul(u64::from(k3.to_bits())),
            self.belt_q16_per_count,
            30,
        )
        .unwrap_or(u64::MAX >> 1)
        .wrapping_add(self.belt_rem);
        let belt_before = self.belt_nm;
        self.belt_nm = self.belt_nm.saturating_add(acc >> 16);
        self.belt_rem = acc & 0xFFFF;
        // The step's ground, for interpolating when each partition left
        // (at the step's end it is up to 10 ms late: 1.4 mm at Low 2, which
        // the screen's CV would count).
        let (g0, g1) = (self.step_ground_nm.min(self.ground_nm), self.ground_nm);
        self.step_ground_nm = g1;
        for _ in 0..MAX_EVENTS {
            let boundary = self.next_boundary_nm();
            if self.belt_nm < boundary {
                break;
            }
            self.left = self.left.saturating_add(1);
            // A new boundary: not reached yet.
            self.holding = false;
            // g0 + (g1 − g0)·(boundary − b0)/(b1 − b0): a step moves the
            // ground < 2²⁶ nm (67 m/s) and the belt < 2³² nm, so the
            // product < 2⁵⁸.
            let g = g0
                .wrapping_add(
                    g1.saturating_sub(g0)
                        .min(1 << 26)
                        .wrapping_mul(boundary.saturating_sub(belt_before).min(1 << 32))
                        .checked_div(self.belt_nm.saturating_sub(belt_before))
                        .unwrap_or(0),
                )
                .min(g1)
                / 1000;
            if let Some(slot) = self.events.get_mut(usize::from(self.n_events)) {
                *slot = g;
                self.n_events = self.n_events.saturating_add(1);
            }
            if self.belt_nm >= self.ref_belt_nm {
                self.ref_belt_nm = self.ref_belt_nm.saturating_add(PARTITION_NM);
                self.ref_ground_nm = self.ref_ground_nm.saturating_add(self.x_nm);
                self.pass_started = true;
            }
        }
    }

    /// The phase error now (belt nm, positive: ahead), kept for
    /// [`Phase::error_ground_um`].
    pub fn update_error(&mut self) -> i64 {
        // Positions below 2⁶³ nm (9·10⁹ km): the differences are exact as
        // two's complement.
        let db = self.belt_nm.wrapping_sub(self.ref_belt_nm).cast_signed();
        let dg = self
            .ground_nm
            .wrapping_sub(self.ref_ground_nm)
            .cast_signed()
            .clamp(-(1 << 36), 1 << 36);
        // |dg| ≤ 2³⁶ nm (68 m: the correction is saturated long before),
        // l/x ≤ 2²⁴ · 50/10 (spacing ≥ 10 mm): the product < 2⁶³.
        let lx = self.l_over_x_q24.min(5 << 24).cast_signed();
        let target = dg.wrapping_mul(lx) >> 24;
        self.error_nm = db
            .clamp(-(1 << 40), 1 << 40)
            .wrapping_sub(target.clamp(-(1 << 40), 1 << 40));
        self.error_nm
    }

    /// The drum speed offset for the feed-forward speed `n_ff` (r/min):
    /// proportional to the phase error, within the bounds (module docs).
    #[inline(never)]
    pub fn correction(&mut self, n_ff: I16F16) -> I16F16 {
        // |e| ≤ 2⁴¹ ([`Phase::update_error`]).
        let e = self.update_error();
        if !self.armed || n_ff <= I16F16::ZERO {
            return I16F16::ZERO;
        }
        // |e| ≤ 2⁴¹, gain < 2¹²: the product < 2⁵³; ff < 2³¹, the bound
        // factors < 2¹⁷: < 2⁴⁸. The bounds in Q16 (no division).
        // Before the pass's first plant: twice the gain (T/2), to absorb
        // the start lag within the first spacing.
        let shift = if self.pass_started { 16 } else { 15 };
        let (gain, up_q16) = if self.fine {
            (FINE_GAIN_Q16, FINE_UP_Q16)
        } else {
            (GAIN_Q16, UP_Q16)
        };
        let raw = e.wrapping_mul(gain).wrapping_neg() >> shift;
        let ff = i64::from(n_ff.to_bits());
        let up = if self.pass_started {
            ff.wrapping_mul(up_q16) >> 16
        } else {
            ff
        };
        let down = ff.wrapping_mul(DOWN_Q16) >> 16;
        let bits = raw.max(down.wrapping_neg()).min(up);
        I16F16::from_bits(i32::try_from(bits).unwrap_or(0))
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_precision_loss,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)]
mod tests {
    use super::*;
    use kinematics::units::Coefficient;

    /// A travel speed in m/h as `MetresPerSecond` bits (U8F24), rounded.
    fn mps(mh: u32) -> u32 {
        u32::try_from(((u64::from(mh) << 24) + 1800) / 3600).unwrap()
    }

    /// A coefficient product in Q30.
    fn q30(k: f64) -> u64 {
        (k * f64::from(1u32 << 30)) as u64
    }

    #[test]
    fn the_gain_is_the_documented_time_constant() {
        // Δn = e / T · 60 / (π·0.070 m): for 1 mm of belt error and
        // T = 0.5 s, 0.001/0.5 · 60 / 0.219 911 486 = 0.545 674 r/min.
        let mut p = Phase::new(47_200, 70);
        p.armed = true;
        p.pass_started = true;
        p.belt_nm = PARTITION_NM - 1_000_000; // 1 mm behind the line at g_ref
        p.ref_ground_nm = 0;
        // Tolerance: the gain is 2343.65 rounded to 2344 (+0.015 %), plus
        // one I16F16 step.
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        let expect = 0.001 / 0.5 * 60.0 / 0.219_911_486;
        assert!((c / expect - 1.0).abs() < 2e-4, "{c} vs {expect}");
        // Before the pass's first plant: T/2, twice the offset.
        p.pass_started = false;
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!(
            (c / (2.0 * expect) - 1.0).abs() < 2e-4,
            "{c} vs {}",
            2.0 * expect
        );
    }

    #[test]
    fn the_correction_is_bounded_by_the_spacing_rule() {
        // A partition already left: +10 % of 20 r/min at most (2 r/min),
        // −33 % (6.6 r/min) at most.
        let mut p = Phase::new(47_200, 70);
        p.armed = true;
        p.pass_started = true;
        p.belt_nm = 0; // 50 mm behind: wants +27 r/min
                       // (Tolerance: the bounds' Q16 factors are rounded down, ≤ 0.002 %
                       // of 20 r/min = 4·10⁻⁴, plus one I16F16 step.)
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!(c <= 2.0 && 2.0 - c < 5e-4, "{c}");
        p.belt_nm = 3 * PARTITION_NM; // far ahead
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!((-6.6..-6.6 + 5e-4).contains(&c), "{c}");
        // At rest: nothing.
        assert_eq!(p.correction(I16F16::ZERO), I16F16::ZERO);
    }

    #[test]
    fn ground_counts_edges_after_the_origin_and_extrapolates_at_most_one_edge() {
        let mut p = Phase::new(47_200, 70);
        p.start(7, 7 << 16);
        p.realign(first_plant_place_um(70));
        // First edge: the origin.
        p.advance_ground(8, 8 << 16, 1 << 16, 0, mps(500), Some(1 << 30));
        assert_eq!(p.ground_um(), 0);
        // 0.5 km/h = 500 m/h for 100 ms = 13 888.9 µm.
        p.advance_ground(8, 8 << 16, 1 << 16, 100_000, mps(500), Some(1 << 30));
        assert_eq!(p.ground_um(), 13_888);
        // A second without an edge: capped at one edge (25 132 µm).
        p.advance_ground(8, 8 << 16, 1 << 16, 1_000_000, mps(500), Some(1 << 30));
        assert_eq!(p.ground_um(), 25_132);
        // Two edges at k1·k2 = 0.98: 2 · 25 132 741 · 0.98 = 49 260 172 nm.
        p.advance_ground(10, 10 << 16, 1 << 16, 0, mps(500), Some(q30(0.98)));
        assert_eq!(p.ground_um(), 49_260);
    }

    #[test]
    fn ground_counts_each_edge_at_its_learned_pitch() {
        // Teeth of a real gear are not evenly spaced: the estimator's learned
        // shares (Q16 pitches) give each edge its own length.
        let mut p = Phase::new(47_200, 70);
        p.start(0, 0);
        p.realign(first_plant_place_um(70));
        // The origin (its own pitch, 1.03, counts nothing).
        p.advance_ground(1, 67_502, 1 << 16, 0, 0, Some(1 << 30));
        assert_eq!(p.ground_um(), 0);
        // Two edges of 0.98 and 1.01 pitches (64 225 + 66 191 = 130 416 Q16
        // = 1.989 99 pitches) × 25 132 675 nm (the pitch at k1·k2 = 1 in
        // advance_ground's Q16 form) = 50 013 778 nm.
        p.advance_ground(3, 67_502 + 64_225 + 66_191, 1 << 16, 0, 0, Some(1 << 30));
        assert_eq!(p.ground_at_edge_nm() / 1000, 50_013);
        // Nominal pitches give the edge count × the pitch, as before.
        let mut n = Phase::new(47_200, 70);
        n.start(0, 0);
        n.advance_ground(1, 1 << 16, 1 << 16, 0, 0, Some(1 << 30));
        n.advance_ground(3, 3 << 16, 1 << 16, 0, 0, Some(1 << 30));
        assert_eq!(n.ground_at_edge_nm(), (2 * EDGE_NM_Q8) >> 8);
    }

    /// A phase past its origin whose next partition is one partition
    /// pitch (50 mm of belt) away with the ground already at its place,
    /// a partition having left (so the +10 % bound applies).
    fn running_a_partition_behind() -> Phase {
        let mut p = Phase::new(47_200, 70);
        p.start(0, 0);
        p.advance_ground(1, 1 << 16, 1 << 16, 0, 0, Some(1 << 30)); // the origin
        p.pass_started = true;
        p.belt_nm = 0;
        p.ref_belt_nm = PARTITION_NM;
        p.ref_ground_nm = 0;
        p
    }

    #[test]
    fn after_a_rest_the_lag_is_recovered_with_the_first_plants_allowance() {
        // Running, a partition already left (+10 % bound): 50 mm behind
        // wants 2 · 0.05/0.5 · 60/0.219 911 = 27.3 r/min, capped at +10 %
        // of 20 r/min = 2 r/min (as `the_correction_is_bounded_...`).
        let mut p = running_a_partition_behind();
        p.advance_ground(1, 1 << 16, 1 << 16, 10_000, mps(500), Some(1 << 30));
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!(c <= 2.0 && 2.0 - c < 5e-4, "{c}");
        // The tractor came to rest (travel 0), then moves again: the
        // first plant after the rest may be reached at up to +100 %
        // (20 r/min) with twice the gain: 2 · 27.3 → capped at 20.
        p.advance_ground(1, 1 << 16, 1 << 16, 2_000_000, 0, Some(1 << 30));
        p.advance_ground(2, 2 << 16, 1 << 16, 10_000, mps(500), Some(1 << 30));
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!((19.999..=20.0).contains(&c), "{c}");
    }

    #[test]
    fn a_second_without_an_edge_is_a_rest_before_the_stop_timeout() {
        // As `after_a_rest_…`, but the estimator still reports a decaying
        // speed (one gap / 1.2 s = 75 m/h) when the tractor moves again:
        // 1.2 s > REST_US counts as a rest, so the first plant after it may
        // be reached at +100 % (20 r/min). Before: the +10 % bound, 2 r/min.
        let mut p = running_a_partition_behind();
        p.advance_ground(1, 1 << 16, 1 << 16, 1_200_000, mps(75), Some(1 << 30));
        p.advance_ground(2, 2 << 16, 1 << 16, 10_000, mps(500), Some(1 << 30));
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!((19.999..=20.0).contains(&c), "{c}");
        // 0.9 s without an edge is not a rest: +10 %.
        let mut p = Phase::new(47_200, 70);
        p.start(0, 0);
        p.advance_ground(1, 1 << 16, 1 << 16, 0, 0, Some(1 << 30));
        p.pass_started = true;
        p.belt_nm = 0;
        p.ref_belt_nm = PARTITION_NM;
        p.ref_ground_nm = 0;
        p.advance_ground(1, 1 << 16, 1 << 16, 900_000, mps(100), Some(1 << 30));
        p.advance_ground(2, 2 << 16, 1 << 16, 10_000, mps(500), Some(1 << 30));
        let c = p.correction(I16F16::from_num(20)).to_num::<f64>();
        assert!(c <= 2.0 && 2.0 - c < 5e-4, "{c}");
    }

    #[test]
    fn belt_events_carry_the_ground_distance() {
        // 47 200 counts per turn at k3 = 1: 219 911 486 / 47 200 =
        // 4659.14 nm per count; 50 mm is 10 731.5 counts.
        let mut p = Phase::new(47_200, 70);
        p.start(0, 0);
        p.realign(first_plant_place_um(70));
        p.advance_ground(1, 1 << 16, 1 << 16, 0, 0, None);
        p.advance_ground(2, 2 << 16, 1 << 16, 0, 0, Some(1 << 30));
        p.clear_events();
        p.advance_belt(10_731, Coefficient::ONE);
        assert_eq!(p.events().count(), 0);
        p.advance_belt(1, Coefficient::ONE);
        let ev: std::vec::Vec<_> = p.events().collect();
        assert_eq!(
            ev,
            [PlantEvent {
                ground_distance_um: 25_132
            }]
        );
        assert_eq!(p.partitions_left(), 1);
    }

    /// The hold at a boundary beyond the known ground: the belt 0.3 mm
    /// short of it holds (at 10 r/min the look-ahead is 1.8 mm), a belt a
    /// partition away does not, and once the belt has come near, a
    /// slowing drum still holds; a partition that leaves starts afresh.
    #[test]
    fn the_hold_is_for_the_boundary_the_belt_came_near() {
        // 47 200 counts a turn: 4659.14 nm a count, 50 mm = 10 731.5.
        let mut p = Phase::new(47_200, 70);
        p.start(0, 0);
        // The first place 95.1 mm past the origin, the ground known to one
        // pitch past it (25.1 mm): beyond reach.
        p.realign(first_plant_place_um(70));
        p.advance_ground(1, 1 << 16, 1 << 16, 0, 0, None);
        assert!(p.next_place_beyond_reach());
        let ten = I16F16::from_num(10);
        // Far from the first boundary: no hold.
        p.advance_belt(5_000, Coefficient::ONE);
        assert!(!p.must_hold(ten));
        // 0.3 mm short (10 731 counts): hold, and still at a crawl.
        p.advance_belt(5_731, Coefficient::ONE);
        assert!(p.must_hold(ten));
        assert!(p.must_hold(I16F16::from_num(0.1)));
        // The partition leaves anyway (the drum ran on): the next boundary
        // is a partition away, and a slow drum is not near it.
        p.advance_belt(2, Coefficient::ONE);
        assert_eq!(p.partitions_left(), 1);
        assert!(p.next_place_beyond_reach());
        assert!(!p.must_hold(ten));
        // An edge that shows the ground at the place ends any hold.
        p.advance_belt(10_700, Coefficient::ONE);
        assert!(p.must_hold(ten));
        p.advance_ground(8, 8 << 16, 1 << 16, 0, mps(500), Some(1 << 30));
        assert!(!p.next_place_beyond_reach());
        assert!(!p.must_hold(ten));
    }
}
