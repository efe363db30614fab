//! The drum driver's link seen from the drum machine: its samples as
//! feedback, its command, its alarms.

use super::*;

impl Supervisor {
    /// Page 10: a link setting into the saved settings, not into the link in
    /// force (the board sets its link up at start).
    pub(super) fn set_link_value(&mut self, v: i32) -> Effect {
        if self.run != RunState::Stopped {
            return Effect::Message("Stop the drum first");
        }
        match self.settings.drive_link.with(self.link_parameter, v) {
            Some(Ok(link)) => {
                self.settings.drive_link = link;
                Effect::SettingsChanged
            }
            Some(Err(e)) => Effect::Message(e.text()),
            None => Effect::Message("Value out of range"),
        }
    }

    /// The drum link's newest sample (one more sensor sample, with the
    /// read-back's age): call before [`Supervisor::control_step`].
    pub fn set_link_sample(&mut self, sample: crate::drive_link::LinkSample) {
        // Field by field: a whole-struct assignment here compiled to a
        // `memmove` call, which linked 1.6 KB of compiler-builtins.
        let s = &mut self.link.sample;
        let (milli, age) = sample
            .speed
            .map_or((None, 0), |r| (Some(r.drum_milli_rpm), r.age_us));
        s.speed = milli.map(|drum_milli_rpm| crate::drive_link::ReadBack {
            drum_milli_rpm,
            age_us: age,
        });
        s.lost = sample.lost;
        s.setup = sample.setup;
        s.refused = sample.refused;
        s.answering = sample.answering;
        s.fault_word = sample.fault_word;
        s.fault_reads = sample.fault_reads;
    }

    /// The speed command for the driver's bus (drum milli-r/min) when the
    /// command path is Modbus and the drum runs; `None` otherwise.
    pub fn bus_speed_command(&self) -> Option<i32> {
        self.link.bus.then_some(self.link.bus_command)
    }

    /// Whether the operator's acknowledgement asked the driver to clear its
    /// latched alarm (taken once).
    pub fn take_driver_clear(&mut self) -> bool {
        core::mem::take(&mut self.link.clear_request)
    }

    /// Whether the link is in use (a driver profile and a feedback or
    /// command that needs it, or a profile at all: its faults are read).
    pub(super) fn link_in_use(&self) -> bool {
        self.link_in_force.kind != crate::drive_link::DriverKind::None
    }

    /// This period's drum counts from the feedback source in force: the
    /// encoder's, or the read-back integrated over the period.
    pub(super) fn feedback_counts(&mut self, encoder_delta: u16, elapsed_us: u32) -> u16 {
        use crate::drive_link::FeedbackSource;
        match self.link_in_force.feedback {
            FeedbackSource::Encoder | FeedbackSource::Both => encoder_delta,
            FeedbackSource::Driver => self.link.readback_counts(
                elapsed_us,
                self.hw.encoder_counts_per_drum_rev,
                self.link_in_force.readback_max_age_us(),
            ),
        }
    }

    /// The drive model the controller is scheduled from: the drive's own,
    /// with the driver read-back as the feedback, or the bus command, its
    /// dead time lengthened by one link transaction each ([`crate::drive_link::DriveLinkSettings::readback_delay_us`]),
    /// so that the gains shrink in the SIMC ratio (docs/drive-link.md).
    pub(super) fn control_model(&self) -> DriveModel {
        use crate::drive_link::{CommandPath, FeedbackSource};
        let m = self.settings.drive;
        let link = &self.link_in_force;
        // One transaction's delay for the read-back as the feedback, one
        // more for the bus command (written about every other transaction).
        let transactions = u32::from(link.feedback == FeedbackSource::Driver)
            .saturating_add(u32::from(link.command == CommandPath::Modbus));
        if transactions == 0 {
            return m;
        }
        let extra = u16::try_from(link.readback_delay_us().saturating_mul(transactions) / 100)
            .unwrap_or(u16::MAX);
        let dead = m
            .dead_time_x10_ms()
            .saturating_add(extra)
            .min(DriveModel::DEAD_TIME_MAX);
        DriveModel::new(m.n_max_x100(), m.tau_x10_ms(), dead).unwrap_or(m)
    }

    /// Control periods the measurement lags the command by, beyond the
    /// drive's own: the read-back's age when it is the feedback, and one
    /// link transaction for the bus command (rounded).
    pub(super) fn readback_delay_periods(&self) -> usize {
        use crate::drive_link::{CommandPath, FeedbackSource};
        let link = &self.link_in_force;
        let period = self.hw.control_period_us.max(1);
        let periods = |us: u32| {
            us.saturating_add(period / 2)
                .checked_div(period)
                .unwrap_or(0)
        };
        let feedback = if link.feedback == FeedbackSource::Driver {
            self.link.sample.speed.map_or(0, |r| periods(r.age_us))
        } else {
            0
        };
        // The bus command reaches the driver one transaction later (on
        // average; written about every other transaction).
        let command = if link.command == CommandPath::Modbus {
            periods(link.readback_delay_us())
        } else {
            0
        };
        feedback.saturating_add(command) as usize
    }

    /// The link's alarms: lost, a driver fault, the cross-check.
    pub(super) fn link_alarms(&mut self, encoder_delta: u16, elapsed_us: u32) {
        if !self.link_in_use() {
            return;
        }
        let sample = self.link.sample;
        if sample.lost {
            self.latch(match sample.setup {
                Some(fault) => Alarm::DriverSetup(fault),
                None if sample.refused => Alarm::LinkRefused,
                None => Alarm::LinkLost,
            });
            return;
        }
        if sample.fault_word != 0
            && !(self.link.acked && self.link.acked_fault_reads == sample.fault_reads)
        {
            let fault = drive_link::profile::first_fault(
                &self.link_in_force.fault_masks(),
                sample.fault_word,
            );
            if self.alarm != Some(Alarm::DriverFault(fault)) {
                self.latch(Alarm::DriverFault(fault));
            }
            return;
        }
        if self.link_in_force.feedback == crate::drive_link::FeedbackSource::Both
            && self.run == RunState::Running
        {
            let encoder = milli(self.drum_speed_of(encoder_delta, elapsed_us));
            let driver = self
                .link
                .readback_milli_rpm(self.link_in_force.readback_max_age_us());
            let wrong = match driver {
                Some(d) => self.link.cross.update(
                    elapsed_us,
                    i32::try_from(encoder).unwrap_or(i32::MAX),
                    d,
                ),
                None => false,
            };
            if wrong {
                self.latch(Alarm::SpeedMismatch);
            }
        } else {
            self.link.cross = drive_link::cross_check::CrossCheck::new();
        }
    }

    /// The operator acknowledges a link alarm: a lost link only once the
    /// driver answers again; a driver fault asks the driver to clear its
    /// alarm (a fault still there comes back with the next fault read).
    pub(super) fn acknowledge_link_alarm(&mut self) -> Option<Effect> {
        match self.alarm {
            Some(Alarm::LinkLost | Alarm::LinkRefused | Alarm::DriverSetup(_))
                if !self.link.sample.answering || self.link.sample.lost =>
            {
                Some(Effect::Message("Drum driver still not answering"))
            }
            Some(Alarm::DriverFault(_)) => {
                self.link.acked_fault_reads = self.link.sample.fault_reads;
                self.link.acked = true;
                self.link.clear_request = true;
                self.alarm = None;
                Some(Effect::AlarmCleared)
            }
            _ => None,
        }
    }
}
#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;
    use hmi_proto::screen::DrumSpeed;

    /// Page 10 (docs/hmi.md): the selector shows each setting's saved
    /// value; a value goes into the saved link settings only when the whole
    /// passes `DriveLinkSettings::build`, refused by name otherwise; the
    /// link in force stays the one the supervisor was built with until a
    /// restart: with the read-back chosen as the feedback on the page, the
    /// drum still runs on its encoder (no stall alarm: before
    /// `link_in_force`, the read-back that no link delivers counted 0 and
    /// the stall alarm latched 0.2 s after Start).
    #[test]
    fn page_10_edits_the_saved_link_settings_not_the_link_in_force() {
        use crate::drive_link::FeedbackSource;
        use hmi_proto::screen::{LinkParameter as P, Mode};
        let settings = Settings {
            mode: Mode::Fixed,
            fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
            ..Settings::default()
        };
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        let set = |sup: &mut Supervisor, p: P, v: i32| {
            assert_eq!(
                sup.command(Command::SelectLinkParameter(p)),
                Effect::SettingsChanged
            );
            sup.command(Command::SetLinkValue(v))
        };
        // The ZLAC8015D's default line: 115 200 baud, slave 1.
        sup.command(Command::SelectLinkParameter(P::Baud));
        assert_eq!(sup.screen_settings().link_value, 115_200);
        assert_eq!(
            set(&mut sup, P::Feedback, 1),
            Effect::Message("Needs a driver (Driver 1 or 2)")
        );
        // Paper A's 118:1 behind the driver's 0.1 r/min (847 µr/min per
        // count) reads at most 27.75 r/min: refused until the scale is set.
        assert_eq!(
            set(&mut sup, P::Driver, 1),
            Effect::Message("Scale under 1365: reads < 44.7 r/min")
        );
        // Behind 59:1 (1695) the drum's 44.7 r/min needs 2638 motor r/min,
        // beyond the ZLAC8015D's 1000 (0x2008): refused by name; behind
        // 20:1 (5000) it needs 894: taken.
        assert_eq!(set(&mut sup, P::Scale, 1695), Effect::SettingsChanged);
        assert_eq!(
            set(&mut sup, P::Driver, 1),
            Effect::Message("Gearbox needs over 1000 motor r/min")
        );
        assert_eq!(set(&mut sup, P::Scale, 5000), Effect::SettingsChanged);
        assert_eq!(set(&mut sup, P::Driver, 1), Effect::SettingsChanged);
        // A reply timeout beyond 1000 ms is refused; the saved one stays.
        assert_eq!(
            set(&mut sup, P::ReplyTimeout, 1001),
            Effect::Message("Reply timeout: 5-1000 ms")
        );
        assert_eq!(sup.settings().drive_link.timing.reply_timeout_ms, 60);
        assert_eq!(set(&mut sup, P::ReplyTimeout, 80), Effect::SettingsChanged);
        assert_eq!(sup.settings().drive_link.timing.reply_timeout_ms, 80);
        assert_eq!(set(&mut sup, P::Feedback, 1), Effect::SettingsChanged);
        assert_eq!(sup.settings().drive_link.feedback, FeedbackSource::Driver);
        assert_eq!(sup.screen_settings().link_value, 1);
        assert_eq!(
            sup.command(Command::SetLinkValue(3)),
            Effect::Message("Value out of range")
        );
        assert_eq!(
            set(&mut sup, P::SpeedRegister, 65_536),
            Effect::Message("Value out of range")
        );
        assert_eq!(
            set(&mut sup, P::Baud, 4800),
            Effect::Message("Baud: 9600 19200 38400 57600 115200")
        );
        assert_eq!(
            set(&mut sup, P::Slave, 0),
            Effect::Message("Slave id must be 1-247")
        );
        assert_eq!(sup.settings().drive_link.generic.baud, 115_200);
        // Fixed 20 r/min on the encoder: 20 / 60 rev/s × 47 200 counts ×
        // 0.01 s = 157.3 counts per period.
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        for period in 0..50u32 {
            sup.control_step(Ticks(period * 10_000), encoder);
            encoder = encoder.wrapping_add(157);
        }
        assert_eq!(sup.alarm(), None);
        assert_eq!(
            sup.command(Command::SetLinkValue(1)),
            Effect::Message("Stop the drum first")
        );
    }
}
