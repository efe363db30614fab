//! What the drum's controller takes from the drive model: the feed-forward
//! gain, the reference model, the scheduled and the conservative
//! controllers.

use fuzzy_pid::I16F16;

use super::fix::centi_to_fix;
use crate::drive::{exp_neg_q30, DriveModel};

/// Smoothing factor of the reference model of the drum on the default drive,
/// `1 − e^(−Ts/τ)` with `Ts` = 10 ms and the motor's `τ` = 25 ms. With a
/// drive model ([`DriveModel`], identified on page 9) the factor is computed
/// from its τ and the model's input is delayed by its dead time
/// (docs/firmware.md, "The drum drive model"); on the default model that
/// is this value and two periods.
///
/// The model predicts what the *measurement* (encoder counts over the period
/// that just ended) should read if the feed-forward alone drove the drum:
/// a first-order lag on the command of two periods ago. Two periods because
/// the command set at step k acts after the drive's 5 ms dead time and is
/// seen averaged over the period ending at step k + 1. For a step command
/// this reproduces the averaged response of a 25 ms lag with 5 ms dead time
/// to within 1 % of the step from the second period on (0, 0.33, 0.55, 0.70
/// of the step against the exact 0.05, 0.33, 0.55, 0.70).
///
/// Why: the feed-forward already drives the drum to the target; comparing the
/// measurement with the *target* during a speed change would feed the PID an
/// error that only reflects the drum's lag, wind up the integral and
/// overshoot. Comparing it with the modelled response leaves the PID only the
/// part of the error the feed-forward cannot explain (load, slip, model
/// mismatch): a two-degree-of-freedom structure.
pub const REFERENCE_ALPHA: I16F16 = I16F16::lit("0.3297");

/// Targets the reference model remembers: a dead time up to 200 ms
/// ([`DriveModel::DEAD_TIME_MAX`]) is 1 + 21 periods of 10 ms.
pub(super) const REF_HISTORY: usize = 24;

/// What the controller takes from the drive model: the feed-forward gain
/// (`n_max`), the reference model's smoothing and delay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct DriveLaw {
    /// Drum speed at 100 % duty, r/min × 100.
    pub(super) n_max_x100: u16,
    /// `n_max` in r/min.
    pub(super) n_max: I16F16,
    /// `1 − e^(−T/τ)`.
    pub(super) ref_alpha: I16F16,
    /// Periods from a target to the reference model's lag input:
    /// `1 + round((L + T/2)/T)` (the command acts after the dead time `L`
    /// and is seen in the mean of the period it falls in, half a period
    /// later on average). 2 on the default drive, as before the model.
    pub(super) ref_delay: usize,
}

impl DriveLaw {
    pub(super) fn of(model: &DriveModel, period_us: u32) -> Self {
        let t_x10 = i64::from(period_us / 100).max(1);
        let tau_x10 = i64::from(model.tau_x10_ms()).max(1);
        let dead_x10 = i64::from(model.dead_time_x10_ms());
        // T/τ in Q30 (T ≤ 6553.5 ms, τ ≥ 1 ms: ≤ 2^16 · 2^30).
        let x = (t_x10 << 30).checked_div(tau_x10).unwrap_or(0);
        let alpha_q30 = (1i64 << 30).saturating_sub(exp_neg_q30(x));
        let ref_alpha = I16F16::from_bits(i32::try_from(alpha_q30 >> 14).unwrap_or(i32::MAX));
        let periods = dead_x10
            .saturating_add(t_x10 / 2)
            .saturating_add(t_x10 / 2)
            .checked_div(t_x10)
            .unwrap_or(0);
        let ref_delay = usize::try_from(periods.saturating_add(1))
            .unwrap_or(REF_HISTORY)
            .clamp(2, REF_HISTORY);
        Self {
            n_max_x100: model.n_max_x100(),
            n_max: centi_to_fix(model.n_max_x100()),
            ref_alpha,
            ref_delay,
        }
    }
}

/// The controller scheduled from the drive model: [`drum_controller_config`]
/// with every gain (base gains, fuzzy ranges, floors) scaled by
/// `s = min(1, (τ/θ) / (τ₀/θ₀))`, output limited to the model's `n_max`.
///
/// `θ = L + T` is the loop's effective dead time (the drive's dead time
/// plus half a period of PWM hold and half a period of measurement mean),
/// `τ₀/θ₀ = 25/15` the drive the fuzzy PID was tuned on. The proportional
/// gain SIMC gives a first-order-plus-dead-time plant, `Kc = τ/(K·2θ)`
/// (τc = θ), scales with `τ/θ`; so does the integral gain at a fixed
/// `τI = τ` and the ultimate gain when θ ≫ τ. Keeping the product's
/// proven gains where the drive is as fast as or slower than the design
/// (`s = 1`) and shrinking all of them in the SIMC ratio where the dead time
/// grows or τ shrinks keeps the fuzzy tuner's shape and the nominal
/// behaviour (bench §1) unchanged. docs/fuzzy-pid.md has the table.
pub fn scheduled_config(model: &DriveModel, period_us: u32) -> fuzzy_pid::Config {
    let mut config = drum_controller_config();
    let s = schedule_scale(model, period_us);
    let scale = |g: fuzzy_pid::Gains| fuzzy_pid::Gains {
        kp: g.kp.saturating_mul(s),
        ki: g.ki.saturating_mul(s),
        kd: g.kd.saturating_mul(s),
    };
    config.base = scale(config.base);
    config.min_gains = scale(config.min_gains);
    if let fuzzy_pid::Schedule::Fuzzy(fuzzy) = &mut config.schedule {
        fuzzy.range = scale(fuzzy.range);
    }
    config.output_max = centi_to_fix(model.n_max_x100());
    config
}

/// The scale `s` of [`scheduled_config`], in (0, 1].
pub fn schedule_scale(model: &DriveModel, period_us: u32) -> I16F16 {
    // In 0.1 ms: τ₀ = 250, θ₀ = 50 + 100 (5 ms dead time + 10 ms period).
    let t_x10 = i64::from(period_us / 100);
    let theta = i64::from(model.dead_time_x10_ms())
        .saturating_add(t_x10)
        .max(1);
    let theta0 = 50i64.saturating_add(t_x10);
    let s = i64::from(model.tau_x10_ms())
        .saturating_mul(theta0)
        .saturating_mul(1 << 16)
        .checked_div(theta.saturating_mul(250))
        .unwrap_or(0)
        .clamp(1, 1 << 16);
    I16F16::from_bits(i32::try_from(s).unwrap_or(1 << 16))
}

/// Smoothing of the phase loop's correction when the drum's loop runs
/// through the drive link (`DriveLinkSettings::delays_control`):
/// `1 − e^(−10 ms / 100 ms)`. The correction steps at every Hall edge (the
/// ground is exact there and extrapolated between edges); a loop that sees
/// the drum 30–90 ms late (the read-back) or moves it a transaction late
/// (the bus command) answers such steps with an overshoot, and the
/// instability supervisor tripped in 6 of 80 rows of 70 m at 9600 baud (seeds
/// 1–40, PWM and Modbus command)
/// (test `distance_locked_rows_on_the_readback_raise_no_instability_warning`).
/// 100 ms is the slowest link's delay; against the phase loop's 0.5 s it
/// costs at most atan(0.2) ≈ 11° of phase margin.
pub(super) const PHASE_SMOOTHING: I16F16 = I16F16::lit("0.0952");
/// How fast the phase correction's smoothing fades out when it is no longer
/// needed: its factor rises by this much a period, from [`PHASE_SMOOTHING`]
/// to 1 in 0.5 s, so that the correction does not jump to its unsmoothed
/// value.
pub(super) const PHASE_FADE: I16F16 = I16F16::lit("0.02");

/// The conservative mode after an instability: no proportional or
/// derivative action, integral only with `Ki` = [`FALLBACK_KI`] per period,
/// on top of the feed-forward and the reference model.
///
/// An integrator with gain `Ki/T` behind a delay θ has its crossover at
/// `Ki/T` rad/s and a phase margin of `90° − Ki·θ/T`: with `Ki` = 0.02 and
/// up to 200 ms of effective dead time (the longest a drive model holds)
/// that is ≥ 67°, and ≥ 44° with a drive twice as strong as its model. The
/// price: load changes are corrected in about `T/Ki` = 0.5 s.
pub fn fallback_config(model: &DriveModel) -> fuzzy_pid::Config {
    let mut config = fuzzy_pid::Config::conventional(fuzzy_pid::Gains {
        kp: I16F16::ZERO,
        ki: FALLBACK_KI,
        kd: I16F16::ZERO,
    });
    config.output_max = centi_to_fix(model.n_max_x100());
    config
}

/// Integral gain per period of the conservative mode ([`fallback_config`]).
pub const FALLBACK_KI: I16F16 = I16F16::lit("0.02");

/// Half-width of the product's ΔKp domain (per sample): `Kp ∈ [1, 3]`
/// around `Kp0` = 2, where paper A allows ±5 (`Kp` up to 7).
///
/// Chosen from the robustness sweep of `cargo xtask bench` (docs/PERFORMANCE.md
/// §1): with ±5 the 7×7 tuner raises `Kp` to ≈ 5 at an overspeed error, which
/// is beyond the loop's margin (5 ms dead time, 10 ms measurement) once the
/// motor is faster than the drum model — on a drive with half the model's
/// 25 ms lag the drum oscillated between 17 and 36 r/min and never settled.
/// ±1.5 and below settle there (±1: 13 % overshoot, 1.1 s) and change nothing
/// on the nominal drum (1.2 % overshoot, 0.10 s, as with ±5), on a plant with
/// 20 % less or more gain, or on a slower motor. ±1 leaves a margin below
/// the ±1.5 edge. ΔKi and ΔKd keep the paper's ranges: they did not move the
/// limit.
pub const PRODUCT_DELTA_KP_RANGE: fuzzy_pid::I16F16 = fuzzy_pid::I16F16::ONE;

/// The drum controller: paper A's fuzzy self-tuning PID (7×7 rules,
/// `Kp0` = 2, `Ki0` = 0.1, `Kd0` = 0.05, the paper's rule tables and the
/// ΔKi, ΔKd ranges of SPEC §5) with the ΔKp range narrowed to
/// [`PRODUCT_DELTA_KP_RANGE`] for robustness against a faster drive.
///
/// The paper's base gains work on this drum as they stand because the PID
/// sees only the error the feed-forward cannot explain (the drum model of
/// `Supervisor::control_step`).
/// Compared against its measurement-vs-target form, with which the same gains
/// swung the drum between 0 and 100 % duty, and against ¼ and ½ of the gains,
/// which could not hold the seedlings' per-partition load (±5 % at 1.5 Hz)
/// within 0.5 % (`tests/closed_loop.rs`).
pub fn drum_controller_config() -> fuzzy_pid::Config {
    let mut config = fuzzy_pid::Config::default();
    if let fuzzy_pid::Schedule::Fuzzy(fuzzy) = &mut config.schedule {
        fuzzy.range.kp = PRODUCT_DELTA_KP_RANGE;
    }
    config
}
#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;

    #[test]
    fn the_default_drive_model_reproduces_the_design_controller() {
        // The default model (44.70 r/min, 25 ms, 5 ms) is the drive the
        // controller was tuned on: scale 1, the same configuration, the
        // reference model's 2 periods and α = 1 − e^(−10/25) = 0.329 680.
        let model = DriveModel::DEFAULT;
        assert_eq!(schedule_scale(&model, 10_000), I16F16::ONE);
        let mut design = drum_controller_config();
        design.output_max = I16F16::from_num(44.7);
        let scheduled = scheduled_config(&model, 10_000);
        assert_eq!(scheduled.base, design.base);
        assert_eq!(scheduled.schedule, design.schedule);
        assert_eq!(scheduled.min_gains, design.min_gains);
        assert!((scheduled.output_max - design.output_max).abs() < I16F16::from_num(0.0001));
        let law = DriveLaw::of(&model, 10_000);
        assert_eq!(law.ref_delay, 2);
        let alpha = 1.0 - (-0.4f64).exp();
        assert!((law.ref_alpha.to_num::<f64>() - alpha).abs() < 2e-5);
        assert!((REFERENCE_ALPHA.to_num::<f64>() - alpha).abs() < 1e-4);
    }

    #[test]
    fn scheduled_configs_build_for_extreme_models() {
        // The corners of DriveModel's ranges: every scheduled configuration
        // (and the fallback) builds, so the controller `new` defers can
        // always be built.
        for n in [1000u16, 9000] {
            for tau in [10u16, 5000] {
                for dead in [0u16, 2000] {
                    let m = DriveModel::new(n, tau, dead).unwrap();
                    assert!(scheduled_config(&m, 10_000).build().is_ok(), "{m:?}");
                    assert!(fallback_config(&m).build().is_ok(), "{m:?}");
                }
            }
        }
    }

    #[test]
    fn the_schedule_shrinks_with_dead_time_and_a_faster_drive() {
        // s = min(1, (τ/θ)/(25/15)), θ = L + 10 ms (hand-computed).
        let s = |tau_x10, dead_x10| {
            schedule_scale(&DriveModel::new(4470, tau_x10, dead_x10).unwrap(), 10_000)
                .to_num::<f64>()
        };
        assert!((s(250, 200) - 0.5).abs() < 1e-4); // 25/30 / (25/15)
        assert!((s(88, 600) - 8.8 / 70.0 * 15.0 / 25.0).abs() < 1e-4);
        assert_eq!(s(750, 0), 1.0); // slower drive: the design gains
                                    // Reference delay 1 + round((L + 5 ms)/10 ms): 60 ms → 7 + 1 = 8.
        let law = DriveLaw::of(&DriveModel::new(4470, 250, 600).unwrap(), 10_000);
        assert_eq!(law.ref_delay, 8);
    }
}
