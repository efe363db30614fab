//! The machine the firmware runs, chosen once at start-up from the saved
//! settings: profile A ([`Supervisor`]) or profile B ([`BeltMachine`]).
//!
//! A machine builder sets the profile once, on the settings page: the two
//! profiles drive different motors from the same pins (the drum's PWM timer
//! becomes the planting stepper's pulse timer), so a change takes effect
//! after Save and a restart, never while motors may run.

use fixed::types::U16F16;
use hmi_proto::screen::{self, Command, MachineProfile};
use kinematics::profile_b::ProfileBSettings;
use kinematics::units::{Metres, MetresPerSecond};

use crate::control::Effect;
use crate::control::Supervisor;
use crate::profile_b::{
    BeltPlanter, Error as BeltError, PlanterState, ProfileBConfig, ProfileBHardware, StepperCommand,
};
use crate::settings::{Profile, Settings};

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

/// Profile B's parameters as the screen shows them (its scaled integers).
pub fn belt_to_screen(c: &ProfileBConfig) -> screen::BeltSettings {
    let s = c.settings();
    let int = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
    // Metres → mm, 0.1 mm, 0.01 mm; m/s → mm/s (rounded to the nearest).
    // U12F20 / U8F24 bits × units per metre, rounded to the nearest.
    let round_shift = |x: u64, frac: u32| {
        let half = 1u64.checked_shl(frac.saturating_sub(1)).unwrap_or(0);
        int(
            u32::try_from(x.saturating_add(half).checked_shr(frac).unwrap_or(0))
                .unwrap_or(u32::MAX),
        )
    };
    let scaled = |m: Metres, per_m: u32| {
        round_shift(u64::from(m.to_bits()).saturating_mul(u64::from(per_m)), 20)
    };
    let mm_s = |v: MetresPerSecond| round_shift(u64::from(v.to_bits()).saturating_mul(1000), 24);
    screen::BeltSettings {
        spacing: screen::BeltSpacing::new(scaled(s.plant_spacing, 1000)).unwrap_or_default(),
        seedling_pitch: screen::SeedlingPitch::new(scaled(s.belt_pitch, 1000)).unwrap_or_default(),
        // Whole degrees: the integer bits (`to_num::<u32>()` rounds down
        // the same way, through `fixed`'s generic conversion).
        clamp_angle: screen::ClampAngle::new(int(s.clamping_angle_deg.to_bits() >> 16))
            .unwrap_or_default(),
        clamp_count: screen::ClampCount::new(i32::from(s.seedlings_clamped)).unwrap_or_default(),
        roller_radius: screen::RollerRadius::new(scaled(s.roller_radius, 10_000))
            .unwrap_or_default(),
        belt_thickness: screen::BeltThickness::new(scaled(s.belt_thickness, 100_000))
            .unwrap_or_default(),
        speed_threshold: screen::SpeedThreshold::new(mm_s(s.threshold)).unwrap_or_default(),
    }
}

/// Applies one profile B parameter from the screen to `c`; the result is
/// validated as a whole (the screen checked each value's own range).
pub fn belt_with(c: &ProfileBConfig, cmd: Command) -> Option<Result<ProfileBConfig, BeltError>> {
    let mut s: ProfileBSettings = *c.settings();
    // `num / den` metres, rounded to the nearest bit like the limits
    // `ProfileBConfig::new` checks (`Metres::lit`): `from_ratio` rounds
    // down, and 0.1 m (X = 10.0 cm, the screen's minimum) fell half a bit
    // below the check's 0.10.
    let metres = |num: u16, den: u32| {
        Some(Metres::from_bits(nearest_bits(
            u32::from(num),
            den,
            fixed::types::U12F20::FRAC_NBITS,
        )?))
    };
    match cmd {
        Command::SetBeltSpacing(v) => s.plant_spacing = metres(v.raw(), 1000)?,
        Command::SetSeedlingPitch(v) => s.belt_pitch = metres(v.raw(), 1000)?,
        Command::SetClampAngle(v) => s.clamping_angle_deg = U16F16::from_num(v.raw()),
        Command::SetClampCount(v) => s.seedlings_clamped = v.raw(),
        Command::SetRollerRadius(v) => s.roller_radius = metres(v.raw(), 10_000)?,
        Command::SetBeltThickness(v) => s.belt_thickness = metres(v.raw(), 100_000)?,
        Command::SetSpeedThreshold(v) => {
            s.threshold = MetresPerSecond::from_bits(nearest_bits(
                u32::from(v.raw()),
                1000,
                fixed::types::U8F24::FRAC_NBITS,
            )?);
        }
        _ => return None,
    }
    Some(ProfileBConfig::new(s))
}

/// The bits of `num / den` in a fixed-point type with `frac` fractional
/// bits, rounded to the nearest; `None` if `den` is 0 or it does not fit.
fn nearest_bits(num: u32, den: u32, frac: u32) -> Option<u32> {
    let scaled = u64::from(num).checked_shl(frac)?;
    let bits = scaled
        .checked_add(u64::from(den / 2))?
        .checked_div(u64::from(den))?;
    u32::try_from(bits).ok()
}

/// A short text for the screen.
fn belt_error_text(e: BeltError) -> &'static str {
    match e {
        BeltError::Range(field) => field.text(),
        _ => "Parameters rejected",
    }
}

/// The screen's message when the placement is changed with the drum or the
/// motors running (both machines).
pub const PLACEMENT_WHILE_RUNNING: &str = "Stop first to change the placement";

/// The screen's message when profile B gets a command of profile A's drum
/// (page 9's *Identify* and *Save*, page 10's link settings).
pub const DRUM_MACHINE_ONLY: &str = "Drum machine (profile A) only";

/// The screen's message after *New roll* (page 7): the roller turn count
/// starts again.
pub const NEW_ROLL_DONE: &str = "New roll: turns j = 0";

/// The screen's message when *New roll* is pressed with the motors running.
pub const NEW_ROLL_WHILE_RUNNING: &str = "Stop the motors before a new roll";

/// The screen's message when profile A gets a command of profile B's belt
/// (page 7's *New roll*).
pub const BELT_MACHINE_ONLY: &str = "Belt machine (profile B) only";

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
            // The work switch (profile A only, issue 19): kept and saved
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

/// One of the two machines.
#[allow(clippy::large_enum_variant)]
pub enum Machine {
    /// Profile A: the drum-belt transplanter.
    DrumBelt(Supervisor),
    /// Profile B: the seedling-belt planter.
    SeedlingBelt(BeltMachine),
}

impl Machine {
    /// The settings in force.
    pub fn settings(&self) -> &Settings {
        match self {
            Self::DrumBelt(m) => m.settings(),
            Self::SeedlingBelt(m) => m.settings(),
        }
    }

    /// Applies one operator command.
    pub fn command(&mut self, cmd: Command) -> Effect {
        match self {
            Self::DrumBelt(m) => m.command(cmd),
            Self::SeedlingBelt(m) => m.command(cmd),
        }
    }

    /// The settings as the screen shows them.
    pub fn screen_settings(&self) -> screen::Settings {
        match self {
            Self::DrumBelt(m) => m.screen_settings(),
            Self::SeedlingBelt(m) => m.screen_settings(),
        }
    }

    /// The live values as the screen shows them.
    pub fn screen_status(&self) -> screen::Status {
        match self {
            Self::DrumBelt(m) => m.screen_status(),
            Self::SeedlingBelt(m) => m.screen_status(),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::profile_b::ProfileBHardware;
    use crate::settings::Profile;

    #[test]
    fn the_screens_belt_defaults_are_the_kinematics_defaults() {
        // hmi-proto writes profile B's defaults as scaled integers (it does
        // not depend on kinematics); they must be ProfileBSettings::default().
        assert_eq!(
            belt_to_screen(&ProfileBConfig::default()),
            screen::BeltSettings::default()
        );
    }

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

    #[test]
    fn each_screen_parameter_lands_in_its_field_and_reads_back() {
        let c = ProfileBConfig::default();
        let set = |cmd| belt_with(&c, cmd).unwrap().unwrap();
        // r = 30.0 mm entered as 300 (0.1 mm).
        let r = set(Command::SetRollerRadius(
            screen::RollerRadius::new(300).unwrap(),
        ));
        assert_eq!(belt_to_screen(&r).roller_radius.raw(), 300);
        assert!((r.settings().roller_radius.to_f64() - 0.030).abs() < 1e-6);
        // h = 2.50 mm entered as 250 (0.01 mm).
        let h = set(Command::SetBeltThickness(
            screen::BeltThickness::new(250).unwrap(),
        ));
        assert_eq!(belt_to_screen(&h).belt_thickness.raw(), 250);
        // Y = 35 mm/s.
        let y = set(Command::SetSpeedThreshold(
            screen::SpeedThreshold::new(35).unwrap(),
        ));
        assert_eq!(belt_to_screen(&y).speed_threshold.raw(), 35);
        // X = 40 cm, B = 12 cm, β = 90°, N = 3.
        let x = set(Command::SetBeltSpacing(
            screen::BeltSpacing::new(400).unwrap(),
        ));
        assert_eq!(belt_to_screen(&x).spacing.raw(), 400);
        let b = set(Command::SetSeedlingPitch(
            screen::SeedlingPitch::new(120).unwrap(),
        ));
        assert_eq!(belt_to_screen(&b).seedling_pitch.raw(), 120);
        let a = set(Command::SetClampAngle(screen::ClampAngle::new(90).unwrap()));
        assert_eq!(belt_to_screen(&a).clamp_angle.raw(), 90);
        let n = set(Command::SetClampCount(screen::ClampCount::new(3).unwrap()));
        assert_eq!(belt_to_screen(&n).clamp_count.raw(), 3);
        // Not a profile B parameter.
        assert!(belt_with(&c, Command::Start).is_none());
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

    /// On profile B, page 6's *Drive* shows pages 9 and 10 (profile A's
    /// drum drive). Their commands must be refused with a message, not
    /// ignored: measured before the fix, *Identify* did nothing and said
    /// nothing, and a link value left the screen's "Save, then restart to
    /// apply" standing while it was dropped (not in the settings saved).
    #[test]
    fn profile_b_refuses_the_drum_pages_commands_with_a_message() {
        let settings = Settings {
            profile: Profile::SeedlingBelt,
            ..Settings::default()
        };
        let mut m = BeltMachine::new(settings.clone(), ProfileBHardware::BOARD).unwrap();
        for cmd in [
            Command::IdentifyDrive,
            Command::AcceptDriveModel,
            Command::SelectLinkParameter(screen::LinkParameter::Slave),
            Command::SetLinkValue(5),
        ] {
            assert_eq!(
                m.command(cmd),
                Effect::Message(DRUM_MACHINE_ONLY),
                "{cmd:?}"
            );
        }
        assert!(DRUM_MACHINE_ONLY.len() <= hmi_proto::MAX_TEXT_LEN);
        assert_eq!(m.settings(), &settings);
    }

    #[test]
    fn the_placement_changes_only_stopped_on_both_machines() {
        use crate::settings::Placement;
        // Profile A: refused while the drum runs, nothing changed.
        let mut a =
            crate::control::Supervisor::new(crate::control::Hardware::BOARD, Settings::default())
                .unwrap();
        assert_eq!(a.command(Command::Start), Effect::None);
        assert_eq!(
            a.command(Command::SetSpeedFollowing(true)),
            Effect::Message(PLACEMENT_WHILE_RUNNING)
        );
        assert_eq!(a.settings().placement, Placement::DistanceLocked);
        a.command(Command::Stop);
        assert_eq!(
            a.command(Command::SetSpeedFollowing(true)),
            Effect::SettingsChanged
        );
        assert_eq!(a.settings().placement, Placement::SpeedFollowing);
        assert!(a.screen_settings().speed_following);
        // Profile B: the same rule, and the position lock follows.
        let settings = Settings {
            profile: Profile::SeedlingBelt,
            ..Settings::default()
        };
        let mut b = BeltMachine::new(settings, ProfileBHardware::BOARD).unwrap();
        assert!(b.planter.position_lock());
        assert_eq!(b.command(Command::Start), Effect::None);
        assert_eq!(
            b.command(Command::SetSpeedFollowing(true)),
            Effect::Message(PLACEMENT_WHILE_RUNNING)
        );
        assert!(b.planter.position_lock());
        b.command(Command::Stop);
        assert_eq!(
            b.command(Command::SetSpeedFollowing(true)),
            Effect::SettingsChanged
        );
        assert!(!b.planter.position_lock());
        assert!(b.screen_settings().speed_following);
        assert_eq!(
            b.command(Command::SetSpeedFollowing(false)),
            Effect::SettingsChanged
        );
        assert!(b.planter.position_lock());
        assert_eq!(b.settings().placement, Placement::DistanceLocked);
    }

    #[test]
    fn profile_b_refuses_changes_and_saving_while_running() {
        let settings = Settings {
            profile: Profile::SeedlingBelt,
            ..Settings::default()
        };
        let mut m = BeltMachine::new(settings, ProfileBHardware::BOARD).unwrap();
        assert_eq!(m.command(Command::Start), Effect::None);
        let x = screen::BeltSpacing::new(300).unwrap();
        assert_eq!(
            m.command(Command::SetBeltSpacing(x)),
            Effect::Message("Stop the motors first")
        );
        assert!(matches!(
            m.command(Command::SaveSettings),
            Effect::Message(_)
        ));
        m.command(Command::Stop);
        assert_eq!(
            m.command(Command::SetBeltSpacing(x)),
            Effect::SettingsChanged
        );
        assert_eq!(m.screen_settings().belt.spacing.raw(), 300);
        assert_eq!(m.command(Command::SaveSettings), Effect::Save);
        assert_eq!(
            m.command(Command::SelectProfile(MachineProfile::DrumBelt)),
            Effect::None
        );
        assert_eq!(m.settings().profile, Profile::DrumBelt);
    }
}
