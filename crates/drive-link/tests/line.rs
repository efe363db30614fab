//! The master against the virtual ZLAC8015D over a simulated half-duplex
//! line: every frame takes its time on the wire (11 bits a character), the
//! driver answers after its turnaround, a frame is handed over after the
//! 3.5-character silence that ends it, and two frames on the wire at once
//! garble each other. Simulated time in µs; nothing here reads the host's
//! clock.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

use drive_link::link::SetupFault;
use drive_link::link::{
    ControlAction, Event, Link, LinkConfig, LinkTiming, LossCause, FAULT_POLL_EVERY,
};
use drive_link::profile::{DriverFault, DriverProfile, ZLAC8015D};
use drive_link::rtu::MAX_FRAME;
use drive_link::timing::{frame_time_us, silent_interval_us};
use drive_link::virtual_driver::VirtualZlac;

/// A frame on the wire.
struct OnWire {
    start: u64,
    end: u64,
    bytes: Vec<u8>,
    from_master: bool,
    garbled: bool,
}

struct Bench {
    now: u64,
    baud: u32,
    link: Link,
    driver: VirtualZlac,
    wire: Vec<OnWire>,
    /// (time, event)
    events: Vec<(u64, Event)>,
    /// Speed samples seen: (time read, sampled_at, milli-r/min).
    samples: Vec<(u64, u64, i32)>,
    /// Request start times.
    requests: Vec<u64>,
    /// Noise before the next replies: (count, noise bytes, silence between
    /// the noise and the reply, µs). The noise starts when the request
    /// ends (the bus heard as DE drops).
    noise: (u32, u32, u64),
    /// Noise before a reply at random: (per mille, seed).
    noise_random: (u32, u64),
    /// The last request sent.
    last_request: Vec<u8>,
}

const STEP_US: u64 = 50;

impl Bench {
    fn new(baud: u32) -> Self {
        let profile = DriverProfile { baud, ..ZLAC8015D };
        Self {
            now: 0,
            baud,
            link: Link::new(profile, LinkConfig::for_baud(baud).unwrap()),
            driver: VirtualZlac::default(),
            wire: Vec::new(),
            events: Vec::new(),
            samples: Vec::new(),
            requests: Vec::new(),
            noise: (0, 0, 0),
            noise_random: (0, 1),
            last_request: Vec::new(),
        }
    }

    /// Runs until a reply is taken: then no request is outstanding.
    fn run_until_answered(&mut self) {
        let r = self.link.counters().replies;
        while self.link.counters().replies == r {
            self.run_for(STEP_US);
        }
    }

    /// xorshift64: the noise's own generator (deterministic).
    fn random(&mut self) -> u64 {
        let mut x = self.noise_random.1;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.noise_random.1 = x;
        x
    }

    fn put(&mut self, start: u64, bytes: Vec<u8>, from_master: bool) {
        let end = start + u64::from(frame_time_us(self.baud, bytes.len() as u32).unwrap());
        let mut garbled = false;
        for w in &mut self.wire {
            if w.start < end && start < w.end {
                w.garbled = true;
                garbled = true;
            }
        }
        self.wire.push(OnWire {
            start,
            end,
            bytes,
            from_master,
            garbled,
        });
    }

    fn run_for(&mut self, us: u64) {
        let stop = self.now + us;
        let t35 = u64::from(silent_interval_us(self.baud).unwrap());
        while self.now < stop {
            self.now += STEP_US;
            let now = self.now;
            self.driver.advance(STEP_US as u32);
            // Frames whose end (or end + t3.5) falls in this step.
            let mut done = Vec::new();
            self.wire.retain(|w| {
                let due = if w.from_master { w.end } else { w.end + t35 };
                if due <= now {
                    done.push((w.end, w.bytes.clone(), w.from_master, w.garbled));
                    false
                } else {
                    true
                }
            });
            for (end, bytes, from_master, garbled) in done {
                if from_master {
                    self.link.sent(end);
                    let mut heard = bytes.clone();
                    if garbled {
                        heard[1] ^= 0x55;
                    }
                    if let Some((reply, delay)) = self.driver.handle(&heard) {
                        let mut start = end + u64::from(delay);
                        let burst = if self.noise.0 > 0 {
                            self.noise.0 -= 1;
                            Some((self.noise.1, self.noise.2))
                        } else if self.noise_random.0 > 0
                            && self.random() % 1000 < u64::from(self.noise_random.0)
                        {
                            Some((8, 5_000))
                        } else {
                            None
                        };
                        if let Some((bytes, gap)) = burst {
                            let noise: Vec<u8> = (0..bytes).map(|_| self.random() as u8).collect();
                            let noise_end =
                                end + u64::from(frame_time_us(self.baud, bytes).unwrap());
                            self.put(end, noise, false);
                            start = start.max(noise_end + gap);
                        }
                        self.put(start, reply, false);
                    }
                } else {
                    let mut heard = bytes.clone();
                    if garbled && heard.len() > 1 {
                        heard[1] ^= 0x55;
                    }
                    if let Some(e) = self.link.received(now, &heard) {
                        self.events.push((now, e));
                    }
                    if let Some(s) = self.link.speed() {
                        if self.samples.last().map(|l| l.1) != Some(s.sampled_at_us) {
                            self.samples.push((now, s.sampled_at_us, s.drum_milli_rpm));
                        }
                    }
                }
            }
            // Bytes from the driver's side on the line, their frame not yet
            // ended by its silence: the board layer tells the master.
            if self.wire.iter().any(|w| !w.from_master && w.start <= now) {
                self.link.line_busy(now);
            }
            if let Some(e) = self.link.tick(now) {
                self.events.push((now, e));
            }
            let mut buf = [0u8; MAX_FRAME];
            if let Some(n) = self.link.next_frame(now, &mut buf) {
                self.requests.push(now);
                self.last_request = buf[..n].to_vec();
                self.put(now, buf[..n].to_vec(), true);
            }
        }
    }
}

/// One speed poll's cycle by hand from the spec's timing: request (8
/// characters) + turnaround + reply (7 characters) + the 3.5-character
/// silence that ends the reply + the 3.5-character gap before the next
/// request.
fn poll_cycle_us(baud: u32, turnaround: u32) -> f64 {
    let c = 11.0e6 / f64::from(baud);
    let t35 = if baud > 19_200 { 1750.0 } else { 3.5 * c };
    8.0 * c + f64::from(turnaround) + 7.0 * c + 2.0 * t35
}

#[test]
fn polls_at_the_rate_the_line_allows_and_reads_the_speed() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.driver.actual_decirpm = 203; // 20.3 r/min
        b.run_for(2_000_000);
        // The first request selects velocity mode; then speed and fault
        // polls (every 6th is the fault register).
        let n = b.requests.len() as f64;
        let expected = 2.0e6 / poll_cycle_us(baud, b.driver.turnaround_us);
        // Within 5 % (the 50 µs simulation step rounds each event).
        assert!(
            (n / expected - 1.0).abs() < 0.05,
            "{baud} baud: {n} requests, expected {expected:.1}"
        );
        assert_eq!(b.samples.last().unwrap().2, 20_300);
        let c = b.link.counters();
        assert_eq!(
            (c.crc_errors, c.timeouts, c.late_replies, c.losses),
            (0, 0, 0, 0),
            "{baud}: {c:?}"
        );
        // Age of a sample when it arrives: reply time + turnaround + t3.5,
        // well under the 20–50 ms the drive model must tolerate at 9600.
        let age = b.samples.iter().map(|s| s.0 - s.1).max().unwrap();
        let c1 = 11.0e6 / f64::from(baud);
        let t35 = if baud > 19_200 { 1750.0 } else { 3.5 * c1 };
        let bound = 7.0 * c1 + 2000.0 + t35 + 2.0 * STEP_US as f64;
        assert!((age as f64) <= bound, "{baud}: age {age} µs > {bound:.0}");
        eprintln!(
            "{baud} baud: {:.1} ms a poll, read-back age ≤ {:.1} ms",
            2000.0 / n,
            age as f64 / 1000.0
        );
    }
}

#[test]
fn enable_and_speed_command_drive_the_motor() {
    let mut b = Bench::new(115_200);
    b.driver.own_motor = true;
    b.link.control(ControlAction::Enable);
    b.link.set_speed_command(Some(20_000));
    b.run_for(1_000_000);
    assert!(b.driver.enabled && b.driver.velocity_mode);
    assert_eq!(b.driver.command_raw, 20);
    // τ = 100 ms: after ~1 s the motor is at the command, and the read-back shows it.
    assert_eq!(b.samples.last().unwrap().2, 20_000);
    b.link.control(ControlAction::Disable);
    b.run_for(50_000);
    assert!(!b.driver.enabled);
}

#[test]
fn crc_errors_within_the_retry_budget_are_counted_and_survived() {
    let mut b = Bench::new(9600);
    b.driver.actual_decirpm = 100;
    b.run_for(200_000);
    // Two corrupted replies in a row: both retried, no loss.
    b.driver.inject.corrupt_replies = 2;
    b.run_for(500_000);
    let c = b.link.counters();
    assert_eq!(c.crc_errors, 2);
    assert_eq!(c.losses, 0);
    assert!(b.events.is_empty(), "{:?}", b.events);
    // Three in a row (1 + 2 retries) lose the link.
    b.driver.inject.corrupt_replies = 3;
    b.run_for(500_000);
    assert_eq!(b.link.counters().crc_errors, 5);
    assert!(matches!(b.events.first(), Some((_, Event::Lost))));
    assert_eq!(b.link.loss_cause(), Some(LossCause::Corrupt));
    // It answers again at once: restored, and the operator's ack clears it.
    assert!(matches!(b.events.get(1), Some((_, Event::Restored))));
    assert!(b.link.acknowledge());
    assert_eq!(b.link.loss_cause(), None);
}

/// A profile naming a register the driver does not have (a generic
/// profile's speed register mistyped): the virtual ZLAC8015D answers
/// exception 2, "illegal data address" (Modbus application protocol
/// v1.1b3 §7). The loss says which request was refused and how, where a
/// silent driver says no reply.
#[test]
fn a_refused_register_is_named_as_the_cause_of_the_loss() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        let profile = DriverProfile {
            baud,
            speed_feedback: 0x2AB0,
            ..ZLAC8015D
        };
        b.link = Link::new(profile, LinkConfig::for_baud(baud).unwrap());
        b.run_for(500_000);
        assert!(matches!(b.events.first(), Some((_, Event::Lost))));
        assert_eq!(
            b.link.loss_cause(),
            Some(LossCause::Refused {
                function: 0x03,
                register: 0x2AB0,
                code: 2
            })
        );
        assert!(b.link.counters().exceptions >= 3);
        assert!(!b.link.acknowledge(), "refused requests are no answer");
    }
    // A silent driver: no reply.
    let mut b = Bench::new(9600);
    b.run_for(300_000);
    b.driver.inject.silent = true;
    b.run_for(1_000_000);
    assert_eq!(b.link.loss_cause(), Some(LossCause::NoReply));
    let losses = b.events.len();
    // Still lost, the driver back but every reply corrupted: the cause
    // follows, reported once more; no second loss is counted.
    b.driver.inject.silent = false;
    b.driver.inject.corrupt_replies = u32::MAX;
    b.run_for(500_000);
    assert_eq!(b.link.loss_cause(), Some(LossCause::Corrupt));
    assert_eq!(b.events.len(), losses + 1);
    assert!(matches!(b.events.last(), Some((_, Event::Lost))));
    assert_eq!(b.link.counters().losses, 1);
}

/// A driver whose registers are 32 bits wide (it answers a one-register
/// read with a byte count of 4): every reply is from its slave id and has a
/// good CRC but does not fit the request. The loss must name the request
/// and that the reply did not fit (check the profile), not "no reply"
/// (check the wiring), which it said before.
#[test]
fn a_driver_whose_replies_do_not_fit_is_named_as_the_cause() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.driver.inject.wide_registers = true;
        b.run_for(600_000);
        assert!(matches!(b.events.first(), Some((_, Event::Lost))));
        // The first requests are the velocity-mode and offline-time writes
        // (fit: echoed), then the read of the speed resolution, the
        // ZLAC8015D's 0x2022 (Modbus function 03).
        assert_eq!(
            b.link.loss_cause(),
            Some(LossCause::Unfit {
                function: 0x03,
                register: ZLAC8015D.resolution_register.unwrap()
            }),
            "{baud} baud"
        );
        assert!(b.link.counters().late_replies >= 3);
        // The same driver with 16-bit registers again: it answers.
        b.driver.inject.wide_registers = false;
        b.run_for(300_000);
        assert!(b.link.is_answering());
    }
}

#[test]
fn a_cut_link_is_lost_within_the_retry_budget_and_recovers() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.run_for(300_000);
        let cut = b.now;
        b.driver.inject.silent = true;
        b.run_for(1_000_000);
        let (t_lost, e) = b.events[0];
        assert_eq!(e, Event::Lost);
        // By hand: the request in flight at the cut and 2 retries, each a
        // request (8 characters) + the reply timeout + the retry gap; at most one
        // more cycle for the transaction already under way at the cut.
        let c = LinkConfig::for_baud(baud).unwrap();
        let attempt =
            f64::from(frame_time_us(baud, 8).unwrap() + c.reply_timeout_us + c.retry_gap_us);
        let bound = 3.0 * attempt + poll_cycle_us(baud, 2000) + STEP_US as f64;
        let took = (t_lost - cut) as f64;
        assert!(
            took <= bound,
            "{baud}: lost {took} µs after the cut, bound {bound:.0}"
        );
        assert!(b.link.is_lost() && b.link.speed().is_none());
        assert!(!b.link.acknowledge(), "no ack while the driver is silent");
        // The operator cannot clear it; the driver comes back: restored.
        b.driver.inject.silent = false;
        b.run_for(200_000);
        assert!(b.events.iter().any(|(_, e)| *e == Event::Restored));
        assert!(b.link.is_lost(), "latched until acknowledged");
        assert!(b.link.acknowledge());
        assert!(b.link.speed().is_some());
        eprintln!(
            "{baud} baud: link lost {:.1} ms after the cut",
            took / 1000.0
        );
    }
}

/// A reply that starts after the answer time (the driver slower than its
/// setting): the request has timed out, but the retry waits for a quiet
/// line, so the late reply is heard first and taken (it answers the same
/// request) instead of colliding with the retry. Before, the retry went
/// out 1.75 ms after the timeout, on top of the late reply.
#[test]
fn a_late_reply_is_taken_not_collided_with() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.driver.actual_decirpm = 55;
        b.run_for(100_000);
        // One reply 65 ms late (67 ms answer): past the 60 ms answer time.
        b.driver.inject.late_replies = 1;
        b.driver.inject.extra_delay_us = 65_000;
        b.run_for(300_000);
        let c = b.link.counters();
        assert_eq!(
            (c.timeouts, c.retries, c.crc_errors, c.losses),
            (1, 0, 0, 0),
            "{baud}: {c:?}"
        );
        assert_eq!(b.samples.last().unwrap().2, 5_500);
    }
}

#[test]
fn driver_faults_are_read_and_named() {
    let mut b = Bench::new(115_200);
    b.run_for(100_000);
    b.driver.fault_bits = 0x0004 | 0x0400;
    let set = b.now;
    b.run_for(200_000);
    let (t, e) = *b
        .events
        .iter()
        .find(|(_, e)| matches!(e, Event::Faults(_)))
        .unwrap();
    assert_eq!(e, Event::Faults(0x0404));
    // Within 6 polls + one (every 6th poll reads the faults).
    let polls = f64::from(FAULT_POLL_EVERY) + 1.0;
    assert!(
        (t - set) as f64 <= polls * poll_cycle_us(115_200, 2000),
        "{} µs",
        t - set
    );
    let names: Vec<_> = ZLAC8015D.faults(0x0404).collect();
    assert_eq!(
        names,
        [DriverFault::OverCurrent, DriverFault::OverTemperature]
    );
    assert_eq!(names[0].to_string(), "driver over-current");
}

/// A reply that comes after its request's timeout must not be taken as the
/// answer to a later request (Modbus over Serial Line V1.02 §2.4.1: a
/// reply that comes after the response timeout is an error, and the
/// master's next request is a new transaction). A function-03 reply names
/// no register, so a late speed reply landing while the fault register is
/// being read would be taken as the fault word (here 252 counts = 0x00FC:
/// over-current and overload bits), and a late fault reply (0) as the
/// speed. One slow reply (the driver busy, e.g. writing its EEPROM) in
/// normal running, delayed by anything from just past the timeout to one
/// more timeout, and started at every phase of the poll cycle.
#[test]
fn a_reply_after_its_timeout_is_never_the_answer_to_the_next_request() {
    let mut bad = Vec::new();
    for baud in [115_200, 9600] {
        // From just past the timeout to a reply that ends one more reply
        // timeout after its request's deadline (the bound the master
        // drains for; a driver later than that answers no request).
        let timeout = LinkConfig::for_baud(baud).unwrap().reply_timeout_us;
        let turnaround = VirtualZlac::default().turnaround_us;
        let first = (timeout - turnaround) / 1000;
        let last = (2 * timeout - turnaround - frame_time_us(baud, 7).unwrap()) / 1000;
        for extra_ms in first..=last {
            for phase_us in (0..40_000u64).step_by(2_500) {
                let mut b = Bench::new(baud);
                b.driver.actual_decirpm = 252;
                b.run_for(100_000 + phase_us);
                let start = b.samples.len();
                b.driver.inject.late_replies = 1;
                b.driver.inject.extra_delay_us = extra_ms * 1000;
                b.run_for(400_000);
                let faults: Vec<_> = b
                    .events
                    .iter()
                    .filter(|(_, e)| matches!(e, Event::Faults(_)))
                    .collect();
                let wrong_speed = b.samples[start..].iter().any(|s| s.2 != 25_200);
                if !faults.is_empty() || wrong_speed {
                    bad.push((baud, extra_ms, phase_us, faults.len(), wrong_speed));
                }
            }
        }
    }
    assert!(
        bad.is_empty(),
        "late replies taken as the next request's answer (extra ms, phase µs, fault events, wrong speed): {bad:?}"
    );
}

/// The reply timeout promises the driver its answer time (the setting,
/// 60 ms by default) to start its reply (docs/drive-link.md). But a reply is only seen once
/// the 3.5-character silence after its last byte has passed (Modbus over
/// Serial Line V1.02 §2.5.1.1: the frame ends there), so the deadline must
/// cover that silence too, or a driver answering within the last 1.7–4 ms
/// of its answer time times out on every request and the link is lost for
/// good.
#[test]
fn a_driver_within_the_promised_turnaround_is_never_timed_out() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.driver.actual_decirpm = 100;
        b.driver.turnaround_us = u32::from(LinkTiming::DEFAULT.reply_timeout_ms) * 1000 - 500;
        b.run_for(1_000_000);
        let c = b.link.counters();
        assert_eq!((c.timeouts, c.losses), (0, 0), "{baud}: {c:?}");
        assert_eq!(b.samples.last().map(|s| s.2), Some(10_000), "{baud}");
    }
}

/// Noise before a valid reply: a transceiver whose bus is not fail-safe
/// biased may hear a byte or two of garbage when DE drops after TC, ended
/// by silence as a frame of its own, and the driver's valid reply follows
/// a few ms later. A fragment under 4 bytes is no Modbus RTU frame
/// (address, function and the two CRC bytes at least: Modbus over Serial
/// Line V1.02 §2.5.1): it must not end the wait. Before, it failed the
/// attempt at once, the retry went out on top of the reply in flight, and
/// noise at every turnaround lost the link for good.
#[test]
fn a_noise_fragment_before_the_reply_does_not_end_the_wait() {
    let profile = drive_link::profile::GenericSettings {
        slave: 1,
        baud: 115_200,
        speed_feedback: 0x20AB,
        micro_rpm_per_count: 100_000,
        fault_register: 0x20A5,
        fault_masks: [0; 6],
        speed_command: None,
        command_scale: 100_000,
        control: None,
        velocity_mode: None,
        offline_register: None,
        resolution_register: None,
        max_speed_register: None,
    }
    .build()
    .unwrap();
    let mut link = Link::new(profile, LinkConfig::for_baud(115_200).unwrap());
    let mut t = 0u64;
    for _ in 0..10 {
        let mut buf = [0u8; MAX_FRAME];
        let n = link.next_frame(t, &mut buf).unwrap();
        assert_eq!(n, 8);
        // Speed reads, every 6th the fault register (word 0).
        let value: u8 = if buf[3] == 0xA5 { 0 } else { 0xFA };
        t += 760;
        link.sent(t);
        // DE drops: one garbage byte, seen 1.75 ms later.
        for noise in [&[0x00u8][..], &[0xFF, 0xFE], &[0x01, 0x03, 0x02]] {
            assert_eq!(link.received(t + 1_900, noise), None);
            assert_eq!(link.tick(t + 1_900), None);
        }
        // The reply (25.0 r/min = 250 counts), 2 ms after the request.
        let mut reply = vec![0x01, 0x03, 0x02, 0x00, value];
        reply.extend_from_slice(&drive_link::rtu::crc16(&reply).to_le_bytes());
        t += 4_500;
        assert_eq!(link.received(t, &reply), None);
        assert_eq!(link.speed().map(|s| s.drum_milli_rpm), Some(25_000));
        t += 2_000;
    }
    let c = link.counters();
    assert_eq!((c.replies, c.timeouts, c.losses), (10, 0, 0), "{c:?}");
    assert!(!link.is_lost());
}

/// "The latest request wins" (`Link::control`): a control word queued
/// while another is on its way must still be written. Before, the reply to
/// the write in flight cleared the queue: Start (Enable on the wire) and a
/// stop within the transaction (Disable queued) left the driver enabled
/// through its control word for good, and with the bus speed command the
/// command stops being written, so the motor ran on at its last command.
/// Every moment of the Enable's transaction is tried.
#[test]
fn a_control_word_queued_during_a_write_is_still_written() {
    for baud in [9600, 115_200] {
        let window = poll_cycle_us(baud, 2000) as u64;
        for at in (0..window).step_by(250) {
            let mut b = Bench::new(baud);
            b.run_for(300_000);
            b.link.control(ControlAction::Enable);
            b.run_for(at);
            b.link.control(ControlAction::Disable);
            b.run_for(200_000);
            assert!(
                !b.driver.enabled,
                "{baud}: Disable {at} µs after Enable lost"
            );
        }
    }
}

/// The speed command written is the one the driver has: a command changed
/// while the previous one is on its way is written at the next chance (the
/// poll after the speed read that follows), not only at the refresh every
/// 4th poll, which is when it came otherwise.
#[test]
fn a_speed_command_changed_during_its_write_is_written_next() {
    let baud = 115_200;
    let cycle = poll_cycle_us(baud, 2000) as u64;
    for at in (0..cycle).step_by(250) {
        let mut b = Bench::new(baud);
        b.run_for(300_000);
        b.link.set_speed_command(Some(20_000));
        b.run_for(at);
        b.link.set_speed_command(Some(10_000));
        // The write in flight, a speed read, the new command: 3 cycles
        // (and one for the 50 µs steps).
        b.run_for(4 * cycle);
        assert_eq!(b.driver.command_raw, 10, "changed {at} µs after the first");
    }
}

/// A control word changed while the previous one waits for its retry: the
/// retry carries the newest one. Before, an Enable that timed out was sent
/// again after the operator's stop had queued Disable, and the driver was
/// enabled through its control word for a transaction after the stop.
#[test]
fn a_retried_enable_is_not_sent_after_a_disable() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.run_for(300_000);
        // The Enable's first attempt goes unanswered.
        b.driver.inject.silent = true;
        b.link.control(ControlAction::Enable);
        b.run_for(15_000);
        b.link.control(ControlAction::Disable);
        b.driver.inject.silent = false;
        for ms in 0..300 {
            b.run_for(1_000);
            assert!(!b.driver.enabled, "{baud}: enabled {ms} ms after Disable");
        }
        assert_eq!(b.link.counters().losses, 0);
    }
}

/// The fault word is read at a guaranteed rate whatever else is polled.
/// Before, with a speed command set, every 4th poll wrote the command
/// instead of reading the fault register: 0 fault reads while commanding,
/// and a driver fault went unseen until the drum stopped. A constant
/// command and one changed every 10 ms (the control period), at both
/// bauds: the fault word is read on at least one poll in 6, and a fault
/// set at any moment is reported within 6 polls and the fault read's own
/// reply.
#[test]
fn a_fault_is_read_while_a_speed_command_runs() {
    for baud in [9600, 115_200] {
        for changing in [false, true] {
            let mut b = Bench::new(baud);
            b.link.control(ControlAction::Enable);
            b.link.set_speed_command(Some(20_000));
            b.run_for(200_000);
            let reads_before = b.link.counters().fault_reads;
            let requests_before = b.requests.len();
            for k in 0..30 {
                if changing {
                    b.link.set_speed_command(Some(20_000 + 100 * (k % 2)));
                }
                b.run_for(10_000);
            }
            let polls = b.requests.len() - requests_before;
            let reads = b.link.counters().fault_reads - reads_before;
            let every = usize::from(FAULT_POLL_EVERY);
            assert!(
                reads as usize * every >= polls - every,
                "{baud} baud, changing {changing}: {reads} fault reads in {polls} polls"
            );
            // A fault set now is reported within 6 polls + one.
            b.driver.fault_bits = 0x0800;
            let set = b.now;
            for k in 0..60 {
                if changing {
                    b.link.set_speed_command(Some(20_000 + 100 * (k % 2)));
                }
                b.run_for(10_000);
            }
            let seen = b
                .events
                .iter()
                .find(|(_, e)| *e == Event::Faults(0x0800))
                .map(|(t, _)| t - set);
            let bound =
                (f64::from(FAULT_POLL_EVERY) + 1.0) * poll_cycle_us(baud, b.driver.turnaround_us);
            assert!(
                seen.is_some_and(|s| s as f64 <= bound),
                "{baud} baud, changing {changing}: fault seen after {seen:?} µs, bound {bound:.0}"
            );
        }
    }
}

/// A clear after an acknowledged fault must reach the driver, whatever
/// follows it. The firmware queues ClearAlarm when the operator
/// acknowledges, and the next control period (10 ms later) queues the
/// enable state again (Enable or Disable). Before, the control word kept
/// only the latest request: a ClearAlarm not yet on the line was replaced
/// by the Enable, and the driver's alarm stayed latched. 50 phases over
/// one transaction and a control period, at both bauds: 50 of 50 clears
/// written, in order, before the Enable.
#[test]
fn a_clear_followed_by_an_enable_reaches_the_driver_every_time() {
    for baud in [9600, 115_200] {
        let span = poll_cycle_us(baud, 2000) as u64 + 10_000;
        let mut reached = 0;
        for k in 0..50u64 {
            let mut b = Bench::new(baud);
            b.run_for(200_000);
            b.driver.fault_bits = 0x0004;
            b.run_for(200_000);
            assert!(b.link.fault_word() == 0x0004, "{baud}: fault not read");
            b.run_for(k * span / 50);
            b.link.control(ControlAction::ClearAlarm);
            b.run_for(10_000);
            b.link.control(ControlAction::Enable);
            b.run_for(300_000);
            let clear = b.driver.writes.iter().position(|&w| w == (0x200E, 0x06));
            let enable = b.driver.writes.iter().rposition(|&w| w == (0x200E, 0x08));
            if matches!((clear, enable), (Some(c), Some(e)) if c < e) && b.driver.fault_bits == 0 {
                reached += 1;
            }
            assert!(b.driver.enabled, "{baud}: phase {k}: the Enable was lost");
        }
        assert_eq!(reached, 50, "{baud} baud: clears that reached the driver");
    }
}

/// A driver that answers in 25, 40 or 50 ms works with the default link
/// settings: no timeout, no loss, every read-back exact. Before, the
/// reply timeout was fixed at 20 ms of answer time (+ the reply's time on
/// the line): the link was lost within 150 ms and stayed lost.
#[test]
fn a_driver_answering_in_up_to_50_ms_works_with_the_defaults() {
    for baud in [9600, 115_200] {
        for answer_ms in [0, 10, 25, 40, 50] {
            let mut b = Bench::new(baud);
            b.driver.turnaround_us = answer_ms * 1000;
            b.driver.actual_decirpm = 203;
            b.link.set_speed_command(Some(20_000));
            b.run_for(2_000_000);
            let c = b.link.counters();
            assert_eq!(
                (c.timeouts, c.losses, c.late_replies),
                (0, 0, 0),
                "{baud} baud, answer {answer_ms} ms: {c:?}"
            );
            assert!(c.replies > 10, "{baud}, {answer_ms} ms: {c:?}");
            assert_eq!(b.samples.last().map(|s| s.2), Some(20_300));
            assert_eq!(b.driver.command_raw, 20);
        }
    }
}

/// Noise, a gap, then the valid reply (a bus that hears garbage as DE
/// drops): the noise is a corrupt frame of its own. It must cost at most
/// one attempt, never a retry on top of the reply in flight. Before, the
/// corrupt frame failed the attempt at once and the retry went out while
/// the reply was on the line: both were garbled, and the next attempt met
/// the same noise.
#[test]
fn noise_then_a_gap_then_the_reply_costs_at_most_one_attempt() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.driver.actual_decirpm = 250;
        b.run_for(200_000);
        b.run_until_answered();
        let before = b.requests.len();
        let answered = b.link.counters().replies;
        // Eight noise bytes, 5 ms of silence, then the reply.
        b.noise = (1, 8, 5_000);
        b.run_for(200_000);
        b.run_until_answered();
        let c = b.link.counters();
        assert_eq!(c.losses, 0, "{baud}: {c:?}");
        // Requests sent minus transactions answered: the attempts lost.
        let lost = (b.requests.len() - before) as u32 - (c.replies - answered);
        assert!(
            lost <= 1,
            "{baud} baud: {lost} attempts lost to one burst, {c:?}"
        );
        assert_eq!(b.samples.last().map(|s| s.2), Some(25_000));
    }
}

/// 2 % of replies preceded by a burst of noise and a gap, for 30 s of
/// polling at each baud rate: no link loss. Before, 3 losses in 30 s.
#[test]
fn two_percent_noise_bursts_never_lose_the_link() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.driver.actual_decirpm = 250;
        b.noise_random = (20, 0x9E37_79B9_7F4A_7C15);
        b.run_for(30_000_000);
        let c = b.link.counters();
        assert_eq!(c.losses, 0, "{baud}: {c:?}");
        assert!(c.crc_errors > 0, "{baud}: no noise met: {c:?}");
    }
}

/// The driver's given-speed resolution (0x2022) is read at start-up and
/// honoured: with 10 (0.1 r/min) a 20.0 r/min command is written as 200,
/// and the driver runs at 20 r/min, not 2. Before, 0x2022 was never read:
/// a driver set to 10 ran at a tenth of the command. The read-back (0x20AB,
/// always 0.1 r/min) is unaffected.
#[test]
fn the_speed_resolution_is_read_and_commands_follow_it() {
    for baud in [9600, 115_200] {
        for (resolution, raw) in [(1u16, 20i16), (10, 200), (4, 80)] {
            let mut b = Bench::new(baud);
            b.driver.own_motor = true;
            b.driver.resolution = resolution;
            b.link.control(ControlAction::Enable);
            b.link.set_speed_command(Some(20_000));
            b.run_for(1_500_000);
            assert_eq!(b.driver.command_raw, raw, "{baud}, resolution {resolution}");
            assert!((b.driver.target_rpm() - 20.0).abs() < 1e-9);
            assert_eq!(b.samples.last().unwrap().2, 20_000, "{baud}, {resolution}");
            assert!(!b.link.is_lost());
        }
    }
}

/// A resolution register the link cannot use (0, written by a harness or
/// a tool): the link refuses the driver with the reason, writes no speed
/// command, and takes it again once the register is corrected.
#[test]
fn an_unusable_resolution_is_refused_with_its_reason() {
    let mut b = Bench::new(115_200);
    b.driver.resolution = 0;
    b.link.control(ControlAction::Enable);
    b.link.set_speed_command(Some(20_000));
    b.run_for(300_000);
    assert_eq!(
        b.link.loss_cause(),
        Some(LossCause::Setup(SetupFault::Resolution(0)))
    );
    assert!(!b.driver.writes.iter().any(|w| w.0 == 0x2088));
    b.driver.resolution = 10;
    b.run_for(300_000);
    assert!(b.events.iter().any(|(_, e)| *e == Event::Restored));
    assert!(b.link.acknowledge());
    assert_eq!(b.driver.command_raw, 200);
}

/// The driver's maximum motor speed (0x2008, ≤ 1000 r/min) is read and
/// the drum's top speed (44.7 r/min) must fit under it through the
/// gearbox: behind 59:1 the drum needs 2638 motor r/min, and the link
/// refuses the driver by name instead of letting it limit the motor
/// silently (it ran at 0.64 of the command before). Behind 20:1 (894 r/min)
/// it works, and is refused when the driver comes back from a power cut
/// with 0x2008 set to 800 (the set-up is read again after every loss).
#[test]
fn a_gearbox_beyond_the_drivers_maximum_speed_is_refused() {
    let geared = |ratio: i32| DriverProfile {
        micro_rpm_per_count: 100_000 / ratio,
        speed_command: Some((0x2088, 1_000_000 / ratio)),
        ..ZLAC8015D
    };
    let mut b = Bench::new(115_200);
    b.link = Link::new(geared(59), LinkConfig::for_baud(115_200).unwrap());
    b.link.set_speed_command(Some(20_000));
    b.run_for(300_000);
    // 44.7 r/min × 59 = 2637.3 → 2638 counts of 1 r/min (16 949 µr/min each).
    assert_eq!(
        b.link.loss_cause(),
        Some(LossCause::Setup(SetupFault::MaxSpeed {
            driver: 1000,
            needed: 2638
        }))
    );
    assert!(!b.driver.writes.iter().any(|w| w.0 == 0x2088));
    let mut b = Bench::new(115_200);
    b.link = Link::new(geared(20), LinkConfig::for_baud(115_200).unwrap());
    b.link.set_speed_command(Some(20_000));
    b.run_for(300_000);
    assert_eq!(b.link.loss_cause(), None);
    assert_eq!(b.driver.command_raw, 400);
    b.driver.inject.silent = true;
    b.run_for(500_000);
    b.driver.max_rpm = 800;
    b.driver.inject.silent = false;
    b.run_for(500_000);
    assert_eq!(
        b.link.loss_cause(),
        Some(LossCause::Setup(SetupFault::MaxSpeed {
            driver: 800,
            needed: 894
        }))
    );
}

/// The driver's offline time (0x2000) is written from the link's setting
/// at start-up and again after a loss: a driver left silent that long
/// stops its motor on its own.
#[test]
fn the_offline_time_is_written_from_the_setting() {
    let mut b = Bench::new(9600);
    let timing = LinkTiming {
        offline_time_ms: 700,
        ..LinkTiming::DEFAULT
    };
    b.link = Link::new(ZLAC8015D, LinkConfig::new(9600, timing).unwrap());
    b.run_for(300_000);
    assert_eq!(b.driver.offline_ms, 700);
    // Power-cycled (back to its default) while the link is cut: written
    // again when it answers.
    b.driver.inject.silent = true;
    b.run_for(1_000_000);
    b.driver.offline_ms = 1000;
    b.driver.inject.silent = false;
    b.run_for(500_000);
    assert_eq!(b.driver.offline_ms, 700);
    assert!(
        b.driver
            .writes
            .iter()
            .filter(|w| **w == (0x2000, 700))
            .count()
            >= 2
    );
}

/// A speed command write that fails is sent again with the newest command,
/// not the one it carried: a retry of a stale speed (the command changes
/// every control period) would leave the driver a transaction behind, and
/// after a stop the last speed before it. Before, the retry re-sent the
/// old value (seen against the independent peer: a CRC error on a command
/// write's echo, then the old command written again).
#[test]
fn a_failed_command_write_is_sent_again_with_the_newest_command() {
    for baud in [9600, 115_200] {
        let mut b = Bench::new(baud);
        b.link.control(ControlAction::Enable);
        b.link.set_speed_command(Some(20_000));
        b.run_for(300_000);
        // Wait for a command write on the line, then lose its reply.
        b.link.set_speed_command(Some(21_000));
        while b.last_request.get(1..4) != Some(&[0x06, 0x20, 0x88]) {
            b.run_for(STEP_US);
        }
        b.driver.inject.silent = true;
        b.link.set_speed_command(Some(25_000));
        b.run_for(frame_time_us(baud, 8).unwrap().into());
        b.driver.inject.silent = false;
        let before = b.driver.writes.len();
        b.run_for(300_000);
        let commands: Vec<u16> = b.driver.writes[before..]
            .iter()
            .filter(|w| w.0 == 0x2088)
            .map(|w| w.1)
            .collect();
        assert_eq!(commands.first(), Some(&25), "{baud}: {commands:?}");
        assert_eq!(b.link.counters().losses, 0);
    }
}
