//! CRC-32/ISO-HDLC (the zlib, Ethernet and PNG CRC) of the settings records,
//! computed by the [`crc`] crate.
//!
//! Parameters: polynomial `0x04C11DB7` (processed reflected, `0xEDB88320`),
//! initial value `0xFFFFFFFF`, input and output reflected, final XOR
//! `0xFFFFFFFF`; check value `CRC(b"123456789") = 0xCBF43926`.
//!
//! The crate's table-less implementation ([`crc::NoTable`], a bit at a time)
//! is used: no 1 KB table in flash, and the firmware checks one ~300-byte
//! record at boot and on save, so speed does not matter.
//!
//! ```
//! use supervisor::settings::crc::{crc32, Crc32};
//! // The catalogue check value of CRC-32/ISO-HDLC.
//! assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
//! // Incremental updates give the same result as one pass.
//! let c = Crc32::new().update(b"1234").update(b"56789").finish();
//! assert_eq!(c, 0xCBF4_3926);
//! ```

use crc::{Crc, Digest, NoTable, CRC_32_ISO_HDLC};

/// The algorithm, bit-at-a-time (no table in flash).
static CRC_32: Crc<u32, NoTable> = Crc::<u32, NoTable>::new(&CRC_32_ISO_HDLC);

/// An incremental CRC-32/ISO-HDLC computation.
///
/// `Crc32::new().update(a).update(b).finish() == crc32(a ++ b)`.
#[derive(Clone)]
pub struct Crc32 {
    /// The crate's running digest.
    digest: Digest<'static, u32, NoTable>,
}

impl Crc32 {
    /// A fresh computation.
    #[must_use]
    pub fn new() -> Self {
        Self {
            digest: CRC_32.digest(),
        }
    }

    /// Feeds `bytes`.
    #[must_use]
    pub fn update(mut self, bytes: &[u8]) -> Self {
        self.feed(bytes);
        self
    }

    /// Feeds `bytes` in place.
    pub fn feed(&mut self, bytes: &[u8]) {
        self.digest.update(bytes);
    }

    /// The CRC of everything fed so far.
    #[must_use]
    pub fn finish(self) -> u32 {
        self.digest.finalize()
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl core::fmt::Debug for Crc32 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Crc32")
            .field("so_far", &self.clone().finish())
            .finish()
    }
}

/// CRC-32/ISO-HDLC of `bytes` in one call.
#[must_use]
pub fn crc32(bytes: &[u8]) -> u32 {
    CRC_32.checksum(bytes)
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
