//! A bounds-checked write cursor over the caller's buffer (internal).

/// The three bytes that end every instruction and every return frame.
pub const TERMINATOR: [u8; 3] = [0xFF, 0xFF, 0xFF];

/// The buffer is full: the write did not fit (the encoder's
/// `EncodeError::BufferTooSmall`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct BufferFull;

/// Writes bytes into a borrowed buffer; every write is checked, nothing panics.
pub(crate) struct Cursor<'b> {
    buf: &'b mut [u8],
    pos: usize,
}

impl<'b> Cursor<'b> {
    pub(crate) fn new(buf: &'b mut [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    /// Bytes written so far.
    pub(crate) fn len(&self) -> usize {
        self.pos
    }

    // Out of line: inlined at each of the encoder's ≈ 25 writes it cost
    // ≈ 400 B of flash (docs/hmi.md, "Flash").
    #[inline(never)]
    pub(crate) fn put(&mut self, bytes: &[u8]) -> Result<(), BufferFull> {
        let end = self.pos.checked_add(bytes.len()).ok_or(BufferFull)?;
        let dst = self.buf.get_mut(self.pos..end).ok_or(BufferFull)?;
        dst.copy_from_slice(bytes);
        self.pos = end;
        Ok(())
    }

    pub(crate) fn byte(&mut self, b: u8) -> Result<(), BufferFull> {
        self.put(&[b])
    }

    /// Decimal ASCII, no leading zeros.
    pub(crate) fn u32(&mut self, mut n: u32) -> Result<(), BufferFull> {
        // Digits from the last place up, into the end of the buffer (a
        // `u32` has at most 10).
        let mut digits = [0u8; 10];
        let mut start = digits.len();
        while let Some(i) = start.checked_sub(1) {
            let d = u8::try_from(n.wrapping_rem(10)).unwrap_or(0);
            if let Some(slot) = digits.get_mut(i) {
                *slot = b'0'.wrapping_add(d);
            }
            start = i;
            n = n.wrapping_div(10);
            if n == 0 {
                break;
            }
        }
        self.put(digits.get(start..).ok_or(BufferFull)?)
    }

    /// Signed decimal ASCII (`-` then digits); handles `i32::MIN`.
    pub(crate) fn i32(&mut self, n: i32) -> Result<(), BufferFull> {
        if n < 0 {
            self.byte(b'-')?;
        }
        self.u32(n.unsigned_abs())
    }

    /// The Nextion terminator `0xFF 0xFF 0xFF`.
    pub(crate) fn terminator(&mut self) -> Result<(), BufferFull> {
        self.put(&TERMINATOR)
    }
}
