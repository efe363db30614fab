//! The transmit queue bound ([`TX_CAPACITY`]): the longest burst the firmware
//! queues before it drains (a page shown, its live status written and a
//! 40-character message, nothing sent in between) must fit without a drop.
//! Measured: 379 bytes on the Adaptive page with the planting quality
//! figures and the ground's two texts (313 before the texts, 207 before the
//! figures; docs/hmi.md), so the queue holds 384.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use hmi_proto::hmi::{Hmi, TX_CAPACITY};
use hmi_proto::screen::{Page, Settings, Status};

/// A 40-character (the screen's limit) plain ASCII text.
const LONG: &str = "0123456789012345678901234567890123456789";

/// Bytes queued by `show_page` + `write_status` (every value at its widest) +
/// `show_message` (40 characters) on a connected link with a 40-character
/// version text.
fn burst(page: Page) -> (usize, u32) {
    let mut hmi = Hmi::new(Settings::default(), LONG);
    for b in [0x66, 0x00, 0xFF, 0xFF, 0xFF] {
        hmi.push(b);
    }
    assert!(hmi.is_connected());
    let mut sink = [0u8; 512];
    let _ = hmi.poll_transmit(&mut sink);
    let status = Status {
        travel_speed_kmh_x100: u16::MAX,
        target_drum_rpm_x100: u16::MAX,
        actual_drum_rpm_x100: u16::MAX,
        plants: u32::MAX,
        distance_dm: u32::MAX,
        measured_distance_cm: u32::MAX,
        calibration_result_x1000: u16::MAX,
        travel_speed_mps_x100: u16::MAX,
        plant_motor_rpm_x100: u16::MAX,
        feed_motor_rpm_x100: u16::MAX,
        roller_turns: u32::MAX,
        roller_radius_dmm: u16::MAX,
        drive_n_max_x100: u16::MAX,
        drive_tau_x10_ms: u16::MAX,
        drive_dead_time_x10_ms: u16::MAX,
        drive_identification: u8::MAX,
        quality_of_feed_x10: u16::MAX,
        multiples_x10: u16::MAX,
        misses_x10: u16::MAX,
        precision_cv_x10: u16::MAX,
        within_10_pct_x10: u16::MAX,
        plants_per_m_x100: u16::MAX,
        track_slip_x10: i16::MIN + 1,
        travel_source_in_use: hmi_proto::screen::TravelSourceInUse::HallStandIn,
    };
    let _ = hmi.show_page(page);
    let _ = hmi.write_status(&status);
    let _ = hmi.show_message(LONG);
    (hmi.tx_pending(), hmi.stats().tx_dropped)
}

#[test]
fn longest_burst_fits_the_transmit_queue() {
    let mut longest = 0;
    for page in Page::ALL {
        let (n, dropped) = burst(page);
        println!("{page:?}: {n} bytes");
        assert_eq!(dropped, 0, "{page:?}: {n} bytes > {TX_CAPACITY}");
        longest = longest.max(n);
    }
    // The figure documented in docs/hmi.md; update both if the pages change.
    assert_eq!(longest, 379);
    assert!(longest <= TX_CAPACITY);
}

/// Profile B's pages with every parameter at its widest (and profile B
/// running, so its home page is shown at connect): still below the bound.
#[test]
fn profile_b_pages_fit_with_the_widest_parameters() {
    use hmi_proto::screen::{
        BeltSettings, BeltSpacing, BeltThickness, ClampAngle, ClampCount, MachineProfile,
        RollerRadius, SeedlingPitch, SpeedThreshold,
    };
    let settings = Settings {
        profile: MachineProfile::SeedlingBelt,
        belt: BeltSettings {
            spacing: BeltSpacing::new(1000).unwrap(),
            seedling_pitch: SeedlingPitch::new(500).unwrap(),
            clamp_angle: ClampAngle::new(360).unwrap(),
            clamp_count: ClampCount::new(12).unwrap(),
            roller_radius: RollerRadius::new(1000).unwrap(),
            belt_thickness: BeltThickness::new(1000).unwrap(),
            speed_threshold: SpeedThreshold::new(200).unwrap(),
        },
        ..Settings::default()
    };
    let mut hmi = Hmi::new(settings, LONG);
    for b in [0x66, 0x00, 0xFF, 0xFF, 0xFF] {
        hmi.push(b);
    }
    assert_eq!(hmi.page(), Page::Belt);
    let mut sink = [0u8; 512];
    let _ = hmi.poll_transmit(&mut sink);
    let _ = hmi.show_page(Page::BeltParameters);
    let _ = hmi.show_message(LONG);
    let n = hmi.tx_pending();
    println!("BeltParameters (widest): {n} bytes");
    assert_eq!(hmi.stats().tx_dropped, 0);
    // The figure documented in docs/hmi.md.
    assert_eq!(n, 188);
    assert!(n < 207);
}

/// The profile refusal of a one-machine image on page 6 (the firmware's
/// `handle_event`): the screen steps the profile (its own settings update
/// and "Save, then restart…"), the firmware puts it back and says why, all
/// before the queue drains. With the work switch's two settings on page 6
/// (issue 19) the full page written twice overflowed 320 bytes and the
/// firmware's message was dropped (tests/tests/one_machine_images.rs,
/// `a_profile_a_image_refuses_profile_b_on_the_screen_and_in_the_log`);
/// `set_settings` now writes only what changed.
#[test]
fn the_profile_refusal_on_the_settings_page_fits() {
    use hmi_proto::screen::MachineProfile;
    let mut hmi = Hmi::new(Settings::default(), LONG);
    for b in [0x66, 0x00, 0xFF, 0xFF, 0xFF] {
        hmi.push(b);
    }
    let mut sink = [0u8; 512];
    let _ = hmi.show_page(Page::Settings);
    let _ = hmi.poll_transmit(&mut sink);
    let a = Settings::default();
    let b = Settings {
        profile: MachineProfile::SeedlingBelt,
        ..a
    };
    let _ = hmi.set_settings(b);
    let _ = hmi.show_message(LONG);
    let _ = hmi.set_settings(a);
    let _ = hmi.show_message(LONG);
    let n = hmi.tx_pending();
    println!("profile refusal: {n} bytes");
    assert_eq!(hmi.stats().tx_dropped, 0, "{n} bytes");
    // Two profile labels and two messages: nothing else was rewritten.
    let label = |p: MachineProfile| p.label().len() + "tprofile.txt=\"\"".len() + 3;
    let message = LONG.len() + "tmsg.txt=\"\"".len() + 3;
    assert_eq!(
        n,
        label(MachineProfile::SeedlingBelt) + label(MachineProfile::DrumBelt) + 2 * message
    );
}
