//! The drum drive's model: its gain (`n_max`, the drum speed at 100 %
//! duty), time constant τ and dead time, as persisted in the settings
//! (format version 3) and used by the feed-forward and the controller's
//! drum model.

use core::fmt;

/// The drum drive's first-order-plus-dead-time model, validated.
///
/// Speed at duty `d` (0–1): `n_max · d`, reached through a first-order lag
/// of time constant τ after a dead time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveModel {
    n_max_x100: u16,
    tau_x10_ms: u16,
    dead_time_x10_ms: u16,
}

/// Which parameter of a [`DriveModel`] is out of range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveModelError {
    /// `n_max` outside [`DriveModel::N_MAX_RANGE`] (r/min × 100).
    NMax(u16),
    /// τ outside [`DriveModel::TAU_RANGE`] (0.1 ms).
    Tau(u16),
    /// Dead time above [`DriveModel::DEAD_TIME_MAX`] (0.1 ms).
    DeadTime(u16),
}

impl fmt::Display for DriveModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NMax(v) => write!(f, "drive n_max {v} (r/min x100) outside 1000-9000"),
            Self::Tau(v) => write!(f, "drive time constant {v} (0.1 ms) outside 10-5000"),
            Self::DeadTime(v) => write!(f, "drive dead time {v} (0.1 ms) above 2000"),
        }
    }
}

/// Bytes of [`DriveModel::to_bytes`].
pub const DRIVE_MODEL_BYTES: usize = 6;

impl DriveModel {
    /// Accepted `n_max`, r/min × 100: 10–90 r/min (the paper's drive is
    /// 44.7; identification covers ±30 % and more).
    pub const N_MAX_RANGE: core::ops::RangeInclusive<u16> = 1000..=9000;
    /// Accepted τ, 0.1 ms: 1–500 ms.
    pub const TAU_RANGE: core::ops::RangeInclusive<u16> = 10..=5000;
    /// Largest accepted dead time, 0.1 ms: 200 ms.
    pub const DEAD_TIME_MAX: u16 = 2000;

    /// The drive the firmware was designed on (SPEC §3, paper A): `n_max`
    /// 44.70 r/min, τ 25 ms, dead time 5 ms. Used until an identification
    /// is saved.
    pub const DEFAULT: Self = Self {
        n_max_x100: 4470,
        tau_x10_ms: 250,
        dead_time_x10_ms: 50,
    };

    /// A validated model: `n_max` in r/min × 100, τ and dead time in 0.1 ms.
    pub fn new(
        n_max_x100: u16,
        tau_x10_ms: u16,
        dead_time_x10_ms: u16,
    ) -> Result<Self, DriveModelError> {
        if !Self::N_MAX_RANGE.contains(&n_max_x100) {
            return Err(DriveModelError::NMax(n_max_x100));
        }
        if !Self::TAU_RANGE.contains(&tau_x10_ms) {
            return Err(DriveModelError::Tau(tau_x10_ms));
        }
        if dead_time_x10_ms > Self::DEAD_TIME_MAX {
            return Err(DriveModelError::DeadTime(dead_time_x10_ms));
        }
        Ok(Self {
            n_max_x100,
            tau_x10_ms,
            dead_time_x10_ms,
        })
    }

    /// Drum speed at 100 % duty, r/min × 100.
    pub const fn n_max_x100(&self) -> u16 {
        self.n_max_x100
    }

    /// Time constant, 0.1 ms.
    pub const fn tau_x10_ms(&self) -> u16 {
        self.tau_x10_ms
    }

    /// Dead time, 0.1 ms.
    pub const fn dead_time_x10_ms(&self) -> u16 {
        self.dead_time_x10_ms
    }

    /// `[n_max, τ, dead time]`, each u16 little endian.
    pub fn to_bytes(&self) -> [u8; DRIVE_MODEL_BYTES] {
        let [a0, a1] = self.n_max_x100.to_le_bytes();
        let [b0, b1] = self.tau_x10_ms.to_le_bytes();
        let [c0, c1] = self.dead_time_x10_ms.to_le_bytes();
        [a0, a1, b0, b1, c0, c1]
    }

    /// Parses and validates [`DriveModel::to_bytes`].
    pub fn from_bytes(b: &[u8; DRIVE_MODEL_BYTES]) -> Result<Self, DriveModelError> {
        let [a0, a1, b0, b1, c0, c1] = *b;
        Self::new(
            u16::from_le_bytes([a0, a1]),
            u16::from_le_bytes([b0, b1]),
            u16::from_le_bytes([c0, c1]),
        )
    }
}

impl Default for DriveModel {
    fn default() -> Self {
        Self::DEFAULT
    }
}

// ---------------------------------------------------------------------------
// Fixed-point helpers (no FPU on the Cortex-M3; no `libm` on the control path)
// ---------------------------------------------------------------------------

/// 1.0 in Q30.
const Q30: i64 = 1 << 30;
/// ln 2 in Q30: 0.693 147 180 56 · 2³⁰ = 744 261 117.95.
const LN2_Q30: i64 = 744_261_118;

/// `num / den` in Q30 for `0 < num ≤ den`; `None` otherwise.
fn ratio_q30(mut num: i64, mut den: i64) -> Option<i64> {
    if num <= 0 || den <= 0 || num > den {
        return None;
    }
    // Keep `num << 30` inside i64.
    while den > (1 << 32) {
        num >>= 1;
        den >>= 1;
    }
    if num == 0 {
        return None;
    }
    num.checked_shl(30)?.checked_div(den)
}

/// `ln x` in Q30 for `x` in Q30, `0 < x ≤ 1` (so the result is ≤ 0).
///
/// `x = m · 2^−k` with `m ∈ [½, 1]`, `ln m = 2·atanh z`, `z = (m − 1)/(m + 1)
/// ∈ [−⅓, 0]`, summed to `z¹⁵` (the rest below 2·10⁻⁹).
pub fn ln_q30(x_q30: i64) -> Option<i64> {
    if x_q30 <= 0 || x_q30 > Q30 {
        return None;
    }
    let mut m = x_q30;
    let mut k: i64 = 0;
    while m < Q30 / 2 {
        m = m.checked_shl(1)?;
        k = k.checked_add(1)?;
    }
    let z = m
        .checked_sub(Q30)?
        .checked_shl(30)?
        .checked_div(m.checked_add(Q30)?)?;
    let z2 = z.checked_mul(z)? >> 30;
    // z · (1 + z²/3 + z⁴/5 + … + z¹⁴/15), Horner from the inside.
    let mut sum: i64 = 0;
    for d in [15i64, 13, 11, 9, 7, 5, 3] {
        sum = (Q30.checked_div(d)?.checked_add(sum)?).checked_mul(z2)? >> 30;
    }
    let atanh = (Q30.checked_add(sum)?).checked_mul(z)? >> 30;
    atanh.checked_mul(2)?.checked_sub(k.checked_mul(LN2_Q30)?)
}

/// `e^−x` in Q30 for `x ≥ 0` in Q30 (0 for `x` beyond 40).
pub fn exp_neg_q30(x_q30: i64) -> i64 {
    if x_q30 <= 0 {
        return Q30;
    }
    if x_q30 > 40 * Q30 {
        return 0;
    }
    // x = n·ln2 + r, r ∈ [0, ln2): e^−x = e^−r / 2ⁿ; e^−r by Taylor to r⁹/9!
    // (|terms| ≤ 1 in Q30: no overflow).
    let n = x_q30 / LN2_Q30;
    let r = x_q30 % LN2_Q30;
    let mut term = Q30;
    let mut sum = Q30;
    for i in 1..=9i64 {
        term = (term.saturating_mul(r) >> 30)
            .saturating_neg()
            .checked_div(i)
            .unwrap_or(0);
        sum = sum.saturating_add(term);
    }
    sum >> n
}

// ---------------------------------------------------------------------------
// Identification
// ---------------------------------------------------------------------------

/// Control periods per hold of the identification (1 s at 10 ms).
pub const HOLD_PERIODS: usize = 100;
/// The first half of a hold is the transient; the second gives the level.
const HALF: usize = HOLD_PERIODS / 2;
/// Steps after the first (settling) hold: up, down, up, down, up, down.
pub const IDENTIFY_STEPS: u16 = 6;
/// The two duties the drum is stepped between, ‰ of full scale.
pub const IDENTIFY_DUTY_LOW_PERMILLE: u16 = 250;
/// See [`IDENTIFY_DUTY_LOW_PERMILLE`].
pub const IDENTIFY_DUTY_HIGH_PERMILLE: u16 = 750;

/// Why an identification gave no model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IdentifyError {
    /// The drum did not move, or did not follow the duty steps.
    NoMotion,
    /// The speed was still changing at the end of a hold: a drive slower
    /// than τ + dead time ≈ 0.4 s (it cannot be identified in 1 s holds),
    /// or a belt with seedlings on it, whose load moves the speed by a few
    /// % as each partition passes (the QEMU board's default 5 % load fails
    /// here; the screen asks for an empty belt).
    NotSettled,
    /// No step gave a usable time constant (the response is noise).
    Noisy,
    /// The measured model is outside [`DriveModel`]'s accepted ranges.
    OutOfRange,
    /// Stopped by the operator (Stop, or an alarm).
    Aborted,
}

impl IdentifyError {
    /// The text for the screen (ASCII, at most 40 characters).
    pub const fn text(self) -> &'static str {
        match self {
            Self::NoMotion => "Identify: drum did not follow",
            Self::NotSettled => "Identify: speed not steady (belt empty?)",
            Self::Noisy => "Identify: response too noisy",
            Self::OutOfRange => "Identify: result out of range",
            Self::Aborted => "Identify: stopped",
        }
    }
}

impl fmt::Display for IdentifyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.text())
    }
}

/// Where an identification stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IdentifyState {
    /// Not started.
    Idle,
    /// Stepping the drum.
    Running,
    /// Finished: the model measured, shown until it is saved or discarded.
    Done(DriveModel),
    /// Finished without a model.
    Failed(IdentifyError),
}

/// The drive identification: steps the drum between 25 % and 75 % duty
/// (1 s holds: one to settle, then six steps) and fits a
/// first-order-plus-dead-time model to the measured period speeds.
///
/// The measurement of a period is the mean speed over it (encoder counts
/// over 10 ms), so for a step at `t = 0` of size `Δn` the deficit
/// `eₖ = n∞ − n̄ₖ` of period `k` is, once `kT ≥ L`,
/// `Δn·(τ/T)(1 − a)·e^{L/τ}·aᵏ` with `a = e^{−T/τ}`: geometric. Hence
///
/// - the **gain** from the levels: `n_max = Δn / Δduty`;
/// - **`L + τ`** from the area of the deficits, `Σ eₖ·T = Δn·(L + τ)`
///   (exact for period means: the sum of counts telescopes);
/// - **τ** from the ratio of window sums, `S(m+p)/S(m) = aᵖ` with
///   `S(m) = Σ_{m≤k<m+w} eₖ` and `m = ⌈(L + τ)/T⌉` (so that `mT ≥ L`): first
///   `p = 1, w = 3`, then `p` the nearest whole number of periods to that
///   first τ and `w = 2p + 1` (so that `aᵖ ≈ 1/e`, where the ratio is best
///   conditioned, and the windows stay where the deficit is well above the
///   level's noise);
/// - **L** = `(L + τ) − τ`.
///
/// Down steps give the same with the signs reversed; the gain and `L + τ`
/// are pooled over the six steps, τ averaged. Host tests
/// (`crates/supervisor/tests/drive.rs`) recover all three within 10 % on
/// drives with gain ±30 %, τ × 0.35–3 and dead time 0–60 ms.
#[derive(Debug, Clone)]
pub struct Identifier {
    state: IdentifyState,
    /// Control steps since the start.
    calls: u16,
    /// Speeds measured in the first half of the hold being recorded, r/min
    /// × 256 (1/256 r/min is 30 times finer than one encoder count per
    /// period; ±127 r/min covers every accepted `n_max`). Kept small: the
    /// supervisor lives in the board's RAM.
    samples: [i16; HALF],
    /// Sums of the second half's two quarters, r/min × 256.
    quarter: [i64; 2],
    /// Σ of the second half of the previous hold (its level × `HALF`).
    prev_level: i64,
    /// Pooled deficit areas and level changes (× `HALF`), sign-corrected.
    sum_area: i64,
    sum_delta: i64,
    /// Σ τ of the steps, periods in Q16, and how many steps gave one.
    sum_tau_q16: i64,
    taus: u16,
    /// Control period, µs.
    period_us: u32,
}

impl Identifier {
    /// Idle, for a control period of `period_us`.
    pub const fn new(period_us: u32) -> Self {
        Self {
            state: IdentifyState::Idle,
            calls: 0,
            samples: [0; HALF],
            quarter: [0; 2],
            prev_level: 0,
            sum_area: 0,
            sum_delta: 0,
            sum_tau_q16: 0,
            taus: 0,
            period_us,
        }
    }

    /// The state.
    pub const fn state(&self) -> IdentifyState {
        self.state
    }

    /// Starts (or restarts) from the first hold.
    pub fn start(&mut self) {
        *self = Self::new(self.period_us);
        self.state = IdentifyState::Running;
    }

    /// Ends a running identification without a model.
    pub fn abort(&mut self) {
        if self.state == IdentifyState::Running {
            self.state = IdentifyState::Failed(IdentifyError::Aborted);
        }
    }

    /// Back to idle (the result was saved or discarded).
    pub fn clear(&mut self) {
        self.state = IdentifyState::Idle;
    }

    /// One control period: `measured` is the drum speed over the period
    /// that just ended (I16F16 r/min). Returns the duty to apply now, ‰, or
    /// `None` when not running (drum off).
    pub fn step(&mut self, measured: i32) -> Option<u16> {
        if self.state != IdentifyState::Running {
            return None;
        }
        let hold_len = u16::try_from(HOLD_PERIODS).unwrap_or(u16::MAX);
        if self.calls > 0 {
            // This measurement belongs to the duty applied at the previous
            // call: hold (calls − 1) / H, index (calls − 1) % H.
            let i = self.calls.saturating_sub(1);
            let j = usize::from(i.checked_rem(hold_len).unwrap_or(0));
            let v = i16::try_from(measured >> 8).unwrap_or(if measured < 0 {
                i16::MIN
            } else {
                i16::MAX
            });
            if j == 0 {
                self.quarter = [0; 2];
            }
            if let Some(s) = self.samples.get_mut(j) {
                *s = v;
            } else if let Some(q) = self
                .quarter
                .get_mut(usize::from(j >= HALF.saturating_add(HALF / 2)))
            {
                *q = q.saturating_add(i64::from(v));
            }
            if j == HOLD_PERIODS - 1 {
                let hold = i.checked_div(hold_len).unwrap_or(0);
                if let Err(e) = self.end_of_hold(hold) {
                    self.state = IdentifyState::Failed(e);
                    return None;
                }
                if hold == IDENTIFY_STEPS {
                    self.state = match self.result() {
                        Ok(model) => IdentifyState::Done(model),
                        Err(e) => IdentifyState::Failed(e),
                    };
                    return None;
                }
            }
        }
        let hold = self.calls.checked_div(hold_len).unwrap_or(0);
        self.calls = self.calls.saturating_add(1);
        Some(if hold.is_multiple_of(2) {
            IDENTIFY_DUTY_LOW_PERMILLE
        } else {
            IDENTIFY_DUTY_HIGH_PERMILLE
        })
    }

    fn end_of_hold(&mut self, hold: u16) -> Result<(), IdentifyError> {
        let s = &self.samples;
        let [q1, q2] = self.quarter;
        let level = q1.saturating_add(q2);
        // Settled: the two quarters of the second half agree within 2 % of
        // the level (they are means of 25 periods each).
        if q2.abs_diff(q1).saturating_mul(100) > level.unsigned_abs().saturating_mul(2) / 2 {
            return Err(IdentifyError::NotSettled);
        }
        // 1 r/min in the samples' unit.
        let one_rpm: i64 = 1 << 8;
        let half = i64::try_from(HALF).unwrap_or(1);
        if hold == 0 {
            if level < one_rpm.saturating_mul(half) {
                return Err(IdentifyError::NoMotion);
            }
            self.prev_level = level;
            return Ok(());
        }
        let delta = level.saturating_sub(self.prev_level);
        let up = hold % 2 == 1;
        if (up && delta < one_rpm.saturating_mul(half))
            || (!up && delta > one_rpm.saturating_mul(half).saturating_neg())
        {
            return Err(IdentifyError::NoMotion);
        }
        // Deficits × HALF, positive for both directions.
        let deficit = |k: usize| -> i64 {
            let d = level
                .saturating_sub(half.saturating_mul(i64::from(s.get(k).copied().unwrap_or(0))));
            if up {
                d
            } else {
                d.saturating_neg()
            }
        };
        let window = |from: usize, len: usize| -> i64 {
            (from..from.saturating_add(len).min(HALF))
                .map(deficit)
                .sum()
        };
        let area = window(0, HALF);
        let dn = delta.abs();
        self.sum_area = self.sum_area.saturating_add(area);
        self.sum_delta = self.sum_delta.saturating_add(dn);
        self.prev_level = level;
        // m = ⌈(L + τ)/T⌉ for this step.
        let m = usize::try_from(
            area.max(0)
                .saturating_add(dn.saturating_sub(1))
                .checked_div(dn.max(1))
                .unwrap_or(0),
        )
        .unwrap_or(HALF);
        if m.saturating_add(2) >= HALF {
            return Err(IdentifyError::NotSettled);
        }
        // Windows of equal length `w` from m and from m + p: their ratio is
        // aᵖ exactly, and a short window keeps the level's noise (× w) out
        // of the small tail.
        let tau_of = |p: usize, w: usize| -> Option<i64> {
            if m.saturating_add(p).saturating_add(w) > HALF {
                return None;
            }
            let r = ratio_q30(window(m.saturating_add(p), w), window(m, w))?;
            let ln = ln_q30(r)?;
            if ln >= 0 {
                return None;
            }
            // τ = −p / ln r periods, Q16.
            i64::try_from(p)
                .ok()?
                .checked_shl(46)?
                .checked_div(ln.checked_neg()?)
        };
        if let Some(tau1) = tau_of(1, 3) {
            let p = usize::try_from(tau1.saturating_add(1 << 15) >> 16)
                .unwrap_or(1)
                .clamp(1, HALF.saturating_sub(m) / 4);
            if let Some(tau) = tau_of(p, p.saturating_mul(2).saturating_add(1)) {
                self.sum_tau_q16 = self.sum_tau_q16.saturating_add(tau);
                self.taus = self.taus.saturating_add(1);
            }
        }
        Ok(())
    }

    fn result(&self) -> Result<DriveModel, IdentifyError> {
        if self.sum_delta <= 0 {
            return Err(IdentifyError::NoMotion);
        }
        let t_us = i64::from(self.period_us);
        // τ: a step whose deficit is gone after one period (τ ≲ 2 ms) gives
        // no ratio; if none gives one, τ is below what 10 ms periods
        // resolve: the smallest accepted, 1 ms.
        let tau_x10 = if self.taus == 0 {
            i64::from(*DriveModel::TAU_RANGE.start())
        } else {
            // Periods Q16 → 0.1 ms: × T_us / 100.
            (self
                .sum_tau_q16
                .checked_div(i64::from(self.taus))
                .unwrap_or(0))
            .saturating_mul(t_us)
            .checked_div(100 << 16)
            .unwrap_or(0)
        };
        // L + τ = Σ area / Σ Δ periods → 0.1 ms.
        let total_x10 = self
            .sum_area
            .saturating_mul(t_us)
            .checked_div(self.sum_delta.saturating_mul(100))
            .unwrap_or(0);
        let dead_x10 = total_x10.saturating_sub(tau_x10).max(0);
        // Gain: mean |Δn| per step / Δduty (0.5), r/min × 256 → × 100.
        let steps = i64::from(IDENTIFY_STEPS);
        let half = i64::try_from(HALF).unwrap_or(1);
        let dduty_permille =
            i64::from(IDENTIFY_DUTY_HIGH_PERMILLE.saturating_sub(IDENTIFY_DUTY_LOW_PERMILLE));
        let n_max_x100 = self
            .sum_delta
            .saturating_mul(100 * 1000)
            .checked_div(steps.saturating_mul(half).saturating_mul(dduty_permille))
            .map(|v| v.saturating_add(1 << 7) >> 8)
            .unwrap_or(0);
        let narrow = |v: i64| u16::try_from(v).map_err(|_| IdentifyError::OutOfRange);
        DriveModel::new(narrow(n_max_x100)?, narrow(tau_x10)?, narrow(dead_x10)?)
            .map_err(|_| IdentifyError::OutOfRange)
    }
}

#[cfg(test)]
#[allow(clippy::cast_precision_loss, clippy::cast_possible_truncation)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ONE: f64 = (1u64 << 30) as f64;

    proptest! {
        /// Against f64 `ln` over (0, 1]: within 2·10⁻⁸ absolute (a few Q30
        /// LSBs; the identification needs 10⁻³).
        #[test]
        fn ln_matches_f64(x in 1i64..=(1 << 30)) {
            let got = ln_q30(x).unwrap() as f64 / ONE;
            let want = (x as f64 / ONE).ln();
            prop_assert!((got - want).abs() < 2e-8, "{} vs {}", got, want);
        }

        /// Against f64 `exp` over [0, 40]: within 10⁻⁸ absolute.
        #[test]
        fn exp_neg_matches_f64(x in 0i64..=(40 << 30)) {
            let got = exp_neg_q30(x) as f64 / ONE;
            let want = (-(x as f64) / ONE).exp();
            prop_assert!((got - want).abs() < 1e-8, "{} vs {}", got, want);
        }
    }

    #[test]
    fn drive_model_ranges_and_bytes() {
        // DEFAULT is the paper's drive: 44.70 r/min, 25 ms, 5 ms.
        let d = DriveModel::DEFAULT;
        assert_eq!(
            (d.n_max_x100(), d.tau_x10_ms(), d.dead_time_x10_ms()),
            (4470, 250, 50)
        );
        assert_eq!(DriveModel::from_bytes(&d.to_bytes()), Ok(d));
        assert_eq!(
            DriveModel::new(999, 250, 0),
            Err(DriveModelError::NMax(999))
        );
        assert_eq!(
            DriveModel::new(9001, 250, 0),
            Err(DriveModelError::NMax(9001))
        );
        assert_eq!(DriveModel::new(4470, 9, 0), Err(DriveModelError::Tau(9)));
        assert_eq!(
            DriveModel::new(4470, 5001, 0),
            Err(DriveModelError::Tau(5001))
        );
        assert_eq!(
            DriveModel::new(4470, 250, 2001),
            Err(DriveModelError::DeadTime(2001))
        );
        assert!(DriveModel::new(1000, 10, 2000).is_ok());
        for e in [
            IdentifyError::NoMotion,
            IdentifyError::NotSettled,
            IdentifyError::Noisy,
            IdentifyError::OutOfRange,
            IdentifyError::Aborted,
        ] {
            assert!(e.text().is_ascii() && e.text().len() <= 40);
        }
    }
}
