//! The touchscreen line's interrupt: bytes in to the hmi task, bytes out
//! from its transmit ring.

use crate::app::usart1;
use crate::screen_line::LineItem;
use crate::{stats, uptime_ms};

/// The touchscreen's USART1: each byte in goes to the queue of the hmi task
/// with its arrival time; bytes out go from the transmit ring while the
/// data register is empty (TXE).
///
/// - Priority 4 (highest but the stop input): the F103's USART has no
///   FIFO, so a byte must be read within one character time (87 µs at
///   115200 baud).
/// - Released by RXNE and TXE (and pended by the hmi task to start sending),
///   at most 11.5 k times a second each way.
/// - Budget: 2 µs.
pub fn usart1(cx: usart1::Context<'_>) {
    let now = uptime_ms();
    // A few bytes at most are pending; the bound keeps an error storm
    // from holding the CPU.
    for _ in 0..4 {
        match cx.local.hmi_rx.read() {
            Ok(byte) => {
                stats::HMI_RX_BYTES.inc();
                if cx
                    .local
                    .bytes_in
                    .try_send(LineItem::new(byte, now))
                    .is_err()
                {
                    stats::HMI_RX_DROPPED.inc();
                }
            }
            Err(nb::Error::WouldBlock) => break,
            Err(nb::Error::Other(_)) => stats::HMI_RX_ERRORS.inc(),
        }
    }
    cx.local.hmi_tx.send(cx.local.tx_out);
}
