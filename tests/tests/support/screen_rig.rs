//! The firmware's screen line on the host, in virtual time, against the
//! independent Nextion model (`tests/peers/nextion`, written from the
//! Nextion Instruction Set and docs/hmi.md, not from the firmware's code).
//!
//! What runs is the firmware's own: the screen link (`hmi_proto::hmi::Hmi`)
//! and the hmi task's line code (`firmware/src/screen_line.rs`, included by
//! the test): each received byte stamped by the USART1 interrupt and queued
//! in a channel of `RX_QUEUE` items, the link fed at the task's wakes, the
//! link's bytes moved to the transmit ring of `TX_RING` bytes that the
//! USART1 interrupt sends one per character time. What is modelled: the
//! line (10 bits a byte at 115 200 baud, the model's own pacing for the
//! screen's bytes), the interrupt (a byte in the channel when its stop bit
//! ends, dropped when the channel is full, as `usart1` does), the hmi task's
//! schedule (it runs `task_latency_us` after a byte arrives, or 20 ms after
//! its last run: `HMI_TICK_MS`) and the status task (the page's live values
//! every 200 ms: `STATUS_PERIOD_MS`).

use std::collections::VecDeque;

use hmi_proto::hmi::{Event, Hmi, TX_CAPACITY};
use hmi_proto::screen::{Settings, Status};
use nextion_model::Screen;

use super::screen_line::{self, LineItem};

/// The firmware's receive channel (firmware/src/main.rs `RX_QUEUE`, real board).
pub const RX_QUEUE: usize = 64;
/// The firmware's transmit ring (`TX_RING`, real board: holds one less).
pub const TX_RING: usize = TX_CAPACITY + 1;
/// `HMI_TICK_MS`.
pub const HMI_TICK_US: u64 = 20_000;
/// `STATUS_PERIOD_MS`.
pub const STATUS_PERIOD_US: u64 = 200_000;
/// One character at 115 200 baud, 8N1 (10 bits), in ns.
const BYTE_NS: u64 = 10 * 1_000_000_000 / 115_200;

/// An operator action at a time.
// Each test file that includes the rig uses some of them.
#[allow(dead_code)]
#[derive(Clone, Debug)]
pub enum Act {
    /// A finger down on the component of the page shown.
    Press(&'static str),
    /// The finger lifted.
    Release(&'static str),
    /// Raw bytes on the line towards the MCU (noise), arriving back to back.
    Noise(Vec<u8>),
    /// On the open numeric keyboard (the editor's popup page): this value
    /// typed and OK pressed (the field's page is loaded again).
    KeyboardEnter(i32),
    /// On the open numeric keyboard: left without a value.
    KeyboardCancel,
}

/// The rig.
pub struct Rig {
    /// The independent screen.
    pub screen: Screen,
    /// The firmware's screen link.
    pub hmi: Hmi,
    now_us: u64,
    /// Bytes on the line from the screen, with the time their stop bit ends.
    from_screen: VecDeque<(u64, u8)>,
    /// The channel from the USART1 interrupt to the hmi task.
    channel: VecDeque<LineItem>,
    /// Bytes the interrupt dropped on a full channel (`HMI_RX_DROPPED`).
    pub rx_dropped: u32,
    /// The largest fill the channel reached.
    pub channel_peak: usize,
    ring: heapless::spsc::Producer<'static, u8>,
    ring_out: heapless::spsc::Consumer<'static, u8>,
    /// When the byte being sent (if any) ends, ns.
    tx_busy_until_ns: u64,
    /// When the hmi task runs next (a byte woke it, or its timeout).
    task_due_us: u64,
    /// How long after a received byte the hmi task runs.
    pub task_latency_us: u64,
    status_due_us: u64,
    /// The live values the status task writes.
    pub status: Status,
    /// Operator actions not yet done, in time order.
    acts: VecDeque<(u64, Act)>,
    /// Every event of the link, with the time the hmi task took it.
    pub events: Vec<(u64, Event)>,
}

impl Rig {
    /// A screen switched on at time 0 and the firmware's link, run until the
    /// link reports the screen set up.
    pub fn connected(settings: Settings) -> Self {
        Self::connected_to(Screen::new(), settings)
    }

    /// [`connected`](Self::connected) to `screen` (switched on at time 0).
    pub fn connected_to(screen: Screen, settings: Settings) -> Self {
        let ring: &'static mut heapless::spsc::Queue<u8, TX_RING> =
            Box::leak(Box::new(heapless::spsc::Queue::new()));
        let (ring, ring_out) = ring.split();
        let mut rig = Rig {
            screen,
            hmi: Hmi::new(settings, "rig"),
            now_us: 0,
            from_screen: VecDeque::new(),
            channel: VecDeque::new(),
            rx_dropped: 0,
            channel_peak: 0,
            ring,
            ring_out,
            tx_busy_until_ns: 0,
            task_due_us: 0,
            task_latency_us: 50,
            status_due_us: STATUS_PERIOD_US,
            status: Status::default(),
            acts: VecDeque::new(),
            events: Vec::new(),
        };
        let t = rig.run_until_event(2_000_000, |e| matches!(e, Event::Connected));
        assert!(t.is_some(), "the link never connected");
        rig.run_for(100_000);
        rig
    }

    /// Virtual time, µs.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// Schedules `act` at `at_us` (not before the acts already scheduled).
    pub fn at(&mut self, at_us: u64, act: Act) {
        debug_assert!(self.acts.back().is_none_or(|(t, _)| *t <= at_us));
        self.acts.push_back((at_us, act));
    }

    /// Runs for `us` of virtual time.
    pub fn run_for(&mut self, us: u64) {
        let end = self.now_us + us;
        self.run_until(end);
    }

    /// Runs until `pred` holds for an event the link reports, at most until
    /// `limit_us`; returns its time.
    pub fn run_until_event(&mut self, limit_us: u64, pred: impl Fn(&Event) -> bool) -> Option<u64> {
        let seen = self.events.len();
        while self.now_us < limit_us {
            let next = self.next_time().min(limit_us);
            self.step(next);
            if let Some((t, _)) = self.events[seen..].iter().find(|(_, e)| pred(e)) {
                return Some(*t);
            }
        }
        None
    }

    /// Runs until `end_us`.
    pub fn run_until(&mut self, end_us: u64) {
        while self.now_us < end_us {
            let next = self.next_time().min(end_us);
            self.step(next);
        }
    }

    fn next_time(&self) -> u64 {
        let mut t = self.task_due_us.min(self.status_due_us);
        if let Some(&(a, _)) = self.from_screen.front() {
            t = t.min(a);
        }
        if let Some(&(a, _)) = self.acts.front() {
            t = t.min(a);
        }
        if !self.ring_out.is_empty() {
            t = t.min((self.tx_busy_until_ns + BYTE_NS).div_ceil(1000));
        }
        t.max(self.now_us + 1)
    }

    /// Everything due by `t_us`.
    fn step(&mut self, t_us: u64) {
        self.transmit_until(t_us);
        self.now_us = t_us;
        while let Some((_, act)) = self.acts.front().filter(|(a, _)| *a <= t_us) {
            let act = act.clone();
            self.acts.pop_front();
            match act {
                Act::Press(name) => {
                    self.screen.press(t_us, name);
                }
                Act::Release(name) => {
                    self.screen.release(t_us, name);
                }
                Act::KeyboardEnter(value) => {
                    let _ = self.screen.keyboard_enter(t_us, value);
                }
                Act::KeyboardCancel => {
                    let _ = self.screen.keyboard_cancel(t_us);
                }
                Act::Noise(bytes) => {
                    let start = self.from_screen.back().map_or(t_us, |&(a, _)| a).max(t_us);
                    for (i, b) in bytes.into_iter().enumerate() {
                        let end = start + (i as u64 + 1) * BYTE_NS / 1000;
                        self.from_screen.push_back((end, b));
                    }
                }
            }
        }
        self.screen.advance(t_us);
        self.take_screen_output();
        // The USART1 interrupt: each byte whose stop bit has ended.
        while let Some(&(a, b)) = self.from_screen.front().filter(|(a, _)| *a <= t_us) {
            self.from_screen.pop_front();
            if self.channel.len() >= RX_QUEUE {
                self.rx_dropped += 1;
            } else {
                self.channel.push_back(LineItem::new(b, ms(a)));
                self.channel_peak = self.channel_peak.max(self.channel.len());
            }
            self.task_due_us = self.task_due_us.min(a + self.task_latency_us);
        }
        if self.status_due_us <= t_us {
            // The status task (priority 1, between two runs of the hmi task).
            let _ = self.hmi.write_status(&self.status);
            self.status_due_us += STATUS_PERIOD_US;
        }
        if self.task_due_us <= t_us {
            self.run_task();
        }
    }

    /// One run of the hmi task (firmware/src/main.rs `hmi`).
    fn run_task(&mut self) {
        let now = ms(self.now_us);
        while let Some(item) = self.channel.pop_front() {
            screen_line::deliver(&mut self.hmi, item, now);
        }
        self.hmi.tick(now);
        while let Some(e) = self.hmi.poll_event() {
            self.events.push((self.now_us, e));
        }
        if screen_line::refill(&mut self.hmi, &mut self.ring) > 0 && !self.ring_out.is_empty() {
            // The kick: an idle transmitter starts now.
            let now_ns = self.now_us * 1000;
            self.tx_busy_until_ns = self.tx_busy_until_ns.max(now_ns);
        }
        self.task_due_us = self.now_us + HMI_TICK_US;
    }

    /// The USART1 transmitter: the ring's bytes, one per character, to
    /// the screen, up to `t_us`.
    fn transmit_until(&mut self, t_us: u64) {
        let t_ns = t_us * 1000;
        let mut sent = Vec::new();
        while !self.ring_out.is_empty() && self.tx_busy_until_ns + BYTE_NS <= t_ns {
            let b = self.ring_out.dequeue().unwrap_or(0);
            self.tx_busy_until_ns += BYTE_NS;
            sent.push((self.tx_busy_until_ns / 1000, b));
        }
        if !sent.is_empty() {
            self.screen.receive_timed(&sent);
            self.take_screen_output();
        }
    }

    /// The screen's bytes onto the line, after the bytes already on it (a
    /// noise burst holds the line: the screen's bytes follow it).
    fn take_screen_output(&mut self) {
        for (t, b) in self.screen.take_output_timed() {
            let after = self
                .from_screen
                .back()
                .map_or(0, |&(a, _)| a + BYTE_NS.div_ceil(1000));
            self.from_screen.push_back((t.max(after), b));
        }
    }
}

/// The firmware's millisecond clock at `us`.
pub fn ms(us: u64) -> u32 {
    (us / 1000) as u32
}
