//! The pulse input's interrupt (TIM2 CH1): profile A's Hall teeth,
//! profile B's feeding-roller index.

use rtic::Mutex as _;

use crate::app::hall_capture;
use crate::stats;

/// Hall edges: timestamps each tooth of the 25-tooth gear.
///
/// - Priority 3: the capture register latches the edge time in hardware,
///   so latency only has to stay below the shortest period (1 ms).
/// - Released by TIM2 capture (≤ 1 kHz) and overflow (15.3 Hz).
/// - Budget: 2 µs.
pub fn hall_capture(mut cx: hall_capture::Context<'_>) {
    if let Some(edge) = cx.shared.hall.lock(|h| h.on_interrupt()) {
        stats::HALL_EDGES.inc();
        if edge.after_lost {
            stats::HALL_EDGES_LOST.inc();
        }
        // A full queue (the control task late) drops the edge; the next
        // one queued follows a loss (firmware/src/edge_queue.rs).
        let edges_in = &mut cx.local.edges_in;
        if !cx
            .local
            .drop_mark
            .queue(edge, |e| e.after_lost = true, |e| edges_in.enqueue(e))
        {
            stats::HALL_EDGES_DROPPED.inc();
        }
    }
}
