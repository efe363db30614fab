//! Byte stream from the touchscreen split into terminated frames.
//!
//! Every Nextion/TJC return frame ends with `0xFF 0xFF 0xFF`. This splitter is
//! the minimal framing the serial path needs; it keeps at most
//! [`MAX_FRAME`] payload bytes per frame and counts a longer one as one
//! over-long frame instead of stalling.

use heapless::Vec;

/// Longest payload kept per frame, terminator excluded.
pub const MAX_FRAME: usize = 24;

/// One frame without its terminator.
pub type Frame = Vec<u8, MAX_FRAME>;

/// Streaming frame splitter fed one byte at a time from the USART interrupt.
pub struct FrameSplitter {
    buf: Frame,
    ff_run: u8,
    overlong: bool,
}

/// What one byte completed.
pub enum Push {
    /// Nothing yet.
    Pending,
    /// A frame ended with this byte.
    Frame(Frame),
    /// A frame longer than [`MAX_FRAME`] ended with this byte; it was dropped.
    Overlong,
}

impl FrameSplitter {
    /// An empty splitter.
    pub const fn new() -> Self {
        Self {
            buf: Vec::new(),
            ff_run: 0,
            overlong: false,
        }
    }

    /// Takes one received byte.
    pub fn push(&mut self, byte: u8) -> Push {
        if byte == 0xFF {
            self.ff_run = self.ff_run.saturating_add(1);
            if self.ff_run == 3 {
                self.ff_run = 0;
                let overlong = core::mem::replace(&mut self.overlong, false);
                let frame = core::mem::take(&mut self.buf);
                return if overlong {
                    Push::Overlong
                } else {
                    Push::Frame(frame)
                };
            }
            return Push::Pending;
        }
        // 0xFF bytes that were not a terminator belong to the payload.
        for _ in 0..core::mem::take(&mut self.ff_run) {
            self.keep(0xFF);
        }
        self.keep(byte);
        Push::Pending
    }

    fn keep(&mut self, byte: u8) {
        if self.buf.push(byte).is_err() {
            self.overlong = true;
        }
    }
}
