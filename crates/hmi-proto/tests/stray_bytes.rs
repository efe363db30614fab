//! A byte the screen did not send (noise on the line) never costs the touch
//! after it, and a partial frame is forgotten once the line has been quiet
//! for `RX_GAP_MS` (docs/hmi.md §3, "Line errors").
//!
//! Measured before: one stray `0x70` or `0x71` right before a touch made a
//! string or a number reply of it, and `0x67`/`0x68` put the touch inside
//! an unfinished coordinate frame; and the quiet-line rule acted only at
//! the hmi task's next tick, after the byte that ended the quiet had joined
//! the partial frame (`70`, 17 ms quiet, a Stop press: read as a string).
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use hmi_proto::hmi::{Event, Hmi, RX_GAP_MS};
use hmi_proto::screen::{Command, Component, Kind, Page, Settings, COMPONENTS};
use hmi_proto::TouchEvent;

fn touch(page: u8, id: u8, event: TouchEvent) -> [u8; 7] {
    [0x65, page, id, event.to_byte(), 0xFF, 0xFF, 0xFF]
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

/// What the link does with `bytes` (all arriving at `at_ms`, then a tick
/// 1 ms later): its events, what it sends, the page and whether it awaits
/// a reply.
fn outcome(mut hmi: Hmi, at_ms: u32, bytes: &[u8]) -> (Vec<Event>, Vec<u8>, Page, bool) {
    for &b in bytes {
        hmi.push_at(b, at_ms);
    }
    hmi.tick(at_ms + 1);
    (
        events(&mut hmi),
        drain(&mut hmi),
        hmi.page(),
        hmi.awaiting_reply(),
    )
}

/// Every byte value right before every touch frame of the contract (the
/// press and the release of every button, on its page): the touch does
/// what it does without the byte, and so does a touch after it.
#[test]
fn one_stray_byte_never_costs_the_touch_after_it() {
    let buttons: Vec<&Component> = COMPONENTS
        .iter()
        .filter(|c| c.kind() == Kind::Button)
        .collect();
    let mut cases = 0u32;
    let mut bad = Vec::new();
    for c in &buttons {
        let base = showing(c.page);
        for event in [TouchEvent::Press, TouchEvent::Release] {
            let frame = touch(c.page.id(), c.id(), event);
            // Then Stop's press (a frame after the touch): taken too.
            let stop = COMPONENTS
                .iter()
                .find(|s| s.page == c.page && s.name() == "bstop")
                .map(|s| touch(c.page.id(), s.id(), TouchEvent::Press));
            let mut clean = frame.to_vec();
            clean.extend(stop.iter().flatten());
            let want = outcome(base.clone(), 5, &clean);
            for stray in 0..=255u8 {
                cases += 1;
                let mut bytes = vec![stray];
                bytes.extend_from_slice(&clean);
                let got = outcome(base.clone(), 5, &bytes);
                if got != want {
                    bad.push(format!(
                        "{:02X} before {} ({:?} id {}) {event:?}: {:?} instead of {:?}",
                        stray,
                        c.name(),
                        c.page,
                        c.id(),
                        got.0,
                        want.0
                    ));
                }
            }
        }
    }
    eprintln!(
        "{cases} cases (every byte value before the press and the release of {} buttons)",
        buttons.len()
    );
    assert_eq!(cases as usize, buttons.len() * 2 * 256);
    assert!(
        bad.is_empty(),
        "{} of {cases} touches lost or changed, e.g.\n{}",
        bad.len(),
        bad[..bad.len().min(10)].join("\n")
    );
}

/// The limit: while an *Apply*'s `get` is awaited, a number frame is its
/// reply, so a stray `0x71` right before the Stop's press makes a reply of
/// it (range-checked: refused, nothing changes). The Stop's release stops;
/// the real reply that follows is one nobody asked for.
#[test]
fn a_stray_number_header_while_a_reply_is_awaited_costs_the_press_only() {
    let mut hmi = showing(Page::Adaptive);
    hmi.push_slice(&touch(3, 2, TouchEvent::Release)); // Apply: get nspacing.val
    assert!(hmi.awaiting_reply());
    drain(&mut hmi);
    let mut bytes = vec![0x71];
    bytes.extend_from_slice(&touch(3, 7, TouchEvent::Press));
    hmi.push_slice(&bytes);
    assert!(matches!(events(&mut hmi)[..], [Event::Rejected(_)]));
    hmi.push_slice(&touch(3, 7, TouchEvent::Release));
    assert_eq!(events(&mut hmi), [Event::Command(Command::Stop)]);
    // With no reply awaited the same bytes are the Stop's press.
    hmi.push_slice(&bytes);
    assert_eq!(events(&mut hmi), [Event::Command(Command::Stop)]);
}

/// The quiet-line rule as documented: a partial frame is forgotten when
/// the line has been quiet for `RX_GAP_MS`, measured from the bytes'
/// arrival, whenever the link gets them. While an *Apply*'s `get` is
/// awaited (a number or string frame is then read as one), a stray `70`
/// (a string's header, which would take the touch as its text), then the
/// Stop's press 11 ms later: the Stop. 9 ms later: the bytes are one frame
/// (the rule does not cut a frame whose bytes come less than 10 ms apart;
/// the Stop's release still stops).
#[test]
fn a_partial_frame_is_forgotten_after_10_ms_of_quiet_line() {
    let stop = touch(3, 7, TouchEvent::Press);
    for (gap, want) in [
        (RX_GAP_MS + 1, vec![Event::Command(Command::Stop)]),
        (RX_GAP_MS - 1, vec![]),
    ] {
        let mut hmi = showing(Page::Adaptive);
        hmi.tick(100);
        hmi.push_slice(&touch(3, 2, TouchEvent::Release)); // Apply: get nspacing.val
        assert!(hmi.awaiting_reply());
        hmi.push_at(0x70, 100);
        hmi.tick(100);
        // The link gets the Stop's bytes late (its task was busy): the
        // bytes' arrival times count, not the link's.
        for &b in &stop {
            hmi.push_at(b, 100 + gap);
        }
        hmi.tick(100 + gap + 15);
        assert_eq!(events(&mut hmi), want, "{gap} ms");
        assert!(hmi.awaiting_reply(), "{gap} ms: the reply still awaited");
    }
    // No reply awaited, the reproducer (page 3, `70`, 17 ms quiet,
    // Stop's press): the Stop, whatever the gap (the `70` is read as a
    // stray byte at once).
    for gap in [17, 0] {
        let mut hmi = showing(Page::Adaptive);
        hmi.push_at(0x70, 100);
        for &b in &stop {
            hmi.push_at(b, 100 + gap);
        }
        hmi.tick(120);
        assert_eq!(events(&mut hmi), [Event::Command(Command::Stop)]);
    }
}
