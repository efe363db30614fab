//! The QEMU board's side of the host's virtual drum driver: the truth
//! record of each control period to the host, and the driver's replies and
//! state from the lock-step gate.

use super::clocks::now_us;
use super::rs485::{DriveFrame, DRIVE_FRAME_MAX};
use super::sh;

/// Most request end times one truth record carries.
const TRUTH_MAX_FRAMES: usize = 3;

/// The QEMU board's side of the host's virtual drum driver.
pub(super) struct DriveSim {
    /// The truth FIFO (semihosting handle).
    pub(super) truth: usize,
    /// Replies from the gate, to [`DriveLine`](super::DriveLine).
    pub(super) rx_in: heapless::spsc::Producer<'static, DriveFrame>,
    /// Request end times from [`DriveLine`](super::DriveLine).
    pub(super) tx_ends: heapless::spsc::Consumer<'static, u32>,
    /// The driver's state from the last gate record: bit 0 its motor is
    /// enabled (control word, no fault), bit 1 it runs on its bus speed
    /// command (velocity mode, a command received) rather than the PWM.
    pub(super) flags: u8,
    /// Its bus speed command, drum milli-r/min.
    pub(super) command_milli_rpm: i32,
}

/// [`DriveSim::flags`]: the driver's motor is enabled.
pub(super) const DRIVE_ENABLED: u8 = 1;

/// [`DriveSim::flags`]: the driver follows its bus speed command.
pub(super) const DRIVE_BUS_COMMAND: u8 = 2;

/// The truth record of a control period, to the host's virtual driver:
/// the firmware time (µs, u32), the true drum speed (milli-r/min, i32),
/// then how many requests ended
/// since the last record and each one's end (firmware µs, u32); all little
/// endian. Written before the gate is read, so that the host, having read
/// it, knows the period before has ended and its requests are on USART2.
pub(super) fn write_truth(d: &mut DriveSim, drum_rpm: f32) {
    const HEAD: usize = 9;
    let mut rec = [0u8; HEAD + 4 * TRUTH_MAX_FRAMES];
    let milli = (drum_rpm * 1000.0) as i32;
    let mut n = 0usize;
    if let Some(dst) = rec.get_mut(..4) {
        dst.copy_from_slice(&now_us().to_le_bytes());
    }
    if let Some(dst) = rec.get_mut(4..8) {
        dst.copy_from_slice(&milli.to_le_bytes());
    }
    while n < TRUTH_MAX_FRAMES {
        let Some(end) = d.tx_ends.dequeue() else {
            break;
        };
        if let Some(dst) = rec.get_mut(HEAD + 4 * n..HEAD + 4 + 4 * n) {
            dst.copy_from_slice(&end.to_le_bytes());
        }
        n += 1;
    }
    if let Some(c) = rec.get_mut(8) {
        *c = n as u8;
    }
    let _ = sh::write(d.truth, rec.get(..HEAD + 4 * n).unwrap_or(&[]));
}

/// The virtual driver's part of a gate record: a count (≤ 3) of reply
/// frames, each with the firmware time its last byte arrives (µs, u32),
/// its length and bytes; then the driver's flags and bus speed command
/// (drum milli-r/min, i32). False when the host's end is gone.
pub(super) fn read_drive(h: usize, d: &mut DriveSim) -> bool {
    let mut count = [0u8; 1];
    if !sh::read(h, &mut count) {
        return false;
    }
    for _ in 0..count[0].min(3) {
        let mut head = [0u8; 5];
        if !sh::read(h, &mut head) {
            return false;
        }
        let [e0, e1, e2, e3, len] = head;
        let mut f = DriveFrame {
            end_us: u32::from_le_bytes([e0, e1, e2, e3]),
            len: len.min(DRIVE_FRAME_MAX as u8),
            bytes: [0; DRIVE_FRAME_MAX],
        };
        let n = usize::from(f.len);
        if n > 0 && !f.bytes.get_mut(..n).is_some_and(|b| sh::read(h, b)) {
            return false;
        }
        let _ = d.rx_in.enqueue(f);
    }
    let mut tail = [0u8; 5];
    if !sh::read(h, &mut tail) {
        return false;
    }
    let [flags, c0, c1, c2, c3] = tail;
    d.flags = flags;
    d.command_milli_rpm = i32::from_le_bytes([c0, c1, c2, c3]);
    true
}
