//! Machine A's ground-wheel settings on page 6 (docs/hmi.md, page 6
//! `settings`): *Travel source* (`bsource`, id 18) and *Wheel direction*
//! (`bwdir`, id 20) change a setting of the machine, so each must come from
//! its own button's release on the page shown and from no other touch
//! frame.
//!
//! Tested exhaustively: every touch frame `65 page id event FF FF FF` — each
//! of the 256 page bytes × 256 id bytes × press and release — on a link
//! showing each of the 11 pages (1 441 792 frames). The expectation is
//! written here from docs/hmi.md's page table, not from the contract's
//! table. About a second.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use hmi_proto::hmi::{Event, Hmi};
use hmi_proto::screen::{Command, Page, Settings, TravelSource};
use hmi_proto::TouchEvent;

/// docs/hmi.md page 6: `bsource` is id 18, `bwdir` id 20.
const SETTINGS_PAGE: u8 = 6;
const BSOURCE: u8 = 18;
const BWDIR: u8 = 20;

/// A link after the handshake, showing `page` (bytes and events drained).
fn showing(page: Page, settings: Settings) -> Hmi {
    let mut hmi = Hmi::new(settings, "test");
    hmi.tick(0);
    hmi.push_slice(&[0x88, 0xFF, 0xFF, 0xFF]);
    let mut tx = [0u8; 512];
    hmi.poll_transmit(&mut tx);
    hmi.show_page(page).unwrap();
    hmi.poll_transmit(&mut tx);
    while hmi.poll_event().is_some() {}
    hmi
}

fn ground_command(e: &Event) -> bool {
    matches!(
        e,
        Event::Command(Command::SelectTravelSource(_) | Command::SetGroundWheelReversed(_))
    )
}

#[test]
fn only_their_own_release_on_the_settings_page_changes_the_ground_settings() {
    // Not the defaults, so that the command's value is checked too.
    let settings = Settings {
        travel_source: TravelSource::GroundWheel,
        ground_wheel_reversed: true,
        ..Settings::default()
    };
    let mut frames = 0u64;
    let mut wrong = Vec::new();
    for shown in Page::ALL {
        let base = showing(shown, settings);
        for page in 0..=u8::MAX {
            for id in 0..=u8::MAX {
                for event in [TouchEvent::Press, TouchEvent::Release] {
                    let mut hmi = base.clone();
                    hmi.push_slice(&[0x65, page, id, event.to_byte(), 0xFF, 0xFF, 0xFF]);
                    let mut got = Vec::new();
                    while let Some(e) = hmi.poll_event() {
                        got.push(e);
                    }
                    frames += 1;
                    let released_here = shown == Page::Settings
                        && page == SETTINGS_PAGE
                        && event == TouchEvent::Release;
                    let expected: Vec<Event> = match id {
                        BSOURCE if released_here => vec![Event::Command(
                            Command::SelectTravelSource(TravelSource::Both),
                        )],
                        BWDIR if released_here => {
                            vec![Event::Command(Command::SetGroundWheelReversed(false))]
                        }
                        _ => Vec::new(),
                    };
                    let ground: Vec<Event> = got.iter().copied().filter(ground_command).collect();
                    if ground != expected || (!expected.is_empty() && got != expected) {
                        wrong.push(format!(
                            "shown {shown:?}, frame (page {page}, id {id}, {event:?}): {got:?}"
                        ));
                    }
                }
            }
        }
    }
    eprintln!("{frames} touch frames");
    assert_eq!(frames, 11 * 256 * 256 * 2);
    assert!(
        wrong.is_empty(),
        "{} frames wrong, e.g.\n{}",
        wrong.len(),
        wrong
            .iter()
            .take(10)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// From each source, *Travel source* asks for the next one (Hall gear →
/// ground wheel → both → Hall gear, docs/hmi.md page 6), and *Wheel
/// direction* for the other direction.
#[test]
fn each_press_asks_for_the_next_source_and_the_other_direction() {
    let cases = [
        (TravelSource::HallGear, TravelSource::GroundWheel),
        (TravelSource::GroundWheel, TravelSource::Both),
        (TravelSource::Both, TravelSource::HallGear),
    ];
    for (now, next) in cases {
        for reversed in [false, true] {
            let settings = Settings {
                travel_source: now,
                ground_wheel_reversed: reversed,
                ..Settings::default()
            };
            let mut hmi = showing(Page::Settings, settings);
            hmi.push_slice(&[0x65, SETTINGS_PAGE, BSOURCE, 0x00, 0xFF, 0xFF, 0xFF]);
            hmi.push_slice(&[0x65, SETTINGS_PAGE, BWDIR, 0x00, 0xFF, 0xFF, 0xFF]);
            let got: Vec<Event> = std::iter::from_fn(|| hmi.poll_event()).collect();
            assert_eq!(
                got,
                vec![
                    Event::Command(Command::SelectTravelSource(next)),
                    Event::Command(Command::SetGroundWheelReversed(!reversed)),
                ],
                "{now:?} {reversed}"
            );
        }
    }
}
