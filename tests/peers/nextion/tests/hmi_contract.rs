//! The screen file's behaviour as docs/hmi.md states it (§3 data flow, §6
//! pages, §7 instruction examples), on the model.

use nextion_model::{codes, contract, Config, Keyboard, Screen, Touch};

fn i(s: &str) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.extend_from_slice(&codes::TERMINATOR);
    v
}

fn touch(page: u8, id: u8, press: bool) -> Vec<u8> {
    codes::frame(0x65, &[page, id, u8::from(press)])
}

fn showing(page: u8) -> Screen {
    let mut s = Screen::new();
    s.receive(0, &i(&format!("page {page}")));
    s.take_output();
    s
}

/// docs/hmi.md §3, in its own words: the Stop buttons (`bstop` on pages 2,
/// 3, 9 and 7) and the motor-starting buttons (`bstart` on pages 2, 3 and 7,
/// `bident` on page 9) send their id on press and on release; every other
/// button on release only; nothing else sends.
#[test]
fn every_component_of_every_page_sends_what_section_3_says() {
    let press_too = [
        (2, "bstop"),
        (3, "bstop"),
        (9, "bstop"),
        (7, "bstop"),
        (2, "bstart"),
        (3, "bstart"),
        (7, "bstart"),
        (9, "bident"),
    ];
    let mut checked = 0;
    for p in contract::PAGES {
        for c in p.components {
            let mut s = showing(p.id);
            let (pr, rl) = s.tap(1_000, c.name);
            let out = s.take_output();
            let expected = match c.kind {
                contract::Kind::Button if press_too.contains(&(p.id, c.name)) => {
                    assert_eq!(
                        (pr, rl),
                        (Touch::Sent, Touch::Sent),
                        "{}.{}",
                        p.name,
                        c.name
                    );
                    [touch(p.id, c.id, true), touch(p.id, c.id, false)].concat()
                }
                contract::Kind::Button => {
                    assert_eq!(
                        (pr, rl),
                        (Touch::Silent, Touch::Sent),
                        "{}.{}",
                        p.name,
                        c.name
                    );
                    touch(p.id, c.id, false)
                }
                _ if c.keyboard => {
                    assert_eq!(rl, Touch::Keyboard, "{}.{}", p.name, c.name);
                    Vec::new()
                }
                _ => {
                    assert_eq!(
                        (pr, rl),
                        (Touch::Silent, Touch::Silent),
                        "{}.{}",
                        p.name,
                        c.name
                    );
                    Vec::new()
                }
            };
            assert_eq!(out, expected, "{}.{}", p.name, c.name);
            checked += 1;
        }
    }
    assert!(checked > 100);
}

#[test]
fn only_the_page_shown_is_touched() {
    let mut s = showing(1);
    assert_eq!(s.tap(1_000, "bstart"), (Touch::NotShown, Touch::NotShown));
    assert!(s.take_output().is_empty());
}

#[test]
fn start_tapped_on_page_3_sends_press_then_release_at_the_baud_rate() {
    let mut s = showing(3);
    s.tap(1_000_000, "bstart");
    let out = s.take_output_timed();
    let (times, bytes): (Vec<u64>, Vec<u8>) = out.into_iter().unzip();
    assert_eq!(bytes, [touch(3, 13, true), touch(3, 13, false)].concat());
    // 7 bytes of 86.8 µs each, from the touch; the release 100 ms later.
    assert_eq!((times[0], times[6]), (1_000_087, 1_000_608));
    assert_eq!((times[7], times[13]), (1_100_087, 1_100_608));
}

#[test]
fn the_handshake_of_section_7() {
    // `FF FF FF` `sendme` `FF FF FF` → `66 00 FF FF FF`.
    let mut s = Screen::new();
    assert_eq!(
        s.take_output(),
        [codes::STARTUP.to_vec(), codes::frame(0x88, &[])].concat()
    );
    s.receive(10_000, &[&codes::TERMINATOR[..], &i("sendme")].concat());
    assert_eq!(s.take_output(), codes::frame(0x66, &[0]));
    assert!(s.errors().is_empty());
}

#[test]
fn numeric_entry_with_the_editors_keyboard_and_the_get_of_section_7() {
    let mut s = showing(3);
    s.receive(1_000, &i("tmsg.txt=\"too fast\""));
    // The operator touches the field: the keyboard page is shown.
    assert_eq!(s.tap(2_000, "nspacing").1, Touch::Keyboard);
    assert_eq!((s.page(), s.page_name()), (11, "keybdB"));
    // Meanwhile the MCU's status write and heartbeat meet the keyboard page.
    s.receive(3_000, &[i("xtravel.val=550"), i("sendme")].concat());
    assert_eq!(
        s.take_output(),
        [codes::frame(0x1A, &[]), codes::frame(0x66, &[11])].concat()
    );
    // OK: 18.0 cm is in the field, page 3 is loaded again.
    s.keyboard_enter(4_000, 180).unwrap();
    assert_eq!(s.page(), 3);
    assert_eq!(s.shown("nspacing").as_deref(), Some("18.0"));
    assert_eq!(
        s.text("tmsg").as_deref(),
        Some(""),
        "a local: back to design"
    );
    // `get nspacing.val` `FF FF FF` → `71 B4 00 00 00 FF FF FF`.
    s.receive(5_000, &i("get nspacing.val"));
    assert_eq!(s.take_output(), [0x71, 0xB4, 0, 0, 0, 0xFF, 0xFF, 0xFF]);
}

#[test]
fn numeric_entry_in_place_keeps_the_page() {
    let mut s = Screen::with_config(Config {
        keyboard: Keyboard::InPlace,
        ..Config::default()
    });
    s.receive(0, &i("page 6"));
    s.type_value(1_000, "ndim", 40).unwrap();
    assert_eq!((s.page(), s.value("ndim")), (6, Some(40)));
    assert!(s.type_value(2_000, "tmsg", 1).is_err());
    // Page 10's `nlval` has no keyboard in docs/hmi.md.
    s.receive(3_000, &i("page 10"));
    assert!(s.type_value(4_000, "nlval", 1).is_err());
}

#[test]
fn a_release_after_the_mcu_changed_the_page_is_no_event() {
    let mut s = showing(3);
    assert_eq!(s.press(1_000, "bstop"), Touch::Sent);
    s.receive(2_000, &i("page 3"));
    assert_eq!(s.release(50_000, "bstop"), Touch::PageChanged);
    assert_eq!(s.take_output(), touch(3, 7, true));
}

#[test]
fn a_page_instruction_closes_the_keyboard() {
    let mut s = showing(8);
    assert_eq!(s.tap(1_000, "nclamp").1, Touch::Keyboard);
    s.receive(2_000, &i("page 5"));
    assert!(s.keyboard_enter(3_000, 4).is_err());
    assert!(s.keyboard_cancel(3_000).is_err());
    assert_eq!(s.page(), 5);
    assert_eq!(s.global_value(8, "nclamp"), Some(0));
}
