//! What a load found and why a save failed.

use core::fmt;

use embedded_storage::nor_flash::NorFlashError;

use crate::settings::Settings;

/// Why [`SettingsStore::load`](super::SettingsStore::load) fell back to the defaults; the firmware shows
/// it on the screen ([`message`](Self::message)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DefaultsReason {
    /// Both slots erased: first boot.
    Blank,
    /// No slot holds a complete record with a good CRC and valid fields
    /// (bit rot, or the very first save was interrupted).
    Corrupt,
    /// The only intact records have a settings version this firmware does not
    /// read (written by a newer firmware).
    UnsupportedVersion,
    /// Reading the flash failed.
    FlashError,
}

impl DefaultsReason {
    /// Short ASCII message (≤ 40 characters) for the screen.
    #[must_use]
    pub const fn message(self) -> &'static str {
        match self {
            Self::Blank => "No saved settings: defaults",
            Self::Corrupt => "Saved settings corrupt: defaults",
            Self::UnsupportedVersion => "Settings from newer firmware: defaults",
            Self::FlashError => "Flash read error: defaults",
        }
    }
}

impl fmt::Display for DefaultsReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.message())
    }
}

/// What [`SettingsStore::load_into`](super::SettingsStore::load_into) put into the caller's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadStatus {
    /// The newest valid record, of this sequence number.
    Saved {
        /// Its sequence number.
        sequence: u32,
    },
    /// No valid record: [`Settings::default`], and why.
    Defaults {
        /// Why (shown on the screen).
        reason: DefaultsReason,
    },
}

/// What [`SettingsStore::load`](super::SettingsStore::load) found.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Loaded {
    /// The newest valid record.
    Saved {
        /// The stored settings.
        settings: Settings,
        /// Its sequence number.
        sequence: u32,
    },
    /// No valid record: [`Settings::default`], and why.
    Defaults {
        /// [`Settings::default`].
        settings: Settings,
        /// Why (shown on the screen).
        reason: DefaultsReason,
    },
}

impl Loaded {
    /// The settings to run with.
    #[must_use]
    pub fn settings(&self) -> &Settings {
        match self {
            Self::Saved { settings, .. } | Self::Defaults { settings, .. } => settings,
        }
    }

    /// The settings to run with, by value.
    #[must_use]
    pub fn into_settings(self) -> Settings {
        match self {
            Self::Saved { settings, .. } | Self::Defaults { settings, .. } => settings,
        }
    }

    /// `Some(reason)` when the defaults were loaded.
    #[must_use]
    pub fn defaults_reason(&self) -> Option<DefaultsReason> {
        match self {
            Self::Saved { .. } => None,
            Self::Defaults { reason, .. } => Some(*reason),
        }
    }
}

/// What one slot holds (diagnostics: [`SettingsStore::slots`](super::SettingsStore::slots)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SlotStatus {
    /// Erased over the whole record extent.
    Blank,
    /// Something, but not a complete valid record (interrupted save, bit rot).
    Corrupt,
    /// A complete record (magic, commit, CRC good) whose settings version
    /// this firmware does not read.
    UnsupportedVersion {
        /// Its sequence number.
        sequence: u32,
    },
    /// A valid record.
    Valid {
        /// Its sequence number.
        sequence: u32,
    },
    /// Reading the page failed.
    FlashError,
}

/// A failed [`SettingsStore::new`](super::SettingsStore::new) or [`SettingsStore::save`](super::SettingsStore::save).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError<E> {
    /// The flash driver failed (program error, alignment, bounds …).
    Flash(E),
    /// `base_offset` is not a multiple of `ERASE_SIZE`.
    Misaligned,
    /// The two pages do not fit in the flash.
    OutOfBounds,
    /// `READ_SIZE` or `WRITE_SIZE` is not a power of two ≤
    /// [`MAX_ACCESS_SIZE`](super::MAX_ACCESS_SIZE), or a page is too small for a record.
    UnsupportedGeometry,
    /// The data read back after programming differs from what was written;
    /// the record was not committed (or, after the commit, does not check).
    Verify,
}

impl<E> StoreError<E> {
    /// Short ASCII message (≤ 40 characters) for the screen.
    #[must_use]
    pub const fn message(&self) -> &'static str {
        match self {
            Self::Flash(_) => "Save failed: flash error",
            Self::Misaligned | Self::OutOfBounds | Self::UnsupportedGeometry => {
                "Save failed: bad flash layout"
            }
            Self::Verify => "Save failed: verify error",
        }
    }
}

impl<E: NorFlashError> fmt::Display for StoreError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Flash(e) => write!(f, "flash error: {}", e.kind()),
            Self::Misaligned => f.write_str("store base is not page aligned"),
            Self::OutOfBounds => f.write_str("store pages lie outside the flash"),
            Self::UnsupportedGeometry => f.write_str("unsupported flash geometry"),
            Self::Verify => f.write_str("flash read-back differs from the data programmed"),
        }
    }
}

impl<E> From<E> for StoreError<E> {
    fn from(e: E) -> Self {
        Self::Flash(e)
    }
}
