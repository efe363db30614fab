//! The firmware's Hall edge queue (`firmware/src/edge_queue.rs`, the file
//! itself included here) with the firmware's queue type, heapless's SPSC
//! queue of 16 edges: when the control task is late and the queue is full,
//! the edge after a dropped one must carry `after_lost`. Before, it did not:
//! the interval ending at it (two teeth) was measured as one tooth period,
//! a speed reading of half the truth, and the dropped tooth was missing
//! from the distance.

#[path = "../../firmware/src/edge_queue.rs"]
mod edge_queue;

use edge_queue::DropMark;
use heapless::spsc::Queue;

/// The firmware's `board::HallEdge`: capture stamp and the loss flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Edge {
    stamp: u32,
    after_lost: bool,
}

#[test]
fn the_edge_after_a_dropped_one_is_marked_lost() {
    // firmware/src/main.rs: EDGE_QUEUE = 16 (a spsc::Queue of N holds N - 1).
    let mut q: Queue<Edge, 16> = Queue::new();
    let (mut tx, mut rx) = q.split();
    let mut mark = DropMark::new();
    let mut push = |stamp: u32, tx: &mut heapless::spsc::Producer<'_, Edge>| {
        mark.queue(
            Edge {
                stamp,
                after_lost: false,
            },
            |e| e.after_lost = true,
            |e| tx.enqueue(e),
        )
    };
    // 1 ms apart (1 kHz, the Hall switch's fastest): the control task late.
    let mut queued = 0;
    for i in 0..15u32 {
        queued += u32::from(push(i * 1000, &mut tx));
    }
    assert_eq!(queued, 15, "the queue holds 15");
    assert!(!push(15_000, &mut tx), "the 16th is dropped");
    assert!(!push(16_000, &mut tx), "and the 17th");
    // The control task runs: it drains the queue.
    let drained: Vec<Edge> = core::iter::from_fn(|| rx.dequeue()).collect();
    assert_eq!(drained.len(), 15);
    assert!(drained.iter().all(|e| !e.after_lost));
    // The next edge follows two dropped ones: marked; the one after is not.
    assert!(push(17_000, &mut tx));
    assert!(push(18_000, &mut tx));
    assert_eq!(
        rx.dequeue(),
        Some(Edge {
            stamp: 17_000,
            after_lost: true
        })
    );
    assert_eq!(
        rx.dequeue(),
        Some(Edge {
            stamp: 18_000,
            after_lost: false
        })
    );
}
