//! The settings flash stand-in: a host file through semihosting.

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

use crate::board::{
    check_flash_access, check_flash_erase, FlashError, SETTINGS_FLASH_BYTES, SETTINGS_PAGE_BYTES,
};

use super::sh;

/// Where the settings store's two pages start in [`SettingsFlash`] (the
/// host file holds just those pages, the real board's 0x0801E000).
pub const SETTINGS_BASE: u32 = 0;

/// This board has no earlier layout's settings to move.
pub const OLD_SETTINGS_BASE: Option<u32> = None;

/// The pages [`SettingsFlash`] reaches.
#[allow(clippy::single_range_in_vec_init)] // one window, the file's two pages
const SETTINGS_WINDOWS: [core::ops::Range<u32>; 1] = [0..SETTINGS_FLASH_BYTES];

/// The settings flash stand-in: a host file through semihosting, with the
/// F103's NOR rules enforced (erase to 0xFF in 1 KB pages, programming in
/// half-words onto erased half-words only).
pub struct SettingsFlash {
    pub(super) handle: usize,
}

impl SettingsFlash {
    /// Opens (or creates, erased) the host file that backs the stand-in.
    pub(super) fn open(path: &[u8]) -> Option<Self> {
        // Mode 3 = "r+b"; mode 7 = "w+b" (create).
        if let Some(handle) = sh::open(path, 3, None) {
            if sh::flen(handle) == SETTINGS_FLASH_BYTES as usize {
                return Some(Self { handle });
            }
        }
        let handle = sh::open(path, 7, None)?;
        let erased = [0xFFu8; 256];
        for _ in 0..(SETTINGS_FLASH_BYTES / 256) {
            if !sh::write(handle, &erased) {
                return None;
            }
        }
        defmt::info!("settings flash stand-in created (erased)");
        Some(Self { handle })
    }
}

impl ErrorType for SettingsFlash {
    type Error = FlashError;
}

impl ReadNorFlash for SettingsFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 1, &SETTINGS_WINDOWS)?;
        if sh::seek(self.handle, offset) && sh::read(self.handle, bytes) {
            Ok(())
        } else {
            Err(FlashError::Device)
        }
    }

    fn capacity(&self) -> usize {
        SETTINGS_FLASH_BYTES as usize
    }
}

impl NorFlash for SettingsFlash {
    const WRITE_SIZE: usize = 2;
    const ERASE_SIZE: usize = SETTINGS_PAGE_BYTES as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_flash_erase(from, to, &SETTINGS_WINDOWS)?;
        let erased = [0xFFu8; 256];
        let mut at = from;
        while at < to {
            if !(sh::seek(self.handle, at) && sh::write(self.handle, &erased)) {
                return Err(FlashError::Device);
            }
            at += 256;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 2, &SETTINGS_WINDOWS)?;
        // Check erased first, like the F103 refuses to program over data.
        let mut at = offset;
        for chunk in bytes.chunks(64) {
            let mut old = [0u8; 64];
            let old = old.get_mut(..chunk.len()).ok_or(FlashError::OutOfBounds)?;
            self.read(at, old)?;
            if old.iter().any(|&b| b != 0xFF) {
                return Err(FlashError::NotErased);
            }
            if !(sh::seek(self.handle, at) && sh::write(self.handle, chunk)) {
                return Err(FlashError::Device);
            }
            at += chunk.len() as u32;
        }
        Ok(())
    }
}
