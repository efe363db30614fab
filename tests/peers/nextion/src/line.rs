//! Serial line timing: UART 8N1 sends 10 bits a byte (start, 8 data, stop).
//! Times are µs of the caller's clock; a byte is "available" when its stop
//! bit has ended.

use std::collections::VecDeque;

/// The link's baud rate (docs/hmi.md §1: 115 200 baud, 8N1).
pub const DEFAULT_BAUD: u32 = 115_200;

/// Bits on the line per byte (8N1).
pub const BITS_PER_BYTE: u64 = 10;

/// When the `n`-th byte (counted from 1) of a burst that starts at
/// `start_us` has been received, at `baud`, rounded up to the µs.
pub fn byte_end_us(start_us: u64, n: u64, baud: u32) -> u64 {
    let bits = n.saturating_mul(BITS_PER_BYTE).saturating_mul(1_000_000);
    start_us.saturating_add(bits.div_ceil(u64::from(baud.max(1))))
}

/// The time each byte of `bytes` has arrived when they are sent back to back
/// from `start_us` at `baud`: what a UART gives a receiver. Feed the result
/// to [`crate::Screen::receive_timed`] to pace the MCU's bytes.
pub fn pace(start_us: u64, bytes: &[u8], baud: u32) -> Vec<(u64, u8)> {
    (1u64..)
        .zip(bytes)
        .map(|(n, &b)| (byte_end_us(start_us, n, baud), b))
        .collect()
}

/// The screen's transmitter: bytes leave one after another; a burst starts
/// when the line is idle.
#[derive(Debug)]
pub(crate) struct Tx {
    baud: u32,
    burst_start_us: u64,
    burst_len: u64,
    queue: VecDeque<(u64, u8)>,
}

impl Tx {
    pub(crate) fn new(baud: u32) -> Self {
        Tx {
            baud,
            burst_start_us: 0,
            burst_len: 0,
            queue: VecDeque::new(),
        }
    }

    /// When the last byte queued has left.
    pub(crate) fn idle_at_us(&self) -> u64 {
        byte_end_us(self.burst_start_us, self.burst_len, self.baud)
    }

    /// Queue `bytes` produced at `at_us`.
    pub(crate) fn send(&mut self, at_us: u64, bytes: &[u8]) {
        if at_us >= self.idle_at_us() {
            self.burst_start_us = at_us;
            self.burst_len = 0;
        }
        for &b in bytes {
            self.burst_len += 1;
            let t = byte_end_us(self.burst_start_us, self.burst_len, self.baud);
            self.queue.push_back((t, b));
        }
    }

    /// A new rate for the bytes queued after this (`baud=`).
    pub(crate) fn set_baud(&mut self, now_us: u64, baud: u32) {
        let start = self.idle_at_us().max(now_us);
        self.burst_start_us = start;
        self.burst_len = 0;
        self.baud = baud;
    }

    pub(crate) fn baud(&self) -> u32 {
        self.baud
    }

    pub(crate) fn take_all(&mut self) -> Vec<(u64, u8)> {
        self.queue.drain(..).collect()
    }

    pub(crate) fn take_until(&mut self, now_us: u64) -> Vec<(u64, u8)> {
        let n = self.queue.iter().take_while(|(t, _)| *t <= now_us).count();
        self.queue.drain(..n).collect()
    }

    pub(crate) fn pending(&self) -> usize {
        self.queue.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_byte_takes_ten_bit_times() {
        // 10 bits at 115 200 baud: 86.8 µs; 9 bytes (a touch frame is 7): 782 µs.
        assert_eq!(byte_end_us(0, 1, 115_200), 87);
        assert_eq!(byte_end_us(1_000, 9, 115_200), 1_000 + 782);
        assert_eq!(byte_end_us(0, 1, 9_600), 1_042);
    }

    #[test]
    fn a_burst_queued_behind_another_follows_it_without_gap() {
        let mut tx = Tx::new(115_200);
        tx.send(0, &[1, 2]);
        tx.send(10, &[3]);
        tx.send(10_000, &[4]);
        let out = tx.take_all();
        assert_eq!(
            out,
            vec![(87, 1), (174, 2), (261, 3), (10_087, 4)],
            "the third byte waits for the second; the fourth starts a new burst"
        );
    }

    #[test]
    fn take_until_leaves_the_bytes_still_on_the_line() {
        let mut tx = Tx::new(115_200);
        tx.send(0, &[1, 2, 3]);
        assert_eq!(tx.take_until(200), vec![(87, 1), (174, 2)]);
        assert_eq!(tx.pending(), 1);
    }
}
