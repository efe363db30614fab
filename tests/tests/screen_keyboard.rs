//! Numeric entry through the screen's own keyboard, against the independent
//! Nextion model: as the Nextion Editor builds it, touching a number field
//! loads the keyboard page (`keybdB`), and OK loads the field's page again,
//! every other component of it back to its design value. The firmware's
//! screen link (`hmi_proto::hmi::Hmi`) and line code run in virtual time
//! (`support/screen_rig.rs`); the firmware's answer to a command (the
//! settings in force written back, `firmware/src/tasks/hmi.rs`) is played
//! by the test.
//!
//! Cost: well under a second (host code in virtual time).

#[path = "../../firmware/src/screen_line.rs"]
mod screen_line;
#[path = "support/screen_rig.rs"]
mod screen_rig;

use hmi_proto::hmi::Event;
use hmi_proto::screen::{Command, Component, Gear, Page, Settings, Spacing};
use screen_rig::{Act, Rig};

/// Taps a component of the page shown: press and release `hold_us` later.
fn tap(rig: &mut Rig, at_us: u64, name: &'static str, hold_us: u64) {
    rig.at(at_us, Act::Press(name));
    rig.at(at_us + hold_us, Act::Release(name));
}

/// The firmware's side: each command the link reports is applied to
/// `settings` and the settings in force are written back (as
/// `refresh_settings` does), until `end_us`.
fn run_firmware(rig: &mut Rig, settings: &mut Settings, end_us: u64) -> Vec<Command> {
    let mut commands = Vec::new();
    let mut seen = rig.events.len();
    while rig.now_us() < end_us {
        rig.run_for(10_000);
        let new: Vec<Event> = rig.events[seen..].iter().map(|(_, e)| *e).collect();
        seen = rig.events.len();
        for e in new {
            if let Event::Command(c) = e {
                commands.push(c);
                if let Command::SetSpacing(s) = c {
                    settings.spacing = s;
                }
                let _ = rig.hmi.set_settings(*settings);
            }
        }
    }
    commands
}

/// Page 3 in High 2 at 12.0 cm; the operator types 18.0 cm into the spacing
/// with the keyboard (`typing_us` on the keyboard page while the MCU's
/// status writes meet it), then Apply `apply_after_us` after OK, or leaves
/// the keyboard with Cancel.
fn entry(typing_us: u64, value: Option<i32>, apply_after_us: u64) -> (Rig, Vec<Command>) {
    let mut settings = Settings {
        gear: Gear::High2,
        spacing: Spacing::new(120).unwrap(),
        ..Settings::default()
    };
    let mut rig = Rig::connected(settings);
    let t = rig.now_us();
    tap(&mut rig, t, "badapt", 100_000);
    rig.run_for(500_000);
    assert_eq!(rig.screen.page(), 3);
    assert_eq!(rig.screen.text("tgear").as_deref(), Some("High 2"));
    let t = rig.now_us();
    tap(&mut rig, t, "nspacing", 100_000);
    rig.run_for(200_000);
    assert_eq!(
        rig.screen.page_name(),
        "keybdB",
        "the keyboard page is shown"
    );
    let ok_at = rig.now_us() + typing_us;
    match value {
        Some(v) => {
            rig.at(ok_at, Act::KeyboardEnter(v));
            tap(&mut rig, ok_at + apply_after_us, "bapply", 100_000);
        }
        None => rig.at(ok_at, Act::KeyboardCancel),
    }
    let end = ok_at + apply_after_us + 1_500_000;
    let commands = run_firmware(&mut rig, &mut settings, end);
    (rig, commands)
}

/// The page after the entry shows the settings in force: the gear label is
/// the gear's (not its design text), the spacing the one applied. Swept over
/// the time spent typing (across the heartbeat and the status writes) and
/// the time from OK to Apply.
#[test]
fn after_the_keyboard_the_page_shows_the_settings_in_force() {
    for typing_ms in [300u64, 900, 1_100, 2_600, 4_000] {
        for apply_ms in [150u64, 600, 1_300] {
            let (rig, commands) = entry(typing_ms * 1000, Some(180), apply_ms * 1000);
            let case = format!("typing {typing_ms} ms, Apply {apply_ms} ms after OK");
            assert_eq!(
                commands,
                vec![Command::SetSpacing(Spacing::new(180).unwrap())],
                "{case}: one Apply, one command"
            );
            assert_eq!(rig.screen.page(), 3, "{case}");
            assert_eq!(rig.screen.value("nspacing"), Some(180), "{case}");
            assert_eq!(
                rig.screen.text("tgear").as_deref(),
                Some("High 2"),
                "{case}: the gear label"
            );
            // The status writes stop once the screen says its keyboard is
            // shown: one status write at most meets it (each instruction of
            // it is answered `0x1A`) ...
            let invalid = rig
                .screen
                .errors()
                .iter()
                .filter(|e| e.code == 0x1A)
                .count();
            let one_write = Component::on_page(Page::Adaptive).count();
            assert!(
                invalid <= one_write,
                "{case}: {invalid} instructions met the keyboard"
            );
            // ... and the firmware hears of it once (one log line), not
            // once an instruction.
            let reported = rig
                .events
                .iter()
                .filter(|(_, e)| matches!(e, Event::ScreenError(_)))
                .count();
            assert!(reported <= 1, "{case}: {reported} screen errors reported");
        }
    }
}

/// How long the page shows its design values after the keyboard closed
/// without a touch (Cancel, or OK and no Apply yet): the gear label is the
/// gear's again within 400 ms (one poll of 200 ms and the line).
#[test]
fn the_labels_come_back_within_400_ms_of_the_keyboard_closing() {
    for typing_ms in [300u64, 700, 1_100, 2_600] {
        for enter in [false, true] {
            let settings = Settings {
                gear: Gear::High2,
                ..Settings::default()
            };
            let mut rig = Rig::connected(settings);
            let t = rig.now_us();
            tap(&mut rig, t, "badapt", 100_000);
            rig.run_for(500_000);
            let t = rig.now_us();
            tap(&mut rig, t, "nspacing", 100_000);
            let close = t + 100_000 + typing_ms * 1000;
            rig.at(
                close,
                if enter {
                    Act::KeyboardEnter(250)
                } else {
                    Act::KeyboardCancel
                },
            );
            rig.run_until(close + 10_000);
            assert_eq!(rig.screen.page(), 3);
            rig.run_until(close + 400_000);
            assert_eq!(
                rig.screen.text("tgear").as_deref(),
                Some("High 2"),
                "typing {typing_ms} ms, OK {enter}"
            );
            if enter {
                assert_eq!(
                    rig.screen.value("nspacing"),
                    Some(250),
                    "the typed value stays"
                );
            }
        }
    }
}

/// Cancel on the keyboard also reloads the page: it shows the settings in
/// force again without any touch of the operator.
#[test]
fn after_a_cancelled_keyboard_the_page_shows_the_settings_in_force() {
    for typing_ms in [300u64, 1_100, 4_000] {
        let (rig, commands) = entry(typing_ms * 1000, None, 0);
        assert!(commands.is_empty(), "typing {typing_ms} ms: {commands:?}");
        assert_eq!(rig.screen.page(), 3);
        assert_eq!(
            rig.screen.value("nspacing"),
            Some(120),
            "typing {typing_ms} ms"
        );
        assert_eq!(
            rig.screen.text("tgear").as_deref(),
            Some("High 2"),
            "typing {typing_ms} ms: the gear label"
        );
    }
}
