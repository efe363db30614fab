//! The drum driver's RS-485 link as the supervisor sees it
//! (docs/drive-link.md): the settings (feedback source, command path, driver
//! profile), the read-back as one more sensor sample with its age, and the
//! alarms it raises (driver fault, link lost, encoder or driver speed wrong).
//!
//! The Modbus master itself (`drive_link::link`) runs in a task of its own
//! in the firmware; each control period hands the supervisor a
//! [`LinkSample`] and takes back the speed command and the driver's enable.

mod settings;

pub use settings::*;

use drive_link::cross_check::CrossCheck;
use drive_link::link::SetupFault;

/// Which of the driver's set-up registers refuses it (the alarm's name;
/// the numbers are in the link task's log).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SetupRefusal {
    /// Its maximum speed is below what the drum's top speed needs.
    MaxSpeed,
    /// Its speed resolution is unusable.
    Resolution,
}

impl From<SetupFault> for SetupRefusal {
    fn from(f: SetupFault) -> Self {
        match f {
            SetupFault::MaxSpeed { .. } => Self::MaxSpeed,
            SetupFault::Resolution(_) => Self::Resolution,
        }
    }
}

/// What the supervisor keeps of the link settings it was built with (the
/// link in force until a restart): the paths, and what it derives from
/// the rest once (the read-back's delays, the fault masks). Small: it
/// lives in the supervisor, on the QEMU board's 8 KB.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkInForce {
    /// Feedback source.
    pub feedback: FeedbackSource,
    /// Command path.
    pub command: CommandPath,
    /// The driver.
    pub kind: DriverKind,
    /// [`DriveLinkSettings::readback_delay_us`].
    readback_delay_us: u32,
    /// [`DriveLinkSettings::readback_max_age_us`].
    readback_max_age_us: u32,
    /// [`DriveLinkSettings::fault_masks`].
    fault_masks: [u16; 6],
}

impl LinkInForce {
    /// See [`DriveLinkSettings::readback_delay_us`].
    #[must_use]
    pub const fn readback_delay_us(&self) -> u32 {
        self.readback_delay_us
    }

    /// See [`DriveLinkSettings::readback_max_age_us`].
    #[must_use]
    pub const fn readback_max_age_us(&self) -> u32 {
        self.readback_max_age_us
    }

    /// See [`DriveLinkSettings::fault_masks`].
    #[must_use]
    pub const fn fault_masks(&self) -> [u16; 6] {
        self.fault_masks
    }

    /// See [`DriveLinkSettings::delays_control`].
    #[must_use]
    pub fn delays_control(&self) -> bool {
        self.feedback == FeedbackSource::Driver || self.command == CommandPath::Modbus
    }
}

impl From<&DriveLinkSettings> for LinkInForce {
    fn from(s: &DriveLinkSettings) -> Self {
        Self {
            feedback: s.feedback,
            command: s.command,
            kind: s.kind,
            readback_delay_us: s.readback_delay_us(),
            readback_max_age_us: s.readback_max_age_us(),
            fault_masks: s.fault_masks(),
        }
    }
}

/// The driver's speed read-back with its age: one more sensor sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadBack {
    /// Drum speed, milli-r/min.
    pub drum_milli_rpm: i32,
    /// How old it is at this control step (since the driver sampled), µs.
    pub age_us: u32,
}

/// What the link task reports to a control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkSample {
    /// The newest read-back (none while the link is down).
    pub speed: Option<ReadBack>,
    /// The link is lost (its retry budget used up, or the driver's set-up
    /// refused) and not answering yet.
    pub lost: bool,
    /// The loss is the driver's set-up ([`drive_link::link::LossCause::Setup`]):
    /// its maximum speed or speed resolution refuses it.
    pub setup: Option<SetupRefusal>,
    /// The loss came from the driver's profile, not the line: the driver
    /// answers but refuses a register or function its profile names
    /// ([`drive_link::link::LossCause::Refused`]), or its replies do not
    /// fit the requests ([`drive_link::link::LossCause::Unfit`]).
    pub refused: bool,
    /// The last transaction was answered.
    pub answering: bool,
    /// The driver's fault word as last read.
    pub fault_word: u16,
    /// Fault words read since boot (a new reading re-raises a fault the
    /// operator acknowledged while it was still there).
    pub fault_reads: u32,
}

/// The supervisor's side of the link: the newest sample, the encoder
/// equivalent of the read-back, the cross-check. Kept small: it lives in
/// the supervisor.
#[derive(Debug, Clone, Copy, Default)]
pub struct Feedback {
    /// The newest sample from the link task.
    pub sample: LinkSample,
    /// Sub-count remainder of the read-back's integration (milli-r/min ·
    /// µs · counts per rev; one count is 60 000 000 000 of them).
    remainder: i64,
    /// Encoder against read-back.
    pub cross: CrossCheck,
    /// Fault reads seen when the operator last acknowledged a driver fault
    /// (valid when [`Feedback::acked`]).
    pub acked_fault_reads: u32,
    /// This step's bus speed command (drum milli-r/min), Modbus path only
    /// (valid when [`Feedback::bus`]).
    pub bus_command: i32,
    /// Its equivalent PWM compare value (for the log and the instability
    /// supervisor).
    pub bus_ccr: u16,
    /// A driver fault was acknowledged.
    pub acked: bool,
    /// This step commands the driver over the bus.
    pub bus: bool,
    /// The operator acknowledged a driver fault: clear the driver's alarm.
    pub clear_request: bool,
}

impl Feedback {
    /// Encoder counts the read-back speed turns the drum by in
    /// `elapsed_us` (what an encoder of `counts_per_rev` would have
    /// counted), the fractions carried to the next period. 0 with no
    /// usable read-back; never negative (the drum only runs forward).
    pub fn readback_counts(
        &mut self,
        elapsed_us: u32,
        counts_per_rev: u32,
        max_age_us: u32,
    ) -> u16 {
        let Some(rb) = self.sample.speed.filter(|r| r.age_us <= max_age_us) else {
            self.remainder = 0;
            return 0;
        };
        let rpm = i64::from(rb.drum_milli_rpm.max(0));
        // milli-r/min · µs · counts/rev; one count = 60 000 000 000 of them.
        const PER_COUNT: i64 = 60_000_000_000;
        let total = rpm
            .saturating_mul(i64::from(elapsed_us))
            .saturating_mul(i64::from(counts_per_rev))
            .saturating_add(self.remainder);
        let counts = total / PER_COUNT;
        self.remainder = total.saturating_sub(counts.saturating_mul(PER_COUNT));
        u16::try_from(counts).unwrap_or(u16::MAX)
    }

    /// The read-back if it is no older than `max_age_us`, milli-r/min.
    #[must_use]
    pub fn readback_milli_rpm(&self, max_age_us: u32) -> Option<i32> {
        self.sample
            .speed
            .filter(|r| r.age_us <= max_age_us)
            .map(|r| r.drum_milli_rpm)
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;

    #[test]
    fn the_readback_integrates_to_exact_encoder_counts() {
        // 20 r/min for 10 s in 10 ms periods, 47 200 counts per drum turn:
        // 20 / 60 × 10 s × 47 200 = 157 333.3 counts; the remainder is
        // carried, so the sum is the floor of the exact value.
        let mut f = Feedback::default();
        f.sample.speed = Some(ReadBack {
            drum_milli_rpm: 20_000,
            age_us: 20_000,
        });
        let total: u64 = (0..1000)
            .map(|_| u64::from(f.readback_counts(10_000, 400 * 118, READBACK_MAX_AGE_US)))
            .sum();
        let exact: f64 = 20.0 / 60.0 * 10.0 * 47_200.0;
        assert_eq!(total as f64, exact.floor());
        // Too old a read-back counts nothing (the link is failing).
        f.sample.speed = Some(ReadBack {
            drum_milli_rpm: 20_000,
            age_us: READBACK_MAX_AGE_US + 1,
        });
        assert_eq!(f.readback_counts(10_000, 47_200, READBACK_MAX_AGE_US), 0);
        assert_eq!(f.readback_milli_rpm(READBACK_MAX_AGE_US), None);
        // Backwards reads as standstill (the drum only runs forward).
        f.sample.speed = Some(ReadBack {
            drum_milli_rpm: -5_000,
            age_us: 0,
        });
        assert_eq!(f.readback_counts(10_000, 47_200, READBACK_MAX_AGE_US), 0);
    }

    #[test]
    fn the_readback_allowance_covers_a_slow_line_and_a_retry() {
        // 9600 baud: five transactions, 5 × 27 210 µs = 136 050 µs
        // (27 210 µs: one speed transaction,
        // link_settings_are_validated_and_round_trip), but one failed
        // attempt with the default timing is longer: request 9 167 µs +
        // reply timeout 74 324 µs + retry gap 20 000 µs, and three
        // transactions (81 630 µs): 185 121 µs. 115 200: 764 + 62 610 +
        // 20 000 + 3 × 6 933 = 104 173 µs.
        let mut s = DriveLinkSettings::default();
        s.generic.baud = 9600;
        assert_eq!(s.readback_max_age_us(), 185_121);
        s.generic.baud = 115_200;
        assert_eq!(s.readback_max_age_us(), 104_173);
        // A read-back 110 ms old at 9600 baud still counts: 27 r/min for
        // 10 ms at 47 200 counts per turn = 27 / 60 × 0.01 × 47 200 =
        // 212.4 counts.
        let mut f = Feedback::default();
        f.sample.speed = Some(ReadBack {
            drum_milli_rpm: 27_000,
            age_us: 110_000,
        });
        assert_eq!(f.readback_counts(10_000, 47_200, 185_121), 212);
        assert_eq!(f.readback_counts(10_000, 47_200, READBACK_MAX_AGE_US), 0);
    }
}
