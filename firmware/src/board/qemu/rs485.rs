//! USART2, the RS-485 line to the drum driver, with the line's time
//! modelled and the replies from the host's virtual driver.

use stm32f1xx_hal::{pac::USART2, serial::Tx};

// The drum driver's line (docs/drive-link.md).

/// Longest frame the virtual driver's gate record carries (a Modbus RTU
/// reply of this link is at most 9 bytes; a corrupted one the same).
pub const DRIVE_FRAME_MAX: usize = drive_link::rtu::MAX_FRAME;

/// A reply frame from the host's virtual driver and the firmware time (µs,
/// wrapping 32-bit) at which its last byte has arrived.
#[derive(Clone, Copy)]
pub struct DriveFrame {
    pub(super) end_us: u32,
    pub(super) len: u8,
    pub(super) bytes: [u8; DRIVE_FRAME_MAX],
}

/// Reply frames from the gate to [`DriveLine`] (three at a time at most).
pub(super) type DriveRxQueue = heapless::spsc::Queue<DriveFrame, 4>;

/// When each request frame's last bit left (firmware µs), for the truth
/// record (see [`Sensors::sample`](super::Sensors::sample)): at most two requests fit in a 10 ms
/// period at 115 200 baud.
pub(super) type DriveTxQueue = heapless::spsc::Queue<u32, 4>;

/// USART2, the RS-485 line to the drum driver (QEMU: DE on PA1 is a no-op).
///
/// QEMU's USART sends a byte the moment it is written, so the line's time
/// is modelled here: a request of `n` bytes ends `n` character times
/// (11 bits each, `drive_link::timing`) after it was started; the replies
/// come from the host's virtual driver through the lock-step gate, each
/// with the firmware time its last byte arrives (the host computes it from
/// the request's end, the driver's turnaround and the reply's own time on
/// the line), and are handed over from that time on.
pub struct DriveLine {
    pub(super) tx: Tx<USART2>,
    pub(super) baud: u32,
    pub(super) sending_until: Option<u64>,
    pub(super) rx: heapless::spsc::Consumer<'static, DriveFrame>,
    pub(super) tx_ends: heapless::spsc::Producer<'static, u32>,
}

impl DriveLine {
    /// The line's speed (QEMU's USART ignores it; the model uses it).
    pub fn set_baud(&mut self, baud: u32) {
        self.baud = baud;
    }

    /// Sends a request frame (DE high first: no-op here).
    pub fn send(&mut self, frame: &[u8], now_us: u64) {
        for &b in frame {
            let _ = nb::block!(self.tx.write_u8(b));
        }
        let chars = u32::try_from(frame.len()).unwrap_or(u32::MAX);
        let on_line = drive_link::timing::frame_time_us(self.baud, chars).unwrap_or(0);
        let end = now_us.saturating_add(u64::from(on_line));
        self.sending_until = Some(end);
        let _ = self.tx_ends.enqueue(end as u32);
    }

    /// The request's last stop bit has left (TC; DE low): its time, once.
    pub fn sent(&mut self, now_us: u64) -> Option<u64> {
        match self.sending_until {
            Some(end) if now_us >= end => {
                self.sending_until = None;
                Some(end)
            }
            _ => None,
        }
    }

    /// A reply frame whose last byte has arrived by `now_us`, into `buf`.
    pub fn receive(&mut self, now_us: u64, buf: &mut [u8]) -> Option<usize> {
        let f = self.rx.peek()?;
        // Due when `end_us` is not after now (wrapping 32-bit µs).
        if (now_us as u32).wrapping_sub(f.end_us) >= 1 << 31 {
            return None;
        }
        let f = self.rx.dequeue()?;
        let n = usize::from(f.len).min(DRIVE_FRAME_MAX).min(buf.len());
        buf.get_mut(..n)?.copy_from_slice(f.bytes.get(..n)?);
        Some(n)
    }

    /// Whether a reply is on the line at `now_us`, its frame not yet ended
    /// by its silence (from its first byte: its end less its time on the
    /// line and the 3.5-character silence).
    pub fn receiving(&mut self, now_us: u64) -> bool {
        let Some(f) = self.rx.peek() else {
            return false;
        };
        let on_line = drive_link::timing::frame_time_us(self.baud, u32::from(f.len)).unwrap_or(0);
        let silent = drive_link::timing::silent_interval_us(self.baud).unwrap_or(0);
        let start = f.end_us.wrapping_sub(on_line).wrapping_sub(silent);
        // Started when `start` is not after now (wrapping 32-bit µs).
        (now_us as u32).wrapping_sub(start) < 1 << 31
    }

    /// USART2's interrupt: never enabled on this board.
    pub fn on_interrupt(&mut self, _now_us: u64) {}
}
