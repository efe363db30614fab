//! The page the MCU believes shown, against `sendme` answers that cross a
//! page change (docs/hmi.md §3, "Touches count from the page shown only").
//!
//! The screen runs instructions in the order it receives them: a `sendme`
//! the MCU queued before a `page N` is answered with the page shown
//! *before* `page N`. Such an answer arrives after the MCU has changed the
//! page, and must not move the MCU back to the old page: the operator's
//! next touch would count as another page's (a Start refused) and the live
//! status would go to the old page's components (`0x1A` errors).
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use hmi_proto::hmi::{Event, Hmi, HEARTBEAT_MS};
use hmi_proto::screen::{Command, Page, Settings, Status};
use hmi_proto::TouchEvent;

fn touch(page: u8, id: u8, event: TouchEvent) -> [u8; 7] {
    [0x65, page, id, event.to_byte(), 0xFF, 0xFF, 0xFF]
}

fn answer(page: u8) -> [u8; 5] {
    [0x66, page, 0xFF, 0xFF, 0xFF]
}

/// A link after the handshake at time 0, showing `page` (bytes and events
/// drained).
fn showing(page: Page) -> Hmi {
    let mut hmi = Hmi::new(Settings::default(), "test");
    hmi.tick(0);
    hmi.push_slice(&[0x88, 0xFF, 0xFF, 0xFF]);
    hmi.show_page(page).unwrap();
    drain(&mut hmi);
    while hmi.poll_event().is_some() {}
    hmi
}

fn drain(hmi: &mut Hmi) -> Vec<u8> {
    let mut tx = [0u8; 1024];
    let n = hmi.poll_transmit(&mut tx);
    tx[..n].to_vec()
}

fn events(hmi: &mut Hmi) -> Vec<Event> {
    let mut v = Vec::new();
    while let Some(e) = hmi.poll_event() {
        v.push(e);
    }
    v
}

fn has(bytes: &[u8], what: &[u8]) -> bool {
    bytes.windows(what.len()).any(|w| w == what)
}

/// The reproducer: page 6 quiet for a second (the heartbeat `sendme`
/// goes out), the operator taps *Drive* (`bdrive`, id 11: the MCU shows
/// page 9), the screen's answer to the heartbeat names page 6, then the
/// operator taps Identify on page 9. Measured before: the answer moved the
/// MCU back to page 6, Identify was refused as another page's touch and the
/// status went to page 6's components.
#[test]
fn a_heartbeat_answer_that_crossed_a_page_change_is_not_the_page() {
    let mut hmi = showing(Page::Settings);
    hmi.tick(HEARTBEAT_MS);
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    hmi.push_slice(&touch(6, 11, TouchEvent::Release));
    hmi.tick(HEARTBEAT_MS + 1);
    assert!(has(&drain(&mut hmi), b"page 9\xff\xff\xff"));
    // The screen answered the `sendme` before it read `page 9`.
    hmi.push_slice(&answer(6));
    assert_eq!(hmi.page(), Page::Drive);
    hmi.tick(HEARTBEAT_MS + 200);
    hmi.push_slice(&touch(9, 5, TouchEvent::Press));
    hmi.tick(HEARTBEAT_MS + 350);
    hmi.push_slice(&touch(9, 5, TouchEvent::Release));
    assert_eq!(
        events(&mut hmi),
        [Event::Command(Command::IdentifyDrive)],
        "{:?}",
        hmi.stats()
    );
    // The live status goes to page 9's components.
    drain(&mut hmi);
    hmi.write_status(&Status::default()).unwrap();
    let status = drain(&mut hmi);
    assert!(has(&status, b"nidstate.val="), "{}", status.escape_ascii());
    assert!(!has(&status, b"tver.txt"), "{}", status.escape_ascii());
}

/// The same with the `sendme` a touch from another page asks for: the
/// answer to it arrives after the operator's navigation.
#[test]
fn a_probe_answer_that_crossed_a_page_change_is_not_the_page() {
    let mut hmi = showing(Page::Mode);
    // A frame of page 3 still in flight: ignored, the page asked.
    hmi.push_slice(&touch(3, 4, TouchEvent::Release));
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    // The operator taps Fixed Mode (page 1, id 1): page 2.
    hmi.push_slice(&touch(1, 1, TouchEvent::Release));
    assert_eq!(
        events(&mut hmi),
        [Event::Command(Command::SelectMode(
            hmi_proto::screen::Mode::Fixed
        ))]
    );
    assert!(has(&drain(&mut hmi), b"page 2\xff\xff\xff"));
    hmi.push_slice(&answer(1));
    assert_eq!(hmi.page(), Page::Fixed);
    hmi.push_slice(&touch(2, 1, TouchEvent::Press));
    hmi.push_slice(&touch(2, 1, TouchEvent::Release));
    assert_eq!(events(&mut hmi), [Event::Command(Command::Start)]);
}

/// An answer to a `sendme` queued after the last page change is the page:
/// a page the MCU believed wrongly (its `page` instruction lost on the
/// line) is put right by it.
#[test]
fn an_answer_after_the_page_change_is_taken() {
    let mut hmi = showing(Page::Mode);
    hmi.show_page(Page::Adaptive).unwrap();
    drain(&mut hmi);
    // The screen never got `page 3`: it still shows page 1, and a touch of
    // page 1 makes the MCU ask.
    hmi.push_slice(&touch(1, 4, TouchEvent::Release));
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    hmi.push_slice(&answer(1));
    assert_eq!(hmi.page(), Page::Mode);
    hmi.push_slice(&touch(1, 4, TouchEvent::Release));
    assert!(has(&drain(&mut hmi), b"page 6\xff\xff\xff"));
    assert_eq!(hmi.page(), Page::Settings);
}

/// An answer to a `sendme` before the page change that the line lost: the
/// next answer is taken for it (the MCU keeps the page it set), and the one
/// after is the page again.
#[test]
fn a_lost_answer_costs_one_answer() {
    let mut hmi = showing(Page::Settings);
    hmi.tick(HEARTBEAT_MS);
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    hmi.push_slice(&touch(6, 11, TouchEvent::Release)); // page 9
    drain(&mut hmi);
    // The answer naming page 6 is lost. The screen does not show page 9
    // (say its `page 9` was hit): a touch of page 6 is asked about.
    hmi.tick(HEARTBEAT_MS + 50);
    hmi.push_slice(&touch(6, 4, TouchEvent::Release));
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    hmi.push_slice(&answer(6));
    assert_eq!(hmi.page(), Page::Drive, "taken as the lost one's");
    assert_eq!(hmi.stats().stale_page_answers, 1);
    hmi.push_slice(&touch(6, 4, TouchEvent::Release));
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    hmi.push_slice(&answer(6));
    assert_eq!(hmi.page(), Page::Settings);
}

/// The handshake's `sendme` are not owed answers once the screen is set up:
/// the first answer after it is the page (a screen found showing page 3
/// after several unanswered handshakes, its cable plugged back in).
#[test]
fn unanswered_handshakes_are_not_owed() {
    let mut hmi = Hmi::new(Settings::default(), "test");
    for t in 0..5 {
        hmi.tick(t * 500);
    }
    assert_eq!(
        drain(&mut hmi)
            .windows(6)
            .filter(|w| w == b"sendme")
            .count(),
        1,
        "each retry replaces the unsent one"
    );
    hmi.push_slice(&answer(3));
    assert_eq!(events(&mut hmi), [Event::Connected]);
    assert_eq!(hmi.page(), Page::Mode);
    drain(&mut hmi);
    // A page of the screen asked about, then answered.
    hmi.push_slice(&touch(3, 4, TouchEvent::Release));
    assert!(has(&drain(&mut hmi), b"sendme\xff\xff\xff"));
    hmi.push_slice(&answer(3));
    assert_eq!(hmi.page(), Page::Adaptive);
}
