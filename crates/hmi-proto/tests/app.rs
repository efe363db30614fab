//! Application layer against the virtual screen: handshake, commands,
//! validation, the known pitfalls of Nextion libraries, and split streams.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use hmi_proto::hmi::{
    Event, Hmi, EVENT_QUEUE, GET_TIMEOUT_MS, HANDSHAKE_RETRY_MS, HEARTBEAT_MS, LINK_TIMEOUT_MS,
};
use hmi_proto::screen::*;
use hmi_proto::virtual_screen::VirtualScreen;
use hmi_proto::{ErrorCode, Frame};
use proptest::prelude::*;

/// Moves bytes both ways until both sides are quiet; returns the events.
fn pump(hmi: &mut Hmi, screen: &mut VirtualScreen) -> Vec<Event> {
    let mut events = Vec::new();
    let mut buf = [0u8; 512];
    loop {
        let n = hmi.poll_transmit(&mut buf);
        screen.feed(&buf[..n]);
        let back = screen.take_output();
        hmi.push_slice(&back);
        while let Some(e) = hmi.poll_event() {
            events.push(e);
        }
        if n == 0 && back.is_empty() {
            return events;
        }
    }
}

fn connected() -> (Hmi, VirtualScreen) {
    let mut screen = VirtualScreen::with_contract();
    let mut hmi = Hmi::new(Settings::default(), "fw 0.1.0");
    screen.boot();
    hmi.tick(0);
    let ev = pump(&mut hmi, &mut screen);
    assert!(ev.contains(&Event::Connected), "{ev:?}");
    (hmi, screen)
}

fn cmd(c: Command) -> Event {
    Event::Command(c)
}

#[test]
fn handshake_when_screen_boots_first_or_later() {
    // Screen already running (its 0x88 was missed): sendme gets a 0x66 answer.
    let mut screen = VirtualScreen::with_contract();
    let mut hmi = Hmi::new(Settings::default(), "fw 0.1.0");
    hmi.tick(0);
    assert_eq!(pump(&mut hmi, &mut screen), vec![Event::Connected]);
    assert!(hmi.is_connected());
    assert_eq!(screen.page(), Page::Mode.id());
    assert_eq!(screen.value("ncoef"), Some(100));
    assert_eq!(screen.bkcmd(), 2);
    assert_eq!(
        &screen.instructions()[..5],
        ["", "sendme", "bkcmd=2", "dims=100", "page 1"]
    );

    // Screen silent: the MCU retries every HANDSHAKE_RETRY_MS, nothing else.
    let mut hmi = Hmi::new(Settings::default(), "fw");
    let mut tx = [0u8; 256];
    hmi.tick(0);
    let n = hmi.poll_transmit(&mut tx);
    assert_eq!(&tx[..n], b"\xff\xff\xffsendme\xff\xff\xff");
    hmi.tick(HANDSHAKE_RETRY_MS - 1);
    assert_eq!(hmi.poll_transmit(&mut tx), 0);
    hmi.tick(HANDSHAKE_RETRY_MS);
    let n = hmi.poll_transmit(&mut tx);
    assert_eq!(&tx[..n], b"\xff\xff\xffsendme\xff\xff\xff");

    // Screen resets while connected: startup + 0x88 set it up again.
    let (mut hmi, mut screen) = connected();
    screen.feed(b"rest\xff\xff\xff");
    let ev = pump(&mut hmi, &mut screen);
    assert_eq!(ev, vec![Event::Connected]);
    assert_eq!(screen.page(), Page::Mode.id());
}

/// A `get` reply below 65 536 ends `00 00 FF FF FF`; with its header byte
/// hit (one bit: `0x71` → `0x73`) the decoder finds the screen's startup
/// frame `00 00 00 FF FF FF` in it. That is no restart: the screen still
/// shows the run page. Expected (docs/hmi.md §2: only a restart, startup
/// then `0x88`, sets the screen up again): the screen stays on page 3 with
/// its Stop and the link stays up. Measured before the fix: the link was
/// dropped, and 500 ms later the handshake showed the home page 1 (no Stop
/// button on it) with `Event::Connected`.
#[test]
fn a_reply_hit_in_its_header_is_no_screen_restart() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    hmi.tick(100);
    screen.set_value("nspacing", 180).unwrap();
    screen.release("bapply").unwrap();
    hmi.push_slice(&screen.take_output());
    let mut tx = [0u8; 512];
    let n = hmi.poll_transmit(&mut tx);
    screen.feed(&tx[..n]);
    let mut reply = screen.take_output();
    assert_eq!(reply, [0x71, 180, 0, 0, 0, 0xFF, 0xFF, 0xFF]);
    reply[0] = 0x73;
    hmi.push_slice(&reply);
    let mut ev = pump(&mut hmi, &mut screen);
    for t in (110..=2000).step_by(10) {
        hmi.tick(t);
        ev.extend(pump(&mut hmi, &mut screen));
    }
    assert!(!ev.contains(&Event::Connected), "{ev:?}");
    assert!(hmi.is_connected());
    assert_eq!(screen.page(), Page::Adaptive.id());
    assert_eq!(hmi.page(), Page::Adaptive);
    // Touches work at once (Start, then Apply with the value again).
    screen.tap("bstart").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![cmd(Command::Start)]);

    // A real restart whose `0x88` is lost: the heartbeat's answer naming
    // page 0 sets the screen up.
    screen.boot();
    let mut out = screen.take_output();
    assert_eq!(out.split_off(6), [0x88, 0xFF, 0xFF, 0xFF]);
    hmi.tick(2010);
    hmi.push_slice(&out);
    let mut ev = Vec::new();
    for t in (2020..=4000).step_by(10) {
        hmi.tick(t);
        ev.extend(pump(&mut hmi, &mut screen));
    }
    assert_eq!(ev, vec![Event::Connected]);
    assert_eq!(screen.page(), Page::Mode.id());
}

/// The screen's answer to an *Apply*'s `get` is lost on the line (a hit
/// byte drops the frame). Nothing changed, so the field must show the value
/// in force again and the page say so, as for a value out of range
/// (docs/hmi.md §3: "the field is set back to the value in force, and
/// nothing changes"); 70 mm is the default spacing (docs/hmi.md §4).
/// Measured before the fix: the field kept the 180 typed, `tmsg` stayed
/// empty, and the machine kept planting at 70 mm — the screen showed a
/// spacing not in force.
#[test]
fn a_lost_reply_puts_the_value_in_force_back_and_says_so() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    hmi.tick(100);
    screen.set_value("nspacing", 180).unwrap();
    screen.release("bapply").unwrap();
    hmi.push_slice(&screen.take_output());
    let mut tx = [0u8; 512];
    let n = hmi.poll_transmit(&mut tx);
    assert_eq!(&tx[..n], b"get nspacing.val\xff\xff\xff"); // never answered
    hmi.tick(100 + GET_TIMEOUT_MS);
    let ev = pump(&mut hmi, &mut screen);
    assert_eq!(ev, vec![Event::ReplyTimeout(Field::Spacing)]);
    assert_eq!(screen.value("nspacing"), Some(70));
    assert_eq!(
        screen.text("tmsg"),
        Some(hmi_proto::hmi::REPLY_LOST_MESSAGE)
    );
    assert_eq!(hmi.settings().spacing, Spacing::DEFAULT);
}

#[test]
fn operator_sets_spacing_and_starts() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SelectMode(Mode::SpeedAdaptive))]
    );
    assert_eq!(screen.page(), Page::Adaptive.id());
    assert_eq!(screen.value("nspacing"), Some(70));
    assert_eq!(screen.text("tgear"), Some("Low 1"));

    screen.set_value("nspacing", 180).unwrap();
    screen.release("bapply").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetSpacing(Spacing::new(180).unwrap()))]
    );
    assert_eq!(hmi.settings().spacing.raw(), 180);

    screen.release("bgearup").unwrap();
    screen.release("bgearup").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![
            cmd(Command::SelectGear(Gear::Low2)),
            cmd(Command::SelectGear(Gear::Low3))
        ]
    );
    assert_eq!(screen.text("tgear"), Some("Low 3"));

    screen.tap("bstart").unwrap();
    screen.release("bstop").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::Start), cmd(Command::Stop)]
    );

    let status = Status {
        travel_speed_kmh_x100: 52,
        target_drum_rpm_x100: 1234,
        actual_drum_rpm_x100: 1230,
        plants: 99,
        distance_dm: 4567,
        ..Status::default()
    };
    hmi.write_status(&status).unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.value("xtravel"), Some(52));
    assert_eq!(screen.value("xtarget"), Some(1234));
    assert_eq!(screen.value("xdrum"), Some(1230));
    assert_eq!(screen.value("nplants"), Some(99));
    assert_eq!(screen.value("xdist"), Some(4567));
    // Only the current page is written: nothing on the screen raised an error.
    assert_eq!(hmi.stats().tx_dropped, 0);
}

#[test]
fn out_of_range_value_shows_message_and_changes_nothing() {
    let (mut hmi, mut screen) = connected();
    screen.release("bfixed").unwrap();
    pump(&mut hmi, &mut screen);
    screen.set_value("nspeed", 4471).unwrap(); // 44.71 r/min > n_max
    screen.release("bapply").unwrap();
    let ev = pump(&mut hmi, &mut screen);
    assert_eq!(
        ev,
        vec![Event::Rejected(ParamError {
            field: Field::FixedDrumSpeed,
            value: 4471
        })]
    );
    assert_eq!(
        screen.text("tmsg"),
        Some("Drum speed must be 0-44.70 r/min")
    );
    assert_eq!(screen.value("nspeed"), Some(2521)); // old value written back
    assert_eq!(hmi.settings().fixed_drum_speed, DrumSpeed::DEFAULT);
    // -1 (0x71 FF FF FF FF) is rejected the same way, not misread.
    screen.set_value("nspeed", -1).unwrap();
    screen.release("bapply").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![Event::Rejected(ParamError {
            field: Field::FixedDrumSpeed,
            value: -1
        })]
    );
    // A valid value clears the message.
    screen.set_value("nspeed", 4470).unwrap();
    screen.release("bapply").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetFixedDrumSpeed(
            DrumSpeed::new(4470).unwrap()
        ))]
    );
    assert_eq!(screen.text("tmsg"), Some(""));
}

/// `Field::validate` (one table-driven range check) gives, for every field
/// and every raw value around its range, what the field's own type accepts
/// (`X::new`, whose bounds are the spec's, test below).
#[test]
fn validate_agrees_with_each_types_constructor() {
    let expected = |f: Field, raw: i32| -> Result<Command, ParamError> {
        Ok(match f {
            Field::MotorCoefficient => Command::SetMotorCoefficient(MotorCoefficient::new(raw)?),
            Field::FixedDrumSpeed => Command::SetFixedDrumSpeed(DrumSpeed::new(raw)?),
            Field::Spacing => Command::SetSpacing(Spacing::new(raw)?),
            Field::CalibrationDistance => {
                Command::CalibrationActualDistance(CalibrationDistance::new(raw)?)
            }
            Field::CalibrationCoefficient => {
                Command::SetCalibrationCoefficient(CalibrationCoefficient::new(raw)?)
            }
            Field::Brightness => Command::SetBrightness(Brightness::new(raw)?),
            Field::BeltSpacing => Command::SetBeltSpacing(BeltSpacing::new(raw)?),
            Field::SeedlingPitch => Command::SetSeedlingPitch(SeedlingPitch::new(raw)?),
            Field::ClampAngle => Command::SetClampAngle(ClampAngle::new(raw)?),
            Field::ClampCount => Command::SetClampCount(ClampCount::new(raw)?),
            Field::RollerRadius => Command::SetRollerRadius(RollerRadius::new(raw)?),
            Field::BeltThickness => Command::SetBeltThickness(BeltThickness::new(raw)?),
            Field::SpeedThreshold => Command::SetSpeedThreshold(SpeedThreshold::new(raw)?),
            Field::FirstPlantDistance => {
                Command::SetFirstPlantDistance(FirstPlantDistance::new(raw)?)
            }
            // ±10⁸ µr/min per count: drive_link::profile::MAX_SCALE, the
            // widest link value (the supervisor checks each parameter).
            Field::LinkValue => {
                if (-100_000_000..=100_000_000).contains(&raw) {
                    Command::SetLinkValue(raw)
                } else {
                    return Err(ParamError {
                        field: f,
                        value: raw,
                    });
                }
            }
        })
    };
    let extremes = [
        i32::MIN,
        -100_000_001,
        -100_000_000,
        -65_536,
        65_535,
        65_536,
        65_791,
        100_000_000,
        100_000_001,
        i32::MAX,
    ];
    for f in Field::ALL {
        for raw in (-2..=100_002).chain(extremes) {
            assert_eq!(f.validate(raw), expected(f, raw), "{f:?} {raw}");
        }
    }
}

#[test]
fn validation_ranges_match_the_spec() {
    assert!(Spacing::new(29).is_err() && Spacing::new(30).is_ok());
    assert!(Spacing::new(500).is_ok() && Spacing::new(501).is_err());
    assert!(DrumSpeed::new(-1).is_err() && DrumSpeed::new(0).is_ok());
    assert!(DrumSpeed::new(4470).is_ok() && DrumSpeed::new(4471).is_err());
    assert!(MotorCoefficient::new(49).is_err() && MotorCoefficient::new(50).is_ok());
    assert!(MotorCoefficient::new(200).is_ok() && MotorCoefficient::new(201).is_err());
    assert!(CalibrationCoefficient::new(799).is_err() && CalibrationCoefficient::new(800).is_ok());
    assert!(
        CalibrationCoefficient::new(1200).is_ok() && CalibrationCoefficient::new(1201).is_err()
    );
    assert!(Spacing::new(i32::MIN).is_err() && Spacing::new(i32::MAX).is_err());
    // k1 = actual / monitored (spec §4, Table 11: Low 1 0.33 / 0.32 = 1.031).
    assert_eq!(
        CalibrationCoefficient::from_distances(3300, 3200)
            .unwrap()
            .raw(),
        1031
    );
    assert!(CalibrationCoefficient::from_distances(5000, 0).is_err());
    assert!(CalibrationCoefficient::from_distances(5000, 3000).is_err());
    assert_eq!(
        Field::Spacing.validate(20).unwrap_err().to_string(),
        "Spacing must be 3.0-50.0 cm"
    );
}

#[test]
fn pitfall_touch_during_get_is_not_lost() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    screen.set_value("nspacing", 150).unwrap();
    screen.release("bapply").unwrap();
    // Deliver the touch; the MCU sends `get` but the reply is not there yet.
    hmi.push_slice(&screen.take_output());
    let mut buf = [0u8; 128];
    let n = hmi.poll_transmit(&mut buf);
    assert_eq!(&buf[..n], b"get nspacing.val\xff\xff\xff");
    assert!(hmi.awaiting_reply());
    // The operator presses Start before the screen answers: its touch frame
    // arrives first, the number after.
    screen.tap("bstart").unwrap();
    screen.feed(&buf[..n]);
    hmi.push_slice(&screen.take_output());
    let mut ev = Vec::new();
    while let Some(e) = hmi.poll_event() {
        ev.push(e);
    }
    assert_eq!(
        ev,
        vec![
            cmd(Command::SetSpacing(Spacing::new(150).unwrap())),
            cmd(Command::Start)
        ]
    );
}

#[test]
fn stop_is_never_delayed_and_queued_touches_survive_a_timeout() {
    let (mut hmi, mut screen) = connected();
    screen.release("bfixed").unwrap();
    pump(&mut hmi, &mut screen);
    hmi.tick(1000);
    screen.release("bapply").unwrap();
    hmi.push_slice(&screen.take_output());
    assert!(hmi.awaiting_reply());
    // The reply is lost. Start is queued, Stop goes through at once.
    screen.tap("bstart").unwrap();
    screen.release("bstop").unwrap();
    hmi.push_slice(&screen.take_output());
    assert_eq!(hmi.poll_event(), Some(cmd(Command::Stop)));
    assert_eq!(hmi.poll_event(), None);
    hmi.tick(1000 + GET_TIMEOUT_MS - 1);
    assert_eq!(hmi.poll_event(), None);
    hmi.tick(1000 + GET_TIMEOUT_MS);
    assert_eq!(
        hmi.poll_event(),
        Some(Event::ReplyTimeout(Field::FixedDrumSpeed))
    );
    assert_eq!(hmi.poll_event(), Some(cmd(Command::Start)));
    assert!(!hmi.awaiting_reply());
}

#[test]
fn pitfall_screen_errors_are_typed_events() {
    let (mut hmi, mut screen) = connected();
    screen.feed(b"nosuch.val=1\xff\xff\xff"); // the screen itself answers 0x1A
    screen.send(&Frame::Error(ErrorCode::BufferOverflow));
    hmi.push_slice(&screen.take_output());
    assert_eq!(
        hmi.poll_event(),
        Some(Event::ScreenError(ErrorCode::InvalidVariable))
    );
    assert_eq!(
        hmi.poll_event(),
        Some(Event::ScreenError(ErrorCode::BufferOverflow))
    );
}

/// The firmware pushes every byte it has received (up to its 64-byte receive
/// queue) before it polls the events. A screen file with wrong component
/// names answers `0x1A` (4 bytes) to every status write; the Stop pressed
/// in the same burst must still reach the machine, and so must a command.
/// Expected: `Command::Stop` among the events (docs/hmi.md §3: Stop is
/// "reported at once", "whatever the link state"); measured before the fix:
/// the eight errors filled `EVENT_QUEUE` (8) and the Stop was dropped.
#[test]
fn a_burst_of_screen_errors_never_costs_a_stop_or_a_command() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    let error = [0x1A, 0xFF, 0xFF, 0xFF];
    for _ in 0..EVENT_QUEUE {
        hmi.push_slice(&error);
    }
    hmi.push_slice(&[0x65, 0x03, 0x07, 0x01, 0xFF, 0xFF, 0xFF]); // bstop press
    hmi.push_slice(&[0x65, 0x03, 0x07, 0x00, 0xFF, 0xFF, 0xFF]); // and release
    let mut ev = Vec::new();
    while let Some(e) = hmi.poll_event() {
        ev.push(e);
    }
    assert!(ev.contains(&cmd(Command::Stop)), "{ev:?}");
    // A command behind a full queue of errors arrives too (gear up, id 4).
    for _ in 0..EVENT_QUEUE {
        hmi.push_slice(&error);
    }
    hmi.push_slice(&[0x65, 0x03, 0x04, 0x00, 0xFF, 0xFF, 0xFF]);
    let mut ev = Vec::new();
    while let Some(e) = hmi.poll_event() {
        ev.push(e);
    }
    assert_eq!(
        ev.last(),
        Some(&cmd(Command::SelectGear(Gear::Low2))),
        "{ev:?}"
    );
    // A queue full of Starts (eight taps, press and release, in 112 bytes)
    // then Stop: the last word is Stop.
    for _ in 0..EVENT_QUEUE {
        hmi.push_slice(&[0x65, 0x03, 0x0D, 0x01, 0xFF, 0xFF, 0xFF]);
        hmi.push_slice(&[0x65, 0x03, 0x0D, 0x00, 0xFF, 0xFF, 0xFF]);
    }
    hmi.push_slice(&[0x65, 0x03, 0x07, 0x00, 0xFF, 0xFF, 0xFF]);
    let mut ev = Vec::new();
    while let Some(e) = hmi.poll_event() {
        ev.push(e);
    }
    assert_eq!(ev.len(), EVENT_QUEUE, "{ev:?}");
    assert_eq!(ev[0], cmd(Command::Start), "{ev:?}");
    assert_eq!(ev.last(), Some(&cmd(Command::Stop)), "{ev:?}");
}

/// On page 3 `bstop` is id 7 and `bgeardn` id 3: one bit apart (until the
/// ids were chosen two bits from every Start, `bstart` was id 6, one bit
/// from Stop too). The screen sends Stop on press and on release
/// (docs/hmi.md §3); if the release `65 03 07 00` has its id bit 2 hit on
/// the line it reads `65 03 03 00`, a Gear - release. A single-touch screen
/// sends no other component's release between a press and its release, so
/// that frame is the Stop's release: ignored. Measured before the rule
/// (with `bstart` at id 6): `[Stop, Start]` — the drum restarted as the
/// operator lifted the finger from Stop.
#[test]
fn a_stop_release_hit_into_another_button_is_ignored() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    screen.tap("bstart").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![cmd(Command::Start)]);
    hmi.push_slice(&[0x65, 0x03, 0x07, 0x01, 0xFF, 0xFF, 0xFF]); // Stop press
    hmi.push_slice(&[0x65, 0x03, 0x03, 0x00, 0xFF, 0xFF, 0xFF]); // its release, hit
    let mut ev = Vec::new();
    while let Some(e) = hmi.poll_event() {
        ev.push(e);
    }
    assert_eq!(ev, vec![cmd(Command::Stop)]);
    // The operator's next Start is a Start.
    screen.tap("bstart").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![cmd(Command::Start)]);
    // A Stop pressed and released normally, then Start: both count.
    screen.press("bstop").unwrap();
    screen.release("bstop").unwrap();
    screen.tap("bstart").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::Stop), cmd(Command::Stop), cmd(Command::Start)]
    );
}

#[test]
fn alarm_and_acknowledge_return_to_the_page() {
    let (mut hmi, mut screen) = connected();
    screen.release("bfixed").unwrap();
    pump(&mut hmi, &mut screen);
    hmi.show_alarm("Too fast for spacing: slow down").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Alarm.id());
    assert_eq!(
        screen.text("talarm"),
        Some("Too fast for spacing: slow down")
    );
    screen.release("bok").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::AcknowledgeAlarm)]
    );
    assert_eq!(screen.page(), Page::Fixed.id());
    assert_eq!(screen.value("nspeed"), Some(2521));
}

#[test]
fn the_coefficient_button_cycles_k1_k2_k3_ground_wheel_and_labels_it() {
    let (mut hmi, mut screen) = connected();
    screen.release("bcalib").unwrap();
    pump(&mut hmi, &mut screen);
    // The page opens on the default, k2 (docs/hmi.md page 4), and each
    // press selects the next of the four, k2 again after the fourth.
    assert_eq!(screen.text("tkind"), Some("k2 track slip"));
    let cycle = [
        (CalibrationKind::BeltK3, "k3 belt slip"),
        (CalibrationKind::GroundWheel, "ground wheel pulses/m"),
        (CalibrationKind::SpeedK1, "k1 speed sensor"),
        (CalibrationKind::SlipK2, "k2 track slip"),
    ];
    for (kind, label) in cycle {
        screen.release("bkind").unwrap();
        assert_eq!(
            pump(&mut hmi, &mut screen),
            vec![cmd(Command::SelectCalibration(kind))]
        );
        assert_eq!(screen.text("tkind"), Some(label));
    }
    // Two presses before the link answers: both taken, in order.
    screen.release("bkind").unwrap();
    screen.release("bkind").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![
            cmd(Command::SelectCalibration(CalibrationKind::BeltK3)),
            cmd(Command::SelectCalibration(CalibrationKind::GroundWheel)),
        ]
    );
    assert_eq!(screen.text("tkind"), Some("ground wheel pulses/m"));
}

/// Page 6: *Travel source* asks for the next source (Hall gear → ground
/// wheel → both → Hall gear); its label follows the supervisor's settings
/// when they come back (it refuses while the drum runs). *Wheel direction*
/// toggles the ground wheel's direction at once.
#[test]
fn the_settings_page_selects_the_travel_source_and_the_wheel_direction() {
    let (mut hmi, mut screen) = connected();
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Settings.id());
    assert_eq!(screen.text("tsource"), Some("Hall gear"));
    assert_eq!(screen.text("twdir"), Some("normal"));
    let cycle = [
        (TravelSource::GroundWheel, "Ground wheel"),
        (TravelSource::Both, "Wheel + Hall"),
        (TravelSource::HallGear, "Hall gear"),
    ];
    for (source, label) in cycle {
        screen.release("bsource").unwrap();
        assert_eq!(
            pump(&mut hmi, &mut screen),
            vec![cmd(Command::SelectTravelSource(source))]
        );
        // Not taken yet: the label still shows the source in force.
        assert_ne!(screen.text("tsource"), Some(label));
        let taken = Settings {
            travel_source: source,
            ..*hmi.settings()
        };
        hmi.set_settings(taken).unwrap();
        pump(&mut hmi, &mut screen);
        assert_eq!(screen.text("tsource"), Some(label));
    }
    // Refused (the drum runs): the settings come back unchanged, and the
    // next press asks for the same source again.
    screen.release("bsource").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SelectTravelSource(TravelSource::GroundWheel))]
    );
    hmi.set_settings(*hmi.settings()).unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.text("tsource"), Some("Hall gear"));
    screen.release("bsource").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SelectTravelSource(TravelSource::GroundWheel))]
    );

    screen.release("bwdir").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetGroundWheelReversed(true))]
    );
    assert_eq!(screen.text("twdir"), Some("reversed (A/B)"));
    // The drum encoder's direction is another setting.
    assert_eq!(screen.text("tenc"), Some("normal"));
    screen.release("bwdir").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetGroundWheelReversed(false))]
    );
    assert_eq!(screen.text("twdir"), Some("normal"));
    // Shown again after a page change, from the settings.
    hmi.set_settings(Settings {
        travel_source: TravelSource::Both,
        ground_wheel_reversed: true,
        ..*hmi.settings()
    })
    .unwrap();
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.text("tsource"), Some("Wheel + Hall"));
    assert_eq!(screen.text("twdir"), Some("reversed (A/B)"));
}

/// The instructions in `bytes` (terminator-separated) that write `name`.
fn writes_of(bytes: &[u8], name: &str) -> Vec<String> {
    let prefix = format!("{name}.");
    bytes
        .split(|&b| b == 0xFF)
        .filter(|i| i.starts_with(prefix.as_bytes()))
        .map(|i| String::from_utf8_lossy(i).into_owned())
        .collect()
}

/// Moves the queued bytes to the screen; returns them.
fn sent(hmi: &mut Hmi, screen: &mut VirtualScreen) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; 512];
    loop {
        let n = hmi.poll_transmit(&mut buf);
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
    }
    screen.feed(&out);
    let back = screen.take_output();
    hmi.push_slice(&back);
    out
}

/// The run page's two texts: the live track slip (`tslip`) and the sensor
/// measuring the ground (`tground`), written when they change, and again
/// after a page change or a screen error; the numbers at every write.
#[test]
fn the_run_page_shows_the_slip_and_the_ground_sensor_when_they_change() {
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Adaptive.id());
    let mut status = Status {
        track_slip_x10: SLIP_UNKNOWN,
        travel_source_in_use: TravelSourceInUse::HallGear,
        plants: 7,
        ..Status::default()
    };
    hmi.write_status(&status).unwrap();
    let bytes = sent(&mut hmi, &mut screen);
    assert_eq!(screen.text("tslip"), Some("Slip --"));
    assert_eq!(screen.text("tground"), Some("Hall gear"));
    assert_eq!(writes_of(&bytes, "tslip").len(), 1);
    // Unchanged: the numbers again, the texts not.
    hmi.write_status(&status).unwrap();
    let bytes = sent(&mut hmi, &mut screen);
    assert_eq!(writes_of(&bytes, "nplants"), vec!["nplants.val=7"]);
    assert!(writes_of(&bytes, "tslip").is_empty());
    assert!(writes_of(&bytes, "tground").is_empty());
    // Each text when its own value changes, the slip with its sign.
    let steps: [(i16, TravelSourceInUse, &str, &str); 6] = [
        (
            42,
            TravelSourceInUse::GroundWheel,
            "Slip 4.2 %",
            "Ground wheel",
        ),
        (
            -5,
            TravelSourceInUse::GroundWheel,
            "Slip -0.5 %",
            "Ground wheel",
        ),
        (
            -123,
            TravelSourceInUse::GroundWheel,
            "Slip -12.3 %",
            "Ground wheel",
        ),
        (
            -123,
            TravelSourceInUse::HallStandIn,
            "Slip -12.3 %",
            "Hall (wheel stopped)",
        ),
        (
            SLIP_UNKNOWN,
            TravelSourceInUse::HallStandIn,
            "Slip --",
            "Hall (wheel stopped)",
        ),
        (
            1000,
            TravelSourceInUse::GroundWheel,
            "Slip 100.0 %",
            "Ground wheel",
        ),
    ];
    for (slip, in_use, slip_text, in_use_text) in steps {
        let before = status;
        status.track_slip_x10 = slip;
        status.travel_source_in_use = in_use;
        hmi.write_status(&status).unwrap();
        let bytes = sent(&mut hmi, &mut screen);
        assert_eq!(screen.text("tslip"), Some(slip_text));
        assert_eq!(screen.text("tground"), Some(in_use_text));
        assert_eq!(
            writes_of(&bytes, "tslip").len(),
            usize::from(before.track_slip_x10 != slip),
            "{slip}"
        );
        assert_eq!(
            writes_of(&bytes, "tground").len(),
            usize::from(before.travel_source_in_use != in_use),
            "{in_use:?}"
        );
    }
    // Another page has no such texts: nothing written there.
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bfixed").unwrap();
    pump(&mut hmi, &mut screen);
    status.track_slip_x10 = 31;
    hmi.write_status(&status).unwrap();
    let bytes = sent(&mut hmi, &mut screen);
    assert!(writes_of(&bytes, "tslip").is_empty());
    assert!(writes_of(&bytes, "tground").is_empty());
    // Back on the run page (its load resets the texts): written again,
    // though unchanged since they were last written there.
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.text("tslip"), Some(""));
    status.track_slip_x10 = 1000;
    hmi.write_status(&status).unwrap();
    sent(&mut hmi, &mut screen);
    assert_eq!(screen.text("tslip"), Some("Slip 100.0 %"));
    assert_eq!(screen.text("tground"), Some("Ground wheel"));
    // A screen error (the text hit on the line, say): both written again.
    hmi.push_slice(&[0x1A, 0xFF, 0xFF, 0xFF]);
    while hmi.poll_event().is_some() {}
    hmi.write_status(&status).unwrap();
    let bytes = sent(&mut hmi, &mut screen);
    assert_eq!(
        writes_of(&bytes, "tslip"),
        vec!["tslip.txt=\"Slip 100.0 %\""]
    );
    assert_eq!(writes_of(&bytes, "tground").len(), 1);
}

/// A status text that did not fit the transmit queue is not taken as
/// shown: the next status write sends it.
#[test]
fn a_status_text_the_queue_could_not_take_is_written_next_time() {
    use hmi_proto::hmi::TX_CAPACITY;
    let (mut hmi, mut screen) = connected();
    screen.release("badapt").unwrap();
    pump(&mut hmi, &mut screen);
    let mut status = Status {
        track_slip_x10: -42,
        travel_source_in_use: TravelSourceInUse::GroundWheel,
        plants: 12,
        ..Status::default()
    };
    hmi.write_status(&status).unwrap();
    sent(&mut hmi, &mut screen);
    assert_eq!(screen.text("tslip"), Some("Slip -4.2 %"));
    // The numbers alone (the texts unchanged).
    hmi.write_status(&status).unwrap();
    let numbers = sent(&mut hmi, &mut screen).len();
    // The slip changes; the queue has room for the numbers and 5 bytes
    // more, not for `tslip.txt="Slip 7.5 %"`: messages fill the rest.
    status.track_slip_x10 = 75;
    let fill = TX_CAPACITY - numbers - 5;
    while hmi.tx_pending() < fill {
        // `tmsg.txt="…"` and its terminator: 14 bytes and the text.
        let room = fill - hmi.tx_pending();
        let len = if room >= 54 + 14 {
            40
        } else if room > 54 {
            room / 2 - 14
        } else {
            room - 14
        };
        hmi.show_message(&"x".repeat(len)).unwrap();
    }
    assert_eq!(hmi.tx_pending(), fill);
    assert!(hmi.write_status(&status).is_err());
    sent(&mut hmi, &mut screen);
    assert_eq!(screen.text("tslip"), Some("Slip -4.2 %"));
    hmi.write_status(&status).unwrap();
    sent(&mut hmi, &mut screen);
    assert_eq!(screen.text("tslip"), Some("Slip 7.5 %"));
}

#[test]
fn calibration_and_settings_pages() {
    let (mut hmi, mut screen) = connected();
    screen.release("bcalib").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![]);
    assert_eq!(screen.page(), Page::Calibration.id());
    screen.release("bcstart").unwrap();
    screen.release("bcstop").unwrap();
    screen.set_value("nactual", 4950).unwrap();
    screen.release("bactual").unwrap();
    screen.set_value("nk", 966).unwrap();
    screen.release("bk").unwrap();
    screen.release("bsave").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![
            cmd(Command::CalibrationStart),
            cmd(Command::CalibrationStop),
            cmd(Command::CalibrationActualDistance(
                CalibrationDistance::new(4950).unwrap()
            )),
            cmd(Command::SetCalibrationCoefficient(
                CalibrationCoefficient::new(966).unwrap()
            )),
            cmd(Command::CalibrationAccept),
        ]
    );
    hmi.write_status(&Status {
        measured_distance_cm: 5010,
        calibration_result_x1000: 988,
        ..Status::default()
    })
    .unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.value("xmeas"), Some(5010));
    assert_eq!(screen.value("xk"), Some(988));

    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.text("tver"), Some("fw 0.1.0"));
    screen.set_value("ndim", 40).unwrap();
    screen.release("bdim").unwrap();
    screen.release("bsave").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![
            cmd(Command::SetBrightness(Brightness::new(40).unwrap())),
            cmd(Command::SaveSettings)
        ]
    );
    assert_eq!(screen.brightness(), 40);

    // The drum encoder direction toggles on page 6 and its label follows.
    assert_eq!(screen.text("tenc"), Some("normal"));
    screen.release("benc").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetDrumEncoderReversed(true))]
    );
    assert_eq!(screen.text("tenc"), Some("reversed (A/B)"));
    screen.release("benc").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetDrumEncoderReversed(false))]
    );
    assert_eq!(screen.text("tenc"), Some("normal"));

    // The placement: `bplace` asks for the other one; the label changes
    // only when the supervisor's settings come back (it refuses while the
    // drum runs), as the firmware's SettingsChanged does.
    assert_eq!(screen.text("tplace"), Some("distance-locked"));
    screen.release("bplace").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetSpeedFollowing(true))]
    );
    assert_eq!(screen.text("tplace"), Some("distance-locked"));
    let mut back = *hmi.settings();
    back.speed_following = true;
    let _ = hmi.set_settings(back);
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.text("tplace"), Some("speed-following"));
    screen.release("bplace").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetSpeedFollowing(false))]
    );

    // Page 9: the drive identification's buttons and values.
    screen.release("bdrive").unwrap();
    assert!(pump(&mut hmi, &mut screen).is_empty());
    assert_eq!(screen.page(), Page::Drive.id());
    screen.tap("bident").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::IdentifyDrive)]
    );
    hmi.write_status(&Status {
        drive_n_max_x100: 5811,
        drive_tau_x10_ms: 875,
        drive_dead_time_x10_ms: 600,
        drive_identification: 2,
        ..Status::default()
    })
    .unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.value("xnmax"), Some(5811));
    assert_eq!(screen.value("xtau"), Some(875));
    assert_eq!(screen.value("xdead"), Some(600));
    assert_eq!(screen.value("nidstate"), Some(2));
    screen.release("bidsave").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::AcceptDriveModel)]
    );
}

#[test]
fn virtual_screen_answers_like_the_real_one() {
    let mut s = VirtualScreen::with_contract();
    s.feed(b"page 2\xff\xff\xffnspeed.val=-1\xff\xff\xffget nspeed.val\xff\xff\xff");
    assert_eq!(s.take_output(), b"\x71\xff\xff\xff\xff\xff\xff\xff");
    s.feed(b"tmsg.txt=\"a\\\"b\\\\c\\rd\"\xff\xff\xffget tmsg.txt\xff\xff\xff");
    assert_eq!(s.text("tmsg"), Some("a\"b\\c\nd"));
    assert_eq!(s.take_output(), b"\x70a\"b\\c\nd\xff\xff\xff");
    s.feed(b"page 11\xff\xff\xffget nspeed.txt\xff\xff\xffbogus\xff\xff\xff");
    assert_eq!(
        s.take_output(),
        b"\x03\xff\xff\xff\x1a\xff\xff\xff\x00\xff\xff\xff"
    );
    s.feed(b"bkcmd=3\xff\xff\xffsendme\xff\xff\xffpage adaptive\xff\xff\xff");
    assert_eq!(
        s.take_output(),
        b"\x01\xff\xff\xff\x66\x02\xff\xff\xff\x01\xff\xff\xff"
    );
    assert_eq!(s.page(), 3);
    s.feed(b"tsw bstart,0\xff\xff\xff");
    assert!(s.release("bstart").is_err());
    assert!(s.release("nosuch").is_err());
    s.feed(b"baud=115200\xff\xff\xffbaud=1234\xff\xff\xff");
    assert_eq!(
        s.take_output(),
        b"\x01\xff\xff\xff\x01\xff\xff\xff\x11\xff\xff\xff"
    );
    // Overflow of the serial buffer.
    s.feed(&vec![b'a'; hmi_proto::virtual_screen::SERIAL_BUFFER + 4]);
    assert_eq!(s.take_output(), b"\x24\xff\xff\xff");
}

/// Connected in profile B (the settings given to `Hmi::new` name it).
fn connected_b() -> (Hmi, VirtualScreen) {
    let mut screen = VirtualScreen::with_contract();
    let settings = Settings {
        profile: MachineProfile::SeedlingBelt,
        ..Settings::default()
    };
    let mut hmi = Hmi::new(settings, "fw 0.1.0");
    screen.boot();
    hmi.tick(0);
    let ev = pump(&mut hmi, &mut screen);
    assert!(ev.contains(&Event::Connected), "{ev:?}");
    (hmi, screen)
}

#[test]
fn the_profile_button_cycles_a_b_and_labels_it() {
    let (mut hmi, mut screen) = connected();
    assert_eq!(hmi.active_profile(), MachineProfile::DrumBelt);
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Settings.id());
    assert_eq!(screen.text("tprofile"), Some("A: drum-belt transplanter"));

    screen.release("bprofile").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SelectProfile(MachineProfile::SeedlingBelt))]
    );
    assert_eq!(screen.text("tprofile"), Some("B: seedling-belt planter"));
    assert_eq!(hmi.settings().profile, MachineProfile::SeedlingBelt);
    // Only selected: the machine keeps running A until Save and a restart.
    assert_eq!(screen.text("tmsg"), Some(PROFILE_RESTART_MESSAGE));
    assert_eq!(hmi.active_profile(), MachineProfile::DrumBelt);
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Mode.id());

    // Back to A: the selection equals the profile running, no notice.
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.text("tprofile"), Some("B: seedling-belt planter"));
    screen.release("bprofile").unwrap();
    screen.release("bsave").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![
            cmd(Command::SelectProfile(MachineProfile::DrumBelt)),
            cmd(Command::SaveSettings)
        ]
    );
    assert_eq!(screen.text("tprofile"), Some("A: drum-belt transplanter"));
    assert_eq!(screen.text("tmsg"), Some(""));
    assert_eq!(hmi.settings().profile, MachineProfile::DrumBelt);
}

#[test]
fn profile_b_starts_on_the_belt_page_and_returns_home() {
    let (mut hmi, mut screen) = connected_b();
    assert_eq!(hmi.home_page(), Page::Belt);
    assert_eq!(screen.page(), Page::Belt.id());
    assert_eq!(
        &screen.instructions()[..5],
        ["", "sendme", "bkcmd=2", "dims=100", "page 7"]
    );

    // Parameters page: the defaults of paper B's settings, then Back to 7.
    screen.release("bpar").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![]);
    assert_eq!(screen.page(), Page::BeltParameters.id());
    for (name, v) in [
        ("nspacing", 250),
        ("npitch", 100),
        ("nangle", 120),
        ("nclamp", 2),
        ("nradius", 250),
        ("nthick", 100),
        ("nthresh", 20),
    ] {
        assert_eq!(screen.value(name), Some(v), "{name}");
    }
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Belt.id());

    // Settings page: its Back goes to the profile's home page, page 7.
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Settings.id());
    assert_eq!(screen.text("tprofile"), Some("B: seedling-belt planter"));
    assert_eq!(screen.text("tver"), Some("fw 0.1.0"));
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), Page::Belt.id());

    // Start and Stop on page 7.
    screen.tap("bstart").unwrap();
    screen.release("bstop").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::Start), cmd(Command::Stop)]
    );

    // An alarm returns to page 7; a screen reset sets it up on page 7 again.
    hmi.show_alarm("Seedling belt empty").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bok").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::AcknowledgeAlarm)]
    );
    assert_eq!(screen.page(), Page::Belt.id());
    screen.feed(b"rest\xff\xff\xff");
    assert_eq!(pump(&mut hmi, &mut screen), vec![Event::Connected]);
    assert_eq!(screen.page(), Page::Belt.id());
}

/// Page 7's *New roll* (`broll`, id 12): a button like Start, reported on
/// release as `Command::NewRoll` (the machine decides whether it is taken
/// and answers with a message, crates/supervisor `BeltMachine::command`).
#[test]
fn profile_b_new_roll_button_sends_its_command() {
    let (mut hmi, mut screen) = connected_b();
    let c = Component::lookup(Page::Belt.id(), 12).unwrap();
    assert_eq!(
        (c.name(), c.kind(), c.role),
        ("broll", Kind::Button, Role::Action(Action::NewRoll))
    );
    // A press alone is not a touch (release only, like every button but
    // Stop).
    screen.press("broll").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![]);
    screen.release("broll").unwrap();
    assert_eq!(pump(&mut hmi, &mut screen), vec![cmd(Command::NewRoll)]);
    assert_eq!(screen.page(), Page::Belt.id());
}

/// One page-8 field: its input and Apply button, a valid and an
/// out-of-range value, the command and the message.
struct BeltCase {
    input: &'static str,
    apply: &'static str,
    field: Field,
    valid: i32,
    invalid: i32,
    command: Command,
    message: &'static str,
}

fn belt_cases() -> Vec<BeltCase> {
    vec![
        BeltCase {
            input: "nspacing",
            apply: "bspacing",
            field: Field::BeltSpacing,
            valid: 300,
            invalid: 99,
            command: Command::SetBeltSpacing(BeltSpacing::new(300).unwrap()),
            message: "Spacing X must be 10.0-100.0 cm",
        },
        BeltCase {
            input: "npitch",
            apply: "bpitch",
            field: Field::SeedlingPitch,
            valid: 120,
            invalid: 501,
            command: Command::SetSeedlingPitch(SeedlingPitch::new(120).unwrap()),
            message: "Belt pitch B must be 2.0-50.0 cm",
        },
        BeltCase {
            input: "nangle",
            apply: "bangle",
            field: Field::ClampAngle,
            valid: 90,
            invalid: 0,
            command: Command::SetClampAngle(ClampAngle::new(90).unwrap()),
            message: "Clamp angle must be 1-360 deg",
        },
        BeltCase {
            input: "nclamp",
            apply: "bclamp",
            field: Field::ClampCount,
            valid: 3,
            invalid: 13,
            command: Command::SetClampCount(ClampCount::new(3).unwrap()),
            message: "Seedlings clamped must be 1-12",
        },
        BeltCase {
            input: "nradius",
            apply: "bradius",
            field: Field::RollerRadius,
            valid: 305,
            invalid: 49,
            command: Command::SetRollerRadius(RollerRadius::new(305).unwrap()),
            message: "Roller radius must be 5.0-100.0 mm",
        },
        BeltCase {
            input: "nthick",
            apply: "bthick",
            field: Field::BeltThickness,
            valid: 80,
            invalid: 1001,
            command: Command::SetBeltThickness(BeltThickness::new(80).unwrap()),
            message: "Belt thickness must be 0.01-10.00 mm",
        },
        BeltCase {
            input: "nthresh",
            apply: "bthresh",
            field: Field::SpeedThreshold,
            valid: 30,
            invalid: -1,
            command: Command::SetSpeedThreshold(SpeedThreshold::new(30).unwrap()),
            message: "Threshold Y must be 0.001-0.200 m/s",
        },
    ]
}

#[test]
fn every_belt_parameter_is_applied_or_rejected_with_a_message() {
    let (mut hmi, mut screen) = connected_b();
    screen.release("bpar").unwrap();
    pump(&mut hmi, &mut screen);
    for case in belt_cases() {
        // Valid: the command, the settings copy follows, the message clears.
        screen.set_value(case.input, case.valid).unwrap();
        screen.release(case.apply).unwrap();
        assert_eq!(
            pump(&mut hmi, &mut screen),
            vec![cmd(case.command)],
            "{}",
            case.input
        );
        assert_eq!(screen.text("tmsg"), Some(""));
        assert_eq!(case.field.current(hmi.settings()), case.valid);
        // Out of range: rejected, message shown, the value in force written back.
        screen.set_value(case.input, case.invalid).unwrap();
        screen.release(case.apply).unwrap();
        assert_eq!(
            pump(&mut hmi, &mut screen),
            vec![Event::Rejected(ParamError {
                field: case.field,
                value: case.invalid
            })],
            "{}",
            case.input
        );
        assert_eq!(screen.text("tmsg"), Some(case.message));
        assert_eq!(screen.value(case.input), Some(case.valid), "{}", case.input);
        assert_eq!(case.field.current(hmi.settings()), case.valid);
        assert_eq!(
            Field::ALL
                .iter()
                .find(|f| **f == case.field)
                .map(|f| f.validate(case.invalid).unwrap_err().to_string()),
            Some(case.message.to_string())
        );
    }
    let b = hmi.settings().belt;
    assert_eq!(
        (
            b.spacing.raw(),
            b.seedling_pitch.raw(),
            b.clamp_angle.raw(),
            b.clamp_count.raw(),
            b.roller_radius.raw(),
            b.belt_thickness.raw(),
            b.speed_threshold.raw()
        ),
        (300, 120, 90, 3, 305, 80, 30)
    );
    // Shown again after a page change.
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bpar").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.value("nradius"), Some(305));
    assert_eq!(hmi.stats().tx_dropped, 0);
}

#[test]
fn belt_validation_ranges_match_the_contract() {
    assert!(BeltSpacing::new(99).is_err() && BeltSpacing::new(100).is_ok());
    assert!(BeltSpacing::new(1000).is_ok() && BeltSpacing::new(1001).is_err());
    assert!(SeedlingPitch::new(19).is_err() && SeedlingPitch::new(20).is_ok());
    assert!(SeedlingPitch::new(500).is_ok() && SeedlingPitch::new(501).is_err());
    assert!(ClampAngle::new(0).is_err() && ClampAngle::new(1).is_ok());
    assert!(ClampAngle::new(360).is_ok() && ClampAngle::new(361).is_err());
    assert!(ClampCount::new(0).is_err() && ClampCount::new(1).is_ok());
    assert!(ClampCount::new(12).is_ok() && ClampCount::new(13).is_err());
    assert!(RollerRadius::new(49).is_err() && RollerRadius::new(50).is_ok());
    assert!(RollerRadius::new(1000).is_ok() && RollerRadius::new(1001).is_err());
    assert!(BeltThickness::new(0).is_err() && BeltThickness::new(1).is_ok());
    assert!(BeltThickness::new(1000).is_ok() && BeltThickness::new(1001).is_err());
    assert!(SpeedThreshold::new(0).is_err() && SpeedThreshold::new(1).is_ok());
    assert!(SpeedThreshold::new(200).is_ok() && SpeedThreshold::new(201).is_err());
    assert!(ClampCount::new(i32::MAX).is_err() && ClampAngle::new(i32::MIN).is_err());
}

#[test]
fn belt_page_status_lands_on_its_components() {
    let (mut hmi, mut screen) = connected_b();
    // The screen's late answer to the handshake `sendme` (page 0) does not
    // make the MCU forget that it shows page 7: its status is written at once.
    assert_eq!(hmi.page(), Page::Belt);
    let status = Status {
        travel_speed_kmh_x100: 108,
        travel_speed_mps_x100: 30,
        plant_motor_rpm_x100: 2149,
        feed_motor_rpm_x100: 1146,
        roller_turns: 17,
        roller_radius_dmm: 420,
        plants: 321,
        ..Status::default()
    };
    hmi.write_status(&status).unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.value("xtravel"), Some(30)); // m/s x 100, not km/h
    assert_eq!(screen.value("xn1"), Some(2149));
    assert_eq!(screen.value("xn2"), Some(1146));
    assert_eq!(screen.value("nj"), Some(17));
    assert_eq!(screen.value("xrad"), Some(420));
    assert_eq!(screen.value("nplants"), Some(321));
    // Page 8 shows no status: nothing is written there.
    screen.release("bpar").unwrap();
    pump(&mut hmi, &mut screen);
    let before = screen.instructions().len();
    hmi.write_status(&status).unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.instructions().len(), before);
}

#[test]
fn stop_on_the_belt_page_is_never_delayed() {
    let (mut hmi, mut screen) = connected_b();
    screen.release("bpar").unwrap();
    pump(&mut hmi, &mut screen);
    hmi.tick(500);
    screen.set_value("nspacing", 400).unwrap();
    screen.release("bspacing").unwrap();
    hmi.push_slice(&screen.take_output());
    let mut buf = [0u8; 128];
    let n = hmi.poll_transmit(&mut buf);
    assert_eq!(&buf[..n], b"get nspacing.val\xff\xff\xff");
    assert!(hmi.awaiting_reply());
    // Back is queued behind the reply; a Stop from page 7 (id 2) is not.
    screen.release("bback").unwrap();
    screen.send(&Frame::Touch {
        page: Page::Belt.id(),
        component: 2,
        event: hmi_proto::TouchEvent::Release,
    });
    hmi.push_slice(&screen.take_output());
    assert_eq!(hmi.poll_event(), Some(cmd(Command::Stop)));
    assert_eq!(hmi.poll_event(), None);
    // The reply arrives: the value, then the queued Back to page 7.
    screen.feed(&buf[..n]);
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetBeltSpacing(BeltSpacing::new(400).unwrap()))]
    );
    assert_eq!(screen.page(), Page::Belt.id());
    // And with the reply lost, Stop on page 7 still goes through at once.
    screen.release("bpar").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bthresh").unwrap();
    hmi.push_slice(&screen.take_output());
    assert!(hmi.awaiting_reply());
    screen.send(&Frame::Touch {
        page: Page::Belt.id(),
        component: 2,
        event: hmi_proto::TouchEvent::Release,
    });
    hmi.push_slice(&screen.take_output());
    assert_eq!(hmi.poll_event(), Some(cmd(Command::Stop)));
    hmi.tick(500 + GET_TIMEOUT_MS);
    assert_eq!(
        hmi.poll_event(),
        Some(Event::ReplyTimeout(Field::SpeedThreshold))
    );
}

#[test]
fn docs_list_every_component() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/hmi.md"))
        .expect("docs/hmi.md");
    for p in Page::ALL {
        let row = format!("### Page {} `{}`", p.id(), p.name());
        assert!(doc.contains(&row), "missing {row}");
    }
    for c in COMPONENTS {
        let row = format!("| {} | `{}` |", c.id(), c.name());
        assert!(doc.contains(&row), "missing {row} ({:?})", c.page);
    }
    // A builder creates the components in the order listed (the editor's
    // ids): each page's table lists ids 1, 2, 3, … in that order, and
    // exactly the contract's.
    for p in Page::ALL {
        let heading = format!("### Page {} `{}`", p.id(), p.name());
        let section = doc.split(&heading).nth(1).expect("page section");
        let section = section.split("### Page").next().unwrap_or("");
        let listed: Vec<(u8, &str)> = section
            .lines()
            .filter_map(|l| {
                let mut cells = l.split('|').map(str::trim);
                cells.next()?;
                let id = cells.next()?.parse().ok()?;
                let name = cells.next()?.strip_prefix('`')?.strip_suffix('`')?;
                Some((id, name))
            })
            .collect();
        let mut contract: Vec<(u8, &str)> =
            Component::on_page(p).map(|c| (c.id(), c.name())).collect();
        contract.sort_unstable();
        // (The doc may list static components the MCU never touches, such
        // as page 3's label `tqlabel`.)
        let known: Vec<(u8, &str)> = listed
            .iter()
            .copied()
            .filter(|&(id, _)| Component::lookup(p.id(), id).is_some())
            .collect();
        assert_eq!(known, contract, "page {p:?}: rows in the doc's order");
        // The rest are the screen file's static texts, which the contract
        // knows by page, id and name.
        let statics: Vec<(u8, &str)> = listed
            .iter()
            .copied()
            .filter(|&(id, _)| Component::lookup(p.id(), id).is_none())
            .collect();
        let expected: Vec<(u8, &str)> = STATIC_TEXTS
            .iter()
            .filter(|s| s.0 == p)
            .map(|s| (s.1, s.2))
            .collect();
        assert_eq!(statics, expected, "page {p:?}: static texts");
        let ids: Vec<u8> = listed.iter().map(|&(id, _)| id).collect();
        let dense: Vec<u8> = (1..=u8::try_from(ids.len()).unwrap_or(u8::MAX)).collect();
        assert_eq!(ids, dense, "page {p:?}: ids 1..n in creation order");
    }
}

/// A Stop survives one lost or corrupted frame only if the screen sends it
/// on press *and* on release (docs/hmi.md §3); a builder follows the page
/// tables, so every Stop row must say so, and §3 must name the pages that
/// have one. Measured before the fix: page 9's `bstop` row said "Release:
/// Send ID" only, and §3 named pages 4, 7 and 2 (page 4 has no Stop; 3 and
/// 9 were missing).
/// docs/hmi.md's row of component `c` in its page's table.
#[allow(clippy::expect_used, clippy::panic, clippy::unwrap_used)]
fn doc_row<'d>(doc: &'d str, c: &Component) -> &'d str {
    let heading = format!("### Page {} `{}`", c.page.id(), c.page.name());
    let section = doc.split(&heading).nth(1).expect("page section");
    let section = section.split("### Page").next().unwrap();
    let row_start = format!("| {} | `{}` |", c.id(), c.name());
    section
        .lines()
        .find(|l| l.starts_with(&row_start))
        .unwrap_or_else(|| panic!("no row for {:?} {}", c.page, c.name()))
}

#[allow(clippy::expect_used)]
fn hmi_doc() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/hmi.md"))
        .expect("docs/hmi.md")
}

#[test]
fn docs_ask_for_press_and_release_on_every_stop() {
    let doc = hmi_doc();
    let mut stop_pages = Vec::new();
    for c in COMPONENTS
        .iter()
        .filter(|c| c.role == Role::Action(Action::Stop))
    {
        let row = doc_row(&doc, c);
        assert!(row.contains("Press **and** Release"), "{:?}: {row}", c.page);
        stop_pages.push(c.page.id());
    }
    stop_pages.sort_unstable();
    assert_eq!(stop_pages, [2, 3, 7, 9]);
    assert!(
        doc.contains("(`bstop` on pages 2, 3 and 9 of profile A and page 7 of profile B)"),
        "§3 names the Stop pages"
    );
}

/// A builder follows the page tables: every motor-starting button's row
/// must ask for its ID on press and on release (docs/hmi.md §6), and §3
/// must name them.
#[test]
fn docs_ask_for_press_and_release_on_every_motor_start() {
    let doc = hmi_doc();
    for c in COMPONENTS
        .iter()
        .filter(|c| matches!(c.role, Role::Action(a) if a.starts_motor()))
    {
        let row = doc_row(&doc, c);
        assert!(row.contains("Press **and** Release"), "{:?}: {row}", c.page);
    }
    assert!(
        doc.contains("(`bstart` on pages 2, 3 and 7, `bident` on page\n  9)"),
        "§3 names the motor-starting buttons"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    /// The same session gives the same events however both directions are chunked.
    #[test]
    fn session_is_split_invariant(chunks in proptest::collection::vec(1usize..9, 1..40)) {
        let run = |chunks: &[usize]| {
            let mut screen = VirtualScreen::with_contract();
            let mut hmi = Hmi::new(Settings::default(), "fw");
            screen.boot();
            hmi.tick(0);
            let mut events = Vec::new();
            let mut k = 0usize;
            let mut buf = [0u8; 512];
            let script: &[&dyn Fn(&mut VirtualScreen)] = &[
                &|s| { let _ = s.release("badapt"); },
                &|s| { let _ = s.set_value("nspacing", 250); let _ = s.release("bapply"); let _ = s.tap("bstart"); },
                &|s| { let _ = s.set_value("nspacing", 5); let _ = s.release("bapply"); },
                &|s| { let _ = s.release("bgeardn"); let _ = s.release("bstop"); },
            ];
            for step in 0..=script.len() {
                for _ in 0..50 {
                    let n = hmi.poll_transmit(&mut buf);
                    let mut i = 0;
                    while i < n {
                        let c = chunks[k % chunks.len()]; k += 1;
                        let end = (i + c).min(n);
                        screen.feed(&buf[i..end]);
                        i = end;
                    }
                    let back = screen.take_output();
                    let mut i = 0;
                    while i < back.len() {
                        let c = chunks[k % chunks.len()]; k += 1;
                        let end = (i + c).min(back.len());
                        hmi.push_slice(&back[i..end]);
                        i = end;
                    }
                    while let Some(e) = hmi.poll_event() { events.push(e); }
                }
                if let Some(f) = script.get(step) { f(&mut screen); }
            }
            events
        };
        let reference = run(&[usize::MAX / 2]);
        prop_assert_eq!(reference.len(), 7);
        prop_assert_eq!(run(&chunks), reference);
    }
}

/// The `sendme` instructions the screen has received.
fn sendmes(screen: &VirtualScreen) -> usize {
    screen
        .instructions()
        .iter()
        .filter(|i| *i == "sendme")
        .count()
}

#[test]
fn a_screen_that_goes_silent_is_asked_then_lost_then_set_up_again() {
    let (mut hmi, mut screen) = connected(); // at 0 ms
    let mut buf = [0u8; 256];
    // Quiet for less than a heartbeat: nothing is sent.
    hmi.tick(HEARTBEAT_MS - 1);
    assert_eq!(hmi.poll_transmit(&mut buf), 0);
    // The cable is cut now: what the MCU sends is lost, nothing comes back.
    hmi.tick(HEARTBEAT_MS);
    let n = hmi.poll_transmit(&mut buf);
    assert_eq!(&buf[..n], b"sendme\xff\xff\xff");
    hmi.tick(2 * HEARTBEAT_MS);
    let n = hmi.poll_transmit(&mut buf);
    assert_eq!(&buf[..n], b"sendme\xff\xff\xff");
    hmi.tick(LINK_TIMEOUT_MS - 1);
    assert!(hmi.is_connected());
    assert_eq!(hmi.poll_event(), None);
    // Silent for LINK_TIMEOUT_MS since the connection: lost, and the
    // handshake starts over at once.
    hmi.tick(LINK_TIMEOUT_MS);
    assert!(!hmi.is_connected());
    assert_eq!(hmi.poll_event(), Some(Event::Disconnected));
    assert_eq!(hmi.stats().link_losses, 1);
    let n = hmi.poll_transmit(&mut buf);
    assert_eq!(&buf[..n], b"\xff\xff\xffsendme\xff\xff\xff");
    // Live status is not queued for a screen that is not there.
    hmi.write_status(&Status::default()).unwrap();
    assert_eq!(hmi.tx_pending(), 0);
    // Meanwhile the screen shows another page (as after a power cycle of
    // its own); the cable is mended and the next handshake is answered:
    // set up again, on the home page.
    screen.feed(b"page 2\xff\xff\xff");
    let _ = screen.take_output();
    assert_eq!(screen.page(), Page::Fixed.id());
    hmi.tick(LINK_TIMEOUT_MS + HANDSHAKE_RETRY_MS);
    assert_eq!(pump(&mut hmi, &mut screen), vec![Event::Connected]);
    assert!(hmi.is_connected());
    assert_eq!(screen.page(), Page::Mode.id());
}

#[test]
fn an_answering_screen_is_asked_once_a_heartbeat_and_never_lost() {
    let (mut hmi, mut screen) = connected();
    let before = sendmes(&screen);
    // One minute of 20 ms ticks with nothing touched; the screen answers
    // every `sendme` at once. Expected (by hand): a heartbeat at 1 s,
    // 2 s, … 59 s after the connection at 0 ms, each answered, so 59.
    let mut events = Vec::new();
    for t in (0..60_000u32).step_by(20) {
        hmi.tick(t);
        events.extend(pump(&mut hmi, &mut screen));
    }
    assert!(events.is_empty(), "{events:?}");
    assert_eq!(sendmes(&screen) - before, 59);
    assert_eq!(hmi.stats().link_losses, 0);
}

proptest! {
    /// Whatever the tick schedule (10–50 ms, as the firmware's HMI task
    /// runs), a screen that answers is never declared lost, and one that
    /// stops answering is lost at the first tick at least LINK_TIMEOUT_MS
    /// after the last frame it sent.
    #[test]
    fn link_supervision_follows_the_screen(
        gaps in prop::collection::vec(10u32..=50, 1..400),
        cut_at in 0usize..400,
    ) {
        let (mut hmi, mut screen) = connected();
        let mut now = 0u32;
        let mut heard = 0u32; // the connection counts as heard at 0 ms
        let mut lost_at = None;
        for (i, gap) in gaps.iter().enumerate() {
            now += gap;
            hmi.tick(now);
            if i < cut_at {
                let mut buf = [0u8; 512];
                let n = hmi.poll_transmit(&mut buf);
                screen.feed(&buf[..n]);
                let back = screen.take_output();
                if !back.is_empty() {
                    heard = now;
                }
                hmi.push_slice(&back);
            } else {
                let mut buf = [0u8; 512];
                hmi.poll_transmit(&mut buf);
            }
            while let Some(e) = hmi.poll_event() {
                prop_assert_eq!(e, Event::Disconnected);
                prop_assert!(lost_at.is_none());
                lost_at = Some(now);
            }
            if lost_at.is_none() {
                prop_assert!(now - heard < LINK_TIMEOUT_MS, "not lost at {} (heard {})", now, heard);
            }
        }
        if let Some(t) = lost_at {
            prop_assert!(t - heard >= LINK_TIMEOUT_MS);
            prop_assert!(t - heard < LINK_TIMEOUT_MS + 50);
        }
    }
}

/// Page 10 (docs/hmi.md): from page 9's `blink`, the selector walks the
/// link settings (label in `tlpar`, each step a command so that the
/// supervisor sends the value back), `blval` reads `nlval` and commands the
/// value for the selected one with the restart notice; a value beyond
/// ±10⁸ is refused on the screen, the old value written back.
#[test]
fn page_10_edits_the_drive_link_one_setting_at_a_time() {
    let (mut hmi, mut screen) = connected();
    screen.release("bset").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("bdrive").unwrap();
    pump(&mut hmi, &mut screen);
    screen.release("blink").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), 10);
    assert_eq!(screen.text("tlpar"), Some("Feedback 0enc 1drv 2both"));
    let mut seen = vec![LinkParameter::Feedback];
    let n = LinkParameter::ALL.len();
    for _ in 0..n {
        screen.release("blpar").unwrap();
        let ev = pump(&mut hmi, &mut screen);
        let [Event::Command(Command::SelectLinkParameter(p))] = ev[..] else {
            panic!("{ev:?}");
        };
        assert_eq!(screen.text("tlpar"), Some(p.label()));
        seen.push(p);
    }
    // One step each: every parameter once, back to the first.
    assert_eq!(seen[..n], LinkParameter::ALL);
    assert_eq!(seen[n], LinkParameter::Feedback);
    screen.set_value("nlval", 1).unwrap();
    screen.release("blval").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![cmd(Command::SetLinkValue(1))]
    );
    assert_eq!(screen.text("tmsg"), Some("Save, then restart to apply"));
    screen.set_value("nlval", 100_000_001).unwrap();
    screen.release("blval").unwrap();
    assert_eq!(
        pump(&mut hmi, &mut screen),
        vec![Event::Rejected(ParamError {
            field: Field::LinkValue,
            value: 100_000_001
        })]
    );
    assert_eq!(screen.value("nlval"), Some(1));
    screen.release("bback").unwrap();
    pump(&mut hmi, &mut screen);
    assert_eq!(screen.page(), 9);
}
