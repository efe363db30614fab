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
    /// micro-r/min per count), when the driver takes speed commands.
    pub speed_command: Option<(u16, i32)>,
}

/// The ZLAC8015D (ZLTECH dual-channel BLDC driver), left motor, slave 1 at
/// 115 200 baud: control word 0x200E (0x08 enable, 0x07 disable, 0x06 clear
/// alarm), mode 0x200D = 3 (velocity), speed command 0x2088 in r/min, actual
/// speed 0x20AB in 0.1 r/min, fault bits 0x20A5 (over-voltage 0x0001,
/// under-voltage 0x0002, over-current 0x0004, overload 0x0008, encoder out
/// of tolerance 0x0020, Hall error 0x0200, motor over-temperature 0x0400; as
/// read from ZLTECH's manual — check your driver's). The drum is taken as
/// driven 1:1 by the motor: set a [`GenericSettings`] with the gearbox in
/// the scale otherwise.
///
/// The speed command register counts whole r/min (its feedback 0.1 r/min).
pub const ZLAC8015D: DriverProfile = DriverProfile {
    slave: 1,
    baud: 115_200,
    speed_feedback: 0x20AB,
    micro_rpm_per_count: 100_000,
    fault_register: 0x20A5,
    fault_masks: [0x0004, 0x0001, 0x0002, 0x0008, 0x0220, 0x0400],
    control: Some(ControlWord {
        address: 0x200E,
        enable: 0x08,
        disable: 0x07,
        clear_alarm: 0x06,
    }),
    velocity_mode: Some((0x200D, 3)),
    speed_command: Some((0x2088, 1_000_000)),
};

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

    /// The speed command register's value for a drum speed, rounded to the
    /// nearest count and limited to the register's range.
    /// `None` when the driver takes no speed command.
    #[must_use]
    pub fn command_counts(&self, drum_milli_rpm: i32) -> Option<u16> {
        let (_, scale) = self.speed_command?;
        let scale = i64::from(scale);
        if scale == 0 {
            return Some(0);
        }
        let num = i64::from(drum_milli_rpm).saturating_mul(1000);
        // Round half away from zero, on magnitudes (|num| < 2^31, |scale| ≤ 2^31).
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

    /// The named faults in a fault word, then the unnamed bits as one
    /// [`DriverFault::Other`].
    pub fn faults(&self, word: u16) -> impl Iterator<Item = DriverFault> + '_ {
        let named = self.fault_masks.iter().fold(0u16, |acc, m| acc | m);
        let other = word & !named;
        NAMED_FAULTS
            .iter()
            .zip(self.fault_masks.iter())
            .filter(move |(_, &mask)| mask != 0 && word & mask != 0)
            .map(|(&f, _)| f)
            .chain((other != 0).then_some(DriverFault::Other(other)))
    }
}

/// The largest |scale| a generic profile may name: 100 r/min per count
/// (in micro-r/min).
pub const MAX_SCALE: i32 = 100_000_000;

/// A generic driver, as the operator enters it on the screen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GenericSettings {
    /// Slave id, 1–247.
    pub slave: u8,
    /// Baud rate, one of [`BAUD_RATES`].
    pub baud: u32,
    /// Speed feedback register.
    pub speed_feedback: u16,
    /// Drum micro-r/min per count, nonzero, |scale| ≤ [`MAX_SCALE`].
    pub micro_rpm_per_count: i32,
    /// Fault register.
    pub fault_register: u16,
    /// Masks of the named faults (pairwise disjoint).
    pub fault_masks: [u16; 6],
    /// Speed command register (same scale), if the driver takes one.
    pub speed_command: Option<u16>,
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
    /// Two named faults share a bit.
    FaultMasksOverlap,
    /// The speed feedback and the fault register are the same register, or
    /// the speed command writes to one of them.
    RegisterClash,
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
            Self::FaultMasksOverlap => f.write_str("two fault names share a bit"),
            Self::RegisterClash => f.write_str("speed, fault and command registers must differ"),
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
    let s = micro_rpm_per_count;
    if s == 0 || s.unsigned_abs() > MAX_SCALE.unsigned_abs() {
        return Err(ProfileError::Scale(s));
    }
    Ok(())
}

impl GenericSettings {
    /// Validates the settings into a profile.
    pub fn build(&self) -> Result<DriverProfile, ProfileError> {
        let s = self.micro_rpm_per_count;
        check_line(self.slave, self.baud, s)?;
        let mut seen = 0u16;
        for &m in &self.fault_masks {
            if seen & m != 0 {
                return Err(ProfileError::FaultMasksOverlap);
            }
            seen |= m;
        }
        if self.speed_feedback == self.fault_register
            || self
                .speed_command
                .is_some_and(|c| c == self.speed_feedback || c == self.fault_register)
        {
            return Err(ProfileError::RegisterClash);
        }
        Ok(DriverProfile {
            slave: self.slave,
            baud: self.baud,
            speed_feedback: self.speed_feedback,
            micro_rpm_per_count: s,
            fault_register: self.fault_register,
            fault_masks: self.fault_masks,
            control: None,
            velocity_mode: None,
            speed_command: self.speed_command.map(|c| (c, s)),
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
}
