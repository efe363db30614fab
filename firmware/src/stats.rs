//! Run-time counters shared between interrupt handlers and tasks.
//!
//! Plain atomics: every counter has one writer, readers only log them, and a
//! 32-bit load/store is single-copy atomic on the Cortex-M3, so no task ever
//! has to take a lock (and raise its priority) just to count.

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// A monotonically increasing event counter (wraps after 2³² events).
pub struct Counter(AtomicU32);

impl Counter {
    /// A counter at zero.
    pub const fn new() -> Self {
        Self(AtomicU32::new(0))
    }

    /// Counts one event.
    #[inline]
    pub fn inc(&self) {
        self.add(1);
    }

    /// Counts `n` events. Load and store rather than `fetch_add`: each
    /// counter has exactly one writer, so the read-modify-write cannot race.
    #[inline]
    pub fn add(&self, n: u32) {
        self.0.store(self.0.load(Relaxed).wrapping_add(n), Relaxed);
    }

    /// The current count.
    #[inline]
    pub fn get(&self) -> u32 {
        self.0.load(Relaxed)
    }
}

/// Runs of the 10 ms control task.
pub static CONTROL_LOOPS: Counter = Counter::new();
/// Control-task runs that finished after their next release time.
pub static CONTROL_OVERRUNS: Counter = Counter::new();
/// Bytes received from the touchscreen (USART1).
pub static HMI_RX_BYTES: Counter = Counter::new();
/// Received bytes dropped because the HMI task had not taken the earlier ones.
pub static HMI_RX_DROPPED: Counter = Counter::new();
/// Receive errors (overrun, framing, noise, parity) reported by USART1.
pub static HMI_RX_ERRORS: Counter = Counter::new();
/// Instructions to the screen dropped because its transmit queue was full.
pub static HMI_TX_DROPPED: Counter = Counter::new();
/// Hall edges captured (TIM2 CH1, or the simulated machine on the QEMU board).
pub static HALL_EDGES: Counter = Counter::new();
/// Hall edges dropped because the control task had not taken the earlier ones.
pub static HALL_EDGES_DROPPED: Counter = Counter::new();
/// Hall captures that came after lost edges (TIM2's overcapture flag CC1OF:
/// a capture while the previous one was still unread). Each hides at least
/// one edge; the estimator skips the interval ending at it.
pub static HALL_EDGES_LOST: Counter = Counter::new();
