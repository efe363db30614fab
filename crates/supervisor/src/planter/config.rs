//! Profile B's board facts and the operator's parameters, validated.

use fixed::types::U16F16;
use kinematics::profile_b::{ProfileB, ProfileBConfigError, ProfileBSettings};
use kinematics::units::{Hertz, Metres, MetresPerSecond};

/// Longest speed window, control periods.
pub const SPEED_WINDOW_MAX: usize = 32;

/// Fixed facts of the profile B board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProfileBHardware {
    /// Control period, µs (1 000 … 100 000).
    pub control_period_us: u32,
    /// Ground-wheel diameter (0.05 … 2 m).
    pub ground_wheel_diameter: Metres,
    /// Ground-wheel encoder counts per wheel turn, after quadrature (1 … 100 000).
    pub ground_counts_per_turn: u32,
    /// Periods the travel speed is averaged over (1 … [`SPEED_WINDOW_MAX`]).
    pub speed_window_periods: u8,
    /// Periods without a ground count that mean standstill (1 … 100).
    pub standstill_periods: u8,
    /// Largest change of a step rate from one period to the next while
    /// running (the acceleration limit; stops are immediate), > 0.
    pub max_step_change_hz: Hertz,
    /// Highest step rate either timer is asked for, > 0.
    pub max_step_hz: Hertz,
}

impl ProfileBHardware {
    /// The board: 10 ms period, a 600 ppr encoder (×4 = 2400 counts) on a
    /// 0.25 m ground wheel, a 200 ms speed window, standstill after one silent
    /// period, 40 Hz per period (4 kHz/s) acceleration limit, 20 kHz maximum
    /// step rate (750 r/min at 1600 steps/rev, far above paper B's needs).
    pub const BOARD: Self = Self {
        control_period_us: 10_000,
        ground_wheel_diameter: Metres::lit("0.25"),
        ground_counts_per_turn: 2400,
        speed_window_periods: 20,
        standstill_periods: 1,
        max_step_change_hz: Hertz::lit("40"),
        max_step_hz: Hertz::lit("20000"),
    };

    pub(super) fn validate(&self) -> Result<(), Error> {
        let ok = (1_000..=100_000).contains(&self.control_period_us)
            && self.ground_wheel_diameter >= const { Metres::lit("0.05") }
            && self.ground_wheel_diameter <= const { Metres::lit("2") }
            && (1..=100_000).contains(&self.ground_counts_per_turn)
            && (1..=SPEED_WINDOW_MAX).contains(&usize::from(self.speed_window_periods))
            && (1..=100).contains(&self.standstill_periods)
            && self.max_step_change_hz > Hertz::ZERO
            && self.max_step_hz > Hertz::ZERO;
        if ok {
            Ok(())
        } else {
            Err(Error::Hardware)
        }
    }
}

impl Default for ProfileBHardware {
    fn default() -> Self {
        Self::BOARD
    }
}

/// A profile B setting outside its range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigField {
    /// Target plant spacing X: 0.10 … 1.00 m.
    PlantSpacing,
    /// Seedling pitch on the belt B: 0.02 … 0.50 m.
    BeltPitch,
    /// Clamping angle β: 1 … 360°.
    ClampingAngle,
    /// Seedlings clamped at once N: 1 … 20.
    SeedlingsClamped,
    /// Empty roller radius r: 5 … 200 mm.
    RollerRadius,
    /// Belt thickness h: 0 … 10 mm.
    BeltThickness,
    /// Speed threshold Y: 0 … 0.2 m/s.
    Threshold,
    /// Steps per revolution (either motor): 200 … 51 200.
    StepsPerRev,
}

impl ConfigField {
    /// The field's name and range, for the screen (ASCII, ≤ 40 characters).
    pub const fn text(&self) -> &'static str {
        match self {
            Self::PlantSpacing => "Spacing X: 10-100 cm",
            Self::BeltPitch => "Belt pitch B: 2-50 cm",
            Self::ClampingAngle => "Clamping angle: 1-360 deg",
            Self::SeedlingsClamped => "Seedlings clamped N: 1-20",
            Self::RollerRadius => "Roller radius r: 5-200 mm",
            Self::BeltThickness => "Belt thickness h: 0-10 mm",
            Self::Threshold => "Threshold Y: 0-0.2 m/s",
            Self::StepsPerRev => "Steps/rev: 200-51200",
        }
    }
}

/// Errors of profile B.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// A setting is outside this module's range.
    Range(ConfigField),
    /// The kinematics refused the settings.
    Kinematics(ProfileBConfigError),
    /// The hardware description is unusable.
    Hardware,
    /// The settings cannot change while the motors run.
    Running,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Range(field) => write!(f, "out of range: {}", field.text()),
            Self::Kinematics(e) => write!(f, "profile B settings: {e}"),
            Self::Hardware => f.write_str("bad profile B hardware description"),
            Self::Running => f.write_str("stop the motors before changing the settings"),
        }
    }
}

impl core::error::Error for Error {}

impl From<ProfileBConfigError> for Error {
    fn from(e: ProfileBConfigError) -> Self {
        Self::Kinematics(e)
    }
}

/// Validated profile B settings (the operator's pages): target spacing X,
/// belt seedling pitch B, β, N, r, h, Y and the motors' steps per revolution,
/// held as [`kinematics::profile_b::ProfileBSettings`].
///
/// The defaults are `ProfileBSettings::default()`: X = 25 cm, B = 10 cm
/// (paper B's bench), β = 120°, N = 2, r = 25 mm, h = 1 mm, Y = 0.02 m/s,
/// 1600 steps/rev (unpublished, SPEC §8; `machine-sim` models the same
/// machine by default): `ProfileBConfig::new(ProfileBSettings::default())`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProfileBConfig {
    plan: ProfileB,
}

/// Size of [`ProfileBConfig::to_bytes`].
pub const CONFIG_BYTES: usize = 33;

impl ProfileBConfig {
    /// Validates the settings against the ranges of [`ConfigField`] and the
    /// kinematics' own checks.
    pub fn new(s: ProfileBSettings) -> Result<Self, Error> {
        let range = |ok: bool, field| if ok { Ok(()) } else { Err(Error::Range(field)) };
        range(
            s.plant_spacing >= const { Metres::lit("0.10") }
                && s.plant_spacing <= const { Metres::lit("1.00") },
            ConfigField::PlantSpacing,
        )?;
        range(
            s.belt_pitch >= const { Metres::lit("0.02") }
                && s.belt_pitch <= const { Metres::lit("0.50") },
            ConfigField::BeltPitch,
        )?;
        range(
            s.clamping_angle_deg >= U16F16::ONE
                && s.clamping_angle_deg <= const { U16F16::lit("360") },
            ConfigField::ClampingAngle,
        )?;
        range(
            (1..=20).contains(&s.seedlings_clamped),
            ConfigField::SeedlingsClamped,
        )?;
        range(
            s.roller_radius >= const { Metres::lit("0.005") }
                && s.roller_radius <= const { Metres::lit("0.200") },
            ConfigField::RollerRadius,
        )?;
        range(
            s.belt_thickness <= const { Metres::lit("0.010") },
            ConfigField::BeltThickness,
        )?;
        range(
            s.threshold <= const { MetresPerSecond::lit("0.2") },
            ConfigField::Threshold,
        )?;
        range(
            (200..=51_200).contains(&s.planting_steps_per_rev)
                && (200..=51_200).contains(&s.feeding_steps_per_rev),
            ConfigField::StepsPerRev,
        )?;
        Ok(Self { plan: s.build()? })
    }

    /// The validated settings.
    #[must_use]
    pub const fn settings(&self) -> &ProfileBSettings {
        self.plan.settings()
    }

    /// The validated kinematics (eq. 1, 4, 8, 9).
    #[must_use]
    pub const fn plan(&self) -> &ProfileB {
        &self.plan
    }

    /// The settings as bytes for the settings store: the raw fixed-point bits
    /// of X, B, β, r, h, Y (little-endian `u32` each), N, and the two steps
    /// per revolution (`u32`), so that a round trip is exact.
    #[must_use]
    pub fn to_bytes(&self) -> [u8; CONFIG_BYTES] {
        let s = self.settings();
        let mut out = [0u8; CONFIG_BYTES];
        let words = [
            s.plant_spacing.to_bits(),
            s.belt_pitch.to_bits(),
            s.clamping_angle_deg.to_bits(),
            s.roller_radius.to_bits(),
            s.belt_thickness.to_bits(),
            s.threshold.to_bits(),
            s.planting_steps_per_rev,
            s.feeding_steps_per_rev,
        ];
        for (chunk, w) in out.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        if let Some(last) = out.last_mut() {
            *last = s.seedlings_clamped;
        }
        out
    }

    /// Reads [`ProfileBConfig::to_bytes`] back, validating as [`ProfileBConfig::new`].
    pub fn from_bytes(bytes: &[u8; CONFIG_BYTES]) -> Result<Self, Error> {
        let mut words = [0u32; 8];
        for (w, chunk) in words.iter_mut().zip(bytes.chunks_exact(4)) {
            let mut b = [0u8; 4];
            b.copy_from_slice(chunk);
            *w = u32::from_le_bytes(b);
        }
        let [x, b, beta, r, h, y, sp, sf] = words;
        Self::new(ProfileBSettings {
            plant_spacing: Metres::from_bits(x),
            belt_pitch: Metres::from_bits(b),
            clamping_angle_deg: U16F16::from_bits(beta),
            seedlings_clamped: bytes.last().copied().unwrap_or(0),
            roller_radius: Metres::from_bits(r),
            belt_thickness: Metres::from_bits(h),
            threshold: MetresPerSecond::from_bits(y),
            planting_steps_per_rev: sp,
            feeding_steps_per_rev: sf,
        })
    }
}
