//! The boot's builders, called by `init`: the settings loaded (the earlier
//! layout's record moved first), then the machine, the screen link and the
//! drive link built in the static slots `init` owns and shares by
//! reference.

use core::mem::MaybeUninit;

use ::drive_link::link::Link;
use hmi_proto::hmi::Hmi;
use supervisor::{
    belt::BeltMachine,
    drum::Supervisor,
    machine::Machine,
    migrate::{migrate, Migration},
    planter::ProfileBHardware,
    settings::store::{LoadStatus, SettingsStore},
    settings::{Profile, Settings},
};

use crate::board;
use crate::tasks::drive_link::DriveState;
use crate::tasks::settings::Store;

/// Settings: the newest valid record (moved from where the earlier
/// layout kept it, once), or the defaults, said out loud; then the
/// machine built from them.
pub fn load_settings(
    flash: Option<board::SettingsFlash>,
    slot: &'static mut MaybeUninit<Machine>,
) -> (Option<Store>, &'static mut Machine, Option<&'static str>) {
    let mut store = flash.and_then(|flash| SettingsStore::new(flash, board::SETTINGS_BASE).ok());
    let mut notice = None;
    let (machine, machine_notice) = build_machine(slot, load_record(&mut store, &mut notice));
    (store, machine, machine_notice.or(notice))
}

/// The saved settings (the defaults without a valid record or a
/// store) and the screen's notice.
fn load_record(store: &mut Option<Store>, notice: &mut Option<&'static str>) -> Settings {
    let mut settings = Settings::default();
    let Some(store) = store.as_mut() else {
        defmt::warn!("settings: no settings store, defaults in use");
        *notice = Some("No settings store: defaults");
        return settings;
    };
    let mut status = store.load_into(&mut settings);
    if let Some(old_base) = board::OLD_SETTINGS_BASE {
        let migration;
        (status, migration) = migrate(store, old_base, status, &mut settings);
        log_migration(migration);
    }
    *notice = match status {
        LoadStatus::Saved { sequence } => {
            defmt::info!("settings: loaded record {=u32}", sequence);
            None
        }
        LoadStatus::Defaults { reason } => {
            defmt::warn!("settings: defaults in use ({})", reason);
            Some(reason.message())
        }
    };
    settings
}

/// The log line of the move of the earlier layout's settings.
fn log_migration(migration: Migration) {
    match migration {
        Migration::None => {}
        Migration::Moved { from, to } => defmt::info!(
            "settings: record {=u32} moved from the earlier layout's pages into the store as record {=u32}, old pages erased",
            from,
            to
        ),
        Migration::OldErased => {
            defmt::info!("settings: the earlier layout's settings pages erased")
        }
        Migration::Failed => defmt::warn!(
            "settings: the earlier layout's record could not be moved (flash error): in use, moved at the next boot"
        ),
    }
}

/// Builds the machine of the saved profile in its static slot; the
/// notice says why it is not the saved one.
fn build_machine(
    slot: &'static mut MaybeUninit<Machine>,
    settings: Settings,
) -> (&'static mut Machine, Option<&'static str>) {
    let profile = settings.profile;
    match build_profile(slot, settings) {
        Ok(machine) => (machine, None),
        Err(slot) => build_defaults(slot, profile),
    }
}

/// The machine with default settings, when the saved ones were
/// rejected. Only a saved record can be (the store validates what it
/// loads, so this is a last line of defence); the defaults are valid by
/// construction, a failure with them is a build-time bug, caught on the
/// first boot of any board.
fn build_defaults(
    slot: &'static mut MaybeUninit<Machine>,
    profile: Profile,
) -> (&'static mut Machine, Option<&'static str>) {
    defmt::error!("machine settings rejected, defaults in use");
    let defaults = Settings {
        profile,
        ..Settings::default()
    };
    match build_profile(slot, defaults) {
        Ok(machine) => (machine, Some("Saved settings rejected: defaults")),
        Err(_) => board::fatal(),
    }
}

/// Builds the machine of `settings.profile`; gives the slot back when
/// the settings are rejected.
fn build_profile(
    slot: &'static mut MaybeUninit<Machine>,
    settings: Settings,
) -> Result<&'static mut Machine, &'static mut MaybeUninit<Machine>> {
    match settings.profile {
        Profile::DrumBelt => {
            defmt::info!("machine: profile A, drum-belt transplanter");
            build_drum_belt(slot, settings)
        }
        Profile::SeedlingBelt => {
            defmt::info!("machine: profile B, seedling-belt planter");
            build_seedling_belt(slot, settings)
        }
    }
}

/// Profile A.
fn build_drum_belt(
    slot: &'static mut MaybeUninit<Machine>,
    settings: Settings,
) -> Result<&'static mut Machine, &'static mut MaybeUninit<Machine>> {
    match Supervisor::new(board::HARDWARE, settings) {
        Ok(sup) => Ok(slot.write(Machine::DrumBelt(sup))),
        Err(_) => Err(slot),
    }
}

/// Profile B.
fn build_seedling_belt(
    slot: &'static mut MaybeUninit<Machine>,
    settings: Settings,
) -> Result<&'static mut Machine, &'static mut MaybeUninit<Machine>> {
    match BeltMachine::new(settings, ProfileBHardware::BOARD) {
        Ok(belt) => Ok(slot.write(Machine::SeedlingBelt(belt))),
        Err(_) => Err(slot),
    }
}

/// The drum driver's link in its static slot: a Modbus master when the
/// settings name a driver (profile A only), else none.
pub fn build_drive(
    slot: &'static mut MaybeUninit<DriveState>,
    machine: &Machine,
) -> &'static mut DriveState {
    let link = match machine {
        Machine::DrumBelt(sup) => sup.settings().drive_link.config().ok().flatten(),
        Machine::SeedlingBelt(_) => None,
    };
    let link = link.map(|(p, config)| {
        defmt::info!(
            "drive link: slave {=u8} at {=u32} baud, reply timeout {=u32} us, retry gap {=u32} us, driver offline time {=u16} ms",
            p.slave,
            p.baud,
            config.reply_timeout_us,
            config.retry_gap_us,
            config.offline_time_ms
        );
        Link::new(p, config)
    });
    slot.write(DriveState {
        link,
        enabled: None,
    })
}

/// Builds the screen link in its static slot.
pub fn build_hmi(slot: &'static mut MaybeUninit<Hmi>, machine: &Machine) -> &'static mut Hmi {
    slot.write(Hmi::new(
        machine.screen_settings(),
        env!("CARGO_PKG_VERSION"),
    ))
}
