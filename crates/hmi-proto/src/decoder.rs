//! Streaming decoder of return frames (screen → MCU), one byte at a time.
//!
//! Framing rules (Nextion Instruction Set ch. 7): every frame is a header byte,
//! a payload and `0xFF 0xFF 0xFF`. All frames but `0x70` have a fixed payload
//! length given by the header, so they are parsed by length — a `0x71` number
//! or `0x67` coordinate may contain `0xFF` bytes. A `0x70` string ends at the
//! first `0xFF` and is bounded by [`MAX_STRING_LEN`].
//!
//! Resynchronisation (details and the tie rule on [`Decoder`]):
//! * a stray `0xFF` between frames is dropped (counted);
//! * a frame that breaks (unknown header, wrong terminator, string too long)
//!   is reported once; the bytes after its header are kept and the next frame
//!   is the one that ends at a following terminator, wherever it starts, so
//!   one corrupted, lost or extra byte costs one frame, never the next;
//! * a frame of the right length and terminator with an impossible payload is
//!   reported and searched like a broken one.
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
    /// Frames dropped, each reported once as a [`DecodeError`] (the bytes
    /// of a run of garbage after one are counted in `dropped_bytes` only).
    pub dropped_frames: u32,
    /// Bytes that ended up in no decoded frame.
    pub dropped_bytes: u32,
}

/// The longest frame on the wire: a `0x70` header, [`MAX_STRING_LEN`] bytes
/// of text and the terminator.
const WINDOW: usize = 1 + MAX_STRING_LEN + 3;

/// What the bytes from a frame's header onwards say so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scan {
    /// A frame that may still complete.
    Incomplete,
    /// A complete frame of this many bytes (terminator included).
    Complete(usize),
    /// It cannot become a frame; `.1`: it broke in its terminator, after
    /// a body (header and payload) of `.1.0` bytes and `.1.1` good
    /// terminator bytes (0–2).
    Broken(DecodeError, Option<(usize, usize)>),
}

/// Reads the frame that starts at `bytes[0]` (a header, never `0xFF`):
/// header, payload by the header's rule, then `0xFF 0xFF 0xFF`.
fn scan(bytes: &[u8]) -> Scan {
    let Some(&header) = bytes.first() else {
        return Scan::Incomplete;
    };
    let body = match kind_of(header) {
        None => return Scan::Broken(DecodeError::UnknownHeader(header), None),
        Some(Kind::Fixed(n)) => usize::from(n).saturating_add(1),
        // `00 FF FF FF` (invalid instruction) or `00 00 00 FF FF FF` (startup).
        Some(Kind::Zero) => match bytes.get(1) {
            None => return Scan::Incomplete,
            Some(0xFF) => 1,
            Some(_) => 3,
        },
        // A string ends at its first `0xFF`.
        Some(Kind::Str) => {
            let text = bytes.get(1..).unwrap_or(&[]);
            match text.iter().position(|&b| b == 0xFF) {
                Some(n) if n <= MAX_STRING_LEN => n.saturating_add(1),
                None if text.len() <= MAX_STRING_LEN => return Scan::Incomplete,
                _ => return Scan::Broken(DecodeError::StringTooLong, None),
            }
        }
    };
    for k in 0..3 {
        match bytes.get(body.saturating_add(k)) {
            None => return Scan::Incomplete,
            Some(0xFF) => {}
            Some(_) => {
                return Scan::Broken(DecodeError::MissingTerminator { header }, Some((body, k)));
            }
        }
    }
    Scan::Complete(body.saturating_add(3))
}

/// Streaming return-frame decoder.
///
/// Its size is fixed (≤ 80 bytes with [`MAX_STRING_LEN`] = 48, asserted by a
/// test); feed it from the UART receive interrupt or from a byte queue.
///
/// # Resynchronisation
///
/// Between frames the decoder reads the next frame by its header's rule. When
/// that frame breaks (an unknown header, a wrong terminator, a string too
/// long, an impossible payload), it reports the error once and *recovers*:
/// only the header is dropped (it may be the byte that was hit), the bytes
/// after it are kept (at most one frame's worth, 52 bytes) and every
/// terminator `FF FF FF` that follows is tried as the end of a frame starting
/// at any of the kept bytes. The frame found there is decoded and the decoder
/// is back between frames. Three rules pick among the possible frames:
///
/// 1. a frame found inside a frame that broke in its terminator must end
///    after the byte that broke it (up to there the bytes agreed with the
///    broken frame, so a frame ending earlier would overlap it);
/// 2. the frame that starts first wins, except
/// 3. when the byte that broke a frame's terminator was followed by the rest
///    of a terminator, that byte was probably a terminator byte turned into
///    another (or an extra byte), and a *touch event* starting right after
///    that terminator wins over a frame starting earlier (a lost Stop costs
///    more than a lost reply, which the link asks for again; a lost byte
///    still makes the byte after it the next header otherwise).
///
/// So a corrupted, lost or extra byte anywhere in a frame costs that frame
/// only, never the touch event after it (tested exhaustively over every
/// frame type, byte position and byte value in `tests/resync.rs`, with a
/// property test of noise followed by two frames). The screen link adds a
/// line-quiet rule on top ([`crate::hmi::RX_GAP_MS`]).
///
/// Known limit: while recovering, a frame whose payload ends in `FF` bytes
/// that themselves complete a shorter valid frame (a `get` number reply of
/// `…24 FF` holds the return code `24 FF FF FF`) is taken as that shorter
/// frame — its true end comes one byte later, and the decoder does not wait
/// for it. Touch events never carry `FF` in their payload; the lost reply is
/// asked for again by the link.
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
///
/// // A `get` reply whose last terminator byte was hit by noise (0x71, itself
/// // a header), then a Stop touch (page 2, component 7, release): the reply
/// // is lost, the touch is not.
/// let bytes = [0x71, 0x10, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0x71,
///              0x65, 0x02, 0x07, 0x00, 0xFF, 0xFF, 0xFF];
/// let mut results = Vec::new();
/// dec.push_slice(&bytes, |r| results.push(r));
/// assert_eq!(results.last(), Some(&Ok(Frame::Touch { page: 2, component: 7, event: TouchEvent::Release })));
/// ```
#[derive(Debug, Clone)]
pub struct Decoder {
    /// The frame in progress, or while recovering the bytes still in question.
    buf: heapless::Vec<u8, WINDOW, u8>,
    /// A frame broke: looking for the next frame end in `buf`.
    recovering: bool,
    /// Bytes that were no frame since the last frame: further broken
    /// frames are counted, not reported again.
    in_garbage: bool,
    /// While recovering: the bytes of `buf` already tried as frame ends.
    examined: u8,
    /// Index in `buf` where the next frame starts if the byte that broke
    /// the last one was a terminator byte turned into another (`[0]`) or an
    /// extra byte (`[1]`), and how many bytes right before it must be `0xFF`
    /// (the rest of that terminator).
    expected_start: [Option<(u8, u8)>; 2],
    /// While recovering: a frame found must end at or after this index.
    min_end: u8,
    /// Whether frames only a request brings are expected
    /// ([`Decoder::expect_replies`]).
    replies: bool,
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
            buf: heapless::Vec::new(),
            recovering: false,
            in_garbage: false,
            examined: 0,
            expected_start: [None; 2],
            min_end: 0,
            replies: true,
            stats: DecoderStats {
                frames: 0,
                dropped_frames: 0,
                dropped_bytes: 0,
            },
        }
    }

    /// Says whether the frames that only a request brings are expected
    /// (the default): a string (`0x70`, `get x.txt`), a number (`0x71`,
    /// `get x.val`) and touch coordinates (`0x67`/`0x68`, `sendxy=1`).
    /// When not, such a header between frames is read as a stray byte
    /// (reported as [`DecodeError::UnknownHeader`]): a string, a number or
    /// a coordinate frame would otherwise take the touch frame after it as
    /// its payload (`71 65 03 07 01 FF FF FF` is a valid number frame).
    pub fn expect_replies(&mut self, expected: bool) {
        self.replies = expected;
    }

    /// `header` starts a frame that only a request brings, and none is
    /// expected ([`expect_replies`](Self::expect_replies)).
    fn unexpected(&self, header: u8) -> bool {
        !self.replies
            && matches!(
                header,
                HEADER_STRING | HEADER_NUMBER | HEADER_XY_AWAKE | HEADER_XY_ASLEEP
            )
    }

    /// Counters since construction.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// `true` between frames (nothing partial buffered).
    pub fn is_idle(&self) -> bool {
        self.buf.is_empty()
    }

    /// Forgets any partial frame (counted as dropped); counters are kept.
    /// The screen link calls it when the line has been quiet for longer
    /// than a frame takes: the next byte is a header.
    pub fn reset(&mut self) {
        if !self.buf.is_empty() {
            if !self.recovering {
                self.stats.dropped_frames = self.stats.dropped_frames.wrapping_add(1);
            }
            self.drop_front(self.buf.len());
        }
        self.recovering = false;
        self.in_garbage = false;
        self.examined = 0;
    }

    /// Feeds a slice; `f` is called for every result, in order.
    pub fn push_slice(&mut self, bytes: &[u8], mut f: impl FnMut(Result<Frame, DecodeError>)) {
        for &b in bytes {
            let mut next = self.push(b);
            while let Some(r) = next {
                f(r);
                next = self.poll();
            }
        }
    }

    /// Feeds one byte; returns the first frame or error that ends with this
    /// byte. One byte can end more than one (an error, then a frame found in
    /// the bytes after it): after a `Some`, call [`poll`](Self::poll) until
    /// it returns `None`.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, DecodeError>> {
        if self.buf.is_full() {
            // Only while recovering (a frame in progress never fills it).
            self.drop_front(1);
        }
        if self.buf.push(byte).is_err() {
            self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(1);
        }
        self.poll()
    }

    /// The next frame or error in the bytes already pushed, if any.
    pub fn poll(&mut self) -> Option<Result<Frame, DecodeError>> {
        loop {
            let step = if self.recovering {
                self.recover()
            } else {
                self.between_frames()
            };
            match step {
                Step::Wait => return None,
                Step::Again => {}
                Step::Result(r) => return Some(r),
            }
        }
    }

    /// Reads `buf` as the frame that starts at its first byte.
    fn between_frames(&mut self) -> Step {
        match self.buf.first() {
            None => return Step::Wait,
            Some(0xFF) => {
                // A stray terminator byte between frames.
                self.drop_front(1);
                return Step::Again;
            }
            // A frame that only a request brings, none made: a stray byte,
            // which would take the frame after it as its payload.
            Some(&h) if self.unexpected(h) => {
                return self.broken(DecodeError::UnknownHeader(h), None);
            }
            Some(_) => {}
        }
        match scan(&self.buf) {
            Scan::Incomplete => Step::Wait,
            Scan::Complete(n) => match parse(self.buf.get(..n).unwrap_or(&[])) {
                Ok(_) => Step::Result(self.take_frame(0, n)),
                // Right length and terminator, impossible payload: the
                // header may be what was hit, so only the header goes.
                Err(e) => self.broken(e, None),
            },
            Scan::Broken(e, at) => self.broken(e, at),
        }
    }

    /// The frame at the start of `buf` cannot be one: its first `body`
    /// bytes go, the rest is searched for the next frame.
    ///
    /// `in_terminator`: it broke in its terminator, `(body, k)`: the frame
    /// without terminator was `body` bytes and `k` terminator bytes were
    /// good. If the bytes after the one that broke it complete a terminator
    /// of three, that byte was probably a corrupted terminator byte and the
    /// next frame probably starts right after: remember where.
    fn broken(&mut self, e: DecodeError, in_terminator: Option<(usize, usize)>) -> Step {
        // Indices before the drop below, which shifts them. Substituted:
        // the terminator's remaining `2 - k` bytes follow it; inserted: all
        // its remaining `3 - k`.
        self.expected_start = [0u8, 1].map(|extra| {
            let (body, k) = in_terminator?;
            let start = body.checked_add(3)?.checked_add(usize::from(extra))?;
            let pad = 2usize.checked_sub(k)?.checked_add(usize::from(extra))?;
            Some((u8::try_from(start).ok()?, u8::try_from(pad).ok()?))
        });
        // A frame inside it must end after the byte that broke it (up to
        // there its bytes were consistent with it).
        self.min_end = in_terminator
            .and_then(|(body, k)| u8::try_from(body.checked_add(k)?.checked_add(1)?).ok())
            .unwrap_or(0);
        // Only the header goes: it may be the byte that was hit.
        self.drop_front(1);
        self.recovering = true;
        self.examined = 0;
        if core::mem::replace(&mut self.in_garbage, true) {
            // Still the same run of garbage: its bytes are counted.
            Step::Again
        } else {
            self.stats.dropped_frames = self.stats.dropped_frames.wrapping_add(1);
            Step::Result(Err(e))
        }
    }

    /// Looks for a frame end in the bytes kept since a frame broke.
    fn recover(&mut self) -> Step {
        // Bytes that start no frame still possible go (a complete frame at
        // the front was tried at its end already).
        while let Some(&first) = self.buf.first() {
            let tried = match scan(&self.buf) {
                Scan::Incomplete => false,
                Scan::Complete(n) => n <= usize::from(self.examined),
                Scan::Broken(..) => true,
            };
            if first == 0xFF || tried {
                self.drop_front(1);
            } else {
                break;
            }
        }
        if self.buf.is_empty() {
            self.recovering = false;
            self.examined = 0;
            return Step::Wait;
        }
        let len = self.buf.len();
        for end in usize::from(self.examined).saturating_add(1)..=len {
            let tail = self.buf.get(end.saturating_sub(3)..end);
            if end >= 4 && end >= usize::from(self.min_end) && tail == Some(&[0xFF; 3][..]) {
                if let Some(start) = self.frame_ending_at(end) {
                    self.drop_front(start);
                    self.recovering = false;
                    self.examined = 0;
                    return Step::Result(self.take_frame(0, end.saturating_sub(start)));
                }
            }
        }
        self.examined = u8::try_from(len).unwrap_or(u8::MAX);
        Step::Wait
    }

    /// Where a whole, valid frame ending at `end` (one past a terminator)
    /// starts in `buf`: the rules 2 and 3 of [`Decoder`]'s documentation.
    fn frame_ending_at(&self, end: usize) -> Option<usize> {
        let valid = |start: usize| {
            let bytes = self.buf.get(start..end).unwrap_or(&[]);
            bytes
                .first()
                .is_some_and(|&h| h != 0xFF && !self.unexpected(h))
                && scan(bytes) == Scan::Complete(bytes.len())
                && parse(bytes).is_ok()
        };
        let last_start = end.saturating_sub(3);
        let first = (0..last_start).find(|&s| valid(s))?;
        for (expected, pad) in self.expected_start.into_iter().flatten() {
            let expected = usize::from(expected);
            let rest_of_terminator = expected
                .checked_sub(usize::from(pad))
                .and_then(|from| self.buf.get(from..expected))
                .is_some_and(|r| r.iter().all(|&b| b == 0xFF));
            let touch = self.buf.get(expected) == Some(&HEADER_TOUCH);
            if expected > first
                && expected < last_start
                && touch
                && rest_of_terminator
                && valid(expected)
            {
                return Some(expected);
            }
        }
        Some(first)
    }

    /// Decodes `buf[start..start + n]` (a complete frame) and removes it.
    fn take_frame(&mut self, start: usize, n: usize) -> Result<Frame, DecodeError> {
        let end = start.saturating_add(n).min(self.buf.len());
        let r = parse(self.buf.get(start..end).unwrap_or(&[]));
        match r {
            Ok(_) => {
                self.stats.frames = self.stats.frames.wrapping_add(1);
                self.in_garbage = false;
                self.remove_front(end);
            }
            Err(_) => {
                self.stats.dropped_frames = self.stats.dropped_frames.wrapping_add(1);
                self.drop_front(end);
            }
        }
        r
    }

    /// Removes the first `n` bytes of `buf`, counted as dropped.
    fn drop_front(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.stats.dropped_bytes = self
            .stats
            .dropped_bytes
            .wrapping_add(u32::try_from(n).unwrap_or(u32::MAX));
        self.remove_front(n);
    }

    /// Removes the first `n` bytes of `buf`.
    fn remove_front(&mut self, n: usize) {
        let len = self.buf.len();
        let n = n.min(len);
        // A byte loop, not `copy_within`: that is the firmware's only use of
        // `memmove` (1.6 KB of flash on profile A) for at most 52 bytes.
        for i in 0..len.saturating_sub(n) {
            let b = self.buf.get(i.saturating_add(n)).copied();
            if let (Some(b), Some(d)) = (b, self.buf.get_mut(i)) {
                *d = b;
            }
        }
        self.buf.truncate(len.saturating_sub(n));
        let n = u8::try_from(n).unwrap_or(u8::MAX);
        self.examined = self.examined.saturating_sub(n);
        self.min_end = self.min_end.saturating_sub(n);
        self.expected_start = self
            .expected_start
            .map(|e| e.and_then(|(i, pad)| Some((i.checked_sub(n)?, pad))));
    }
}

/// What one step of [`Decoder::push`] came to.
enum Step {
    /// Needs more bytes.
    Wait,
    /// Look at the buffer again.
    Again,
    /// A frame or an error, and look again.
    Result(Result<Frame, DecodeError>),
}

/// Decodes a complete frame (terminator included, as [`scan`] found it).
fn parse(bytes: &[u8]) -> Result<Frame, DecodeError> {
    let header = bytes.first().copied().unwrap_or(0);
    let body = bytes.get(..bytes.len().saturating_sub(3)).unwrap_or(&[]);
    let payload = body.get(1..).unwrap_or(&[]);
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
        (HEADER_XY_AWAKE | HEADER_XY_ASLEEP, &[xh, xl, yh, yl, ev]) => TouchEvent::from_byte(ev)
            .map(|event| Frame::TouchXy {
                x: u16::from_be_bytes([xh, xl]),
                y: u16::from_be_bytes([yh, yl]),
                event,
                asleep: header == HEADER_XY_ASLEEP,
            }),
        (HEADER_STRING, text) => {
            let mut t = Text(heapless::Vec::new());
            text.iter().all(|&b| t.push(b)).then_some(Frame::Text(t))
        }
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
    frame.ok_or(DecodeError::Malformed { header })
}
