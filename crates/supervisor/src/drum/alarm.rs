//! What the operator must see: the alarms and warnings, their screen
//! texts, and the limits the control step judges faults by.

use fuzzy_pid::I16F16;

use crate::drive::IdentifyError;

/// A condition the operator must see.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Alarm {
    /// Commanded drum with no encoder motion: jammed drum, or encoder lost.
    /// Latched.
    DrumStall,
    /// Commanded drum whose feedback turned backwards for the whole stall
    /// time (encoder: ≥ 2 counts a period the wrong way; driver read-back:
    /// below −1 r/min): the motor's wiring or direction, the encoder's A/B
    /// (the encoder direction setting) or the driver scale's sign. Latched.
    DrumBackwards,
    /// The next Hall edge is later than any stop of the chassis allows
    /// (module docs) while the drum was running. Latched.
    HallLost,
    /// No Hall edge for [`NO_PULSES_US`] while the drum runs in
    /// Speed-Adaptive mode with the unit down: the tractor has stopped, or
    /// the Hall sensor (or its wire) is dead and the machine plants
    /// nothing while it moves. One sensor cannot tell them apart below
    /// High 3 (module docs), so this is a warning, not a stop: it clears
    /// with the next edges.
    NoTravelPulses,
    /// Travel speed too high for the spacing; the drum is held at `n_max`.
    /// Clears by itself. Carries the allowed maximum, km/h × 100.
    TooFast {
        /// The highest travel speed this spacing allows, km/h × 100.
        max_kmh_x100: u16,
    },
    /// The drum speed oscillated, or missed the drive model's response by
    /// more than 5 % for more than 1 s: the controller switched to its
    /// conservative mode (see [`Supervisor`](super::Supervisor)'s instability supervisor). A
    /// warning: the drum keeps running. Run the drive identification again.
    DrumUnstable,
    /// The drive identification ended without a model (a warning).
    IdentifyFailed(IdentifyError),
    /// The drum driver reports a fault over its link (the first named
    /// one). Latched.
    DriverFault(drive_link::profile::DriverFault),
    /// No valid reply from the drum driver within the link's retry budget.
    /// Latched; acknowledged only once the driver answers again.
    LinkLost,
    /// The link is lost because the driver answers with Modbus exceptions:
    /// its profile names a register or function this driver does not have
    /// (a generic profile's registers, most often). As [`Alarm::LinkLost`]
    /// otherwise.
    LinkRefused,
    /// The driver answers, but its set-up refuses it: its maximum speed
    /// is below what the drum's top speed needs through the gearbox, or
    /// its speed resolution is unusable
    /// ([`drive_link::link::SetupFault`]). As [`Alarm::LinkLost`]
    /// otherwise; cleared once the driver's register is corrected.
    DriverSetup(crate::drive_link::SetupRefusal),
    /// Encoder and driver read-back disagree beyond the cross-check's
    /// margin for its hold time ([`drive_link::cross_check`]): a lost
    /// encoder, or a driver reporting wrong. Latched.
    SpeedMismatch,
    /// The ground wheel (both sensors fitted) does not roll while the Hall
    /// gear turns: lifted, blocked or clogged. A warning: the machine plants
    /// on the Hall gear until the wheel rolls again ([`crate::ground`]).
    GroundWheelStopped,
    /// The ground wheel counts backwards while the machine moves forward.
    /// With both sensors a warning (the Hall gear stands in); with the wheel
    /// alone latched: the drum stops.
    GroundWheelBackwards {
        /// The wheel is the only source (latched).
        alone: bool,
    },
    /// The Hall gear (both sensors fitted) is silent while the ground wheel
    /// rolls: the track slip is not measured. A warning: the wheel carries
    /// on.
    HallGearStopped,
    /// No ground-wheel count for [`NO_PULSES_US`] while the drum runs in
    /// Speed-Adaptive mode with the unit down (the wheel the source): as
    /// [`Alarm::NoTravelPulses`] for the wheel.
    NoWheelPulses,
}

impl Alarm {
    /// Latched alarms stop the drum and need an acknowledgement.
    pub const fn is_latched(&self) -> bool {
        matches!(
            self,
            Self::DrumStall
                | Self::DrumBackwards
                | Self::HallLost
                | Self::DriverFault(_)
                | Self::LinkLost
                | Self::LinkRefused
                | Self::DriverSetup(_)
                | Self::SpeedMismatch
                | Self::GroundWheelBackwards { alone: true }
        )
    }

    /// The text for the screen (ASCII, at most 40 characters).
    pub fn write_text(&self, w: &mut impl core::fmt::Write) -> core::fmt::Result {
        match self {
            Self::DrumStall => w.write_str("Drum stalled or encoder lost"),
            Self::DrumBackwards => w.write_str("Drum turns backwards: check direction"),
            Self::HallLost => w.write_str("Hall speed signal lost"),
            Self::NoTravelPulses => w.write_str(NO_PULSES_TEXT),
            Self::DrumUnstable => w.write_str(DRUM_UNSTABLE_TEXT),
            Self::IdentifyFailed(e) => w.write_str(e.text()),
            Self::DriverFault(f) => {
                use drive_link::profile::DriverFault as F;
                w.write_str(match f {
                    F::OverCurrent => "Driver fault: over-current",
                    F::OverVoltage => "Driver fault: over-voltage",
                    F::UnderVoltage => "Driver fault: under-voltage",
                    F::Overload => "Driver fault: overload",
                    F::HallOrEncoder => "Driver fault: Hall/encoder",
                    F::OverTemperature => "Driver fault: over-temperature",
                    F::Other(_) => "Driver fault (unnamed)",
                })
            }
            Self::LinkLost => w.write_str("Drum driver link lost"),
            Self::LinkRefused => w.write_str("Driver refuses register: check profile"),
            Self::DriverSetup(crate::drive_link::SetupRefusal::MaxSpeed) => {
                w.write_str("Driver max speed too low for gearbox")
            }
            Self::DriverSetup(crate::drive_link::SetupRefusal::Resolution) => {
                w.write_str("Driver speed resolution unusable")
            }
            Self::SpeedMismatch => w.write_str("Encoder or driver speed wrong"),
            Self::GroundWheelStopped => w.write_str(WHEEL_STOPPED_TEXT),
            Self::GroundWheelBackwards { alone: false } => {
                w.write_str("Wheel counts backwards: on Hall gear")
            }
            Self::GroundWheelBackwards { alone: true } => {
                w.write_str("Wheel counts backwards: set direction")
            }
            Self::HallGearStopped => w.write_str(HALL_STOPPED_TEXT),
            Self::NoWheelPulses => w.write_str(NO_WHEEL_PULSES_TEXT),
            Self::TooFast { max_kmh_x100 } => {
                // Digits by hand: `write!` with integers would pull in
                // `core::fmt`'s number formatting (~2 KB of flash), and
                // `str::from_utf8` on a digit buffer 300 B more.
                const DIGITS: [&str; 10] = ["0", "1", "2", "3", "4", "5", "6", "7", "8", "9"];
                let v = *max_kmh_x100;
                w.write_str("Too fast: max ")?;
                // km/h × 100 ≤ 655.35: up to three integer digits, no
                // leading zeros, then always two decimals.
                let mut started = false;
                for (place, point) in [
                    (10_000, false),
                    (1000, false),
                    (100, true),
                    (10, false),
                    (1, false),
                ] {
                    let d = usize::from(v.checked_div(place).unwrap_or(0) % 10);
                    if d > 0 || started || place <= 100 {
                        w.write_str(DIGITS.get(d).copied().unwrap_or("?"))?;
                        started = true;
                    }
                    if point {
                        w.write_str(".")?;
                    }
                }
                w.write_str(" km/h")
            }
        }
    }
}

/// The message shown when the drive identification starts.
pub const IDENTIFY_MESSAGE: &str = "Identifying drive: keep belt empty";

/// The warning text of [`Alarm::NoTravelPulses`] (the screen's 40
/// characters).
pub const NO_PULSES_TEXT: &str = "No travel pulses: check Hall, or Stop";

/// Page 4: a ground-wheel calibration run in which the wheel did not count.
pub const WHEEL_NO_PULSES_TEXT: &str = "No wheel pulses: check the wheel sensor";
/// Page 4: a ground-wheel calibration run that counted backwards.
pub const WHEEL_BACKWARDS_RUN_TEXT: &str = "Wheel counted backwards: set direction";
/// Page 4: a ground-wheel calibration result beyond ±20 % of the nominal
/// wheel.
pub const WHEEL_TOLERANCE_TEXT: &str = "Wheel off nominal by >20 %: not saved";

/// The warning text of [`Alarm::GroundWheelStopped`].
pub const WHEEL_STOPPED_TEXT: &str = "Ground wheel not turning: on Hall gear";
/// The warning text of [`Alarm::HallGearStopped`].
pub const HALL_STOPPED_TEXT: &str = "Hall gear silent: slip not measured";
/// The warning text of [`Alarm::NoWheelPulses`].
pub const NO_WHEEL_PULSES_TEXT: &str = "No travel pulses: check wheel, or Stop";

/// The warning text of [`Alarm::DrumUnstable`].
pub const DRUM_UNSTABLE_TEXT: &str = "Drum unstable: safe mode, identify";

/// Stall: commanded drum speed from which the encoder must move.
pub(super) const STALL_MIN_COMMAND: I16F16 = I16F16::lit("1");
/// Stall: time without encoder motion, µs.
pub(super) const STALL_TIME_US: u32 = 200_000;
/// Backwards: encoder counts a period against the drum's direction that
/// count as turning backwards (the drum at the stall command of 1 r/min
/// makes 7.9 a period, 47 200 counts a turn; a still drum's jitter is ±1).
pub(super) const BACKWARD_MIN_COUNTS: u16 = 2;
/// Hall silence: the fastest the Hall gear's speed can fall when the
/// tractor stops, mm/s² of monitored track speed: the chassis limit of 1 g
/// ([`kinematics::consts::CHASSIS_DECEL_LIMIT_MM_S2`]) seen through a k1 down to 0.934
/// (9.81 / 0.934 = 10.5; paper A's Table 11 has k1 = 0.966 … 1.031), so
/// that no stop the chassis can make reads as a lost signal.
pub const HALL_SILENCE_DECEL_MM_S2: u32 = 10_500;
/// Ground distance: a Hall edge the speed estimator drops as a glitch for
/// its ¼-period rule still counts as a tooth when it comes at least this
/// long (µs) after the previous counted edge. The ¼ rule protects the speed
/// estimate, but it also drops real teeth: a tractor pulling away from a
/// crawl (a last gap of 1 s or more) makes its next gap shorter than a
/// quarter of it, and each dropped tooth cost the distance 25 mm
/// (measured on the stop-and-go profile: 86 mm lost in 60 s at Low 2, 61 mm
/// with the estimator's bounded glitch reference of aa1e4a8, test
/// `the_ground_distance_keeps_every_tooth_through_stops`; docs/placement.md). 5 ms is ten times the switch's
/// hard glitch limit (500 µs) and below the shortest real gap (9 ms at
/// 10 km/h).
pub const DISTANCE_EDGE_MIN_GAP_US: u32 = 5_000;
/// No Hall edge for this long (µs), while the drum runs in Speed-Adaptive
/// mode with the unit down, raises [`Alarm::NoTravelPulses`]: 2.5 s, nine
/// edge periods of the slowest gear (Low 1, 0.32 km/h at the gear: 283 ms
/// an edge; 300 ms on the terrain's −5 %), so that no working speed leaves
/// such a silence, and short enough that the warning is up within 3 s of a
/// sensor's death (the last edge came before it). A 2 s rest of a
/// stop-and-go is shorter (at most 2.4 s between edges at Low 1 with a
/// 0.5 s chassis); a longer one shows the warning, which clears with the
/// first edges after it.
pub const NO_PULSES_US: u32 = 2_500_000;
/// Hall silence: the tolerance on a gap's length, % — pitch errors of
/// teeth whose share is not learned yet (±2 % of a pitch per tooth, so
/// ±4 % per gap) and the capture jitter.
pub const HALL_SILENCE_GAP_TOLERANCE_PCT: u8 = 5;
