//! Settings kept where an earlier flash layout kept them, moved once into
//! the store in force.
//!
//! Boards flashed with the earlier layout keep their settings store at
//! another place in flash (the real board's 0x0800E000; docs/settings-store.md,
//! "Layout and migration"). At boot, [`migrate`] runs after the store in
//! force was loaded:
//!
//! - the store in force holds no valid record (blank, or a first save cut
//!   short) and the old store holds one: that record is saved into the
//!   store in force through [`SettingsStore::save`] (today's format; a cut
//!   leaves the store in force without a valid record, so the next boot
//!   moves the old record again), then the old slots are erased, so that
//!   it happens once;
//! - the store in force holds a valid record and the old slots are not
//!   blank (a move cut short after its save, or bytes another image left
//!   there): the old slots are erased;
//! - otherwise nothing is written.
//!
//! A power cut at any step therefore leaves either the old record, moved
//! again at the next boot, or the moved one in force: never the defaults,
//! never a mix.

use embedded_storage::nor_flash::NorFlash;

use crate::settings::store::{DefaultsReason, LoadStatus, SettingsStore, SlotStatus};
use crate::settings::Settings;

/// What [`migrate`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Migration {
    /// Nothing: no old record to move, and the old slots blank.
    None,
    /// The old store's record `from` was saved as record `to` of the store
    /// in force, and the old slots erased.
    Moved {
        /// Its sequence number in the old store.
        from: u32,
        /// Its sequence number in the store in force.
        to: u32,
    },
    /// The store in force already held a record; the old slots were not
    /// blank and are erased now.
    OldErased,
    /// The old record is in use but could not be saved into the store in
    /// force, or the old slots could not be erased: tried again at the next
    /// boot.
    Failed,
}

/// Completes the load of `store` (`loaded`, what [`SettingsStore::load_into`]
/// put into `settings`) with the store on the two pages at `old_base` of
/// the same flash, as the module describes; returns the load status in
/// force (a moved record's sequence in the store in force) and what it did.
pub fn migrate<F: NorFlash>(
    store: &mut SettingsStore<F>,
    old_base: u32,
    loaded: LoadStatus,
    settings: &mut Settings,
) -> (LoadStatus, Migration) {
    match loaded {
        LoadStatus::Saved { .. } => {
            let Ok(mut old) = SettingsStore::new(store.flash_mut(), old_base) else {
                return (loaded, Migration::None);
            };
            if old.slots() == [SlotStatus::Blank, SlotStatus::Blank] {
                (loaded, Migration::None)
            } else if old.erase().is_ok() {
                (loaded, Migration::OldErased)
            } else {
                (loaded, Migration::Failed)
            }
        }
        LoadStatus::Defaults {
            reason: DefaultsReason::Blank | DefaultsReason::Corrupt,
        } => {
            let from = match SettingsStore::new(store.flash_mut(), old_base) {
                Ok(mut old) => match old.load_into(settings) {
                    LoadStatus::Saved { sequence } => sequence,
                    LoadStatus::Defaults { .. } => return (loaded, Migration::None),
                },
                Err(_) => return (loaded, Migration::None),
            };
            let Ok(to) = store.save(settings) else {
                return (LoadStatus::Saved { sequence: from }, Migration::Failed);
            };
            let erased = SettingsStore::new(store.flash_mut(), old_base)
                .and_then(|mut old| old.erase())
                .is_ok();
            let done = if erased {
                Migration::Moved { from, to }
            } else {
                Migration::Failed
            };
            (LoadStatus::Saved { sequence: to }, done)
        }
        // Records of a newer firmware, or a flash that cannot be read:
        // nothing is moved over them.
        LoadStatus::Defaults { .. } => (loaded, Migration::None),
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation
)]
mod tests {
    use super::*;
    use embedded_storage::nor_flash::{ErrorType, NorFlashErrorKind, ReadNorFlash};
    use hmi_proto::screen::Spacing;
    use std::vec;
    use std::vec::Vec;

    const PAGE: usize = 1024;
    /// The old store's pages, then a gap, then the store in force's.
    const OLD: u32 = 0;
    const NEW: u32 = 4 * PAGE as u32;

    /// RAM flash with the F1's rules (a program only clears bits) that
    /// stops working after `budget` erases and programs: a power cut.
    struct Flash {
        bytes: Vec<u8>,
        budget: Option<usize>,
    }

    impl Flash {
        fn spend(&mut self) -> Result<(), NorFlashErrorKind> {
            match &mut self.budget {
                Some(0) => Err(NorFlashErrorKind::Other),
                Some(n) => {
                    *n -= 1;
                    Ok(())
                }
                None => Ok(()),
            }
        }
    }

    impl ErrorType for Flash {
        type Error = NorFlashErrorKind;
    }

    impl ReadNorFlash for Flash {
        const READ_SIZE: usize = 1;
        fn read(&mut self, off: u32, buf: &mut [u8]) -> Result<(), Self::Error> {
            let o = off as usize;
            buf.copy_from_slice(&self.bytes[o..o + buf.len()]);
            Ok(())
        }
        fn capacity(&self) -> usize {
            self.bytes.len()
        }
    }

    impl NorFlash for Flash {
        const WRITE_SIZE: usize = 2;
        const ERASE_SIZE: usize = PAGE;
        fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
            self.spend()?;
            self.bytes[from as usize..to as usize].fill(0xFF);
            Ok(())
        }
        fn write(&mut self, off: u32, data: &[u8]) -> Result<(), Self::Error> {
            // One step per half-word, as the F1 programs.
            for (i, pair) in data.chunks(2).enumerate() {
                self.spend()?;
                for (j, b) in pair.iter().enumerate() {
                    self.bytes[off as usize + 2 * i + j] &= b;
                }
            }
            Ok(())
        }
    }

    fn old_settings() -> Settings {
        Settings {
            spacing: Spacing::new(150).unwrap(),
            ..Settings::default()
        }
    }

    /// A board of the earlier layout: two records in the old store (the
    /// newer one `old_settings`), the store in force blank.
    fn earlier_board() -> Vec<u8> {
        let mut old = SettingsStore::new(
            Flash {
                bytes: vec![0xFF; 6 * PAGE],
                budget: None,
            },
            OLD,
        )
        .unwrap();
        old.save(&Settings::default()).unwrap();
        old.save(&old_settings()).unwrap();
        old.into_inner().bytes
    }

    /// One boot: load the store in force, migrate; the settings in force.
    fn boot(bytes: Vec<u8>, budget: Option<usize>) -> (Vec<u8>, LoadStatus, Migration, Settings) {
        let mut store = SettingsStore::new(Flash { bytes, budget }, NEW).unwrap();
        let mut settings = Settings::default();
        let loaded = store.load_into(&mut settings);
        let (status, done) = migrate(&mut store, OLD, loaded, &mut settings);
        (store.into_inner().bytes, status, done, settings)
    }

    fn blank(bytes: &[u8], base: u32) -> bool {
        bytes[base as usize..base as usize + 2 * PAGE]
            .iter()
            .all(|&b| b == 0xFF)
    }

    #[test]
    fn the_old_record_is_moved_once_and_the_old_slots_erased() {
        let (bytes, status, done, settings) = boot(earlier_board(), None);
        assert_eq!(done, Migration::Moved { from: 2, to: 1 });
        assert_eq!(status, LoadStatus::Saved { sequence: 1 });
        assert_eq!(settings, old_settings());
        assert!(blank(&bytes, OLD));
        // The next boot loads it and writes nothing.
        let (after, status, done, settings) = boot(bytes.clone(), Some(0));
        assert_eq!(
            (status, done),
            (LoadStatus::Saved { sequence: 1 }, Migration::None)
        );
        assert_eq!(settings, old_settings());
        assert_eq!(after, bytes);
    }

    #[test]
    fn a_blank_board_keeps_its_defaults_and_nothing_is_written() {
        let (bytes, status, done, settings) = boot(vec![0xFF; 6 * PAGE], Some(0));
        assert_eq!(
            (status, done),
            (
                LoadStatus::Defaults {
                    reason: DefaultsReason::Blank
                },
                Migration::None
            )
        );
        assert_eq!(settings, Settings::default());
        assert!(bytes.iter().all(|&b| b == 0xFF));
    }

    /// Garbage in the old pages (another image's code) under a store in
    /// force with a record: erased once, the record in force kept.
    #[test]
    fn other_bytes_on_the_old_pages_are_erased_under_a_valid_store() {
        let mut bytes = vec![0xFF; 6 * PAGE];
        for (i, b) in bytes[..2 * PAGE].iter_mut().enumerate() {
            *b = (i * 7 + 3) as u8;
        }
        let mut store = SettingsStore::new(
            Flash {
                bytes,
                budget: None,
            },
            NEW,
        )
        .unwrap();
        store.save(&old_settings()).unwrap();
        let (bytes, status, done, settings) = boot(store.into_inner().bytes, None);
        assert_eq!(
            (status, done),
            (LoadStatus::Saved { sequence: 1 }, Migration::OldErased)
        );
        assert_eq!(settings, old_settings());
        assert!(blank(&bytes, OLD));
    }

    /// A power cut before every erase and program of the move: the next
    /// boot (uncut) runs the old record, moved or to be moved, never the
    /// defaults; the end state is the moved record and blank old slots.
    #[test]
    fn a_power_cut_at_every_step_of_the_move_leaves_old_or_moved() {
        let mut steps = 0;
        loop {
            let (cut, _, done, _) = boot(earlier_board(), Some(steps));
            if done != Migration::Failed && steps > 0 {
                // The budget outlasted the move: every step was cut once.
                break;
            }
            let (after, status, _, settings) = boot(cut, None);
            assert!(
                matches!(status, LoadStatus::Saved { .. }),
                "cut before step {steps}: {status:?}"
            );
            assert_eq!(settings, old_settings(), "cut before step {steps}");
            assert!(blank(&after, OLD), "cut before step {steps}");
            let (_, again, done, settings) = boot(after, Some(0));
            assert_eq!(done, Migration::None, "cut before step {steps}");
            assert!(matches!(again, LoadStatus::Saved { .. }));
            assert_eq!(settings, old_settings());
            steps += 1;
        }
        // One erase and 170 programs for the save (the 317-byte record's
        // 340 bytes, store layout), two erases after it.
        assert_eq!(steps, 173);
    }
}
