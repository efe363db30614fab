//! Driver profiles as data: which registers hold what, in which units.
//!
//! A profile names the registers the master reads and writes, their
//! scalings and the fault bits. [`ZLAC8015D`] is shipped (its left-motor
//! registers); any other driver that speaks Modbus RTU with function 03/06
//! is described by a [`GenericSettings`], validated by
//! [`GenericSettings::build`] like every other setting.
//!
//! Units: speeds in milli-r/min of the **drum** (the driver reports its
//! motor; `micro_rpm_per_count` folds the gearbox in), signed. The scale is
//! in micro-r/min of the drum per count so that a gearbox is represented:
//! paper A's 118:1 gearbox behind a driver counting 0.1 r/min of its motor
//! is 100 000 / 118 = 847 µr/min per count (0.05 % rounding).
//!
//! ```
//! use drive_link::profile::{DriverFault, ZLAC8015D};
//! // The ZLAC8015D reports 0.1 r/min per count: 123 counts = 12.3 r/min.
//! assert_eq!(ZLAC8015D.speed_from_register(123), 12_300);
//! // −50 counts (0xFFCE) = −5.0 r/min.
//! assert_eq!(ZLAC8015D.speed_from_register(0xFFCE), -5_000);
//! // Fault word 0x0004 = over-current.
//! assert_eq!(ZLAC8015D.faults(0x0004).next(), Some(DriverFault::OverCurrent));
//! ```

use core::fmt;

use crate::timing::BAUD_RATES;

/// A fault the driver reports, by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriverFault {
    /// Motor current over the limit.
    OverCurrent,
    /// Supply voltage too high.
    OverVoltage,
    /// Supply voltage too low.
    UnderVoltage,
    /// Overload (current above rated for too long).
    Overload,
    /// The motor's Hall sensors or encoder failed.
    HallOrEncoder,
    /// Motor or driver too hot.
    OverTemperature,
    /// Fault bits the profile has no name for (the raw bits).
    Other(u16),
}

impl fmt::Display for DriverFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OverCurrent => f.write_str("driver over-current"),
            Self::OverVoltage => f.write_str("driver over-voltage"),
            Self::UnderVoltage => f.write_str("driver under-voltage"),
            Self::Overload => f.write_str("driver overload"),
            Self::HallOrEncoder => f.write_str("driver Hall/encoder fault"),
            Self::OverTemperature => f.write_str("driver over-temperature"),
            Self::Other(bits) => write!(f, "driver fault 0x{bits:04X}"),
        }
    }
}

/// The named faults, in the order the masks are given.
pub const NAMED_FAULTS: [DriverFault; 6] = [
    DriverFault::OverCurrent,
    DriverFault::OverVoltage,
    DriverFault::UnderVoltage,
    DriverFault::Overload,
    DriverFault::HallOrEncoder,
    DriverFault::OverTemperature,
];

/// Control-word commands (the driver's enable through its register, beside
/// the enable pin).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlWord {
    /// The register.
    pub address: u16,
    /// Value that enables the motor.
    pub enable: u16,
    /// Value that disables it (free-wheel).
    pub disable: u16,
    /// Value that clears a latched alarm.
    pub clear_alarm: u16,
}

/// A driver's registers and scalings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriverProfile {
    /// Modbus slave id, 1–247.
    pub slave: u8,
    /// Line speed, one of [`BAUD_RATES`].
    pub baud: u32,
    /// Holding register with the actual speed (signed 16 bit).
    pub speed_feedback: u16,
    /// Drum micro-r/min per count of the speed feedback register (signed:
    /// a negative scale reverses the direction).
    pub micro_rpm_per_count: i32,
    /// Holding register with the fault bits.
    pub fault_register: u16,
    /// Masks of [`NAMED_FAULTS`] in the fault register (0: not reported).
    pub fault_masks: [u16; 6],
    /// The control word, when the driver has one.
    pub control: Option<ControlWord>,
    /// Register and value that select velocity mode, written at start-up.
    pub velocity_mode: Option<(u16, u16)>,
    /// Holding register of the speed command and its scale (drum
    /// micro-r/min per count at a speed resolution of 1), when the driver
    /// takes speed commands.
    pub speed_command: Option<(u16, i32)>,
    /// The driver's communication-loss ("offline") time register, written
    /// at start-up with the link's offline time in ms
    /// ([`crate::link::LinkTiming::offline_time_ms`]).
    pub offline_register: Option<u16>,
    /// The driver's speed-resolution register, read at start-up: the
    /// command register counts 1/n of the command scale's unit when it
    /// holds n (1–10; the ZLAC8015D's 0x2022: 1 = 1 r/min, 10 = 0.1 r/min).
    /// The speed feedback does not follow it.
    pub resolution_register: Option<u16>,
    /// The driver's maximum-speed register, read at start-up, in counts of
    /// the speed command at a resolution of 1 (the ZLAC8015D's 0x2008,
    /// r/min of its motor, 1–1000): the drum's top speed must fit under it,
    /// or the link refuses the driver (a command above it would be
    /// silently limited).
    pub max_speed_register: Option<u16>,
}

/// The ZLAC8015D (ZLTECH dual-channel BLDC driver), left motor, slave 1 at
/// 115 200 baud, from ZLTECH's *RS485 Communication Instruction* V1.06:
/// control word 0x200E (0x08 enable, 0x07 stop, 0x06 clear alarm), mode
/// 0x200D = 3 (velocity), target speed 0x2088 in r/min divided by the
/// given-speed resolution 0x2022 (1: 1 r/min, 10: 0.1 r/min), actual speed
/// 0x20AB in 0.1 r/min whatever 0x2022 holds, maximum motor speed 0x2008
/// (1–1000 r/min: a target above it is limited to it), offline time 0x2000
/// (ms), fault bits 0x20A5 (over-voltage 0x0001, under-voltage 0x0002,
/// over-current 0x0004, overload 0x0008, encoder out of tolerance 0x0020,
/// Hall error 0x0200, encoder error 0x0800 — these three are one name —
/// motor over-temperature 0x0400). The drum is taken as driven 1:1 by the
/// motor: the supervisor's ZLAC8015D kind puts the gearbox in the scales.
pub const ZLAC8015D: DriverProfile = DriverProfile {
    slave: 1,
    baud: 115_200,
    speed_feedback: 0x20AB,
    micro_rpm_per_count: 100_000,
    fault_register: 0x20A5,
    fault_masks: [0x0004, 0x0001, 0x0002, 0x0008, 0x0A20, 0x0400],
    control: Some(ControlWord {
        address: 0x200E,
        enable: 0x08,
        disable: 0x07,
        clear_alarm: 0x06,
    }),
    velocity_mode: Some((0x200D, 3)),
    speed_command: Some((0x2088, 1_000_000)),
    offline_register: Some(0x2000),
    resolution_register: Some(0x2022),
    max_speed_register: Some(0x2008),
};

/// The highest speed resolution the link takes from a resolution register
/// (the ZLAC8015D's 0x2022 holds 1–10).
pub const MAX_RESOLUTION: u16 = 10;

impl DriverProfile {
    /// Drum speed in milli-r/min from a speed register's raw value.
    #[must_use]
    pub fn speed_from_register(&self, raw: u16) -> i32 {
        let counts = i64::from(i16::from_ne_bytes(raw.to_ne_bytes()));
        // |counts| ≤ 32 768 and |scale| ≤ MAX_SCALE: no overflow in i64;
        // µ → milli rounded half away from zero.
        let micro = counts.saturating_mul(i64::from(self.micro_rpm_per_count));
        let half = if micro < 0 { -500 } else { 500 };
        let milli = micro.saturating_add(half) / 1000;
        // Beyond ±2 147 483 r/min (a scale near MAX_SCALE): the limit of
        // the sign, never 0 (a drum read as still would be driven harder).
        i32::try_from(milli).unwrap_or(if milli < 0 { i32::MIN } else { i32::MAX })
    }

    /// The speed command register's value for a drum speed at a speed
    /// resolution of 1 ([`DriverProfile::command_counts_at`]).
    #[must_use]
    pub fn command_counts(&self, drum_milli_rpm: i32) -> Option<u16> {
        self.command_counts_at(drum_milli_rpm, 1)
    }

    /// The speed command register's value for a drum speed when the
    /// driver's resolution register holds `resolution` (the register then
    /// counts 1/`resolution` of the scale's unit), rounded to the nearest
    /// count and limited to the register's range. `None` when the driver
    /// takes no speed command.
    #[must_use]
    pub fn command_counts_at(&self, drum_milli_rpm: i32, resolution: u16) -> Option<u16> {
        let (_, scale) = self.speed_command?;
        let scale = i64::from(scale);
        if scale == 0 {
            return Some(0);
        }
        let num = i64::from(drum_milli_rpm)
            .saturating_mul(1000)
            .saturating_mul(i64::from(resolution.max(1)));
        // Round half away from zero, on magnitudes (|num| < 2^45, |scale| ≤ 2^31).
        let magnitude = num
            .unsigned_abs()
            .saturating_add(scale.unsigned_abs() / 2)
            .checked_div(scale.unsigned_abs())
            .unwrap_or(0);
        let magnitude = i64::try_from(magnitude).unwrap_or(i64::MAX);
        let counts = if (num < 0) == (scale < 0) {
            magnitude
        } else {
            magnitude.saturating_neg()
        };
        let clamped = counts.clamp(i64::from(i16::MIN), i64::from(i16::MAX));
        let small = i16::try_from(clamped).unwrap_or(0);
        Some(u16::from_ne_bytes(small.to_ne_bytes()))
    }

    /// The command counts (at a resolution of 1, rounded up, magnitude) a
    /// drum speed needs: what the driver's maximum-speed register must
    /// allow. `None` without a speed command.
    #[must_use]
    pub fn command_counts_needed(&self, drum_milli_rpm: u32) -> Option<u32> {
        let (_, scale) = self.speed_command?;
        // In u32 (no 64-bit division on the boot path): a drum top speed
        // beyond 4294 r/min saturates, and needs the most anyway.
        Some(
            drum_milli_rpm
                .saturating_mul(1000)
                .div_ceil(scale.unsigned_abs().max(1)),
        )
    }

    /// The named faults in a fault word, then the unnamed bits as one
    /// [`DriverFault::Other`].
    pub fn faults(&self, word: u16) -> impl Iterator<Item = DriverFault> + '_ {
        faults_in(&self.fault_masks, word)
    }
}

/// The named faults of a fault word under `masks` ([`NAMED_FAULTS`]'
/// order), then the unnamed bits as one [`DriverFault::Other`].
pub fn faults_in(masks: &[u16; 6], word: u16) -> impl Iterator<Item = DriverFault> + '_ {
    let named = masks.iter().fold(0u16, |acc, m| acc | m);
    let other = word & !named;
    NAMED_FAULTS
        .iter()
        .zip(masks.iter())
        .filter(move |(_, &mask)| mask != 0 && word & mask != 0)
        .map(|(&f, _)| f)
        .chain((other != 0).then_some(DriverFault::Other(other)))
}

/// The first fault of a nonzero fault word under `masks` (what an alarm
/// names).
#[must_use]
pub fn first_fault(masks: &[u16; 6], word: u16) -> DriverFault {
    faults_in(masks, word)
        .next()
        .unwrap_or(DriverFault::Other(word))
}

/// The largest |scale| a generic profile may name: 100 r/min per count
/// (in micro-r/min).
pub const MAX_SCALE: i32 = 100_000_000;

/// A generic driver, as the operator enters it on the screen.
///
/// It describes any driver that speaks Modbus RTU with functions 03 and
/// 06, a ZLAC8015D behind a gearbox included: the feedback and the command
/// have scales of their own (the ZLAC8015D reports 0.1 r/min and takes
/// whole r/min), and the control word, the mode write, the offline time,
/// the speed resolution and the maximum speed are optional registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GenericSettings {
    /// Slave id, 1–247.
    pub slave: u8,
    /// Baud rate, one of [`BAUD_RATES`].
    pub baud: u32,
    /// Speed feedback register.
    pub speed_feedback: u16,
    /// Drum micro-r/min per count of the feedback, nonzero, |scale| ≤
    /// [`MAX_SCALE`].
    pub micro_rpm_per_count: i32,
    /// Fault register.
    pub fault_register: u16,
    /// Masks of the named faults (pairwise disjoint).
    pub fault_masks: [u16; 6],
    /// Speed command register, if the driver takes one.
    pub speed_command: Option<u16>,
    /// Drum micro-r/min per count of the speed command at a speed
    /// resolution of 1, nonzero, |scale| ≤ [`MAX_SCALE`] (checked when
    /// there is a command register).
    pub command_scale: i32,
    /// The control word (enable, disable, clear alarm), if any.
    pub control: Option<ControlWord>,
    /// Register and value that select velocity mode, written at start-up.
    pub velocity_mode: Option<(u16, u16)>,
    /// The offline-time register ([`DriverProfile::offline_register`]).
    pub offline_register: Option<u16>,
    /// The speed-resolution register ([`DriverProfile::resolution_register`]).
    pub resolution_register: Option<u16>,
    /// The maximum-speed register ([`DriverProfile::max_speed_register`]).
    pub max_speed_register: Option<u16>,
}

/// Why a generic profile was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ProfileError {
    /// Slave id outside 1–247.
    SlaveId(u8),
    /// Baud rate not one of [`BAUD_RATES`].
    Baud(u32),
    /// Scale 0 or beyond ±[`MAX_SCALE`].
    Scale(i32),
    /// The command scale 0 or beyond ±[`MAX_SCALE`].
    CommandScale(i32),
    /// Two named faults share a bit.
    FaultMasksOverlap,
    /// Two of the registers the profile names are the same register.
    RegisterClash,
    /// Two of the control word's values (enable, disable, clear) are the
    /// same.
    ControlValues,
}

impl fmt::Display for ProfileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::SlaveId(id) => write!(f, "slave id {id} outside 1..247"),
            Self::Baud(b) => write!(f, "baud {b} not 9600/19200/38400/57600/115200"),
            Self::Scale(s) => write!(
                f,
                "speed scale {s} micro-r/min per count (0 or beyond 100 r/min)"
            ),
            Self::CommandScale(s) => write!(
                f,
                "command scale {s} micro-r/min per count (0 or beyond 100 r/min)"
            ),
            Self::FaultMasksOverlap => f.write_str("two fault names share a bit"),
            Self::RegisterClash => f.write_str("the profile's registers must differ"),
            Self::ControlValues => f.write_str("enable, disable and clear values must differ"),
        }
    }
}

/// The checks every profile's line settings pass: slave id 1–247, a baud
/// rate of [`BAUD_RATES`], a nonzero feedback scale within ±[`MAX_SCALE`].
pub fn check_line(slave: u8, baud: u32, micro_rpm_per_count: i32) -> Result<(), ProfileError> {
    if !(1..=247).contains(&slave) {
        return Err(ProfileError::SlaveId(slave));
    }
    if !BAUD_RATES.contains(&baud) {
        return Err(ProfileError::Baud(baud));
    }
    if !scale_ok(micro_rpm_per_count) {
        return Err(ProfileError::Scale(micro_rpm_per_count));
    }
    Ok(())
}

fn scale_ok(s: i32) -> bool {
    s != 0 && s.unsigned_abs() <= MAX_SCALE.unsigned_abs()
}

impl GenericSettings {
    /// Validates the settings into a profile.
    pub fn build(&self) -> Result<DriverProfile, ProfileError> {
        let s = self.micro_rpm_per_count;
        check_line(self.slave, self.baud, s)?;
        if self.speed_command.is_some() && !scale_ok(self.command_scale) {
            return Err(ProfileError::CommandScale(self.command_scale));
        }
        let mut seen = 0u16;
        for &m in &self.fault_masks {
            if seen & m != 0 {
                return Err(ProfileError::FaultMasksOverlap);
            }
            seen |= m;
        }
        let registers = [
            Some(self.speed_feedback),
            Some(self.fault_register),
            self.speed_command,
            self.control.map(|c| c.address),
            self.velocity_mode.map(|m| m.0),
            self.offline_register,
            self.resolution_register,
            self.max_speed_register,
        ];
        for (i, a) in registers.iter().enumerate() {
            let later = registers.get(i.saturating_add(1)..).unwrap_or(&[]);
            if a.is_some() && later.contains(a) {
                return Err(ProfileError::RegisterClash);
            }
        }
        if let Some(c) = self.control {
            if c.enable == c.disable || c.enable == c.clear_alarm || c.disable == c.clear_alarm {
                return Err(ProfileError::ControlValues);
            }
        }
        Ok(DriverProfile {
            slave: self.slave,
            baud: self.baud,
            speed_feedback: self.speed_feedback,
            micro_rpm_per_count: s,
            fault_register: self.fault_register,
            fault_masks: self.fault_masks,
            control: self.control,
            velocity_mode: self.velocity_mode,
            speed_command: self.speed_command.map(|c| (c, self.command_scale)),
            offline_register: self.offline_register,
            resolution_register: self.resolution_register,
            max_speed_register: self.max_speed_register,
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn generic() -> GenericSettings {
        GenericSettings {
            slave: 3,
            baud: 9600,
            speed_feedback: 0x0010,
            micro_rpm_per_count: -250_000,
            fault_register: 0x0011,
            fault_masks: [1, 2, 4, 8, 16, 32],
            speed_command: Some(0x0020),
            command_scale: -250_000,
            control: None,
            velocity_mode: None,
            offline_register: None,
            resolution_register: None,
            max_speed_register: None,
        }
    }

    /// The largest scale on the largest register values: 32 767 counts ×
    /// 100 r/min = 3 276 700 r/min, beyond i32 milli-r/min (2 147 483 r/min):
    /// the read-back is the limit of its sign. It was 0 before: a drum
    /// racing read as still.
    #[test]
    fn a_read_back_beyond_i32_is_its_limit_not_zero() {
        let p = GenericSettings {
            micro_rpm_per_count: MAX_SCALE,
            ..generic()
        }
        .build()
        .unwrap();
        assert_eq!(p.speed_from_register(0x7FFF), i32::MAX);
        assert_eq!(p.speed_from_register(0x8000), i32::MIN);
        // 21 474 counts × 100 r/min = 2 147 400 r/min: still exact.
        assert_eq!(p.speed_from_register(21_474), 2_147_400_000);
    }

    #[test]
    fn generic_settings_are_validated() {
        let p = generic().build().unwrap();
        // −250 milli-r/min per count (reversed, 0.25 r/min): 40 counts = −10 r/min.
        assert_eq!(p.speed_from_register(40), -10_000);
        assert_eq!(
            GenericSettings {
                slave: 0,
                ..generic()
            }
            .build(),
            Err(ProfileError::SlaveId(0))
        );
        assert_eq!(
            GenericSettings {
                slave: 248,
                ..generic()
            }
            .build(),
            Err(ProfileError::SlaveId(248))
        );
        assert_eq!(
            GenericSettings {
                baud: 14_400,
                ..generic()
            }
            .build(),
            Err(ProfileError::Baud(14_400))
        );
        assert_eq!(
            GenericSettings {
                micro_rpm_per_count: 0,
                ..generic()
            }
            .build(),
            Err(ProfileError::Scale(0))
        );
        assert_eq!(
            GenericSettings {
                micro_rpm_per_count: -100_000_001,
                ..generic()
            }
            .build(),
            Err(ProfileError::Scale(-100_000_001))
        );
        assert_eq!(
            GenericSettings {
                fault_masks: [1, 3, 0, 0, 0, 0],
                ..generic()
            }
            .build(),
            Err(ProfileError::FaultMasksOverlap)
        );
        assert_eq!(
            GenericSettings {
                speed_command: Some(0x0011),
                ..generic()
            }
            .build(),
            Err(ProfileError::RegisterClash)
        );
    }

    #[test]
    fn faults_by_name_and_the_rest_raw() {
        let named: std::vec::Vec<_> = ZLAC8015D.faults(0x0001 | 0x0400 | 0x0100).collect();
        // 0x0100 (EEPROM error) has no name here: reported raw.
        assert_eq!(
            named,
            [
                DriverFault::OverVoltage,
                DriverFault::OverTemperature,
                DriverFault::Other(0x0100)
            ]
        );
        assert_eq!(ZLAC8015D.faults(0).count(), 0);
        // Hall error and encoder out of tolerance are one name.
        assert_eq!(
            ZLAC8015D.faults(0x0200).collect::<std::vec::Vec<_>>(),
            [DriverFault::HallOrEncoder]
        );
    }

    #[test]
    fn speed_command_counts_round_and_clamp() {
        // ZLAC8015D: whole r/min. 20.4 r/min → 20; 20.5 → 21; −20.5 → −21.
        assert_eq!(ZLAC8015D.command_counts(20_400), Some(20));
        assert_eq!(ZLAC8015D.command_counts(20_500), Some(21));
        assert_eq!(ZLAC8015D.command_counts(-20_500), Some(0xFFEB));
        // Beyond the register: clamped to i16.
        assert_eq!(ZLAC8015D.command_counts(i32::MAX), Some(0x7FFF));
        let p = generic().build().unwrap();
        // Reversed 0.25 r/min per count: 10 r/min → −40.
        assert_eq!(p.command_counts(10_000), Some((-40i16).cast_unsigned()));
        let no_command = GenericSettings {
            speed_command: None,
            ..generic()
        }
        .build()
        .unwrap();
        assert_eq!(no_command.command_counts(10_000), None);
    }

    #[test]
    fn a_gearbox_in_the_scale() {
        // Paper A's 118:1 gearbox behind a driver counting 0.1 r/min of its
        // motor: 100 000 / 118 = 847.46 → 847 µr/min of the drum per count.
        let p = GenericSettings {
            micro_rpm_per_count: 847,
            command_scale: 847,
            ..generic()
        }
        .build()
        .unwrap();
        // Drum 20 r/min = motor 2360 r/min = 23 600 counts; 23 600 × 847 µ
        // = 19 989.2 milli-r/min → 19 989.
        assert_eq!(p.speed_from_register(23_600), 19_989);
        // The command in the same scale: 20 r/min / 0.847 milli = 23 612.75
        // → 23 613 counts.
        assert_eq!(p.command_counts(20_000), Some(23_613));
    }

    /// A ZLAC8015D behind a 20:1 gearbox through the generic profile: its
    /// feedback counts 0.1 r/min of the motor (100 000 / 20 = 5000 µr/min
    /// of the drum per count), its command whole r/min (1 000 000 / 20 =
    /// 50 000), its control word and velocity mode written, the offline
    /// time, resolution and maximum-speed registers named: the same
    /// profile as the shipped one with the gearbox in the two scales.
    #[test]
    fn a_zlac8015d_with_a_gearbox_through_the_generic_profile() {
        let g = GenericSettings {
            slave: 1,
            baud: 115_200,
            speed_feedback: 0x20AB,
            micro_rpm_per_count: 5000,
            fault_register: 0x20A5,
            fault_masks: ZLAC8015D.fault_masks,
            speed_command: Some(0x2088),
            command_scale: 50_000,
            control: ZLAC8015D.control,
            velocity_mode: Some((0x200D, 3)),
            offline_register: Some(0x2000),
            resolution_register: Some(0x2022),
            max_speed_register: Some(0x2008),
        };
        let p = g.build().unwrap();
        assert_eq!(
            p,
            DriverProfile {
                micro_rpm_per_count: 5000,
                speed_command: Some((0x2088, 50_000)),
                ..ZLAC8015D
            }
        );
        // 20.0 drum r/min = 400 motor r/min: 400 counts, 4000 at 0.1 r/min.
        assert_eq!(p.command_counts(20_000), Some(400));
        assert_eq!(p.command_counts_at(20_000, 10), Some(4000));
        // Read back: 4000 × 0.1 r/min / 20 = 20.0 drum r/min.
        assert_eq!(p.speed_from_register(4000), 20_000);
        // The drum's 44.7 r/min needs 894 motor r/min.
        assert_eq!(p.command_counts_needed(44_700), Some(894));
        // One register named twice, or two equal control values: refused.
        let twice = GenericSettings {
            offline_register: Some(0x2088),
            ..g
        };
        assert_eq!(twice.build(), Err(ProfileError::RegisterClash));
        let mut same = g;
        if let Some(c) = &mut same.control {
            c.clear_alarm = c.enable;
        }
        assert_eq!(same.build(), Err(ProfileError::ControlValues));
        let zero = GenericSettings {
            command_scale: 0,
            ..g
        };
        assert_eq!(zero.build(), Err(ProfileError::CommandScale(0)));
        // Without a command register the command scale is not used.
        let no_command = GenericSettings {
            speed_command: None,
            ..zero
        };
        assert!(no_command.build().is_ok());
    }

    /// The manual's fault word bit 0x0800, encoder error, is named (it was
    /// reported raw, "driver fault 0x0800").
    #[test]
    fn the_encoder_error_bit_is_named() {
        assert_eq!(
            ZLAC8015D.faults(0x0800).collect::<std::vec::Vec<_>>(),
            [DriverFault::HallOrEncoder]
        );
    }
}
