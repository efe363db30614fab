//! The board's settings pages (2 KB: two 1 KB pages, the board's
//! `SETTINGS_FLASH_BYTES`) as a NOR flash for the supervisor's own store:
//! the QEMU and twin tests that boot on saved settings write their record
//! with the product's store, as a previous Save would have.

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};
use supervisor::settings::store::SettingsStore;
use supervisor::settings::Settings;

/// The two pages in memory (erased: 0xFF; programming clears bits).
struct Pages(Vec<u8>);

impl ErrorType for Pages {
    type Error = NorFlashErrorKind;
}

impl ReadNorFlash for Pages {
    const READ_SIZE: usize = 1;
    fn read(&mut self, off: u32, buf: &mut [u8]) -> Result<(), Self::Error> {
        let o = off as usize;
        buf.copy_from_slice(&self.0[o..o + buf.len()]);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.0.len()
    }
}

impl NorFlash for Pages {
    const WRITE_SIZE: usize = 2;
    const ERASE_SIZE: usize = 1024;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0[from as usize..to as usize].fill(0xFF);
        Ok(())
    }
    fn write(&mut self, off: u32, data: &[u8]) -> Result<(), Self::Error> {
        for (d, s) in self.0[off as usize..].iter_mut().zip(data) {
            *d &= *s;
        }
        Ok(())
    }
}

/// The pages holding `settings` as one saved record.
pub fn pages_with(settings: &Settings) -> Vec<u8> {
    let mut store = SettingsStore::new(Pages(vec![0xFF; 2048]), 0).unwrap();
    store.save(settings).unwrap();
    store.into_inner().0
}

/// The settings the store on `pages` (two 1 KB pages) loads, if it holds a
/// valid record.
#[allow(dead_code)] // not every test file reads pages back
pub fn saved_in(pages: &[u8]) -> Option<Settings> {
    let mut store = SettingsStore::new(Pages(pages.to_vec()), 0).unwrap();
    match store.load() {
        supervisor::settings::store::Loaded::Saved { settings, .. } => Some(settings),
        supervisor::settings::store::Loaded::Defaults { .. } => None,
    }
}
