//! The machine the firmware runs, chosen once at start-up from the saved
//! settings: profile A ([`Supervisor`]) or profile B ([`BeltMachine`]).
//!
//! A machine builder sets the profile once, on the settings page: the two
//! profiles drive different motors from the same pins (the drum's PWM timer
//! becomes the planting stepper's pulse timer), so a change takes effect
//! after Save and a restart, never while motors may run.

use hmi_proto::screen::{self, Command};

use crate::belt::BeltMachine;
use crate::drum::Supervisor;
use crate::effect::Effect;
use crate::settings::Settings;

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
    use crate::effect::{DRUM_MACHINE_ONLY, PLACEMENT_WHILE_RUNNING};
    use crate::planter::ProfileBHardware;
    use crate::settings::Profile;
    use hmi_proto::screen::MachineProfile;

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
        let mut a = crate::drum::Supervisor::new(crate::drum::Hardware::BOARD, Settings::default())
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
        assert!(b.planter().position_lock());
        assert_eq!(b.command(Command::Start), Effect::None);
        assert_eq!(
            b.command(Command::SetSpeedFollowing(true)),
            Effect::Message(PLACEMENT_WHILE_RUNNING)
        );
        assert!(b.planter().position_lock());
        b.command(Command::Stop);
        assert_eq!(
            b.command(Command::SetSpeedFollowing(true)),
            Effect::SettingsChanged
        );
        assert!(!b.planter().position_lock());
        assert!(b.screen_settings().speed_following);
        assert_eq!(
            b.command(Command::SetSpeedFollowing(false)),
            Effect::SettingsChanged
        );
        assert!(b.planter().position_lock());
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
