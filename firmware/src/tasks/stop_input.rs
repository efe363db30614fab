//! The stop input's interrupt and the state it shares with the control
//! task.

use rtic::Mutex as _;
use supervisor::stop_input::StopLatch;

use crate::app::stop_input;
use crate::board;

/// The stop input's pin and latch.
pub struct StopCircuit {
    /// PB10.
    pub pin: board::StopInput,
    /// Latched from an opening until closed and Start.
    pub latch: StopLatch,
}

/// The stop input (a normally closed contact on PB10): outputs off at
/// once, in the interrupt, then the latch.
///
/// - Priority 5 (highest): nothing delays a stop.
/// - Released by each edge of the contact (a bouncing contact: a few per
///   operation).
/// - Budget: 1 µs (register writes only); the alarm and the log follow
///   in the next control period.
pub fn stop_input(mut cx: stop_input::Context<'_>) {
    cx.shared.stop.lock(|stop| {
        stop.pin.clear_interrupt();
        if stop.pin.is_open() {
            board::stop_outputs();
            stop.latch.trip();
        }
    });
}
