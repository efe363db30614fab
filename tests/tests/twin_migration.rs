//! A board flashed with the earlier layout, whose settings store sat at
//! 0x0800E000, gets today's image: flashed the way probe-rs and cargo-flash
//! do it (every 1 KB page a loadable segment of the ELF covers is erased and
//! programmed, every other page keeps its bytes: `twin::image::programmed`),
//! it boots on the saved settings, moved once into the store at 0x0801E000
//! with the old pages erased; and a power cut at every flash step of that
//! move boots the saved settings again — moved, or to be moved — never the
//! defaults, never a mix (docs/settings-store.md, "Layout and migration").
//!
//! The saved settings are Fixed mode at 150 mm, not the defaults'
//! Speed-Adaptive at 70 mm: the status line names the ones in force.

use supervisor::settings::Settings;
use twin::{Options, Twin};

#[path = "support/board.rs"]
mod board;
#[path = "support/pages.rs"]
mod pages;

/// Where the earlier layout kept the settings store, from the start of flash.
const OLD_STORE: usize = 0xE000;

fn saved_settings() -> Settings {
    Settings {
        mode: hmi_proto::screen::Mode::Fixed,
        spacing: hmi_proto::screen::Spacing::new(150).unwrap(),
        ..Settings::default()
    }
}

/// A board of the earlier layout: its image's code everywhere that layout
/// had code (0x08000000..0x0800E000 and 0x08010000..0x0801E000: bytes that
/// are not this image's), its settings record at 0x0800E000, the last 8 KB
/// erased.
fn earlier_board() -> Vec<u8> {
    let mut flash = vec![0xFF; 128 * 1024];
    let mut x: u32 = 0x1234_5678;
    for range in [0..OLD_STORE, 0x1_0000..0x1_E000] {
        for b in &mut flash[range] {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *b = x as u8;
        }
    }
    let pages = pages::pages_with(&saved_settings());
    flash[OLD_STORE..OLD_STORE + pages.len()].copy_from_slice(&pages);
    flash
}

/// The lines of the last boot.
fn last_boot(logs: &[String]) -> Vec<String> {
    let start = logs
        .iter()
        .rposition(|l| l.contains("boot: transplanter"))
        .unwrap_or(0);
    logs[start..].to_vec()
}

/// After a boot: the saved settings in force (status line) and in the
/// store at 0x0801E000, the old pages erased.
fn check_moved(twin: &mut Twin, what: &str) {
    let logs = last_boot(&twin.logs());
    let text = logs.join("\n");
    assert!(
        !text.contains("defaults in use"),
        "{what}: defaults:\n{text}"
    );
    let status = logs
        .iter()
        .find(|l| l.contains("status: uptime"))
        .unwrap_or_else(|| panic!("{what}: no status line:\n{text}"));
    assert!(
        status.contains(" Fixed ") && status.contains("spacing 150 mm"),
        "{what}: not the saved settings: {status}"
    );
    let flash = twin.flash();
    let new = (board::settings_address() - twin::periph::FLASH_BASE) as usize;
    assert_eq!(
        pages::saved_in(&flash[new..new + 2048]),
        Some(saved_settings()),
        "{what}: the store in force"
    );
    assert!(
        flash[OLD_STORE..OLD_STORE + 2048]
            .iter()
            .all(|&b| b == 0xFF),
        "{what}: the old pages are not erased"
    );
}

#[test]
fn the_earlier_layouts_settings_are_moved_once_even_with_a_power_cut_at_every_step() {
    let elf = twin::image::elf().expect("build the real-board image");
    let before = earlier_board();
    let flash = twin::image::programmed(&elf, Some(&before)).unwrap();
    // Flashing kept the old record (no loadable byte on its pages) and
    // replaced the earlier image's code.
    assert_eq!(
        flash[OLD_STORE..OLD_STORE + 2048],
        before[OLD_STORE..OLD_STORE + 2048]
    );
    assert_ne!(flash[..OLD_STORE], before[..OLD_STORE]);

    let mut twin = Twin::new(
        &elf,
        Options {
            flash: Some(flash.clone()),
            ..Options::default()
        },
    )
    .unwrap();
    let at_power_on = twin.snapshot().unwrap();
    twin.run_ms(300).unwrap();
    check_moved(&mut twin, "uncut");
    let text = twin.logs().join("\n");
    assert!(
        text.contains("moved from the earlier layout's pages into the store as record 1"),
        "{text}"
    );
    let steps = twin.state().bus.flash.ops;
    eprintln!("the move is {steps} flash steps");
    // One page erase and 170 half-word programs for the record (format 7's
    // 340 bytes in flash), two page erases for the old pages.
    assert_eq!(steps, 173);

    // The next boot moves nothing and writes nothing.
    let moved = twin.flash();
    let mut again = Twin::new(
        &elf,
        Options {
            flash: Some(moved.clone()),
            ..Options::default()
        },
    )
    .unwrap();
    again.run_ms(300).unwrap();
    check_moved(&mut again, "second boot");
    assert_eq!(again.state().bus.flash.ops, 0);
    assert_eq!(again.flash(), moved);

    // A cut before (during, for an erase) each step, and after the last.
    for k in 0..=steps {
        twin.restore(&at_power_on).unwrap();
        if k < steps {
            twin.cut_power_at_flash_op(k, false);
        } else {
            twin.cut_power_at_flash_op(steps - 1, true);
        }
        let resets = twin.resets.len();
        let cut = twin.run_until(2000, |t| t.resets.len() > resets).unwrap();
        assert!(cut, "step {k}: the power cut never happened");
        twin.run_ms(300).unwrap();
        check_moved(&mut twin, &format!("cut at step {k}"));
    }
}
