//! Profile B: the seedling-belt machine the firmware runs ([`BeltMachine`]),
//! around its steppers' planter ([`crate::planter`]).

use hmi_proto::screen::{self, Command};

use crate::effect::{Effect, DRUM_MACHINE_ONLY, PLACEMENT_WHILE_RUNNING};
use crate::planter::{
    BeltPlanter, Error as BeltError, PlanterState, ProfileBHardware, StepperCommand,
};
use crate::settings::belt::{belt_error_text, belt_to_screen, belt_with};
use crate::settings::{profile_from_screen, screen_profile, Settings};

/// The screen's message after *New roll* (page 7): the roller turn count
/// starts again.
pub const NEW_ROLL_DONE: &str = "New roll: turns j = 0";

/// The screen's message when *New roll* is pressed with the motors running.
pub const NEW_ROLL_WHILE_RUNNING: &str = "Stop the motors before a new roll";

/// Profile B with its settings: the [`BeltPlanter`] plus what the screen and
/// the settings store need.
pub struct BeltMachine {
    planter: BeltPlanter,
    settings: Settings,
    /// Roller turns `j` since power-up or the last *New roll*.
    roller_turns: u32,
    /// Control periods since the last roller index pulse counted
    /// (saturating; `u16::MAX`: none yet, the next one counts).
    since_index: u16,
    /// Roller index pulses not counted by the minimum-gap guard.
    index_pulses_ignored: u32,
}

impl BeltMachine {
    /// A stopped planter with these settings (their profile B part).
    pub fn new(settings: Settings, hw: ProfileBHardware) -> Result<Self, BeltError> {
        let mut planter = BeltPlanter::new(settings.belt, hw)?;
        // The placement setting chooses profile B's feeding too:
        // distance-locked is its position-locked feeding (docs/profile-b.md).
        planter.set_position_lock(settings.placement == crate::settings::Placement::DistanceLocked);
        Ok(Self {
            planter,
            settings,
            roller_turns: 0,
            since_index: u16::MAX,
            index_pulses_ignored: 0,
        })
    }

    /// The settings in force.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The planter (snapshot, state).
    pub fn planter(&self) -> &BeltPlanter {
        &self.planter
    }

    /// One control period: the ground-wheel encoder counter and the number
    /// of roller index pulses (one per feeding-roller turn) since the last
    /// period.
    ///
    /// The index input is not debounced in hardware: a pulse closer than
    /// [`BeltMachine::roller_index_gap_periods`] periods to the last one
    /// counted, and every pulse after the first in one period, is a bounce
    /// and is not counted ([`BeltMachine::index_pulses_ignored`]).
    pub fn control_step(&mut self, ground_encoder: u16, roller_pulses: u32) -> StepperCommand {
        self.since_index = self.since_index.saturating_add(1);
        if roller_pulses > 0 {
            let mut ignored = roller_pulses;
            if u32::from(self.since_index) >= self.roller_index_gap_periods() {
                self.roller_turns = self.roller_turns.saturating_add(1);
                self.since_index = 0;
                ignored = ignored.saturating_sub(1);
            }
            self.index_pulses_ignored = self.index_pulses_ignored.saturating_add(ignored);
        }
        self.planter.control_step(ground_encoder, self.roller_turns)
    }

    /// The roller index guard's minimum gap, control periods (at least 1):
    /// half the shortest roller turn the planter can command, which is
    /// `feeding steps/rev` at the step-rate ceiling `max_step_hz` (the
    /// feeding rate is clamped there). The board: 1600 steps at 20 kHz is
    /// 80 ms a turn (12.5 r/s, twelve times paper B's fastest, ≈ 1 r/s),
    /// so 40 ms = 4 periods: a real turn is never dropped, a bounce within
    /// 30–40 ms of a counted pulse is (docs/profile-b.md, "Roller index").
    pub fn roller_index_gap_periods(&self) -> u32 {
        let hw = self.planter.hardware();
        let steps = u64::from(self.planter.config().settings().feeding_steps_per_rev);
        // µs per turn = steps · 10^6 / Hz, Hertz as U16F16 bits (steps
        // ≤ 51 200 < 2^16, so the product < 2^52).
        let turn_us = steps
            .saturating_mul(1_000_000 << 16)
            .checked_div(u64::from(hw.max_step_hz.to_bits()))
            .unwrap_or(0);
        let gap = turn_us
            .checked_div(u64::from(hw.control_period_us).saturating_mul(2))
            .unwrap_or(0);
        u32::try_from(gap).unwrap_or(u32::MAX).max(1)
    }

    /// Roller index pulses the minimum-gap guard did not count (bounces),
    /// since power-up.
    pub const fn index_pulses_ignored(&self) -> u32 {
        self.index_pulses_ignored
    }

    /// Roller turns `j` since power-up or the last *New roll*.
    pub const fn roller_turns(&self) -> u32 {
        self.roller_turns
    }

    /// Applies one operator command.
    pub fn command(&mut self, cmd: Command) -> Effect {
        match cmd {
            Command::Start => {
                self.planter.start();
                Effect::None
            }
            Command::Stop => {
                self.planter.stop();
                Effect::None
            }
            Command::SelectProfile(p) => {
                // The screen link shows the "restart" message itself.
                self.settings.profile = profile_from_screen(p);
                Effect::None
            }
            Command::SaveSettings => {
                if self.planter.state() == PlanterState::Running {
                    Effect::Message("Stop the motors before saving")
                } else {
                    Effect::Save
                }
            }
            Command::SetBrightness(b) => {
                self.settings.brightness = b;
                Effect::SettingsChanged
            }
            Command::AcknowledgeAlarm => Effect::AlarmCleared,
            // Profile A's drum encoder: kept (and saved) here too, so that
            // it survives a switch of machine.
            Command::SetDrumEncoderReversed(r) => {
                self.settings.drum_encoder_reversed = r;
                Effect::SettingsChanged
            }
            // The work switch (profile A only): kept and saved
            // likewise.
            Command::SetWorkSwitchFitted(w) => {
                self.settings.work_switch_fitted = w;
                Effect::SettingsChanged
            }
            Command::SetFirstPlantDistance(d) => {
                self.settings.first_plant_distance = d;
                Effect::SettingsChanged
            }
            // Position-locked feeding or the linkage alone (docs/profile-b.md),
            // changed only with the motors stopped.
            Command::SetSpeedFollowing(f) => {
                if self.planter.state() == PlanterState::Running {
                    return Effect::Message(PLACEMENT_WHILE_RUNNING);
                }
                self.settings.placement = crate::settings::Placement::from_speed_following(f);
                self.planter.set_position_lock(!f);
                Effect::SettingsChanged
            }
            // A new belt roll (page 7): `j` from 0, only with the motors
            // stopped (docs/profile-b.md, "New roll").
            Command::NewRoll => match self.planter.new_roll() {
                Ok(()) => {
                    self.roller_turns = 0;
                    self.since_index = u16::MAX;
                    Effect::Message(NEW_ROLL_DONE)
                }
                Err(_) => Effect::Message(NEW_ROLL_WHILE_RUNNING),
            },
            other => match belt_with(&self.settings.belt, other) {
                Some(Ok(config)) => match self.planter.set_config(config) {
                    Ok(()) => {
                        self.settings.belt = config;
                        Effect::SettingsChanged
                    }
                    Err(BeltError::Running) => Effect::Message("Stop the motors first"),
                    Err(_) => Effect::Message("Parameters rejected"),
                },
                Some(Err(e)) => Effect::Message(belt_error_text(e)),
                // A profile A command: not for this machine. Pages 9 and 10
                // (the drum drive) are reached from page 6 on this machine
                // too: *Identify* and a link value must not look taken.
                None => Effect::Message(DRUM_MACHINE_ONLY),
            },
        }
    }

    /// The settings as the screen shows them.
    pub fn screen_settings(&self) -> screen::Settings {
        screen::Settings {
            brightness: self.settings.brightness,
            profile: screen_profile(self.settings.profile),
            belt: belt_to_screen(&self.settings.belt),
            drum_encoder_reversed: self.settings.drum_encoder_reversed,
            work_switch_fitted: self.settings.work_switch_fitted,
            first_plant_distance: self.settings.first_plant_distance,
            speed_following: self.settings.placement == crate::settings::Placement::SpeedFollowing,
            ..screen::Settings::default()
        }
    }

    /// The live values as the screen shows them.
    pub fn screen_status(&self) -> screen::Status {
        let s = self.planter.snapshot();
        let x100 =
            |milli: u32| u16::try_from(milli.checked_div(10).unwrap_or(0)).unwrap_or(u16::MAX);
        // Metres → 0.1 mm, rounded to the nearest (r = 25 mm is stored
        // 0.4 µm short: truncated, the screen showed 24.9 mm).
        let dmm = u16::try_from(
            u64::from(s.roller_radius.to_bits())
                .saturating_mul(10_000)
                .saturating_add(1 << 19)
                .checked_shr(20)
                .unwrap_or(0),
        )
        .unwrap_or(u16::MAX);
        screen::Status {
            travel_speed_mps_x100: x100(s.travel_speed.to_milli()),
            plant_motor_rpm_x100: x100(s.planting_speed.to_milli()),
            feed_motor_rpm_x100: x100(s.feeding_speed.to_milli()),
            roller_turns: s.roller_turns,
            roller_radius_dmm: dmm,
            distance_dm: s.distance_mm.checked_div(100).unwrap_or(0),
            ..screen::Status::default()
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::settings::Profile;

    /// The live radius on page 7 (`xrad`, 0.1 mm) is rounded to the
    /// nearest: r = 25 mm is stored 0.4 µm short (U12F20), and truncated
    /// the screen showed 24.9 mm on a new roll (measured before: 249).
    #[test]
    fn the_screens_roller_radius_is_rounded() {
        let settings = Settings {
            profile: Profile::SeedlingBelt,
            ..Settings::default()
        };
        let m = BeltMachine::new(settings, ProfileBHardware::BOARD).unwrap();
        assert_eq!(m.screen_status().roller_radius_dmm, 250);
    }

    /// Every value page 8 takes (its ranges: docs/hmi.md §4, profile B
    /// table), set alone from the defaults on a stopped planter, is taken
    /// by the machine and shown back as typed. Measured before the fix:
    /// the documented minimums X = 10.0 cm, B = 2.0 cm and r = 5.0 mm were
    /// refused with "Spacing X: 10-100 cm" (and the like): `from_ratio`
    /// rounds 0.1 m down to 104 857 µ-bits, the check's `lit("0.10")` to
    /// the nearest, 104 858. And Y above 0.200 m/s, which the screen took
    /// (up to 0.500), was refused with "Threshold Y: 0-0.2 m/s".
    #[test]
    fn every_value_page_8_takes_the_planter_takes() {
        use hmi_proto::screen::Field;
        let settings = Settings {
            profile: Profile::SeedlingBelt,
            ..Settings::default()
        };
        let fields = [
            Field::BeltSpacing,
            Field::SeedlingPitch,
            Field::ClampAngle,
            Field::ClampCount,
            Field::RollerRadius,
            Field::BeltThickness,
            Field::SpeedThreshold,
        ];
        let mut refused = std::vec::Vec::new();
        for f in fields {
            for raw in 0..=1000 {
                let Ok(cmd) = f.validate(raw) else { continue };
                let mut m = BeltMachine::new(settings.clone(), ProfileBHardware::BOARD).unwrap();
                let effect = m.command(cmd);
                let back = f.current(&m.screen_settings());
                if effect != Effect::SettingsChanged || back != raw {
                    refused.push((f, raw, effect, back));
                }
            }
        }
        assert!(
            refused.is_empty(),
            "{} refused, e.g. {:?}",
            refused.len(),
            &refused[..refused.len().min(5)]
        );
    }
}
