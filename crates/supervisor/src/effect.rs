//! What the screen does after an operator command, and the messages both
//! machines give.

/// What the screen should do after a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Effect {
    /// Nothing beyond the live status.
    None,
    /// The settings shown changed (write them back to the screen).
    SettingsChanged,
    /// Persist the settings now (the drum is stopped).
    Save,
    /// Show this message in the message box.
    Message(&'static str),
    /// The alarm was acknowledged: leave the alarm page.
    AlarmCleared,
}

/// The screen's message when the placement is changed with the drum or the
/// motors running (both machines).
pub const PLACEMENT_WHILE_RUNNING: &str = "Stop first to change the placement";

/// The screen's message when machine A's travel source is changed with the
/// drum running.
pub const SOURCE_WHILE_RUNNING: &str = "Stop first to change the travel sensor";

/// The screen's message when profile B gets a command of profile A's drum
/// (page 9's *Identify* and *Save*, page 10's link settings).
pub const DRUM_MACHINE_ONLY: &str = "Drum machine (profile A) only";

/// The screen's message when profile A gets a command of profile B's belt
/// (page 7's *New roll*).
pub const BELT_MACHINE_ONLY: &str = "Belt machine (profile B) only";
