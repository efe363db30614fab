//! Travel-speed measurement from the Hall gear (SPEC §2).
//!
//! * [`m_method_gear_speed`]: the paper's M-method (eq. 1–2), kept for comparison.
//! * [`CaptureExtender`]: 16-bit input captures + timer update events → monotonic
//!   32-bit [`Ticks`].
//! * [`MtEstimator`]: the M/T method on captured edge timestamps with glitch
//!   rejection, tooth-pitch compensation, optional median of 3 and a
//!   zero-speed timeout that decays the estimate by the elapsed time.
//!
//! # M/T method
//!
//! Every accepted Hall edge is timestamped (1 µs). At each [`MtEstimator::update`]
//! the speed is the angle of the `m` gaps that ended since the previous
//! window's last edge, divided by the exact time between that edge and the
//! newest one: `n = 60·f_timer·angle / (t_last − t_ref)`. No time is lost
//! between windows, and when a window holds no edge (slow travel) the next
//! edge simply closes a longer window.
//!
//! *Resolution*: one timer tick over the window, i.e. 1 µs / T (1e-5 at a
//! 100 ms window; the ±5 µs capture jitter gives ±1e-4). *Latency*: the value
//! is the mean speed over the window that ended at the newest edge, so it lags
//! by about half a window plus the time from that edge to the update — at
//! 4 km/h (22.6 ms per tooth, 100 ms updates) ≈ 50–70 ms; at 0.3 km/h (302 ms
//! per tooth) ≈ 150 ms + up to one tooth period.
//!
//! *Tooth-pitch compensation*: a gear with ±1 % pitch errors makes single
//! gaps ±1 % (and more) wrong, which at low speed (one gap per window) is the
//! dominant error. The estimator learns each gap's share from the first
//! thirteen gaps on: the gap six edges back against the parabola through
//! its twelve neighbours' times per pitch (a least-squares fit, the centre
//! left out: a steady acceleration and a steady change of it cancel), when
//! those neighbours lie within 10 % of each other (no stop, restart or
//! speed step inside the window) and the sample within ±6.25 % of a pitch. A
//! tooth's share is the running mean of its samples, after 16 an IIR of
//! 1/16, each step clipped to 0.25 % once the tooth has three samples (one
//! bump of the terrain cannot undo what the others taught); the shares'
//! mean is kept at 1 (the reference cannot see a common scale). Until a
//! tooth has a sample its gap counts as 1/Z. While the learning's mean
//! deviation is above 0.5 % of a pitch ([`MtEstimator::is_noisy`]: the first
//! revolutions after power-up), the window is a steady run of up to eight
//! gaps: the gaps since the last window and those before them, as long as
//! none is more than 4 % off the run's speed (a change of speed starts the
//! run again, and a run is used once three gaps in a row agreed). While the
//! run's mean and the mean of as many gaps before it differ by more than
//! the teeth can make (±4 %/k each for k gaps, plus 2 %), the speed changes
//! along it and the run would lag: the window is the new gaps, and the
//! change is reported ([`TravelMeasurement::trend`]). It
//! assumes no real edge is lost (a lost edge shifts the tooth index; the
//! table is then dropped and re-learnt). [`MtEstimator::gap_pitches_q16`]
//! gives the shares to the ground distance without the table's first
//! harmonic ([`crate::harmonic`]): a ripple of the speed once a revolution
//! reads as that harmonic of the teeth, so the learning cannot pin it down,
//! and summed over several teeth it would move the ground more than the
//! teeth's true errors do.
//!
//! *Zero speed*: when no edge came for longer than the next gap should take,
//! the speed can be at most that gap's angle over the elapsed time, so the
//! output decays as `1/elapsed` instead of holding a stale value; after
//! `stop_timeout` it is 0 and the next edge starts a new window (the first
//! speed after a stop needs two edges).
//!
//! *Glitches*: an edge closer than `min_edge_gap` or than 1/2^`glitch_shift`
//! of the last period (default ¼) is dropped and counted. That reference
//! period grows by at most 2× an edge, so the gap that spans a pause shorter
//! than `stop_timeout` (stop-and-go) does not turn the next full-speed edges
//! into glitches (each dropped real edge is a tooth of distance lost). At a
//! steady working speed an edge that closes a gap shorter than ¾ of the
//! reference is held until the next edge confirms it
//! ([`MtEstimator::push_edge`]): one noise pulse, or a sensor whose line
//! sticks low part-way through a gap, raises no speed.
//!
//! *Zero speed, a tooth not learnt*: the decay's gap gets 5 % more while
//! its tooth has fewer than three samples (an unlearnt tooth may be up to
//! 4 % long, plus the capture jitter), so that a long tooth does not read as
//! a slowing machine.
//!
//! # Hall silence: a stop or a lost signal?
//!
//! [`MtEstimator::next_edge_deadline`] says by when the next edge must come
//! if the machine cannot slow down faster than a [`DecelerationBound`]. Over
//! the last gap (length `s`, time `T`) the mean speed was `s/T`; since the
//! speed drops by at most `a` per second, it was at least `v_e = s/T − a·T/2`
//! at the newest edge, and from there the machine covers at least
//! `v_e²/(2a)` before it can be at rest. If that is less than the next gap
//! `s′`, the machine may stop before the next tooth: silence then proves
//! nothing ([`None`]). Otherwise the next edge must come by the time `t` with
//! `v_e·t − a·t²/2 = s′`, i.e. `t = 2s′ / (v_e + √(v_e² − 2a·s′))`; an edge
//! later than that is impossible for a moving machine, so the signal is lost.
//! `T` is the longest of the last three gaps, so that one spurious edge
//! (which splits a gap in two) is no evidence (docs/kinematics.md).
//! The gap lengths are the learned tooth shares with a tolerance (pitch
//! errors of teeth not learned yet, capture jitter) that shortens `s` and
//! lengthens `s′`. With the chassis limit of 1 g this leaves evidence only
//! above ≈ 3.4 km/h (docs/kinematics.md).

use crate::units::{RevPerMin, Seconds, Ticks};
use crate::{fx, Error};
use fixed::types::U12F20;

/// Largest tooth count the estimator supports.
pub const MAX_TEETH: usize = 32;
/// Edge stamps kept: a revolution and a half of the largest gear and a few
/// (tooth learning reaches a revolution and half a revolution back).
const RING: usize = MAX_TEETH + MAX_TEETH / 2 + 4;
/// Tooth learning: the gaps on either side of a learnt gap that give its
/// reference (module docs, "Tooth-pitch compensation").
const LEARN_HALF: usize = 6;
/// The reference's weights for the gaps 1 … 6 away on each side, over
/// [`LEARN_DIVISOR`]: the value at the centre of a least-squares parabola
/// through the twelve neighbours' per-pitch times (the centre left out),
/// `(Σx⁴ − Σx²·x²) / (n·Σx⁴ − (Σx²)²)` with x = ±1 … ±6: 4550 − 182·x².
const LEARN_WEIGHTS: [i16; LEARN_HALF] = [4368, 3822, 2912, 1638, 0, -2002];
/// The sum of the weights over both sides (n·Σx⁴ − (Σx²)² = 21 476).
const LEARN_DIVISOR: u64 = 21_476;
/// Tooth learning's gate on one sample: within ±1/16 (6.25 %) of a pitch,
/// Q16 (room for a gap between two teeth ±2 % of a pitch off their places,
/// ±4 %, with the terrain's noise on top).
const SAMPLE_GATE_Q16: u32 = ONE_Q16 / 16;
/// Tooth learning's gate: the neighbours' per-pitch times within 10 % of
/// the reference (max − min). A stop, a restart or a speed step inside the
/// thirteen gaps leaves no usable parabola.
const SPREAD_GATE: u64 = 10;
/// After this many samples a tooth's share moves by at most
/// [`SHARE_CLIP_Q16`] a sample (before the running mean's 1/n): a sample
/// taken while the speed changes faster than a parabola follows (a
/// chassis's 0.5 s answer to a throttle step) is biased by up to 1 %, which
/// a running mean would keep as tooth error; the teeth's true shares do not
/// move.
const SHARE_CLIP_FROM: u8 = 3;
/// The largest step of a learnt share per sample, Q16 (0.25 %).
const SHARE_CLIP_Q16: i32 = 164;
/// A tooth's share is the running mean of its samples up to this many, then
/// an IIR of the same weight (1/16).
const SHARE_SAMPLES: u8 = 16;
/// Samples from which a tooth's share counts as learnt: before, its gap is
/// given 5 % of slack before the edge counts as late.
const LEARNT_SAMPLES: u8 = 3;
/// A gap whose speed differs from the steady run's by more than 1/25 (4 %)
/// ends the run: unlearnt teeth make at most ±4 % a gap (the machine
/// model's ±2 % of a pitch per tooth), so the speed changed.
const STEADY_BREAK: u64 = 25;
/// The longest steady run, gaps: its mean lags a slowly changing speed by
/// half of it (a ±10 % change through a 2.5 s chassis: 0.7 % a gap at
/// Low 2), so a whole revolution lagged by 3 %.
const STEADY_RUN_MAX: u32 = 8;
/// Beyond the teeth's bound, the change between two adjacent runs that
/// counts as the speed's ([`MtEstimator::steady_window`]), percent: room
/// for the ground's slip noise and the capture jitter.
const TREND_MARGIN_PCT: u64 = 2;
/// The learning's mean deviation above which the single gaps read noisy
/// ([`MtEstimator::is_noisy`]): 0.75 %, Q16.
pub const NOISY_LIMIT_Q16: u32 = 328;
/// The learning's mean deviation at power-up (and after lost edges): 2 %.
const NOISY_START_Q16: u32 = 1311;
/// Gaps in a row within [`STEADY_BREAK`] of the run before the run is used:
/// a tractor pulling away from rest settles its speed in a few gaps, and a
/// run averaging the last of its rise would lag it.
const STEADY_SETTLE: u8 = 3;
/// The suspect-edge rule ([`MtEstimator::push_edge`]) holds at working
/// speeds only: gaps up to 0.6 s, half the slowest gear's speed (Low 1,
/// 0.32 km/h at the gear: 0.28 s a gap).
const SUSPECT_MAX_GAP_MS: u32 = 600;
/// Q16 unity for the learned tooth shares.
const ONE_Q16: u32 = 1 << 16;

/// Paper A eq. 1: the M-method window `t = (PSC+1)(ARR1+1)/Hclk`.
pub fn m_method_window(psc: u16, arr: u16, hclk_hz: u32) -> Result<Seconds, Error> {
    let counts = u64::from(psc)
        .saturating_add(1)
        .saturating_mul(u64::from(arr).saturating_add(1));
    Seconds::try_from_w(fx::div_int(
        fx::mul_int(counts, fx::ONE)?,
        u64::from(hclk_hz),
    )?)
}

/// Paper A eq. 2 without k1: `n = 60·N/(Z1·t)` r/min for `pulses` counted in `window`.
///
/// ```
/// use kinematics::speed::{m_method_gear_speed, m_method_window};
/// // 1 s window (PSC = 7199, ARR1 = 9999 at 72 MHz); 3 pulses ⇒ 60·3/25 = 7.2 r/min,
/// // 4 pulses ⇒ 9.6 r/min: at Low 1 (8.2 r/min) the M-method can only say 7.2 or 9.6.
/// let t = m_method_window(7199, 9999, 72_000_000)?;
/// assert!((m_method_gear_speed(3, t, 25)?.to_f64() - 7.2).abs() < 1e-5);
/// assert!((m_method_gear_speed(4, t, 25)?.to_f64() - 9.6).abs() < 1e-5);
/// # Ok::<(), kinematics::Error>(())
/// ```
pub fn m_method_gear_speed(pulses: u32, window: Seconds, teeth: u8) -> Result<RevPerMin, Error> {
    let den = fx::mul_int(window.w(), u64::from(teeth))?;
    RevPerMin::try_from_w(fx::div(
        fx::mul_int(u64::from(pulses).saturating_mul(60), fx::ONE)?,
        den,
    )?)
}

/// Extends 16-bit input-capture values to monotonic 32-bit ticks using the
/// timer's update (overflow) events.
///
/// Call order in the timer interrupt (capture and update share one IRQ on
/// TIM2–4 of the F103): read the status register; for a capture, read the
/// capture value and call [`extend`](Self::extend) with `overflow_pending =
/// UIF`; *then*, if UIF was set, clear it and call
/// [`on_overflow`](Self::on_overflow). If an overflow is pending while a
/// capture is processed, a capture value in the lower half of the range was
/// taken after the wrap (it belongs to the next period), one in the upper
/// half before it. This assumes the interrupt is serviced within half a wrap
/// (32 ms).
///
/// ```
/// use kinematics::speed::CaptureExtender;
/// let mut x = CaptureExtender::new();
/// x.on_overflow(); // counter wrapped once: now in 65536 … 131071
/// assert_eq!(x.extend(100, false).0, 65_536 + 100);
/// // The counter wrapped again, the update is still pending:
/// assert_eq!(x.extend(65_530, true).0, 65_536 + 65_530); // captured before the wrap
/// assert_eq!(x.extend(3, true).0, 2 * 65_536 + 3); // captured after the wrap
/// x.on_overflow();
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CaptureExtender {
    high: u16,
}

impl CaptureExtender {
    /// Starts at tick 0.
    #[must_use]
    pub const fn new() -> Self {
        Self { high: 0 }
    }

    /// Accounts one timer update (overflow) event.
    pub fn on_overflow(&mut self) {
        self.high = self.high.wrapping_add(1);
    }

    /// Extends a 16-bit capture (or counter) value; `overflow_pending` is the
    /// timer's update flag not yet passed to [`on_overflow`](Self::on_overflow).
    #[must_use]
    pub fn extend(&self, capture: u16, overflow_pending: bool) -> Ticks {
        let high = if overflow_pending && capture < 0x8000 {
            self.high.wrapping_add(1)
        } else {
            self.high
        };
        Ticks((u32::from(high) << 16) | u32::from(capture))
    }

    /// The current time from the free-running counter (same rule as `extend`).
    #[must_use]
    pub fn now(&self, counter: u16, overflow_pending: bool) -> Ticks {
        self.extend(counter, overflow_pending)
    }

    /// Extends a capture with the counter read *after* the update flag:
    /// exact as long as the capture and the pending update are less than one
    /// whole wrap old (65.5 ms at 1 MHz), where [`extend`](Self::extend)'s
    /// half-range rule needs the interrupt within half a wrap.
    ///
    /// Read in this order in the timer interrupt: the capture register, then
    /// the status register (`overflow_pending` = its UIF, not yet passed to
    /// [`on_overflow`](Self::on_overflow)), then the counter
    /// (`counter_after`). With an update pending, the counter has wrapped
    /// since the last accounted period and only counted up from 0 since: a
    /// capture taken after the wrap is at most the counter read later, one
    /// taken before it (less than a wrap ago) is above it. Without one, no
    /// wrap came before the status read, so the capture (read earlier) is in
    /// the accounted period.
    ///
    /// This is what a CPU stall needs: a flash page erase holds the bus for
    /// up to 40 ms, and a capture made 35 ms after an overflow that could not
    /// be serviced reads 35 000 (above half the range): the half-range rule
    /// stamps it a whole wrap early, this one does not.
    ///
    /// ```
    /// use kinematics::speed::CaptureExtender;
    /// let x = CaptureExtender::new();
    /// // Overflow at 65 536 µs, unserviced; edge at 65 536 + 35 000; the
    /// // interrupt runs at 65 536 + 38 000 (counter 38 000).
    /// assert_eq!(x.extend_at(35_000, true, 38_000).0, 65_536 + 35_000);
    /// // Edge at 60 000 (before the wrap), read at 65 536 + 30 000.
    /// assert_eq!(x.extend_at(60_000, true, 30_000).0, 60_000);
    /// // No update pending: the capture is in the accounted period.
    /// assert_eq!(x.extend_at(65_000, false, 65_100).0, 65_000);
    /// ```
    #[must_use]
    pub fn extend_at(&self, capture: u16, overflow_pending: bool, counter_after: u16) -> Ticks {
        let high = if overflow_pending && capture <= counter_after {
            self.high.wrapping_add(1)
        } else {
            self.high
        };
        Ticks((u32::from(high) << 16) | u32::from(capture))
    }

    /// The current time from the counter read between two reads of the
    /// update flag (`pending_before`, `counter`, `pending_after`): exact while
    /// the pending update is less than a whole wrap old. An update already
    /// pending before the read means the counter is past the wrap; one that
    /// appeared between the reads happened next to the counter read (the
    /// counter is then near 0 or near 2^16, and the half-range rule decides).
    #[must_use]
    pub fn now_between(&self, pending_before: bool, counter: u16, pending_after: bool) -> Ticks {
        if pending_before {
            Ticks((u32::from(self.high.wrapping_add(1)) << 16) | u32::from(counter))
        } else {
            self.extend(counter, pending_after)
        }
    }
}

/// Estimator settings; [`EstimatorSettings::build`] validates them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EstimatorSettings {
    /// Teeth on the gear (2 … [`MAX_TEETH`]; SPEC: 25).
    pub teeth: u8,
    /// Timer tick rate, Hz (board: 1 MHz).
    pub timer_hz: u32,
    /// No edge for this long ⇒ speed 0 (default 1.5 s ⇒ lowest speed
    /// 25.13 mm / 1.5 s = 0.06 km/h).
    pub stop_timeout_ticks: u32,
    /// Edges closer than this are always glitches (default 500 µs, half the
    /// 1 kHz limit of the switch).
    pub min_edge_gap_ticks: u32,
    /// An edge closer than `last period >> glitch_shift` is a glitch
    /// (default 2, i.e. ¼ period).
    pub glitch_shift: u8,
    /// The first gap after a stop (no edge for `stop_timeout_ticks`) shorter
    /// than this is a glitch: there is no period yet to judge it by, and
    /// from rest the gear cannot cover a tooth that fast. Default 20 ms:
    /// from rest the first tooth (25.13 mm) brings the track to at most
    /// √(2·a·p) and the next one takes ≥ 29 ms even at a = 1 g (docs/
    /// kinematics.md). A contact bounce of the first edge (1 ms) read as
    /// 85 km/h for a window and ran the drum to its limit. 0: off.
    pub from_rest_min_gap_ticks: u32,
    /// Median of the last 3 measurements (adds about one window of latency).
    pub median_of_3: bool,
    /// Learn and compensate the tooth-pitch errors.
    pub pitch_compensation: bool,
}

impl Default for EstimatorSettings {
    fn default() -> Self {
        Self {
            teeth: crate::consts::Z1,
            timer_hz: crate::consts::CAPTURE_TIMER_HZ,
            stop_timeout_ticks: 1_500_000,
            min_edge_gap_ticks: 500,
            glitch_shift: 2,
            from_rest_min_gap_ticks: 20_000,
            median_of_3: false,
            pitch_compensation: true,
        }
    }
}

/// Why [`EstimatorSettings::build`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EstimatorConfigError {
    /// Teeth outside 2 … [`MAX_TEETH`].
    Teeth,
    /// Timer rate zero.
    TimerRate,
    /// Timeout zero or not above the minimum edge gap, or above 2³¹ ticks.
    Timeout,
    /// Glitch shift outside 1 … 8.
    GlitchShift,
}

impl core::fmt::Display for EstimatorConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            EstimatorConfigError::Teeth => "tooth count outside 2 .. 32",
            EstimatorConfigError::TimerRate => "timer rate is zero",
            EstimatorConfigError::Timeout => "stop timeout invalid",
            EstimatorConfigError::GlitchShift => "glitch shift outside 1 .. 8",
        })
    }
}

impl core::error::Error for EstimatorConfigError {}

impl EstimatorSettings {
    /// Validates and creates the estimator.
    pub fn build(self) -> Result<MtEstimator, EstimatorConfigError> {
        if self.teeth < 2 || usize::from(self.teeth) > MAX_TEETH {
            return Err(EstimatorConfigError::Teeth);
        }
        if self.timer_hz == 0 {
            return Err(EstimatorConfigError::TimerRate);
        }
        if self.stop_timeout_ticks <= self.min_edge_gap_ticks
            || self.stop_timeout_ticks <= self.from_rest_min_gap_ticks
            || self.stop_timeout_ticks > 1 << 31
        {
            return Err(EstimatorConfigError::Timeout);
        }
        if !(1..=8).contains(&self.glitch_shift) {
            return Err(EstimatorConfigError::GlitchShift);
        }
        Ok(MtEstimator {
            cfg: self,
            z: usize::from(self.teeth),
            stamps: [0; RING],
            last: 0,
            head: 0,
            tooth: 0,
            has_last: false,
            edges_total: 0,
            valid_run: 0,
            last_gap: 0,
            gaps: [0; 3],
            glitch_ref: 0,
            ref_stamp: 0,
            ref_edges: 0,
            ref_valid: false,
            learned_upto: 0,
            samples: [0; MAX_TEETH],
            weights: [0; MAX_TEETH],
            weight_sum: u32::from(self.teeth).saturating_mul(ONE_Q16),
            harmonic: [0; MAX_TEETH],
            held: 0,
            history: [0; 3],
            history_len: 0,
            glitches: 0,
            lost: false,
            from_rest: false,
            pending: None,
            steady: 0,
            calm: 0,
            trend: (0, 0),
            rough: NOISY_START_Q16,
        })
    }
}

/// The fastest the Hall gear's track speed can fall, with the gap tolerance
/// of the silence rule ([`MtEstimator::next_edge_deadline`]); build it with
/// [`DecelerationBound::new`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecelerationBound {
    /// Deceleration in Q16 nominal gaps per tick², × 2^48.
    alpha_q48: u64,
    /// Relative tolerance on a gap's length, %.
    tolerance_pct: u8,
}

/// Why [`DecelerationBound::new`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecelerationBoundError {
    /// Deceleration outside 1 … 100 m/s².
    Deceleration,
    /// Gap length outside 1 mm … 1 m.
    Gap,
    /// Timer rate outside 1 … 100 MHz.
    TimerRate,
    /// Gap tolerance above 50 %.
    Tolerance,
}

impl core::fmt::Display for DecelerationBoundError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Deceleration => "deceleration outside 1 .. 100 m/s2",
            Self::Gap => "gap length outside 1 mm .. 1 m",
            Self::TimerRate => "timer rate outside 1 .. 100 MHz",
            Self::Tolerance => "gap tolerance above 50 %",
        })
    }
}

impl core::error::Error for DecelerationBoundError {}

impl DecelerationBound {
    /// A deceleration of `decel_mm_s2` of track speed, where one nominal gap
    /// of the gear is `gap_um` of track and the capture timer counts
    /// `timer_hz`; gap lengths are trusted to ±`tolerance_pct` %.
    ///
    /// ```
    /// use kinematics::speed::DecelerationBound;
    /// // 10.5 m/s² on the 25.133 mm gaps of the Hall gear, 1 MHz ticks, ±5 %.
    /// assert!(DecelerationBound::new(10_500, 25_133, 1_000_000, 5).is_ok());
    /// assert!(DecelerationBound::new(0, 25_133, 1_000_000, 5).is_err());
    /// ```
    pub fn new(
        decel_mm_s2: u32,
        gap_um: u32,
        timer_hz: u32,
        tolerance_pct: u8,
    ) -> Result<Self, DecelerationBoundError> {
        if !(1_000..=100_000).contains(&decel_mm_s2) {
            return Err(DecelerationBoundError::Deceleration);
        }
        if !(1_000..=1_000_000).contains(&gap_um) {
            return Err(DecelerationBoundError::Gap);
        }
        if !(1_000_000..=100_000_000).contains(&timer_hz) {
            return Err(DecelerationBoundError::TimerRate);
        }
        if tolerance_pct > 50 {
            return Err(DecelerationBoundError::Tolerance);
        }
        // α = a / gap nominal gaps per s² = a·1000/gap_um (a in mm/s²);
        // in Q16 gaps per tick², × 2^48: α·2^16·2^48 / f². Formed as
        // ((a·2^40 / gap_um)·1000 / f)·2^24 / f without u128 division: over
        // the accepted ranges every step fits u64 (a·2^40 < 2^57; at most
        // 2^61 before the last division) and the result is exact to 1e-8 at
        // the board's values, to 0.1 % at the far corner (1 m/s², 1 m gaps,
        // 100 MHz).
        let f = u64::from(timer_hz);
        let alpha_q48 = (u64::from(decel_mm_s2) << 40)
            .checked_div(u64::from(gap_um))
            .and_then(|q| q.checked_mul(1000))
            .and_then(|q| q.checked_div(f))
            .and_then(|q| q.checked_mul(1 << 24))
            .and_then(|q| q.checked_div(f))
            .ok_or(DecelerationBoundError::Deceleration)?;
        Ok(Self {
            alpha_q48,
            tolerance_pct,
        })
    }
}

/// The terms of the Hall silence rule for the newest edge (see
/// `MtEstimator::silence`).
struct Silence {
    t: u64,
    e: u64,
    a: u64,
    s_next: u64,
    disc: u64,
}

/// What an update saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MotionState {
    /// No edge for longer than the timeout (or never): speed 0.
    Stopped,
    /// First edge after a stop: moving, speed not known yet (reported 0).
    Starting,
    /// New edges closed a window: a fresh measurement.
    Measured,
    /// No new edge, but not overdue: last measurement held.
    Holding,
    /// No new edge for longer than the next gap should take: speed capped
    /// at one gap over the elapsed time.
    Decaying,
}

/// One update of the estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TravelMeasurement {
    /// Gear speed without k1 (feed into [`crate::travel::travel_speed`]).
    pub gear_speed: RevPerMin,
    /// How the value was obtained.
    pub state: MotionState,
    /// Gaps in the window that closed (0 unless `Measured`).
    pub edges: u32,
    /// Window length in ticks (0 unless `Measured`).
    pub window_ticks: u32,
    /// Ticks since the newest edge.
    pub since_edge_ticks: u32,
    /// Glitches dropped since start (wrapping).
    pub glitches: u32,
    /// The single gaps read noisy ([`MtEstimator::is_noisy`]): their tooth
    /// shares are not learnt (yet), and the window may be a steady run of
    /// them reaching back beyond the previous window (see
    /// `MtEstimator::steady_window`), whose speed does not change: no slope
    /// between two such windows means anything but [`Self::trend`].
    pub noisy: bool,
    /// While the gaps read noisy and the speed changes beyond what their
    /// teeth can make: that change (U12F20 bits of `gear_speed`) over
    /// ticks, measured between two adjacent runs of gaps (their tooth
    /// errors cancel but for ±8 %/run length); `(0, 0)` otherwise.
    pub trend: (i32, u32),
}

/// Verdict on one pushed edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EdgeVerdict {
    /// Accepted.
    Accepted,
    /// Accepted as the first edge after a stop or at start.
    Restart,
    /// Dropped as a glitch.
    Glitch,
    /// Held until the next edge: at a steady working speed, the gap it
    /// closes is shorter than ¾ of the glitch reference (see
    /// [`MtEstimator::push_edge`]).
    Suspect,
    /// Dropped for the ¼-period rule while the speed was changing (a
    /// tractor pulling away from a crawl): it may be a real tooth, which
    /// the ground distance can count.
    Early,
}

/// M/T speed estimator on 32-bit edge timestamps (wrapping arithmetic).
///
/// ```
/// use kinematics::speed::{EstimatorSettings, MotionState};
/// use kinematics::units::Ticks;
/// let mut est = EstimatorSettings::default().build()?;
/// // 10 r/min on 25 teeth: one edge every 60 s / 250 = 240 000 µs.
/// for k in 0..6u32 {
///     est.push_edge(Ticks(1_000 + k * 240_000));
/// }
/// let m = est.update(Ticks(1_000 + 5 * 240_000 + 50_000));
/// assert_eq!(m.state, MotionState::Measured);
/// assert!((m.gear_speed.to_f64() - 10.0).abs() < 1e-4);
/// // 1.2 s after the last edge (5 gaps' worth) the speed is at most one gap
/// // over 1.2 s; a tooth not learnt yet gets 5 % more: 1.05/25 rev = 2.1 r/min.
/// let m = est.update(Ticks(1_000 + 5 * 240_000 + 1_200_000));
/// assert_eq!(m.state, MotionState::Decaying);
/// assert!((m.gear_speed.to_f64() - 2.1).abs() < 1e-4);
/// # Ok::<(), kinematics::speed::EstimatorConfigError>(())
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MtEstimator {
    cfg: EstimatorSettings,
    z: usize,
    /// Ring of the last accepted edge stamps; `head` is the newest.
    stamps: [u32; RING],
    /// The newest stamp (`stamps[head]`).
    last: u32,
    head: usize,
    /// Tooth index (0 … z−1) of the gap that ended at the newest edge.
    tooth: usize,
    has_last: bool,
    edges_total: u32,
    /// Accepted edges since the last restart (saturating).
    valid_run: u32,
    last_gap: u32,
    /// The last three measured gaps since a restart (ticks, newest first;
    /// 0: not measured yet), for the Hall silence rule.
    gaps: [u32; 3],
    /// The period glitches are judged against (µs): the last gap, but grown
    /// by at most 2× an edge.
    glitch_ref: u32,
    /// The newest edge came after a stop: the next gap is the first from
    /// rest ([`EstimatorSettings::from_rest_min_gap_ticks`]).
    from_rest: bool,
    ref_stamp: u32,
    ref_edges: u32,
    ref_valid: bool,
    learned_upto: u32,
    /// Samples each tooth's share has taken, up to [`SHARE_SAMPLES`].
    samples: [u8; MAX_TEETH],
    /// Learned share of each gap, Q16 (1.0 = 1/z of a revolution), stored as
    /// its offset from 1.0: a learned share lies within ±4 % (±2621) of it,
    /// so `i16` holds it exactly (64 bytes instead of 128).
    weights: [i16; MAX_TEETH],
    weight_sum: u32,
    /// The first harmonic of `weights` (Q16 offsets,
    /// [`crate::harmonic::first_harmonic_q16`]): the part of the table the
    /// learning cannot tell from a speed ripple, left out of the ground's
    /// pitches ([`MtEstimator::gap_pitches_q16`]).
    harmonic: [i16; MAX_TEETH],
    /// Last measurement, U12F20 bits.
    held: u32,
    history: [u32; 3],
    history_len: u8,
    glitches: u32,
    /// Edges were lost before the next one (see [`MtEstimator::edges_lost`]).
    lost: bool,
    /// A suspect edge waiting for the next one ([`MtEstimator::push_edge`]).
    pending: Option<u32>,
    /// Gaps in the current steady run ([`MtEstimator::steady_window`]), and
    /// the gaps in a row that kept to it.
    steady: u32,
    calm: u8,
    /// The speed's change along the steady run beyond the teeth's (set by
    /// [`MtEstimator::steady_window`] for the window it chose).
    trend: (i32, u32),
    /// The running mean of the learning's deviations, Q16
    /// ([`MtEstimator::is_noisy`]).
    rough: u32,
}

#[cfg(feature = "defmt")]
impl defmt::Format for MtEstimator {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "MtEstimator(edges={=u32}, held={=u32}, glitches={=u32})",
            self.edges_total,
            self.held,
            self.glitches
        );
    }
}

fn ring_prev(i: usize, back: usize) -> usize {
    // (i − back) mod RING, for back ≤ RING.
    let back = back % RING;
    if i >= back {
        i.saturating_sub(back)
    } else {
        RING.saturating_sub(back.saturating_sub(i))
    }
}

/// Q16 share from its stored offset to 1.0.
fn weight_from_offset(d: i16) -> u32 {
    ONE_Q16.saturating_add_signed(i32::from(d))
}

/// Offset to 1.0 of a Q16 share within ±4 % (always representable; a value
/// outside `i16` cannot occur and would read as nominal).
fn weight_to_offset(w: u32) -> i16 {
    i64::from(w)
        .checked_sub(i64::from(ONE_Q16))
        .and_then(|d| i16::try_from(d).ok())
        .unwrap_or(0)
}

fn median3(a: u32, b: u32, c: u32) -> u32 {
    a.max(b).min(a.min(b).max(c))
}

impl MtEstimator {
    /// The settings in use.
    #[must_use]
    pub const fn settings(&self) -> &EstimatorSettings {
        &self.cfg
    }

    /// Learned share of each gap relative to 1/Z (Q16 bits: 65536 = nominal),
    /// one per tooth.
    pub fn tooth_weights(&self) -> impl ExactSizeIterator<Item = u32> + '_ {
        self.weights
            .get(..self.z)
            .unwrap_or(&[])
            .iter()
            .map(|&d| weight_from_offset(d))
    }

    /// The gap that ended at the newest edge in pitches, Q16 (65 536: one
    /// nominal pitch, 1/Z of a revolution): its learned share, scaled so that
    /// a revolution's gaps add up to Z pitches (nominal until learnt). The
    /// ground between two teeth of a gear with ±2 % pitch errors is then
    /// right to the learning's precision instead of ±2 % of a pitch.
    ///
    /// ```
    /// use kinematics::speed::EstimatorSettings;
    /// use kinematics::units::Ticks;
    /// let mut est = EstimatorSettings::default().build().unwrap();
    /// // Not learnt yet: a nominal pitch.
    /// est.push_edge(Ticks(0));
    /// est.push_edge(Ticks(20_000));
    /// assert_eq!(est.newest_gap_pitches_q16(), 65_536);
    /// ```
    #[must_use]
    pub fn newest_gap_pitches_q16(&self) -> u32 {
        self.ground_pitches_q16_of(self.tooth)
    }

    /// The gap after the newest edge (the one the gear is in now) in
    /// pitches, Q16, as [`MtEstimator::newest_gap_pitches_q16`]: the ground
    /// between the newest edge and the next one.
    #[must_use]
    pub fn next_gap_pitches_q16(&self) -> u32 {
        let next = self
            .tooth
            .checked_add(1)
            .filter(|&i| i < self.z)
            .unwrap_or(0);
        self.ground_pitches_q16_of(next)
    }

    /// Gap `idx`'s learned share in pitches, Q16 (a revolution's gaps add
    /// up to Z pitches).
    fn pitches_q16_of(&self, idx: usize) -> u32 {
        // w · Z · 2¹⁶ ≤ 2¹⁷ · 32 · 2¹⁶ = 2³⁸.
        let z = u64::try_from(self.z).unwrap_or(0);
        u64::from(self.weight(idx))
            .wrapping_mul(z)
            .wrapping_mul(u64::from(ONE_Q16))
            .checked_div(u64::from(self.weight_sum))
            .and_then(|v| u32::try_from(v).ok())
            .unwrap_or(ONE_Q16)
    }

    /// Gap `idx` in pitches of ground, Q16: its learned share without the
    /// table's first harmonic (module docs, "Tooth-pitch compensation").
    fn ground_pitches_q16_of(&self, idx: usize) -> u32 {
        let h = self.harmonic.get(idx).copied().unwrap_or(0);
        self.pitches_q16_of(idx)
            .saturating_add_signed(i32::from(h).saturating_neg())
    }

    /// Learned share of gap `idx`, Q16 (nominal outside the table).
    fn weight(&self, idx: usize) -> u32 {
        self.weights
            .get(idx)
            .map_or(ONE_Q16, |&d| weight_from_offset(d))
    }

    /// By how many ticks after the newest edge the next edge must have come
    /// if the machine slows down no faster than `bound` (module docs, "Hall
    /// silence"); `None` when the silence proves nothing: the machine may
    /// stop before the next tooth (too slow for the bound), or there is no
    /// measured gap (at start, after a stop).
    ///
    /// ```
    /// use kinematics::speed::{DecelerationBound, EstimatorSettings};
    /// use kinematics::units::Ticks;
    /// let bound = DecelerationBound::new(10_500, 25_133, 1_000_000, 5).unwrap();
    /// let mut est = EstimatorSettings::default().build().unwrap();
    /// // High 3 (3.66 km/h at the gear): one edge every 24.7 ms.
    /// for k in 0..5u32 {
    ///     est.push_edge(Ticks(k * 24_700));
    /// }
    /// // By hand: u = a·T²/s = 10.5 · 0.0247² / 0.025 133 = 0.2549 gap;
    /// // v_e·T = 0.95 − u/2 = 0.8225 gap; t = T · 2·1.05 / (0.8225 +
    /// // √(0.8225² − 2·0.2549·1.05)) = 1.7524 T = 43.28 ms.
    /// let d = est.next_edge_deadline(&bound).unwrap();
    /// assert!((43_200..43_360).contains(&d), "{d}");
    /// // Low 2 (0.51 km/h, 177 ms per edge): the machine can stop within
    /// // a gap, so silence proves nothing.
    /// let mut est = EstimatorSettings::default().build().unwrap();
    /// for k in 0..5u32 {
    ///     est.push_edge(Ticks(k * 177_000));
    /// }
    /// assert_eq!(est.next_edge_deadline(&bound), None);
    /// ```
    #[must_use]
    pub fn next_edge_deadline(&self, bound: &DecelerationBound) -> Option<u32> {
        let Silence {
            t, e, s_next, disc, ..
        } = self.silence(bound)?;
        let root = disc.isqrt();
        // t = 2s′/(v_e + √…) = T·2s′/(v_e·T + √…·T).
        let deadline = t
            .checked_mul(s_next)?
            .checked_mul(2)?
            .checked_div(e.checked_add(root)?)?;
        Some(u32::try_from(deadline).unwrap_or(u32::MAX))
    }

    /// Whether the next edge, `since_edge_ticks` after the newest one and
    /// still not there, is later than any machine slowing down no faster
    /// than `bound` allows: the same rule as
    /// [`next_edge_deadline`](Self::next_edge_deadline) (`since >
    /// deadline`), without its square root (≈ 0.5 KB of flash on the MCU):
    /// the least distance such a machine covers in that time,
    /// `v_e·t − a·t²/2` (or `v_e²/2a` once it can be at rest), exceeds the
    /// next gap. `false` whenever there is no deadline.
    ///
    /// ```
    /// use kinematics::speed::{DecelerationBound, EstimatorSettings};
    /// use kinematics::units::Ticks;
    /// let bound = DecelerationBound::new(10_500, 25_133, 1_000_000, 5).unwrap();
    /// let mut est = EstimatorSettings::default().build().unwrap();
    /// for k in 0..5u32 {
    ///     est.push_edge(Ticks(k * 24_700)); // High 3
    /// }
    /// // The deadline is 43.28 ms (see `next_edge_deadline`).
    /// assert!(!est.next_edge_overdue(43_200, &bound));
    /// assert!(est.next_edge_overdue(43_360, &bound));
    /// ```
    #[must_use]
    pub fn next_edge_overdue(&self, since_edge_ticks: u32, bound: &DecelerationBound) -> bool {
        let Some(Silence {
            t, e, a, s_next, ..
        }) = self.silence(bound)
        else {
            return false;
        };
        // r = τ/T, Q16 (τ < 2^32, so τ·2^16 < 2^48), taken to at most 2^38
        // (2^22 gaps: overdue either way, see below). The terms are below
        // 2^18 (e, s′ < 2^17 as Q16 gaps of at most 1.05 nominal; a ≤
        // e²/2s′ since the discriminant is not negative), so no product
        // below reaches 2^64.
        let Some(r) = (u64::from(since_edge_ticks) << 16).checked_div(t) else {
            return false;
        };
        let r = r.min(1 << 38);
        let (e, a) = (e.min(1 << 18), a.min(1 << 18));
        // Past the moment the machine can be at rest (a·τ ≥ v_e, i.e.
        // a·T²·r ≥ v_e·T·2^16): it has covered v_e²/2a ≥ s′ (there is a
        // deadline), so the edge is overdue.
        let a_r = a.wrapping_mul(r);
        if a_r >= e << 16 {
            return true;
        }
        // Least distance covered, Q32 gaps: (v_e·T)·r − (a·T²)·r²/2, with
        // a·T²·r < v_e·T·2^16 < 2^34 here.
        let covered = e
            .wrapping_mul(r)
            .saturating_sub(((a_r >> 16).wrapping_mul(r)) >> 1);
        covered > s_next.min(1 << 18) << 16
    }

    /// The terms of the silence rule (module docs), when the silence can
    /// prove anything: the last gap `t` (ticks), `v_e·T` (`e`), `a·T²`
    /// (`a`) and the next gap `s′` (`s_next`), all in Q16 nominal gaps, and
    /// the discriminant `(v_e·T)² − 2·a·T²·s′ ≥ 0`.
    fn silence(&self, bound: &DecelerationBound) -> Option<Silence> {
        // The longest of the last three gaps: one spurious edge splits a
        // gap into two short ones, each of which alone reads as a faster
        // machine whose next tooth is overdue long before it can come; a
        // longer gap gives a lower bound on the speed at the newest edge
        // (`s/T − a·T/2` falls with T), so the rule only grows more lenient
        // (a lost signal is seen at most two teeth later while the machine
        // accelerates; braking, the newest gap is the longest).
        if !self.has_last || self.valid_run < 2 || self.gaps.contains(&0) {
            return None;
        }
        let (back, gap) =
            self.gaps
                .iter()
                .enumerate()
                .fold((0, 0), |m, (i, &g)| if g > m.1 { (i, g) } else { m });
        let t = u64::from(gap);
        let tol = u64::from(bound.tolerance_pct);
        // The gap `back` edges before the newest has tooth index
        // `tooth − back` (mod z).
        let tooth = self
            .tooth
            .wrapping_add(self.z)
            .wrapping_sub(back)
            .checked_rem(self.z)
            .unwrap_or(0);
        // Gap lengths, Q16 nominal gaps (< 2^17 each).
        let s_last = u64::from(self.weight(tooth))
            .checked_mul(100_u64.checked_sub(tol)?)?
            .checked_div(100)?;
        let next = self
            .tooth
            .checked_add(1)
            .filter(|&i| i < self.z)
            .unwrap_or(0);
        let s_next = u64::from(self.weight(next))
            .checked_mul(tol.checked_add(100)?)?
            .checked_div(100)?;
        // a·T², Q16 gaps: (α·T >> 24)·T >> 24. A product that overflows is
        // a deceleration far beyond one gap: no evidence.
        let a = (bound.alpha_q48.checked_mul(t)? >> 24).checked_mul(t)? >> 24;
        // v_e·T = s − a·T²/2; not positive: the machine may be at rest.
        let e = s_last.checked_sub(a / 2).filter(|&e| e > 0)?;
        // (v_e·T)² − 2·a·T²·s′ < 0: it may stop before the next tooth.
        let disc = e
            .checked_mul(e)?
            .checked_sub(a.checked_mul(s_next)?.checked_mul(2)?)?;
        Some(Silence {
            t,
            e,
            a,
            s_next,
            disc,
        })
    }

    /// Records one Hall edge (call from the capture interrupt). O(1), no division.
    ///
    /// At a steady working speed (the last two gaps within a quarter of each
    /// other, none longer than 0.6 s), an edge that closes a gap shorter
    /// than ¾ of the glitch reference (a third faster within one tooth,
    /// beyond the ±4 % of unlearnt teeth and any chassis) is held as
    /// [`EdgeVerdict::Suspect`] until the next edge: if the gap after it is
    /// no longer than 1¼ times its own, the speed really rose and both are
    /// taken (the count of accepted edges, [`MtEstimator::accepted_edges`],
    /// grows by two); otherwise it was a spurious edge — one noise pulse,
    /// or the line of a sensor that sticks low falling part-way through a
    /// gap — and is dropped as a glitch. Without a next edge it is never
    /// taken: a sensor stuck after one spurious edge does not read as a
    /// sprint. An edge inside the ¼-period glitch rule is dropped
    /// ([`EdgeVerdict::Glitch`]) at a steady speed, and reported as
    /// [`EdgeVerdict::Early`] while the speed changes.
    pub fn push_edge(&mut self, t: Ticks) -> EdgeVerdict {
        let t = t.0;
        if let Some(p) = self.pending.take() {
            let g1 = p.wrapping_sub(self.newest());
            let g2 = t.wrapping_sub(p);
            if !self.lost && g2 <= g1.saturating_add(g1 / 4) {
                let _ = self.take(p);
            } else {
                self.glitches = self.glitches.wrapping_add(1);
            }
        }
        if self.has_last {
            let dt = t.wrapping_sub(self.newest());
            let expected_min = if self.glitch_ref == 0 {
                if self.from_rest {
                    self.cfg.from_rest_min_gap_ticks
                } else {
                    0
                }
            } else {
                self.glitch_ref >> self.cfg.glitch_shift
            };
            // At a steady working speed: the last two gaps within a quarter
            // of each other, and not from a crawl (gaps longer than
            // [`SUSPECT_MAX_GAP_MS`]: a tractor pulling away doubles its
            // speed within a tooth). A start from rest shortens every gap by
            // more than half at first, and a pull-away after a slow-down
            // follows gaps that grew.
            let [g0, g1, _] = self.gaps;
            let steady = g1 != 0
                && g0.abs_diff(g1) <= g1 / 4
                && u64::from(g0).wrapping_mul(1000)
                    <= u64::from(self.cfg.timer_hz).wrapping_mul(u64::from(SUSPECT_MAX_GAP_MS));
            if dt < self.cfg.min_edge_gap_ticks || dt < expected_min {
                self.glitches = self.glitches.wrapping_add(1);
                // Under a changing speed a real tooth may come this early
                // (the ground distance may count it); at a steady speed it is
                // noise, or the line of a sensor sticking low.
                return if steady || self.glitch_ref == 0 || dt < self.cfg.min_edge_gap_ticks {
                    EdgeVerdict::Glitch
                } else {
                    EdgeVerdict::Early
                };
            }
            if !self.lost && steady && dt < self.glitch_ref.wrapping_sub(self.glitch_ref >> 2) {
                self.pending = Some(t);
                return EdgeVerdict::Suspect;
            }
        }
        self.take(t)
    }

    /// Whether the single gaps read noisy: the teeth's shares are not learnt
    /// well yet. The measure is the learning's own: the running mean (1/8 a
    /// sample) of how far each sample lies from the share it updates, above
    /// [`NOISY_LIMIT_Q16`]. It starts at 2 % (`NOISY_START_Q16`: nothing is
    /// known of the gear at power-up). Unlearnt teeth (±2 % of a pitch) put
    /// it at 1.5–2 %; learnt ones below 0.5 % on the default terrain. While
    /// it holds, the window may be a steady run and the supervisor smooths
    /// the phase loop's correction.
    #[must_use]
    pub fn is_noisy(&self) -> bool {
        self.rough != 0
    }

    /// Edges accepted since start (wrapping): a confirmed suspect edge
    /// counts when it is confirmed, together with the edge that confirms it.
    #[must_use]
    pub const fn accepted_edges(&self) -> u32 {
        self.edges_total
    }

    /// The gap that ended `back` accepted edges before the newest one in
    /// pitches, Q16 (`back` = 0: [`MtEstimator::newest_gap_pitches_q16`]).
    #[must_use]
    pub fn gap_pitches_q16(&self, back: usize) -> u32 {
        self.ground_pitches_q16_of(self.tooth_back(back, self.z.max(1)))
    }

    /// Accepts edge `t` (the glitch rules passed): a new gap, or a restart
    /// after a stop.
    fn take(&mut self, t: u32) -> EdgeVerdict {
        let mut verdict = EdgeVerdict::Accepted;
        if self.has_last {
            let dt = t.wrapping_sub(self.newest());
            if dt > self.cfg.stop_timeout_ticks {
                self.restart();
                verdict = EdgeVerdict::Restart;
            } else if !self.lost {
                // (A gap with lost edges in it is not a tooth period.)
                self.last_gap = dt;
                self.gaps = [dt, self.gaps[0], self.gaps[1]];
                // The glitch reference grows by at most 2× an edge: a gap
                // that spans a short pause must not make the next
                // full-speed gaps look like glitches.
                self.from_rest = false;
                self.glitch_ref = if self.glitch_ref == 0 {
                    dt
                } else {
                    dt.min(self.glitch_ref.saturating_mul(2))
                };
            }
        } else {
            verdict = EdgeVerdict::Restart;
        }
        self.head = self.head.checked_add(1).filter(|&h| h < RING).unwrap_or(0);
        if let Some(s) = self.stamps.get_mut(self.head) {
            *s = t;
        }
        self.last = t;
        if self.has_last {
            self.tooth = self
                .tooth
                .checked_add(1)
                .filter(|&h| h < self.z)
                .unwrap_or(0);
        }
        self.has_last = true;
        self.edges_total = self.edges_total.wrapping_add(1);
        self.valid_run = self.valid_run.saturating_add(1);
        if core::mem::take(&mut self.lost) && verdict == EdgeVerdict::Accepted {
            self.resync();
        }
        verdict
    }

    /// Says that the capture hardware lost one or more edges before the next
    /// one pushed (the F103's overcapture flag CC1OF: a capture came while
    /// the previous one was unread). The interval that ends at the next edge
    /// spans an unknown number of teeth, so it is not measured: the next
    /// edge starts a new window (the speed held until then is kept, and
    /// decays as usual), and the tooth-pitch table, whose tooth index is
    /// now off by the lost count, is dropped and learnt again from whole
    /// revolutions.
    pub fn edges_lost(&mut self) {
        self.lost = true;
    }

    /// Restarts the window and the pitch table at the newest edge after lost
    /// edges, keeping the held speed.
    fn resync(&mut self) {
        self.ref_stamp = self.newest();
        self.ref_edges = self.edges_total;
        self.ref_valid = true;
        self.valid_run = 1;
        self.gaps = [0; 3];
        self.weights = [0; MAX_TEETH];
        self.harmonic = [0; MAX_TEETH];
        self.weight_sum = u32::try_from(self.z).unwrap_or(0).saturating_mul(ONE_Q16);
        self.samples = [0; MAX_TEETH];
        self.learned_upto = self.edges_total;
        self.steady = 0;
        self.rough = NOISY_START_Q16;
    }

    fn restart(&mut self) {
        self.pending = None;
        self.steady = 0;
        self.calm = 0;
        self.from_rest = true;
        self.valid_run = 0;
        self.last_gap = 0;
        self.gaps = [0; 3];
        self.glitch_ref = 0;
        self.ref_valid = false;
        self.history_len = 0;
        self.held = 0;
    }

    fn newest(&self) -> u32 {
        self.last
    }

    /// Sum of the weights of the `m` gaps ending at the newest edge (Q16).
    fn window_weight(&self, m: u32) -> u64 {
        self.window_weight_from(self.tooth, m)
    }

    /// Sum of the weights of the `m` gaps ending with tooth `idx`'s (Q16).
    fn window_weight_from(&self, mut idx: usize, m: u32) -> u64 {
        let z = u32::try_from(self.z).unwrap_or(1).max(1);
        let full = u64::from(m.checked_div(z).unwrap_or(0));
        let rem = usize::try_from(m.checked_rem(z).unwrap_or(0)).unwrap_or(0);
        let mut sum = full.saturating_mul(u64::from(self.weight_sum));
        for _ in 0..rem {
            sum = sum.saturating_add(u64::from(self.weight(idx)));
            idx = if idx == 0 {
                self.z.saturating_sub(1)
            } else {
                idx.saturating_sub(1)
            };
        }
        sum
    }

    /// The window while the newest gap's tooth is not learnt: the `new`
    /// gaps since the last window, or, at a steady speed, the steady run
    /// they extend, up to a revolution (a whole revolution has no tooth
    /// error at all; k gaps carry at most ±4 %/k of it). A gap whose speed
    /// is more than [`STEADY_BREAK`] off the run's is a change of speed:
    /// the run starts again there. Returns the gap count and the start
    /// stamp.
    fn steady_window(&mut self, new: u32) -> (u32, u32) {
        let newest = self.newest();
        let single = self.rpm_bits(self.window_weight(new), newest.wrapping_sub(self.ref_stamp));
        let z = u32::try_from(self.z).unwrap_or(1);
        let long = self
            .steady
            .saturating_add(new)
            .min(z)
            .min(STEADY_RUN_MAX)
            .min(self.valid_run.saturating_sub(1))
            .min(u32::try_from(RING).unwrap_or(1).saturating_sub(1));
        self.trend = (0, 0);
        if long <= new {
            self.steady = new;
            return (new, self.ref_stamp);
        }
        let start = self
            .stamps
            .get(ring_prev(self.head, usize::try_from(long).unwrap_or(0)))
            .copied()
            .unwrap_or(self.ref_stamp);
        let run = self.rpm_bits(self.window_weight(long), newest.wrapping_sub(start));
        if let Some(trend) = self.run_trend(long, start, run) {
            // The speed changes along the run: its mean lags; the window is
            // the new gaps, the run goes on growing to see the trend.
            self.trend = trend;
            self.calm = 0;
            self.steady = long;
            return (new, self.ref_stamp);
        }
        let broke = u64::from(single.abs_diff(run)).saturating_mul(STEADY_BREAK) > u64::from(run);
        let calm_before = self.calm;
        self.calm = if broke {
            0
        } else {
            self.calm.saturating_add(1)
        };
        if broke || calm_before < STEADY_SETTLE {
            self.steady = if broke { new } else { long };
            (new, self.ref_stamp)
        } else {
            self.steady = long;
            (long, start)
        }
    }

    /// Whether the speed changes along the run (`run` over the `long` gaps
    /// since `start`): its mean against the mean of the `k` gaps before it
    /// (as many as the run holds, or as are known; at least
    /// [`STEADY_SETTLE`]) differs by more than unlearnt teeth can make plus
    /// [`TREND_MARGIN_PCT`]. Each tooth's edge lies within ±2 % of a pitch
    /// of its place, so a mean over k gaps is off by at most ±4 %/k. Beyond
    /// that the run's mean lags the speed by half the run (a pull-away
    /// through a 2.5 s chassis, 1–2 % a gap at Low 2: 3 % and more). Returns
    /// the change (U12F20 bits) over the ticks between the two means'
    /// middles, or `None`.
    fn run_trend(&self, long: u32, start: u32, run: u32) -> Option<(i32, u32)> {
        // As many gaps before the run as it holds, or as are known.
        let k = long.min(self.valid_run.saturating_sub(long.saturating_add(1)));
        let back = usize::try_from(long.saturating_add(k)).ok()?;
        if k < u32::from(STEADY_SETTLE) || back >= RING {
            return None;
        }
        let first = self.stamps.get(ring_prev(self.head, back)).copied()?;
        let tooth = self.tooth_back(usize::try_from(long).ok()?, self.z.max(1));
        let before = self.rpm_bits(self.window_weight_from(tooth, k), start.wrapping_sub(first));
        // |run − before| > (4/long + 4/k + TREND_MARGIN_PCT) % of the run.
        let (long, k) = (u64::from(long), u64::from(k));
        let bound = long
            .saturating_mul(k)
            .saturating_mul(TREND_MARGIN_PCT)
            .saturating_add(long.saturating_add(k).saturating_mul(4));
        let trends = u64::from(run.abs_diff(before))
            .saturating_mul(long)
            .saturating_mul(k)
            .saturating_mul(100)
            > u64::from(run).saturating_mul(bound);
        let change = i64::from(run).wrapping_sub(i64::from(before));
        // The two means' middles lie half of each segment apart.
        let ticks = self.newest().wrapping_sub(first) / 2;
        (trends && ticks > 0).then(|| (i32::try_from(change).unwrap_or(0), ticks))
    }

    /// 60·f·2²⁰ (< 2⁵⁸): r/min in U12F20 per share over ticks.
    fn rpm_scale(&self) -> u64 {
        u64::from(self.cfg.timer_hz).wrapping_mul(60) << 20
    }

    /// r/min (U12F20 bits, saturating) for an angle `w` (Q16 shares) over `ticks`.
    fn rpm_bits(&self, w: u64, ticks: u32) -> u32 {
        // S < 2^22 and T < 2^32: the product is exact.
        let den = u64::from(self.weight_sum).saturating_mul(u64::from(ticks));
        if den == 0 {
            return u32::MAX;
        }
        // n = 60·f·(w/S)/T r/min; ·2^20 for U12F20; the weights carry z·2^16 per rev in S.
        // w·60·f·2^20 is formed exactly in 128 bits.
        fx::mul_div(w, self.rpm_scale(), den)
            .and_then(|q| u32::try_from(q).ok())
            .unwrap_or(u32::MAX)
    }

    /// Learns the share of the gap [`LEARN_HALF`] gaps behind each fresh
    /// edge (module docs, "Tooth-pitch compensation").
    fn learn(&mut self) {
        let fresh = self.edges_total.wrapping_sub(self.learned_upto);
        self.learned_upto = self.edges_total;
        let z = self.z;
        let mut learnt = false;
        for b in 0..usize::try_from(fresh.min(4)).unwrap_or(0) {
            // The centre gap ends `b + LEARN_HALF` edges back; its farthest
            // neighbour starts `b + 2·LEARN_HALF + 1` back.
            let reach = b.saturating_add(2 * LEARN_HALF + 1);
            if reach >= RING || u32::try_from(reach).map_or(true, |r| r >= self.valid_run) {
                break;
            }
            learnt |= self.learn_gap(b.saturating_add(LEARN_HALF), z);
        }
        if learnt {
            self.harmonic = crate::harmonic::first_harmonic_q16(&self.weights, z);
        }
    }

    /// One sample for the gap ending `c` edges back: its time against the
    /// parabola through its neighbours' per-pitch times.
    fn learn_gap(&mut self, c: usize, z: usize) -> bool {
        let (mut sum, mut lo, mut hi) = (0i64, i32::MAX, 0i32);
        for back in c.saturating_sub(LEARN_HALF)..=c.saturating_add(LEARN_HALF) {
            let Some(&w) = LEARN_WEIGHTS.get(back.abs_diff(c).wrapping_sub(1)) else {
                continue; // the centre itself
            };
            let u = self.per_pitch(back, z);
            sum = sum.wrapping_add(i64::from(w).wrapping_mul(i64::from(u)));
            lo = lo.min(u);
            hi = hi.max(u);
        }
        // sum = reference · LEARN_DIVISOR (< 2⁴⁷: 12 · 2¹³ · 2³¹).
        let Ok(reference) = u64::try_from(sum) else {
            return false;
        };
        // (< 2³¹: × SPREAD_GATE × LEARN_DIVISOR < 2⁴⁹.)
        let spread = u64::from(hi.wrapping_sub(lo).unsigned_abs());
        // The sample: gap / reference, Q16 (< 2³³ · 2¹⁶ · 2¹⁵).
        let sample = u64::from(self.gap_back(c))
            .wrapping_mul(u64::from(ONE_Q16))
            .wrapping_mul(LEARN_DIVISOR)
            .checked_div(reference)
            .and_then(|v| i32::try_from(v).ok())
            .unwrap_or(0);
        let one = i32::try_from(ONE_Q16).unwrap_or(0);
        // Within ±6.25 % of a pitch (a gap between two teeth each up to
        // ±2 % of a pitch off their places is up to ±4 % long, and a
        // gate at the edge of that range kept such a tooth unlearnt for
        // minutes); the neighbours within SPREAD_GATE.
        if sample.abs_diff(one) > SAMPLE_GATE_Q16
            || spread.wrapping_mul(SPREAD_GATE * LEARN_DIVISOR) > reference
        {
            return false;
        }
        let tooth = self.tooth_back(c, z);
        let n = self.samples.get(tooth).copied().unwrap_or(0);
        let w = i32::try_from(self.weight(tooth)).unwrap_or(one);
        let mut step = sample.wrapping_sub(w);
        if self.rough != 0 {
            // The learning's mean deviation (1/8 a sample); learnt once it
            // is below the limit: noisy no more (until the table is dropped).
            let rough = i32::try_from(self.rough).unwrap_or(i32::MAX);
            let r = rough.wrapping_add(step.abs().wrapping_sub(rough) / 8);
            self.rough = if r <= i32::try_from(NOISY_LIMIT_Q16).unwrap_or(0) {
                0
            } else {
                r.unsigned_abs()
            };
        }
        if n >= SHARE_CLIP_FROM {
            step = step.clamp(-SHARE_CLIP_Q16, SHARE_CLIP_Q16);
        }
        let n = n.saturating_add(1).min(SHARE_SAMPLES);
        let w = w.wrapping_add(step.checked_div(i32::from(n)).unwrap_or(0));
        if let Some(slot) = self.weights.get_mut(tooth) {
            *slot = weight_to_offset(w.unsigned_abs());
        }
        if let Some(cnt) = self.samples.get_mut(tooth) {
            *cnt = n;
        }
        // The shares' mean back to 1 (the reference cannot see a common
        // scale, so it would wander); then their sum.
        let teeth = self.weights.get_mut(..z).unwrap_or(&mut []);
        let total: i32 = teeth.iter().map(|&d| i32::from(d)).sum();
        let mean = total
            .checked_div(i32::try_from(z).unwrap_or(1))
            .unwrap_or(0);
        let mut sum_w = 0u32;
        for d in teeth.iter_mut() {
            *d = i16::try_from(i32::from(*d).wrapping_sub(mean)).unwrap_or(0);
            sum_w = sum_w.saturating_add(weight_from_offset(*d));
        }
        self.weight_sum = sum_w;
        true
    }

    /// The gap that ended `back` accepted edges before the newest one, ticks.
    fn gap_back(&self, back: usize) -> u32 {
        let i = ring_prev(self.head, back);
        let before = i.checked_sub(1).unwrap_or(RING - 1);
        let stamp = |j: usize| self.stamps.get(j).copied().unwrap_or(0);
        stamp(i).wrapping_sub(stamp(before))
    }

    /// The tooth index of the gap that ended `back` edges before the newest.
    #[inline(never)]
    fn tooth_back(&self, back: usize, z: usize) -> usize {
        self.tooth
            .wrapping_add(z.saturating_mul(2))
            .wrapping_sub(back.checked_rem(z).unwrap_or(0))
            .checked_rem(z)
            .unwrap_or(0)
    }

    /// That gap's time per nominal pitch: gap / share, the share 1 + d (Q16
    /// offset d within ±4 %) as 1 − d + d² (error d³ < 7·10⁻⁵): no division.
    fn per_pitch(&self, back: usize, z: usize) -> i32 {
        let d = i32::from(
            self.weights
                .get(self.tooth_back(back, z))
                .copied()
                .unwrap_or(0),
        );
        // |d| < 2¹⁵: 0 < inv < 2¹⁸.
        let inv = i32::try_from(ONE_Q16)
            .unwrap_or(0)
            .wrapping_sub(d)
            .wrapping_add(d.wrapping_mul(d) >> 16)
            .unsigned_abs();
        // gap < 2³² ticks, inv < 2¹⁸: the product < 2⁵⁰; a real gap (below
        // the stop timeout, < 2³¹) gives < 2³¹ after the shift.
        let t = u64::from(self.gap_back(back)).wrapping_mul(u64::from(inv)) >> 16;
        i32::try_from(t).unwrap_or(i32::MAX)
    }

    /// Computes the speed at `now` (call periodically from the control task).
    pub fn update(&mut self, now: Ticks) -> TravelMeasurement {
        let newest = self.newest();
        let since = now.0.wrapping_sub(newest);
        let since_edge_ticks = if !self.has_last || since > 1 << 31 {
            0
        } else {
            since
        };
        let mut out = TravelMeasurement {
            gear_speed: RevPerMin::ZERO,
            state: MotionState::Stopped,
            edges: 0,
            window_ticks: 0,
            since_edge_ticks,
            glitches: self.glitches,
            noisy: false,
            trend: (0, 0),
        };
        if !self.has_last {
            return out;
        }
        let new = self.edges_total.wrapping_sub(self.ref_edges);
        if new > 0 && self.valid_run > 0 {
            if self.cfg.pitch_compensation {
                self.learn();
            }
            // Window start: the previous window's last edge, or after a
            // restart the oldest edge still in the ring. While the single
            // gaps read noisy (their teeth not learnt yet), at a steady speed
            // the window reaches back over the steady run
            // ([`MtEstimator::steady_window`]).
            let (m, start) = if self.ref_valid && new < self.valid_run {
                out.noisy = self.is_noisy();
                if self.cfg.pitch_compensation && out.noisy {
                    let w = self.steady_window(new);
                    out.trend = self.trend;
                    w
                } else {
                    self.steady = 0;
                    (new, self.ref_stamp)
                }
            } else {
                let back = self
                    .valid_run
                    .saturating_sub(1)
                    .min(u32::try_from(RING).unwrap_or(1).saturating_sub(1));
                let start = self
                    .stamps
                    .get(ring_prev(self.head, usize::try_from(back).unwrap_or(0)))
                    .copied()
                    .unwrap_or(newest);
                self.steady = back;
                (back, start)
            };
            self.ref_stamp = newest;
            self.ref_edges = self.edges_total;
            self.ref_valid = true;
            // A gap whose own tooth has not been learnt yet reads noisy
            // too, whatever the rest of the table: its share is still
            // nominal, up to twice the gear's tooth tolerance off, and the
            // predictor must not carry that along as a slope.
            if self.cfg.pitch_compensation
                && self.samples.get(self.tooth).copied().unwrap_or(0) < LEARNT_SAMPLES
            {
                out.noisy = true;
            }
            let window = newest.wrapping_sub(start);
            if m == 0 || window == 0 {
                out.state = MotionState::Starting;
                return out;
            }
            let rpm = self.rpm_bits(self.window_weight(m), window);
            self.push_history(rpm);
            self.held = if self.cfg.median_of_3 && self.history_len >= 3 {
                let [a, b, c] = self.history;
                median3(a, b, c)
            } else {
                rpm
            };
            out.state = MotionState::Measured;
            out.edges = m;
            out.window_ticks = window;
            out.gear_speed = RevPerMin::from_fixed(U12F20::from_bits(self.held));
            return out;
        }
        if !self.ref_valid || since_edge_ticks > self.cfg.stop_timeout_ticks {
            if self.ref_valid {
                self.restart();
            }
            out.state = if self.ref_valid || self.valid_run == 0 {
                MotionState::Stopped
            } else {
                MotionState::Starting
            };
            return out;
        }
        // No new edge: cap at one (learned) gap over the elapsed time.
        let next = self
            .tooth
            .checked_add(1)
            .filter(|&t| t < self.z)
            .unwrap_or(0);
        // A tooth not learnt yet may be up to 4 % of a pitch long (and the
        // capture jitter): its gap gets 5 % more before it counts as late,
        // so that a long tooth does not read as a slowing machine.
        let w_next = u64::from(self.weight(next));
        let w_next = if self.samples.get(next).copied().unwrap_or(0) < LEARNT_SAMPLES {
            w_next.saturating_add(w_next / 20)
        } else {
            w_next
        };
        // cap < held ⇔ ⌊w·scale / (S·since)⌋ < held ⇔ w·scale < held·S·since:
        // the products compared, the division only once it decays (most
        // control periods hold: 300 instructions a period saved).
        let den = u64::from(self.weight_sum).saturating_mul(u64::from(since_edge_ticks));
        if fx::mul_lt(w_next, self.rpm_scale(), u64::from(self.held), den) {
            out.state = MotionState::Decaying;
            let cap = self.rpm_bits(w_next, since_edge_ticks);
            out.gear_speed = RevPerMin::from_fixed(U12F20::from_bits(cap));
        } else {
            out.state = MotionState::Holding;
            out.gear_speed = RevPerMin::from_fixed(U12F20::from_bits(self.held));
        }
        out
    }

    fn push_history(&mut self, v: u32) {
        self.history = [self.history[1], self.history[2], v];
        self.history_len = self.history_len.saturating_add(1).min(3);
    }
}
