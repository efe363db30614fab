//! The operator's commands on the drum machine.

use super::*;

impl Supervisor {
    /// Applies one operator command from the screen (already range-checked
    /// by the screen contract).
    #[inline(never)]
    pub fn command(&mut self, cmd: Command) -> Effect {
        match cmd {
            Command::Start => self.start(),
            Command::Stop => {
                self.stop();
                Effect::None
            }
            Command::SelectMode(mode) => {
                if mode != self.settings.mode {
                    // Bumpless: the controller restarts from its output.
                    self.settings.mode = mode;
                    if let (RunState::Running, Drum::Control(c)) = (self.run, &mut self.drum) {
                        c.start();
                    }
                }
                Effect::SettingsChanged
            }
            Command::SetSpacing(spacing) => {
                // The plan depends on the spacing alone: no copy of the
                // settings to try it on (≈ 130 B of flash).
                match Self::plan_of(spacing, self.hw) {
                    Ok(plan) => {
                        self.plan = plan;
                        self.settings.spacing = spacing;
                        self.phase.set_spacing(spacing.raw());
                        if self.run == RunState::Running {
                            // The new spacing from one spacing ahead.
                            let at = self
                                .ground_distance_um()
                                .saturating_add(u64::from(spacing.raw()).saturating_mul(1000));
                            self.realign_next_plant(at);
                        }
                        Effect::SettingsChanged
                    }
                    Err(_) => Effect::Message("Spacing rejected"),
                }
            }
            Command::SetFixedDrumSpeed(speed) => {
                self.settings.fixed_drum_speed = speed;
                Effect::SettingsChanged
            }
            Command::SetMotorCoefficient(k) => {
                self.settings.motor_coefficient = k;
                Effect::SettingsChanged
            }
            Command::SelectGear(gear) => {
                self.settings.gear = settings::gear_from_screen(gear);
                Effect::SettingsChanged
            }
            Command::SelectCalibration(kind) => self.select_calibration(kind),
            Command::CalibrationStart => self.calibration_start(),
            Command::CalibrationStop => self.calibration_stop(),
            Command::CalibrationActualDistance(distance) => {
                self.compute_coefficient(distance.raw())
            }
            Command::CalibrationAccept => self.accept_coefficient(),
            Command::SetCalibrationCoefficient(k) => self.set_coefficient_by_hand(k),
            Command::AcknowledgeAlarm => {
                if let Some(effect) = self.acknowledge_link_alarm() {
                    return effect;
                }
                if self.alarm.is_some() {
                    self.alarm = None;
                    Effect::AlarmCleared
                } else {
                    Effect::None
                }
            }
            Command::SaveSettings => {
                if self.run == RunState::Running {
                    // A flash erase stalls the CPU for up to 40 ms.
                    Effect::Message("Stop the drum before saving")
                } else {
                    Effect::Save
                }
            }
            Command::SetBrightness(b) => {
                self.settings.brightness = b;
                Effect::SettingsChanged
            }
            Command::IdentifyDrive => self.identify_drive(),
            Command::AcceptDriveModel => self.accept_drive_model(),
            // Applies from the next control step (the counter's raw value
            // is kept, only the sign of its delta changes).
            // Only with the drum stopped: the ground of a pass comes from
            // one source (docs/ground-wheel.md).
            Command::SelectTravelSource(source) => {
                if self.run == RunState::Running {
                    return Effect::Message(crate::effect::SOURCE_WHILE_RUNNING);
                }
                self.settings.ground_wheel.source = source;
                Effect::SettingsChanged
            }
            Command::SetGroundWheelReversed(reversed) => {
                self.settings.ground_wheel.reversed = reversed;
                Effect::SettingsChanged
            }
            Command::SetDrumEncoderReversed(reversed) => {
                self.settings.drum_encoder_reversed = reversed;
                Effect::SettingsChanged
            }
            // Apply at once (the pass, drum/pass.rs); persisted by Save.
            Command::SetWorkSwitchFitted(fitted) => {
                self.set_work_switch_fitted(fitted);
                Effect::SettingsChanged
            }
            Command::SetFirstPlantDistance(d) => {
                self.settings.first_plant_distance = d;
                Effect::SettingsChanged
            }
            // Only with the drum stopped: switched while running, the phase
            // error that speed-following let build up would be made up at
            // the loop's bounded rate over the next plants (docs/placement.md).
            Command::SetSpeedFollowing(f) => {
                if self.run == RunState::Running {
                    return Effect::Message(crate::effect::PLACEMENT_WHILE_RUNNING);
                }
                self.settings.placement = Placement::from_speed_following(f);
                Effect::SettingsChanged
            }
            // The machine profile applies after Save and a restart
            // (crate::machine).
            Command::SelectProfile(p) => {
                // The screen link shows the "restart" message itself.
                self.settings.profile = settings::profile_from_screen(p);
                Effect::None
            }
            Command::SelectLinkParameter(p) => {
                self.link_parameter = p;
                Effect::SettingsChanged
            }
            Command::SetLinkValue(v) => self.set_link_value(v),
            // Page 7's *New roll* (the belt roller's turn count).
            Command::NewRoll => Effect::Message(crate::effect::BELT_MACHINE_ONLY),
            // Profile B's parameters are kept (and saved) here too, so that
            // they survive a switch of machine.
            Command::SetBeltSpacing(_)
            | Command::SetSeedlingPitch(_)
            | Command::SetClampAngle(_)
            | Command::SetClampCount(_)
            | Command::SetRollerRadius(_)
            | Command::SetBeltThickness(_)
            | Command::SetSpeedThreshold(_) => {
                match settings::belt::belt_with(&self.settings.belt, cmd) {
                    Some(Ok(belt)) => {
                        self.settings.belt = belt;
                        Effect::SettingsChanged
                    }
                    _ => Effect::Message("Parameters rejected"),
                }
            }
        }
    }
}
