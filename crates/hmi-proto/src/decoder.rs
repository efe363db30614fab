//! Streaming decoder of return frames (screen → MCU), one byte at a time.
//!
//! Framing rules (Nextion Instruction Set ch. 7): every frame is a header byte,
//! a payload and `0xFF 0xFF 0xFF`. All frames but `0x70` have a fixed payload
//! length given by the header, so they are parsed by length — a `0x71` number
//! or `0x67` coordinate may contain `0xFF` bytes. A `0x70` string ends at the
//! first `0xFF` and is bounded by [`MAX_STRING_LEN`].
//!
//! Resynchronisation:
//! * a stray `0xFF` between frames is dropped (counted);
//! * an unknown header, or a string longer than the bound, is dropped together
//!   with everything up to and including the next `0xFF 0xFF 0xFF`;
//! * a fixed-length frame whose terminator is wrong is dropped, and the byte
//!   that broke it is examined again as a possible header (so one lost byte
//!   costs one frame, not two).
//!
//! The decoder never allocates, never blocks and never panics; its state is a
//! fixed-size struct (see [`Decoder`]).

use core::fmt;

use crate::frame::{
    ErrorCode, Frame, Text, TouchEvent, HEADER_NUMBER, HEADER_PAGE, HEADER_STRING, HEADER_TOUCH,
    HEADER_XY_ASLEEP, HEADER_XY_AWAKE, MAX_STRING_LEN,
};

/// Why a frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// A byte that starts no known frame; skipped up to the next terminator.
    UnknownHeader(u8),
    /// A fixed-length frame not followed by `0xFF 0xFF 0xFF`.
    MissingTerminator {
        /// Header of the dropped frame.
        header: u8,
    },
    /// A `0x70` string longer than [`MAX_STRING_LEN`]; skipped up to the next terminator.
    StringTooLong,
    /// Right length and terminator but an impossible payload (e.g. touch event byte 7).
    Malformed {
        /// Header of the dropped frame.
        header: u8,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnknownHeader(h) => write!(f, "unknown frame header 0x{h:02X}"),
            Self::MissingTerminator { header } => {
                write!(f, "frame 0x{header:02X} without terminator")
            }
            Self::StringTooLong => write!(f, "string frame longer than {MAX_STRING_LEN} bytes"),
            Self::Malformed { header } => write!(f, "malformed frame 0x{header:02X}"),
        }
    }
}

/// Counters kept by the decoder (wrapping at `u32::MAX`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderStats {
    /// Frames decoded successfully.
    pub frames: u32,
    /// Frames dropped (each also reported once as a [`DecodeError`], except
    /// an unknown header found while reporting another error).
    pub dropped_frames: u32,
    /// Bytes that ended up in no decoded frame.
    pub dropped_bytes: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between frames.
    Idle,
    /// After a `0x00` header: `0xFF` → invalid instruction, else startup `00 00 00`.
    Zero,
    /// Fixed payload bytes still to come.
    Payload { left: u8 },
    /// Inside a `0x70` string.
    Str,
    /// `ff` terminator bytes seen.
    Term { ff: u8 },
    /// Dropping bytes until `0xFF 0xFF 0xFF`; `ff` seen so far.
    Skip { ff: u8 },
}

/// Fixed-length payloads are at most this long (`0x67`: 5 bytes).
const MAX_FIXED: usize = 5;

/// Streaming return-frame decoder.
///
/// Its size is fixed (≤ 80 bytes with [`MAX_STRING_LEN`] = 48, asserted by a
/// test); feed it
/// from the UART receive interrupt or from a byte queue.
///
/// ```
/// use hmi_proto::{Decoder, Frame, TouchEvent};
///
/// let mut dec = Decoder::new();
/// // Touch release of component 2 on page 1, then `get n0.val` answering -1.
/// let bytes = [0x65, 0x01, 0x02, 0x00, 0xFF, 0xFF, 0xFF,
///              0x71, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF];
/// let mut frames = bytes.iter().filter_map(|&b| dec.push(b));
/// assert_eq!(frames.next(), Some(Ok(Frame::Touch { page: 1, component: 2, event: TouchEvent::Release })));
/// assert_eq!(frames.next(), Some(Ok(Frame::Number(-1))));
/// assert_eq!(frames.next(), None);
/// ```
#[derive(Debug, Clone)]
pub struct Decoder {
    state: State,
    header: u8,
    fixed_len: u8,
    fixed: [u8; MAX_FIXED],
    text: Text,
    /// Bytes of the frame in progress (for drop accounting).
    frame_bytes: u16,
    stats: DecoderStats,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

enum Kind {
    Fixed(u8),
    Zero,
    Str,
}

fn kind_of(header: u8) -> Option<Kind> {
    Some(match header {
        0x00 => Kind::Zero,
        0x01 | 0x86 | 0x87 | 0x88 | 0x89 | 0xFD | 0xFE => Kind::Fixed(0),
        HEADER_TOUCH => Kind::Fixed(3),
        HEADER_PAGE => Kind::Fixed(1),
        HEADER_XY_AWAKE | HEADER_XY_ASLEEP => Kind::Fixed(5),
        HEADER_STRING => Kind::Str,
        HEADER_NUMBER => Kind::Fixed(4),
        h if ErrorCode::from_byte(h).is_some() => Kind::Fixed(0),
        _ => return None,
    })
}

impl Decoder {
    /// A decoder waiting for the first frame.
    pub const fn new() -> Self {
        Self {
            state: State::Idle,
            header: 0,
            fixed_len: 0,
            fixed: [0; MAX_FIXED],
            text: Text(heapless::Vec::new()),
            frame_bytes: 0,
            stats: DecoderStats {
                frames: 0,
                dropped_frames: 0,
                dropped_bytes: 0,
            },
        }
    }

    /// Counters since construction.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// `true` between frames (nothing partial buffered).
    pub fn is_idle(&self) -> bool {
        self.state == State::Idle
    }

    /// Forgets any partial frame (counted as dropped); counters are kept.
    pub fn reset(&mut self) {
        if self.state != State::Idle {
            self.drop_frame();
        }
        self.state = State::Idle;
    }

    /// Feeds a slice; `f` is called for every result, in order.
    pub fn push_slice(&mut self, bytes: &[u8], mut f: impl FnMut(Result<Frame, DecodeError>)) {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                f(r);
            }
        }
    }

    /// Feeds one byte; returns a frame or an error when one ends with this byte.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, DecodeError>> {
        match self.state {
            State::Idle => self.start(byte).map(Err),
            State::Zero => {
                self.frame_bytes = self.frame_bytes.saturating_add(1);
                if byte == 0xFF {
                    self.state = State::Term { ff: 1 };
                } else {
                    self.store_fixed(byte);
                    self.state = State::Payload { left: 1 };
                }
                None
            }
            State::Payload { left } => {
                self.frame_bytes = self.frame_bytes.saturating_add(1);
                self.store_fixed(byte);
                let left = left.saturating_sub(1);
                self.state = if left == 0 {
                    State::Term { ff: 0 }
                } else {
                    State::Payload { left }
                };
                None
            }
            State::Str => {
                self.frame_bytes = self.frame_bytes.saturating_add(1);
                if byte == 0xFF {
                    self.state = State::Term { ff: 1 };
                    None
                } else if self.text.push(byte) {
                    None
                } else {
                    self.drop_frame();
                    self.state = State::Skip { ff: 0 };
                    Some(Err(DecodeError::StringTooLong))
                }
            }
            State::Term { ff } => {
                if byte == 0xFF {
                    self.frame_bytes = self.frame_bytes.saturating_add(1);
                    let ff = ff.saturating_add(1);
                    if ff >= 3 {
                        self.state = State::Idle;
                        Some(self.finish())
                    } else {
                        self.state = State::Term { ff };
                        None
                    }
                } else {
                    let header = self.header;
                    self.drop_frame();
                    self.state = State::Idle;
                    // The breaking byte may start the next frame; an error it
                    // raises itself is only counted.
                    let _ = self.start(byte);
                    Some(Err(DecodeError::MissingTerminator { header }))
                }
            }
            State::Skip { ff } => {
                self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(1);
                let ff = if byte == 0xFF {
                    ff.saturating_add(1)
                } else {
                    0
                };
                self.state = if ff >= 3 {
                    State::Idle
                } else {
                    State::Skip { ff }
                };
                None
            }
        }
    }

    /// First byte of a frame.
    fn start(&mut self, byte: u8) -> Option<DecodeError> {
        self.header = byte;
        self.fixed_len = 0;
        self.text.0.clear();
        self.frame_bytes = 1;
        if byte == 0xFF {
            // Stray terminator byte between frames.
            self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(1);
            self.frame_bytes = 0;
            return None;
        }
        match kind_of(byte) {
            Some(Kind::Fixed(0)) => self.state = State::Term { ff: 0 },
            Some(Kind::Fixed(n)) => self.state = State::Payload { left: n },
            Some(Kind::Zero) => self.state = State::Zero,
            Some(Kind::Str) => self.state = State::Str,
            None => {
                self.drop_frame();
                self.state = State::Skip { ff: 0 };
                return Some(DecodeError::UnknownHeader(byte));
            }
        }
        None
    }

    fn store_fixed(&mut self, byte: u8) {
        if let Some(slot) = self.fixed.get_mut(usize::from(self.fixed_len)) {
            *slot = byte;
            self.fixed_len = self.fixed_len.saturating_add(1);
        }
    }

    fn drop_frame(&mut self) {
        self.stats.dropped_frames = self.stats.dropped_frames.wrapping_add(1);
        self.stats.dropped_bytes = self
            .stats
            .dropped_bytes
            .wrapping_add(u32::from(self.frame_bytes));
        self.frame_bytes = 0;
    }

    fn finish(&mut self) -> Result<Frame, DecodeError> {
        let header = self.header;
        let payload = self.fixed.get(..usize::from(self.fixed_len)).unwrap_or(&[]);
        let frame = match (header, payload) {
            (0x00, []) => Some(Frame::Error(ErrorCode::InvalidInstruction)),
            (0x00, [0x00, 0x00]) => Some(Frame::Startup),
            (0x01, []) => Some(Frame::Success),
            (HEADER_TOUCH, &[page, component, ev]) => {
                TouchEvent::from_byte(ev).map(|event| Frame::Touch {
                    page,
                    component,
                    event,
                })
            }
            (HEADER_PAGE, &[p]) => Some(Frame::CurrentPage(p)),
            (HEADER_XY_AWAKE | HEADER_XY_ASLEEP, &[xh, xl, yh, yl, ev]) => {
                TouchEvent::from_byte(ev).map(|event| Frame::TouchXy {
                    x: u16::from_be_bytes([xh, xl]),
                    y: u16::from_be_bytes([yh, yl]),
                    event,
                    asleep: header == HEADER_XY_ASLEEP,
                })
            }
            (HEADER_STRING, []) => Some(Frame::Text(self.text.clone())),
            (HEADER_NUMBER, &[a, b, c, d]) => Some(Frame::Number(i32::from_le_bytes([a, b, c, d]))),
            (0x86, []) => Some(Frame::AutoSleep),
            (0x87, []) => Some(Frame::AutoWake),
            (0x88, []) => Some(Frame::Ready),
            (0x89, []) => Some(Frame::Upgrade),
            (0xFD, []) => Some(Frame::TransparentFinished),
            (0xFE, []) => Some(Frame::TransparentReady),
            (h, []) => ErrorCode::from_byte(h).map(Frame::Error),
            _ => None,
        };
        match frame {
            Some(f) => {
                self.stats.frames = self.stats.frames.wrapping_add(1);
                self.frame_bytes = 0;
                Ok(f)
            }
            None => {
                self.drop_frame();
                Err(DecodeError::Malformed { header })
            }
        }
    }
}
