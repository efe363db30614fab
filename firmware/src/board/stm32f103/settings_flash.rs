//! The settings pages of the MCU's own flash as a NOR flash.

use super::*;

/// Where the settings store's two pages start, from the start of flash:
/// 0x0801E000, the first pages of the last 8 KB of the 128 KB
/// (memory-stm32f103.x).
pub const SETTINGS_BASE: u32 = 0x1_E000;
/// Where images of the earlier layout kept them: 0x0800E000 (moved once
/// at boot, `supervisor::migrate`; no loaded byte of this image falls on
/// those two pages).
pub const OLD_SETTINGS_BASE: Option<u32> = Some(0xE000);
/// The pages [`SettingsFlash`] reaches: the store's and the old store's.
pub(super) const SETTINGS_WINDOWS: [core::ops::Range<u32>; 2] = [
    SETTINGS_BASE..SETTINGS_BASE + SETTINGS_FLASH_BYTES,
    0xE000..0xE000 + SETTINGS_FLASH_BYTES,
];
/// The flash the HAL's writer may reach: all 128 KB.
pub(super) const FLASH_SIZE: FlashSize = FlashSize::Sz128K;
/// The MCU's own flash as a NOR flash (offsets from 0x08000000) that reaches
/// the settings pages only ([`SETTINGS_WINDOWS`]).
pub struct SettingsFlash {
    pub(super) flash: flash::Parts,
}

impl ErrorType for SettingsFlash {
    type Error = FlashError;
}

impl ReadNorFlash for SettingsFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 1, &SETTINGS_WINDOWS)?;
        let writer = self.flash.writer(SectorSize::Sz1K, FLASH_SIZE);
        let data = writer
            .read(offset, bytes.len())
            .map_err(|_| FlashError::Device)?;
        bytes.copy_from_slice(data);
        Ok(())
    }

    fn capacity(&self) -> usize {
        128 * 1024
    }
}

impl NorFlash for SettingsFlash {
    const WRITE_SIZE: usize = 2;
    const ERASE_SIZE: usize = SETTINGS_PAGE_BYTES as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_flash_erase(from, to, &SETTINGS_WINDOWS)?;
        let mut writer = self.flash.writer(SectorSize::Sz1K, FLASH_SIZE);
        writer
            .erase(from, (to - from) as usize)
            .map_err(|_| FlashError::Device)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 2, &SETTINGS_WINDOWS)?;
        let mut writer = self.flash.writer(SectorSize::Sz1K, FLASH_SIZE);
        writer.write(offset, bytes).map_err(|_| FlashError::Device)
    }
}
