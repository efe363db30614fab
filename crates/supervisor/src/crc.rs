//! CRC-32/ISO-HDLC (the zlib, Ethernet and PNG CRC), small and incremental.
//!
//! Parameters: polynomial `0x04C11DB7` (processed reflected, `0xEDB88320`),
//! initial value `0xFFFFFFFF`, input and output reflected, final XOR
//! `0xFFFFFFFF`; check value `CRC(b"123456789") = 0xCBF43926`.
//!
//! The implementation uses a 16-entry nibble table (64 bytes of flash, two
//! lookups per byte) rather than the usual 1 KB byte table: the firmware has a
//! 32 KB budget and checks one ~230-byte record at boot and on save, so speed
//! does not matter.
//!
//! ```
//! use supervisor::crc::{crc32, Crc32};
//! // The catalogue check value of CRC-32/ISO-HDLC.
//! assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
//! // Incremental updates give the same result as one pass.
//! let c = Crc32::new().update(b"1234").update(b"56789").finish();
//! assert_eq!(c, 0xCBF4_3926);
//! ```

/// `NIBBLE[n]` is the CRC register after shifting the 4-bit value `n` through
/// the reflected polynomial `0xEDB88320` four times (a unit test recomputes
/// every entry bit by bit).
const NIBBLE: [u32; 16] = [
    0x0000_0000,
    0x1DB7_1064,
    0x3B6E_20C8,
    0x26D9_30AC,
    0x76DC_4190,
    0x6B6B_51F4,
    0x4DB2_6158,
    0x5005_713C,
    0xEDB8_8320,
    0xF00F_9344,
    0xD6D6_A3E8,
    0xCB61_B38C,
    0x9B64_C2B0,
    0x86D3_D2D4,
    0xA00A_E278,
    0xBDBD_F21C,
];

/// One nibble step: shift the low 4 bits of `crc` out through the table.
#[inline]
fn step(crc: u32) -> u32 {
    let [low, ..] = crc.to_le_bytes();
    let t = NIBBLE.get(usize::from(low & 0x0F)).copied().unwrap_or(0);
    (crc >> 4) ^ t
}

/// An incremental CRC-32/ISO-HDLC computation.
///
/// `Crc32::new().update(a).update(b).finish() == crc32(a ++ b)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Crc32 {
    /// The (non-inverted) shift register.
    state: u32,
}

impl Crc32 {
    /// A fresh computation (register `0xFFFFFFFF`).
    #[must_use]
    pub const fn new() -> Self {
        Self { state: 0xFFFF_FFFF }
    }

    /// Feeds `bytes`.
    #[must_use]
    pub fn update(mut self, bytes: &[u8]) -> Self {
        for &b in bytes {
            let c = self.state ^ u32::from(b);
            self.state = step(step(c));
        }
        self
    }

    /// The CRC of everything fed so far (the computation can continue).
    #[must_use]
    pub const fn finish(self) -> u32 {
        !self.state
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

/// CRC-32/ISO-HDLC of `bytes` in one call.
#[must_use]
pub fn crc32(bytes: &[u8]) -> u32 {
    Crc32::new().update(bytes).finish()
}

#[cfg(test)]
#[allow(clippy::arithmetic_side_effects, clippy::cast_possible_truncation)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::vec::Vec;

    /// Independent reference: the textbook bit-at-a-time reflected CRC-32.
    fn reference(bytes: &[u8]) -> u32 {
        let mut crc = 0xFFFF_FFFFu32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn nibble_table_matches_bitwise_construction() {
        for (n, &entry) in NIBBLE.iter().enumerate() {
            let mut c = n as u32;
            for _ in 0..4 {
                c = if c & 1 == 1 {
                    (c >> 1) ^ 0xEDB8_8320
                } else {
                    c >> 1
                };
            }
            assert_eq!(entry, c, "entry {n}");
        }
    }

    #[test]
    fn check_value() {
        // Catalogue of parametrised CRC algorithms (reveng), CRC-32/ISO-HDLC:
        // check = 0xcbf43926.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(reference(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn known_vectors() {
        // Empty input: init and xorout cancel.
        assert_eq!(crc32(b""), 0);
        // zlib.crc32(b"a") == 0xe8b7be43 and
        // zlib.crc32(b"The quick brown fox jumps over the lazy dog") == 0x414fa339.
        assert_eq!(crc32(b"a"), 0xE8B7_BE43);
        assert_eq!(
            crc32(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
    }

    proptest! {
        #[test]
        fn matches_bitwise_reference(data in proptest::collection::vec(any::<u8>(), 0..300)) {
            prop_assert_eq!(crc32(&data), reference(&data));
        }

        #[test]
        fn incremental_equals_one_shot(
            data in proptest::collection::vec(any::<u8>(), 0..300),
            cut in any::<proptest::sample::Index>(),
        ) {
            let at = cut.index(data.len() + 1);
            let (a, b) = data.split_at(at);
            let inc = Crc32::new().update(a).update(b).finish();
            let whole: Vec<u8> = data.clone();
            prop_assert_eq!(inc, crc32(&whole));
        }
    }
}
