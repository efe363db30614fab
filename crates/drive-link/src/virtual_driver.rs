//! A simulated ZLAC8015D on the host (tests and tools): answers function 03
//! and 06 on its registers, follows its speed command with a first-order
//! motor, and misbehaves on request (faults, CRC errors, late replies,
//! silence).
//!
//! As ZLTECH's *RS485 Communication Instruction* V1.06 states: the target
//! speed 0x2088 counts 1/n r/min when the given-speed resolution 0x2022
//! holds n (1–10; 1: 1 r/min, 10: 0.1 r/min), and the motor runs at most at
//! the maximum speed 0x2008 (1–1000 r/min: a target above it is taken and
//! limited); the actual speed 0x20AB counts 0.1 r/min whatever 0x2022
//! holds; a fault disables the driver and latches until the control word's
//! clear (0x06), after which it needs an enable (0x08) again; an enable
//! takes effect only in velocity mode; the offline time 0x2000 (ms, 0: off)
//! disables a driver that has had no request for that long.
//!
//! Host-only test code (feature `std`): panics on its own bugs are fine here.
#![allow(
    clippy::arithmetic_side_effects,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

use std::vec::Vec;

use crate::profile::ZLAC8015D;
use crate::rtu::crc16;

/// Misbehaviour to inject.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Injection {
    /// Corrupt (flip one bit of) the next n replies.
    pub corrupt_replies: u32,
    /// Delay the next n replies by [`Injection::extra_delay_us`].
    pub late_replies: u32,
    /// The delay of a late reply on top of the turnaround (µs).
    pub extra_delay_us: u32,
    /// Answer nothing.
    pub silent: bool,
    /// Answer reads as a driver with 32-bit registers does: four bytes a
    /// register (the value sign-extended), a byte count twice the asked.
    pub wide_registers: bool,
}

/// The simulated driver.
#[derive(Debug, Clone)]
pub struct VirtualZlac {
    /// Slave id.
    pub slave: u8,
    /// Enabled by the control word.
    pub enabled: bool,
    /// Velocity mode selected (0x200D = 3).
    pub velocity_mode: bool,
    /// The target speed register 0x2088 as written (signed, 1/resolution
    /// r/min).
    pub command_raw: i16,
    /// The given-speed resolution 0x2022 (1–10, default 1).
    pub resolution: u16,
    /// The maximum motor speed 0x2008, r/min (1–1000, default 1000).
    pub max_rpm: u16,
    /// The offline time 0x2000, ms (0: off; default 1000).
    pub offline_ms: u16,
    /// Time since the last request to this driver, µs (for the offline
    /// time; advanced by [`VirtualZlac::advance`]).
    pub since_request_us: u64,
    /// The driver disabled itself because no request came within the
    /// offline time (cleared by the next enable).
    pub offline_stop: bool,
    /// The motor's actual speed, r/min ×10 (the feedback register): set it
    /// from a machine model, or let [`VirtualZlac::advance`] follow the
    /// command.
    pub actual_decirpm: i16,
    /// Fault bits (0x20A5).
    pub fault_bits: u16,
    /// What to do wrong.
    pub inject: Injection,
    /// Requests it answered.
    pub answered: u32,
    /// Every register write it took (function 06), in order.
    pub writes: Vec<(u16, u16)>,
    /// Requests it received with a bad CRC (ignored, as the spec says).
    pub bad_requests: u32,
    /// The driver's turnaround, µs.
    pub turnaround_us: u32,
    /// Whether [`VirtualZlac::advance`] moves the motor (false: the test
    /// sets `actual_decirpm` from its own machine model).
    pub own_motor: bool,
    /// The own motor's speed, r/min ×10, unrounded.
    motor: f64,
}

impl Default for VirtualZlac {
    fn default() -> Self {
        Self {
            slave: ZLAC8015D.slave,
            enabled: false,
            velocity_mode: false,
            command_raw: 0,
            resolution: 1,
            max_rpm: 1000,
            offline_ms: 1000,
            since_request_us: 0,
            offline_stop: false,
            actual_decirpm: 0,
            fault_bits: 0,
            inject: Injection::default(),
            answered: 0,
            writes: Vec::new(),
            bad_requests: 0,
            turnaround_us: 2_000,
            own_motor: false,
            motor: 0.0,
        }
    }
}

fn with_crc(mut body: Vec<u8>) -> Vec<u8> {
    let crc = crc16(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    body
}

impl VirtualZlac {
    /// The speed the motor is driven to, r/min: the target register over
    /// the resolution, limited to ± the maximum speed.
    #[must_use]
    pub fn target_rpm(&self) -> f64 {
        let max = f64::from(self.max_rpm);
        (f64::from(self.command_raw) / f64::from(self.resolution.max(1))).clamp(-max, max)
    }

    /// Whether the motor is driven: enabled, in velocity mode, no fault.
    #[must_use]
    pub fn running(&self) -> bool {
        self.enabled && self.velocity_mode && self.fault_bits == 0
    }

    /// Time passes: the offline time, and the first-order motor (τ =
    /// 100 ms) toward the target when running, toward 0 otherwise.
    pub fn advance(&mut self, dt_us: u32) {
        self.since_request_us = self.since_request_us.saturating_add(u64::from(dt_us));
        if self.offline_ms != 0
            && self.enabled
            && self.since_request_us > u64::from(self.offline_ms) * 1000
        {
            self.enabled = false;
            self.offline_stop = true;
        }
        if self.fault_bits != 0 {
            self.enabled = false;
        }
        if !self.own_motor {
            return;
        }
        let target = if self.running() {
            self.target_rpm() * 10.0
        } else {
            0.0
        };
        let k = 1.0 - (-f64::from(dt_us) / 100_000.0).exp();
        self.motor += (target - self.motor) * k;
        self.actual_decirpm = self.motor.round() as i16;
    }

    /// Handles one request frame; the reply frame and its delay (µs after
    /// the request's end), or `None` when it stays silent.
    pub fn handle(&mut self, request: &[u8]) -> Option<(Vec<u8>, u32)> {
        if request.len() < 4 {
            return None;
        }
        let (body, crc) = request.split_at(request.len() - 2);
        if crc16(body) != u16::from_le_bytes([crc[0], crc[1]]) {
            self.bad_requests += 1;
            return None;
        }
        if body[0] != self.slave || self.inject.silent {
            return None;
        }
        self.since_request_us = 0;
        if self.fault_bits != 0 {
            // A fault disables the driver at once and latches.
            self.enabled = false;
        }
        let f = body[1];
        let reg = u16::from_be_bytes([body[2], body[3]]);
        let arg = u16::from_be_bytes([body[4], body[5]]);
        let reply = match f {
            0x03 if (1..=2).contains(&arg) => {
                let width = if self.inject.wide_registers { 4 } else { 2 };
                let mut out = std::vec![self.slave, 0x03, (arg * width) as u8];
                for r in reg..reg + arg {
                    let v = match r {
                        0x20AB => self.actual_decirpm as u16,
                        0x20A5 => self.fault_bits,
                        0x200D => {
                            if self.velocity_mode {
                                3
                            } else {
                                0
                            }
                        }
                        0x2088 => self.command_raw as u16,
                        0x2000 => self.offline_ms,
                        0x2008 => self.max_rpm,
                        0x2022 => self.resolution,
                        _ => {
                            return Some((
                                with_crc(std::vec![self.slave, 0x83, 0x02]),
                                self.turnaround_us,
                            ))
                        }
                    };
                    if self.inject.wide_registers {
                        out.extend_from_slice(&(v as i16 as i32).to_be_bytes());
                    } else {
                        out.extend_from_slice(&v.to_be_bytes());
                    }
                }
                out
            }
            0x06 => {
                let refuse = |code: u8| {
                    Some((
                        with_crc(std::vec![self.slave, 0x86, code]),
                        self.turnaround_us,
                    ))
                };
                let limit = 3000 * i32::from(self.resolution);
                match (reg, arg) {
                    (0x200E, 0x08) => {
                        // Only in a mode and with no fault latched.
                        if self.velocity_mode && self.fault_bits == 0 {
                            self.enabled = true;
                            self.offline_stop = false;
                        }
                    }
                    (0x200E, 0x07) => self.enabled = false,
                    (0x200E, 0x06) => self.fault_bits = 0,
                    (0x200D, 3) => self.velocity_mode = true,
                    (0x2088, v) if i32::from(v as i16).abs() <= limit => {
                        self.command_raw = v as i16;
                    }
                    (0x2000, v) if v <= 32_767 => self.offline_ms = v,
                    (0x2008, v) if (1..=1000).contains(&v) => self.max_rpm = v,
                    (0x2022, v) if (1..=10).contains(&v) => self.resolution = v,
                    // A value outside the manual's range: "illegal data
                    // value"; a register it does not have: "illegal data
                    // address".
                    (0x200E | 0x200D | 0x2088 | 0x2000 | 0x2008 | 0x2022, _) => {
                        return refuse(0x03)
                    }
                    _ => return refuse(0x02),
                }
                self.writes.push((reg, arg));
                body.to_vec()
            }
            _ => std::vec![self.slave, f | 0x80, 0x01],
        };
        self.answered += 1;
        let mut frame = with_crc(reply);
        if self.inject.corrupt_replies > 0 {
            self.inject.corrupt_replies -= 1;
            frame[2] ^= 0x04;
        }
        let mut delay = self.turnaround_us;
        if self.inject.late_replies > 0 {
            self.inject.late_replies -= 1;
            delay += self.inject.extra_delay_us;
        }
        Some((frame, delay))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn write(d: &mut VirtualZlac, reg: u16, value: u16) -> Vec<u8> {
        let mut body = std::vec![1, 0x06];
        body.extend_from_slice(&reg.to_be_bytes());
        body.extend_from_slice(&value.to_be_bytes());
        d.handle(&with_crc(body)).unwrap().0
    }

    fn read(d: &mut VirtualZlac, reg: u16) -> u16 {
        let mut body = std::vec![1, 0x03];
        body.extend_from_slice(&reg.to_be_bytes());
        body.extend_from_slice(&[0, 1]);
        let r = d.handle(&with_crc(body)).unwrap().0;
        u16::from_be_bytes([r[3], r[4]])
    }

    /// As the manual (V1.06) states: 0x2022 = 10 makes the target count
    /// 0.1 r/min, the actual speed stays in 0.1 r/min; 0x2008 limits the
    /// motor (a target above it is taken and limited) and takes 1–1000
    /// only; 0x2022 takes 1–10; a target beyond ±3000 r/min is refused.
    #[test]
    fn honours_the_resolution_and_the_maximum_speed() {
        let mut d = VirtualZlac {
            own_motor: true,
            ..VirtualZlac::default()
        };
        assert_eq!((read(&mut d, 0x2022), read(&mut d, 0x2008)), (1, 1000));
        // No offline stop while the motor settles without requests.
        write(&mut d, 0x2000, 0);
        write(&mut d, 0x200D, 3);
        write(&mut d, 0x200E, 0x08);
        write(&mut d, 0x2022, 10);
        write(&mut d, 0x2088, 205);
        assert_eq!(d.target_rpm(), 20.5);
        for _ in 0..2000 {
            d.advance(1000);
        }
        // 20.5 r/min read back as 205 (0.1 r/min), whatever 0x2022 says.
        assert_eq!(read(&mut d, 0x20AB), 205);
        // A maximum of 15 r/min limits the motor; the target reads back.
        write(&mut d, 0x2008, 15);
        for _ in 0..2000 {
            d.advance(1000);
        }
        assert_eq!(read(&mut d, 0x20AB), 150);
        assert_eq!(read(&mut d, 0x2088), 205);
        // Out of range: exception 3 (illegal data value), nothing changes.
        for (reg, value) in [(0x2008, 1001), (0x2008, 0), (0x2022, 11), (0x2022, 0)] {
            let r = write(&mut d, reg, value);
            assert_eq!(&r[1..3], &[0x86, 0x03], "{reg:#x} = {value}");
        }
        // ±3000 r/min at 0.1 r/min is ±30 000.
        assert_eq!(&write(&mut d, 0x2088, 30_001)[1..3], &[0x86, 0x03]);
        assert_eq!(write(&mut d, 0x2088, (-30_000i16) as u16)[1], 0x06);
        assert_eq!((read(&mut d, 0x2022), read(&mut d, 0x2008)), (10, 15));
    }

    /// A fault disables the driver and latches until the clear (0x06),
    /// after which it needs an enable again; the offline time disables a
    /// driver that hears no request.
    #[test]
    fn faults_latch_and_the_offline_time_stops_the_driver() {
        let mut d = VirtualZlac::default();
        write(&mut d, 0x200E, 0x08);
        assert!(!d.enabled, "no enable outside velocity mode");
        write(&mut d, 0x200D, 3);
        write(&mut d, 0x200E, 0x08);
        assert!(d.enabled);
        d.fault_bits = 0x0800;
        d.advance(1000);
        assert!(!d.enabled);
        write(&mut d, 0x200E, 0x08);
        assert!(!d.enabled, "no enable with a fault latched");
        write(&mut d, 0x200E, 0x06);
        assert_eq!(d.fault_bits, 0);
        assert!(!d.enabled);
        write(&mut d, 0x200E, 0x08);
        assert!(d.enabled);
        write(&mut d, 0x2000, 300);
        d.advance(299_000);
        assert!(d.enabled);
        d.advance(2_000);
        assert!(!d.enabled && d.offline_stop);
    }
}
