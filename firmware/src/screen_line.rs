//! The touchscreen line between the USART1 interrupt and the hmi task
//! (host test: `tests/tests/screen_line.rs`, which includes this file).
//!
//! - Received bytes go to the hmi task with their arrival time, so that the
//!   quiet-line rule (`hmi_proto::hmi::RX_GAP_MS`) is measured on the line,
//!   not when the task gets to them: one `u16` each in the channel, the
//!   byte and the low 8 bits of the millisecond clock (a byte waits there
//!   far less than 256 ms: the hmi task runs at least every 20 ms, and its
//!   longest wait behind a task of its priority is a settings save, 50 ms).
//! - The task never waits on the transmitter: it moves the screen link's
//!   queued bytes into a ring that the USART1 interrupt empties, one byte
//!   per TXE (`board::HmiTx`).

use heapless::spsc::Producer;
use hmi_proto::hmi::Hmi;

/// One received byte and its arrival time, as the USART1 interrupt hands
/// it to the hmi task.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct LineItem(u16);

impl LineItem {
    /// `byte`, received at `at_ms` (the monotonic's milliseconds).
    pub const fn new(byte: u8, at_ms: u32) -> Self {
        Self(u16::from_le_bytes([byte, at_ms as u8]))
    }

    /// The byte and its arrival time, taken at `now_ms` (not before it
    /// arrived, and less than 256 ms after).
    pub fn received(self, now_ms: u32) -> (u8, u32) {
        let [byte, stamp] = self.0.to_le_bytes();
        let age = (now_ms as u8).wrapping_sub(stamp);
        (byte, now_ms.wrapping_sub(u32::from(age)))
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
