//! A motor start needs evidence one corrupted frame cannot fake
//! (docs/hmi.md §3, "Motor-starting buttons").
//!
//! Nextion touch frames `65 <page> <id> <event> FF FF FF` carry no CRC, and
//! with the ids of the earlier screen layout the Start and Identify buttons
//! were one bit away from other buttons (page 3 `bstart` id 6 next to
//! `bgearup` 4, `bapply` 2 and `bstop` 7; page 2 `bstart` id 3 next to
//! `bapply` 2; page 7 `bstart` id 1 next to `bpar` 3; page 9 `bident` id 1
//! next to `bback` 3 and page 1's `bfixed` 1). Before this rule a touch was
//! taken from any page and a release alone started the drum, so one bit
//! error in another button's frame could start a motor. (The ids now keep
//! every motor start two bits from every other button:
//! `tests/start_flips.rs` tests two and three hit bits.)
//!
//! Now a motor-starting command needs the press *and* the release of the
//! same component, nothing between them, within `START_TAP_MS`, both naming
//! the page the MCU knows is shown. Tested exhaustively: every page shown ×
//! every component of the contract × its press and its release × every bit
//! of every byte of the frame flipped (the operator's tap with one of its
//! two frames hit on the line).
//!
//! Measured before the change (hmi.rs without the pairing, the same
//! tests): 2 717 of the 142 912 taps with one frame hit started a motor,
//! 2 494 of them taps of another button than the Start shown (the first
//! listed: page 0 shown, page 1 `bfixed` tapped, its release `65 01 01 00`
//! hit in bit 3 of the page byte into `65 09 01 00`, page 9 `bident`:
//! `IdentifyDrive`); a lone Start release started the drum, from any page.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use hmi_proto::hmi::{Event, Hmi, HEARTBEAT_MS, START_TAP_MS, TX_CAPACITY};
use hmi_proto::screen::{Action, Command, Page, Role, Settings, COMPONENTS};
use hmi_proto::TouchEvent;

const T: [u8; 3] = [0xFF; 3];

fn touch(page: u8, id: u8, event: TouchEvent) -> [u8; 7] {
    [0x65, page, id, event.to_byte(), T[0], T[1], T[2]]
}

/// A link after the handshake, showing `page` (queued bytes and events
/// drained).
fn showing(page: Page) -> Hmi {
    let mut hmi = Hmi::new(Settings::default(), "test");
    hmi.tick(0);
    hmi.push_slice(&[0x88, 0xFF, 0xFF, 0xFF]);
    let mut tx = [0u8; 512];
    hmi.poll_transmit(&mut tx);
    hmi.show_page(page).unwrap();
    hmi.poll_transmit(&mut tx);
    while hmi.poll_event().is_some() {}
    assert!(hmi.is_connected());
    assert_eq!(hmi.page(), page);
    hmi
}

fn events(hmi: &mut Hmi) -> Vec<Event> {
    let mut v = Vec::new();
    while let Some(e) = hmi.poll_event() {
        v.push(e);
    }
    v
}

fn starts_motor(e: &Event) -> bool {
    matches!(e, Event::Command(Command::Start | Command::IdentifyDrive))
}

/// The motor-starting buttons of the contract (docs/hmi.md §6): page 2
/// `bstart` id 1, page 3 `bstart` id 13, page 7 `bstart` id 1 (profile B's
/// two steppers), page 9 `bident` id 5 (runs the drum for 7 s). Calibration's
/// *Start run* (page 4 `bcstart`) only starts counting: the k3 run's drum is
/// started with page 2's Start.
#[test]
fn the_motor_starting_buttons_are_start_and_identify() {
    let mut starters: Vec<(u8, u8, &str)> = COMPONENTS
        .iter()
        .filter(|c| matches!(c.role, Role::Action(a) if a.starts_motor()))
        .map(|c| (c.page.id(), c.id(), c.name()))
        .collect();
    starters.sort_unstable();
    assert_eq!(
        starters,
        [
            (2, 1, "bstart"),
            (3, 13, "bstart"),
            (7, 1, "bstart"),
            (9, 5, "bident")
        ]
    );
    for a in [Action::Start, Action::IdentifyDrive] {
        assert!(a.starts_motor());
    }
    assert!(!Action::CalibrationStart.starts_motor());
    assert!(!Action::Stop.starts_motor());
}

/// Every tap of every component of the contract (its press then its
/// release), on every page shown, with one bit of one byte of one of its
/// two frames flipped: never a motor start.
#[test]
fn one_flipped_bit_in_any_tap_never_starts_a_motor() {
    let mut cases = 0u32;
    let mut other = 0u32;
    let mut bad = Vec::new();
    for shown in Page::ALL {
        for c in COMPONENTS {
            let frames = [
                touch(c.page.id(), c.id(), TouchEvent::Press),
                touch(c.page.id(), c.id(), TouchEvent::Release),
            ];
            for hit in 0..2 {
                for byte in 0..7 {
                    for bit in 0..8 {
                        cases += 1;
                        let mut f = frames;
                        f[hit][byte] ^= 1 << bit;
                        let mut hmi = showing(shown);
                        hmi.push_slice(&f[0]);
                        hmi.push_slice(&f[1]);
                        let ev = events(&mut hmi);
                        if ev.iter().any(starts_motor) {
                            // The operator's tap of the Start shown
                            // itself, its press hit: refused too (tap
                            // again), counted apart.
                            if c.page != shown
                                || !matches!(c.role, Role::Action(a) if a.starts_motor())
                            {
                                other += 1;
                            }
                            bad.push(format!(
                                "{shown:?} shown, {} on {:?}: {:02X?} then {:02X?} -> {ev:?}",
                                c.name(),
                                c.page,
                                f[0],
                                f[1]
                            ));
                        }
                    }
                }
            }
        }
    }
    assert!(
        bad.is_empty(),
        "{} of {cases} taps with one bit hit started a motor ({other} of them taps of \
         another button than the Start shown), e.g.\n{}",
        bad.len(),
        bad[..bad.len().min(8)].join("\n")
    );
    // Every page shown x every component of the contract x 2 frames x 56
    // bits (11 x 117 x 112 = 144 144 with page 7's `broll`).
    assert_eq!(cases as usize, Page::ALL.len() * COMPONENTS.len() * 2 * 56);
}

/// A hit frame alone (its partner lost as well, or a frame of noise that
/// decodes as a touch): never a motor start, on any page shown.
#[test]
fn a_flipped_frame_alone_never_starts_a_motor() {
    for shown in Page::ALL {
        for c in COMPONENTS {
            for ev in [TouchEvent::Press, TouchEvent::Release] {
                for byte in 0..7 {
                    for bit in 0..8 {
                        let mut f = touch(c.page.id(), c.id(), ev);
                        f[byte] ^= 1 << bit;
                        let mut hmi = showing(shown);
                        hmi.push_slice(&f);
                        let e = events(&mut hmi);
                        assert!(!e.iter().any(starts_motor), "{shown:?}: {f:02X?} -> {e:?}");
                    }
                }
            }
        }
    }
}

/// The operator's tap of each motor-starting button on its page: the press
/// and the release → the command; each frame alone → nothing.
#[test]
fn a_press_and_release_of_start_starts() {
    // (page, the button's id, another button's id on the page: `bapply`,
    // `bapply`, `bpar`, `bback`; docs/hmi.md §6)
    for (page, id, other, want) in [
        (Page::Fixed, 1, 2, Command::Start),
        (Page::Adaptive, 13, 2, Command::Start),
        (Page::Belt, 1, 6, Command::Start),
        (Page::Drive, 5, 3, Command::IdentifyDrive),
    ] {
        let mut hmi = showing(page);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Press));
        assert_eq!(events(&mut hmi), []);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Release));
        assert_eq!(events(&mut hmi), [Event::Command(want)], "{page:?}");

        // The release alone (its press lost): refused and counted.
        let mut hmi = showing(page);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Release));
        assert_eq!(events(&mut hmi), [], "{page:?}");
        assert_eq!(hmi.stats().unpaired_starts, 1);

        // Another touch frame between them (a press of another button).
        let mut hmi = showing(page);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Press));
        hmi.push_slice(&touch(page.id(), other, TouchEvent::Press));
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Release));
        assert_eq!(events(&mut hmi), [], "{page:?}");

        // Held longer than START_TAP_MS: not a tap.
        let mut hmi = showing(page);
        hmi.tick(10);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Press));
        hmi.tick(10 + START_TAP_MS);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Release));
        assert_eq!(events(&mut hmi), [Event::Command(want)], "{page:?}");
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Press));
        hmi.tick(10 + 2 * START_TAP_MS + 1);
        hmi.push_slice(&touch(page.id(), id, TouchEvent::Release));
        assert_eq!(events(&mut hmi), [], "{page:?}");
    }
}

/// Page 3: the operator presses Start and its release is hit on the line
/// (every bit of every byte): no start; the next clean tap starts.
#[test]
fn a_start_press_then_a_corrupted_release_does_not_start() {
    let press = touch(3, 13, TouchEvent::Press);
    for byte in 0..7 {
        for bit in 0..8 {
            let mut hmi = showing(Page::Adaptive);
            let mut release = touch(3, 13, TouchEvent::Release);
            release[byte] ^= 1 << bit;
            hmi.push_slice(&press);
            hmi.push_slice(&release);
            let ev = events(&mut hmi);
            assert!(!ev.iter().any(starts_motor), "{release:02X?} -> {ev:?}");
            // The line is quiet for a while (a partial frame is forgotten,
            // a `get` the hit release asked for times out).
            hmi.tick(100);
            hmi.tick(400);
            let ev = events(&mut hmi);
            assert!(!ev.iter().any(starts_motor), "{release:02X?} -> {ev:?}");
            hmi.push_slice(&press);
            hmi.push_slice(&touch(3, 13, TouchEvent::Release));
            assert_eq!(events(&mut hmi), [Event::Command(Command::Start)]);
        }
    }
}

/// Stop stays act-on-press, from any page, shown or not, connected or not.
#[test]
fn stop_acts_on_its_press_alone() {
    for (page, id) in [(2u8, 4u8), (3, 7), (7, 2), (9, 8)] {
        for shown in Page::ALL {
            let mut hmi = showing(shown);
            hmi.push_slice(&touch(page, id, TouchEvent::Press));
            assert_eq!(events(&mut hmi), [Event::Command(Command::Stop)]);
        }
        let mut hmi = Hmi::new(Settings::default(), "test");
        hmi.push_slice(&touch(page, id, TouchEvent::Press));
        assert_eq!(events(&mut hmi), [Event::Command(Command::Stop)]);
    }
}

/// A touch naming a page other than the one shown is ignored and counted,
/// and the MCU asks the screen its page (`sendme`): a page the MCU believed
/// wrongly (a late `0x66` answer) is put right by the next touch.
#[test]
fn a_touch_from_another_page_is_ignored_and_the_page_asked() {
    let mut hmi = showing(Page::Settings);
    let mut tx = [0u8; 512];
    // Page 3's Apply (id 2) while page 6 is shown: not acted on.
    hmi.push_slice(&touch(3, 2, TouchEvent::Release));
    assert_eq!(events(&mut hmi), []);
    assert!(!hmi.awaiting_reply());
    assert_eq!(hmi.stats().foreign_page_touches, 1);
    let n = hmi.poll_transmit(&mut tx);
    assert_eq!(&tx[..n], b"sendme\xff\xff\xff");
    // The screen says it shows page 3: its touches count again.
    hmi.push_slice(&[0x66, 0x03, 0xFF, 0xFF, 0xFF]);
    assert_eq!(hmi.page(), Page::Adaptive);
    hmi.push_slice(&touch(3, 13, TouchEvent::Press));
    hmi.push_slice(&touch(3, 13, TouchEvent::Release));
    assert_eq!(events(&mut hmi), [Event::Command(Command::Start)]);
}

/// The page is unknown after a `page` instruction that did not fit the
/// transmit queue (the screen may still show the old page): a motor start
/// is refused, other touches follow the old rule (taken from the page they
/// name), and the MCU asks the page; once the screen answers, Start works.
#[test]
fn while_the_page_is_unknown_no_motor_starts() {
    let mut hmi = showing(Page::Mode);
    // Fill the transmit queue until a `page` instruction does not fit.
    while hmi.tx_pending() + b"page 0\xff\xff\xff".len() <= TX_CAPACITY {
        let _ = hmi.show_page(Page::Boot);
    }
    assert!(hmi.show_page(Page::Adaptive).is_err());
    let mut tx = [0u8; 1024];
    hmi.poll_transmit(&mut tx);
    hmi.push_slice(&touch(3, 13, TouchEvent::Press));
    hmi.push_slice(&touch(3, 13, TouchEvent::Release));
    assert_eq!(events(&mut hmi), []);
    assert_eq!(hmi.stats().foreign_page_touches, 1);
    // Gear up (page 3, id 4) is taken as before.
    hmi.push_slice(&touch(3, 4, TouchEvent::Release));
    assert!(matches!(
        events(&mut hmi)[..],
        [Event::Command(Command::SelectGear(_))]
    ));
    let n = hmi.poll_transmit(&mut tx);
    assert!(tx[..n].windows(9).any(|w| w == b"sendme\xff\xff\xff"));
    hmi.push_slice(&[0x66, 0x03, 0xFF, 0xFF, 0xFF]);
    hmi.push_slice(&touch(3, 13, TouchEvent::Press));
    hmi.push_slice(&touch(3, 13, TouchEvent::Release));
    assert_eq!(events(&mut hmi), [Event::Command(Command::Start)]);
}

/// After a lost link the screen is set up again on the home page; a Start
/// pair from the page it showed before (frames in flight) is ignored.
#[test]
fn after_a_reconnect_an_old_pages_start_is_ignored() {
    let mut hmi = showing(Page::Adaptive);
    hmi.tick(HEARTBEAT_MS * 3);
    assert!(!hmi.is_connected());
    // Not connected: a Start pair is ignored.
    hmi.push_slice(&touch(3, 13, TouchEvent::Press));
    hmi.push_slice(&touch(3, 13, TouchEvent::Release));
    assert!(!events(&mut hmi).iter().any(starts_motor));
    hmi.push_slice(&[0x66, 0x03, 0xFF, 0xFF, 0xFF]); // connects, shows page 1
    assert_eq!(events(&mut hmi), [Event::Connected]);
    assert_eq!(hmi.page(), Page::Mode);
    hmi.push_slice(&touch(3, 13, TouchEvent::Press));
    hmi.push_slice(&touch(3, 13, TouchEvent::Release));
    assert_eq!(events(&mut hmi), []);
}
