//! The transplanter's screen contract: pages, components, scalings, commands.
//!
//! This module is the single source of truth for the screen file (`docs/hmi.md`
//! lists the same table for the vendor editor; a test checks they agree).
//!
//! Numbers on the screen are 32-bit integers, so every quantity has a fixed
//! scaling (the screen shows them with an *Xfloat* component whose `ws1` is
//! the number of decimals):
//!
//! | quantity | unit on the wire | range | Xfloat `ws1` |
//! |---|---|---|---|
//! | plant spacing | mm | 30–500 (3–50 cm) | 1, shown in cm |
//! | drum speed (set, target, actual) | r/min × 100 | 0–4470 (0–44.70) | 2 |
//! | travel speed | km/h × 100 | 0–65535 | 2 |
//! | motor coefficient | × 100 | 50–200 (0.50–2.00) | 2 |
//! | calibration coefficient | × 1000 | 800–1200 (0.800–1.200) | 3 |
//! | calibration distances | cm | 100–100000 (1–1000 m) | 2, shown in m |
//! | distance travelled | dm (0.1 m) | 0–2³¹ | 1, shown in m |
//! | plants planted | count | 0–2³¹ | – (Number) |
//! | brightness | % | 10–100 | – (Number) |
//! | first-plant distance after the work switch closes | mm | 0–1000 (0–100 cm) | 1, shown in cm |
//! | planting quality shares and CV (page 3) | 0.1 % | 0–1000 | 1 |
//! | plants per metre (page 3) | × 100 | 0–65535 | 2 |
//!
//! Profile B (the seedling-belt planter, paper B; pages 7 and 8):
//!
//! | quantity | unit on the wire | range | component |
//! |---|---|---|---|
//! | target plant spacing X | mm | 100–1000 (10–100 cm) | Xfloat `ws1`=1, shown in cm |
//! | belt seedling pitch B | mm | 20–500 (2–50 cm) | Xfloat `ws1`=1, shown in cm |
//! | clamping angle β | degrees | 1–360 | Number |
//! | seedlings clamped N | count | 1–12 | Number |
//! | roller radius r | 0.1 mm | 50–1000 (5.0–100.0 mm) | Xfloat `ws1`=1, shown in mm |
//! | belt thickness h | 0.01 mm | 1–1000 (0.01–10.00 mm) | Xfloat `ws1`=2, shown in mm |
//! | speed threshold Y | mm/s | 1–200 (0.001–0.200 m/s) | Xfloat `ws1`=3, shown in m/s |
//! | travel speed | m/s × 100 | 0–65535 | Xfloat `ws1`=2 |
//! | planting / feeding motor speed n1, n2 | r/min × 100 | 0–65535 | Xfloat `ws1`=2 |
//! | roller turns j | count | 0–2³¹ | Number |
//! | roller radius r' = r + h·j | 0.1 mm | 0–65535 | Xfloat `ws1`=1 |
//!
//! **Home page.** The machine runs one [`MachineProfile`]; its home page
//! ([`MachineProfile::home`]) is page 1 `mode` for profile A and page 7
//! `belt` for profile B. [`Hmi`](crate::hmi::Hmi) shows it after the
//! handshake, and *Back* on page 6 ([`Action::ShowHome`]) returns to it.

use core::fmt;

use crate::encoder::{Instruction, ObjName, ScreenText};

/// The screen's pages; the discriminant is the page id (creation order in the editor).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Page {
    /// 0 `boot`: shown by the screen at power-on until the MCU has synchronised.
    Boot = 0,
    /// 1 `mode`: mode select and transplanting-motor coefficient.
    Mode = 1,
    /// 2 `fixed`: Fixed Mode, operator-set drum speed.
    Fixed = 2,
    /// 3 `adaptive`: Speed-Adaptive Mode, plant spacing and gear.
    Adaptive = 3,
    /// 4 `calib`: calibration run and coefficients.
    Calibration = 4,
    /// 5 `alarm`: an alarm text and its acknowledge button.
    Alarm = 5,
    /// 6 `settings`: brightness, save settings, firmware version, machine profile.
    Settings = 6,
    /// 7 `belt`: profile B run page (start/stop, motor speeds, roller).
    Belt = 7,
    /// 8 `beltpar`: profile B parameters (X, B, β, N, r, h, Y).
    BeltParameters = 8,
    /// 9 `drive`: drum drive identification (profile A).
    Drive = 9,
    /// 10 `link`: the drum driver's RS-485 link settings (profile A).
    Link = 10,
}

impl Page {
    /// All pages in id order.
    pub const ALL: [Page; 11] = [
        Self::Boot,
        Self::Mode,
        Self::Fixed,
        Self::Adaptive,
        Self::Calibration,
        Self::Alarm,
        Self::Settings,
        Self::Belt,
        Self::BeltParameters,
        Self::Drive,
        Self::Link,
    ];

    /// The page id.
    pub const fn id(self) -> u8 {
        self as u8
    }

    /// Page from its id.
    pub fn from_id(id: u8) -> Option<Self> {
        Self::ALL.iter().copied().find(|p| p.id() == id)
    }

    /// The page name in the screen file.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Boot => "boot",
            Self::Mode => "mode",
            Self::Fixed => "fixed",
            Self::Adaptive => "adaptive",
            Self::Calibration => "calib",
            Self::Alarm => "alarm",
            Self::Settings => "settings",
            Self::Belt => "belt",
            Self::BeltParameters => "beltpar",
            Self::Drive => "drive",
            Self::Link => "link",
        }
    }

    /// The home page of `profile` (see [`MachineProfile::home`]).
    pub const fn home(profile: MachineProfile) -> Self {
        profile.home()
    }
}

/// The machine the firmware drives (SPEC §8): the same firmware runs either.
///
/// The profile is a setting ([`Settings::profile`]). Changing it on page 6
/// (`bprofile`) only selects it: the firmware applies it after *Save
/// settings* and a restart, because it switches the motor outputs (profile A:
/// one drum motor; profile B: the feeding and planting steppers). Until then
/// the machine keeps running the profile it started with, and the screen
/// says so ([`PROFILE_RESTART_MESSAGE`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MachineProfile {
    /// Profile A: the drum-belt transplanter (paper A; pages 1–4). The default.
    #[default]
    DrumBelt,
    /// Profile B: the seedling-belt planter (paper B; pages 7–8).
    SeedlingBelt,
}

impl MachineProfile {
    /// Both profiles, A first.
    pub const ALL: [MachineProfile; 2] = [Self::DrumBelt, Self::SeedlingBelt];

    /// The label shown in `tprofile` (ASCII, ≤ 40 characters).
    pub const fn label(self) -> &'static str {
        match self {
            Self::DrumBelt => "A: drum-belt transplanter",
            Self::SeedlingBelt => "B: seedling-belt planter",
        }
    }

    /// The next profile (A → B → A), for the selector button.
    pub const fn next(self) -> Self {
        match self {
            Self::DrumBelt => Self::SeedlingBelt,
            Self::SeedlingBelt => Self::DrumBelt,
        }
    }

    /// The page shown after the handshake and by *Back* on page 6:
    /// page 1 `mode` (A) or page 7 `belt` (B).
    pub const fn home(self) -> Page {
        match self {
            Self::DrumBelt => Page::Mode,
            Self::SeedlingBelt => Page::Belt,
        }
    }
}

/// Shown in page 6's `tmsg` when the profile selected differs from the one
/// running: the change takes effect after *Save settings* and a restart.
pub const PROFILE_RESTART_MESSAGE: &str = "Save, then restart to switch machine";

/// Operating mode (paper A: Fixed Mode and Speed-Adaptive Mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Drum at an operator-set speed.
    Fixed,
    /// Drum follows travel speed for the set plant spacing.
    SpeedAdaptive,
}

impl Mode {
    /// The page that runs this mode.
    pub const fn page(self) -> Page {
        match self {
            Self::Fixed => Page::Fixed,
            Self::SpeedAdaptive => Page::Adaptive,
        }
    }
}

/// Which coefficient the calibration page measures (paper A §3: k1 the speed
/// sensor, k2 the track slip, k3 the belt slip).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationKind {
    /// k1: a timed run over a taped course; the travel speed the firmware
    /// shows is corrected to the speed measured.
    SpeedK1,
    /// k2: wheel turns counted over a taped course (the default).
    #[default]
    SlipK2,
    /// k3: the drum turns counted while the belt runs; the belt length that
    /// passed is taped.
    BeltK3,
    /// Machine A's ground wheel: its encoder counts over a taped course give
    /// its counts per metre.
    GroundWheel,
}

impl CalibrationKind {
    /// The label shown in `tkind`.
    pub const fn label(self) -> &'static str {
        match self {
            Self::SpeedK1 => "k1 speed sensor",
            Self::SlipK2 => "k2 track slip",
            Self::BeltK3 => "k3 belt slip",
            Self::GroundWheel => "ground wheel pulses/m",
        }
    }

    /// The next kind (k1 → k2 → k3 → ground wheel → k1), for the selector
    /// button.
    pub const fn next(self) -> Self {
        match self {
            Self::SpeedK1 => Self::SlipK2,
            Self::SlipK2 => Self::BeltK3,
            Self::BeltK3 => Self::GroundWheel,
            Self::GroundWheel => Self::SpeedK1,
        }
    }
}

/// Where machine A's travel speed and ground distance come from
/// (docs/ground-wheel.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TravelSource {
    /// The Hall gear on the track's driving wheel (paper A; the default).
    #[default]
    HallGear,
    /// The ground wheel's encoder alone.
    GroundWheel,
    /// The ground wheel for speed and distance, the Hall gear as its
    /// cross-check: the live track slip, and either one stopping while the
    /// other turns.
    Both,
}

impl TravelSource {
    /// The label shown on the settings page.
    pub const fn label(self) -> &'static str {
        match self {
            Self::HallGear => "Hall gear",
            Self::GroundWheel => "Ground wheel",
            Self::Both => "Wheel + Hall",
        }
    }

    /// The next source (Hall → wheel → both → Hall), for the selector button.
    pub const fn next(self) -> Self {
        match self {
            Self::HallGear => Self::GroundWheel,
            Self::GroundWheel => Self::Both,
            Self::Both => Self::HallGear,
        }
    }

    /// The ground wheel is read (alone or with the Hall gear).
    pub const fn uses_wheel(self) -> bool {
        matches!(self, Self::GroundWheel | Self::Both)
    }
}

/// The drum driver link's setting page 10 edits (docs/drive-link.md,
/// settings format 6): one at a time, picked with `blpar`, its value in
/// `nlval`, applied with `blval`. The codes of the three choices are in
/// their labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkParameter {
    /// Feedback source: 0 encoder, 1 driver read-back, 2 both (the default
    /// selection).
    #[default]
    Feedback,
    /// Command path: 0 PWM, 1 the driver's speed command over Modbus.
    Command,
    /// Driver: 0 none, 1 ZLAC8015D, 2 generic.
    Driver,
    /// Modbus slave id, 1–247.
    Slave,
    /// Baud rate: 9600, 19 200, 38 400, 57 600 or 115 200.
    Baud,
    /// Reply timeout: the driver's answer time allowed, ms (5–1000).
    ReplyTimeout,
    /// Quiet line before a retry, ms (2–1000).
    RetryGap,
    /// The driver's offline (communication-loss) time, ms.
    OfflineTime,
    /// Read-back scale: micro-r/min of the drum per register count (the
    /// gearbox included; negative: the driver counts the other way).
    Scale,
    /// Generic driver: the speed read-back's holding register.
    SpeedRegister,
    /// Generic driver: the fault word's holding register.
    FaultRegister,
    /// Generic driver: the speed command's holding register (0: none).
    CommandRegister,
    /// Generic driver: the command scale, micro-r/min of the drum per
    /// command count at a speed resolution of 1.
    CommandScale,
    /// Generic driver: the control word's register (0: none).
    ControlRegister,
    /// Generic driver: the control word's enable value.
    EnableValue,
    /// Generic driver: the control word's disable value.
    DisableValue,
    /// Generic driver: the control word's clear-alarm value.
    ClearValue,
    /// Generic driver: the register written at start-up to select
    /// velocity mode (0: none).
    ModeRegister,
    /// Generic driver: the value written there.
    ModeValue,
    /// Generic driver: the offline-time register (0: none).
    OfflineRegister,
    /// Generic driver: the speed-resolution register (0: none).
    ResolutionRegister,
    /// Generic driver: the maximum-speed register (0: none).
    MaxSpeedRegister,
}

impl LinkParameter {
    /// Every parameter, in the selector's order.
    pub const ALL: [LinkParameter; 22] = [
        Self::Feedback,
        Self::Command,
        Self::Driver,
        Self::Slave,
        Self::Baud,
        Self::ReplyTimeout,
        Self::RetryGap,
        Self::OfflineTime,
        Self::Scale,
        Self::SpeedRegister,
        Self::FaultRegister,
        Self::CommandRegister,
        Self::CommandScale,
        Self::ControlRegister,
        Self::EnableValue,
        Self::DisableValue,
        Self::ClearValue,
        Self::ModeRegister,
        Self::ModeValue,
        Self::OfflineRegister,
        Self::ResolutionRegister,
        Self::MaxSpeedRegister,
    ];

    /// The label shown in `tlpar` (≤ 40 characters).
    pub const fn label(self) -> &'static str {
        match self {
            Self::Feedback => "Feedback 0enc 1drv 2both",
            Self::Command => "Command 0PWM 1Modbus",
            Self::Driver => "Driver 0none 1ZLAC 2gen",
            Self::Slave => "Slave id",
            Self::Baud => "Baud",
            Self::ReplyTimeout => "Reply timeout ms",
            Self::RetryGap => "Retry gap ms",
            Self::OfflineTime => "Driver offline time ms",
            Self::Scale => "Scale urpm/count",
            Self::SpeedRegister => "Speed register",
            Self::FaultRegister => "Fault register",
            Self::CommandRegister => "Command reg (0 none)",
            Self::CommandScale => "Command scale urpm/count",
            Self::ControlRegister => "Control reg (0 none)",
            Self::EnableValue => "Control: enable value",
            Self::DisableValue => "Control: disable value",
            Self::ClearValue => "Control: clear value",
            Self::ModeRegister => "Mode reg (0 none)",
            Self::ModeValue => "Mode value",
            Self::OfflineRegister => "Offline time reg (0 none)",
            Self::ResolutionRegister => "Resolution reg (0 none)",
            Self::MaxSpeedRegister => "Max speed reg (0 none)",
        }
    }

    /// The next parameter (the last wraps to the first): the one after it
    /// in [`LinkParameter::ALL`], whose order is the declaration's.
    #[must_use]
    pub fn next(self) -> Self {
        Self::ALL
            .get((self as usize).saturating_add(1))
            .copied()
            .unwrap_or(Self::Feedback)
    }
}

/// The bound of [`Field::LinkValue`]: the widest link value, the read-back
/// scale's (`drive_link::profile::MAX_SCALE`, 10⁸ µr/min per count).
pub const LINK_VALUE_MAX: i32 = 100_000_000;

/// The screen's message after a link setting is taken: the link runs the
/// settings it started with until *Save settings* and a restart.
pub const LINK_RESTART_MESSAGE: &str = "Save, then restart to apply";

/// Tractor gear presets (spec §4: Low 1–3, High 1–3); the wire index is 1–6.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gear {
    /// Low 1 (the default).
    #[default]
    Low1 = 1,
    /// Low 2.
    Low2 = 2,
    /// Low 3.
    Low3 = 3,
    /// High 1.
    High1 = 4,
    /// High 2.
    High2 = 5,
    /// High 3.
    High3 = 6,
}

impl Gear {
    /// All gears, slowest first.
    pub const ALL: [Gear; 6] = [
        Self::Low1,
        Self::Low2,
        Self::Low3,
        Self::High1,
        Self::High2,
        Self::High3,
    ];

    /// 1–6.
    pub const fn index(self) -> u8 {
        self as u8
    }

    /// Gear from its index 1–6.
    pub fn from_index(i: u8) -> Option<Self> {
        Self::ALL.iter().copied().find(|g| g.index() == i)
    }

    /// Text shown in `tgear`.
    pub const fn label(self) -> &'static str {
        match self {
            Self::Low1 => "Low 1",
            Self::Low2 => "Low 2",
            Self::Low3 => "Low 3",
            Self::High1 => "High 1",
            Self::High2 => "High 2",
            Self::High3 => "High 3",
        }
    }

    /// Next faster gear (saturates at High 3).
    pub fn next(self) -> Self {
        Self::from_index(self.index().saturating_add(1)).unwrap_or(self)
    }

    /// Next slower gear (saturates at Low 1).
    pub fn prev(self) -> Self {
        Self::from_index(self.index().saturating_sub(1)).unwrap_or(self)
    }
}

/// A numeric field the operator edits and applies (read by `get obj.val`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Field {
    /// Transplanting-motor coefficient, × 100.
    MotorCoefficient,
    /// Fixed-mode drum speed, r/min × 100.
    FixedDrumSpeed,
    /// Plant spacing, mm.
    Spacing,
    /// Tape-measured distance of a calibration run, cm.
    CalibrationDistance,
    /// Calibration coefficient typed in by hand, × 1000.
    CalibrationCoefficient,
    /// Screen brightness, %.
    Brightness,
    /// Profile B: target plant spacing X, mm.
    BeltSpacing,
    /// Profile B: seedling pitch on the belt B, mm.
    SeedlingPitch,
    /// Profile B: clamping angle β of the flexible disc, degrees.
    ClampAngle,
    /// Profile B: seedlings clamped at once N.
    ClampCount,
    /// Profile B: initial roller radius r, 0.1 mm.
    RollerRadius,
    /// Profile B: seedling-belt thickness h, 0.01 mm.
    BeltThickness,
    /// Profile B: speed-change threshold Y, mm/s.
    SpeedThreshold,
    /// Where the first plant of a pass lands after the work switch closes,
    /// mm (page 6).
    FirstPlantDistance,
    /// The value of the drum driver link's selected [`LinkParameter`]
    /// (page 10); the supervisor checks it against the parameter.
    LinkValue,
}

impl Field {
    /// Every field.
    pub const ALL: [Field; 15] = [
        Self::MotorCoefficient,
        Self::FixedDrumSpeed,
        Self::Spacing,
        Self::CalibrationDistance,
        Self::CalibrationCoefficient,
        Self::Brightness,
        Self::BeltSpacing,
        Self::SeedlingPitch,
        Self::ClampAngle,
        Self::ClampCount,
        Self::RollerRadius,
        Self::BeltThickness,
        Self::SpeedThreshold,
        Self::FirstPlantDistance,
        Self::LinkValue,
    ];
}

/// An operator value outside its range: nothing changed; [`message`](Self::message)
/// is the short ASCII text shown in the page's `tmsg` box.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ParamError {
    /// The field.
    pub field: Field,
    /// The raw value received.
    pub value: i32,
}

impl ParamError {
    /// Short ASCII message (≤ 40 characters) fit for the screen.
    pub const fn message(&self) -> &'static str {
        match self.field {
            Field::MotorCoefficient => "Motor coef must be 0.50-2.00",
            Field::FixedDrumSpeed => "Drum speed must be 0-44.70 r/min",
            Field::Spacing => "Spacing must be 3.0-50.0 cm",
            Field::CalibrationDistance => "Distance must be 1-1000 m",
            Field::CalibrationCoefficient => "Calib coef must be 0.800-1.200",
            Field::Brightness => "Brightness must be 10-100 %",
            Field::BeltSpacing => "Spacing X must be 10.0-100.0 cm",
            Field::SeedlingPitch => "Belt pitch B must be 2.0-50.0 cm",
            Field::ClampAngle => "Clamp angle must be 1-360 deg",
            Field::ClampCount => "Seedlings clamped must be 1-12",
            Field::RollerRadius => "Roller radius must be 5.0-100.0 mm",
            Field::BeltThickness => "Belt thickness must be 0.01-10.00 mm",
            Field::SpeedThreshold => "Threshold Y must be 0.001-0.200 m/s",
            Field::FirstPlantDistance => "First plant must be 0.0-100.0 cm",
            Field::LinkValue => "Value out of range",
        }
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.message())
    }
}

/// `raw` if within `min..=max`, else the field's [`ParamError`]: the one
/// check behind every bounded value's `new` (shared, not repeated per type,
/// to keep the image small).
#[inline(never)]
fn check_range(raw: i32, min: i32, max: i32, field: Field) -> Result<i32, ParamError> {
    if (min..=max).contains(&raw) {
        Ok(raw)
    } else {
        Err(ParamError { field, value: raw })
    }
}

macro_rules! bounded {
    ($(#[$doc:meta])* $name:ident, $t:ty, $field:expr, $min:expr, $max:expr, $default:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name($t);

        impl $name {
            /// Smallest accepted raw value.
            pub const MIN: $t = $min;
            /// Largest accepted raw value.
            pub const MAX: $t = $max;
            /// Value used before the operator sets one.
            pub const DEFAULT: Self = Self($default);

            /// Checked construction from the raw (scaled) value.
            pub fn new(raw: i32) -> Result<Self, ParamError> {
                // Every bound is within 0..=100 000 (below), so it fits an
                // `i32`, and a value between two bounds fits `$t`.
                #[allow(clippy::cast_possible_truncation, clippy::cast_possible_wrap, clippy::cast_sign_loss)]
                check_range(raw, Self::MIN as i32, Self::MAX as i32, $field).map(|v| Self(v as $t))
            }

            /// The raw (scaled) value.
            pub const fn raw(self) -> $t {
                self.0
            }
        }

        impl Default for $name {
            fn default() -> Self {
                Self::DEFAULT
            }
        }
    };
}

bounded!(
    /// Plant spacing in mm, 30–500 (3–50 cm). Default 70 mm (Codonopsis).
    Spacing, u16, Field::Spacing, 30, 500, 70
);
bounded!(
    /// Fixed-mode drum speed in r/min × 100, 0–4470 (`n_max` = 44.7 r/min).
    /// Default 2521 (rated 25.21 r/min).
    DrumSpeed, u16, Field::FixedDrumSpeed, 0, 4470, 2521
);
bounded!(
    /// Transplanting-motor coefficient × 100, 50–200 (0.50–2.00). Default 100.
    MotorCoefficient, u16, Field::MotorCoefficient, 50, 200, 100
);
bounded!(
    /// Calibration coefficient × 1000, 800–1200 (0.800–1.200). Default 1000.
    CalibrationCoefficient, u16, Field::CalibrationCoefficient, 800, 1200, 1000
);
bounded!(
    /// Distance of a calibration run in cm, 100–100000 (1–1000 m). Default 5000 (50 m).
    CalibrationDistance, u32, Field::CalibrationDistance, 100, 100_000, 5000
);
bounded!(
    /// Screen brightness in %, 10–100 (never dark). Default 100.
    Brightness, u8, Field::Brightness, 10, 100, 100
);

// Profile B. The defaults equal `kinematics::profile_b::ProfileBSettings::default()`
// (X 0.25 m, B 0.10 m, β 120°, N 2, r 25 mm, h 1 mm, Y 0.02 m/s); this crate
// stays free of a kinematics dependency, so the numbers are written out here
// and the supervisor crate converts them (`belt_defaults_match_paper_b_defaults`
// below pins the figures).
bounded!(
    /// Profile B target plant spacing X in mm, 100–1000 (10–100 cm).
    /// Default 250 (paper B's bench value, 25 cm).
    BeltSpacing, u16, Field::BeltSpacing, 100, 1000, 250
);
bounded!(
    /// Profile B seedling pitch on the belt B in mm, 20–500 (2–50 cm).
    /// Default 100 (paper B's bench value, 10 cm).
    SeedlingPitch, u16, Field::SeedlingPitch, 20, 500, 100
);
bounded!(
    /// Profile B clamping angle β of the flexible disc in degrees, 1–360.
    /// Default 120.
    ClampAngle, u16, Field::ClampAngle, 1, 360, 120
);
bounded!(
    /// Profile B seedlings clamped at once within β, N, 1–12. Default 2.
    ClampCount, u8, Field::ClampCount, 1, 12, 2
);
bounded!(
    /// Profile B initial roller radius r in 0.1 mm, 50–1000 (5.0–100.0 mm).
    /// Default 250 (25.0 mm).
    RollerRadius, u16, Field::RollerRadius, 50, 1000, 250
);
bounded!(
    /// Profile B seedling-belt thickness h in 0.01 mm, 1–1000 (0.01–10.00 mm).
    /// Default 100 (1.00 mm).
    BeltThickness, u16, Field::BeltThickness, 1, 1000, 100
);
bounded!(
    /// Profile B speed-change threshold Y in mm/s, 1–200 (0.001–0.200 m/s:
    /// the planter's own limit, `supervisor::planter`). Default 20 (0.02 m/s).
    SpeedThreshold, u16, Field::SpeedThreshold, 1, 200, 20
);

bounded!(
    /// Where the first plant of a pass lands, mm of ground after the point
    /// where the work switch closed, 0–1000 (0–100 cm). Default 100 mm: the
    /// drum reaches speed from rest in ≈ 0.1 s (≈ 15 mm at Low 2), so the
    /// place can be met at every gear.
    FirstPlantDistance, u16, Field::FirstPlantDistance, 0, 1000, 100
);

impl CalibrationCoefficient {
    /// `actual / measured`, rounded to 0.001, then range-checked; a zero
    /// `measured` distance is out of range too.
    pub fn from_distances(actual_cm: u32, measured_cm: u32) -> Result<Self, ParamError> {
        let num = u64::from(actual_cm)
            .saturating_mul(1000)
            .saturating_add(u64::from(measured_cm) / 2);
        let k = num.checked_div(u64::from(measured_cm)).unwrap_or(u64::MAX);
        Self::new(i32::try_from(k).unwrap_or(i32::MAX))
    }
}

impl Field {
    /// Validates a raw value read from the screen into the command it asks for.
    pub fn validate(self, raw: i32) -> Result<Command, ParamError> {
        // One range check for every field (table-driven, to keep the image
        // small), then the value in its type: within its bounds it fits.
        let (min, max) = self.bounds();
        let v = check_range(raw, min, max, self)?;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (v8, v16, v32) = (v as u8, v as u16, v as u32);
        Ok(match self {
            Self::MotorCoefficient => Command::SetMotorCoefficient(MotorCoefficient(v16)),
            Self::FixedDrumSpeed => Command::SetFixedDrumSpeed(DrumSpeed(v16)),
            Self::Spacing => Command::SetSpacing(Spacing(v16)),
            Self::CalibrationDistance => {
                Command::CalibrationActualDistance(CalibrationDistance(v32))
            }
            Self::CalibrationCoefficient => {
                Command::SetCalibrationCoefficient(CalibrationCoefficient(v16))
            }
            Self::Brightness => Command::SetBrightness(Brightness(v8)),
            Self::BeltSpacing => Command::SetBeltSpacing(BeltSpacing(v16)),
            Self::SeedlingPitch => Command::SetSeedlingPitch(SeedlingPitch(v16)),
            Self::ClampAngle => Command::SetClampAngle(ClampAngle(v16)),
            Self::ClampCount => Command::SetClampCount(ClampCount(v8)),
            Self::RollerRadius => Command::SetRollerRadius(RollerRadius(v16)),
            Self::BeltThickness => Command::SetBeltThickness(BeltThickness(v16)),
            Self::SpeedThreshold => Command::SetSpeedThreshold(SpeedThreshold(v16)),
            Self::FirstPlantDistance => Command::SetFirstPlantDistance(FirstPlantDistance(v16)),
            Self::LinkValue => Command::SetLinkValue(v),
        })
    }

    /// The field's accepted raw range, inclusive: what [`Field::validate`]
    /// takes (for screens built from the contract, `crate::export`).
    pub const fn range(self) -> (i32, i32) {
        self.bounds()
    }

    /// The field's accepted raw range (its type's `MIN` and `MAX`; for
    /// [`Field::LinkValue`] ±[`LINK_VALUE_MAX`]).
    const fn bounds(self) -> (i32, i32) {
        // Every bound is within 0..=100 000: exact in `i32`.
        #[allow(clippy::cast_possible_wrap)]
        match self {
            Self::MotorCoefficient => (MotorCoefficient::MIN as i32, MotorCoefficient::MAX as i32),
            Self::FixedDrumSpeed => (DrumSpeed::MIN as i32, DrumSpeed::MAX as i32),
            Self::Spacing => (Spacing::MIN as i32, Spacing::MAX as i32),
            Self::CalibrationDistance => (
                CalibrationDistance::MIN as i32,
                CalibrationDistance::MAX as i32,
            ),
            Self::CalibrationCoefficient => (
                CalibrationCoefficient::MIN as i32,
                CalibrationCoefficient::MAX as i32,
            ),
            Self::Brightness => (Brightness::MIN as i32, Brightness::MAX as i32),
            Self::BeltSpacing => (BeltSpacing::MIN as i32, BeltSpacing::MAX as i32),
            Self::SeedlingPitch => (SeedlingPitch::MIN as i32, SeedlingPitch::MAX as i32),
            Self::ClampAngle => (ClampAngle::MIN as i32, ClampAngle::MAX as i32),
            Self::ClampCount => (ClampCount::MIN as i32, ClampCount::MAX as i32),
            Self::RollerRadius => (RollerRadius::MIN as i32, RollerRadius::MAX as i32),
            Self::BeltThickness => (BeltThickness::MIN as i32, BeltThickness::MAX as i32),
            Self::SpeedThreshold => (SpeedThreshold::MIN as i32, SpeedThreshold::MAX as i32),
            Self::FirstPlantDistance => (
                FirstPlantDistance::MIN as i32,
                FirstPlantDistance::MAX as i32,
            ),
            // The widest of the link's values: its read-back scale
            // (`drive_link::profile::MAX_SCALE`).
            Self::LinkValue => (-LINK_VALUE_MAX, LINK_VALUE_MAX),
        }
    }

    /// The field's current value in `settings`, raw (as written to the screen).
    pub fn current(self, s: &Settings) -> i32 {
        match self {
            Self::MotorCoefficient => i32::from(s.motor_coefficient.raw()),
            Self::FixedDrumSpeed => i32::from(s.fixed_drum_speed.raw()),
            Self::Spacing => i32::from(s.spacing.raw()),
            Self::CalibrationDistance => {
                i32::try_from(s.calibration_distance.raw()).unwrap_or(i32::MAX)
            }
            Self::CalibrationCoefficient => i32::from(s.calibration_coefficient.raw()),
            Self::Brightness => i32::from(s.brightness.raw()),
            Self::BeltSpacing => i32::from(s.belt.spacing.raw()),
            Self::SeedlingPitch => i32::from(s.belt.seedling_pitch.raw()),
            Self::ClampAngle => i32::from(s.belt.clamp_angle.raw()),
            Self::ClampCount => i32::from(s.belt.clamp_count.raw()),
            Self::RollerRadius => i32::from(s.belt.roller_radius.raw()),
            Self::BeltThickness => i32::from(s.belt.belt_thickness.raw()),
            Self::SpeedThreshold => i32::from(s.belt.speed_threshold.raw()),
            Self::FirstPlantDistance => i32::from(s.first_plant_distance.raw()),
            Self::LinkValue => s.link_value,
        }
    }
}

/// What the operator asked for: the MCU's reaction to touch events.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Start transplanting in the current mode.
    Start,
    /// Stop (never delayed behind a pending `get`).
    Stop,
    /// Switch mode (the page changes with it).
    SelectMode(Mode),
    /// New plant spacing.
    SetSpacing(Spacing),
    /// New Fixed-mode drum speed.
    SetFixedDrumSpeed(DrumSpeed),
    /// New transplanting-motor coefficient.
    SetMotorCoefficient(MotorCoefficient),
    /// New gear preset.
    SelectGear(Gear),
    /// Calibration: measure this coefficient next.
    SelectCalibration(CalibrationKind),
    /// Calibration: start counting a run at the current gear.
    CalibrationStart,
    /// Calibration: end the run; the firmware shows the measured distance.
    CalibrationStop,
    /// Calibration: the tape-measured distance of the run.
    CalibrationActualDistance(CalibrationDistance),
    /// Calibration: store the computed coefficient for the current gear.
    CalibrationAccept,
    /// Calibration: set the current gear's coefficient by hand.
    SetCalibrationCoefficient(CalibrationCoefficient),
    /// The operator acknowledged the alarm shown.
    AcknowledgeAlarm,
    /// Persist the settings.
    SaveSettings,
    /// New screen brightness (already sent to the screen as `dims`).
    SetBrightness(Brightness),
    /// Select the machine profile (page 6 `bprofile`). It takes effect after
    /// [`SaveSettings`](Self::SaveSettings) and a restart (the firmware
    /// switches the motor outputs); the screen says so.
    SelectProfile(MachineProfile),
    /// Profile B: new target plant spacing X.
    SetBeltSpacing(BeltSpacing),
    /// Profile B: new belt seedling pitch B.
    SetSeedlingPitch(SeedlingPitch),
    /// Profile B: new clamping angle β.
    SetClampAngle(ClampAngle),
    /// Profile B: new number of seedlings clamped N.
    SetClampCount(ClampCount),
    /// Profile B: new initial roller radius r.
    SetRollerRadius(RollerRadius),
    /// Profile B: new belt thickness h.
    SetBeltThickness(BeltThickness),
    /// Profile B: new speed-change threshold Y.
    SetSpeedThreshold(SpeedThreshold),
    /// The drum encoder counts backwards (`true`: A/B swapped on the
    /// machine); page 6 `benc` toggles it. Persisted with *Save settings*.
    SetDrumEncoderReversed(bool),
    /// Page 9: start the drive identification (drum stopped, belt empty).
    IdentifyDrive,
    /// Page 9: use and save the drive model just identified.
    AcceptDriveModel,
    /// A work switch is fitted (`true`) or not; page 6 `bwork` toggles it.
    /// Persisted with *Save settings*.
    SetWorkSwitchFitted(bool),
    /// Where the first plant of a pass lands after the work switch closes.
    SetFirstPlantDistance(FirstPlantDistance),
    /// Plant placement: speed-following (`true`, the papers' law) or
    /// distance-locked (`false`, the default); page 6 `bplace` toggles it.
    /// Only with the drum stopped; persisted with *Save settings*.
    SetSpeedFollowing(bool),
    /// Page 10: the link setting `nlval` shows and `blval` sets next.
    SelectLinkParameter(LinkParameter),
    /// Page 10: the selected link setting's new value (the whole link
    /// settings are validated; they apply after *Save* and a restart).
    SetLinkValue(i32),
    /// Profile B, page 7 `broll`: a new seedling-belt roll is loaded, the
    /// roller turn count j (and with it the radius `r + h·j`) starts again
    /// from 0. Only with the motors stopped.
    NewRoll,
    /// Profile A: the travel source (Hall gear, ground wheel, both). Only
    /// with the drum stopped; persisted with *Save settings*.
    SelectTravelSource(TravelSource),
    /// Profile A: the ground wheel's encoder counts backwards (`true`: A/B
    /// swapped, or the encoder mounted the other way). Persisted with *Save
    /// settings*.
    SetGroundWheelReversed(bool),
}

/// Profile B's parameters as the screen shows them (paper B; the defaults are
/// `kinematics::profile_b::ProfileBSettings::default()`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BeltSettings {
    /// Target plant spacing X.
    pub spacing: BeltSpacing,
    /// Seedling pitch on the belt B.
    pub seedling_pitch: SeedlingPitch,
    /// Clamping angle β.
    pub clamp_angle: ClampAngle,
    /// Seedlings clamped at once N.
    pub clamp_count: ClampCount,
    /// Initial roller radius r.
    pub roller_radius: RollerRadius,
    /// Belt thickness h.
    pub belt_thickness: BeltThickness,
    /// Speed-change threshold Y.
    pub speed_threshold: SpeedThreshold,
}

/// The settings the screen displays (the firmware owns and persists them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings {
    /// Plant spacing.
    pub spacing: Spacing,
    /// Fixed-mode drum speed.
    pub fixed_drum_speed: DrumSpeed,
    /// Transplanting-motor coefficient.
    pub motor_coefficient: MotorCoefficient,
    /// Selected gear.
    pub gear: Gear,
    /// Calibration coefficient of the selected gear.
    pub calibration_coefficient: CalibrationCoefficient,
    /// Last calibration distance entered.
    pub calibration_distance: CalibrationDistance,
    /// The coefficient the calibration page measures.
    pub calibration_kind: CalibrationKind,
    /// Screen brightness.
    pub brightness: Brightness,
    /// The machine profile selected (the one running is fixed at start-up:
    /// see [`MachineProfile`]).
    pub profile: MachineProfile,
    /// Profile B's parameters.
    pub belt: BeltSettings,
    /// The drum encoder's direction is reversed (page 6 `tenc`).
    pub drum_encoder_reversed: bool,
    /// A work switch is fitted (page 6 `twork`).
    pub work_switch_fitted: bool,
    /// First-plant distance after the work switch closes (page 6 `nfirst`).
    pub first_plant_distance: FirstPlantDistance,
    /// Plants placed by following the travel speed (the papers' law)
    /// instead of locked to the ground distance (page 6 `tplace`).
    pub speed_following: bool,
    /// The link setting page 10 shows (`tlpar`).
    pub link_parameter: LinkParameter,
    /// Its value as saved (`nlval`).
    pub link_value: i32,
    /// Machine A's travel source setting.
    pub travel_source: TravelSource,
    /// The ground wheel counts backwards (its direction setting).
    pub ground_wheel_reversed: bool,
}

/// The label of the placement setting (page 6 `tplace`).
pub const fn placement_label(speed_following: bool) -> &'static str {
    if speed_following {
        "speed-following"
    } else {
        "distance-locked"
    }
}

/// The label of the work switch setting (page 6 `twork`).
pub const fn work_switch_label(fitted: bool) -> &'static str {
    if fitted {
        "fitted (PB11)"
    } else {
        "not fitted"
    }
}

/// The label of the drum encoder direction (page 6 `tenc`).
pub const fn encoder_direction_label(reversed: bool) -> &'static str {
    if reversed {
        "reversed (A/B)"
    } else {
        "normal"
    }
}

/// Live values written to the screen; each goes to the components showing it
/// on the current page only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Travel speed, km/h × 100.
    pub travel_speed_kmh_x100: u16,
    /// Target drum speed, r/min × 100.
    pub target_drum_rpm_x100: u16,
    /// Measured drum speed, r/min × 100.
    pub actual_drum_rpm_x100: u16,
    /// Plants planted since start.
    pub plants: u32,
    /// Distance travelled since start, dm.
    pub distance_dm: u32,
    /// Distance measured by the machine during a calibration run, cm.
    pub measured_distance_cm: u32,
    /// Coefficient computed by the calibration, × 1000 (0 = none yet).
    pub calibration_result_x1000: u16,
    /// Profile B: travel speed, m/s × 100 (paper B's unit; profile A shows
    /// [`travel_speed_kmh_x100`](Self::travel_speed_kmh_x100)).
    pub travel_speed_mps_x100: u16,
    /// Profile B: planting motor speed n1, r/min × 100 (saturating).
    pub plant_motor_rpm_x100: u16,
    /// Profile B: feeding motor speed n2, r/min × 100 (saturating).
    pub feed_motor_rpm_x100: u16,
    /// Profile B: seedling-roller turns j since the belt was loaded (page 7
    /// *New roll*, [`Command::NewRoll`]; power-up counts from 0 too).
    pub roller_turns: u32,
    /// Profile B: effective roller radius r' = r + h·j, 0.1 mm (saturating).
    pub roller_radius_dmm: u16,
    /// Drum drive `n_max` (identified, or in force), r/min × 100.
    pub drive_n_max_x100: u16,
    /// Drum drive time constant τ, 0.1 ms.
    pub drive_tau_x10_ms: u16,
    /// Drum drive dead time, 0.1 ms.
    pub drive_dead_time_x10_ms: u16,
    /// Drive identification: 0 idle, 1 running, 2 done (press Save), 3 failed.
    pub drive_identification: u8,
    /// Planting quality since Start (of the *commanded* spacings: the
    /// control, not the seedlings' fall): quality of feed, 0.1 %.
    pub quality_of_feed_x10: u16,
    /// Multiples index (spacings ≤ 0.5 X), 0.1 %.
    pub multiples_x10: u16,
    /// Miss index (spacings > 1.5 X), 0.1 %.
    pub misses_x10: u16,
    /// Precision: CV of the spacings in the quality-of-feed band, 0.1 %.
    pub precision_cv_x10: u16,
    /// Share of the spacings within ±10 % of X, 0.1 %.
    pub within_10_pct_x10: u16,
    /// Plants per metre planted (unit down), × 100.
    pub plants_per_m_x100: u16,
    /// Machine A: the track's live slip measured against the ground wheel,
    /// 0.1 % ([`SLIP_UNKNOWN`] while not measured).
    pub track_slip_x10: i16,
    /// Machine A: the sensor giving the ground now.
    pub travel_source_in_use: TravelSourceInUse,
}

/// [`Status::track_slip_x10`] while no slip is measured (the Hall gear alone,
/// or one of the two sensors failing, or before three gear turns).
pub const SLIP_UNKNOWN: i16 = i16::MIN;

/// The sensor machine A measures the ground with now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TravelSourceInUse {
    /// The Hall gear (its setting).
    #[default]
    HallGear,
    /// The ground wheel.
    GroundWheel,
    /// The Hall gear standing in for a ground wheel that does not roll.
    HallStandIn,
}

impl TravelSourceInUse {
    /// The label shown on the run page.
    pub const fn label(self) -> &'static str {
        match self {
            Self::HallGear => "Hall gear",
            Self::GroundWheel => "Ground wheel",
            Self::HallStandIn => "Hall (wheel stopped)",
        }
    }
}

/// The buffer a [`StatusText`] is formatted into: the longest slip text,
/// `"Slip -3276.7 %"`.
pub const STATUS_TEXT_LEN: usize = 14;

/// A live value shown as a text (machine A's run page). Unlike the
/// numbers, which are written at every status write, a status text is
/// written only when it changes (and after a page change, a screen error or
/// a new link: [`Hmi::write_status`](crate::hmi::Hmi::write_status)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusText {
    /// [`Status::track_slip_x10`] as `"Slip 4.2 %"`, `"Slip -0.5 %"`, or
    /// `"Slip --"` while [`SLIP_UNKNOWN`] ([`slip_text`]).
    TrackSlip,
    /// [`Status::travel_source_in_use`]'s label
    /// ([`TravelSourceInUse::label`]).
    TravelSourceInUse,
}

impl StatusText {
    /// Every status text; [`index`](Self::index) is the position here.
    pub const ALL: [StatusText; 2] = [Self::TrackSlip, Self::TravelSourceInUse];

    /// The position in [`StatusText::ALL`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// What the text shows of `s`: equal keys, equal texts.
    pub fn key(self, s: &Status) -> i16 {
        match self {
            Self::TrackSlip => s.track_slip_x10,
            Self::TravelSourceInUse => s.travel_source_in_use as i16,
        }
    }

    /// The text for `s` (in `buf` or a constant).
    pub fn text<'b>(self, s: &Status, buf: &'b mut [u8; STATUS_TEXT_LEN]) -> &'b str {
        match self {
            Self::TrackSlip => slip_text(s.track_slip_x10, buf),
            Self::TravelSourceInUse => s.travel_source_in_use.label(),
        }
    }
}

/// The run page's slip text: `"Slip 4.2 %"` (0.1 % steps, the sign of a
/// negative slip), `"Slip --"` for [`SLIP_UNKNOWN`]. Digits by hand:
/// `core::fmt`'s integer formatting costs ≈ 2 KB of flash.
pub fn slip_text(slip_x10: i16, buf: &mut [u8; STATUS_TEXT_LEN]) -> &str {
    if slip_x10 == SLIP_UNKNOWN {
        return "Slip --";
    }
    let v = slip_x10.unsigned_abs();
    let (whole, tenth) = (v / 10, v % 10);
    let mut len = 0usize;
    let mut put = |b: u8| {
        if let Some(slot) = buf.get_mut(len) {
            *slot = b;
            len = len.saturating_add(1);
        }
    };
    for &b in b"Slip " {
        put(b);
    }
    if slip_x10 < 0 {
        put(b'-');
    }
    // At most 3276: four digits, no leading zeros.
    let mut started = false;
    for unit in [1000u16, 100, 10, 1] {
        let digit = whole.checked_div(unit).unwrap_or(0) % 10;
        if digit != 0 || started || unit == 1 {
            started = true;
            put(b'0'.saturating_add(u8::try_from(digit).unwrap_or(0)));
        }
    }
    put(b'.');
    put(b'0'.saturating_add(u8::try_from(tenth).unwrap_or(0)));
    for &b in b" %" {
        put(b);
    }
    core::str::from_utf8(buf.get(..len).unwrap_or(&[])).unwrap_or("Slip --")
}

/// Live values shown by display-only components.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusField {
    /// [`Status::travel_speed_kmh_x100`].
    TravelSpeed,
    /// [`Status::target_drum_rpm_x100`].
    TargetDrumSpeed,
    /// [`Status::actual_drum_rpm_x100`].
    ActualDrumSpeed,
    /// [`Status::plants`].
    Plants,
    /// [`Status::distance_dm`].
    Distance,
    /// [`Status::measured_distance_cm`].
    MeasuredDistance,
    /// [`Status::calibration_result_x1000`].
    CalibrationResult,
    /// [`Status::travel_speed_mps_x100`].
    TravelSpeedMps,
    /// [`Status::plant_motor_rpm_x100`].
    PlantMotorSpeed,
    /// [`Status::feed_motor_rpm_x100`].
    FeedMotorSpeed,
    /// [`Status::roller_turns`].
    RollerTurns,
    /// [`Status::roller_radius_dmm`].
    RollerRadius,
    /// [`Status::drive_n_max_x100`].
    DriveNMax,
    /// [`Status::drive_tau_x10_ms`].
    DriveTau,
    /// [`Status::drive_dead_time_x10_ms`].
    DriveDeadTime,
    /// [`Status::drive_identification`].
    DriveIdentification,
    /// [`Status::quality_of_feed_x10`].
    QualityOfFeed,
    /// [`Status::multiples_x10`].
    Multiples,
    /// [`Status::misses_x10`].
    Misses,
    /// [`Status::precision_cv_x10`].
    PrecisionCv,
    /// [`Status::within_10_pct_x10`].
    Within10Pct,
    /// [`Status::plants_per_m_x100`].
    PlantsPerMetre,
}

impl StatusField {
    /// The raw value of this field in `s`.
    pub fn value(self, s: &Status) -> i32 {
        let sat = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
        match self {
            Self::TravelSpeed => i32::from(s.travel_speed_kmh_x100),
            Self::TargetDrumSpeed => i32::from(s.target_drum_rpm_x100),
            Self::ActualDrumSpeed => i32::from(s.actual_drum_rpm_x100),
            Self::Plants => sat(s.plants),
            Self::Distance => sat(s.distance_dm),
            Self::MeasuredDistance => sat(s.measured_distance_cm),
            Self::CalibrationResult => i32::from(s.calibration_result_x1000),
            Self::TravelSpeedMps => i32::from(s.travel_speed_mps_x100),
            Self::PlantMotorSpeed => i32::from(s.plant_motor_rpm_x100),
            Self::FeedMotorSpeed => i32::from(s.feed_motor_rpm_x100),
            Self::RollerTurns => sat(s.roller_turns),
            Self::RollerRadius => i32::from(s.roller_radius_dmm),
            Self::DriveNMax => i32::from(s.drive_n_max_x100),
            Self::DriveTau => i32::from(s.drive_tau_x10_ms),
            Self::DriveDeadTime => i32::from(s.drive_dead_time_x10_ms),
            Self::DriveIdentification => i32::from(s.drive_identification),
            Self::QualityOfFeed => i32::from(s.quality_of_feed_x10),
            Self::Multiples => i32::from(s.multiples_x10),
            Self::Misses => i32::from(s.misses_x10),
            Self::PrecisionCv => i32::from(s.precision_cv_x10),
            Self::Within10Pct => i32::from(s.within_10_pct_x10),
            Self::PlantsPerMetre => i32::from(s.plants_per_m_x100),
        }
    }
}

/// What a button does when released (a motor-starting one: when pressed
/// then released, [`Action::starts_motor`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Action {
    /// Navigate (no machine command).
    ShowPage(Page),
    /// Navigate to the home page of the profile running
    /// ([`MachineProfile::home`]; no machine command).
    ShowHome,
    /// [`Command::SelectProfile`] with the next profile.
    NextProfile,
    /// [`Command::SelectMode`] and show the mode's page.
    SelectMode(Mode),
    /// Read the page's input for this field with `get`, validate, command.
    Apply(Field),
    /// [`Command::Start`].
    Start,
    /// [`Command::Stop`].
    Stop,
    /// [`Command::SelectGear`] with the next slower gear.
    GearDown,
    /// [`Command::SelectGear`] with the next faster gear.
    GearUp,
    /// [`Command::SelectCalibration`] with the next kind.
    NextCalibration,
    /// [`Command::CalibrationStart`].
    CalibrationStart,
    /// [`Command::CalibrationStop`].
    CalibrationStop,
    /// [`Command::CalibrationAccept`].
    CalibrationAccept,
    /// [`Command::AcknowledgeAlarm`], then back to the page before the alarm.
    AcknowledgeAlarm,
    /// [`Command::SaveSettings`].
    SaveSettings,
    /// [`Command::SetDrumEncoderReversed`] with the other direction.
    ToggleEncoderDirection,
    /// [`Command::IdentifyDrive`].
    IdentifyDrive,
    /// [`Command::SetWorkSwitchFitted`] with the other state.
    ToggleWorkSwitch,
    /// [`Command::SetSpeedFollowing`] with the other placement.
    TogglePlacement,
    /// [`Command::AcceptDriveModel`].
    AcceptDriveModel,
    /// [`Command::SelectLinkParameter`] with the next parameter.
    NextLinkParameter,
    /// [`Command::NewRoll`].
    NewRoll,
    /// [`Command::SelectTravelSource`] with the next source.
    NextTravelSource,
    /// [`Command::SetGroundWheelReversed`] with the other direction.
    ToggleGroundWheelDirection,
}

impl Action {
    /// `true` for the buttons whose command starts a motor: *Start*
    /// (profile A's drum, profile B's two steppers) and *Identify* (runs
    /// the drum for 7 s). Their screen file sends the press and the
    /// release, and the MCU acts only on the press then the release of the
    /// same button on the page shown (docs/hmi.md §3). Calibration's
    /// *Start run* only starts counting.
    pub const fn starts_motor(self) -> bool {
        matches!(self, Self::Start | Self::IdentifyDrive)
    }
}

/// The role of a component in the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Role {
    /// A button: "Send Component ID" on Touch Release (and on Touch Press
    /// for Stop and [`Action::starts_motor`], docs/hmi.md §3).
    Action(Action),
    /// An editable number (numeric keyboard); read by `get name.val`.
    Input(Field),
    /// A display-only number written with `name.val=`.
    Status(StatusField),
    /// The gear label, written with `tgear.txt=`.
    GearLabel,
    /// The calibration kind's label, written with `tkind.txt=`.
    CalibrationLabel,
    /// The selected machine profile's label, written with `tprofile.txt=`.
    ProfileLabel,
    /// The firmware version, written with `tver.txt=`.
    Version,
    /// The drum encoder direction's label, written with `tenc.txt=`.
    EncoderDirectionLabel,
    /// The work switch setting's label, written with `twork.txt=`.
    WorkSwitchLabel,
    /// The placement setting's label, written with `tplace.txt=`.
    PlacementLabel,
    /// The selected link setting's label, written with `tlpar.txt=`.
    LinkParameterLabel,
    /// Machine A's travel source setting's label, written with
    /// `tsource.txt=`.
    TravelSourceLabel,
    /// The ground wheel's direction label, written with `twdir.txt=`.
    GroundWheelDirectionLabel,
    /// A live value shown as a text (`tslip.txt=`, `tground.txt=`), written
    /// only when it changes.
    StatusText(StatusText),
    /// The alarm text, written with `talarm.txt=`.
    AlarmText,
    /// The page's message box for validation errors and notices.
    Message,
}

/// Component type to create in the vendor editor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// Button.
    Button,
    /// Text (`txt_maxl` ≥ 40).
    Text,
    /// Number.
    Number,
    /// Xfloat with this many decimals (`ws1`).
    Xfloat(u8),
}

/// One component of the contract.
///
/// Six bytes in flash: the id and the kind share a byte, and the name is an
/// offset and length into one blob of every name ([`Component::name`]),
/// all built at compile time from the table's source (`docs/hmi.md`,
/// "Flash").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Component {
    /// Page it sits on.
    pub page: Page,
    /// [`Component::id`] in bits 4:0, [`Component::kind`]'s code
    /// ([`kind_code`]) in bits 7:5.
    id_kind: u8,
    /// Object name (`objname`): `offset << 4 | length` in [`NAMES`],
    /// little-endian (bytes: 12 B less code on thumbv7m than a `u16`).
    name: [u8; 2],
    /// What it does.
    pub role: Role,
}

/// Bits of `id_kind` holding the id (ids up to 31 a page).
const ID_BITS: u32 = 5;
const ID_MASK: u8 = (1 << ID_BITS) - 1;

/// The 3-bit code of a kind: Button 0, Text 1, Number 2, Xfloat with `d`
/// decimals 3 + d (d ≤ 4; more is a build error).
#[allow(clippy::arithmetic_side_effects)]
const fn kind_code(kind: Kind) -> u8 {
    match kind {
        Kind::Button => 0,
        Kind::Text => 1,
        Kind::Number => 2,
        Kind::Xfloat(d) => {
            assert!(d <= 4);
            3 + d
        }
    }
}

impl Component {
    /// Component id (creation order on the page, the page itself is 0).
    pub fn id(&self) -> u8 {
        self.id_kind & ID_MASK
    }

    /// Type to create.
    pub fn kind(&self) -> Kind {
        match self.id_kind >> ID_BITS {
            0 => Kind::Button,
            1 => Kind::Text,
            2 => Kind::Number,
            code => Kind::Xfloat(code.saturating_sub(3)),
        }
    }

    /// Object name (`objname`).
    pub fn name(&self) -> &'static str {
        let name = u16::from_le_bytes(self.name);
        let start = usize::from(name >> NAME_LEN_BITS);
        let len = usize::from(name & NAME_LEN_MASK);
        // Always in the blob and on character boundaries (checked by the
        // test `packed_names_are_the_sources`); "" is never reached.
        NAMES.get(start..start.saturating_add(len)).unwrap_or("")
    }

    /// The name as an [`ObjName`] (the table's names are checked by a test).
    pub fn obj(&self) -> ObjName<'static> {
        ObjName::new_unchecked(self.name())
    }

    /// Looks up the component a touch event names.
    pub fn lookup(page: u8, id: u8) -> Option<&'static Component> {
        COMPONENTS
            .iter()
            .find(|c| c.page.id() == page && c.id() == id)
    }

    /// The components of one page.
    pub fn on_page(page: Page) -> impl Iterator<Item = &'static Component> {
        COMPONENTS.iter().filter(move |c| c.page == page)
    }

    /// The input component for `field` on `page`.
    pub fn input(page: Page, field: Field) -> Option<&'static Component> {
        // `matches!`, not `==`: the derived comparison of two roles is a
        // function of its own in flash.
        Self::on_page(page).find(|c| matches!(c.role, Role::Input(f) if f == field))
    }
}

/// One row of the table's source ([`SOURCE`]); never in the image.
struct Source {
    page: Page,
    id: u8,
    name: &'static str,
    kind: Kind,
    role: Role,
}

const fn c(page: Page, id: u8, name: &'static str, kind: Kind, role: Role) -> Source {
    Source {
        page,
        id,
        name,
        kind,
        role,
    }
}

/// Bits of a packed name holding its length (names have at most 15 bytes;
/// the blob at most 4095).
const NAME_LEN_BITS: u32 = 4;
const NAME_LEN_MASK: u16 = (1 << NAME_LEN_BITS) - 1;
/// Room for the blob while it is built (more is a build error).
const NAMES_ROOM: usize = 1024;

/// Where `name` starts in `blob[..len]`, if it is there already (as a
/// whole name or inside a longer one). Compile time only, like [`pack_names`].
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
const fn find_name(blob: &[u8; NAMES_ROOM], len: usize, name: &[u8]) -> Option<usize> {
    let mut at = 0;
    while at + name.len() <= len {
        let mut i = 0;
        while i < name.len() && blob[at + i] == name[i] {
            i += 1;
        }
        if i == name.len() {
            return Some(at);
        }
        at += 1;
    }
    None
}

/// Every name once, and the packed name of every row. Evaluated only at
/// compile time: an index out of range or a name too long is a build error.
#[allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::panic
)]
const fn pack_names() -> ([u8; NAMES_ROOM], usize, [u16; SOURCE.len()]) {
    let mut blob = [0u8; NAMES_ROOM];
    let mut len = 0;
    let mut packed = [0u16; SOURCE.len()];
    let mut row = 0;
    while row < SOURCE.len() {
        let name = SOURCE[row].name.as_bytes();
        assert!(!name.is_empty() && name.len() <= NAME_LEN_MASK as usize);
        let start = match find_name(&blob, len, name) {
            Some(at) => at,
            None => {
                let mut i = 0;
                while i < name.len() {
                    blob[len + i] = name[i];
                    i += 1;
                }
                len += name.len();
                len - name.len()
            }
        };
        assert!(start < (1 << (16 - NAME_LEN_BITS)));
        packed[row] = (start as u16) << NAME_LEN_BITS | name.len() as u16;
        row += 1;
    }
    (blob, len, packed)
}

const PACKED_NAMES: ([u8; NAMES_ROOM], usize, [u16; SOURCE.len()]) = pack_names();

/// The used part of the blob (compile time only).
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
const fn used_names<const N: usize>() -> [u8; N] {
    let mut out = [0u8; N];
    let mut i = 0;
    while i < N {
        out[i] = PACKED_NAMES.0[i];
        i += 1;
    }
    out
}

const NAME_BYTES: [u8; PACKED_NAMES.1] = used_names();

/// Every component name once, each found by offset and length.
const NAMES: &str = match core::str::from_utf8(&NAME_BYTES) {
    Ok(s) => s,
    Err(_) => panic!("component names are ASCII"),
};

/// The table packed for flash (compile time only).
#[allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]
const fn pack_table() -> [Component; SOURCE.len()] {
    let mut out = [Component {
        page: Page::Boot,
        id_kind: 0,
        name: [0; 2],
        role: Role::Message,
    }; SOURCE.len()];
    let mut row = 0;
    while row < SOURCE.len() {
        let s = &SOURCE[row];
        assert!(s.id <= ID_MASK);
        out[row] = Component {
            page: s.page,
            id_kind: kind_code(s.kind) << ID_BITS | s.id,
            name: PACKED_NAMES.2[row].to_le_bytes(),
            role: s.role,
        };
        row += 1;
    }
    out
}

const PACKED_TABLE: [Component; SOURCE.len()] = pack_table();

/// Every component the MCU knows, by page and id (see `docs/hmi.md`).
pub const COMPONENTS: &[Component] = &PACKED_TABLE;

/// The screen file's static texts: components the MCU never writes nor
/// reads (their text is the editor's), listed in docs/hmi.md §6 with their
/// page and id. They take an id on their page, so the contract's ids skip
/// them.
pub const STATIC_TEXTS: &[(Page, u8, &str)] = &[(Page::Adaptive, 21, "tqlabel")];

use Action as A;
use Kind as K;
use Page as P;
use Role as R;

/// The table's source: every component by page and id (see `docs/hmi.md`),
/// packed into [`COMPONENTS`] at compile time.
const SOURCE: &[Source] = &[
    // 0 boot
    c(P::Boot, 1, "tmsg", K::Text, R::Message),
    c(P::Boot, 2, "tver", K::Text, R::Version),
    // 1 mode
    c(
        P::Mode,
        1,
        "bfixed",
        K::Button,
        R::Action(A::SelectMode(Mode::Fixed)),
    ),
    c(
        P::Mode,
        2,
        "badapt",
        K::Button,
        R::Action(A::SelectMode(Mode::SpeedAdaptive)),
    ),
    c(
        P::Mode,
        3,
        "bcalib",
        K::Button,
        R::Action(A::ShowPage(P::Calibration)),
    ),
    c(
        P::Mode,
        4,
        "bset",
        K::Button,
        R::Action(A::ShowPage(P::Settings)),
    ),
    c(
        P::Mode,
        5,
        "ncoef",
        K::Xfloat(2),
        R::Input(Field::MotorCoefficient),
    ),
    c(
        P::Mode,
        6,
        "bcoef",
        K::Button,
        R::Action(A::Apply(Field::MotorCoefficient)),
    ),
    c(P::Mode, 7, "tmsg", K::Text, R::Message),
    // 2 fixed
    c(P::Fixed, 1, "bstart", K::Button, R::Action(A::Start)),
    c(
        P::Fixed,
        2,
        "bapply",
        K::Button,
        R::Action(A::Apply(Field::FixedDrumSpeed)),
    ),
    c(
        P::Fixed,
        3,
        "nspeed",
        K::Xfloat(2),
        R::Input(Field::FixedDrumSpeed),
    ),
    c(P::Fixed, 4, "bstop", K::Button, R::Action(A::Stop)),
    c(
        P::Fixed,
        5,
        "xtravel",
        K::Xfloat(2),
        R::Status(StatusField::TravelSpeed),
    ),
    c(
        P::Fixed,
        6,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Mode)),
    ),
    c(
        P::Fixed,
        7,
        "xtarget",
        K::Xfloat(2),
        R::Status(StatusField::TargetDrumSpeed),
    ),
    c(
        P::Fixed,
        8,
        "xdrum",
        K::Xfloat(2),
        R::Status(StatusField::ActualDrumSpeed),
    ),
    c(
        P::Fixed,
        9,
        "nplants",
        K::Number,
        R::Status(StatusField::Plants),
    ),
    c(
        P::Fixed,
        10,
        "xdist",
        K::Xfloat(1),
        R::Status(StatusField::Distance),
    ),
    c(P::Fixed, 11, "tmsg", K::Text, R::Message),
    // 3 adaptive
    c(
        P::Adaptive,
        1,
        "nspacing",
        K::Xfloat(1),
        R::Input(Field::Spacing),
    ),
    c(
        P::Adaptive,
        2,
        "bapply",
        K::Button,
        R::Action(A::Apply(Field::Spacing)),
    ),
    c(P::Adaptive, 3, "bgeardn", K::Button, R::Action(A::GearDown)),
    c(P::Adaptive, 4, "bgearup", K::Button, R::Action(A::GearUp)),
    c(P::Adaptive, 5, "tgear", K::Text, R::GearLabel),
    c(
        P::Adaptive,
        6,
        "xdist",
        K::Xfloat(1),
        R::Status(StatusField::Distance),
    ),
    c(P::Adaptive, 7, "bstop", K::Button, R::Action(A::Stop)),
    c(
        P::Adaptive,
        8,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Mode)),
    ),
    c(
        P::Adaptive,
        9,
        "xtravel",
        K::Xfloat(2),
        R::Status(StatusField::TravelSpeed),
    ),
    c(
        P::Adaptive,
        10,
        "xtarget",
        K::Xfloat(2),
        R::Status(StatusField::TargetDrumSpeed),
    ),
    c(
        P::Adaptive,
        11,
        "xdrum",
        K::Xfloat(2),
        R::Status(StatusField::ActualDrumSpeed),
    ),
    c(
        P::Adaptive,
        12,
        "nplants",
        K::Number,
        R::Status(StatusField::Plants),
    ),
    c(P::Adaptive, 13, "bstart", K::Button, R::Action(A::Start)),
    c(P::Adaptive, 14, "tmsg", K::Text, R::Message),
    // Planting quality since Start (the control's, not the seedlings' fall:
    // the page's static label says so, docs/hmi.md).
    c(
        P::Adaptive,
        15,
        "xqf",
        K::Xfloat(1),
        R::Status(StatusField::QualityOfFeed),
    ),
    c(
        P::Adaptive,
        16,
        "xmult",
        K::Xfloat(1),
        R::Status(StatusField::Multiples),
    ),
    c(
        P::Adaptive,
        17,
        "xmiss",
        K::Xfloat(1),
        R::Status(StatusField::Misses),
    ),
    c(
        P::Adaptive,
        18,
        "xcv",
        K::Xfloat(1),
        R::Status(StatusField::PrecisionCv),
    ),
    c(
        P::Adaptive,
        19,
        "xwithin",
        K::Xfloat(1),
        R::Status(StatusField::Within10Pct),
    ),
    c(
        P::Adaptive,
        20,
        "xperm",
        K::Xfloat(2),
        R::Status(StatusField::PlantsPerMetre),
    ),
    // Id 21 is the static text `tqlabel` ([`STATIC_TEXTS`]). Machine A's
    // ground: the live track slip and the sensor in use.
    c(
        P::Adaptive,
        22,
        "tslip",
        K::Text,
        R::StatusText(StatusText::TrackSlip),
    ),
    c(
        P::Adaptive,
        23,
        "tground",
        K::Text,
        R::StatusText(StatusText::TravelSourceInUse),
    ),
    // 4 calib
    c(
        P::Calibration,
        1,
        "bcstart",
        K::Button,
        R::Action(A::CalibrationStart),
    ),
    c(
        P::Calibration,
        2,
        "bcstop",
        K::Button,
        R::Action(A::CalibrationStop),
    ),
    c(
        P::Calibration,
        3,
        "xmeas",
        K::Xfloat(2),
        R::Status(StatusField::MeasuredDistance),
    ),
    c(
        P::Calibration,
        4,
        "nactual",
        K::Xfloat(2),
        R::Input(Field::CalibrationDistance),
    ),
    c(
        P::Calibration,
        5,
        "bactual",
        K::Button,
        R::Action(A::Apply(Field::CalibrationDistance)),
    ),
    c(
        P::Calibration,
        6,
        "xk",
        K::Xfloat(3),
        R::Status(StatusField::CalibrationResult),
    ),
    c(
        P::Calibration,
        7,
        "nk",
        K::Xfloat(3),
        R::Input(Field::CalibrationCoefficient),
    ),
    c(
        P::Calibration,
        8,
        "bk",
        K::Button,
        R::Action(A::Apply(Field::CalibrationCoefficient)),
    ),
    c(
        P::Calibration,
        9,
        "bsave",
        K::Button,
        R::Action(A::CalibrationAccept),
    ),
    c(
        P::Calibration,
        10,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Mode)),
    ),
    c(P::Calibration, 11, "tgear", K::Text, R::GearLabel),
    c(P::Calibration, 12, "tmsg", K::Text, R::Message),
    c(
        P::Calibration,
        13,
        "bkind",
        K::Button,
        R::Action(A::NextCalibration),
    ),
    c(P::Calibration, 14, "tkind", K::Text, R::CalibrationLabel),
    // 5 alarm
    c(P::Alarm, 1, "talarm", K::Text, R::AlarmText),
    c(
        P::Alarm,
        2,
        "bok",
        K::Button,
        R::Action(A::AcknowledgeAlarm),
    ),
    // 6 settings
    c(
        P::Settings,
        1,
        "ndim",
        K::Number,
        R::Input(Field::Brightness),
    ),
    c(
        P::Settings,
        2,
        "bdim",
        K::Button,
        R::Action(A::Apply(Field::Brightness)),
    ),
    c(
        P::Settings,
        3,
        "bsave",
        K::Button,
        R::Action(A::SaveSettings),
    ),
    c(P::Settings, 4, "bback", K::Button, R::Action(A::ShowHome)),
    c(P::Settings, 5, "tver", K::Text, R::Version),
    c(P::Settings, 6, "tmsg", K::Text, R::Message),
    c(
        P::Settings,
        7,
        "bprofile",
        K::Button,
        R::Action(A::NextProfile),
    ),
    c(P::Settings, 8, "tprofile", K::Text, R::ProfileLabel),
    c(
        P::Settings,
        9,
        "benc",
        K::Button,
        R::Action(A::ToggleEncoderDirection),
    ),
    c(P::Settings, 10, "tenc", K::Text, R::EncoderDirectionLabel),
    c(
        P::Settings,
        11,
        "bdrive",
        K::Button,
        R::Action(A::ShowPage(P::Drive)),
    ),
    c(
        P::Settings,
        12,
        "bwork",
        K::Button,
        R::Action(A::ToggleWorkSwitch),
    ),
    c(P::Settings, 13, "twork", K::Text, R::WorkSwitchLabel),
    c(
        P::Settings,
        14,
        "nfirst",
        K::Xfloat(1),
        R::Input(Field::FirstPlantDistance),
    ),
    c(
        P::Settings,
        15,
        "bfirst",
        K::Button,
        R::Action(A::Apply(Field::FirstPlantDistance)),
    ),
    c(
        P::Settings,
        16,
        "bplace",
        K::Button,
        R::Action(A::TogglePlacement),
    ),
    c(P::Settings, 17, "tplace", K::Text, R::PlacementLabel),
    // Machine A's ground wheel: the travel source and the wheel's
    // direction.
    c(
        P::Settings,
        18,
        "bsource",
        K::Button,
        R::Action(A::NextTravelSource),
    ),
    c(P::Settings, 19, "tsource", K::Text, R::TravelSourceLabel),
    c(
        P::Settings,
        20,
        "bwdir",
        K::Button,
        R::Action(A::ToggleGroundWheelDirection),
    ),
    c(
        P::Settings,
        21,
        "twdir",
        K::Text,
        R::GroundWheelDirectionLabel,
    ),
    // 7 belt (profile B home)
    c(P::Belt, 1, "bstart", K::Button, R::Action(A::Start)),
    c(P::Belt, 2, "bstop", K::Button, R::Action(A::Stop)),
    c(
        P::Belt,
        3,
        "xn1",
        K::Xfloat(2),
        R::Status(StatusField::PlantMotorSpeed),
    ),
    c(
        P::Belt,
        4,
        "bset",
        K::Button,
        R::Action(A::ShowPage(P::Settings)),
    ),
    c(
        P::Belt,
        5,
        "xtravel",
        K::Xfloat(2),
        R::Status(StatusField::TravelSpeedMps),
    ),
    c(
        P::Belt,
        6,
        "bpar",
        K::Button,
        R::Action(A::ShowPage(P::BeltParameters)),
    ),
    c(
        P::Belt,
        7,
        "xn2",
        K::Xfloat(2),
        R::Status(StatusField::FeedMotorSpeed),
    ),
    c(
        P::Belt,
        8,
        "nj",
        K::Number,
        R::Status(StatusField::RollerTurns),
    ),
    c(
        P::Belt,
        9,
        "xrad",
        K::Xfloat(1),
        R::Status(StatusField::RollerRadius),
    ),
    c(
        P::Belt,
        10,
        "nplants",
        K::Number,
        R::Status(StatusField::Plants),
    ),
    c(P::Belt, 11, "tmsg", K::Text, R::Message),
    c(P::Belt, 12, "broll", K::Button, R::Action(A::NewRoll)),
    // 8 beltpar (profile B parameters)
    c(
        P::BeltParameters,
        1,
        "nspacing",
        K::Xfloat(1),
        R::Input(Field::BeltSpacing),
    ),
    c(
        P::BeltParameters,
        2,
        "bspacing",
        K::Button,
        R::Action(A::Apply(Field::BeltSpacing)),
    ),
    c(
        P::BeltParameters,
        3,
        "npitch",
        K::Xfloat(1),
        R::Input(Field::SeedlingPitch),
    ),
    c(
        P::BeltParameters,
        4,
        "bpitch",
        K::Button,
        R::Action(A::Apply(Field::SeedlingPitch)),
    ),
    c(
        P::BeltParameters,
        5,
        "nangle",
        K::Number,
        R::Input(Field::ClampAngle),
    ),
    c(
        P::BeltParameters,
        6,
        "bangle",
        K::Button,
        R::Action(A::Apply(Field::ClampAngle)),
    ),
    c(
        P::BeltParameters,
        7,
        "nclamp",
        K::Number,
        R::Input(Field::ClampCount),
    ),
    c(
        P::BeltParameters,
        8,
        "bclamp",
        K::Button,
        R::Action(A::Apply(Field::ClampCount)),
    ),
    c(
        P::BeltParameters,
        9,
        "nradius",
        K::Xfloat(1),
        R::Input(Field::RollerRadius),
    ),
    c(
        P::BeltParameters,
        10,
        "bradius",
        K::Button,
        R::Action(A::Apply(Field::RollerRadius)),
    ),
    c(
        P::BeltParameters,
        11,
        "nthick",
        K::Xfloat(2),
        R::Input(Field::BeltThickness),
    ),
    c(
        P::BeltParameters,
        12,
        "bthick",
        K::Button,
        R::Action(A::Apply(Field::BeltThickness)),
    ),
    c(
        P::BeltParameters,
        13,
        "nthresh",
        K::Xfloat(3),
        R::Input(Field::SpeedThreshold),
    ),
    c(
        P::BeltParameters,
        14,
        "bthresh",
        K::Button,
        R::Action(A::Apply(Field::SpeedThreshold)),
    ),
    c(
        P::BeltParameters,
        15,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Belt)),
    ),
    c(P::BeltParameters, 16, "tmsg", K::Text, R::Message),
    // 9 drive (profile A: drum drive identification)
    c(
        P::Drive,
        1,
        "xtau",
        K::Xfloat(1),
        R::Status(StatusField::DriveTau),
    ),
    c(
        P::Drive,
        2,
        "bidsave",
        K::Button,
        R::Action(A::AcceptDriveModel),
    ),
    c(
        P::Drive,
        3,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Settings)),
    ),
    c(
        P::Drive,
        4,
        "xnmax",
        K::Xfloat(2),
        R::Status(StatusField::DriveNMax),
    ),
    c(
        P::Drive,
        5,
        "bident",
        K::Button,
        R::Action(A::IdentifyDrive),
    ),
    c(
        P::Drive,
        6,
        "xdead",
        K::Xfloat(1),
        R::Status(StatusField::DriveDeadTime),
    ),
    c(
        P::Drive,
        7,
        "nidstate",
        K::Number,
        R::Status(StatusField::DriveIdentification),
    ),
    c(P::Drive, 8, "bstop", K::Button, R::Action(A::Stop)),
    c(P::Drive, 9, "tmsg", K::Text, R::Message),
    c(
        P::Drive,
        10,
        "blink",
        K::Button,
        R::Action(A::ShowPage(P::Link)),
    ),
    // 10 link (profile A: the drum driver's RS-485 link, docs/drive-link.md)
    c(P::Link, 1, "tlpar", K::Text, R::LinkParameterLabel),
    c(
        P::Link,
        2,
        "blpar",
        K::Button,
        R::Action(A::NextLinkParameter),
    ),
    c(P::Link, 3, "nlval", K::Number, R::Input(Field::LinkValue)),
    c(
        P::Link,
        4,
        "blval",
        K::Button,
        R::Action(A::Apply(Field::LinkValue)),
    ),
    c(
        P::Link,
        5,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Drive)),
    ),
    c(P::Link, 6, "tmsg", K::Text, R::Message),
];

/// Most instructions one page refresh needs ([`page_instructions`]).
pub const MAX_PAGE_INSTRUCTIONS: usize = 9;

/// The instructions that show the settings on `page`: each input's current
/// value, the gear, calibration-kind and profile labels and the version text.
pub fn page_instructions(
    page: Page,
    settings: &Settings,
    version: ScreenText<'static>,
) -> heapless::Vec<Instruction<'static>, MAX_PAGE_INSTRUCTIONS> {
    let mut out = heapless::Vec::new();
    for comp in Component::on_page(page) {
        if let Some(ins) = component_instruction(comp, settings, version) {
            // Capacity is checked by a test for every page.
            let _ = out.push(ins);
        }
    }
    out
}

/// What [`page_instructions`] writes for one component (`None`: a component
/// that shows no setting).
pub(crate) fn component_instruction(
    comp: &'static Component,
    settings: &Settings,
    version: ScreenText<'static>,
) -> Option<Instruction<'static>> {
    // The labels share one text check and one instruction (smaller in flash).
    let label = match comp.role {
        Role::Input(f) => return Some(Instruction::SetValue(comp.obj(), f.current(settings))),
        Role::Version => return Some(Instruction::SetText(comp.obj(), version)),
        Role::GearLabel => settings.gear.label(),
        Role::CalibrationLabel => settings.calibration_kind.label(),
        Role::ProfileLabel => settings.profile.label(),
        Role::EncoderDirectionLabel => encoder_direction_label(settings.drum_encoder_reversed),
        Role::WorkSwitchLabel => work_switch_label(settings.work_switch_fitted),
        Role::PlacementLabel => placement_label(settings.speed_following),
        Role::LinkParameterLabel => settings.link_parameter.label(),
        Role::TravelSourceLabel => settings.travel_source.label(),
        Role::GroundWheelDirectionLabel => encoder_direction_label(settings.ground_wheel_reversed),
        _ => return None,
    };
    Some(Instruction::SetText(
        comp.obj(),
        ScreenText::new(label).unwrap_or(version),
    ))
}

/// Each instruction that shows `status` on `page` (its status numbers and
/// status texts, whether changed or not), one at a time (the Adaptive page
/// has 13: no buffer).
pub fn status_instructions(page: Page, status: &Status, mut each: impl FnMut(&Instruction<'_>)) {
    for comp in Component::on_page(page) {
        let mut buf = [0u8; STATUS_TEXT_LEN];
        if let Some(ins) = status_instruction(comp, status, &mut buf) {
            each(&ins);
        }
    }
}

/// What shows `status` in one component (`None`: a component that shows no
/// live value); a status text is formatted into `buf`.
pub(crate) fn status_instruction<'b>(
    comp: &'static Component,
    status: &Status,
    buf: &'b mut [u8; STATUS_TEXT_LEN],
) -> Option<Instruction<'b>> {
    match comp.role {
        Role::Status(f) => Some(Instruction::SetValue(comp.obj(), f.value(status))),
        Role::StatusText(t) => Some(Instruction::SetText(
            comp.obj(),
            ScreenText::new(t.text(status, buf)).unwrap_or(ScreenText::EMPTY),
        )),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    /// Each packed name reads back as the source row's name (the `&str`
    /// literal in [`SOURCE`], which does not go through the packing).
    #[test]
    fn packed_names_are_the_sources() {
        assert_eq!(COMPONENTS.len(), SOURCE.len());
        for (packed, source) in COMPONENTS.iter().zip(SOURCE) {
            assert_eq!(packed.name(), source.name);
            assert_eq!(packed.obj(), ObjName::new(source.name).unwrap());
            assert_eq!(
                (packed.page, packed.id(), packed.kind(), packed.role),
                (source.page, source.id, source.kind, source.role)
            );
        }
        // Duplicates are stored once: the blob is shorter than all names.
        let all: usize = SOURCE.iter().map(|s| s.name.len()).sum();
        assert!(NAMES.len() < all, "{} {all}", NAMES.len());
        assert_eq!(core::mem::size_of::<Component>(), 6);
    }

    #[test]
    fn table_is_consistent() {
        for (i, a) in COMPONENTS.iter().enumerate() {
            assert!(ObjName::new(a.name()).is_ok(), "{}", a.name());
            assert!(a.id() >= 1);
            for b in COMPONENTS.get(i + 1..).unwrap() {
                assert!(!(a.page == b.page && a.id() == b.id()), "{a:?} {b:?}");
                assert!(!(a.page == b.page && a.name() == b.name()), "{a:?} {b:?}");
            }
            if let Role::Action(Action::Apply(f)) = a.role {
                assert!(Component::input(a.page, f).is_some(), "{a:?}");
            }
        }
        // Ids are 1..=n without gaps on every page (creation order in the
        // editor), counting the static texts, which the contract skips.
        for (page, id, name) in STATIC_TEXTS {
            assert!(Component::lookup(page.id(), *id).is_none(), "{name}");
            assert!(ObjName::new(name).is_ok(), "{name}");
            assert!(Component::on_page(*page).all(|c| c.name() != *name));
        }
        for p in Page::ALL {
            let statics = STATIC_TEXTS.iter().filter(|s| s.0 == p).count();
            let n = Component::on_page(p).count() + statics;
            for id in 1..=n {
                let id = u8::try_from(id).unwrap();
                assert!(
                    Component::lookup(p.id(), id).is_some()
                        || STATIC_TEXTS.iter().any(|s| s.0 == p && s.1 == id),
                    "{p:?} id {id}"
                );
            }
            // The Adaptive page has 20 (the quality figures); the editor
            // takes up to 250 a page.
            assert!(Component::on_page(p).count() <= 24);
            assert!(
                Component::on_page(p)
                    .filter(|c| {
                        matches!(
                            c.role,
                            Role::Input(_)
                                | Role::GearLabel
                                | Role::CalibrationLabel
                                | Role::ProfileLabel
                                | Role::EncoderDirectionLabel
                                | Role::WorkSwitchLabel
                                | Role::PlacementLabel
                                | Role::LinkParameterLabel
                                | Role::TravelSourceLabel
                                | Role::GroundWheelDirectionLabel
                                | Role::Version
                        )
                    })
                    .count()
                    <= MAX_PAGE_INSTRUCTIONS
            );
        }
    }

    #[test]
    fn messages_fit_the_screen() {
        for f in Field::ALL {
            let m = ParamError { field: f, value: 0 }.message();
            assert!(m.is_ascii() && m.len() <= crate::MAX_TEXT_LEN, "{m}");
        }
        for p in MachineProfile::ALL {
            let l = p.label();
            assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
        }
        for r in [false, true] {
            let l = encoder_direction_label(r);
            assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
            let l = work_switch_label(r);
            assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
            let l = placement_label(r);
            assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
        }
        let m = PROFILE_RESTART_MESSAGE;
        assert!(m.is_ascii() && m.len() <= crate::MAX_TEXT_LEN, "{m}");
        let mut kind = CalibrationKind::SpeedK1;
        let mut source = TravelSource::HallGear;
        for _ in 0..4 {
            let l = kind.label();
            assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
            let l = source.label();
            assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
            kind = kind.next();
            source = source.next();
        }
        // Every status text, every slip and source: within the buffer
        // and the screen's limit.
        for slip in i16::MIN..=i16::MAX {
            for in_use in [
                TravelSourceInUse::HallGear,
                TravelSourceInUse::GroundWheel,
                TravelSourceInUse::HallStandIn,
            ] {
                let s = Status {
                    track_slip_x10: slip,
                    travel_source_in_use: in_use,
                    ..Status::default()
                };
                for t in StatusText::ALL {
                    let mut buf = [0u8; STATUS_TEXT_LEN];
                    let l = t.text(&s, &mut buf);
                    assert!(l.is_ascii() && l.len() <= crate::MAX_TEXT_LEN, "{l}");
                    let l = slip_text(slip, &mut buf);
                    assert!(l.len() <= STATUS_TEXT_LEN, "{l}");
                }
            }
        }
    }

    /// The slip text against the standard library's formatting (the
    /// reference), for every value a slip can take.
    #[test]
    fn the_slip_text_is_the_slip_to_a_tenth_of_a_percent() {
        let mut buf = [0u8; STATUS_TEXT_LEN];
        assert_eq!(slip_text(SLIP_UNKNOWN, &mut buf), "Slip --");
        assert_eq!(slip_text(42, &mut buf), "Slip 4.2 %");
        assert_eq!(slip_text(-5, &mut buf), "Slip -0.5 %");
        assert_eq!(slip_text(0, &mut buf), "Slip 0.0 %");
        assert_eq!(slip_text(i16::MIN + 1, &mut buf), "Slip -3276.7 %");
        for v in (i16::MIN + 1)..=i16::MAX {
            let reference = std::format!(
                "Slip {}{}.{} %",
                if v < 0 { "-" } else { "" },
                v.unsigned_abs() / 10,
                v.unsigned_abs() % 10
            );
            assert_eq!(slip_text(v, &mut buf), reference);
        }
    }

    #[test]
    fn every_field_has_one_input_and_one_apply_button() {
        for f in Field::ALL {
            let inputs: std::vec::Vec<_> = COMPONENTS
                .iter()
                .filter(|c| c.role == Role::Input(f))
                .collect();
            assert_eq!(inputs.len(), 1, "{f:?}");
            let page = inputs.first().unwrap().page;
            assert!(
                Component::on_page(page).any(|c| c.role == Role::Action(Action::Apply(f))),
                "{f:?}"
            );
            // The raw default validates to the command that sets it.
            let raw = f.current(&Settings::default());
            assert!(f.validate(raw).is_ok(), "{f:?}");
        }
    }

    #[test]
    fn profiles_have_their_home_pages() {
        assert_eq!(MachineProfile::default(), MachineProfile::DrumBelt);
        assert_eq!(Page::home(MachineProfile::DrumBelt), Page::Mode);
        assert_eq!(Page::home(MachineProfile::SeedlingBelt), Page::Belt);
        for p in MachineProfile::ALL {
            assert_eq!(p.next().next(), p);
            assert_ne!(p.next(), p);
        }
        // Every page is reachable: a button on another page shows it, or it is
        // a home page, the boot page or the alarm page (shown by the MCU).
        for p in Page::ALL {
            let reachable = matches!(p, Page::Boot | Page::Alarm)
                || MachineProfile::ALL.iter().any(|m| m.home() == p)
                || COMPONENTS.iter().any(|c| {
                    c.page != p
                        && matches!(
                            c.role,
                            Role::Action(Action::ShowPage(q)) if q == p
                        )
                })
                || COMPONENTS.iter().any(|c| {
                    matches!(
                        c.role,
                        Role::Action(Action::SelectMode(m)) if m.page() == p
                    )
                });
            assert!(reachable, "{p:?}");
        }
    }

    #[test]
    fn belt_defaults_match_paper_b_defaults() {
        // kinematics::profile_b::ProfileBSettings::default(): X 0.25 m,
        // B 0.10 m, beta 120 deg, N 2, r 25 mm, h 1 mm, Y 0.02 m/s.
        let b = BeltSettings::default();
        assert_eq!(b.spacing.raw(), 250);
        assert_eq!(b.seedling_pitch.raw(), 100);
        assert_eq!(b.clamp_angle.raw(), 120);
        assert_eq!(b.clamp_count.raw(), 2);
        assert_eq!(b.roller_radius.raw(), 250);
        assert_eq!(b.belt_thickness.raw(), 100);
        assert_eq!(b.speed_threshold.raw(), 20);
        assert_eq!(Settings::default().belt, b);
        assert_eq!(Settings::default().profile, MachineProfile::DrumBelt);
    }
}
