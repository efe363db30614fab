//! The firmware's screen line against an independent screen, in virtual
//! time (`support/screen_rig.rs`: the screen link `Hmi`, the hmi task's line
//! code `firmware/src/screen_line.rs`, its channel and transmit ring, with
//! the Nextion model of `tests/peers/nextion` on the other end of a
//! 115 200-baud line).
//!
//! No QEMU: each case is host code in virtual time, so a busy host changes
//! nothing. Cost: about two seconds in all (the 20 000 sessions on two
//! threads take most of it).

#[path = "../../firmware/src/screen_line.rs"]
mod screen_line;
#[path = "support/screen_rig.rs"]
mod screen_rig;

use hmi_proto::hmi::{Event, HEARTBEAT_MS, RX_GAP_MS};
use hmi_proto::screen::{Command, Settings};
use screen_line::LineItem;
use screen_rig::{Act, Rig, RX_QUEUE};

/// A small deterministic generator (xorshift64*), so every run is the same.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next() % (hi - lo + 1)
    }
}

fn is_stop(e: &Event) -> bool {
    matches!(e, Event::Command(Command::Stop))
}

/// A byte and its arrival time survive the channel item, across the wrap
/// of the 8 bits of milliseconds it keeps, for any wait under 256 ms.
#[test]
fn a_line_item_keeps_the_byte_and_its_arrival_time() {
    for at in [0u32, 1, 255, 256, 0x0123_4567, u32::MAX - 3, u32::MAX] {
        for age in [0u32, 1, 9, 10, 11, 20, 100, 255] {
            for byte in [0u8, 0x65, 0xFF] {
                let item = LineItem::new(byte, at);
                assert_eq!(
                    item.received(at.wrapping_add(age)),
                    (byte, at),
                    "{at} + {age}"
                );
            }
        }
    }
}

/// Taps a button of the page shown: press (if the contract sends it) and
/// release `hold_us` later.
fn tap(rig: &mut Rig, at_us: u64, name: &'static str, hold_us: u64) {
    rig.at(at_us, Act::Press(name));
    rig.at(at_us + hold_us, Act::Release(name));
}

/// The reproducer, against the independent screen: page 6 quiet for a
/// second, the operator taps *Drive* (the MCU shows page 9) just as the
/// heartbeat `sendme` goes out, so the screen answers it with page 6 after
/// the MCU has changed the page; then Identify on page 9. Swept over the
/// release's time across the heartbeat (0.25 ms steps over 25 ms): every
/// Identify taken, the status always on page 9, and the crossing happened.
#[test]
fn a_heartbeat_answer_crossing_a_page_change_with_the_independent_screen() {
    let mut crossed = 0;
    let mut cases = 0;
    for step in 0..100u64 {
        let mut rig = Rig::connected(Settings::default());
        let t0 = rig.now_us();
        tap(&mut rig, t0, "bset", 100_000);
        rig.run_for(150_000);
        assert_eq!(rig.screen.page(), 6);
        // The last frame heard: bset's release at t0 + 100 ms (+ 0.6 ms).
        let release = t0 + 100_000 + u64::from(HEARTBEAT_MS) * 1000 - 5_000 + step * 250;
        tap(&mut rig, release - 100_000, "bdrive", 100_000);
        rig.run_until(release + 300_000);
        assert_eq!(rig.screen.page(), 9);
        cases += 1;
        crossed += u32::from(rig.hmi.stats().stale_page_answers > 0);
        assert_eq!(rig.hmi.page().id(), 9, "release at +{} µs", step * 250);
        let t = rig.now_us();
        tap(&mut rig, t, "bident", 150_000);
        let got = rig.run_until_event(t + 400_000, |e| {
            matches!(e, Event::Command(Command::IdentifyDrive))
        });
        assert!(
            got.is_some(),
            "Identify refused (release at +{} µs)",
            step * 250
        );
        rig.run_for(400_000);
        let wrong: Vec<_> = rig
            .screen
            .errors()
            .iter()
            .filter(|e| e.code == 0x1A)
            .collect();
        assert!(wrong.is_empty(), "status on the wrong page: {wrong:?}");
    }
    eprintln!("{cases} releases across the heartbeat, {crossed} crossed by its answer");
    assert!(
        crossed > 0,
        "no answer crossed the page change: the sweep missed"
    );
}

/// 20 000 operator sessions against the independent screen: from the home
/// page to a run page (Fixed, Speed-Adaptive, or via Settings to Drive),
/// each touch frame 0.99–1.01 s after the one before (so that heartbeat
/// answers cross the navigation), Start (or Identify) held 80–400 ms, Stop,
/// back home.
/// Every Start and Identify is taken, and no status write goes to a page
/// not shown (the screen would answer `0x1A`, invalid variable).
#[test]
fn twenty_thousand_operator_sessions_every_start_taken_no_status_on_a_wrong_page() {
    const SESSIONS: u64 = 20_000;
    const PER_RIG: u64 = 50;
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get() as u64);
    let results: Vec<(u64, u64, u64, u64, Vec<String>)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|th| {
                s.spawn(move || {
                    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ (th + 1));
                    let (mut starts, mut taken, mut crossed, mut wrong) = (0, 0, 0, 0);
                    let mut bad = Vec::new();
                    let mut done = 0;
                    let mine = (SESSIONS / threads) + u64::from(th < SESSIONS % threads);
                    while done < mine {
                        // Fifty sessions a screen, then a fresh one (the
                        // model keeps a log of every instruction).
                        let mut rig = Rig::connected(Settings::default());
                        for _ in 0..PER_RIG.min(mine - done) {
                            let r = session(&mut rig, &mut rng);
                            starts += 1;
                            taken += u64::from(r.is_ok());
                            if let Err(e) = r {
                                if bad.len() < 5 {
                                    bad.push(e);
                                }
                            }
                            done += 1;
                        }
                        crossed += u64::from(rig.hmi.stats().stale_page_answers);
                        wrong += rig
                            .screen
                            .errors()
                            .iter()
                            .filter(|e| e.code == 0x1A)
                            .count() as u64;
                    }
                    (starts, taken, crossed, wrong, bad)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let (mut starts, mut taken, mut crossed, mut wrong) = (0, 0, 0, 0);
    let mut bad = Vec::new();
    for (s, t, c, w, b) in results {
        starts += s;
        taken += t;
        crossed += c;
        wrong += w;
        bad.extend(b);
    }
    eprintln!(
        "{starts} sessions: {taken} Starts taken; {crossed} sendme answers crossed a page change; \
         {wrong} status writes to a page not shown"
    );
    assert_eq!(starts, SESSIONS);
    assert_eq!(taken, starts, "refused: {bad:?}");
    assert_eq!(wrong, 0);
    assert!(
        crossed > 0,
        "no answer crossed a page change: the sessions missed the case"
    );
}

/// One session from the home page; `Err` if Start was not taken. Each
/// touch frame comes 0.99–1.01 s after the one before: around the
/// heartbeat, which goes out 1 s after the last frame heard, so that its
/// answer often crosses the page change the touch makes.
fn session(rig: &mut Rig, rng: &mut Rng) -> Result<(), String> {
    let quiet = |rng: &mut Rng| rng.range(990_000, 1_010_000);
    let route: &[&'static str] = match rng.range(0, 2) {
        0 => &["bfixed"],
        1 => &["badapt"],
        _ => &["bset", "bdrive"],
    };
    // The navigation buttons send on release only: the release is the
    // frame.
    let mut last_frame = rig.now_us();
    for &b in route {
        let release = last_frame + quiet(rng);
        rig.at(release - rng.range(60_000, 200_000), Act::Press(b));
        rig.at(release, Act::Release(b));
        last_frame = release;
    }
    let (start, want) = if route.len() == 2 {
        ("bident", Command::IdentifyDrive)
    } else {
        ("bstart", Command::Start)
    };
    let press = last_frame + quiet(rng);
    let hold = rng.range(80_000, 400_000);
    tap(rig, press, start, hold);
    let got = rig.run_until_event(press + hold + 100_000, |e| *e == Event::Command(want));
    let page = rig.screen.page();
    let mut t = rig.now_us() + rng.range(200_000, 500_000);
    tap(rig, t, "bstop", 80_000);
    t += 300_000;
    // Back home.
    for _ in 0..route.len() {
        tap(rig, t, "bback", 80_000);
        t += 300_000;
    }
    rig.run_until(t);
    got.map(|_| ())
        .ok_or_else(|| format!("{want:?} refused on page {page}, route {route:?}"))
}

/// Every byte value as one stray byte on the line right before a touch of
/// the independent screen (page 3: the Stop's press; Start's press and
/// release; Gear +'s release): the touch does what it does without it.
#[test]
fn every_stray_byte_before_a_touch_with_the_independent_screen() {
    let mut lost = Vec::new();
    let mut cases = 0;
    for stray in 0..=255u8 {
        for (what, name, hold, want) in [
            (
                "Stop press",
                "bstop",
                100_000,
                Event::Command(Command::Stop),
            ),
            (
                "Start tap",
                "bstart",
                150_000,
                Event::Command(Command::Start),
            ),
            (
                "Gear + release",
                "bgearup",
                100_000,
                Event::Command(Command::SelectGear(hmi_proto::screen::Gear::Low2)),
            ),
        ] {
            cases += 1;
            let mut rig = Rig::connected(Settings::default());
            let t = rig.now_us();
            tap(&mut rig, t, "badapt", 80_000);
            rig.run_for(300_000);
            let t = rig.now_us();
            // The stray byte ends right where the touch frame starts.
            let frame_at = if name == "bgearup" { t + hold } else { t };
            if name == "bgearup" {
                rig.at(t, Act::Press(name));
                rig.at(frame_at - 87, Act::Noise(vec![stray]));
                rig.at(frame_at, Act::Release(name));
            } else {
                rig.at(frame_at - 87, Act::Noise(vec![stray]));
                rig.at(frame_at, Act::Press(name));
                rig.at(t + hold, Act::Release(name));
            }
            let got = rig.run_until_event(t + hold + 50_000, |e| *e == want);
            if got.is_none() {
                lost.push(format!("{stray:02X} before the {what}"));
            }
        }
    }
    eprintln!(
        "{cases} cases (256 byte values x 3 touches), {} lost",
        lost.len()
    );
    assert!(lost.is_empty(), "{lost:?}");
}

/// The quiet-line rule with the independent screen: while an *Apply*'s
/// `get` is awaited (a number or string frame is then read as one; the
/// screen takes 15 ms an instruction here, so the reply comes late), a
/// stray `70` (a string's header, which would take the touch as its text),
/// then the Stop's press 11 ms later: the Stop, even with the hmi task
/// 15 ms late (the bytes' arrival times count). 9 ms later the bytes are
/// one stream and the press is lost (its release still stops).
#[test]
fn the_quiet_line_rule_at_11_ms_with_the_independent_screen() {
    for (gap_ms, taken) in [(RX_GAP_MS + 1, true), (RX_GAP_MS - 1, false)] {
        for latency_us in [50, 15_000] {
            let slow = nextion_model::Config {
                instruction_us: 15_000,
                ..nextion_model::Config::default()
            };
            let mut rig = Rig::connected_to(
                nextion_model::Screen::with_config(slow),
                Settings::default(),
            );
            let t = rig.now_us();
            tap(&mut rig, t, "badapt", 80_000);
            rig.run_for(1_000_000);
            rig.task_latency_us = latency_us;
            let t = rig.now_us();
            // Apply: `get nspacing.val` goes out, answered 15 ms or more later.
            tap(&mut rig, t, "bapply", 80_000);
            let stray = t + 80_000 + 1_000;
            rig.at(stray, Act::Noise(vec![0x70]));
            let press = stray + 87 + u64::from(gap_ms) * 1000;
            rig.at(press, Act::Press("bstop"));
            let seen = rig.events.len();
            rig.run_until(press + 50_000);
            let new = &rig.events[seen..];
            let got = new.iter().find(|(_, e)| is_stop(e)).map(|(at, _)| *at);
            let reply = new
                .iter()
                .find(|(_, e)| matches!(e, Event::Command(Command::SetSpacing(_))))
                .map(|(at, _)| *at);
            assert!(
                reply.is_some_and(|r| r > press + 1_000),
                "the reply came before the press: {new:?}"
            );
            assert_eq!(
                got.is_some(),
                taken,
                "{gap_ms} ms of quiet, task {latency_us} µs late: {new:?}"
            );
            if let Some(at) = got {
                eprintln!(
                    "{gap_ms} ms quiet, task {latency_us} µs late: Stop {} µs after the press",
                    at - press
                );
            }
        }
    }
}

/// The Stop's press is never held up by a full receive queue: the MCU
/// changes the page (page 1 → 3: 379 bytes to send, 33 ms of line) while
/// the screen floods the line back to back with `1A FF FF FF` (a screen
/// file answering every write with "invalid variable") for 80 ms, and the
/// operator presses Stop 15 ms into it; the hmi task runs 3 ms after each
/// byte (the status task's budget and a control period's). The channel
/// never fills, and Stop reaches the link within the task's lateness.
#[test]
fn the_stop_press_is_never_held_up_by_a_full_receive_queue() {
    for press_ms in [5u64, 15, 27, 40] {
        let mut rig = Rig::connected(Settings::default());
        rig.task_latency_us = 3_000;
        let t = rig.now_us();
        // Page 1 → 3 (the page's settings and status values follow).
        rig.at(t, Act::Release("badapt"));
        for k in 0..230u64 {
            rig.at(t + 600 + k * 348, Act::Noise(vec![0x1A, 0xFF, 0xFF, 0xFF]));
            if k * 348 / 1000 == press_ms && (k.saturating_sub(1) * 348 / 1000) < press_ms {
                rig.at(t + 600 + k * 348 + 1, Act::Press("bstop"));
            }
        }
        rig.run_until(t + 120_000);
        let stop = rig
            .events
            .iter()
            .find(|(_, e)| is_stop(e))
            .map(|(at, _)| *at);
        let stop = stop.expect("Stop reached the link");
        let press = t + 600 + press_ms * 1000;
        eprintln!(
            "Stop pressed ~{press_ms} ms into the flood: taken {} µs after, channel peak {} of \
             {RX_QUEUE}, {} bytes dropped",
            stop - press,
            rig.channel_peak,
            rig.rx_dropped
        );
        assert_eq!(rig.rx_dropped, 0);
        assert!(rig.channel_peak < RX_QUEUE);
        // The press's 7 bytes follow at most one frame of the flood (0.35 ms),
        // then the task's 3 ms.
        assert!(stop - press <= 5_000, "{} µs", stop - press);
    }
}

/// Machine A's ground on the independent screen (docs/hmi.md pages 3 and
/// 6): the run page's live slip and ground sensor land in `tslip` and
/// `tground` as the status task writes them, each change within one status
/// period, with no error from the screen; *Travel source* and *Wheel
/// direction* on page 6 are taken as their commands and their labels follow
/// the settings.
#[test]
fn the_ground_wheel_texts_and_buttons_with_the_independent_screen() {
    use hmi_proto::screen::{Status, TravelSource, TravelSourceInUse, SLIP_UNKNOWN};
    let mut rig = Rig::connected(Settings::default());
    let t = rig.now_us();
    tap(&mut rig, t, "badapt", 100_000);
    rig.run_for(400_000);
    assert_eq!(rig.screen.page(), 3);
    assert_eq!(rig.screen.text("tslip").as_deref(), Some("Slip 0.0 %"));
    assert_eq!(rig.screen.text("tground").as_deref(), Some("Hall gear"));
    let cases: [(i16, TravelSourceInUse, &str, &str); 4] = [
        (
            SLIP_UNKNOWN,
            TravelSourceInUse::HallGear,
            "Slip --",
            "Hall gear",
        ),
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
            -5,
            TravelSourceInUse::HallStandIn,
            "Slip -0.5 %",
            "Hall (wheel stopped)",
        ),
    ];
    for (slip, in_use, slip_text, in_use_text) in cases {
        rig.status = Status {
            track_slip_x10: slip,
            travel_source_in_use: in_use,
            ..Status::default()
        };
        // One status period and the line time.
        rig.run_for(230_000);
        assert_eq!(rig.screen.text("tslip").as_deref(), Some(slip_text));
        assert_eq!(rig.screen.text("tground").as_deref(), Some(in_use_text));
    }
    // The settings page.
    let t = rig.now_us();
    tap(&mut rig, t, "bback", 100_000);
    tap(&mut rig, t + 400_000, "bset", 100_000);
    rig.run_for(800_000);
    assert_eq!(rig.screen.page(), 6);
    assert_eq!(rig.screen.text("tsource").as_deref(), Some("Hall gear"));
    assert_eq!(rig.screen.text("twdir").as_deref(), Some("normal"));
    let t = rig.now_us();
    tap(&mut rig, t, "bsource", 100_000);
    tap(&mut rig, t + 400_000, "bwdir", 100_000);
    rig.run_for(800_000);
    let commands: Vec<Command> = rig
        .events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Command(
                c @ (Command::SelectTravelSource(_) | Command::SetGroundWheelReversed(_)),
            ) => Some(*c),
            _ => None,
        })
        .collect();
    assert_eq!(
        commands,
        vec![
            Command::SelectTravelSource(TravelSource::GroundWheel),
            Command::SetGroundWheelReversed(true),
        ]
    );
    assert_eq!(rig.screen.text("twdir").as_deref(), Some("reversed (A/B)"));
    // The supervisor takes the source: the firmware's settings come back.
    let taken = Settings {
        travel_source: TravelSource::GroundWheel,
        ..*rig.hmi.settings()
    };
    rig.hmi.set_settings(taken).unwrap();
    rig.run_for(100_000);
    assert_eq!(rig.screen.text("tsource").as_deref(), Some("Ground wheel"));
    assert!(rig.screen.errors().is_empty(), "{:?}", rig.screen.errors());
}
