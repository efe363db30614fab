//! Codec tests: hand-written bytes from the Nextion Instruction Set
//! (<https://nextion.tech/instruction-set/>, ch. 1–3, 6 for instructions and
//! ch. 7 "Format of Nextion Return Data" for frames), round trips and resync.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
#![allow(clippy::arithmetic_side_effects, clippy::cast_possible_truncation)]

use hmi_proto::*;
use proptest::prelude::*;

fn decode_all(bytes: &[u8]) -> Vec<Result<Frame, DecodeError>> {
    let mut d = Decoder::new();
    let mut out = Vec::new();
    d.push_slice(bytes, |r| out.push(r));
    out
}

fn emit(i: Instruction<'_>) -> Vec<u8> {
    let mut buf = [0u8; MAX_INSTRUCTION_LEN];
    let n = i.emit(&mut buf).unwrap();
    buf[..n].to_vec()
}

fn name(s: &str) -> ObjName<'_> {
    ObjName::new(s).unwrap()
}

// ---------------------------------------------------------------- decoding

#[test]
fn decodes_every_fixed_frame_from_hand_written_bytes() {
    use ErrorCode::*;
    let cases: Vec<(&[u8], Frame)> = vec![
        (b"\x00\xff\xff\xff", Frame::Error(InvalidInstruction)),
        (b"\x00\x00\x00\xff\xff\xff", Frame::Startup),
        (b"\x01\xff\xff\xff", Frame::Success),
        (b"\x02\xff\xff\xff", Frame::Error(InvalidComponent)),
        (b"\x03\xff\xff\xff", Frame::Error(InvalidPage)),
        (b"\x04\xff\xff\xff", Frame::Error(InvalidPicture)),
        (b"\x05\xff\xff\xff", Frame::Error(InvalidFont)),
        (b"\x06\xff\xff\xff", Frame::Error(InvalidFileOperation)),
        (b"\x09\xff\xff\xff", Frame::Error(InvalidCrc)),
        (b"\x11\xff\xff\xff", Frame::Error(InvalidBaudRate)),
        (b"\x12\xff\xff\xff", Frame::Error(InvalidWaveform)),
        (b"\x1a\xff\xff\xff", Frame::Error(InvalidVariable)),
        (b"\x1b\xff\xff\xff", Frame::Error(InvalidOperation)),
        (b"\x1c\xff\xff\xff", Frame::Error(AssignmentFailed)),
        (b"\x1d\xff\xff\xff", Frame::Error(EepromFailed)),
        (b"\x1e\xff\xff\xff", Frame::Error(InvalidParameterCount)),
        (b"\x1f\xff\xff\xff", Frame::Error(IoFailed)),
        (b"\x20\xff\xff\xff", Frame::Error(InvalidEscape)),
        (b"\x23\xff\xff\xff", Frame::Error(NameTooLong)),
        (b"\x24\xff\xff\xff", Frame::Error(BufferOverflow)),
        // Instruction set 7.x example: page 0, component 2, press.
        (
            b"\x65\x00\x02\x01\xff\xff\xff",
            Frame::Touch {
                page: 0,
                component: 2,
                event: TouchEvent::Press,
            },
        ),
        (b"\x66\x02\xff\xff\xff", Frame::CurrentPage(2)),
        // x = 0x007A = 122, y = 0x001E = 30, press (awake).
        (
            b"\x67\x00\x7a\x00\x1e\x01\xff\xff\xff",
            Frame::TouchXy {
                x: 122,
                y: 30,
                event: TouchEvent::Press,
                asleep: false,
            },
        ),
        (
            b"\x68\x01\x02\x03\x04\x00\xff\xff\xff",
            Frame::TouchXy {
                x: 0x0102,
                y: 0x0304,
                event: TouchEvent::Release,
                asleep: true,
            },
        ),
        // Example of the instruction set: 0x70 "ab123".
        (
            b"\x70\x61\x62\x31\x32\x33\xff\xff\xff",
            Frame::Text(Text::new(b"ab123").unwrap()),
        ),
        (b"\x70\xff\xff\xff", Frame::Text(Text::new(b"").unwrap())),
        // Example of the instruction set: 0x71 0x01 0x02 0x03 0x04 = 67305985.
        (
            b"\x71\x01\x02\x03\x04\xff\xff\xff",
            Frame::Number(67_305_985),
        ),
        (b"\x71\x66\x00\x00\x00\xff\xff\xff", Frame::Number(102)),
        (b"\x86\xff\xff\xff", Frame::AutoSleep),
        (b"\x87\xff\xff\xff", Frame::AutoWake),
        (b"\x88\xff\xff\xff", Frame::Ready),
        (b"\x89\xff\xff\xff", Frame::Upgrade),
        (b"\xfd\xff\xff\xff", Frame::TransparentFinished),
        (b"\xfe\xff\xff\xff", Frame::TransparentReady),
    ];
    for (bytes, frame) in cases {
        assert_eq!(decode_all(bytes), vec![Ok(frame.clone())], "{bytes:02x?}");
        // And the host-side encoder writes the same bytes.
        let mut buf = [0u8; 64];
        let n = frame.emit(&mut buf).unwrap();
        assert_eq!(&buf[..n], bytes);
    }
}

#[test]
fn pitfall_number_minus_one_with_ff_payload() {
    // 0x71 0xFF 0xFF 0xFF 0xFF + terminator: seven 0xFF in a row. Libraries that
    // scan for the terminator instead of using the length break here.
    let bytes = b"\x71\xff\xff\xff\xff\xff\xff\xff";
    assert_eq!(decode_all(bytes), vec![Ok(Frame::Number(-1))]);
    assert_eq!(
        decode_all(b"\x71\x00\x00\x00\x80\xff\xff\xff"),
        vec![Ok(Frame::Number(i32::MIN))]
    );
    assert_eq!(
        decode_all(b"\x71\xff\xff\xff\x7f\xff\xff\xff"),
        vec![Ok(Frame::Number(i32::MAX))]
    );
}

#[test]
fn pitfall_overflow_and_invalid_variable_are_typed_errors() {
    let out = decode_all(b"\x24\xff\xff\xff\x1a\xff\xff\xff");
    assert_eq!(
        out,
        vec![
            Ok(Frame::Error(ErrorCode::BufferOverflow)),
            Ok(Frame::Error(ErrorCode::InvalidVariable))
        ]
    );
    assert_eq!(
        ErrorCode::BufferOverflow.to_string(),
        "screen error 0x24: serial buffer overflow"
    );
    assert_eq!(ErrorCode::from_byte(0x1A), Some(ErrorCode::InvalidVariable));
}

#[test]
fn error_code_table_round_trips() {
    for c in ErrorCode::ALL {
        assert_eq!(ErrorCode::from_byte(c.code()), Some(c));
    }
    let known: Vec<u8> = ErrorCode::ALL.iter().map(|c| c.code()).collect();
    for b in 0u8..=0xFF {
        assert_eq!(ErrorCode::from_byte(b).is_some(), known.contains(&b));
    }
}

#[test]
fn stray_terminators_and_garbage_are_skipped_and_counted() {
    let mut d = Decoder::new();
    let mut out = Vec::new();
    // Stray 0xFF, unknown header 0x42 with junk up to a terminator, then a good frame.
    d.push_slice(b"\xff\xff\x42junk\xff\xff\xff\x66\x03\xff\xff\xff", |r| {
        out.push(r)
    });
    assert_eq!(
        out,
        vec![
            Err(DecodeError::UnknownHeader(0x42)),
            Ok(Frame::CurrentPage(3))
        ]
    );
    let s = d.stats();
    assert_eq!(s.frames, 1);
    assert_eq!(s.dropped_frames, 1);
    assert_eq!(s.dropped_bytes, 2 + 1 + 4 + 3);
    assert!(d.is_idle());
}

#[test]
fn lost_terminator_byte_costs_one_frame_only() {
    // The first touch frame lost one 0xFF; the breaking byte 0x66 starts the next frame.
    let out = decode_all(b"\x65\x01\x02\x00\xff\xff\x66\x01\xff\xff\xff");
    assert_eq!(
        out,
        vec![
            Err(DecodeError::MissingTerminator { header: 0x65 }),
            Ok(Frame::CurrentPage(1))
        ]
    );
}

#[test]
fn over_long_string_is_an_error_not_a_stall() {
    let mut bytes = vec![0x70];
    bytes.extend(std::iter::repeat_n(b'a', MAX_STRING_LEN + 10));
    bytes.extend_from_slice(b"\xff\xff\xff\x88\xff\xff\xff");
    let mut d = Decoder::new();
    let mut out = Vec::new();
    for (i, &b) in bytes.iter().enumerate() {
        let mut next = d.push(b);
        while let Some(r) = next {
            out.push((i, r));
            next = d.poll();
        }
    }
    // The error comes at the first byte over the bound, not at the terminator.
    assert_eq!(
        out[0],
        (MAX_STRING_LEN + 1, Err(DecodeError::StringTooLong))
    );
    assert_eq!(out[1].1, Ok(Frame::Ready));
    assert_eq!(out.len(), 2);
    // Exactly MAX_STRING_LEN bytes still fit.
    let mut ok = vec![0x70];
    ok.extend(std::iter::repeat_n(b'z', MAX_STRING_LEN));
    ok.extend_from_slice(&TERMINATOR);
    assert!(
        matches!(&decode_all(&ok)[..], [Ok(Frame::Text(t))] if t.as_bytes().len() == MAX_STRING_LEN)
    );
}

#[test]
fn malformed_payloads_are_rejected() {
    assert_eq!(
        decode_all(b"\x65\x00\x01\x07\xff\xff\xff"),
        vec![Err(DecodeError::Malformed { header: 0x65 })]
    );
    // The header may be the byte that was hit: what follows it is read
    // again, and `05 FF FF FF` is a whole frame (error "invalid font").
    assert_eq!(
        decode_all(b"\x00\x00\x05\xff\xff\xff"),
        vec![
            Err(DecodeError::Malformed { header: 0x00 }),
            Ok(Frame::Error(ErrorCode::InvalidFont))
        ]
    );
}

#[test]
fn decoder_state_is_small_and_fixed() {
    assert!(
        core::mem::size_of::<Decoder>() <= 80,
        "{}",
        core::mem::size_of::<Decoder>()
    );
}

// ---------------------------------------------------------------- encoding

#[test]
fn instructions_match_hand_written_bytes() {
    let cases: Vec<(Instruction<'_>, &[u8])> = vec![
        (Instruction::Page(1), b"page 1\xff\xff\xff"),
        (Instruction::Page(255), b"page 255\xff\xff\xff"),
        (
            Instruction::set_text(name("t0"), "Hello").unwrap(),
            b"t0.txt=\"Hello\"\xff\xff\xff",
        ),
        (
            Instruction::SetValue(name("n0"), 0),
            b"n0.val=0\xff\xff\xff",
        ),
        (
            Instruction::SetValue(name("n0"), 250),
            b"n0.val=250\xff\xff\xff",
        ),
        (
            Instruction::SetValue(name("n0"), -17),
            b"n0.val=-17\xff\xff\xff",
        ),
        (
            Instruction::SetValue(name("x1"), i32::MIN),
            b"x1.val=-2147483648\xff\xff\xff",
        ),
        (
            Instruction::SetValue(name("x1"), i32::MAX),
            b"x1.val=2147483647\xff\xff\xff",
        ),
        (
            Instruction::Get(name("n0"), Attr::Val),
            b"get n0.val\xff\xff\xff",
        ),
        (
            Instruction::Get(name("t0"), Attr::Txt),
            b"get t0.txt\xff\xff\xff",
        ),
        (
            Instruction::Get(name("fixed.nspeed"), Attr::Val),
            b"get fixed.nspeed.val\xff\xff\xff",
        ),
        (
            Instruction::Visible(name("b0"), false),
            b"vis b0,0\xff\xff\xff",
        ),
        (
            Instruction::Visible(name("b0"), true),
            b"vis b0,1\xff\xff\xff",
        ),
        (
            Instruction::TouchEnable(Some(name("b1")), false),
            b"tsw b1,0\xff\xff\xff",
        ),
        (
            Instruction::TouchEnable(None, true),
            b"tsw 255,1\xff\xff\xff",
        ),
        (Instruction::Refresh(name("t0")), b"ref t0\xff\xff\xff"),
        (Instruction::SendMe, b"sendme\xff\xff\xff"),
        (Instruction::BkCmd(BkCmd::OnFailure), b"bkcmd=2\xff\xff\xff"),
        (Instruction::BkCmd(BkCmd::Always), b"bkcmd=3\xff\xff\xff"),
        (Instruction::Dims(100), b"dims=100\xff\xff\xff"),
        (Instruction::Dims(0), b"dims=0\xff\xff\xff"),
        (Instruction::Sleep(true), b"sleep=1\xff\xff\xff"),
        (Instruction::Sleep(false), b"sleep=0\xff\xff\xff"),
        (Instruction::Reset, b"rest\xff\xff\xff"),
        (
            Instruction::Baud(BaudRate::B115200),
            b"baud=115200\xff\xff\xff",
        ),
        (Instruction::Baud(BaudRate::B9600), b"baud=9600\xff\xff\xff"),
        (Instruction::Flush, b"\xff\xff\xff"),
    ];
    for (i, bytes) in cases {
        assert_eq!(emit(i), bytes, "{i:?}");
    }
}

#[test]
fn text_is_escaped_and_made_ascii() {
    let t = |s| emit(Instruction::set_text(name("t0"), s).unwrap());
    assert_eq!(t("a\"b"), b"t0.txt=\"a\\\"b\"\xff\xff\xff");
    assert_eq!(t("c:\\x"), b"t0.txt=\"c:\\\\x\"\xff\xff\xff");
    assert_eq!(t("l1\nl2"), b"t0.txt=\"l1\\rl2\"\xff\xff\xff");
    assert_eq!(t("tab\there\r"), b"t0.txt=\"tabhere\"\xff\xff\xff");
    assert_eq!(t("5 °C ÿ"), b"t0.txt=\"5 ?C ?\"\xff\xff\xff");
    assert_eq!(t(""), b"t0.txt=\"\"\xff\xff\xff");
    let long = "x".repeat(MAX_TEXT_LEN);
    assert!(Instruction::set_text(name("t0"), &long).is_ok());
    let too_long = "x".repeat(MAX_TEXT_LEN + 1);
    assert_eq!(
        Instruction::set_text(name("t0"), &too_long),
        Err(EncodeError::TextTooLong)
    );
}

#[test]
fn buffer_too_small_and_range_errors() {
    let mut buf = [0u8; 8];
    assert_eq!(
        Instruction::Page(1).emit(&mut buf[..8]),
        Err(EncodeError::BufferTooSmall)
    );
    assert_eq!(
        Instruction::Page(1).emit(&mut buf[..9 - 1]),
        Err(EncodeError::BufferTooSmall)
    );
    let mut buf9 = [0u8; 9];
    assert_eq!(Instruction::Page(1).emit(&mut buf9), Ok(9));
    assert_eq!(
        Instruction::Dims(101).emit(&mut [0u8; 32]),
        Err(EncodeError::OutOfRange)
    );
    assert_eq!(
        Frame::Number(5).emit(&mut [0u8; 7]),
        Err(EncodeError::BufferTooSmall)
    );
    assert_eq!(
        Instruction::Page(7).to_vec::<16>().unwrap().as_slice(),
        b"page 7\xff\xff\xff"
    );
    assert!(Instruction::Page(7).to_vec::<4>().is_err());
}

#[test]
fn longest_instruction_fits_the_documented_bound() {
    let n = "abcdefghijklmn.abcdefghijklmn";
    let text = "\"".repeat(MAX_TEXT_LEN);
    let i = Instruction::set_text(name(n), &text).unwrap();
    assert_eq!(emit(i).len(), MAX_INSTRUCTION_LEN);
}

#[test]
fn object_names_are_validated() {
    assert!(ObjName::new("t0").is_ok());
    assert!(ObjName::new("_x").is_ok());
    assert!(ObjName::new("page0.n_1").is_ok());
    assert!(ObjName::new("abcdefghijklmn").is_ok());
    assert_eq!(ObjName::new(""), Err(NameError::Empty));
    assert_eq!(ObjName::new("a."), Err(NameError::Empty));
    assert_eq!(ObjName::new(".a"), Err(NameError::Empty));
    assert_eq!(ObjName::new("abcdefghijklmno"), Err(NameError::TooLong));
    assert_eq!(ObjName::new("0t"), Err(NameError::InvalidChar));
    assert_eq!(ObjName::new("t 0"), Err(NameError::InvalidChar));
    assert_eq!(ObjName::new("t0\"x"), Err(NameError::InvalidChar));
    assert_eq!(ObjName::new("a.b.c"), Err(NameError::TooManySegments));
    assert_eq!(ObjName::new("é"), Err(NameError::InvalidChar));
    const N: Result<ObjName<'static>, NameError> = ObjName::new("t0");
    assert!(N.is_ok());
}

// ---------------------------------------------------------------- properties

fn any_event() -> impl Strategy<Value = TouchEvent> {
    prop_oneof![Just(TouchEvent::Press), Just(TouchEvent::Release)]
}

fn any_frame() -> impl Strategy<Value = Frame> {
    prop_oneof![
        Just(Frame::Startup),
        Just(Frame::Success),
        proptest::sample::select(ErrorCode::ALL.to_vec()).prop_map(Frame::Error),
        (any::<u8>(), any::<u8>(), any_event()).prop_map(|(page, component, event)| Frame::Touch {
            page,
            component,
            event
        }),
        any::<u8>().prop_map(Frame::CurrentPage),
        (any::<u16>(), any::<u16>(), any_event(), any::<bool>()).prop_map(
            |(x, y, event, asleep)| Frame::TouchXy {
                x,
                y,
                event,
                asleep
            }
        ),
        proptest::collection::vec(0u8..0xFF, 0..=MAX_STRING_LEN)
            .prop_map(|v| Frame::Text(Text::new(&v).unwrap())),
        any::<i32>().prop_map(Frame::Number),
        Just(Frame::AutoSleep),
        Just(Frame::AutoWake),
        Just(Frame::Ready),
        Just(Frame::Upgrade),
        Just(Frame::TransparentFinished),
        Just(Frame::TransparentReady),
    ]
}

fn encode_frames(frames: &[Frame]) -> Vec<u8> {
    let mut bytes = Vec::new();
    for f in frames {
        let mut buf = [0u8; 64];
        let n = f.emit(&mut buf).unwrap();
        bytes.extend_from_slice(&buf[..n]);
    }
    bytes
}

proptest! {
    #[test]
    fn frames_round_trip_however_split(
        frames in proptest::collection::vec(any_frame(), 1..12),
        cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..10),
    ) {
        let bytes = encode_frames(&frames);
        let mut points: Vec<usize> = cuts.iter().map(|c| c.index(bytes.len() + 1)).collect();
        points.push(0);
        points.push(bytes.len());
        points.sort_unstable();
        let mut d = Decoder::new();
        let mut out = Vec::new();
        for w in points.windows(2) {
            d.push_slice(&bytes[w[0]..w[1]], |r| out.push(r));
        }
        let expected: Vec<_> = frames.into_iter().map(Ok).collect();
        prop_assert_eq!(out, expected);
        prop_assert_eq!(d.stats().dropped_bytes, 0);
        prop_assert!(d.is_idle());
    }

    #[test]
    fn decoder_recovers_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..40),
        frames in proptest::collection::vec(any_frame(), 1..5),
    ) {
        // Whatever came before, a full terminator followed by good frames decodes them.
        let mut bytes = garbage;
        bytes.extend_from_slice(&TERMINATOR);
        let good = encode_frames(&frames);
        let mut d = Decoder::new();
        d.push_slice(&bytes, |_| {});
        // Right after garbage + terminator the decoder may still be inside a
        // fixed-length frame; a second terminator flushes any state.
        d.push_slice(&TERMINATOR, |_| {});
        d.push_slice(&TERMINATOR, |_| {});
        let mut out = Vec::new();
        d.push_slice(&good, |r| out.push(r));
        let expected: Vec<_> = frames.into_iter().map(Ok).collect();
        prop_assert_eq!(out, expected);
    }

    #[test]
    fn instructions_never_contain_terminator_before_end(
        text in "\\PC{0,40}",
        value in any::<i32>(),
    ) {
        let i = Instruction::set_text(name("t0"), &text).unwrap();
        let b = emit(i);
        prop_assert!(b[..b.len() - 3].is_ascii());
        prop_assert!(b.ends_with(&TERMINATOR));
        let mut expected = format!("n0.val={value}").into_bytes();
        expected.extend_from_slice(&TERMINATOR);
        prop_assert_eq!(emit(Instruction::SetValue(name("n0"), value)), expected);
    }
}
