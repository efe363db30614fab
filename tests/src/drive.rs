//! The host's virtual drum driver on the QEMU board's USART2
//! (docs/drive-link.md, "QEMU").
//!
//! The firmware's requests leave through the emulated USART2 (a TCP
//! chardev, the second `-serial`); the replies come back through the
//! lock-step gate, each with the firmware time its last byte arrives, so
//! that the link's timing is deterministic whatever the host's load. Once
//! a control period the QEMU board writes a *truth record* into a second
//! FIFO (the gate's path with a `t`): the firmware time, the simulated
//! drum's true speed and the end times of the requests sent since the last
//! record. Reading it tells this side that the period before has ended and
//! its requests are all on USART2.
//!
//! The driver is [`drive_link::virtual_driver::VirtualZlac`] (the
//! ZLAC8015D's registers) behind a 20:1 gearbox ([`GEAR_RATIO`]): its speed
//! register reads the simulated drum's speed × 20 in 0.1 r/min, sampled
//! at the request's end plus its turnaround (interpolated between the
//! truth records around it, never ahead of the newest); its target speed
//! (motor r/min, at its speed resolution, limited to its maximum speed)
//! ÷ 20 drives the simulated drum when it is enabled and in velocity mode;
//! the board applies it as the drive's speed loop (the command over the
//! drive's n_max, through the simulated motor's lag).

use std::collections::VecDeque;
use std::io::{self, Read};
use std::net::TcpStream;

use drive_link::timing::frame_time_us;
use drive_link::virtual_driver::VirtualZlac;

/// The virtual driver's motor turns per drum turn: 20:1, not paper A's
/// 118:1, whose motor speed overflows the ZLAC8015D's 0.1 r/min register
/// above 27.77 drum r/min, and whose motor would need more than the
/// driver's 1000 r/min (0x2008) for the drum's 44.7 (docs/drive-link.md,
/// "Limits"). The settings' scale for it: 100 000 / 20 = 5000 µr/min per
/// count.
pub const GEAR_RATIO: f64 = 20.0;

/// One control period's truth record from the QEMU board.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    /// Firmware time at the start of the period, µs.
    pub now_us: u32,
    /// The simulated drum's true speed, milli-r/min.
    pub drum_milli_rpm: i32,
    /// End times of the requests sent since the last record, µs.
    pub request_ends_us: Vec<u32>,
}

/// Parses truth records from a byte stream (9-byte head, then 4 bytes per
/// request end).
pub fn read_truth(r: &mut impl Read) -> io::Result<Truth> {
    let mut head = [0u8; 9];
    r.read_exact(&mut head)?;
    let n = usize::from(head[8]);
    let mut ends = vec![0u8; 4 * n];
    r.read_exact(&mut ends)?;
    Ok(Truth {
        now_us: u32::from_le_bytes([head[0], head[1], head[2], head[3]]),
        drum_milli_rpm: i32::from_le_bytes([head[4], head[5], head[6], head[7]]),
        request_ends_us: ends
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
    })
}

/// One transaction as the virtual driver saw it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Transaction {
    /// The request's end, firmware µs.
    pub request_end_us: u32,
    /// Function code (3 read, 6 write).
    pub function: u8,
    /// Register.
    pub register: u16,
    /// When the reply's last byte arrives, firmware µs (none: no reply).
    pub reply_end_us: Option<u32>,
}

/// The virtual driver and its line.
pub struct DriveBench {
    /// The driver: tests change its `inject` and `fault_bits` between pumps.
    pub driver: VirtualZlac,
    /// The line's speed (the firmware's settings must name the same).
    pub baud: u32,
    usart2: TcpStream,
    rx: Vec<u8>,
    prev: Option<(u32, i32)>,
    pending: VecDeque<(u32, Vec<u8>)>,
    /// Every request seen, in order.
    pub log: Vec<Transaction>,
    /// Requests whose end time was missing from the truth records (would
    /// mean the harness lost sync; a test can assert it stays 0).
    pub unmatched: u32,
    /// Firmware time of the newest truth record, µs (the start of the
    /// period the firmware runs next).
    pub now_us: u32,
    command_seen: bool,
}

/// Most reply frames one gate record carries (the QEMU board's queue).
const FRAMES_PER_RECORD: usize = 3;

impl DriveBench {
    /// A driver (slave 1, the ZLAC8015D's registers) at `baud` on `usart2`.
    pub fn new(usart2: TcpStream, baud: u32) -> io::Result<Self> {
        usart2.set_nonblocking(true)?;
        Ok(Self {
            driver: VirtualZlac::default(),
            baud,
            usart2,
            rx: Vec::new(),
            prev: None,
            pending: VecDeque::new(),
            log: Vec::new(),
            unmatched: 0,
            now_us: 0,
            command_seen: false,
        })
    }

    /// The drum speed at firmware time `t_us`, milli-r/min: linear between
    /// the previous truth record and `truth`, held at the ends.
    fn drum_at(&self, truth: &Truth, t_us: u32) -> f64 {
        let now = (truth.now_us, truth.drum_milli_rpm);
        let (t0, v0) = self.prev.unwrap_or(now);
        let (t1, v1) = now;
        if t1 <= t0 || t_us >= t1 {
            return f64::from(v1);
        }
        if t_us <= t0 {
            return f64::from(v0);
        }
        let f = f64::from(t_us - t0) / f64::from(t1 - t0);
        f64::from(v0) + (f64::from(v1) - f64::from(v0)) * f
    }

    /// One control period: takes the requests of the period that ended,
    /// answers them, and returns the driver's part of the next gate record.
    pub fn period(&mut self, truth: &Truth) -> io::Result<Vec<u8>> {
        let mut chunk = [0u8; 256];
        // The truth record announces the requests that ended in the period:
        // their bytes are on their way through QEMU's serial socket, and on
        // a busy host they may not be readable yet. Wait for them (in host
        // time, a guard only: firmware time does not move meanwhile), so a
        // loaded host never drops a request.
        let expected = 8 * truth.request_ends_us.len();
        let guard = std::time::Instant::now() + std::time::Duration::from_secs(60);
        loop {
            match self.usart2.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => self.rx.extend_from_slice(&chunk[..n]),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    if self.rx.len() >= expected {
                        break;
                    }
                    if std::time::Instant::now() > guard {
                        return Err(io::Error::other(format!(
                            "USART2: {} of the {expected} request bytes the firmware sent",
                            self.rx.len()
                        )));
                    }
                    std::thread::sleep(std::time::Duration::from_micros(50));
                }
                Err(e) => return Err(e),
            }
        }
        // Requests of this master are 8 bytes (functions 03 and 06).
        let mut ends = truth.request_ends_us.iter();
        while self.rx.len() >= 8 {
            let request: Vec<u8> = self.rx.drain(..8).collect();
            let Some(&end) = ends.next() else {
                self.unmatched += 1;
                continue;
            };
            let sample_at = end.wrapping_add(self.driver.turnaround_us);
            let motor_decirpm = self.drum_at(truth, sample_at) / 1000.0 * GEAR_RATIO * 10.0;
            self.driver.actual_decirpm = motor_decirpm
                .round()
                .clamp(f64::from(i16::MIN), f64::from(i16::MAX))
                as i16;
            let reply = self.driver.handle(&request);
            if request.get(1) == Some(&0x06) && request.get(2..4) == Some(&[0x20, 0x88]) {
                self.command_seen = true;
            }
            let reply_end = reply.map(|(frame, delay)| {
                // The master sees the frame end after 3.5 characters of
                // silence (the real board's frame-end timer).
                let on_line = frame_time_us(self.baud, frame.len() as u32).unwrap_or(0);
                let silence = drive_link::timing::silent_interval_us(self.baud).unwrap_or(0);
                let due = end
                    .wrapping_add(delay)
                    .wrapping_add(on_line)
                    .wrapping_add(silence);
                self.pending.push_back((due, frame));
                due
            });
            self.log.push(Transaction {
                request_end_us: end,
                function: request[1],
                register: u16::from_be_bytes([request[2], request[3]]),
                reply_end_us: reply_end,
            });
        }
        self.unmatched += ends.count() as u32;
        self.prev = Some((truth.now_us, truth.drum_milli_rpm));
        self.now_us = truth.now_us;
        // The gate record's driver part: frames, then flags and command.
        let n = self.pending.len().min(FRAMES_PER_RECORD);
        let mut out = vec![n as u8];
        for (due, frame) in self.pending.drain(..n) {
            out.extend_from_slice(&due.to_le_bytes());
            out.push(frame.len() as u8);
            out.extend_from_slice(&frame);
        }
        let d = &self.driver;
        let enabled = d.enabled && d.fault_bits == 0;
        let bus = d.velocity_mode && self.command_seen;
        out.push(u8::from(enabled) | (u8::from(bus) << 1));
        let command_milli = (d.target_rpm() * 1000.0 / GEAR_RATIO).round() as i32;
        out.extend_from_slice(&command_milli.to_le_bytes());
        Ok(out)
    }

    /// Poll period of the speed reads, µs: the mean interval between
    /// consecutive speed-register requests in `from_us..to_us`.
    pub fn speed_poll_period_us(&self, from_us: u32, to_us: u32) -> Option<f64> {
        let t: Vec<u32> = self
            .log
            .iter()
            .filter(|x| x.function == 3 && x.register == 0x20AB)
            .map(|x| x.request_end_us)
            .filter(|&t| t >= from_us && t <= to_us)
            .collect();
        (t.len() >= 2).then(|| f64::from(t[t.len() - 1] - t[0]) / (t.len() - 1) as f64)
    }
}
