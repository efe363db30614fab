//! The drum controller in force: the drive model, the conservative mode
//! after an instability, and the drive identification (page 9).

use super::*;

impl Supervisor {
    /// Page 9: starts the drive identification (drum stopped, no latched
    /// alarm).
    pub(super) fn identify_drive(&mut self) -> Effect {
        if self.run != RunState::Stopped {
            return Effect::Message("Stop the drum first");
        }
        if self.alarm.is_some_and(|a| a.is_latched()) {
            return Effect::Message("Acknowledge the alarm first");
        }
        if matches!(self.alarm, Some(Alarm::IdentifyFailed(_))) {
            self.alarm = None;
        }
        let mut id = Identifier::new(self.hw.control_period_us);
        id.start();
        self.drum = Drum::Identify(id);
        self.identified = IdentifyState::Running;
        self.run = RunState::Identifying;
        self.stall_us = 0;
        self.belt_counts_k3 = 0;
        Effect::Message(IDENTIFY_MESSAGE)
    }

    /// Page 9: takes the identified drive model into use and saves it.
    pub(super) fn accept_drive_model(&mut self) -> Effect {
        match self.identify_state() {
            IdentifyState::Done(model) if self.run == RunState::Stopped => {
                self.use_drive(model);
                self.identified = IdentifyState::Idle;
                if self.alarm == Some(Alarm::DrumUnstable) {
                    self.alarm = None;
                }
                // Persisted at once (the drum is stopped).
                Effect::Save
            }
            _ => Effect::Message("Identify the drive first"),
        }
    }

    /// The instability supervisor fired: the conservative controller takes
    /// over (bumpless from the feed-forward), the warning goes up. Not
    /// inlined: the controller it builds (≈ 0.6 KB with its configuration)
    /// must not widen `control_step`'s own stack frame on every period.
    #[inline(never)]
    pub(super) fn fall_back(&mut self) {
        self.fallback = true;
        self.restore_controller();
        if let Drum::Control(c) = &mut self.drum {
            c.start();
        }
        if !self.alarm.is_some_and(|a| a.is_latched()) {
            self.alarm = Some(Alarm::DrumUnstable);
        }
    }

    /// Whether the conservative mode is on ([`fallback_config`]).
    pub fn in_fallback(&self) -> bool {
        self.fallback
    }

    /// The drive model in force, with the controller scheduled from it (or
    /// the given controller kept, for [`Supervisor::with_controller`]).
    ///
    /// The controller is not built here but by the next control step
    /// ([`Supervisor::ensure_controller`], in the control task): built here,
    /// in the screen task (the operator's *Save* on page 9), its frames
    /// (≈ 2.6 KB: the command, the build, the fuzzy tuner) would sit under
    /// the control task preempting it. Every model [`DriveModel`] accepts builds
    /// (`scheduled_configs_build_for_extreme_models`).
    #[inline(never)]
    pub(super) fn use_drive(&mut self, model: DriveModel) {
        self.settings.drive = model;
        self.fallback = false;
        if self.scheduled {
            self.drum = Drum::Unbuilt;
        }
        self.law = DriveLaw::of(&model, self.hw.control_period_us);
        self.monitor = Monitor::default();
    }

    /// Builds the controller if it is not yet ([`Supervisor::new`]).
    pub(super) fn ensure_controller(&mut self) {
        if matches!(self.drum, Drum::Unbuilt) {
            self.restore_controller();
            // A drive model changed while running (`apply_settings`).
            if let (RunState::Running, Drum::Control(c)) = (self.run, &mut self.drum) {
                c.start();
            }
        }
    }

    /// The controller back in place of an identification that ended: the
    /// one scheduled from the drive model in force (a controller given to
    /// [`Supervisor::with_controller`] is not kept across an
    /// identification).
    #[inline(never)]
    pub(super) fn restore_controller(&mut self) {
        let model = self.control_model();
        let config = if self.fallback {
            fallback_config(&model)
        } else {
            let mut c = scheduled_config(&model, self.hw.control_period_us);
            // Through the link: the integral gain is not tuned
            // (`DriveLinkSettings::delays_control`).
            if self.link_in_force.delays_control() {
                if let fuzzy_pid::Schedule::Fuzzy(f) = &mut c.schedule {
                    // The smallest range `FuzzyConfig` accepts (> 0):
                    // ΔKi within ±1/65 536, Ki its base.
                    f.range.ki = I16F16::DELTA;
                }
            }
            c
        };
        if let Ok(c) = config.build() {
            self.drum = Drum::Control(c);
        }
    }

    /// One period of the drive identification.
    #[inline(never)]
    pub(super) fn identify_step(
        &mut self,
        measured: I16F16,
        delta: u16,
        elapsed_us: u32,
    ) -> Actuation {
        let duty = match &mut self.drum {
            Drum::Identify(id) => {
                let duty = id.step(measured.to_bits());
                if duty.is_none() {
                    self.identified = id.state();
                }
                duty
            }
            Drum::Unbuilt | Drum::Control(_) => None,
        };
        match duty {
            Some(permille) => {
                // Stall: the drum does not move under a 25 % or 75 % duty.
                if let Some(alarm) = self.stall_watch(delta == 0, elapsed_us) {
                    self.latch(alarm);
                    return Actuation::OFF;
                }
                let arr1 = u32::from(self.hw.pwm_arr).saturating_add(1);
                let ccr = arr1.saturating_mul(u32::from(permille)) / 1000;
                Actuation {
                    ccr: u16::try_from(ccr).unwrap_or(0),
                    driver_enabled: true,
                }
            }
            None => {
                self.run = RunState::Stopped;
                self.stall_us = 0;
                self.restore_controller();
                if let IdentifyState::Failed(e) = self.identified {
                    if !self.alarm.is_some_and(|a| a.is_latched()) {
                        self.alarm = Some(Alarm::IdentifyFailed(e));
                    }
                }
                Actuation::OFF
            }
        }
    }

    /// The drive identification's state (page 9).
    pub fn identify_state(&self) -> IdentifyState {
        match &self.drum {
            Drum::Identify(id) => id.state(),
            Drum::Unbuilt | Drum::Control(_) => self.identified,
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

    /// The drive identification (page 9) steps the drum at 25 % and 75 %
    /// duty; the drum driver's link is lost in the middle of it (or the
    /// driver reports a fault). The alarm latches and stops the drum
    /// (module docs: latched alarms mean PWM 0, driver off) — in the same
    /// control step. Before: the step's identification duty had been
    /// computed before the link's alarms were checked and was applied with
    /// the driver enabled for that period, the alarm already up.
    #[test]
    fn a_link_alarm_during_the_identification_switches_the_drum_off_at_once() {
        use crate::drive_link::{DriveLinkSettings, DriverKind, LinkSample};
        for fault in [false, true] {
            let mut drive_link = DriveLinkSettings {
                kind: DriverKind::Zlac8015d,
                ..DriveLinkSettings::default()
            };
            drive_link.generic.micro_rpm_per_count = 5000;
            let settings = Settings {
                drive_link,
                ..Settings::default()
            };
            assert!(settings.drive_link.build().is_ok());
            let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
            assert_eq!(
                sup.command(Command::IdentifyDrive),
                Effect::Message(IDENTIFY_MESSAGE)
            );
            let answering = LinkSample {
                answering: true,
                ..LinkSample::default()
            };
            let mut encoder: u16 = 0;
            for period in 0..30u32 {
                sup.set_link_sample(answering);
                let act = sup.control_step(Ticks(period * 10_000), encoder);
                assert!(act.driver_enabled && act.ccr > 0, "{act:?}");
                encoder = encoder.wrapping_add(100);
            }
            sup.set_link_sample(if fault {
                LinkSample {
                    fault_word: 1,
                    fault_reads: 1,
                    ..answering
                }
            } else {
                LinkSample {
                    lost: true,
                    ..LinkSample::default()
                }
            });
            let act = sup.control_step(Ticks(300_000), encoder);
            assert!(
                sup.alarm().is_some_and(|a| a.is_latched()),
                "{:?}",
                sup.alarm()
            );
            assert_eq!(act, Actuation::OFF, "fault {fault}");
        }
    }
}
