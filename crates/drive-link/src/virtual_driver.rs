//! A simulated ZLAC8015D on the host (tests and tools): answers function 03
//! and 06 on its registers, follows its speed command with a first-order
//! motor, and misbehaves on request (faults, CRC errors, late replies,
//! silence).
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
    /// The last speed command, r/min (signed).
    pub command_rpm: i16,
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
            command_rpm: 0,
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
    /// First-order motor (τ = 100 ms) toward the command when enabled and
    /// in velocity mode, toward 0 otherwise; a fault stops it.
    pub fn advance(&mut self, dt_us: u32) {
        if !self.own_motor {
            return;
        }
        let target = if self.enabled && self.velocity_mode && self.fault_bits == 0 {
            f64::from(self.command_rpm) * 10.0
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
                        0x2088 => self.command_rpm as u16,
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
                match (reg, arg) {
                    (0x200E, 0x08) => self.enabled = true,
                    (0x200E, 0x07) => self.enabled = false,
                    (0x200E, 0x06) => self.fault_bits = 0,
                    (0x200D, 3) => self.velocity_mode = true,
                    (0x2088, v) => self.command_rpm = v as i16,
                    _ => {
                        return Some((
                            with_crc(std::vec![self.slave, 0x86, 0x03]),
                            self.turnaround_us,
                        ))
                    }
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
