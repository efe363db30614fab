//! The model against the Nextion Instruction Set's own rules and examples
//! (<https://nextion.tech/instruction-set/>). Each test names the section it
//! follows ("NIS 7.26" is §7, item 26). Components are the screen file's of
//! docs/hmi.md: `tmsg` (Text), `nplants` (Number), `bstop` (Button, id 7 on
//! page 3), `nspacing` (Xfloat, keyboard, global).

use nextion_model::{codes, Config, NoteKind, Overflow, Screen};

const T: &[u8] = &[0xFF, 0xFF, 0xFF];

/// `instruction FF FF FF`.
fn i(s: &str) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.extend_from_slice(T);
    v
}

/// A frame `header payload FF FF FF`.
fn f(header: u8, payload: &[u8]) -> Vec<u8> {
    codes::frame(header, payload)
}

/// A screen past its start-up, output empty, showing page 3 `adaptive`.
fn on_page_3() -> Screen {
    let mut s = Screen::new();
    s.receive(0, &i("page 3"));
    s.take_output();
    s
}

/// Send instructions at `t`, return what the screen answered.
fn send(s: &mut Screen, t: u64, instructions: &[&str]) -> Vec<u8> {
    for x in instructions {
        s.receive(t, &i(x));
    }
    s.take_output()
}

#[test]
fn nis_1_1_and_1_10_an_instruction_runs_when_its_three_ff_arrive() {
    let mut s = on_page_3();
    s.receive(10, b"page 1");
    s.receive(20, &[0xFF, 0xFF]);
    assert_eq!(s.page(), 3, "unterminated: waits");
    assert_eq!(s.buffered(), 8);
    s.receive(30, &[0xFF]);
    assert_eq!(s.page(), 1);
    assert_eq!(s.buffered(), 0);
    // Any three FF end an instruction: FF FF FF alone is an empty one, the
    // fourth FF starts the next.
    s.receive(40, &[0xFF, 0xFF, 0xFF, 0xFF]);
    s.receive(50, b"sendme\xFF\xFF\xFF");
    assert_eq!(
        s.take_output(),
        f(0x1A, &[]),
        "FF then sendme: no such word"
    );
    let e = s.errors().last().cloned();
    assert_eq!(e.map(|e| (e.code, e.sent)), Some((0x1A, true)));
}

#[test]
fn nis_1_3_instructions_are_lower_case() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["SENDME"]), f(0x1A, &[]));
    assert_eq!(send(&mut s, 2, &["PAGE 1"]), f(0x00, &[]));
    assert_eq!(s.page(), 3);
}

#[test]
fn nis_1_6_no_spaces_in_parameters() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["tmsg.txt = \"x\""]), f(0x1A, &[]));
    assert_eq!(s.text("tmsg").as_deref(), Some(""));
    // printh separates its bytes with spaces (NIS 3.18).
    assert_eq!(send(&mut s, 2, &["printh 0d 0a"]), vec![0x0D, 0x0A]);
}

#[test]
fn nis_1_11_escapes_are_cr_quote_and_backslash() {
    let mut s = on_page_3();
    assert!(send(&mut s, 1, &[r#"tmsg.txt="a\rb \"q\" \\""#]).is_empty());
    assert_eq!(s.text_bytes("tmsg"), Some(&b"a\r\nb \"q\" \\"[..]));
    assert_eq!(
        send(&mut s, 2, &["get tmsg.txt"]),
        f(0x70, b"a\r\nb \"q\" \\")
    );
    assert_eq!(send(&mut s, 3, &[r#"tmsg.txt="\n""#]), f(0x20, &[]));
}

#[test]
fn nis_1_12_no_order_of_operations() {
    let mut s = on_page_3();
    assert!(send(&mut s, 1, &["sys0=3+8*4", "nplants.val=sys0"]).is_empty());
    assert_eq!(s.value("nplants"), Some(44), "(3+8)*4, left to right");
    assert_eq!(send(&mut s, 2, &["sys0=3+(8*4)"]), f(0x1B, &[]));
}

#[test]
fn nis_1_18_and_1_26_hex_constants_are_byte_aligned() {
    let mut s = on_page_3();
    assert!(send(&mut s, 1, &["nplants.val=0x01FF"]).is_empty());
    assert_eq!(s.value("nplants"), Some(0x01FF));
    assert_eq!(send(&mut s, 2, &["nplants.val=0x123"]), f(0x1A, &[]));
    assert_eq!(s.value("nplants"), Some(0x01FF));
}

#[test]
fn nis_2_text_assignment_append_and_remove() {
    let mut s = on_page_3();
    send(&mut s, 1, &["tmsg.txt=\"Hello\"", "tmsg.txt+=\" World\""]);
    assert_eq!(s.text("tmsg").as_deref(), Some("Hello World"));
    send(&mut s, 2, &["tmsg.txt-=4"]);
    assert_eq!(s.text("tmsg").as_deref(), Some("Hello W"));
    send(&mut s, 3, &["tgear.txt=tmsg.txt+\"!\""]);
    assert_eq!(s.text("tgear").as_deref(), Some("Hello W!"));
    send(
        &mut s,
        4,
        &["nplants.val=7", "nplants.val+=3", "nplants.val++"],
    );
    assert_eq!(s.value("nplants"), Some(11));
}

#[test]
fn nis_3_1_page_by_index_or_name() {
    let mut s = on_page_3();
    assert!(send(&mut s, 1, &["page 0"]).is_empty());
    assert_eq!(s.page(), 0);
    assert!(send(&mut s, 2, &["page belt"]).is_empty());
    assert_eq!((s.page(), s.page_name()), (7, "belt"));
    // 0x03: invalid page id or name (NIS 7.4).
    assert_eq!(
        send(&mut s, 3, &["page 12", "page main"]),
        [f(3, &[]), f(3, &[])].concat()
    );
    assert_eq!(s.page(), 7);
}

#[test]
fn nis_3_6_get_and_7_25_7_26_data_frames() {
    let mut s = on_page_3();
    send(&mut s, 1, &["tmsg.txt=\"ab123\"", "nplants.val=67305985"]);
    // NIS 7.25: 0x70 0x61 0x62 0x31 0x32 0x33 is "ab123".
    assert_eq!(send(&mut s, 2, &["get tmsg.txt"]), f(0x70, b"ab123"));
    // NIS 7.26: 0x71 0x01 0x02 0x03 0x04 is 67305985.
    assert_eq!(
        send(&mut s, 3, &["get nplants.val"]),
        f(0x71, &[1, 2, 3, 4])
    );
    // NIS 3.6: constants.
    assert_eq!(send(&mut s, 4, &["get \"123\""]), f(0x70, b"123"));
    assert_eq!(send(&mut s, 5, &["get 123"]), f(0x71, &[0x7B, 0, 0, 0]));
    // A negative number is its two's complement, little-endian.
    send(&mut s, 6, &["nplants.val=-1"]);
    assert_eq!(send(&mut s, 7, &["get nplants.val"]), f(0x71, &[0xFF; 4]));
    assert_eq!(send(&mut s, 8, &["get nosuch.val"]), f(0x1A, &[]));
}

#[test]
fn nis_3_7_sendme_and_7_22_current_page() {
    let mut s = Screen::new();
    s.take_output();
    assert_eq!(send(&mut s, 1, &["page 1", "sendme"]), f(0x66, &[1]));
    assert_eq!(send(&mut s, 2, &["sendme 1"]), f(0x1E, &[]));
}

#[test]
fn nis_3_11_vis_and_3_12_tsw_disable_touch() {
    let mut s = on_page_3();
    assert!(send(&mut s, 1, &["vis bstop,0"]).is_empty());
    assert_eq!(s.visible("bstop"), Some(false));
    assert_eq!(s.press(2, "bstop"), nextion_model::Touch::Hidden);
    send(&mut s, 3, &["vis 7,1", "tsw bstop,0"]);
    assert_eq!(s.press(4, "bstop"), nextion_model::Touch::Disabled);
    send(&mut s, 5, &["tsw 255,1"]);
    assert_eq!(s.press(6, "bstop"), nextion_model::Touch::Sent);
    assert_eq!(s.take_output(), f(0x65, &[3, 7, 1]));
    // 0x02: invalid component id or name (NIS 7.3); 0x1E: parameter count.
    assert_eq!(
        send(&mut s, 7, &["vis nosuch,0", "ref 99", "vis bstop"]),
        [f(2, &[]), f(2, &[]), f(0x1E, &[])].concat()
    );
    // A page load shows everything again.
    send(&mut s, 8, &["vis 255,0", "page 3"]);
    assert_eq!(s.visible("bstart"), Some(true));
}

#[test]
fn nis_3_3_click_triggers_the_event_with_its_send_component_id() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["click bstop,1"]), f(0x65, &[3, 7, 1]));
    assert_eq!(send(&mut s, 2, &["click 2,0"]), f(0x65, &[3, 2, 0]));
    assert!(
        send(&mut s, 3, &["click 2,1"]).is_empty(),
        "Apply: release only"
    );
}

#[test]
fn nis_3_17_print_prints_and_3_18_printh() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["print \"123\""]), b"123");
    assert_eq!(send(&mut s, 2, &["print 123"]), [0x7B, 0, 0, 0]);
    assert_eq!(send(&mut s, 3, &["prints \"123\",2"]), b"12");
    assert_eq!(send(&mut s, 4, &["prints 123,2"]), [0x7B, 0]);
    assert_eq!(send(&mut s, 5, &["printh 0d"]), [0x0D]);
    assert_eq!(
        send(&mut s, 6, &["printh 65 03 07 01 ff ff ff"]),
        f(0x65, &[3, 7, 1])
    );
}

#[test]
fn nis_3_13_com_stop_holds_instructions_until_com_star() {
    let mut s = on_page_3();
    send(&mut s, 1, &["com_stop", "page 1", "sendme"]);
    assert_eq!(s.page(), 3);
    assert_eq!(s.buffered(), 18);
    assert_eq!(send(&mut s, 2, &["com_star"]), f(0x66, &[1]));
}

#[test]
fn nis_3_16_code_c_drops_the_queued_instructions() {
    let mut s = Screen::with_config(Config {
        instruction_us: 1_000,
        ..Config::default()
    });
    s.receive(0, &i("page 3"));
    s.advance(10_000);
    s.take_output();
    s.receive(10_000, &[i("code_c"), i("sendme")].concat());
    s.advance(20_000);
    assert!(s.take_output().is_empty(), "sendme cleared before it ran");
    assert!(s.notes().iter().any(|n| n.kind == NoteKind::Cleared));
}

#[test]
fn nis_3_22_rest_and_7_19_7_29_startup_then_ready() {
    let mut s = on_page_3();
    send(&mut s, 1, &["bkcmd=3", "dim=30"]);
    assert_eq!(
        send(&mut s, 2, &["rest"]),
        [vec![0, 0, 0, 0xFF, 0xFF, 0xFF], f(0x88, &[])].concat()
    );
    assert_eq!((s.page(), s.bkcmd(), s.brightness()), (0, 2, 100));
    assert_eq!(s.text("tmsg").as_deref(), Some("Connecting..."));
}

#[test]
fn a_screen_starting_loses_the_bytes_it_receives() {
    let mut s = Screen::with_config(Config {
        boot_us: 500_000,
        ..Config::default()
    });
    assert!(s.booting());
    s.receive(100_000, &i("sendme"));
    s.advance(500_000);
    assert!(!s.booting());
    assert_eq!(
        s.take_output_timed().first().map(|&(t, b)| (t, b)),
        Some((500_087, 0))
    );
    assert!(s
        .notes()
        .iter()
        .any(|n| n.kind == NoteKind::DroppedWhileBooting));
}

#[test]
fn nis_6_2_dims_persists_over_a_reset_dim_does_not() {
    let mut s = on_page_3();
    send(&mut s, 1, &["dims=40", "dim=70"]);
    assert_eq!((s.brightness(), s.saved_brightness()), (70, 40));
    send(&mut s, 2, &["rest"]);
    assert_eq!(s.brightness(), 40);
    assert_eq!(send(&mut s, 3, &["dim=101"]), f(0x1C, &[]));
}

#[test]
fn nis_6_3_baud_rates() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["baud=12345"]), f(0x11, &[]));
    assert!(send(&mut s, 2, &["baud=9600"]).is_empty());
    assert_eq!(s.baud(), 9600);
    // One byte takes 10 bits: 1.042 ms at 9600.
    s.receive(10_000, &i("sendme"));
    assert_eq!(
        s.take_output_timed().last().map(|&(t, _)| t),
        Some(10_000 + 5_209)
    );
    send(&mut s, 20_000, &["rest"]);
    assert_eq!(s.baud(), 115_200, "baud is not saved; bauds is");
}

#[test]
fn nis_6_11_delay_holds_the_next_instructions() {
    let mut s = on_page_3();
    s.receive(0, &[i("delay=100"), i("sendme")].concat());
    assert!(s.take_output_until(99_999).is_empty());
    let out = s.take_output_until(200_000);
    assert_eq!(out.first().map(|&(t, b)| (t, b)), Some((100_087, 0x66)));
}

#[test]
fn nis_6_12_asleep_only_get_print_printh_wup_sleep_run() {
    let mut s = on_page_3();
    assert!(send(&mut s, 1, &["sleep=1", "page 1"]).is_empty());
    assert_eq!(s.page(), 3, "page ignored asleep");
    assert!(s.notes().iter().any(|n| n.kind == NoteKind::IgnoredAsleep));
    assert_eq!(send(&mut s, 2, &["get dp"]), f(0x71, &[3, 0, 0, 0]));
    // sleep=0 wakes without 0x87 (NIS 7.28).
    assert!(send(&mut s, 3, &["sleep=0"]).is_empty());
    assert!(!s.asleep());
}

#[test]
fn nis_6_17_usup_and_6_9_thup_wake_with_0x87() {
    let mut s = on_page_3();
    send(&mut s, 1, &["usup=1", "sleep=1"]);
    assert_eq!(
        send(&mut s, 2, &["sendme"]),
        [f(0x87, &[]), f(0x66, &[3])].concat()
    );
    send(&mut s, 3, &["usup=0", "thup=0", "sleep=1"]);
    assert_eq!(s.press(4, "bstop"), nextion_model::Touch::Asleep);
    // thup is no instruction sleep mode runs: set it awake.
    send(&mut s, 5, &["thup=1", "sleep=0", "thup=1", "sleep=1"]);
    assert_eq!(s.press(6, "bstop"), nextion_model::Touch::Woke);
    assert_eq!(
        s.take_output(),
        f(0x87, &[]),
        "the waking touch is no event"
    );
}

#[test]
fn nis_6_7_ussp_sleeps_after_silence_with_0x86() {
    let mut s = on_page_3();
    send(&mut s, 1_000, &["ussp=3"]);
    s.advance(3_000_999);
    assert!(!s.asleep());
    assert_eq!(
        s.take_output_until(3_002_000),
        [
            (3_001_087, 0x86),
            (3_001_174, 0xFF),
            (3_001_261, 0xFF),
            (3_001_348, 0xFF)
        ]
    );
    assert!(s.asleep());
}

#[test]
fn nis_6_13_bkcmd_levels() {
    let mut s = on_page_3();
    let ok = "nplants.val=1";
    let bad = "nosuch.val=1";
    // Level 2 (power-on default): failures only.
    assert_eq!(send(&mut s, 1, &[ok, bad]), f(0x1A, &[]));
    assert!(send(&mut s, 2, &["bkcmd=0", ok, bad]).is_empty());
    assert_eq!(
        send(&mut s, 3, &["bkcmd=1", ok, bad]),
        [f(1, &[]), f(1, &[])].concat()
    );
    assert_eq!(
        send(&mut s, 4, &["bkcmd=3", ok, bad]),
        [f(1, &[]), f(1, &[]), f(0x1A, &[])].concat()
    );
    // Table 2 is not subject to bkcmd: data replies come at level 0 too.
    assert_eq!(send(&mut s, 5, &["bkcmd=0", "sendme"]), f(0x66, &[3]));
    // The screen knows every failure, reported or not.
    assert_eq!(s.errors().iter().filter(|e| !e.sent).count(), 2);
    assert_eq!(send(&mut s, 6, &["bkcmd=2", "bkcmd=7"]), f(0x1C, &[]));
}

#[test]
fn nis_7_11_and_7_12_invalid_variable_and_operation() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["nosuch.txt=\"a\""]), f(0x1A, &[]));
    assert_eq!(
        send(&mut s, 2, &["tmsg.val=1"]),
        f(0x1A, &[]),
        "a Text has no val"
    );
    assert_eq!(
        send(&mut s, 3, &["bstop.val=1"]),
        f(0x1A, &[]),
        "nor a Button"
    );
    assert_eq!(send(&mut s, 4, &["nplants.txt=\"1\""]), f(0x1A, &[]));
    // NIS 7.12's examples: t0.txt=abc, t0.txt=23, j0.val="50", j0.val=abc.
    assert_eq!(
        send(
            &mut s,
            5,
            &[
                "tmsg.txt=abc",
                "tmsg.txt=23",
                "nplants.val=\"50\"",
                "nplants.val=abc"
            ]
        ),
        [f(0x1B, &[]), f(0x1B, &[]), f(0x1B, &[]), f(0x1B, &[])].concat()
    );
    assert_eq!(
        send(&mut s, 6, &["tmsg.txt_maxl=50"]),
        f(0x1C, &[]),
        "read-only"
    );
    assert_eq!(send(&mut s, 7, &["abc"]), f(0x1A, &[]));
}

#[test]
fn nis_7_18_names_longer_than_14_characters() {
    let mut s = on_page_3();
    assert_eq!(send(&mut s, 1, &["abcdefghijklmno.val=1"]), f(0x23, &[]));
}

#[test]
fn local_components_exist_only_on_their_page_globals_everywhere() {
    let mut s = on_page_3();
    send(
        &mut s,
        1,
        &["xtravel.val=550", "nspacing.val=180", "tmsg.txt=\"x\""],
    );
    assert_eq!(s.shown("xtravel").as_deref(), Some("5.50"));
    send(&mut s, 2, &["page 1"]);
    // From page 1: the global keyboard field by its page's name; a local is
    // not loaded (0x1A).
    assert!(send(&mut s, 3, &["adaptive.nspacing.val=200"]).is_empty());
    assert_eq!(send(&mut s, 4, &["adaptive.xtravel.val=1"]), f(0x1A, &[]));
    assert_eq!(send(&mut s, 5, &["p[3].b[1].val=210"]), Vec::<u8>::new());
    assert_eq!(
        send(&mut s, 6, &["nspacing.val=1"]),
        f(0x1A, &[]),
        "not on page 1"
    );
    send(&mut s, 7, &["page 3"]);
    assert_eq!(s.value("nspacing"), Some(210), "global: kept");
    assert_eq!(s.value("xtravel"), Some(0), "local: design value again");
    assert_eq!(s.text("tmsg").as_deref(), Some(""));
    assert_eq!(
        s.text("tqlabel").as_deref(),
        Some("Control figures, not seedling fall")
    );
}

#[test]
fn a_text_longer_than_txt_maxl_is_cut_and_noted() {
    let mut s = on_page_3();
    let long = format!("tmsg.txt=\"{}\"", "x".repeat(45));
    assert!(send(&mut s, 1, &[&long]).is_empty());
    assert_eq!(s.text("tmsg").map(|t| t.len()), Some(40));
    assert!(s.notes().iter().any(|n| n.kind == NoteKind::TextTruncated));
}

/// A screen whose page loads take 30 ms, so that a burst queues up.
fn slow_pages(overflow: Overflow) -> Screen {
    let mut s = Screen::with_config(Config {
        page_load_us: 30_000,
        overflow,
        ..Config::default()
    });
    s.take_output();
    s
}

#[test]
fn nis_7_20_overflow_loses_the_queued_instructions_keeps_the_current_one() {
    let mut s = slow_pages(Overflow::Nextion);
    // A page load, then 1100 bytes of instructions at once: the buffer (1024)
    // fills while the page loads.
    s.receive(0, &i("page 3"));
    let filler = i("nplants.val=1234567"); // 22 bytes
    for _ in 0..46 {
        s.receive(0, &filler);
    }
    assert!(s.buffered() <= 1024);
    s.receive(0, &i("sendme"));
    s.advance(100_000);
    let out = s.take_output();
    assert_eq!(out, [f(0x24, &[]), f(0x66, &[3])].concat());
    assert_eq!(s.page(), 3, "page 3 went on loading");
    // The instruction being received when the buffer overflowed (sendme)
    // and the one executing survived; the ones queued between are lost.
    let n = s
        .executed()
        .iter()
        .filter(|e| e.instruction.starts_with(b"nplants"))
        .count();
    assert_eq!(n, 0);
    assert!(s.notes().iter().any(|n| n.kind == NoteKind::LostToOverflow));
}

#[test]
fn tjc_overflow_drops_the_bytes_until_there_is_room() {
    let mut s = slow_pages(Overflow::Tjc);
    s.receive(0, &i("page 3"));
    for _ in 0..50 {
        s.receive(0, &i("nplants.val=1234567"));
    }
    // The screen works through its queue; later instructions fit again.
    // The 47th instruction's first bytes wait in the buffer: an empty
    // instruction ends them (0x1A) before the next one.
    s.advance(100_000);
    s.receive(100_000, &[T, &i("sendme")].concat());
    let out = s.take_output();
    assert_eq!(out, [f(0x24, &[]), f(0x1A, &[]), f(0x66, &[3])].concat());
    let n = s
        .executed()
        .iter()
        .filter(|e| e.instruction == b"nplants.val=1234567")
        .count();
    assert_eq!(n, (1024 - 9) / 22, "what fitted ran; the rest was dropped");
}

#[test]
fn replies_leave_at_ten_bits_a_byte() {
    let mut s = on_page_3();
    // `sendme` paced at 115 200 baud: 9 bytes end 782 µs after the start.
    let end = s.receive_paced(1_000, &i("sendme"));
    assert_eq!(end, 1_782);
    let out = s.take_output_timed();
    let times: Vec<u64> = out.iter().map(|&(t, _)| t).collect();
    assert_eq!(times, [1_869, 1_956, 2_043, 2_130, 2_217]);
}
