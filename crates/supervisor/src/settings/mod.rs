//! The persisted settings and their versioned byte format.
//!
//! [`Settings::encode`] produces exactly [`SETTINGS_BYTES`] bytes; every
//! multi-byte number is little endian. Format version 7. [`decode`] still
//! reads the older formats: version 6 is version 7 without its last 6 bytes
//! (written before machine A's ground wheel; read with the Hall gear as the
//! travel source and the nominal wheel), version 5 has the drive link block's first 31
//! bytes only (written before the link's timing settings and the generic
//! profile's command scale and optional registers; read with the default
//! timing and a generic profile that does what it did: the command in the
//! feedback's scale, no control word, mode, offline-time, resolution or
//! maximum-speed register), version 4 is version 5 without its last 31
//! bytes (written before the drum driver's link; read with encoder
//! feedback, PWM command and no driver, the behaviour then), version 3 is version 4 without its last 2 bytes
//! and knows flag bit 0 only (written before the placement setting and the
//! work switch; read as [`Placement::DistanceLocked`], with no work switch
//! fitted and [`FirstPlantDistance::DEFAULT`]), version 2 is version 3 without its last 7 bytes
//! (written before the drum encoder direction and the drive model existed;
//! read with the encoder not reversed and [`DriveModel::DEFAULT`]), version 1
//! is version 2 without its last 34 bytes (written before profile B existed;
//! read as profile A with profile B's defaults):
//!
//! | offset | size | field | encoding |
//! |---|---|---|---|
//! | 0 | 1 | format version | [`SETTINGS_FORMAT_VERSION`] = 7 |
//! | 1 | 1 | [`Settings::mode`] | 1 = Fixed, 2 = Speed-Adaptive |
//! | 2 | 2 | [`Settings::spacing`] | u16, mm, 30–500 |
//! | 4 | 2 | [`Settings::fixed_drum_speed`] | u16, r/min × 100, 0–4470 |
//! | 6 | 2 | [`Settings::motor_coefficient`] | u16, × 100, 50–200 |
//! | 8 | 1 | [`Settings::gear`] | screen wire index 1–6 (Low 1 … High 3) |
//! | 9 | 1 | [`Settings::brightness`] | u8, %, 10–100 |
//! | 10 | 199 | [`Settings::calibration`] | [`Calibration::to_bytes`] (its own version byte, then k1, k2, k3 tables padded to 66 bytes each) |
//! | 209 | 1 | [`Settings::profile`] | 1 = A (drum belt), 2 = B (seedling belt) |
//! | 210 | 33 | [`Settings::belt`] | [`ProfileBConfig::to_bytes`] |
//! | 243 | 1 | flags | bit 0: [`Settings::drum_encoder_reversed`]; bit 1 (format 4): [`Settings::placement`] is [`Placement::SpeedFollowing`]; bit 2 (format 4): [`Settings::work_switch_fitted`]; bits 3–7 zero |
//! | 244 | 6 | [`Settings::drive`] | [`DriveModel::to_bytes`]: `n_max` r/min × 100, τ and dead time in 0.1 ms, u16 each |
//! | 250 | 2 | [`Settings::first_plant_distance`] | u16, mm, 0–1000 ([`FirstPlantDistance`], default 100) |
//! | 252 | 59 | [`Settings::drive_link`] (format 6; 31 bytes in format 5) | [`DriveLinkSettings::to_bytes`]: feedback, command path, driver kind, slave id, baud (u32), speed register, scale (i32, micro-r/min per count), fault register, six fault masks, speed command register (presence byte + u16); then (format 6) reply timeout, retry gap, offline time (ms, u16 each), command scale (i32), control register and its three values, mode register and value, offline-time, resolution and maximum-speed registers (u16 each, register 0: none) |
//!
//! | 311 | 6 | [`Settings::ground_wheel`] (format 7) | [`GroundWheelSettings::to_bytes`]: travel source (1 Hall gear, 2 ground wheel, 3 both), flags (bit 0: the wheel counts backwards), counts per metre × 1000 (u32) |
//!
//! Total 317 bytes (version 6: 311, version 5: 283, version 4: 252, version 3: 250, version 2: 243, version 1: 209). Neither `0x00` nor `0xFF` is a valid mode or gear byte, so
//! an erased (all `0xFF`) or zeroed buffer never decodes.
//!
//! [`decode`] checks the version first (so a record written by a newer
//! firmware is reported as [`SettingsError::UnsupportedVersion`], not as
//! corruption), then the length, then every field through its validating
//! constructor.
//!
//! ```
//! use supervisor::settings::{decode, Settings, SETTINGS_BYTES};
//! use hmi_proto::screen::Spacing;
//!
//! let mut s = Settings::default();
//! s.spacing = Spacing::new(120).unwrap();
//! let bytes = s.encode();
//! assert_eq!(bytes.len(), SETTINGS_BYTES);
//! // version 7, Speed-Adaptive (2), spacing 120 = 0x0078 LE, drum speed
//! // 2521 = 0x09D9 LE, motor coefficient 100 = 0x0064 LE, gear Low 1 (1),
//! // brightness 100 (0x64).
//! assert_eq!(
//!     bytes[..10],
//!     [7, 2, 0x78, 0x00, 0xD9, 0x09, 0x64, 0x00, 1, 0x64]
//! );
//! assert_eq!(decode(&bytes).unwrap(), s);
//! ```

pub mod belt;
pub mod crc;
pub mod store;
pub mod wheel;

use core::fmt;

use hmi_proto::screen::{
    self, Brightness, DrumSpeed, FirstPlantDistance, MachineProfile, Mode, MotorCoefficient,
    ParamError, Spacing,
};
use kinematics::consts::Gear;
use kinematics::table::TableError;
use kinematics::travel::{Calibration, CALIBRATION_BYTES};

use crate::drive::{DriveModel, DriveModelError, DRIVE_MODEL_BYTES};
use crate::drive_link::{DriveLinkError, DriveLinkSettings, DRIVE_LINK_BYTES, DRIVE_LINK_V5_BYTES};
use crate::planter::{ProfileBConfig, CONFIG_BYTES};
use wheel::{GroundWheelError, GroundWheelSettings, GROUND_WHEEL_BYTES};

/// Version byte (offset 0) of the format [`Settings::encode`] writes.
pub const SETTINGS_FORMAT_VERSION: u8 = 7;

/// Bytes before the calibration block: version, mode, spacing, drum speed,
/// motor coefficient, gear, brightness.
const HEAD_BYTES: usize = 10;

/// Size of a format-1 record: 10 + 199 = 209.
pub const SETTINGS_V1_BYTES: usize = HEAD_BYTES + CALIBRATION_BYTES;

/// Size of a format-2 record: 209 + 1 + 33 = 243.
pub const SETTINGS_V2_BYTES: usize = SETTINGS_V1_BYTES + 1 + CONFIG_BYTES;

/// Size of a format-3 record: 243 + 1 + 6 = 250.
pub const SETTINGS_V3_BYTES: usize = SETTINGS_V2_BYTES + 1 + DRIVE_MODEL_BYTES;

/// Size of a format-4 record: 250 + 2 = 252.
pub const SETTINGS_V4_BYTES: usize = SETTINGS_V3_BYTES + 2;

/// Size of a format-5 record: 252 + 31 = 283.
pub const SETTINGS_V5_BYTES: usize = SETTINGS_V4_BYTES + DRIVE_LINK_V5_BYTES;

/// Size of a format-6 record: 252 + 59 = 311.
pub const SETTINGS_V6_BYTES: usize = SETTINGS_V4_BYTES + DRIVE_LINK_BYTES;

/// Size of an encoded [`Settings`] (format version 7): 311 + 6 = 317.
pub const SETTINGS_BYTES: usize = SETTINGS_V6_BYTES + GROUND_WHEEL_BYTES;

/// Flags byte (offset 243), bit 0: the drum encoder counts backwards.
const FLAG_ENCODER_REVERSED: u8 = 1;
/// Flags byte, bit 1 (format 4): speed-following placement.
const FLAG_SPEED_FOLLOWING: u8 = 2;
/// Flags byte, bit 2 (format 4): a work switch is fitted.
const FLAG_WORK_SWITCH: u8 = 4;

/// How profile A's drum places the plants in Speed-Adaptive mode
/// (docs/placement.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Placement {
    /// Partition `n` leaves at ground distance `origin + n·X`: a phase loop
    /// around the speed loop ([`crate::phase`]). The default.
    #[default]
    DistanceLocked,
    /// The drum's speed follows the travel speed (eq. 7 + the fuzzy PID)
    /// and position errors stay in the row; kept for comparison.
    SpeedFollowing,
}

impl Placement {
    /// The placement the screen's toggle names (`true`: speed-following).
    #[must_use]
    pub const fn from_speed_following(speed_following: bool) -> Self {
        if speed_following {
            Self::SpeedFollowing
        } else {
            Self::DistanceLocked
        }
    }
}

/// Which machine the firmware runs (SPEC §1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Profile {
    /// Profile A: the tracked drum-belt transplanter (paper A).
    DrumBelt,
    /// Profile B: the seedling-belt feeder/planter (paper B).
    SeedlingBelt,
}

impl Default for Profile {
    /// The machine of a first boot (or of defaults after a corrupt store):
    /// profile A.
    fn default() -> Self {
        Self::DrumBelt
    }
}

/// Everything the firmware persists: the operator's choices and the
/// calibration tables.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings {
    /// Operating mode. Default: Speed-Adaptive.
    pub mode: Mode,
    /// Plant spacing, mm. Default: 70 ([`Spacing::DEFAULT`]).
    pub spacing: Spacing,
    /// Fixed-mode drum speed, r/min × 100. Default: 2521 ([`DrumSpeed::DEFAULT`]).
    pub fixed_drum_speed: DrumSpeed,
    /// Transplanting-motor coefficient × 100. Default: 100 ([`MotorCoefficient::DEFAULT`]).
    pub motor_coefficient: MotorCoefficient,
    /// Selected gear. Default: Low 1, the screen's own default
    /// ([`hmi_proto::screen::Gear::default`]) and the slowest, safest gear.
    pub gear: Gear,
    /// Screen brightness, %. Default: 100 ([`Brightness::DEFAULT`]).
    pub brightness: Brightness,
    /// The k1/k2/k3 tables. Default: [`Calibration::paper_defaults`].
    pub calibration: Calibration,
    /// Which machine this is. Default: [`Profile::default`] (profile A,
    /// or B in a build with profile B only).
    pub profile: Profile,
    /// Profile B's parameters. Default: `ProfileBSettings::default()`.
    pub belt: ProfileBConfig,
    /// The drum encoder's A/B channels are swapped (or the motor turns the
    /// other way): the supervisor negates its counts before anything else.
    /// Default: `false`.
    pub drum_encoder_reversed: bool,
    /// The drum drive's model (feed-forward gain, controller's drum model).
    /// Default: [`DriveModel::DEFAULT`], until an identification is saved.
    pub drive: DriveModel,
    /// Distance-locked or speed-following placement (Speed-Adaptive mode).
    /// Default: [`Placement::DistanceLocked`].
    pub placement: Placement,
    /// A work switch is wired to PB11 (docs/firmware.md, "Work switch").
    /// Without one (the default) the unit counts as always down: the machine
    /// plants from Start to Stop as before.
    pub work_switch_fitted: bool,
    /// Where the first plant of a pass lands after the work switch closes.
    /// Default: [`FirstPlantDistance::DEFAULT`].
    pub first_plant_distance: FirstPlantDistance,
    /// The drum driver's RS-485 link (format 5): feedback source, command
    /// path, driver profile. Default: encoder, PWM, no driver (the
    /// behaviour before the link).
    pub drive_link: DriveLinkSettings,
    /// Machine A's travel source and ground wheel (format 7). Default: the
    /// Hall gear, the nominal wheel.
    pub ground_wheel: GroundWheelSettings,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::DEFAULT,
            fixed_drum_speed: DrumSpeed::DEFAULT,
            motor_coefficient: MotorCoefficient::DEFAULT,
            gear: gear_from_screen(screen::Gear::default()),
            brightness: Brightness::DEFAULT,
            calibration: Calibration::paper_defaults(),
            profile: Profile::default(),
            belt: ProfileBConfig::default(),
            drum_encoder_reversed: false,
            drive: DriveModel::DEFAULT,
            placement: Placement::DistanceLocked,
            work_switch_fitted: false,
            first_plant_distance: FirstPlantDistance::DEFAULT,
            drive_link: DriveLinkSettings::default(),
            ground_wheel: GroundWheelSettings::default(),
        }
    }
}

/// Why bytes are not a valid [`Settings`] record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingsError {
    /// The version byte is not one this firmware reads (offset 0).
    UnsupportedVersion(u8),
    /// The buffer is not [`SETTINGS_BYTES`] long (an empty buffer included).
    Length {
        /// [`SETTINGS_BYTES`].
        expected: usize,
        /// The length received.
        found: usize,
    },
    /// Unknown mode byte (offset 1).
    Mode(u8),
    /// Gear byte outside 1–6 (offset 8).
    Gear(u8),
    /// A bounded value out of range (spacing, drum speed, coefficient, brightness).
    Param(ParamError),
    /// The calibration block failed validation.
    Calibration(TableError),
    /// Unknown machine profile byte (offset 209).
    Profile(u8),
    /// Profile B's parameters failed validation.
    Belt,
    /// The flags byte (offset 243) has bits set this firmware does not know.
    Flags(u8),
    /// The drive model (offset 244) failed validation.
    Drive(DriveModelError),
    /// The drive link block (offset 252, format 5 and 6) failed validation.
    DriveLink(DriveLinkError),
    /// The ground-wheel block (offset 311, format 7) failed validation.
    GroundWheel(GroundWheelError),
}

impl fmt::Display for SettingsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnsupportedVersion(v) => write!(f, "unsupported settings version {v}"),
            Self::Length { expected, found } => {
                write!(f, "settings are {found} bytes, expected {expected}")
            }
            Self::Mode(m) => write!(f, "invalid mode byte {m}"),
            Self::Gear(g) => write!(f, "invalid gear index {g}"),
            Self::Param(e) => write!(f, "{e}"),
            Self::Calibration(e) => write!(f, "calibration: {e}"),
            Self::Profile(p) => write!(f, "invalid machine profile byte {p}"),
            Self::Belt => f.write_str("invalid profile B parameters"),
            Self::Flags(b) => write!(f, "invalid flags byte {b}"),
            Self::Drive(e) => write!(f, "{e}"),
            Self::DriveLink(e) => write!(f, "{e}"),
            Self::GroundWheel(e) => write!(f, "{e}"),
        }
    }
}

impl From<ParamError> for SettingsError {
    fn from(e: ParamError) -> Self {
        Self::Param(e)
    }
}

/// The screen's gear (wire index 1–6) as the kinematics gear.
#[must_use]
pub const fn gear_from_screen(g: screen::Gear) -> Gear {
    match g {
        screen::Gear::Low1 => Gear::Low1,
        screen::Gear::Low2 => Gear::Low2,
        screen::Gear::Low3 => Gear::Low3,
        screen::Gear::High1 => Gear::High1,
        screen::Gear::High2 => Gear::High2,
        screen::Gear::High3 => Gear::High3,
    }
}

/// The kinematics gear as the screen's gear (wire index 1–6).
#[must_use]
pub const fn gear_to_screen(g: Gear) -> screen::Gear {
    match g {
        Gear::Low1 => screen::Gear::Low1,
        Gear::Low2 => screen::Gear::Low2,
        Gear::Low3 => screen::Gear::Low3,
        Gear::High1 => screen::Gear::High1,
        Gear::High2 => screen::Gear::High2,
        Gear::High3 => screen::Gear::High3,
    }
}

const fn mode_byte(m: Mode) -> u8 {
    match m {
        Mode::Fixed => 1,
        Mode::SpeedAdaptive => 2,
    }
}

const fn mode_from_byte(b: u8) -> Option<Mode> {
    match b {
        1 => Some(Mode::Fixed),
        2 => Some(Mode::SpeedAdaptive),
        _ => None,
    }
}

impl Settings {
    /// Serialises in format version 7 (layout in the [module docs](self)).
    #[must_use]
    pub fn encode(&self) -> [u8; SETTINGS_BYTES] {
        let mut out = [0u8; SETTINGS_BYTES];
        let (v6, v7) = out.split_at_mut(SETTINGS_V6_BYTES);
        v7.copy_from_slice(&self.ground_wheel.to_bytes());
        let (v4, v5) = v6.split_at_mut(SETTINGS_V4_BYTES);
        v5.copy_from_slice(&self.drive_link.to_bytes());
        let (v3, v4) = v4.split_at_mut(SETTINGS_V3_BYTES);
        v4.copy_from_slice(&self.first_plant_distance.raw().to_le_bytes());
        let (v2, v3) = v3.split_at_mut(SETTINGS_V2_BYTES);
        if let Some((flags, drive)) = v3.split_first_mut() {
            *flags = if self.drum_encoder_reversed {
                FLAG_ENCODER_REVERSED
            } else {
                0
            } | if self.placement == Placement::SpeedFollowing {
                FLAG_SPEED_FOLLOWING
            } else {
                0
            } | if self.work_switch_fitted {
                FLAG_WORK_SWITCH
            } else {
                0
            };
            drive.copy_from_slice(&self.drive.to_bytes());
        }
        let (v1, tail) = v2.split_at_mut(SETTINGS_V1_BYTES);
        if let Some((profile, belt)) = tail.split_first_mut() {
            *profile = match self.profile {
                Profile::DrumBelt => 1,
                Profile::SeedlingBelt => 2,
            };
            belt.copy_from_slice(&self.belt.to_bytes());
        }
        let (head, cal) = v1.split_at_mut(HEAD_BYTES);
        let [s0, s1] = self.spacing.raw().to_le_bytes();
        let [d0, d1] = self.fixed_drum_speed.raw().to_le_bytes();
        let [m0, m1] = self.motor_coefficient.raw().to_le_bytes();
        head.copy_from_slice(&[
            SETTINGS_FORMAT_VERSION,
            mode_byte(self.mode),
            s0,
            s1,
            d0,
            d1,
            m0,
            m1,
            gear_to_screen(self.gear).index(),
            self.brightness.raw(),
        ]);
        cal.copy_from_slice(&self.calibration.to_bytes());
        out
    }
}

/// Parses and validates bytes written by [`Settings::encode`].
pub fn decode(bytes: &[u8]) -> Result<Settings, SettingsError> {
    let mut settings = Settings::default();
    decode_into(bytes, &mut settings)?;
    Ok(settings)
}

/// [`decode`] into `out`, the calibration tables in place: no second
/// `Settings` on the stack (the store decodes in `init`). On an error `out`
/// holds valid values but not the record's:
/// decode into a scratch value.
pub fn decode_into(bytes: &[u8], out: &mut Settings) -> Result<(), SettingsError> {
    decode_into_unchecked_link(bytes, out)?;
    out.drive_link.check().map_err(SettingsError::DriveLink)
}

/// [`decode_into`] but the drive link block is parsed, not checked
/// ([`DriveLinkSettings::check`]): the store checks it once its read
/// buffer is off the stack (on the QEMU board's boot path the two frames
/// come one after the other, not one on top of the other). A record is
/// valid only when both pass.
pub fn decode_into_unchecked_link(bytes: &[u8], out: &mut Settings) -> Result<(), SettingsError> {
    // Every field is written below: this pattern stops compiling when a
    // field is added, until it is decoded here too.
    let Settings {
        mode: _,
        spacing: _,
        fixed_drum_speed: _,
        motor_coefficient: _,
        gear: _,
        brightness: _,
        calibration: _,
        profile: _,
        belt: _,
        drum_encoder_reversed: _,
        drive: _,
        placement: _,
        work_switch_fitted: _,
        first_plant_distance: _,
        drive_link: _,
        ground_wheel: _,
    } = out;
    let length = SettingsError::Length {
        expected: SETTINGS_BYTES,
        found: bytes.len(),
    };
    let (&version, _) = bytes.split_first().ok_or(length)?;
    let expected = match version {
        1 => SETTINGS_V1_BYTES,
        2 => SETTINGS_V2_BYTES,
        3 => SETTINGS_V3_BYTES,
        4 => SETTINGS_V4_BYTES,
        5 => SETTINGS_V5_BYTES,
        6 => SETTINGS_V6_BYTES,
        SETTINGS_FORMAT_VERSION => SETTINGS_BYTES,
        other => return Err(SettingsError::UnsupportedVersion(other)),
    };
    if bytes.len() != expected {
        return Err(SettingsError::Length {
            expected,
            found: bytes.len(),
        });
    }
    let (v6, v7) = bytes.split_at(bytes.len().min(SETTINGS_V6_BYTES));
    let (v4, v5) = v6.split_at(v6.len().min(SETTINGS_V4_BYTES));
    // Parsed here, checked by the caller (`decode_into`, the store).
    let drive_link = if v5.is_empty() {
        DriveLinkSettings::default()
    } else if let Ok(block) = <&[u8; DRIVE_LINK_BYTES]>::try_from(v5) {
        DriveLinkSettings::parse(block).map_err(SettingsError::DriveLink)?
    } else if let Ok(block) = <&[u8; DRIVE_LINK_V5_BYTES]>::try_from(v5) {
        // Format 5: migrated (the timing's defaults, a generic profile as
        // it worked then).
        DriveLinkSettings::parse_v5(block).map_err(SettingsError::DriveLink)?
    } else {
        return Err(length);
    };
    let (v3, v4) = v4.split_at(v4.len().min(SETTINGS_V3_BYTES));
    let first_plant_distance = match v4 {
        [] => FirstPlantDistance::DEFAULT,
        [a, b] => FirstPlantDistance::new(i32::from(u16::from_le_bytes([*a, *b])))?,
        _ => return Err(length),
    };
    let (v2, v3) = v3.split_at(v3.len().min(SETTINGS_V2_BYTES));
    let (v1, tail) = v2.split_at(v2.len().min(SETTINGS_V1_BYTES));
    let tail = if tail.is_empty() { None } else { Some(tail) };
    let (head, cal) = v1.split_at(HEAD_BYTES);
    let Ok::<[u8; HEAD_BYTES], _>([_, mode, s0, s1, d0, d1, m0, m1, gear, brightness]) =
        head.try_into()
    else {
        return Err(length);
    };
    let mode = mode_from_byte(mode).ok_or(SettingsError::Mode(mode))?;
    let spacing = Spacing::new(i32::from(u16::from_le_bytes([s0, s1])))?;
    let fixed_drum_speed = DrumSpeed::new(i32::from(u16::from_le_bytes([d0, d1])))?;
    let motor_coefficient = MotorCoefficient::new(i32::from(u16::from_le_bytes([m0, m1])))?;
    let gear = screen::Gear::from_index(gear)
        .map(gear_from_screen)
        .ok_or(SettingsError::Gear(gear))?;
    let brightness = Brightness::new(i32::from(brightness))?;
    out.calibration
        .read_from(cal)
        .map_err(SettingsError::Calibration)?;
    let (profile, belt) = match tail.and_then(|t| t.split_first()) {
        None => (Profile::DrumBelt, ProfileBConfig::default()),
        Some((&p, belt)) => {
            let profile = match p {
                1 => Profile::DrumBelt,
                2 => Profile::SeedlingBelt,
                other => return Err(SettingsError::Profile(other)),
            };
            let belt: &[u8; CONFIG_BYTES] = belt.try_into().map_err(|_| length)?;
            (
                profile,
                ProfileBConfig::from_bytes(belt).map_err(|_| SettingsError::Belt)?,
            )
        }
    };
    // Bits 1 and 2 are known from format 4 on.
    let known = if v4.is_empty() {
        FLAG_ENCODER_REVERSED
    } else {
        FLAG_ENCODER_REVERSED | FLAG_SPEED_FOLLOWING | FLAG_WORK_SWITCH
    };
    let (drum_encoder_reversed, placement, drive) = match v3.split_first() {
        None => (false, Placement::DistanceLocked, DriveModel::DEFAULT),
        Some((&flags, drive)) => {
            if flags & !known != 0 {
                return Err(SettingsError::Flags(flags));
            }
            let drive: &[u8; DRIVE_MODEL_BYTES] = drive.try_into().map_err(|_| length)?;
            (
                flags & FLAG_ENCODER_REVERSED != 0,
                if flags & FLAG_SPEED_FOLLOWING != 0 {
                    Placement::SpeedFollowing
                } else {
                    Placement::DistanceLocked
                },
                DriveModel::from_bytes(drive).map_err(SettingsError::Drive)?,
            )
        }
    };
    // The last block (format 7), checked after the ones before it.
    let ground_wheel = match <&[u8; GROUND_WHEEL_BYTES]>::try_from(v7) {
        Ok(block) => GroundWheelSettings::from_bytes(block).map_err(SettingsError::GroundWheel)?,
        Err(_) if v7.is_empty() => GroundWheelSettings::default(),
        Err(_) => return Err(length),
    };
    out.mode = mode;
    out.spacing = spacing;
    out.fixed_drum_speed = fixed_drum_speed;
    out.motor_coefficient = motor_coefficient;
    out.gear = gear;
    out.brightness = brightness;
    out.profile = profile;
    out.belt = belt;
    out.drum_encoder_reversed = drum_encoder_reversed;
    out.drive = drive;
    out.placement = placement;
    out.work_switch_fitted = v3
        .first()
        .is_some_and(|&flags| flags & FLAG_WORK_SWITCH != 0);
    out.first_plant_distance = first_plant_distance;
    out.drive_link = drive_link;
    out.ground_wheel = ground_wheel;
    Ok(())
}

/// The screen's profile for ours.
pub const fn screen_profile(p: Profile) -> MachineProfile {
    match p {
        Profile::DrumBelt => MachineProfile::DrumBelt,
        Profile::SeedlingBelt => MachineProfile::SeedlingBelt,
    }
}

/// Ours for the screen's profile.
pub const fn profile_from_screen(p: MachineProfile) -> Profile {
    match p {
        MachineProfile::DrumBelt => Profile::DrumBelt,
        MachineProfile::SeedlingBelt => Profile::SeedlingBelt,
    }
}

#[cfg(test)]
#[allow(clippy::arithmetic_side_effects, clippy::cast_possible_truncation)]
mod tests {
    use super::*;
    use crate::drive_link::{CommandPath, DriverKind, FeedbackSource};
    use drive_link::profile::GenericSettings;
    use hmi_proto::screen::Field;
    use kinematics::profile_b::ProfileBSettings;
    use kinematics::table::{CoeffTable, K_MAX, K_MIN, MAX_POINTS};
    use proptest::prelude::*;
    use std::collections::BTreeSet;
    use std::vec::Vec;

    #[test]
    fn sizes() {
        // kinematics::travel: CALIBRATION_BYTES = 1 + 3 × 66 = 199.
        assert_eq!(CALIBRATION_BYTES, 199);
        assert_eq!(SETTINGS_V1_BYTES, 209);
        // + profile byte + ProfileBConfig::to_bytes (33).
        assert_eq!(SETTINGS_V2_BYTES, 243);
        // + flags byte + DriveModel::to_bytes (3 × u16).
        assert_eq!(SETTINGS_V3_BYTES, 250);
        // + the first-plant distance (u16).
        assert_eq!(SETTINGS_V4_BYTES, 252);
        // + the drive link block of format 5: 4 bytes, baud u32, register
        // u16, scale i32, register u16, 6 masks u16, presence byte,
        // register u16.
        assert_eq!(DRIVE_LINK_V5_BYTES, 4 + 4 + 2 + 4 + 2 + 12 + 1 + 2);
        assert_eq!(SETTINGS_V5_BYTES, 283);
        // Format 6: + 3 timings u16, command scale i32, control register
        // and 3 values u16, mode register and value u16, 3 registers u16.
        assert_eq!(DRIVE_LINK_BYTES, DRIVE_LINK_V5_BYTES + 6 + 4 + 8 + 4 + 6);
        assert_eq!(SETTINGS_V6_BYTES, 311);
        // Format 7: + the ground-wheel block (source, flags, u32).
        assert_eq!(SETTINGS_BYTES, 317);
    }

    #[test]
    fn defaults_are_the_documented_ones() {
        let s = Settings::default();
        assert_eq!(s.mode, Mode::SpeedAdaptive);
        // hmi_proto::screen: Spacing 70 mm, DrumSpeed 2521, MotorCoefficient 100,
        // Brightness 100; the screen's default gear is Low 1.
        assert_eq!(s.spacing.raw(), 70);
        assert_eq!(s.fixed_drum_speed.raw(), 2521);
        assert_eq!(s.motor_coefficient.raw(), 100);
        assert_eq!(s.brightness.raw(), 100);
        assert_eq!(s.gear, Gear::Low1);
        assert_eq!(s.calibration, Calibration::paper_defaults());
    }

    #[test]
    fn encode_layout_byte_by_byte() {
        let s = Settings {
            mode: Mode::Fixed,
            spacing: Spacing::new(500).unwrap(),
            fixed_drum_speed: DrumSpeed::new(4470).unwrap(),
            motor_coefficient: MotorCoefficient::new(200).unwrap(),
            gear: Gear::High3,
            brightness: Brightness::new(10).unwrap(),
            calibration: Calibration::identity(),
            profile: Profile::SeedlingBelt,
            belt: ProfileBConfig::default(),
            drum_encoder_reversed: true,
            drive: DriveModel::new(5811, 875, 600).unwrap(),
            placement: Placement::SpeedFollowing,
            work_switch_fitted: true,
            first_plant_distance: FirstPlantDistance::new(1000).unwrap(),
            drive_link: DriveLinkSettings {
                feedback: FeedbackSource::Both,
                command: CommandPath::Modbus,
                kind: DriverKind::Generic,
                generic: GenericSettings {
                    slave: 17,
                    baud: 9600,
                    speed_feedback: 0x1234,
                    micro_rpm_per_count: -2500,
                    fault_register: 0x0100,
                    fault_masks: [1, 2, 4, 8, 0x10, 0x8000],
                    speed_command: Some(0x0200),
                    command_scale: -25_000,
                    control: None,
                    velocity_mode: Some((0x0300, 2)),
                    offline_register: None,
                    resolution_register: Some(0x0400),
                    max_speed_register: None,
                },
                timing: drive_link::link::LinkTiming {
                    reply_timeout_ms: 50,
                    retry_gap_ms: 10,
                    offline_time_ms: 400,
                },
            },
            ground_wheel: GroundWheelSettings {
                source: screen::TravelSource::Both,
                counts_per_m_x1000: 3_100_000,
                reversed: true,
            },
        };
        let b = s.encode();
        // 500 = 0x01F4, 4470 = 0x1176, 200 = 0x00C8; High 3 is wire index 6.
        assert_eq!(b[..10], [7, 1, 0xF4, 0x01, 0x76, 0x11, 0xC8, 0x00, 6, 10]);
        assert_eq!(b[10..209], Calibration::identity().to_bytes());
        // Profile B (2) and its parameters.
        assert_eq!(b[209], 2);
        assert_eq!(b[210..243], s.belt.to_bytes());
        // Flags: encoder reversed (bit 0), speed-following (bit 1), work
        // switch (bit 2); drive 58.11 r/min = 5811 = 0x16B3, τ 87.5 ms = 875
        // = 0x036B, dead time 60 ms = 600 = 0x0258; first plant 1000 mm =
        // 0x03E8.
        assert_eq!(
            b[243..252],
            [7, 0xB3, 0x16, 0x6B, 0x03, 0x58, 0x02, 0xE8, 0x03]
        );
        // The drive link block: both (2), Modbus (1), generic (2), slave
        // 17; 9600 = 0x2580 (u32); 0x1234; −2500 = 0xFFFFF63C (i32);
        // 0x0100; the masks; command present (1), 0x0200; then (format 6)
        // 50 ms, 10 ms, 400 ms = 0x0190; −25 000 = 0xFFFF9E58; no control
        // register (0) with the ZLAC8015D's values 8, 7, 6 stored; mode
        // register 0x0300 = 2; no offline register; resolution register
        // 0x0400; no maximum-speed register.
        // The ground wheel (format 7): both (3), reversed (bit 0),
        // 3 100 000 = 0x002F4D60.
        assert_eq!(b[311..], [3, 1, 0x60, 0x4D, 0x2F, 0x00]);
        assert_eq!(
            b[252..311],
            [
                2, 1, 2, 17, 0x80, 0x25, 0, 0, 0x34, 0x12, 0x3C, 0xF6, 0xFF, 0xFF, 0x00, 0x01, 1,
                0, 2, 0, 4, 0, 8, 0, 0x10, 0, 0x00, 0x80, 1, 0x00, 0x02, 50, 0, 10, 0, 0x90, 0x01,
                0x58, 0x9E, 0xFF, 0xFF, 0, 0, 8, 0, 7, 0, 6, 0, 0x00, 0x03, 2, 0, 0, 0, 0x00, 0x04,
                0, 0
            ]
        );
        assert_eq!(decode(&b).unwrap(), s);
    }

    #[test]
    fn a_version_2_record_reads_with_the_encoder_forward_and_the_default_drive() {
        // A record written before the encoder direction and the drive model:
        // version 2, the first 243 bytes (profile B and its parameters kept).
        let s = Settings {
            profile: Profile::SeedlingBelt,
            spacing: Spacing::new(150).unwrap(),
            drum_encoder_reversed: true,
            drive: DriveModel::new(3000, 100, 0).unwrap(),
            ..Settings::default()
        };
        let mut v2 = [0u8; SETTINGS_V2_BYTES];
        v2.copy_from_slice(&s.encode()[..SETTINGS_V2_BYTES]);
        v2[0] = 2;
        assert_eq!(
            decode(&v2),
            Ok(Settings {
                drum_encoder_reversed: false,
                drive: DriveModel::DEFAULT,
                ..s.clone()
            })
        );
        // A version-2 record must be 243 bytes long, a version-3 one 250.
        let mut v2_long = [0u8; SETTINGS_V3_BYTES];
        v2_long.copy_from_slice(&s.encode()[..SETTINGS_V3_BYTES]);
        v2_long[0] = 2;
        assert_eq!(
            decode(&v2_long),
            Err(SettingsError::Length {
                expected: 243,
                found: 250
            })
        );
        let mut v3_short = v2;
        v3_short[0] = 3;
        assert_eq!(
            decode(&v3_short),
            Err(SettingsError::Length {
                expected: 250,
                found: 243
            })
        );
    }

    #[test]
    fn a_version_3_record_reads_distance_locked_without_a_work_switch() {
        // A record written before the placement setting and the work switch:
        // version 3, the first 250 bytes; its flags byte knows bit 0 only.
        let s = Settings {
            drum_encoder_reversed: true,
            placement: Placement::SpeedFollowing,
            work_switch_fitted: true,
            first_plant_distance: FirstPlantDistance::new(350).unwrap(),
            ..Settings::default()
        };
        let mut v3 = [0u8; SETTINGS_V3_BYTES];
        v3.copy_from_slice(&s.encode()[..SETTINGS_V3_BYTES]);
        v3[0] = 3;
        // Bits 1 and 2 are unknown in format 3.
        assert_eq!(decode(&v3), Err(SettingsError::Flags(7)));
        v3[243] = 1;
        assert_eq!(
            decode(&v3),
            Ok(Settings {
                placement: Placement::DistanceLocked,
                work_switch_fitted: false,
                first_plant_distance: FirstPlantDistance::DEFAULT,
                ..s.clone()
            })
        );
        // The default placement is distance-locked.
        assert_eq!(Settings::default().placement, Placement::DistanceLocked);
        // A version-4 record is 252 bytes long.
        let mut v4_short = v3;
        v4_short[0] = 4;
        assert_eq!(
            decode(&v4_short),
            Err(SettingsError::Length {
                expected: 252,
                found: 250
            })
        );
    }

    #[test]
    fn a_version_4_record_reads_without_a_drive_link() {
        // A record written before the drive link: version 4, the first 252
        // bytes; read with today's behaviour (encoder, PWM, no driver).
        let s = Settings {
            drive_link: DriveLinkSettings {
                feedback: FeedbackSource::Driver,
                kind: DriverKind::Zlac8015d,
                ..DriveLinkSettings::default()
            },
            ..Settings::default()
        };
        let mut v4 = [0u8; SETTINGS_V4_BYTES];
        v4.copy_from_slice(&s.encode()[..SETTINGS_V4_BYTES]);
        v4[0] = 4;
        assert_eq!(
            decode(&v4),
            Ok(Settings {
                drive_link: DriveLinkSettings::default(),
                ..s.clone()
            })
        );
        // A version-5 record is 283 bytes long.
        let mut v5_short = v4;
        v5_short[0] = 5;
        assert_eq!(
            decode(&v5_short),
            Err(SettingsError::Length {
                expected: 283,
                found: 252
            })
        );
    }

    /// A record of format 5 (before the link's timing and the generic
    /// profile's command scale and optional registers): its first 283
    /// bytes, version 5. It reads with everything as saved, the link's
    /// timing at its defaults, and a generic profile that does what it did
    /// (its command in the feedback's scale, none of the new registers);
    /// saved again it becomes format 6 and reads back the same.
    #[test]
    fn a_version_5_record_reads_with_the_default_timing() {
        let s = Settings {
            drive_link: DriveLinkSettings {
                feedback: FeedbackSource::Driver,
                command: CommandPath::Modbus,
                kind: DriverKind::Generic,
                generic: GenericSettings {
                    micro_rpm_per_count: 1695,
                    speed_command: Some(0x2088),
                    command_scale: 1695,
                    control: None,
                    velocity_mode: None,
                    offline_register: None,
                    resolution_register: None,
                    max_speed_register: None,
                    ..crate::drive_link::GENERIC_DEFAULT
                },
                ..DriveLinkSettings::default()
            },
            spacing: Spacing::new(120).unwrap(),
            ..Settings::default()
        };
        let mut v5 = [0u8; SETTINGS_V5_BYTES];
        v5.copy_from_slice(&s.encode()[..SETTINGS_V5_BYTES]);
        v5[0] = 5;
        let read = decode(&v5).unwrap();
        assert_eq!(read, s);
        assert_eq!(
            read.drive_link.timing,
            drive_link::link::LinkTiming::DEFAULT
        );
        assert_eq!(decode(&read.encode()), Ok(s));
        // A format-5 record whose link block is bad stays refused.
        v5[255] = 0;
        assert!(matches!(decode(&v5), Err(SettingsError::DriveLink(_))));
        // A version-6 record is 311 bytes long.
        v5[0] = 6;
        assert_eq!(
            decode(&v5),
            Err(SettingsError::Length {
                expected: 311,
                found: 283
            })
        );
    }

    #[test]
    fn rejects_a_drive_link_that_cannot_work() {
        // Driver feedback without a driver (byte 252 = 1, kind byte 254 = 0).
        let mut b = Settings::default().encode();
        b[252] = 1;
        let e = decode(&b).unwrap_err();
        assert_eq!(
            e,
            SettingsError::DriveLink(crate::drive_link::DriveLinkError::NoDriver)
        );
        assert_eq!(
            std::format!("{e}"),
            "driver feedback or command needs a driver profile"
        );
        // With the ZLAC8015D behind paper A's 118:1 (the default scale,
        // 847 µr/min per count) its speed register ends at 27.753 r/min:
        // refused; with a 20:1 gearbox (5000, bytes 262–265) it loads;
        // slave id 0 (byte 255) is refused.
        b[254] = 1;
        assert_eq!(
            decode(&b),
            Err(SettingsError::DriveLink(
                crate::drive_link::DriveLinkError::SpeedRange {
                    top_milli_rpm: 27_753
                }
            ))
        );
        b[262..266].copy_from_slice(&5000i32.to_le_bytes());
        assert_eq!(
            decode(&b).map(|s| s.drive_link.feedback),
            Ok(FeedbackSource::Driver)
        );
        b[255] = 0;
        assert_eq!(
            decode(&b),
            Err(SettingsError::DriveLink(
                crate::drive_link::DriveLinkError::Profile(
                    drive_link::profile::ProfileError::SlaveId(0)
                )
            ))
        );
        // An unknown feedback byte.
        let mut c = Settings::default().encode();
        c[252] = 3;
        assert_eq!(
            decode(&c),
            Err(SettingsError::DriveLink(
                crate::drive_link::DriveLinkError::Byte(3)
            ))
        );
    }

    #[test]
    fn rejects_a_first_plant_distance_above_a_metre() {
        let mut b = Settings::default().encode();
        // 1001 = 0x03E9.
        b[250] = 0xE9;
        b[251] = 0x03;
        let e = decode(&b).unwrap_err();
        assert_eq!(
            e,
            SettingsError::Param(ParamError {
                field: Field::FirstPlantDistance,
                value: 1001
            })
        );
        assert_eq!(std::format!("{e}"), "First plant must be 0.0-100.0 cm");
        b[250] = 0xE8;
        assert_eq!(decode(&b).map(|s| s.first_plant_distance.raw()), Ok(1000));
    }

    #[test]
    fn rejects_unknown_flags_and_a_bad_drive_model() {
        let good = Settings::default().encode();
        let with = |i: usize, v: u8| {
            let mut b = good;
            b[i] = v;
            decode(&b)
        };
        assert_eq!(with(243, 8), Err(SettingsError::Flags(8)));
        assert!(with(243, 4).unwrap().work_switch_fitted);
        assert_eq!(with(243, 0xFF), Err(SettingsError::Flags(0xFF)));
        assert!(with(243, 1).unwrap().drum_encoder_reversed);
        assert_eq!(with(243, 2).unwrap().placement, Placement::SpeedFollowing);
        assert_eq!(with(243, 0).unwrap().placement, Placement::DistanceLocked);
        // n_max 0x1100 + low byte: 4352 + 0xFF… → 0xFF_xx > 9000.
        assert_eq!(
            with(245, 0xFF),
            Err(SettingsError::Drive(DriveModelError::NMax(
                u16::from_le_bytes([good[244], 0xFF])
            )))
        );
        // τ 0 < 1 ms.
        let mut b = good;
        b[246] = 0;
        b[247] = 0;
        assert_eq!(
            decode(&b),
            Err(SettingsError::Drive(DriveModelError::Tau(0)))
        );
        // Dead time 0xFFFF > 200 ms.
        let mut b = good;
        b[248] = 0xFF;
        b[249] = 0xFF;
        assert_eq!(
            decode(&b),
            Err(SettingsError::Drive(DriveModelError::DeadTime(0xFFFF)))
        );
    }

    #[test]
    fn a_version_1_record_reads_as_profile_a_with_profile_b_defaults() {
        // A record written before profile B: version 1, the first 209 bytes.
        let mut v1 = [0u8; SETTINGS_V1_BYTES];
        let v2 = Settings::default().encode();
        v1.copy_from_slice(&v2[..SETTINGS_V1_BYTES]);
        v1[0] = 1;
        let s = decode(&v1).unwrap();
        assert_eq!(s.profile, Profile::DrumBelt);
        assert_eq!(s.belt, ProfileBConfig::default());
        assert_eq!(
            s,
            Settings {
                profile: Profile::DrumBelt,
                ..Settings::default()
            }
        );
        // And the default profile B parameters are the validated defaults.
        assert_eq!(
            ProfileBConfig::new(kinematics::profile_b::ProfileBSettings::default()),
            Ok(ProfileBConfig::default())
        );
    }

    #[test]
    fn rejects_every_bad_field() {
        let good = Settings::default().encode();
        let with = |i: usize, v: u8| {
            let mut b = good;
            b[i] = v;
            decode(&b)
        };
        assert_eq!(with(0, 8), Err(SettingsError::UnsupportedVersion(8)));
        assert_eq!(
            with(311, 0),
            Err(SettingsError::GroundWheel(GroundWheelError::Source(0)))
        );
        assert_eq!(
            with(312, 2),
            Err(SettingsError::GroundWheel(GroundWheelError::Flags(2)))
        );
        assert_eq!(
            with(316, 0xFF),
            Err(SettingsError::GroundWheel(
                GroundWheelError::CountsPerMetre(0xFF2E_A09F)
            ))
        );
        assert_eq!(with(0, 0xFF), Err(SettingsError::UnsupportedVersion(0xFF)));
        assert_eq!(with(1, 0), Err(SettingsError::Mode(0)));
        assert_eq!(with(1, 3), Err(SettingsError::Mode(3)));
        // Spacing 29 < 30 mm.
        assert_eq!(
            with(2, 29),
            Err(SettingsError::Param(ParamError {
                field: Field::Spacing,
                value: 29
            }))
        );
        // Drum speed 0xFF_D9 = 65497 > 4470.
        assert!(
            matches!(with(5, 0xFF), Err(SettingsError::Param(p)) if p.field == Field::FixedDrumSpeed)
        );
        // Motor coefficient 49 < 50.
        assert!(
            matches!(with(6, 49), Err(SettingsError::Param(p)) if p.field == Field::MotorCoefficient)
        );
        assert_eq!(with(8, 0), Err(SettingsError::Gear(0)));
        assert_eq!(with(8, 7), Err(SettingsError::Gear(7)));
        // Brightness 9 < 10 %.
        assert!(matches!(with(9, 9), Err(SettingsError::Param(p)) if p.field == Field::Brightness));
        // Calibration version byte.
        assert_eq!(
            with(10, 9),
            Err(SettingsError::Calibration(TableError::BadVersion))
        );
        // k1 table point count 0.
        assert_eq!(
            with(12, 0),
            Err(SettingsError::Calibration(TableError::Empty))
        );
    }

    #[test]
    fn rejects_lengths_and_blank() {
        let good = Settings::default().encode();
        assert_eq!(
            decode(&[]),
            Err(SettingsError::Length {
                expected: 317,
                found: 0
            })
        );
        assert_eq!(
            decode(&good[..316]),
            Err(SettingsError::Length {
                expected: 317,
                found: 316
            })
        );
        let mut long = [0u8; 318];
        long[..317].copy_from_slice(&good);
        assert!(matches!(decode(&long), Err(SettingsError::Length { .. })));
        // A version-1 record must be 209 bytes long.
        let mut v1_short = good;
        v1_short[0] = 1;
        assert_eq!(
            decode(&v1_short),
            Err(SettingsError::Length {
                expected: 209,
                found: 317
            })
        );
        assert_eq!(
            decode(&[0xFF; SETTINGS_BYTES]),
            Err(SettingsError::UnsupportedVersion(0xFF))
        );
        let mut zero = [0u8; SETTINGS_BYTES];
        zero[0] = SETTINGS_FORMAT_VERSION;
        assert_eq!(decode(&zero), Err(SettingsError::Mode(0)));
        // An unknown profile byte.
        let mut bad = good;
        bad[209] = 3;
        assert_eq!(decode(&bad), Err(SettingsError::Profile(3)));
    }

    #[test]
    fn gear_mapping_round_trips_and_keeps_order() {
        for (i, g) in hmi_proto::screen::Gear::ALL.iter().enumerate() {
            let k = gear_from_screen(*g);
            assert_eq!(k, Gear::ALL[i]);
            assert_eq!(gear_to_screen(k), *g);
        }
    }

    #[test]
    fn errors_display() {
        let e = SettingsError::UnsupportedVersion(7);
        assert_eq!(std::format!("{e}"), "unsupported settings version 7");
        let e = SettingsError::Calibration(TableError::Empty);
        assert_eq!(std::format!("{e}"), "calibration: table has no points");
    }

    /// A random valid table, built from its serialised form.
    fn table() -> impl Strategy<Value = CoeffTable> {
        (
            proptest::collection::btree_set(any::<u32>(), 1..=MAX_POINTS),
            proptest::collection::vec(K_MIN.to_bits()..=K_MAX.to_bits(), MAX_POINTS),
        )
            .prop_map(|(xs, ks): (BTreeSet<u32>, Vec<u32>)| {
                let mut b = std::vec![1u8, xs.len() as u8];
                for (x, k) in xs.iter().zip(ks.iter()) {
                    b.extend_from_slice(&x.to_le_bytes());
                    b.extend_from_slice(&k.to_le_bytes());
                }
                CoeffTable::from_bytes(&b).unwrap().0
            })
    }

    /// A random valid [`Settings`].
    fn settings() -> impl Strategy<Value = Settings> {
        (
            any::<bool>(),
            Spacing::MIN..=Spacing::MAX,
            DrumSpeed::MIN..=DrumSpeed::MAX,
            MotorCoefficient::MIN..=MotorCoefficient::MAX,
            0usize..6,
            Brightness::MIN..=Brightness::MAX,
            (table(), table(), table()),
            (any::<bool>(), 110u32..=990),
            (
                (any::<bool>(), any::<bool>()),
                DriveModel::N_MAX_RANGE,
                DriveModel::TAU_RANGE,
                0..=DriveModel::DEAD_TIME_MAX,
            ),
            (
                any::<bool>(),
                FirstPlantDistance::MIN..=FirstPlantDistance::MAX,
            ),
        )
            .prop_map(
                |(
                    fixed,
                    sp,
                    ds,
                    mc,
                    g,
                    br,
                    (k1, k2, k3),
                    (b, x_mm),
                    ((rev, sf), n, tau, dead),
                    (work, first),
                )| {
                    Settings {
                        mode: if fixed {
                            Mode::Fixed
                        } else {
                            Mode::SpeedAdaptive
                        },
                        spacing: Spacing::new(i32::from(sp)).unwrap(),
                        fixed_drum_speed: DrumSpeed::new(i32::from(ds)).unwrap(),
                        motor_coefficient: MotorCoefficient::new(i32::from(mc)).unwrap(),
                        gear: Gear::ALL[g],
                        brightness: Brightness::new(i32::from(br)).unwrap(),
                        calibration: Calibration { k1, k2, k3 },
                        profile: if b {
                            Profile::SeedlingBelt
                        } else {
                            Profile::DrumBelt
                        },
                        belt: ProfileBConfig::new(ProfileBSettings {
                            plant_spacing: kinematics::units::Metres::from_mm(x_mm),
                            ..ProfileBSettings::default()
                        })
                        .unwrap(),
                        drum_encoder_reversed: rev,
                        drive: DriveModel::new(n, tau, dead).unwrap(),
                        placement: if sf {
                            Placement::SpeedFollowing
                        } else {
                            Placement::DistanceLocked
                        },
                        work_switch_fitted: work,
                        first_plant_distance: FirstPlantDistance::new(i32::from(first)).unwrap(),
                        drive_link: if work {
                            DriveLinkSettings {
                                feedback: FeedbackSource::Driver,
                                kind: DriverKind::Zlac8015d,
                                generic: drive_link::profile::GenericSettings {
                                    micro_rpm_per_count: 5000,
                                    ..crate::drive_link::GENERIC_DEFAULT
                                },
                                ..DriveLinkSettings::default()
                            }
                        } else {
                            DriveLinkSettings::default()
                        },
                        ground_wheel: GroundWheelSettings {
                            source: if rev {
                                screen::TravelSource::Both
                            } else if sf {
                                screen::TravelSource::GroundWheel
                            } else {
                                screen::TravelSource::HallGear
                            },
                            counts_per_m_x1000: 100_000 + u32::from(sp) * 1000,
                            reversed: work,
                        },
                    }
                },
            )
    }

    proptest! {
        #[test]
        fn encode_decode_round_trip(s in settings()) {
            let b = s.encode();
            prop_assert_eq!(b[0], SETTINGS_FORMAT_VERSION);
            prop_assert_eq!(decode(&b), Ok(s));
        }

        #[test]
        fn decode_arbitrary_bytes_never_panics(b in proptest::collection::vec(any::<u8>(), 0..262)) {
            let _ = decode(&b);
        }

        #[test]
        fn decode_mutated_record_never_panics_and_revalidates(
            s in settings(),
            at in 0usize..SETTINGS_BYTES,
            v in any::<u8>(),
        ) {
            let mut b = s.encode();
            b[at] = v;
            // Whatever decodes must re-encode to a record that decodes to itself.
            if let Ok(d) = decode(&b) {
                prop_assert_eq!(decode(&d.encode()), Ok(d));
            }
        }
    }
}
