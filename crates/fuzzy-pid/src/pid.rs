//! The PID around the tuner: positional form, feed-forward, derivative on the
//! filtered measurement, anti-windup, output limits, bumpless mode changes.
//!
//! One step (auto mode), all `I16F16`:
//!
//! ```text
//! e   = target − measured                  ec = e − e_prev
//! ΔK  = tuner(e, ec)                       K  = max(K0 + ΔK, floor ≥ 0)
//! d   = d + α·((y_prev − y) − d)           (filtered −Δy per sample)
//! I'  = I + Ki·e                           (per-sample integral of Ki·e)
//! v   = ff + Kp·e + I' + Kd·d              u = clamp(v, min, max)
//! clamping:         if v is beyond a limit and Ki·e pushes further, I' = I
//! back-calculation: I' += kb·(u − v)
//! ```
//!
//! The integral stores the sum of `Ki·e` (not of `e`), so a gain change never
//! moves the output by itself.

use fixed::types::I16F16;

use crate::fuzzy::{FuzzyConfig, FuzzyTuner, LutTuner};
use crate::{smul, Error, Gains};

type Fix = I16F16;

/// Where the gain corrections come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Schedule {
    /// Conventional PID: fixed gains `K0`.
    Conventional,
    /// Fuzzy self-tuning, direct inference over the active rules.
    Fuzzy(FuzzyConfig),
    /// Fuzzy self-tuning, surface precomputed into a 13×13 lookup table.
    Lookup(FuzzyConfig),
}

/// Integral anti-windup against the output limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AntiWindup {
    /// Conditional integration: do not integrate while the output is beyond a
    /// limit and the error would push it further.
    pub clamping: bool,
    /// Back-calculation (tracking) gain `kb ∈ [0, 1]` per sample: the integral
    /// moves by `kb·(u − v)` towards the value that would just reach the limit.
    /// 0 disables it.
    pub back_calculation: Fix,
}

impl AntiWindup {
    /// No anti-windup at all (for comparisons); the integral is still bounded
    /// by `±(max − min)`.
    pub const NONE: Self = Self {
        clamping: false,
        back_calculation: Fix::ZERO,
    };
}

impl Default for AntiWindup {
    /// Clamping plus back-calculation with `kb = 0.25` (time constant ≈ 4
    /// samples).
    fn default() -> Self {
        Self {
            clamping: true,
            back_calculation: const { Fix::lit("0.25") },
        }
    }
}

/// Controller configuration; [`Config::build`] validates it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    /// Base gains `Kp0`, `Ki0` (per sample), `Kd0` (per sample).
    pub base: Gains,
    /// Gain schedule.
    pub schedule: Schedule,
    /// Floors of the scheduled gains: `K = max(K0 + ΔK, floor)`, each ≥ 0.
    /// SPEC §5 clamps at 0; the default keeps `Ki ≥ 0.05` because with
    /// `Ki0 = 0.1` and ΔKi ∈ ±1.25 the paper's tables drive `Ki` to 0 for any
    /// overspeed beyond ≈ 2 r/min at steady state (rows NS…NB, column ZO are
    /// negative), which freezes the integral and leaves a permanent error (see
    /// `docs/fuzzy-pid.md`). Set to [`Gains::ZERO`] for the literal SPEC clamp.
    pub min_gains: Gains,
    /// Lower output limit, r/min (0).
    pub output_min: Fix,
    /// Upper output limit, r/min (`n_max` = 44.7).
    pub output_max: Fix,
    /// Derivative filter coefficient `α ∈ (0, 1]` (1 = unfiltered; 0.5 default,
    /// a time constant of about one sample).
    pub derivative_filter: Fix,
    /// Anti-windup.
    pub anti_windup: AntiWindup,
}

/// Drum motor maximum speed `n_max`, r/min (SPEC §3).
pub const N_MAX: Fix = Fix::lit("44.7");

/// Paper A eq. 19–21: `Kp0 = 2`, `Ki0 = 0.1`, `Kd0 = 0.05`.
pub const PAPER_BASE: Gains = Gains {
    kp: const { Fix::lit("2") },
    ki: const { Fix::lit("0.1") },
    kd: const { Fix::lit("0.05") },
};

/// Default gain floors: `Kp ≥ 0`, `Ki ≥ 0.05` (half of `Ki0`), `Kd ≥ 0`.
pub const DEFAULT_MIN_GAINS: Gains = Gains {
    kp: Fix::ZERO,
    ki: const { Fix::lit("0.05") },
    kd: Fix::ZERO,
};

impl Default for Config {
    /// The paper's 7×7 fuzzy PID, output `[0, 44.7]` r/min.
    fn default() -> Self {
        Self::with_schedule(Schedule::Fuzzy(FuzzyConfig::default()))
    }
}

impl Config {
    /// Paper base gains and SPEC limits with the given schedule.
    #[must_use]
    pub fn with_schedule(schedule: Schedule) -> Self {
        Self {
            base: PAPER_BASE,
            schedule,
            min_gains: DEFAULT_MIN_GAINS,
            output_min: Fix::ZERO,
            output_max: N_MAX,
            derivative_filter: const { Fix::lit("0.5") },
            anti_windup: AntiWindup::default(),
        }
    }

    /// A conventional fixed-gain PID with the given gains (per sample), no gain
    /// floors, and the SPEC limits.
    #[must_use]
    pub fn conventional(base: Gains) -> Self {
        Self {
            base,
            min_gains: Gains::ZERO,
            ..Self::with_schedule(Schedule::Conventional)
        }
    }

    /// Validates the configuration and precomputes the tuner: a conventional
    /// or direct fuzzy [`Controller`] (≈ 400 bytes on thumbv7m).
    ///
    /// A [`Schedule::Lookup`] configuration is refused with
    /// [`Error::LookupSchedule`]: its 1 KB table would sit in every
    /// `Controller`. Build it with [`build_lut`](Self::build_lut) (or
    /// [`build_any`](Self::build_any) to pick the schedule at run time).
    pub fn build(&self) -> Result<Controller, Error> {
        self.build_with()
    }

    /// Like [`build`](Self::build), for any schedule: a controller that holds
    /// whichever tuner the configuration names (≈ 1.2 KB, the lookup table
    /// included). For hosts and tests that switch schedules at run time.
    pub fn build_any(&self) -> Result<AnyController, Error> {
        self.build_with()
    }

    /// Like [`build`](Self::build), for a [`Schedule::Lookup`] configuration
    /// only (a conventional or direct fuzzy one is refused with
    /// [`Error::LookupSchedule`]).
    pub fn build_lut(&self) -> Result<LutController, Error> {
        self.build_with()
    }

    /// Validates the configuration and builds a controller around the gain
    /// schedule type `S` ([`DirectSchedule`], [`LutTuner`] or
    /// [`AnySchedule`]).
    pub fn build_with<S: GainSchedule>(&self) -> Result<Controller<S>, Error> {
        if self.output_min >= self.output_max {
            return Err(Error::OutputLimits);
        }
        let b = self.base;
        let m = self.min_gains;
        if [b.kp, b.ki, b.kd, m.kp, m.ki, m.kd]
            .iter()
            .any(|g| *g < Fix::ZERO)
        {
            return Err(Error::NegativeGain);
        }
        if self.derivative_filter <= Fix::ZERO || self.derivative_filter > Fix::ONE {
            return Err(Error::DerivativeFilter);
        }
        let kb = self.anti_windup.back_calculation;
        if kb < Fix::ZERO || kb > Fix::ONE {
            return Err(Error::BackCalculation);
        }
        let tuner = S::from_schedule(&self.schedule)?;
        let integral_limit = self.output_max.saturating_sub(self.output_min);
        let mut c = Controller {
            tuner,
            base: b,
            min_gains: m,
            output_min: self.output_min,
            output_max: self.output_max,
            alpha: self.derivative_filter,
            clamping: self.anti_windup.clamping,
            kb,
            integral_limit,
            mode: Mode::Off,
            manual_output: Fix::ZERO,
            primed: false,
            prev_error: Fix::ZERO,
            prev_measured: Fix::ZERO,
            derivative: Fix::ZERO,
            integral: Fix::ZERO,
            status: Status::default(),
        };
        c.status.output = c.stopped_output();
        Ok(c)
    }
}

/// A source of gain corrections ΔK for a [`Controller`]: built from a
/// [`Schedule`] and asked once per step.
pub trait GainSchedule: Sized {
    /// Builds the tuner for `schedule`, or refuses a schedule this type cannot
    /// hold ([`Error::LookupSchedule`]) or an invalid fuzzy configuration.
    fn from_schedule(schedule: &Schedule) -> Result<Self, Error>;

    /// ΔKp, ΔKi, ΔKd for error `e` and error change `ec` (zero for a
    /// conventional PID).
    fn delta(&self, e: Fix, ec: Fix) -> Gains;
}

/// The default gain schedule of a [`Controller`]: fixed gains or direct fuzzy
/// inference ([`Schedule::Conventional`] or [`Schedule::Fuzzy`]).
// No heap: the tuner is stored inline (280 bytes), by design.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirectSchedule {
    /// Conventional PID: fixed gains `K0`.
    Conventional,
    /// Fuzzy self-tuning, direct inference over the active rules.
    Fuzzy(FuzzyTuner),
}

impl GainSchedule for DirectSchedule {
    fn from_schedule(schedule: &Schedule) -> Result<Self, Error> {
        match schedule {
            Schedule::Conventional => Ok(Self::Conventional),
            Schedule::Fuzzy(f) => FuzzyTuner::new(f).map(Self::Fuzzy),
            Schedule::Lookup(_) => Err(Error::LookupSchedule),
        }
    }

    #[inline]
    fn delta(&self, e: Fix, ec: Fix) -> Gains {
        match self {
            Self::Conventional => Gains::ZERO,
            Self::Fuzzy(t) => t.infer(e, ec),
        }
    }
}

impl GainSchedule for LutTuner {
    /// Only [`Schedule::Lookup`].
    fn from_schedule(schedule: &Schedule) -> Result<Self, Error> {
        match schedule {
            Schedule::Lookup(f) => Self::new(f),
            Schedule::Conventional | Schedule::Fuzzy(_) => Err(Error::LookupSchedule),
        }
    }

    #[inline]
    fn delta(&self, e: Fix, ec: Fix) -> Gains {
        self.infer(e, ec)
    }
}

/// Any of the three schedules, chosen at run time (holds the lookup table
/// inline, ≈ 1.1 KB).
// No heap: the variants are stored inline, by design.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnySchedule {
    /// Conventional PID: fixed gains `K0`.
    Conventional,
    /// Fuzzy self-tuning, direct inference over the active rules.
    Fuzzy(FuzzyTuner),
    /// Fuzzy self-tuning, surface precomputed into a 13×13 lookup table.
    Lookup(LutTuner),
}

impl GainSchedule for AnySchedule {
    fn from_schedule(schedule: &Schedule) -> Result<Self, Error> {
        Ok(match schedule {
            Schedule::Conventional => Self::Conventional,
            Schedule::Fuzzy(f) => Self::Fuzzy(FuzzyTuner::new(f)?),
            Schedule::Lookup(f) => Self::Lookup(LutTuner::new(f)?),
        })
    }

    #[inline]
    fn delta(&self, e: Fix, ec: Fix) -> Gains {
        match self {
            Self::Conventional => Gains::ZERO,
            Self::Fuzzy(t) => t.infer(e, ec),
            Self::Lookup(t) => t.infer(e, ec),
        }
    }
}

/// A controller with any schedule ([`Config::build_any`]).
pub type AnyController = Controller<AnySchedule>;

/// A lookup-table controller ([`Config::build_lut`]).
pub type LutController = Controller<LutTuner>;

/// Operating mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Stopped: output 0 (clamped to the limits), state cleared.
    #[default]
    Off,
    /// Manual: the output is the operator's value; the controller tracks it so
    /// that switching to auto is bumpless.
    Manual,
    /// Closed loop.
    Auto,
}

/// Whether the last output was limited.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Saturation {
    /// Within limits.
    #[default]
    None,
    /// Clamped to the upper limit.
    Upper,
    /// Clamped to the lower limit.
    Lower,
}

/// What the last step computed, for logs and the HMI.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Status {
    /// Mode during the step.
    pub mode: Mode,
    /// Gains used (`K0 + ΔK`, clamped to the floors, ≥ 0).
    pub gains: Gains,
    /// Error `e = target − measured`, r/min.
    pub error: Fix,
    /// Error change `ec` per sample, r/min.
    pub error_change: Fix,
    /// Proportional term, r/min.
    pub p: Fix,
    /// Integral term (after anti-windup), r/min.
    pub i: Fix,
    /// Derivative term, r/min.
    pub d: Fix,
    /// Output, r/min.
    pub output: Fix,
    /// Limit reached by the unclamped output.
    pub saturation: Saturation,
}

#[cfg(feature = "defmt")]
impl defmt::Format for Status {
    fn format(&self, f: defmt::Formatter<'_>) {
        use crate::milli;
        defmt::write!(
            f,
            "Status {{ {}, {}, e: {=i32}e-3, ec: {=i32}e-3, p: {=i32}e-3, i: {=i32}e-3, d: {=i32}e-3, out: {=i32}e-3, {} }}",
            self.mode,
            self.gains,
            milli(self.error),
            milli(self.error_change),
            milli(self.p),
            milli(self.i),
            milli(self.d),
            milli(self.output),
            self.saturation
        );
    }
}

/// The drum-speed controller: fuzzy (direct or lookup table) or conventional.
///
/// Built by [`Config::build`] (the default schedule type [`DirectSchedule`]:
/// conventional or direct fuzzy), [`Config::build_lut`] or
/// [`Config::build_any`]; starts in [`Mode::Off`]. Call [`step`](Self::step)
/// once per control period (10 ms).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Controller<S = DirectSchedule> {
    tuner: S,
    base: Gains,
    min_gains: Gains,
    output_min: Fix,
    output_max: Fix,
    alpha: Fix,
    clamping: bool,
    kb: Fix,
    integral_limit: Fix,
    mode: Mode,
    manual_output: Fix,
    /// History (`prev_error`, `prev_measured`) valid.
    primed: bool,
    prev_error: Fix,
    prev_measured: Fix,
    derivative: Fix,
    integral: Fix,
    status: Status,
}

impl<S: GainSchedule> Controller<S> {
    /// One control period. `target`, `measured` and `feedforward` in r/min;
    /// returns the output in r/min within the limits. In [`Mode::Off`] the
    /// output is 0 (clamped into the limits); in [`Mode::Manual`] it is the
    /// manual value.
    pub fn step(&mut self, target: Fix, measured: Fix, feedforward: Fix) -> Fix {
        if self.mode == Mode::Off {
            return self.stopped_output();
        }
        let e = target.saturating_sub(measured);
        if !self.primed {
            // Bumpless (re)start: no error-change or derivative kick.
            self.prev_error = e;
            self.prev_measured = measured;
            self.derivative = Fix::ZERO;
            self.primed = true;
        }
        let ec = e.saturating_sub(self.prev_error);
        let delta = self.tuner.delta(e, ec);
        let gains = Gains {
            kp: self.base.kp.saturating_add(delta.kp).max(self.min_gains.kp),
            ki: self.base.ki.saturating_add(delta.ki).max(self.min_gains.ki),
            kd: self.base.kd.saturating_add(delta.kd).max(self.min_gains.kd),
        };
        let raw_d = self.prev_measured.saturating_sub(measured);
        self.derivative = self
            .derivative
            .saturating_add(smul(self.alpha, raw_d.saturating_sub(self.derivative)));
        let p = smul(gains.kp, e);
        let d = smul(gains.kd, self.derivative);
        let base = feedforward.saturating_add(p).saturating_add(d);

        let (output, integral) = if self.mode == Mode::Manual {
            // Track: choose the integral that reproduces the manual output.
            let u = self.clamp_output(self.manual_output);
            (u, self.clamp_integral(u.saturating_sub(base)))
        } else {
            let di = smul(gains.ki, e);
            let mut i = self.clamp_integral(self.integral.saturating_add(di));
            let mut v = base.saturating_add(i);
            if self.clamping
                && ((v > self.output_max && di > Fix::ZERO)
                    || (v < self.output_min && di < Fix::ZERO))
            {
                i = self.integral;
                v = base.saturating_add(i);
            }
            let u = self.clamp_output(v);
            if self.kb != Fix::ZERO && u != v {
                i = self.clamp_integral(i.saturating_add(smul(self.kb, u.saturating_sub(v))));
            }
            (u, i)
        };
        self.integral = integral;
        self.prev_error = e;
        self.prev_measured = measured;
        let unclamped = base.saturating_add(integral);
        self.status = Status {
            mode: self.mode,
            gains,
            error: e,
            error_change: ec,
            p,
            i: integral,
            d,
            output,
            saturation: if unclamped > self.output_max {
                Saturation::Upper
            } else if unclamped < self.output_min {
                Saturation::Lower
            } else {
                Saturation::None
            },
        };
        output
    }

    /// Start (Off → Auto). The first step afterwards initialises the history,
    /// so there is no derivative or error-change kick, and the integral starts
    /// at 0: the output starts at `feedforward + Kp·e + Ki·e`. No effect in
    /// Manual or Auto.
    pub fn start(&mut self) {
        if self.mode == Mode::Off {
            self.clear();
            self.mode = Mode::Auto;
        }
    }

    /// Stop (→ Off): output 0, state cleared.
    pub fn stop(&mut self) {
        self.mode = Mode::Off;
        self.clear();
    }

    /// Manual mode with `output` r/min (clamped to the limits at each step).
    /// From Off this also starts the controller. While in manual the integral
    /// tracks the output, so [`set_auto`](Self::set_auto) is bumpless.
    pub fn set_manual(&mut self, output: Fix) {
        if self.mode == Mode::Off {
            self.clear();
        }
        self.mode = Mode::Manual;
        self.manual_output = output;
    }

    /// Manual → Auto (bumpless: the integral already holds the value that
    /// reproduces the manual output). From Off this is [`start`](Self::start).
    pub fn set_auto(&mut self) {
        if self.mode == Mode::Off {
            self.start();
        } else {
            self.mode = Mode::Auto;
        }
    }

    /// Clears integral, derivative filter and history without changing mode.
    pub fn reset(&mut self) {
        self.clear();
    }

    /// Current mode.
    #[must_use]
    pub const fn mode(&self) -> Mode {
        self.mode
    }

    /// What the last step computed.
    #[must_use]
    pub const fn status(&self) -> &Status {
        &self.status
    }

    /// The integral term (r/min).
    #[must_use]
    pub const fn integral(&self) -> Fix {
        self.integral
    }

    /// The fuzzy tuner's corrections ΔKp, ΔKi, ΔKd for `(e, ec)`, zero for a
    /// conventional controller. Same computation as inside [`step`](Self::step).
    #[must_use]
    pub fn gain_delta(&self, e: Fix, ec: Fix) -> Gains {
        self.tuner.delta(e, ec)
    }

    fn clear(&mut self) {
        self.primed = false;
        self.integral = Fix::ZERO;
        self.derivative = Fix::ZERO;
        self.prev_error = Fix::ZERO;
        self.prev_measured = Fix::ZERO;
        self.status = Status {
            mode: self.mode,
            output: self.stopped_output(),
            ..Status::default()
        };
    }

    fn stopped_output(&self) -> Fix {
        self.clamp_output(Fix::ZERO)
    }

    #[inline]
    fn clamp_output(&self, x: Fix) -> Fix {
        x.max(self.output_min).min(self.output_max)
    }

    #[inline]
    fn clamp_integral(&self, x: Fix) -> Fix {
        x.max(self.integral_limit.saturating_neg())
            .min(self.integral_limit)
    }
}
