//! One image per machine: the real board is flashed with a profile A image
//! or a profile B image, never both (docs/firmware.md, "One image per
//! machine"). These tests build the QEMU board the same way — one machine
//! per image — and check what a machine builder meets when image and
//! machine disagree: the image refuses the other machine on the screen and
//! in the log, keeps a saved record of the other machine untouched, and a
//! profile B image starts as profile B on its first boot.
//!
//! Expected texts are the firmware's screen contract (docs/hmi.md); the
//! saved record is compared byte for byte with the flash file before the
//! boot, never with a constant.

use std::path::{Path, PathBuf};
use std::time::Duration;

use qemu_tests::{Bench, BootOptions, Image};

/// The mode page of profile A and the home page of profile B
/// (hmi_proto::screen::Page).
const MODE_PAGE: u8 = 1;
const PROFILE_B_HOME_PAGE: u8 = 7;

fn flash_file(name: &str) -> PathBuf {
    let path = std::env::temp_dir().join(format!("transplanter-{name}-{}.bin", std::process::id()));
    let _ = std::fs::remove_file(&path);
    path
}

fn boot(image: Image, scenario: &[&str], flash: &Path, run_ms: u32) -> Bench {
    let options = BootOptions {
        run_ms: Some(run_ms),
        flash: Some(flash.to_path_buf()),
        scenario: scenario.iter().map(|s| s.to_string()).collect(),
        ..BootOptions::default()
    };
    Bench::boot_image(image, &options).expect("boot QEMU")
}

fn wait_page(bench: &mut Bench, page: u8) {
    assert!(
        bench
            .pump_until(Duration::from_secs(5), |s| s.page() == page)
            .unwrap(),
        "the screen never reached page {page} (it shows page {}); log:\n{}",
        bench.screen.page(),
        bench.fw.logs().join("\n")
    );
}

fn wait_message(bench: &mut Bench, text: &str) {
    assert!(
        bench
            .pump_until(Duration::from_secs(2), |s| s.text("tmsg") == Some(text))
            .unwrap(),
        "tmsg: {:?}, expected {text:?}",
        bench.screen.text("tmsg")
    );
}

#[test]
fn a_profile_a_image_refuses_profile_b_on_the_screen_and_in_the_log() {
    let flash = flash_file("a-only-select");
    let mut bench = boot(Image::ProfileAOnly, &[], &flash, 20_000);
    wait_page(&mut bench, MODE_PAGE);
    bench.tap("bset").unwrap();
    assert!(
        bench
            .pump_until(Duration::from_secs(2), |s| s
                .text("tprofile")
                .is_some_and(|t| t.starts_with('A')))
            .unwrap(),
        "tprofile: {:?}",
        bench.screen.text("tprofile")
    );
    // The profile button steps A → B; this image has no B.
    bench.tap("bprofile").unwrap();
    wait_message(&mut bench, "This firmware runs profile A only");
    // The selector is put back to the machine that runs.
    assert!(
        bench
            .screen
            .text("tprofile")
            .is_some_and(|t| t.starts_with('A')),
        "tprofile: {:?}",
        bench.screen.text("tprofile")
    );
    assert!(bench
        .fw
        .wait_log(Duration::from_secs(1), |l| l
            .contains("screen message: This firmware runs profile A only"))
        .is_some());
    drop(bench);
    let _ = std::fs::remove_file(&flash);
}

#[test]
fn a_profile_a_image_keeps_a_saved_profile_b_record_and_says_so() {
    let flash = flash_file("a-only-b-record");
    // Commission profile B with the image that carries both machines.
    let mut bench = boot(Image::BothMachines, &["profile=b"], &flash, 20_000);
    wait_page(&mut bench, MODE_PAGE);
    bench.tap("bset").unwrap();
    bench.tap("bprofile").unwrap();
    assert!(bench
        .pump_until(Duration::from_secs(2), |s| s
            .text("tprofile")
            .is_some_and(|t| t.starts_with('B')))
        .unwrap());
    assert!(
        bench.save_settings().unwrap(),
        "{:?}",
        bench.screen.text("tmsg")
    );
    drop(bench);
    let saved = std::fs::read(&flash).expect("the flash file after the save");

    // Flash the profile A image onto that machine: it runs profile A,
    // stopped, says why on the screen and in the log, and writes nothing.
    let mut bench = boot(Image::ProfileAOnly, &[], &flash, 3_000);
    wait_page(&mut bench, MODE_PAGE);
    wait_message(&mut bench, "This firmware runs profile A only");
    let logs = bench.fw.logs_caught_up();
    assert!(
        logs.iter()
            .any(|l| l.contains("settings: saved profile not in this image")),
        "{logs:#?}"
    );
    bench.pump(Duration::from_millis(500)).unwrap();
    let (status, logs) = bench.fw.wait_exit(Duration::from_secs(30)).unwrap();
    assert!(status.success(), "QEMU: {status}");
    assert!(
        !logs.iter().any(|l| l.contains("settings: saved as record")),
        "the image wrote a record: {logs:#?}"
    );
    assert_eq!(
        std::fs::read(&flash).expect("the flash file after the boot"),
        saved,
        "the saved profile B record changed"
    );
    let _ = std::fs::remove_file(&flash);
}

#[test]
fn a_profile_b_image_starts_as_profile_b_on_its_first_boot() {
    // No record: the defaults of a profile B image are profile B, not a
    // refusal of profile A.
    let flash = flash_file("b-only-first-boot");
    let mut bench = boot(Image::ProfileBOnly, &["profile=b"], &flash, 20_000);
    wait_page(&mut bench, PROFILE_B_HOME_PAGE);
    bench.pump(Duration::from_millis(300)).unwrap();
    let logs = bench.fw.logs_caught_up();
    assert!(
        !logs
            .iter()
            .any(|l| l.contains("saved profile not in this image")
                || l.contains("runs profile B only")),
        "{logs:#?}"
    );
    assert_ne!(
        bench.screen.text("tmsg"),
        Some("This firmware runs profile B only")
    );
    drop(bench);
    let _ = std::fs::remove_file(&flash);
}
