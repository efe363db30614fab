//! The real board's flash as a probe leaves it (`twin::image::programmed`),
//! with a settings record saved by the product's own store: the one image
//! runs the machine and the drum driver's link that the settings name.

use std::path::Path;

use supervisor::settings::{Profile, Settings};

/// Where the real board keeps its settings pages: the SETTINGS region of
/// firmware/memory-stm32f103.x.
pub fn settings_address() -> u32 {
    let x =
        std::fs::read_to_string(twin::image::workspace_root().join("firmware/memory-stm32f103.x"))
            .expect("read firmware/memory-stm32f103.x");
    let line = x
        .lines()
        .find(|l| l.trim_start().starts_with("SETTINGS") && l.contains("ORIGIN"))
        .expect("a SETTINGS region");
    let hex = line.split("0x").nth(1).expect("an address");
    let hex: String = hex.chars().take_while(char::is_ascii_hexdigit).collect();
    u32::from_str_radix(&hex, 16).expect("a hex address")
}

/// The settings of a seedling-belt planter (profile B), defaults otherwise.
#[allow(dead_code)] // not every test file boots profile B
pub fn profile_b() -> Settings {
    Settings {
        profile: Profile::SeedlingBelt,
        ..Settings::default()
    }
}

/// `elf` programmed onto an erased chip, and `settings` saved in the
/// board's settings pages (as a previous Save would have).
#[allow(dead_code)] // not every test file saves settings first
pub fn flash_with(elf: &Path, settings: &Settings) -> Vec<u8> {
    let mut flash = twin::image::programmed(elf, None).expect("program the image");
    let pages = crate::pages::pages_with(settings);
    let off = (settings_address() - twin::periph::FLASH_BASE) as usize;
    assert!(
        flash[off..off + pages.len()].iter().all(|&b| b == 0xFF),
        "the image overlaps the settings pages at {:#010x}",
        settings_address()
    );
    flash[off..off + pages.len()].copy_from_slice(&pages);
    flash
}
