//! The Hall edges' way from the capture interrupt to the control task: an
//! edge that finds the queue full is dropped (counted), and the next edge
//! that gets in is marked as following a loss, so that the interval ending
//! at it, which spans the dropped tooth, is not taken as one tooth period
//! and the tooth still counts for the distance (host test:
//! `tests/tests/edge_queue.rs`, which includes this file).

/// Remembers that an edge was dropped until the next one is queued.
pub struct DropMark {
    dropped: bool,
}

impl DropMark {
    /// Nothing dropped yet.
    pub const fn new() -> Self {
        Self { dropped: false }
    }

    /// Queues `edge` with `enqueue` (`Err`: the queue is full), marked by
    /// `mark_lost` first when the edge before it was dropped. Returns
    /// whether it was queued.
    pub fn queue<E>(
        &mut self,
        mut edge: E,
        mark_lost: impl FnOnce(&mut E),
        enqueue: impl FnOnce(E) -> Result<(), E>,
    ) -> bool {
        if self.dropped {
            mark_lost(&mut edge);
        }
        let queued = enqueue(edge).is_ok();
        self.dropped = !queued;
        queued
    }
}
