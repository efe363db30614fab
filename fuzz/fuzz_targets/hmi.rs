//! The application layer fed arbitrary screen bytes interleaved with time
//! steps and MCU calls: never panics, queues stay bounded.
#![no_main]

use hmi_proto::hmi::{Hmi, TX_CAPACITY};
use hmi_proto::screen::{Page, Settings, Status};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut hmi = Hmi::new(Settings::default(), "fuzz");
    let mut now = 0u32;
    let mut tx = [0u8; 32];
    let mut it = data.iter().copied();
    while let Some(op) = it.next() {
        match op {
            // 0xF0..: control operations; everything else is a received byte.
            0xF0 => {
                now = now.wrapping_add(u32::from(it.next().unwrap_or(0)) * 4);
                hmi.tick(now);
            }
            0xF1 => {
                hmi.poll_transmit(&mut tx);
            }
            0xF2 => {
                let page = Page::from_id(it.next().unwrap_or(0) % Page::ALL.len() as u8)
                    .unwrap_or(Page::Mode);
                let _ = hmi.show_page(page);
            }
            0xF3 => {
                let _ = hmi.write_status(&Status {
                    plants: u32::from(it.next().unwrap_or(0)),
                    ..Status::default()
                });
            }
            0xF4 => {
                let _ = hmi.show_alarm("fuzz alarm");
            }
            0xF5 => while hmi.poll_event().is_some() {},
            b => hmi.push(b),
        }
        assert!(hmi.tx_pending() <= TX_CAPACITY);
    }
});
