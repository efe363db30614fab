//! The drum driver's link fed arbitrary reply bytes, timer ticks and
//! commands: never panics; a reply with a valid CRC is accepted only when it
//! answers the request outstanding; the counters never exceed the events.
#![no_main]

use drive_link::link::{ControlAction, Link, LinkConfig};
use drive_link::profile::ZLAC8015D;
use drive_link::rtu::{self, Request, MAX_FRAME};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // A frame parse of the raw bytes, as each request kind, and of the
    // bytes with a valid CRC appended (random bytes rarely carry one).
    let mut framed = data.to_vec();
    framed.extend_from_slice(&rtu::crc16(data).to_le_bytes());
    for bytes in [data, &framed[..]] {
        let _ = rtu::parse_reply(1, Request::Read { address: 0x20AB, count: 1 }, bytes);
        let _ = rtu::parse_reply(1, Request::Write { address: 0x200E, value: 8 }, bytes);
    }

    let mut link = Link::new(ZLAC8015D, LinkConfig::for_baud(9600).unwrap());
    let mut now = 0u64;
    let mut frames = 0u32;
    let mut buf = [0u8; MAX_FRAME];
    let mut chunks = data.chunks(12);
    while let Some(chunk) = chunks.next() {
        let (&op, rest) = match chunk.split_first() {
            Some(x) => x,
            None => break,
        };
        now += u64::from(op) * 250;
        match op % 5 {
            0 => {
                if link.next_frame(now, &mut buf).is_some() {
                    link.sent(now + 9_000);
                }
            }
            1 => {
                frames += 1;
                let _ = link.received(now, rest);
            }
            2 => {
                let _ = link.tick(now);
            }
            3 => link.control(match op % 3 {
                0 => ControlAction::Enable,
                1 => ControlAction::Disable,
                _ => ControlAction::ClearAlarm,
            }),
            _ => link.set_speed_command(Some(i32::from(op) * 1000 - 100_000)),
        }
    }
    let c = link.counters();
    assert!(c.crc_errors + c.late_replies + c.exceptions + c.replies <= frames);
});
