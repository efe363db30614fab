//! Resynchronisation after one bad byte (issue 16, item 1): a corrupted,
//! lost or extra byte anywhere in a return frame must cost that frame only,
//! never the touch event that follows it.
//!
//! Exhaustive: every return-frame type the decoder knows (with payloads
//! chosen to be hostile: `0xFF` bytes inside numbers and coordinates, a
//! number whose payload looks like a touch frame, the longest string) × every
//! byte position × every byte value (substituted), every deleted byte and
//! every inserted byte (before each byte of the frame), each followed by
//! every touch event (press and release) of every component of every page of
//! the screen contract. The expected frame is the touch itself: the
//! reference is the bytes the test appended, not the decoder.
//!
//! Measured before the fix (the previous decoder behind the same tests):
//! 7 506 690 of the 21 498 880 cases lost the touch (the first one listed:
//! the startup frame `00 00 00 FF FF FF` with its first terminator byte
//! turned into `0x07`), and the Stop test failed on the same frame.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation
)]

use hmi_proto::hmi::{Event, Hmi};
use hmi_proto::screen::{Action, Command, Role, Settings, COMPONENTS};
use hmi_proto::{Decoder, Frame, TouchEvent, MAX_STRING_LEN};
use proptest::prelude::*;

const T: [u8; 3] = [0xFF; 3];

fn framed(body: &[u8]) -> Vec<u8> {
    let mut v = body.to_vec();
    v.extend_from_slice(&T);
    v
}

/// Every frame type the decoder knows, as it comes off the wire.
fn known_frames() -> Vec<Vec<u8>> {
    let mut frames = vec![
        framed(&[0x00, 0x00, 0x00]), // startup
        framed(&[0x01]),             // success
        framed(&[0x65, 0x02, 0x07, 0x00]),
        framed(&[0x65, 0x04, 0x01, 0x01]),
        framed(&[0x66, 0x03]),
        framed(&[0x67, 0x01, 0x40, 0x00, 0xF0, 0x01]),
        framed(&[0x68, 0xFF, 0xFF, 0x01, 0xFF, 0x00]),
        framed(b"\x7012.5"),
        framed(&[0x70]),
        framed(&[0x86]),
        framed(&[0x87]),
        framed(&[0x88]),
        framed(&[0x89]),
        framed(&[0xFD]),
        framed(&[0xFE]),
    ];
    // Numbers: ordinary, all-0xFF (-1), terminator-like (-256), the most
    // negative, and one whose payload is a touch frame's body.
    for v in [1234i32, -1, -256, i32::MIN, 0x0005_0265] {
        let mut body = vec![0x71];
        body.extend_from_slice(&v.to_le_bytes());
        frames.push(framed(&body));
    }
    // The longest string.
    let mut long = vec![0x70];
    long.extend(std::iter::repeat_n(b'x', MAX_STRING_LEN));
    frames.push(framed(&long));
    // Every error code (0x00 is the invalid instruction).
    for code in 0u8..=0xFF {
        if hmi_proto::ErrorCode::from_byte(code).is_some() {
            frames.push(framed(&[code]));
        }
    }
    frames
}

/// Every touch event of every page of the contract.
fn touch_events() -> Vec<(u8, u8, TouchEvent)> {
    let mut v = Vec::new();
    for c in COMPONENTS {
        for ev in [TouchEvent::Press, TouchEvent::Release] {
            v.push((c.page.id(), c.id(), ev));
        }
    }
    v
}

/// Every one-byte corruption of `frame`: substitutions, deletions and
/// insertions (before each byte).
fn corruptions(frame: &[u8]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for i in 0..frame.len() {
        for v in 0u8..=0xFF {
            if v != frame[i] {
                let mut c = frame.to_vec();
                c[i] = v;
                out.push(c);
            }
            let mut c = frame.to_vec();
            c.insert(i, v);
            out.push(c);
        }
        let mut c = frame.to_vec();
        c.remove(i);
        out.push(c);
    }
    out
}

#[test]
fn one_bad_byte_never_costs_the_next_touch() {
    let touches = touch_events();
    let frames = known_frames();
    let mut cases = 0u64;
    let mut failures = Vec::new();
    for frame in &frames {
        for bad in corruptions(frame) {
            let mut d = Decoder::new();
            let mut last = None;
            d.push_slice(&bad, |r| {
                if let Ok(f) = r {
                    last = Some(f);
                }
            });
            for &(page, component, event) in &touches {
                cases += 1;
                let mut d = d.clone();
                let mut got = None;
                d.push_slice(&[0x65, page, component, event.to_byte()], |r| {
                    if let Ok(f) = r {
                        got = Some(f);
                    }
                });
                d.push_slice(&T, |r| {
                    if let Ok(f) = r {
                        got = Some(f);
                    }
                });
                let want = Frame::Touch {
                    page,
                    component,
                    event,
                };
                if got != Some(want.clone()) || !d.is_idle() {
                    if failures.len() < 10 {
                        failures.push(format!("{bad:02X?} then {want:?}: last frame {got:?}"));
                    } else {
                        failures.push(String::new());
                    }
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {cases} cases lost the touch, e.g.\n{}",
        failures.len(),
        failures[..failures.len().min(10)].join("\n")
    );
    // Sanity: the loops ran (frames × corruptions × touches).
    assert!(cases > 1_000_000, "{cases}");
}

/// The same at the screen link: Stop reaches the machine after any one bad
/// byte in any frame, whether the screen reports it on press or on release.
#[test]
fn stop_is_never_lost_after_a_bad_frame_at_the_link() {
    let stops: Vec<_> = COMPONENTS
        .iter()
        .filter(|c| c.role == Role::Action(Action::Stop))
        .collect();
    assert!(stops.len() >= 3, "the contract has a Stop on each run page");
    for frame in known_frames() {
        for bad in corruptions(&frame) {
            for stop in &stops {
                for ev in [TouchEvent::Press, TouchEvent::Release] {
                    let mut hmi = connected_hmi();
                    hmi.push_slice(&bad);
                    hmi.push_slice(&framed(&[0x65, stop.page.id(), stop.id(), ev.to_byte()]));
                    let mut stopped = false;
                    while let Some(e) = hmi.poll_event() {
                        stopped |= e == Event::Command(Command::Stop);
                    }
                    assert!(stopped, "{bad:02X?} then Stop {ev:?} on {:?}", stop.page);
                }
            }
        }
    }
}

/// A screen link after the handshake.
fn connected_hmi() -> Hmi {
    let mut hmi = Hmi::new(Settings::default(), "test");
    hmi.tick(0);
    hmi.push_slice(&framed(&[0x88]));
    while hmi.poll_event().is_some() {}
    assert!(hmi.is_connected());
    hmi
}

fn any_frame() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        (any::<u8>(), any::<u8>(), any::<bool>()).prop_map(|(p, c, e)| framed(&[
            0x65,
            p,
            c,
            u8::from(e)
        ])),
        any::<i32>().prop_map(|v| {
            let mut b = vec![0x71];
            b.extend_from_slice(&v.to_le_bytes());
            framed(&b)
        }),
        any::<u8>().prop_map(|p| framed(&[0x66, p])),
        (any::<u16>(), any::<u16>(), any::<bool>(), any::<bool>()).prop_map(|(x, y, e, s)| {
            let mut b = vec![if s { 0x68 } else { 0x67 }];
            b.extend_from_slice(&x.to_be_bytes());
            b.extend_from_slice(&y.to_be_bytes());
            b.push(u8::from(e));
            framed(&b)
        }),
        proptest::collection::vec(0u8..0xFF, 0..=MAX_STRING_LEN).prop_map(|t| {
            let mut b = vec![0x70];
            b.extend_from_slice(&t);
            framed(&b)
        }),
        prop::sample::select(vec![0x01u8, 0x86, 0x87, 0x88, 0x89, 0xFD, 0xFE, 0x02, 0x24])
            .prop_map(|h| framed(&[h])),
        Just(framed(&[0x00, 0x00, 0x00])),
    ]
}

/// What the decoder makes of `bytes` alone (a valid frame: the reference).
fn decode_alone(bytes: &[u8]) -> Frame {
    let mut d = Decoder::new();
    let mut got = Vec::new();
    d.push_slice(bytes, |r| got.push(r));
    assert_eq!(got.len(), 1, "{bytes:02X?}");
    got.pop().unwrap().unwrap()
}

/// The length of a whole, valid return frame starting at `bytes[p]`, by the
/// protocol's own rules (Nextion Instruction Set ch. 7, written here
/// independently of the decoder): the header fixes the payload length (a
/// `0x70` string ends at its first `0xFF`), then `FF FF FF`.
fn protocol_frame_at(bytes: &[u8], p: usize) -> Option<usize> {
    const ERRORS: [u8; 17] = [
        0x02, 0x03, 0x04, 0x05, 0x06, 0x09, 0x11, 0x12, 0x1A, 0x1B, 0x1C, 0x1D, 0x1E, 0x1F, 0x20,
        0x23, 0x24,
    ];
    let rest = bytes.get(p..)?;
    let event_ok = |i: usize| matches!(rest.get(i), Some(0x00 | 0x01));
    let body = match *rest.first()? {
        0x00 if rest.get(1) == Some(&0xFF) => 1,
        0x00 if rest.get(1..3) == Some(&[0x00, 0x00][..]) => 3,
        0x01 | 0x86..=0x89 | 0xFD | 0xFE => 1,
        h if ERRORS.contains(&h) => 1,
        0x65 if event_ok(3) => 4,
        0x66 => 2,
        0x67 | 0x68 if event_ok(5) => 6,
        0x71 => 5,
        0x70 => {
            let n = rest.iter().skip(1).position(|&b| b == 0xFF)?;
            if n > MAX_STRING_LEN {
                return None;
            }
            n + 1
        }
        _ => return None,
    };
    (rest.get(body..body + 3)? == [0xFF; 3]).then_some(body + 3)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(100_000))]

    /// Noise of any length and content, then two valid frames: at least the
    /// second is decoded, and it is the last thing decoded — whenever the
    /// stream allows it. When a whole, valid frame starts in the noise or
    /// the first frame and runs into the second (e.g. noise `67`, then
    /// `01 FF FF FF` and `01 FF FF FF`: together a valid `0x67` touch
    /// coordinate frame, found by this test), no decoder can know the
    /// second frame is there: such streams are left out, by the protocol's
    /// rules above, not by the decoder's.
    #[test]
    fn noise_then_two_frames_decodes_the_second(
        noise in proptest::collection::vec(any::<u8>(), 0..300),
        first in any_frame(),
        second in any_frame(),
    ) {
        let stream: Vec<u8> = [&noise[..], &first[..], &second[..]].concat();
        let second_at = noise.len() + first.len();
        let straddled = (0..second_at).any(|p| {
            protocol_frame_at(&stream, p).is_some_and(|len| p + len > second_at)
        });
        prop_assume!(!straddled);
        // A shorter valid frame hidden in the second frame's own bytes (a
        // payload ending in FF, e.g. noise `71`, then `01 FF FF FF`, then
        // the number `71 FF FF 24 FF` + terminator: `24 FF FF FF` is a whole
        // return code inside it; found by this test under the load runs of
        // issue 18). A decoder still recovering when such a frame arrives
        // takes the first frame end it meets (rule 2 of `Decoder`) and the
        // longer frame is only known one byte later: left out, and written
        // in the decoder's documentation as its known limit. Touch events,
        // the frames that carry Stop, have no FF in their payload.
        let hidden = (second_at + 1..stream.len()).any(|p| {
            protocol_frame_at(&stream, p).is_some_and(|len| p + len < stream.len())
        });
        prop_assume!(!hidden);
        // Rule 3 of `Decoder`: when the second frame's header breaks a
        // terminator the stream before it had begun (`… FF FF`, the third
        // byte turned into the header), a touch event right after that
        // byte wins over a frame starting at it. A second frame whose
        // bytes after its header are a whole touch event (a number reply
        // `71 65 68 E1 00 FF FF FF`) is then read as that touch, by design
        // (a lost Stop costs more than a lost reply, which the link asks
        // for again). Found by this test on CI: noise `71 00`, first
        // `66 00 FF FF FF`, then that number.
        let rule3 = stream[..second_at].ends_with(&[0xFF, 0xFF])
            && stream.get(second_at + 1) == Some(&0x65)
            && protocol_frame_at(&stream, second_at + 1)
                .is_some_and(|len| second_at + 1 + len == stream.len());
        prop_assume!(!rule3);
        let want = decode_alone(&second);
        let mut d = Decoder::new();
        let mut frames = Vec::new();
        d.push_slice(&noise, |_| {});
        d.push_slice(&first, |r| if let Ok(f) = r { frames.push(f) });
        let mut last = None;
        d.push_slice(&second, |r| if let Ok(f) = r { last = Some(f) });
        prop_assert_eq!(last, Some(want));
        prop_assert!(d.is_idle());
    }

    /// Clean streams are untouched by the recovery: any sequence of valid
    /// frames decodes to exactly those frames.
    #[test]
    fn clean_streams_decode_exactly(frames in proptest::collection::vec(any_frame(), 1..20)) {
        let want: Vec<Frame> = frames.iter().map(|f| decode_alone(f)).collect();
        let mut d = Decoder::new();
        let mut got = Vec::new();
        for f in &frames {
            d.push_slice(f, |r| got.push(r.unwrap()));
        }
        prop_assert_eq!(got, want);
    }
}
