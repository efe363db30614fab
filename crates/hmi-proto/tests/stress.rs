//! One million short random streams through the decoder and the application
//! layer: no panic, bounded state. Seeded xorshift, so a failure reproduces.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
#![allow(clippy::cast_possible_truncation)]

use hmi_proto::hmi::{Hmi, TX_CAPACITY};
use hmi_proto::screen::{Settings, COMPONENTS};
use hmi_proto::{Decoder, Frame, TouchEvent};

/// xorshift64 (Marsaglia 2003).
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}

/// A short stream mixing noise, terminators, known headers and valid frames.
fn stream(rng: &mut XorShift, out: &mut Vec<u8>) {
    out.clear();
    let pieces = 1 + rng.below(4);
    for _ in 0..pieces {
        match rng.below(6) {
            0 => out.push(rng.byte()),
            1 => out.extend_from_slice(&[0xFF; 3][..1 + rng.below(3) as usize]),
            2 => {
                let headers = [0x00, 0x01, 0x1A, 0x24, 0x65, 0x66, 0x67, 0x70, 0x71, 0x88];
                out.push(headers[rng.below(headers.len() as u64) as usize]);
                for _ in 0..rng.below(6) {
                    out.push(rng.byte());
                }
            }
            3 => {
                let c = &COMPONENTS[rng.below(COMPONENTS.len() as u64) as usize];
                let f = Frame::Touch {
                    page: c.page.id(),
                    component: c.id(),
                    event: if rng.below(4) == 0 {
                        TouchEvent::Press
                    } else {
                        TouchEvent::Release
                    },
                };
                let mut buf = [0u8; 16];
                let n = f.emit(&mut buf).unwrap();
                out.extend_from_slice(&buf[..n]);
            }
            4 => {
                let v = match rng.below(3) {
                    0 => rng.next() as i32,
                    1 => rng.below(600) as i32,
                    _ => -1,
                };
                let f = if rng.below(2) == 0 {
                    Frame::Number(v)
                } else {
                    Frame::Ready
                };
                let mut buf = [0u8; 16];
                let n = f.emit(&mut buf).unwrap();
                out.extend_from_slice(&buf[..n]);
            }
            _ => out.extend_from_slice(b"\x66\x01\xff\xff\xff"),
        }
    }
}

#[test]
fn a_million_random_streams() {
    assert!(core::mem::size_of::<Decoder>() <= 80);
    assert!(
        core::mem::size_of::<Hmi>() <= 808,
        "{}",
        core::mem::size_of::<Hmi>()
    );
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let mut bytes = Vec::with_capacity(64);
    let mut tx = [0u8; 64];
    let mut hmi = Hmi::new(Settings::default(), "stress");
    let mut now = 0u32;
    let mut decoded = 0u64;
    let mut total_bytes = 0u64;
    let mut commands = 0u64;
    for i in 0..1_000_000u32 {
        stream(&mut rng, &mut bytes);
        // Decoder alone, fresh each time.
        let mut d = Decoder::new();
        d.push_slice(&bytes, |r| decoded += u64::from(r.is_ok()));
        let s = d.stats();
        assert!(s.dropped_bytes as usize <= bytes.len());
        // Application layer: one long-lived instance, reset now and then.
        if i % 4096 == 0 {
            hmi = Hmi::new(Settings::default(), "stress");
        }
        now = now.wrapping_add(rng.below(120) as u32);
        hmi.tick(now);
        hmi.push_slice(&bytes);
        total_bytes += bytes.len() as u64;
        while let Some(e) = hmi.poll_event() {
            if matches!(e, hmi_proto::hmi::Event::Command(_)) {
                commands += 1;
            }
        }
        assert!(hmi.tx_pending() <= TX_CAPACITY);
        if rng.below(3) != 0 {
            hmi.poll_transmit(&mut tx);
        }
    }
    // The generator does produce valid frames (the test exercises real paths).
    assert!(decoded > 500_000, "{decoded}");
    assert!(total_bytes > 5_000_000, "{total_bytes}");
    assert!(commands > 10_000, "{commands}");
    println!("{total_bytes} bytes, {decoded} frames, {commands} commands");
}
