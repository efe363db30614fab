//! Target drum speed (paper A eq. 7) and its PWM (eq. 8–10), with the
//! feasibility limit of n_max.
//!
//! `n_roll = (k2/k3) · (D1+2H1)/(D2+2H2) · (Lclap/Lplant) · n_teeth` (eq. 7),
//! `D = n_roll / n_max` (eq. 8), `CCR = D · (ARR2 + 1)` (eq. 9–10).
//!
//! k3 is a table over the *set* drum speed, which itself depends on k3; the
//! plan solves `n·k3(n) = n_uncorrected` with two fixed-point iterations
//! (k3 varies by < 2 % over the whole range, so the second iteration is
//! already far below the fixed-point resolution that matters).

use crate::consts;
use crate::fx::{self, W};
use crate::travel::{Calibration, TravelSpeed};
use crate::units::{
    Coefficient, Duty, KilometresPerHour, Metres, MetresPerSecond, PerMinute, RevPerMin,
};
use crate::Error;

/// Shortest accepted plant spacing (1 cm).
pub const SPACING_MIN: Metres = Metres::lit("0.01");
/// Longest accepted plant spacing (1 m).
pub const SPACING_MAX: Metres = Metres::lit("1.0");

/// Settings of the feed-forward: plant spacing, PWM timer ARR and n_max.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DrumSettings {
    /// Target plant spacing Lplant.
    pub plant_spacing: Metres,
    /// ARR2 of the PWM timer (period = ARR2 + 1 counts).
    pub arr: u16,
    /// Drum speed at 100 % duty (SPEC: 44.7 r/min).
    pub n_max: RevPerMin,
}

/// Why [`DrumSettings::build`] refused the settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DrumConfigError {
    /// Plant spacing outside [`SPACING_MIN`] … [`SPACING_MAX`].
    SpacingOutOfRange,
    /// n_max is zero.
    ZeroMaxSpeed,
    /// A derived constant does not fit its fixed-point type.
    Overflow,
}

impl core::fmt::Display for DrumConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            DrumConfigError::SpacingOutOfRange => "plant spacing outside 1 cm .. 1 m",
            DrumConfigError::ZeroMaxSpeed => "maximum drum speed is zero",
            DrumConfigError::Overflow => "drum settings out of range",
        })
    }
}

impl DrumSettings {
    /// Settings with the SPEC's n_max.
    #[must_use]
    pub const fn new(plant_spacing: Metres, arr: u16) -> Self {
        Self {
            plant_spacing,
            arr,
            n_max: consts::N_MAX,
        }
    }

    /// Validates and precomputes the per-call constants.
    pub fn build(self) -> Result<DrumPlan, DrumConfigError> {
        if self.plant_spacing < SPACING_MIN || self.plant_spacing > SPACING_MAX {
            return Err(DrumConfigError::SpacingOutOfRange);
        }
        if self.n_max == RevPerMin::ZERO {
            return Err(DrumConfigError::ZeroMaxSpeed);
        }
        let ovf = |_| DrumConfigError::Overflow;
        // G = (D1+2H1)/(D2+2H2) · Lclap/Lplant.
        let geom = fx::div(consts::w::GEOM_M, self.plant_spacing.w()).map_err(ovf)?;
        let period = (u64::from(self.arr).saturating_add(1)) << fx::FRAC;
        let ccr_per_rpm = fx::div(period, self.n_max.w()).map_err(ovf)?;
        let duty_per_rpm = fx::div(fx::ONE, self.n_max.w()).map_err(ovf)?;
        let vmax_per_k3 = fx::mul(
            fx::mul(consts::w::VMAX_PER_RPM_M, self.n_max.w()).map_err(ovf)?,
            self.plant_spacing.w(),
        )
        .map_err(ovf)?;
        Ok(DrumPlan {
            settings: self,
            geom,
            ccr_per_rpm,
            duty_per_rpm,
            vmax_per_k3,
        })
    }
}

/// Validated feed-forward plan for one plant spacing and PWM timer.
///
/// ```
/// use kinematics::drum::{DrumSettings, DrumTarget};
/// use kinematics::travel::Calibration;
/// use kinematics::units::{Metres, RevPerMin};
/// let plan = DrumSettings::new(Metres::from_mm(70), 999).build()?;
/// // n_teeth = 10 r/min, k2 = k3 = 1: n_roll = 2.857·(0.05/0.07)·10 = 20.408 r/min,
/// // CCR = 20.408/44.7·1000 = 456.6 → 457.
/// let n_roll = plan.drum_speed(RevPerMin::from_ratio(10, 1).unwrap(),
///     kinematics::units::Coefficient::ONE, &Calibration::identity())?;
/// assert!((n_roll.to_f64() - 20.408).abs() < 1e-3);
/// assert_eq!(plan.ccr(n_roll)?, 457);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DrumPlan {
    settings: DrumSettings,
    /// (D1+2H1)/(D2+2H2) · Lclap/Lplant.
    geom: W,
    /// (ARR+1)/n_max.
    ccr_per_rpm: W,
    /// 1/n_max.
    duty_per_rpm: W,
    /// The feasibility limit for k3 = 1, km/h:
    /// `π·(D2+2H2)·n_max/60 · Lplant/Lclap · 3.6`.
    vmax_per_k3: W,
}

#[cfg(feature = "defmt")]
impl defmt::Format for DrumPlan {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "DrumPlan({})", self.settings);
    }
}

/// A drum command: speed, duty and compare value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DrumCommand {
    /// Target drum speed n_roll.
    pub drum_speed: RevPerMin,
    /// k3 used.
    pub k3: Coefficient,
    /// Duty D = n_roll / n_max.
    pub duty: Duty,
    /// Compare value CCR = D·(ARR+1), rounded to nearest, at most ARR+1
    /// (saturating at 65535 when ARR = 65535).
    pub ccr: u16,
}

/// The outcome of the feed-forward.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DrumTarget {
    /// The drum can follow: run it at `command`.
    Follow(DrumCommand),
    /// The travel speed is too high for this spacing: the drum would need
    /// `requested`; `command` is the best it can do (n_max, 100 %), and
    /// `max_travel_speed` is the highest travel speed this spacing allows.
    Saturated {
        /// The command at n_max.
        command: DrumCommand,
        /// The drum speed eq. 7 asked for.
        requested: RevPerMin,
        /// The highest travel speed the drum can follow at this spacing.
        max_travel_speed: KilometresPerHour,
    },
}

impl DrumTarget {
    /// The command to apply in either case.
    #[must_use]
    pub const fn command(&self) -> &DrumCommand {
        match self {
            DrumTarget::Follow(c) | DrumTarget::Saturated { command: c, .. } => c,
        }
    }

    /// Whether the drum saturated.
    #[must_use]
    pub const fn is_saturated(&self) -> bool {
        matches!(self, DrumTarget::Saturated { .. })
    }
}

impl DrumPlan {
    /// The validated settings.
    #[must_use]
    pub const fn settings(&self) -> &DrumSettings {
        &self.settings
    }

    /// Eq. 7 with the k3 table: the drum speed for a gear speed `n_teeth`
    /// (k1 already applied) and track-slip coefficient `k2`.
    pub fn drum_speed(
        &self,
        gear_speed: RevPerMin,
        k2: Coefficient,
        cal: &Calibration,
    ) -> Result<RevPerMin, Error> {
        let uncorrected = fx::mul(fx::mul(k2.w(), self.geom)?, gear_speed.w())?;
        // Solve n = u / k3(n) by two fixed-point iterations from n = u.
        let mut n = uncorrected;
        for _ in 0..2 {
            let k3 = cal.k3_at(RevPerMin::saturating_from_w(n));
            n = fx::div(uncorrected, k3.w())?;
        }
        RevPerMin::try_from_w(n)
    }

    /// Eq. 8: duty for a drum speed (may exceed 1 if above n_max).
    pub fn duty(&self, drum_speed: RevPerMin) -> Result<Duty, Error> {
        Duty::try_from_w(fx::mul(drum_speed.w(), self.duty_per_rpm)?)
    }

    /// Eq. 10: compare value for a drum speed, rounded to nearest and capped
    /// at ARR+1 (100 %); saturates at 65535.
    pub fn ccr(&self, drum_speed: RevPerMin) -> Result<u16, Error> {
        let raw = fx::mul(drum_speed.w(), self.ccr_per_rpm)?;
        let cap = u32::from(self.settings.arr).saturating_add(1);
        let rounded = u32::try_from(raw.saturating_add(fx::ONE >> 1) >> fx::FRAC)
            .unwrap_or(u32::MAX)
            .min(cap);
        Ok(u16::try_from(rounded).unwrap_or(u16::MAX))
    }

    /// The full feed-forward for a corrected travel measurement.
    ///
    /// ```
    /// use kinematics::drum::{DrumSettings, DrumTarget};
    /// use kinematics::travel::{travel_speed, gear_speed_for, Calibration};
    /// use kinematics::units::{KilometresPerHour, Metres};
    /// let cal = Calibration::paper_defaults();
    /// let plan = DrumSettings::new(Metres::from_mm(70), 999).build()?;
    /// // 1.4 km/h (High 1) is too fast for 7 cm: the limit is ≈ 0.81 km/h.
    /// let v = KilometresPerHour::from_f64(1.4).unwrap().to_mps()?;
    /// let t = travel_speed(gear_speed_for(v)?, &cal)?;
    /// match plan.target(&t, &cal)? {
    ///     DrumTarget::Saturated { max_travel_speed, command, .. } => {
    ///         assert!((max_travel_speed.to_f64() - 0.81).abs() < 0.01);
    ///         assert_eq!(command.ccr, 1000);
    ///     }
    ///     DrumTarget::Follow(_) => panic!("should saturate"),
    /// }
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn target(&self, travel: &TravelSpeed, cal: &Calibration) -> Result<DrumTarget, Error> {
        let n = self.drum_speed(travel.gear_speed, travel.k2, cal)?;
        let n_max = self.settings.n_max;
        // One command for both cases: at n (it follows) or at n_max.
        let drum_speed = n.min(n_max);
        let command = DrumCommand {
            drum_speed,
            k3: cal.k3_at(drum_speed),
            duty: self.duty(drum_speed)?,
            ccr: self.ccr(drum_speed)?,
        };
        if n <= n_max {
            return Ok(DrumTarget::Follow(command));
        }
        Ok(DrumTarget::Saturated {
            command,
            requested: n,
            max_travel_speed: self.max_travel_speed(cal)?,
        })
    }

    /// The highest travel speed V1 the drum can follow at this spacing:
    /// `V1max = k3(n_max)·π·(D2+2H2)·n_max/60 · Lplant/Lclap`.
    pub fn max_travel_speed(&self, cal: &Calibration) -> Result<KilometresPerHour, Error> {
        let k3 = cal.k3_at(self.settings.n_max);
        KilometresPerHour::try_from_w(fx::mul(self.vmax_per_k3, k3.w())?)
    }

    /// Plants per minute per row at travel speed V1: `60·V1/Lplant`.
    pub fn plants_per_minute(&self, travel_speed: MetresPerSecond) -> Result<PerMinute, Error> {
        plants_per_minute(travel_speed, self.settings.plant_spacing)
    }
}

/// Plants (or planting cycles) per minute: `f = 60·V/X` (paper B eq. 1).
pub fn plants_per_minute(speed: MetresPerSecond, spacing: Metres) -> Result<PerMinute, Error> {
    PerMinute::try_from_w(fx::div(fx::mul_int(speed.w(), 60)?, spacing.w())?)
}

impl core::error::Error for DrumConfigError {}
