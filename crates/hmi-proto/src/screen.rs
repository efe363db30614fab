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
    /// 6 `settings`: brightness, save settings, firmware version.
    Settings = 6,
}

impl Page {
    /// All pages in id order.
    pub const ALL: [Page; 7] = [
        Self::Boot,
        Self::Mode,
        Self::Fixed,
        Self::Adaptive,
        Self::Calibration,
        Self::Alarm,
        Self::Settings,
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
        }
    }
}

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
}

impl CalibrationKind {
    /// The label shown in `tkind`.
    pub const fn label(self) -> &'static str {
        match self {
            Self::SpeedK1 => "k1 speed sensor",
            Self::SlipK2 => "k2 track slip",
            Self::BeltK3 => "k3 belt slip",
        }
    }

    /// The next kind (k1 → k2 → k3 → k1), for the selector button.
    pub const fn next(self) -> Self {
        match self {
            Self::SpeedK1 => Self::SlipK2,
            Self::SlipK2 => Self::BeltK3,
            Self::BeltK3 => Self::SpeedK1,
        }
    }
}

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
        }
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.message())
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
                <$t>::try_from(raw)
                    .ok()
                    .filter(|v| (Self::MIN..=Self::MAX).contains(v))
                    .map(Self)
                    .ok_or(ParamError { field: $field, value: raw })
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
        Ok(match self {
            Self::MotorCoefficient => Command::SetMotorCoefficient(MotorCoefficient::new(raw)?),
            Self::FixedDrumSpeed => Command::SetFixedDrumSpeed(DrumSpeed::new(raw)?),
            Self::Spacing => Command::SetSpacing(Spacing::new(raw)?),
            Self::CalibrationDistance => {
                Command::CalibrationActualDistance(CalibrationDistance::new(raw)?)
            }
            Self::CalibrationCoefficient => {
                Command::SetCalibrationCoefficient(CalibrationCoefficient::new(raw)?)
            }
            Self::Brightness => Command::SetBrightness(Brightness::new(raw)?),
        })
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
        }
    }
}

/// What a button does when released.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Action {
    /// Navigate (no machine command).
    ShowPage(Page),
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
}

/// The role of a component in the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Role {
    /// A button: "Send Component ID" on Touch Release.
    Action(Action),
    /// An editable number (numeric keyboard); read by `get name.val`.
    Input(Field),
    /// A display-only number written with `name.val=`.
    Status(StatusField),
    /// The gear label, written with `tgear.txt=`.
    GearLabel,
    /// The calibration kind's label, written with `tkind.txt=`.
    CalibrationLabel,
    /// The firmware version, written with `tver.txt=`.
    Version,
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Component {
    /// Page it sits on.
    pub page: Page,
    /// Component id (creation order on the page, the page itself is 0).
    pub id: u8,
    /// Object name (`objname`).
    pub name: &'static str,
    /// Type to create.
    pub kind: Kind,
    /// What it does.
    pub role: Role,
}

impl Component {
    /// The name as an [`ObjName`] (the table's names are checked by a test).
    pub const fn obj(&self) -> ObjName<'static> {
        ObjName::new_unchecked(self.name)
    }

    /// Looks up the component a touch event names.
    pub fn lookup(page: u8, id: u8) -> Option<&'static Component> {
        COMPONENTS
            .iter()
            .find(|c| c.page.id() == page && c.id == id)
    }

    /// The components of one page.
    pub fn on_page(page: Page) -> impl Iterator<Item = &'static Component> {
        COMPONENTS.iter().filter(move |c| c.page == page)
    }

    /// The input component for `field` on `page`.
    pub fn input(page: Page, field: Field) -> Option<&'static Component> {
        Self::on_page(page).find(|c| c.role == Role::Input(field))
    }
}

const fn c(page: Page, id: u8, name: &'static str, kind: Kind, role: Role) -> Component {
    Component {
        page,
        id,
        name,
        kind,
        role,
    }
}

use Action as A;
use Kind as K;
use Page as P;
use Role as R;

/// Every component the MCU knows, by page and id (see `docs/hmi.md`).
pub const COMPONENTS: &[Component] = &[
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
    c(
        P::Fixed,
        1,
        "nspeed",
        K::Xfloat(2),
        R::Input(Field::FixedDrumSpeed),
    ),
    c(
        P::Fixed,
        2,
        "bapply",
        K::Button,
        R::Action(A::Apply(Field::FixedDrumSpeed)),
    ),
    c(P::Fixed, 3, "bstart", K::Button, R::Action(A::Start)),
    c(P::Fixed, 4, "bstop", K::Button, R::Action(A::Stop)),
    c(
        P::Fixed,
        5,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Mode)),
    ),
    c(
        P::Fixed,
        6,
        "xtravel",
        K::Xfloat(2),
        R::Status(StatusField::TravelSpeed),
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
    c(P::Adaptive, 6, "bstart", K::Button, R::Action(A::Start)),
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
    c(
        P::Adaptive,
        13,
        "xdist",
        K::Xfloat(1),
        R::Status(StatusField::Distance),
    ),
    c(P::Adaptive, 14, "tmsg", K::Text, R::Message),
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
    c(
        P::Settings,
        4,
        "bback",
        K::Button,
        R::Action(A::ShowPage(P::Mode)),
    ),
    c(P::Settings, 5, "tver", K::Text, R::Version),
    c(P::Settings, 6, "tmsg", K::Text, R::Message),
];

/// Most instructions one page refresh needs ([`page_instructions`]).
pub const MAX_PAGE_INSTRUCTIONS: usize = 8;

/// The instructions that show the settings on `page`: each input's current
/// value, the gear label and the version text.
pub fn page_instructions(
    page: Page,
    settings: &Settings,
    version: ScreenText<'static>,
) -> heapless::Vec<Instruction<'static>, MAX_PAGE_INSTRUCTIONS> {
    let mut out = heapless::Vec::new();
    for comp in Component::on_page(page) {
        let ins = match comp.role {
            Role::Input(f) => Instruction::SetValue(comp.obj(), f.current(settings)),
            Role::GearLabel => Instruction::SetText(
                comp.obj(),
                ScreenText::new(settings.gear.label()).unwrap_or(version),
            ),
            Role::CalibrationLabel => Instruction::SetText(
                comp.obj(),
                ScreenText::new(settings.calibration_kind.label()).unwrap_or(version),
            ),
            Role::Version => Instruction::SetText(comp.obj(), version),
            _ => continue,
        };
        // Capacity is checked by a test for every page.
        let _ = out.push(ins);
    }
    out
}

/// The instructions that show `status` on `page` (only its status components).
pub fn status_instructions(
    page: Page,
    status: &Status,
) -> heapless::Vec<Instruction<'static>, MAX_PAGE_INSTRUCTIONS> {
    let mut out = heapless::Vec::new();
    for comp in Component::on_page(page) {
        if let Role::Status(f) = comp.role {
            let _ = out.push(Instruction::SetValue(comp.obj(), f.value(status)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    #[test]
    fn table_is_consistent() {
        for (i, a) in COMPONENTS.iter().enumerate() {
            assert!(ObjName::new(a.name).is_ok(), "{}", a.name);
            assert!(a.id >= 1);
            for b in COMPONENTS.get(i + 1..).unwrap() {
                assert!(!(a.page == b.page && a.id == b.id), "{a:?} {b:?}");
                assert!(!(a.page == b.page && a.name == b.name), "{a:?} {b:?}");
            }
            if let Role::Action(Action::Apply(f)) = a.role {
                assert!(Component::input(a.page, f).is_some(), "{a:?}");
            }
        }
        // Ids are 1..=n without gaps on every page (creation order in the editor).
        for p in Page::ALL {
            let n = Component::on_page(p).count();
            for id in 1..=n {
                assert!(Component::lookup(p.id(), u8::try_from(id).unwrap()).is_some());
            }
            assert!(Component::on_page(p).count() <= 16);
            assert!(
                Component::on_page(p)
                    .filter(|c| {
                        matches!(
                            c.role,
                            Role::Input(_)
                                | Role::GearLabel
                                | Role::CalibrationLabel
                                | Role::Version
                        )
                    })
                    .count()
                    <= MAX_PAGE_INSTRUCTIONS
            );
            assert!(
                Component::on_page(p)
                    .filter(|c| matches!(c.role, Role::Status(_)))
                    .count()
                    <= MAX_PAGE_INSTRUCTIONS
            );
        }
    }

    #[test]
    fn messages_fit_the_screen() {
        let fields = [
            Field::MotorCoefficient,
            Field::FixedDrumSpeed,
            Field::Spacing,
            Field::CalibrationDistance,
            Field::CalibrationCoefficient,
            Field::Brightness,
        ];
        for f in fields {
            let m = ParamError { field: f, value: 0 }.message();
            assert!(m.is_ascii() && m.len() <= crate::MAX_TEXT_LEN, "{m}");
        }
    }
}
