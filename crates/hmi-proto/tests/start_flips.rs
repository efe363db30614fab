//! No motor start without the operator's Start, with one, two or three
//! bits hit anywhere in a tap (docs/hmi.md §3, "Motor-starting buttons").
//!
//! A tap is the press frame `65 p id 01 FF FF FF` and the release frame
//! `65 p id 00 FF FF FF` of one component: 14 bytes, 112 bits. Touch frames
//! carry no CRC, so the screen contract itself must keep the motor starts
//! away from every other button: each Start (and Identify) differs from
//! every other button of the contract in at least two bits of its
//! (page, id) bytes, and a Start needs its press and its release, so a tap
//! of another button needs at least two hit bits in each of its two frames
//! (four) to become a Start.
//!
//! Tested exhaustively: every button of the contract (the components that
//! send touch frames; text, number and Xfloat components send none) tapped
//! with its press and its release (the contract asks for the press of Stop
//! and the motor-starting buttons only: every button here, the worst case)
//! × every set of one, two or three of the 112 bits flipped × every page
//! shown (a tap in flight while the MCU changes the page). The bytes go through
//! the decoder and the application layer ([`Hmi`]) as they come off the
//! line (headers and terminators can be hit as well). A motor start counts
//! as the operator's only when the tap is of the motor-starting button of
//! the page shown.
//!
//! Cost: the application layer's result depends only on the frames the
//! decoder makes of the 14 bytes and the page shown (`Hmi::push` hands
//! each decoded frame to the link), so each tap's flipped bytes are decoded
//! once (the press half once per flip set of its own, shared by the
//! release halves after it), and the link is run once per page shown for
//! each distinct sequence of decoded frames. A few seconds on two threads.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation
)]

use std::collections::HashMap;
use std::hash::BuildHasherDefault;

use hmi_proto::hmi::{Event, Hmi};
use hmi_proto::screen::{Command, Component, Kind, Page, Role, Settings, COMPONENTS};
use hmi_proto::{Decoder, TouchEvent};

/// Bits in one frame.
const FRAME_BITS: usize = 56;

fn frame(c: &Component, event: TouchEvent) -> [u8; 7] {
    [0x65, c.page.id(), c.id(), event.to_byte(), 0xFF, 0xFF, 0xFF]
}

/// A link after the handshake, showing `page` (bytes and events drained).
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
    hmi
}

fn starts_motor(e: &Event) -> bool {
    matches!(e, Event::Command(Command::Start | Command::IdentifyDrive))
}

/// `c` is the motor-starting button of `shown`.
fn is_start_of(c: &Component, shown: Page) -> bool {
    c.page == shown && matches!(c.role, Role::Action(a) if a.starts_motor())
}

/// Every set of at most `max` bits of `0..FRAME_BITS`, as bit masks of
/// the frame's 7 bytes, with the set's size; sorted by size.
fn flip_sets(max: usize) -> Vec<([u8; 7], usize)> {
    let mut sets = vec![([0u8; 7], 0)];
    for a in 0..FRAME_BITS {
        let mut m = [0u8; 7];
        m[a / 8] ^= 1 << (a % 8);
        sets.push((m, 1));
        if max < 2 {
            continue;
        }
        for b in a + 1..FRAME_BITS {
            let mut m2 = m;
            m2[b / 8] ^= 1 << (b % 8);
            sets.push((m2, 2));
            if max < 3 {
                continue;
            }
            for c in b + 1..FRAME_BITS {
                let mut m3 = m2;
                m3[c / 8] ^= 1 << (c % 8);
                sets.push((m3, 3));
            }
        }
    }
    sets.sort_by_key(|&(_, n)| n);
    sets
}

fn xor(f: [u8; 7], m: [u8; 7]) -> [u8; 7] {
    let mut o = f;
    for (b, m) in o.iter_mut().zip(m) {
        *b ^= m;
    }
    o
}

/// The frames decoded from a tap's bytes, re-emitted one after the other,
/// each with its length first (at most 14 bytes of frames come from 14
/// bytes, plus the lengths).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct Key {
    len: u8,
    bytes: [u8; 30],
}

impl Key {
    const EMPTY: Self = Self {
        len: 0,
        bytes: [0; 30],
    };
}

/// Pushes `bytes` into `dec`; appends every frame decoded to `key`.
fn decode_into(dec: &mut Decoder, bytes: &[u8], key: &mut Key) {
    dec.push_slice(bytes, |r| {
        if let Ok(f) = r {
            let at = usize::from(key.len);
            let n = f.emit(&mut key.bytes[at + 1..]).unwrap();
            key.bytes[at] = n as u8;
            key.len += 1 + n as u8;
        }
    });
}

/// FNV-1a: the keys are short and the map is large.
#[derive(Default)]
struct Fnv(u64);

impl std::hash::Hasher for Fnv {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        let mut h = if self.0 == 0 {
            0xcbf2_9ce4_8422_2325
        } else {
            self.0
        };
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        self.0 = h;
    }
}

/// What one thread found: cases per number of flipped bits, distinct frame
/// sequences, and the taps that started a motor that was not the operator's
/// Start.
#[derive(Default)]
struct Found {
    cases: [u64; 4],
    sequences: u64,
    bad: Vec<String>,
    bad_count: u64,
}

fn check(components: &[&'static Component], bases: &[(Page, Hmi)]) -> Found {
    let sets = flip_sets(3);
    let mut found = Found::default();
    // Frame sequence -> for each page shown, whether the link started a
    // motor.
    let mut memo: HashMap<Key, Vec<bool>, BuildHasherDefault<Fnv>> = HashMap::default();
    for c in components {
        let press = frame(c, TouchEvent::Press);
        let release = frame(c, TouchEvent::Release);
        for &(ma, na) in &sets {
            let first = xor(press, ma);
            let mut dec1 = Decoder::new();
            let mut key1 = Key::EMPTY;
            decode_into(&mut dec1, &first, &mut key1);
            // Sorted by size: the sets of at most `3 - na` bits come first.
            let fit = sets.partition_point(|&(_, nb)| na + nb <= 3);
            for &(mb, nb) in &sets[usize::from(na == 0)..fit] {
                let n = na + nb;
                found.cases[n] += 1;
                let second = xor(release, mb);
                let mut dec = dec1.clone();
                let mut key = key1;
                decode_into(&mut dec, &second, &mut key);
                let outcome = memo.entry(key).or_insert_with(|| {
                    found.sequences += 1;
                    bases
                        .iter()
                        .map(|(_, base)| {
                            let mut hmi = base.clone();
                            hmi.push_slice(&first);
                            hmi.push_slice(&second);
                            let mut started = false;
                            while let Some(e) = hmi.poll_event() {
                                started |= starts_motor(&e);
                            }
                            started
                        })
                        .collect()
                });
                for (&(shown, _), &started) in bases.iter().zip(outcome.iter()) {
                    if started && !is_start_of(c, shown) {
                        found.bad_count += 1;
                        if found.bad.len() < 8 {
                            found.bad.push(format!(
                                "{shown:?} shown, {} ({:?} id {}) tapped, {n} bits: \
                                 {first:02X?} {second:02X?}",
                                c.name(),
                                c.page,
                                c.id()
                            ));
                        }
                    }
                }
            }
        }
    }
    found
}

#[test]
fn one_two_or_three_hit_bits_in_any_tap_never_start_a_motor() {
    let bases: Vec<(Page, Hmi)> = Page::ALL.iter().map(|&p| (p, showing(p))).collect();
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let all: Vec<&'static Component> = COMPONENTS
        .iter()
        .filter(|c| c.kind() == Kind::Button)
        .collect();
    let chunk = all.len().div_ceil(threads);
    let results: Vec<Found> = std::thread::scope(|s| {
        let handles: Vec<_> = all
            .chunks(chunk)
            .map(|part| {
                let bases = &bases;
                s.spawn(move || check(part, bases))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let mut cases = [0u64; 4];
    let mut sequences = 0;
    let mut bad_count = 0;
    let mut bad = Vec::new();
    for r in results {
        for (t, n) in cases.iter_mut().zip(r.cases) {
            *t += n;
        }
        sequences += r.sequences;
        bad_count += r.bad_count;
        bad.extend(r.bad);
    }
    let pages = Page::ALL.len() as u64;
    eprintln!(
        "taps {} x flips (1: {}, 2: {}, 3: {}) x {pages} pages shown = {} cases; \
         {sequences} distinct frame sequences run through the link",
        all.len(),
        cases[1],
        cases[2],
        cases[3],
        (cases[1] + cases[2] + cases[3]) * pages,
    );
    // Every button x every set of 1, 2 and 3 of the 112 bits.
    let n = all.len() as u64;
    assert_eq!(cases[1], n * 112);
    assert_eq!(cases[2], n * 112 * 111 / 2);
    assert_eq!(cases[3], n * 112 * 111 * 110 / 6);
    assert!(
        bad.is_empty(),
        "{bad_count} (tap, page shown) cases started a motor without the operator's Start, e.g.\n{}",
        bad.join("\n")
    );
}

/// The contract's side of it: the (page, id) bytes of each motor-starting
/// button differ from those of every other button of the contract in at
/// least two bits (a tap of another button then needs two hit bits in each
/// of its two frames), and no motor start shares a page with a button one
/// bit away in its id.
#[test]
fn every_motor_start_is_two_bits_from_every_other_button() {
    let buttons: Vec<&Component> = COMPONENTS
        .iter()
        .filter(|c| c.kind() == Kind::Button)
        .collect();
    let mut close = Vec::new();
    for s in buttons
        .iter()
        .filter(|c| matches!(c.role, Role::Action(a) if a.starts_motor()))
    {
        for b in &buttons {
            if std::ptr::eq(*s, *b) {
                continue;
            }
            let d = (s.page.id() ^ b.page.id()).count_ones() + (s.id() ^ b.id()).count_ones();
            if d < 2 {
                close.push(format!(
                    "{} ({:?} id {}) and {} ({:?} id {}): {d} bit",
                    s.name(),
                    s.page,
                    s.id(),
                    b.name(),
                    b.page,
                    b.id()
                ));
            }
        }
    }
    assert!(close.is_empty(), "{}", close.join("\n"));
}
