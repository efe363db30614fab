//! Any byte stream: the decoder never panics, every decoded frame re-encodes
//! to bytes that decode to the same frame, and the counters stay consistent.
#![no_main]

use hmi_proto::{Decoder, Frame};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut d = Decoder::new();
    let mut frames: Vec<Frame> = Vec::new();
    d.push_slice(data, |r| {
        if let Ok(f) = r {
            frames.push(f);
        }
    });
    assert!(d.stats().dropped_bytes as usize <= data.len());
    for f in frames {
        let mut buf = [0u8; 64];
        let n = f.emit(&mut buf).expect("frames fit 64 bytes");
        let mut again = Decoder::new();
        let mut out = None;
        again.push_slice(&buf[..n], |r| out = Some(r));
        assert_eq!(out, Some(Ok(f)));
    }
});
