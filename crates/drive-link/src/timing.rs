//! Serial-line timing of Modbus RTU (Modbus over Serial Line V1.02, §2.5.1.1).
//!
//! One character is 11 bits on the line (start, 8 data, parity or a second
//! stop bit, stop; 8N1 drivers add a stop bit to keep 11, and those that do
//! not send 10 — the 11-bit figure is the longer, so the safe one). Frames
//! are separated by at least 3.5 characters of silence; above 19 200 baud the
//! spec fixes that interval at 1.75 ms.
//!
//! ```
//! use drive_link::timing::{char_time_us, silent_interval_us};
//! // 9600 baud: 11 bits / 9600 = 1145.8 µs a character, 3.5 × = 4010 µs.
//! assert_eq!(char_time_us(9600), Some(1146));
//! assert_eq!(silent_interval_us(9600), Some(4011));
//! // 115 200 baud: the fixed 1.75 ms.
//! assert_eq!(silent_interval_us(115_200), Some(1750));
//! ```

/// Bits a character takes on the line.
pub const BITS_PER_CHAR: u32 = 11;

/// The baud rates a profile may name.
pub const BAUD_RATES: [u32; 5] = [9600, 19_200, 38_400, 57_600, 115_200];

/// One character's time in µs, rounded up; `None` for a baud rate of 0.
#[must_use]
pub const fn char_time_us(baud: u32) -> Option<u32> {
    if baud == 0 {
        return None;
    }
    Some((BITS_PER_CHAR * 1_000_000).div_ceil(baud))
}

/// The 3.5-character silent interval in µs, rounded up (1750 µs above
/// 19 200 baud, §2.5.1.1).
#[must_use]
pub const fn silent_interval_us(baud: u32) -> Option<u32> {
    if baud == 0 {
        return None;
    }
    if baud > 19_200 {
        return Some(1750);
    }
    match baud.checked_mul(2) {
        Some(two_baud) => Some((7 * BITS_PER_CHAR * 1_000_000).div_ceil(two_baud)),
        None => None,
    }
}

/// Time on the line of a frame of `bytes` characters, in µs (rounded up);
/// `None` for a baud rate of 0 or a frame longer than 390 characters.
#[must_use]
pub const fn frame_time_us(baud: u32, bytes: u32) -> Option<u32> {
    if baud == 0 {
        return None;
    }
    match (BITS_PER_CHAR * 1_000_000).checked_mul(bytes) {
        Some(bits_us) => Some(bits_us.div_ceil(baud)),
        None => None,
    }
}
