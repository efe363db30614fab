//! Profile B (SPEC §8, paper B): seedling-belt feeding and planting motors.
//!
//! * planting frequency `f = 60·Vm/X` (eq. 1);
//! * planting motor `n1 = 60·β·Vm/(2π·N·X)` (eq. 4) with β in radians, i.e.
//!   `n1 = f·β°/(360·N)`: one revolution of the flexible disc plants
//!   `360/β°·N` seedlings;
//! * feeding motor `n2 = 60·Vm·B/(2π·X·(r + h·j))` (eq. 9), `j` roller turns;
//! * step-pulse frequency `f_step = n·steps_per_rev/60`;
//! * [`Linkage`]: the speed-linkage rule as a small state machine.
//!
//! Defaults for the constants paper B does not publish (documented in
//! `docs/kinematics.md`): β = 120°, N = 2, r = 25 mm, h = 1 mm, Y = 0.02 m/s,
//! 1600 steps per revolution; X = 25 cm and B = 10 cm are the paper's bench
//! values.

use fixed::types::U16F16;

use crate::fx;
use crate::units::{Hertz, Metres, MetresPerSecond, PerMinute, RevPerMin};
use crate::Error;

/// Profile B settings; [`ProfileBSettings::build`] validates them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProfileBSettings {
    /// Target plant spacing X.
    pub plant_spacing: Metres,
    /// Seedling pitch on the belt B.
    pub belt_pitch: Metres,
    /// Clamping angle β of the flexible disc, degrees.
    pub clamping_angle_deg: U16F16,
    /// Seedlings clamped at once within β, N.
    pub seedlings_clamped: u8,
    /// Initial equivalent radius r of the seedling roller.
    pub roller_radius: Metres,
    /// Seedling-belt thickness h (radius growth per roller turn).
    pub belt_thickness: Metres,
    /// Speed-change threshold Y.
    pub threshold: MetresPerSecond,
    /// Step pulses per revolution of the planting motor.
    pub planting_steps_per_rev: u32,
    /// Step pulses per revolution of the feeding motor.
    pub feeding_steps_per_rev: u32,
}

#[cfg(feature = "defmt")]
impl defmt::Format for ProfileBSettings {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "ProfileB(X={}, B={}, beta={=u32}/65536 deg, N={=u8}, r={}, h={}, Y={})",
            self.plant_spacing,
            self.belt_pitch,
            self.clamping_angle_deg.to_bits(),
            self.seedlings_clamped,
            self.roller_radius,
            self.belt_thickness,
            self.threshold
        );
    }
}

impl Default for ProfileBSettings {
    fn default() -> Self {
        Self {
            plant_spacing: const { Metres::lit("0.25") },
            belt_pitch: const { Metres::lit("0.10") },
            clamping_angle_deg: const { U16F16::lit("120") },
            seedlings_clamped: 2,
            roller_radius: const { Metres::lit("0.025") },
            belt_thickness: const { Metres::lit("0.001") },
            threshold: const { MetresPerSecond::lit("0.02") },
            planting_steps_per_rev: 1600,
            feeding_steps_per_rev: 1600,
        }
    }
}

/// Why [`ProfileBSettings::build`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ProfileBConfigError {
    /// Plant spacing or belt pitch is zero.
    ZeroLength,
    /// β outside (0, 360] degrees.
    ClampingAngle,
    /// N is zero.
    ZeroSeedlings,
    /// Roller radius is zero.
    ZeroRadius,
    /// Steps per revolution is zero.
    ZeroSteps,
}

impl core::fmt::Display for ProfileBConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ProfileBConfigError::ZeroLength => "plant spacing and belt pitch must be positive",
            ProfileBConfigError::ClampingAngle => "clamping angle must be in (0, 360] degrees",
            ProfileBConfigError::ZeroSeedlings => "seedlings clamped must be at least 1",
            ProfileBConfigError::ZeroRadius => "roller radius must be positive",
            ProfileBConfigError::ZeroSteps => "steps per revolution must be positive",
        })
    }
}

impl core::error::Error for ProfileBConfigError {}

impl ProfileBSettings {
    /// Validates the settings.
    pub fn build(self) -> Result<ProfileB, ProfileBConfigError> {
        if self.plant_spacing == Metres::ZERO || self.belt_pitch == Metres::ZERO {
            return Err(ProfileBConfigError::ZeroLength);
        }
        if self.clamping_angle_deg == U16F16::ZERO
            || self.clamping_angle_deg > const { U16F16::lit("360") }
        {
            return Err(ProfileBConfigError::ClampingAngle);
        }
        if self.seedlings_clamped == 0 {
            return Err(ProfileBConfigError::ZeroSeedlings);
        }
        if self.roller_radius == Metres::ZERO {
            return Err(ProfileBConfigError::ZeroRadius);
        }
        if self.planting_steps_per_rev == 0 || self.feeding_steps_per_rev == 0 {
            return Err(ProfileBConfigError::ZeroSteps);
        }
        Ok(ProfileB { s: self })
    }
}

/// Validated profile B kinematics.
///
/// ```
/// use kinematics::profile_b::ProfileBSettings;
/// use kinematics::units::MetresPerSecond;
/// let b = ProfileBSettings::default().build()?;
/// let vm = MetresPerSecond::lit("0.3");
/// // f = 60·0.3/0.25 = 72 per minute (paper B: 72 at 0.3 m/s).
/// assert!((b.planting_frequency(vm)?.to_f64() - 72.0).abs() < 1e-3);
/// // n1 = 72·120/(360·2) = 12 r/min; 1600 steps/rev ⇒ 320 Hz.
/// let n1 = b.planting_motor_speed(vm)?;
/// assert!((n1.to_f64() - 12.0).abs() < 1e-3);
/// // n2 at j = 0: 60·0.3·0.10/(2π·0.25·0.025) = 45.837 r/min.
/// assert!((b.feeding_motor_speed(vm, 0)?.to_f64() - 45.837).abs() < 1e-3);
/// // after 10 roller turns r' = 0.035 m: 1.8/(2π·0.25·0.035) = 32.740 r/min (h = 1 mm is
/// // stored to 1 µm: ±0.05 %, hence 5e-3).
/// assert!((b.feeding_motor_speed(vm, 10)?.to_f64() - 32.740).abs() < 5e-3);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProfileB {
    s: ProfileBSettings,
}

impl Default for ProfileB {
    /// [`ProfileBSettings::default`], which [`ProfileBSettings::build`]
    /// accepts (tested), without a fallible build.
    fn default() -> Self {
        Self {
            s: ProfileBSettings::default(),
        }
    }
}

impl ProfileB {
    /// The validated settings.
    #[must_use]
    pub const fn settings(&self) -> &ProfileBSettings {
        &self.s
    }

    /// Eq. 1: planting frequency `f = 60·Vm/X`, per minute.
    pub fn planting_frequency(&self, vm: MetresPerSecond) -> Result<PerMinute, Error> {
        crate::drum::plants_per_minute(vm, self.s.plant_spacing)
    }

    /// Eq. 4: planting motor speed `n1 = f·β°/(360·N)`.
    pub fn planting_motor_speed(&self, vm: MetresPerSecond) -> Result<RevPerMin, Error> {
        let f = fx::div(fx::mul_int(vm.w(), 60)?, self.s.plant_spacing.w())?;
        let num = fx::mul(f, fx::widen_bits(self.s.clamping_angle_deg.to_bits(), 16))?;
        let den = 360u64.saturating_mul(u64::from(self.s.seedlings_clamped));
        RevPerMin::try_from_w(fx::div_int(num, den)?)
    }

    /// Eq. 8: roller radius after `j` turns, `r' = r + h·j`.
    pub fn roller_radius(&self, j: u32) -> Result<Metres, Error> {
        let grow = fx::mul_int(self.s.belt_thickness.w(), u64::from(j))?;
        Metres::try_from_w(fx::add(self.s.roller_radius.w(), grow)?)
    }

    /// Eq. 9: feeding motor speed `n2 = 60·Vm·B/(2π·X·(r + h·j))`.
    pub fn feeding_motor_speed(&self, vm: MetresPerSecond, j: u32) -> Result<RevPerMin, Error> {
        let r = self.roller_radius(j)?;
        let num = fx::mul_int(fx::mul(vm.w(), self.s.belt_pitch.w())?, 60)?;
        let den = fx::mul(
            fx::mul_int(fx::PI, 2)?,
            fx::mul(self.s.plant_spacing.w(), r.w())?,
        )?;
        RevPerMin::try_from_w(fx::div(num, den)?)
    }
}

/// Step-pulse frequency for a motor speed: `n·steps_per_rev/60` Hz.
///
/// ```
/// use kinematics::profile_b::step_frequency;
/// use kinematics::units::RevPerMin;
/// // 12 r/min at 1600 steps/rev = 320 Hz.
/// assert_eq!(step_frequency(RevPerMin::lit("12"), 1600)?.to_f64(), 320.0);
/// # Ok::<(), kinematics::Error>(())
/// ```
pub fn step_frequency(speed: RevPerMin, steps_per_rev: u32) -> Result<Hertz, Error> {
    Hertz::try_from_w(fx::div_int(
        fx::mul_int(speed.w(), u64::from(steps_per_rev))?,
        60,
    )?)
}

/// What the linkage decided in one cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkageAction {
    /// Vm = 0: both motors stopped.
    Stop,
    /// |Vm − V0| > Y (or starting): both speeds recomputed.
    Recompute,
    /// Roller turns `j` incremented: n2 recomputed for the new radius.
    RecomputeFeeding,
    /// Nothing changed enough: keep the speeds.
    Hold,
}

/// Motor speeds and step rates after one linkage cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MotorCommands {
    /// The decision.
    pub action: LinkageAction,
    /// The travel speed the speeds were computed for (V0).
    pub computed_for: MetresPerSecond,
    /// Planting motor speed n1.
    pub planting_speed: RevPerMin,
    /// Feeding motor speed n2.
    pub feeding_speed: RevPerMin,
    /// Planting motor step rate.
    pub planting_step_hz: Hertz,
    /// Feeding motor step rate.
    pub feeding_step_hz: Hertz,
}

/// The linkage rule of paper B as a state machine.
///
/// Decision (the paper is ambiguous): `V0` is the travel speed the motor
/// speeds were last *computed* for, so a slow drift accumulates until it
/// exceeds `Y` (the paper's text can be read as saving every reading, which
/// would let a slow drift never trigger).
///
/// ```
/// use kinematics::profile_b::{Linkage, LinkageAction, ProfileBSettings};
/// use kinematics::units::MetresPerSecond as Mps;
/// let mut l = Linkage::new(ProfileBSettings::default().build()?);
/// assert_eq!(l.step(Mps::lit("0.30"), 0)?.action, LinkageAction::Recompute);
/// assert_eq!(l.step(Mps::lit("0.31"), 0)?.action, LinkageAction::Hold); // within Y = 0.02
/// assert_eq!(l.step(Mps::lit("0.31"), 1)?.action, LinkageAction::RecomputeFeeding);
/// assert_eq!(l.step(Mps::lit("0.33"), 1)?.action, LinkageAction::Recompute);
/// assert_eq!(l.step(Mps::ZERO, 1)?.action, LinkageAction::Stop);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Linkage {
    plan: ProfileB,
    last: Option<MotorCommands>,
    j0: u32,
}

impl Linkage {
    /// A stopped linkage.
    #[must_use]
    pub const fn new(plan: ProfileB) -> Self {
        Self {
            plan,
            last: None,
            j0: 0,
        }
    }

    /// One cycle with the measured travel speed `vm` and roller turns `j`.
    pub fn step(&mut self, vm: MetresPerSecond, j: u32) -> Result<MotorCommands, Error> {
        let s = self.plan.settings();
        if vm == MetresPerSecond::ZERO {
            self.last = None;
            self.j0 = j;
            return Ok(MotorCommands {
                action: LinkageAction::Stop,
                computed_for: MetresPerSecond::ZERO,
                planting_speed: RevPerMin::ZERO,
                feeding_speed: RevPerMin::ZERO,
                planting_step_hz: Hertz::ZERO,
                feeding_step_hz: Hertz::ZERO,
            });
        }
        let (action, v0, n1) = match self.last {
            Some(c) if vm.abs_diff(c.computed_for) <= s.threshold => {
                if j == self.j0 {
                    self.last = Some(MotorCommands {
                        action: LinkageAction::Hold,
                        ..c
                    });
                    return Ok(MotorCommands {
                        action: LinkageAction::Hold,
                        ..c
                    });
                }
                (
                    LinkageAction::RecomputeFeeding,
                    c.computed_for,
                    c.planting_speed,
                )
            }
            _ => (
                LinkageAction::Recompute,
                vm,
                self.plan.planting_motor_speed(vm)?,
            ),
        };
        let n2 = self.plan.feeding_motor_speed(v0, j)?;
        // A step rate beyond `Hertz` (65 536 Hz: a fine micro-step setting
        // at a sane motor speed) saturates: the caller's step-rate ceiling
        // clamps it and warns; only motor speeds out of range are errors.
        let hz = |n, spr| step_frequency(n, spr).unwrap_or(Hertz::MAX);
        let cmd = MotorCommands {
            action,
            computed_for: v0,
            planting_speed: n1,
            feeding_speed: n2,
            planting_step_hz: hz(n1, s.planting_steps_per_rev),
            feeding_step_hz: hz(n2, s.feeding_steps_per_rev),
        };
        self.last = Some(cmd);
        self.j0 = j;
        Ok(cmd)
    }
}
