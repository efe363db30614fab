//! The drive link against an independent Modbus RTU slave: the ZLAC8015D
//! of `tests/peers/zlac8015d` (pymodbus 3.16.1, written from ZLTECH's
//! RS485 Communication Instruction V1.06, not from this project's code), on
//! one end of a `socat` pty pair; the master (`drive_link::link::Link`, the
//! code the firmware's link task runs, with its timing) on the other end,
//! through a simulated RS-485 line in virtual time.
//!
//! A pty has no baud rate, no character time and no bus turnaround: the
//! line here supplies them. Every frame takes its time on the wire (11 bits
//! a character at the baud rate), a frame is handed to the master 3.5
//! characters after its last byte, the driver's answer time (the reply's
//! delay after the request's end) is the harness's, and the harness breaks
//! replies on purpose: CRC errors (one bit flipped), dropped replies, noise
//! bursts (8 random bytes as DE drops, then a gap, then the reply). Two
//! frames on the wire at once garble each other (counted: a master that
//! waits for a quiet line never collides). Everything is judged in
//! virtual time; the only real-time wait is for the peer's reply to a
//! request (a generous limit, so that a loaded host only slows the run).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap,
    clippy::indexing_slicing,
    missing_docs,
    dead_code
)]

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use drive_link::link::{Event, Link};
use drive_link::rtu::{crc16, MAX_FRAME};
use drive_link::timing::{frame_time_us, silent_interval_us};
use serde_json::{json, Value};

/// How long the peer may take, in real time, to answer a request or a
/// command before the run fails: generous (its replies take a few ms; a
/// loaded host only slows the run, never changes its result).
pub const REAL_LIMIT: Duration = Duration::from_secs(10);

/// The peer's directory in the workspace.
fn peer_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/peers/zlac8015d")
}

/// The independent slave and its pty pair.
pub struct Peer {
    socat: Child,
    slave: Child,
    ctl_in: ChildStdin,
    ctl_out: Receiver<String>,
    master: File,
    rx: Receiver<Vec<u8>>,
    pending: Vec<u8>,
    links: [PathBuf; 2],
    /// Requests the peer did not answer within [`REAL_LIMIT`].
    pub silences: u32,
}

static PEERS: AtomicU32 = AtomicU32::new(0);

impl Peer {
    /// Starts `socat` and the slave (`lag_ms`: the peer's first-order motor
    /// lag, 0 = the actual speed follows at once).
    pub fn start(lag_ms: u32) -> Self {
        let n = PEERS.fetch_add(1, Ordering::Relaxed);
        let base = std::env::temp_dir().join(format!("zlac-peer-{}-{n}", std::process::id()));
        let links = [base.with_extension("drive"), base.with_extension("master")];
        for l in &links {
            let _ = std::fs::remove_file(l);
        }
        let socat = Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", links[0].display()))
            .arg(format!("pty,raw,echo=0,link={}", links[1].display()))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("socat (apt-get install socat; cargo xtask installs it)");
        let started = Instant::now();
        while !links.iter().all(|l| l.exists()) {
            assert!(started.elapsed() < REAL_LIMIT, "socat made no pty pair");
            std::thread::sleep(Duration::from_millis(5));
        }
        let mut slave = Command::new("python3")
            .arg(peer_dir().join("slave.py"))
            .arg("--port")
            .arg(&links[0])
            .arg("--lag-ms")
            .arg(lag_ms.to_string())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("python3 with pymodbus 3.16.1 (cargo xtask installs it)");
        let ctl_in = slave.stdin.take().unwrap();
        let out = slave.stdout.take().unwrap();
        let (tx, ctl_out) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let master = OpenOptions::new()
            .read(true)
            .write(true)
            .open(&links[1])
            .unwrap();
        let mut reader = master.try_clone().unwrap();
        let (btx, rx) = channel();
        std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 || btx.send(buf[..n].to_vec()).is_err() {
                    break;
                }
            }
        });
        let mut peer = Self {
            socat,
            slave,
            ctl_in,
            ctl_out,
            master,
            rx,
            pending: Vec::new(),
            links,
            silences: 0,
        };
        let ready = peer.line();
        assert_eq!(
            ready["ready"],
            json!(true),
            "the peer's ready line: {ready}"
        );
        peer
    }

    fn line(&mut self) -> Value {
        match self.ctl_out.recv_timeout(REAL_LIMIT) {
            Ok(l) => serde_json::from_str(&l).unwrap(),
            Err(e) => panic!("the peer's control channel: {e:?}"),
        }
    }

    /// A control-channel command and its reply (which must say `ok`).
    pub fn cmd(&mut self, c: Value) -> Value {
        writeln!(self.ctl_in, "{c}").unwrap();
        self.ctl_in.flush().unwrap();
        let r = self.line();
        assert_eq!(r["ok"], json!(true), "{c} -> {r}");
        r
    }

    /// Writes a request and waits for the peer's whole reply frame (none
    /// within [`REAL_LIMIT`]: counted in [`Peer::silences`]).
    pub fn exchange(&mut self, request: &[u8]) -> Option<Vec<u8>> {
        self.master.write_all(request).unwrap();
        self.master.flush().unwrap();
        let deadline = Instant::now() + REAL_LIMIT;
        loop {
            let need = match self.pending.as_slice() {
                [_, f, ..] if f & 0x80 != 0 => Some(5),
                [_, 0x06, ..] => Some(8),
                [_, 0x03, n, ..] => Some(5 + usize::from(*n)),
                _ => None,
            };
            if let Some(n) = need.filter(|&n| self.pending.len() >= n) {
                let frame: Vec<u8> = self.pending.drain(..n).collect();
                return Some(frame);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(bytes) => self.pending.extend_from_slice(&bytes),
                Err(RecvTimeoutError::Timeout) => {
                    self.silences += 1;
                    self.pending.clear();
                    return None;
                }
                Err(RecvTimeoutError::Disconnected) => panic!("the pty closed"),
            }
        }
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = writeln!(self.ctl_in, "{}", json!({"cmd": "quit"}));
        let _ = self.ctl_in.flush();
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(2) {
            if let Ok(Some(_)) = self.slave.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = self.slave.kill();
        let _ = self.slave.wait();
        let _ = self.socat.kill();
        let _ = self.socat.wait();
        for l in &self.links {
            let _ = std::fs::remove_file(l);
        }
    }
}

/// What the harness does to the line, per reply (probabilities in parts
/// per 10 000, drawn from its own seeded generator).
#[derive(Clone, Copy, Debug, Default)]
pub struct Faults {
    /// The driver's answer time: from the request's last bit to the
    /// reply's first, µs.
    pub delay_us: u64,
    /// Replies with one bit flipped (a CRC error).
    pub crc: u32,
    /// Replies dropped.
    pub drop: u32,
    /// Replies preceded by a noise burst (8 random bytes from the
    /// request's end, then a gap of 3.5 characters + 0.2 to 10 ms).
    pub noise: u32,
}

/// A frame on the simulated wire.
struct OnWire {
    start: u64,
    end: u64,
    bytes: Vec<u8>,
    from_master: bool,
    garbled: bool,
    /// A request: the speed command the master had when it wrote it.
    command_milli: Option<i32>,
}

/// What the line counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LineStats {
    pub requests: u32,
    pub forwarded: u32,
    pub crc_injected: u32,
    pub dropped: u32,
    pub noise_bursts: u32,
    pub collisions: u32,
    pub exceptions: u32,
    /// Speed read-backs the master took, each checked against the reply.
    pub readbacks: u32,
    /// Speed commands written, each checked against the expected count.
    pub commands: u32,
    /// Read-backs checked against the peer's target (steady scenarios).
    pub readbacks_vs_target: u32,
}

/// The master and the peer on a simulated line.
pub struct Line {
    pub now: u64,
    pub baud: u32,
    pub link: Link,
    pub peer: Peer,
    pub faults: Faults,
    pub stats: LineStats,
    /// Events of the master, with their virtual time.
    pub events: Vec<(u64, Event)>,
    /// Mismatches found (a message each); a run must end with none.
    pub mismatches: Vec<String>,
    /// The drum speed the master was last told to command, milli-r/min.
    pub command_milli: Option<i32>,
    /// Motor turns per drum turn (the profile's gearbox).
    pub ratio: f64,
    /// The driver's speed resolution (0x2022) as set in the peer.
    pub resolution: u16,
    /// Check each read-back against the peer's acknowledged target (only
    /// with the peer's motor lag 0 and no faults: the actual speed is then
    /// the limited target).
    pub check_target: bool,
    wire: Vec<OnWire>,
    rng: u64,
    peer_clock_ms: u64,
    acked_target: i16,
    acked_enabled: bool,
}

/// The line's step, µs.
pub const STEP_US: u64 = 50;

impl Line {
    pub fn new(link: Link, baud: u32, peer: Peer, seed: u64) -> Self {
        Self {
            now: 0,
            baud,
            link,
            peer,
            faults: Faults::default(),
            stats: LineStats::default(),
            events: Vec::new(),
            mismatches: Vec::new(),
            command_milli: None,
            ratio: 20.0,
            resolution: 1,
            check_target: false,
            wire: Vec::new(),
            rng: seed | 1,
            peer_clock_ms: 0,
            acked_target: 0,
            acked_enabled: false,
        }
    }

    fn random(&mut self) -> u64 {
        let mut x = self.rng;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.rng = x;
        x
    }

    fn chance(&mut self, per_10000: u32) -> bool {
        per_10000 > 0 && self.random() % 10_000 < u64::from(per_10000)
    }

    /// The speed command, through the master (and remembered for checks).
    pub fn set_speed_command(&mut self, milli: Option<i32>) {
        self.command_milli = milli;
        self.link.set_speed_command(milli);
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
        if garbled {
            self.stats.collisions += 1;
        }
        self.wire.push(OnWire {
            start,
            end,
            bytes,
            from_master,
            garbled,
            command_milli: self.command_milli,
        });
    }

    /// The peer's virtual clock follows the line's (at least every 20 ms
    /// of it, and before each request).
    fn sync_clock(&mut self) {
        let ms = self.now / 1000;
        if ms >= self.peer_clock_ms + 20 {
            self.peer.cmd(json!({"cmd": "time", "ms": ms}));
            self.peer_clock_ms = ms;
        }
    }

    /// A request reached the driver's end of the line at `end`.
    fn deliver_request(&mut self, end: u64, request: Vec<u8>, command_milli: Option<i32>) {
        self.stats.forwarded += 1;
        self.sync_clock();
        // The expected speed command, by hand in f64: drum r/min × ratio ×
        // resolution, rounded half away from zero.
        if request[1] == 0x06 && request[2..4] == [0x20, 0x88] {
            let value = i16::from_be_bytes([request[4], request[5]]);
            if let Some(milli) = command_milli {
                let counts =
                    (f64::from(milli) / 1000.0 * self.ratio * f64::from(self.resolution)).round();
                self.stats.commands += 1;
                if f64::from(value) != counts {
                    self.mismatches.push(format!(
                        "t {end}: command {value} for {milli} mr/min, expected {counts}"
                    ));
                }
            }
        }
        let Some(reply) = self.peer.exchange(&request) else {
            return;
        };
        if reply[1] & 0x80 != 0 {
            self.stats.exceptions += 1;
        } else if reply[1] == 0x06 {
            let (reg, value) = (
                u16::from_be_bytes([reply[2], reply[3]]),
                u16::from_be_bytes([reply[4], reply[5]]),
            );
            match (reg, value) {
                (0x2088, v) => self.acked_target = v as i16,
                (0x200E, 0x08) => self.acked_enabled = true,
                (0x200E, 0x07) => self.acked_enabled = false,
                _ => {}
            }
        } else if self.check_target && request[2..4] == [0x20, 0xAB] && reply.len() == 7 {
            // Lag 0: the actual speed is the target over the resolution,
            // within ±1000 r/min, in 0.1 r/min.
            let raw = i16::from_be_bytes([reply[3], reply[4]]);
            let expected = if self.acked_enabled {
                (f64::from(self.acked_target) / f64::from(self.resolution)).clamp(-1000.0, 1000.0)
                    * 10.0
            } else {
                0.0
            };
            self.stats.readbacks_vs_target += 1;
            if f64::from(raw) != expected.round() {
                self.mismatches.push(format!(
                    "t {end}: the peer read back {raw}, its target says {expected}"
                ));
            }
        }
        let mut start = end + self.faults.delay_us;
        if self.chance(self.faults.drop) {
            self.stats.dropped += 1;
            return;
        }
        let mut reply = reply;
        if self.chance(self.faults.crc) {
            self.stats.crc_injected += 1;
            let bit = self.random() as usize % (reply.len() * 8);
            reply[bit / 8] ^= 1 << (bit % 8);
        }
        if self.chance(self.faults.noise) {
            self.stats.noise_bursts += 1;
            let noise: Vec<u8> = (0..8).map(|_| self.random() as u8).collect();
            let noise_end = end + u64::from(frame_time_us(self.baud, 8).unwrap());
            let t35 = u64::from(silent_interval_us(self.baud).unwrap());
            let gap = t35 + 200 + self.random() % 10_000;
            self.put(end, noise, false);
            start = start.max(noise_end + gap);
        }
        self.put(start, reply, false);
    }

    /// Runs the line for `us` of virtual time.
    pub fn run_for(&mut self, us: u64) {
        let stop = self.now + us;
        let t35 = u64::from(silent_interval_us(self.baud).unwrap());
        while self.now < stop {
            self.now += STEP_US;
            let now = self.now;
            let mut done = Vec::new();
            self.wire.retain(|w| {
                let due = if w.from_master { w.end } else { w.end + t35 };
                if due <= now {
                    done.push((
                        w.end,
                        w.bytes.clone(),
                        w.from_master,
                        w.garbled,
                        w.command_milli,
                    ));
                    false
                } else {
                    true
                }
            });
            done.sort_by_key(|d| d.0);
            for (end, bytes, from_master, garbled, command_milli) in done {
                if from_master {
                    self.link.sent(end);
                    // A garbled request is no request for the driver.
                    if !garbled {
                        self.deliver_request(end, bytes, command_milli);
                    }
                } else {
                    let mut heard = bytes.clone();
                    if garbled && heard.len() > 1 {
                        heard[1] ^= 0x55;
                    }
                    let before = self.link.speed();
                    if let Some(e) = self.link.received(now, &heard) {
                        self.events.push((now, e));
                    }
                    let after = self.link.speed();
                    if after != before {
                        if let Some(s) = after {
                            self.check_readback(&heard, s.drum_milli_rpm);
                        }
                    }
                }
            }
            if self.wire.iter().any(|w| !w.from_master && w.start <= now) {
                self.link.line_busy(now);
            }
            if let Some(e) = self.link.tick(now) {
                self.events.push((now, e));
            }
            let mut buf = [0u8; MAX_FRAME];
            if let Some(n) = self.link.next_frame(now, &mut buf) {
                self.stats.requests += 1;
                self.put(now, buf[..n].to_vec(), true);
            }
        }
    }

    /// A read-back the master took from `frame`: the drum speed is the
    /// register (0.1 r/min of the motor) over the gearbox, by hand.
    fn check_readback(&mut self, frame: &[u8], drum_milli: i32) {
        self.stats.readbacks += 1;
        let body = &frame[..frame.len() - 2];
        let crc_ok = frame.len() == 7
            && crc16(body).to_le_bytes() == [frame[frame.len() - 2], frame[frame.len() - 1]];
        if !crc_ok {
            self.mismatches.push(format!(
                "t {}: a read-back from a bad frame {frame:02x?}",
                self.now
            ));
            return;
        }
        let raw = i16::from_be_bytes([frame[3], frame[4]]);
        let expected = f64::from(raw) / 10.0 / self.ratio * 1000.0;
        if (f64::from(drum_milli) - expected).abs() > 0.5 {
            self.mismatches.push(format!(
                "t {}: read-back {drum_milli} mr/min from {raw}, expected {expected:.1}",
                self.now
            ));
        }
    }
}
