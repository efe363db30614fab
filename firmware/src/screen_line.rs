//! The touchscreen line between the USART1 interrupt and the hmi task
//! (host test: `tests/tests/screen_line.rs`, which includes this file).
//!
//! - Received bytes go to the hmi task with their arrival time, so that the
//!   quiet-line rule (`hmi_proto::hmi::RX_GAP_MS`) is measured on the line,
//!   not when the task gets to them: one `u32` each in the channel, the
//!   byte and the low 24 bits of the millisecond clock.
//! - The task never waits on the transmitter: it moves the screen link's
//!   queued bytes into a ring that the USART1 interrupt empties, one byte
//!   per TXE (`board::HmiTx`).

use heapless::spsc::Producer;
use hmi_proto::hmi::Hmi;

/// Bits of the arrival time kept (4.6 hours: a byte never waits in the
/// channel that long).
const STAMP_MASK: u32 = (1 << 24) - 1;

/// One received byte and its arrival time, as the USART1 interrupt hands
/// it to the hmi task.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct LineItem(u32);

impl LineItem {
    /// `byte`, received at `at_ms` (the monotonic's milliseconds).
    pub const fn new(byte: u8, at_ms: u32) -> Self {
        Self(((at_ms & STAMP_MASK) << 8) | byte as u32)
    }

    /// The byte and its arrival time, taken at `now_ms` (not before it
    /// arrived, and less than 4.6 hours after).
    pub fn received(self, now_ms: u32) -> (u8, u32) {
        let age = now_ms.wrapping_sub(self.0 >> 8) & STAMP_MASK;
        ((self.0 & 0xFF) as u8, now_ms.wrapping_sub(age))
    }
}

/// Hands the screen link a byte of the channel, taken at `now_ms`.
pub fn deliver(hmi: &mut Hmi, item: LineItem, now_ms: u32) {
    let (byte, at_ms) = item.received(now_ms);
    hmi.push_at(byte, at_ms);
}

/// Moves the link's queued bytes into the transmit ring while it has room;
/// returns how many.
pub fn refill(hmi: &mut Hmi, ring: &mut Producer<'_, u8>) -> usize {
    let mut n = 0usize;
    while ring.ready() {
        let Some(b) = hmi.pop_tx() else { break };
        let _ = ring.enqueue(b);
        n = n.saturating_add(1);
    }
    n
}
