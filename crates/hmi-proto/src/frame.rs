//! Return frames: what the screen sends to the MCU.
//!
//! Source: Nextion Instruction Set, chapter 7 "Format of Nextion Return Data"
//! (<https://nextion.tech/instruction-set/#s7>, mirrored at <https://nextion.ca/nis/>),
//! and ITEAD's `NexHardware.cpp` (ITEADLIB_Arduino_Nextion) for the header constants.
//! TJC screens use the same return set.

use core::fmt;

use crate::cursor::Cursor;
use crate::encoder::EncodeError;

/// Longest `0x70` string payload kept by the decoder, in bytes (documented bound:
/// a longer string is dropped with [`crate::DecodeError::StringTooLong`]).
pub const MAX_STRING_LEN: usize = 48;

/// Header byte of a touch event frame (`0x65 page component event`).
pub const HEADER_TOUCH: u8 = 0x65;
/// Header byte of a current-page frame (`0x66 page`).
pub const HEADER_PAGE: u8 = 0x66;
/// Header byte of a touch-coordinate frame while awake.
pub const HEADER_XY_AWAKE: u8 = 0x67;
/// Header byte of a touch-coordinate frame while asleep.
pub const HEADER_XY_ASLEEP: u8 = 0x68;
/// Header byte of string data (`get obj.txt`).
pub const HEADER_STRING: u8 = 0x70;
/// Header byte of numeric data (`get obj.val`).
pub const HEADER_NUMBER: u8 = 0x71;

/// Press or release, the last byte of `0x65`/`0x67`/`0x68` frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TouchEvent {
    /// `0x00`: the finger left the component.
    Release,
    /// `0x01`: the component was pressed.
    Press,
}

impl TouchEvent {
    /// Decodes the event byte; `None` for anything but `0x00`/`0x01`.
    pub const fn from_byte(b: u8) -> Option<Self> {
        match b {
            0x00 => Some(Self::Release),
            0x01 => Some(Self::Press),
            _ => None,
        }
    }

    /// The event byte on the wire.
    pub const fn to_byte(self) -> u8 {
        match self {
            Self::Release => 0x00,
            Self::Press => 0x01,
        }
    }
}

/// The screen's error return codes (sent when `bkcmd` is 2 or 3; power-on default 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ErrorCode {
    /// `0x00` invalid instruction.
    InvalidInstruction = 0x00,
    /// `0x02` invalid component ID.
    InvalidComponent = 0x02,
    /// `0x03` invalid page ID.
    InvalidPage = 0x03,
    /// `0x04` invalid picture ID.
    InvalidPicture = 0x04,
    /// `0x05` invalid font ID.
    InvalidFont = 0x05,
    /// `0x06` invalid file operation.
    InvalidFileOperation = 0x06,
    /// `0x09` invalid CRC.
    InvalidCrc = 0x09,
    /// `0x11` invalid baud rate setting.
    InvalidBaudRate = 0x11,
    /// `0x12` invalid waveform ID or channel.
    InvalidWaveform = 0x12,
    /// `0x1A` invalid variable name or attribute.
    InvalidVariable = 0x1A,
    /// `0x1B` invalid variable operation.
    InvalidOperation = 0x1B,
    /// `0x1C` assignment failed to assign.
    AssignmentFailed = 0x1C,
    /// `0x1D` EEPROM operation failed.
    EepromFailed = 0x1D,
    /// `0x1E` invalid quantity of parameters.
    InvalidParameterCount = 0x1E,
    /// `0x1F` IO operation failed.
    IoFailed = 0x1F,
    /// `0x20` escape character invalid.
    InvalidEscape = 0x20,
    /// `0x23` variable name too long.
    NameTooLong = 0x23,
    /// `0x24` serial buffer overflow: the screen dropped (part of) an instruction.
    BufferOverflow = 0x24,
}

impl ErrorCode {
    /// All codes, in wire order.
    pub const ALL: [ErrorCode; 18] = [
        Self::InvalidInstruction,
        Self::InvalidComponent,
        Self::InvalidPage,
        Self::InvalidPicture,
        Self::InvalidFont,
        Self::InvalidFileOperation,
        Self::InvalidCrc,
        Self::InvalidBaudRate,
        Self::InvalidWaveform,
        Self::InvalidVariable,
        Self::InvalidOperation,
        Self::AssignmentFailed,
        Self::EepromFailed,
        Self::InvalidParameterCount,
        Self::IoFailed,
        Self::InvalidEscape,
        Self::NameTooLong,
        Self::BufferOverflow,
    ];

    /// Decodes a header byte into an error code.
    pub const fn from_byte(b: u8) -> Option<Self> {
        Some(match b {
            0x00 => Self::InvalidInstruction,
            0x02 => Self::InvalidComponent,
            0x03 => Self::InvalidPage,
            0x04 => Self::InvalidPicture,
            0x05 => Self::InvalidFont,
            0x06 => Self::InvalidFileOperation,
            0x09 => Self::InvalidCrc,
            0x11 => Self::InvalidBaudRate,
            0x12 => Self::InvalidWaveform,
            0x1A => Self::InvalidVariable,
            0x1B => Self::InvalidOperation,
            0x1C => Self::AssignmentFailed,
            0x1D => Self::EepromFailed,
            0x1E => Self::InvalidParameterCount,
            0x1F => Self::IoFailed,
            0x20 => Self::InvalidEscape,
            0x23 => Self::NameTooLong,
            0x24 => Self::BufferOverflow,
            _ => return None,
        })
    }

    /// The byte on the wire.
    pub const fn code(self) -> u8 {
        self as u8
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            Self::InvalidInstruction => "invalid instruction",
            Self::InvalidComponent => "invalid component id",
            Self::InvalidPage => "invalid page id",
            Self::InvalidPicture => "invalid picture id",
            Self::InvalidFont => "invalid font id",
            Self::InvalidFileOperation => "invalid file operation",
            Self::InvalidCrc => "invalid CRC",
            Self::InvalidBaudRate => "invalid baud rate",
            Self::InvalidWaveform => "invalid waveform id or channel",
            Self::InvalidVariable => "invalid variable name or attribute",
            Self::InvalidOperation => "invalid variable operation",
            Self::AssignmentFailed => "assignment failed",
            Self::EepromFailed => "EEPROM operation failed",
            Self::InvalidParameterCount => "invalid quantity of parameters",
            Self::IoFailed => "IO operation failed",
            Self::InvalidEscape => "invalid escape character",
            Self::NameTooLong => "variable name too long",
            Self::BufferOverflow => "serial buffer overflow",
        };
        write!(f, "screen error 0x{:02X}: {}", self.code(), s)
    }
}

/// Why a [`Text`] could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TextError {
    /// Longer than [`MAX_STRING_LEN`].
    TooLong,
    /// Contains `0xFF`, which cannot be framed.
    ContainsTerminator,
}

impl fmt::Display for TextError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooLong => write!(f, "string longer than {MAX_STRING_LEN} bytes"),
            Self::ContainsTerminator => f.write_str("string contains 0xFF"),
        }
    }
}

/// The payload of a `0x70` string frame: at most [`MAX_STRING_LEN`] bytes, never `0xFF`.
///
/// The bytes are in the screen project's character encoding (ASCII for this
/// project's screen file; GB2312/ISO-8859 on others), so they are kept raw.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Text(pub(crate) heapless::Vec<u8, MAX_STRING_LEN>);

impl Text {
    /// Checked construction.
    pub fn new(bytes: &[u8]) -> Result<Self, TextError> {
        if bytes.contains(&0xFF) {
            return Err(TextError::ContainsTerminator);
        }
        heapless::Vec::from_slice(bytes)
            .map(Self)
            .map_err(|_| TextError::TooLong)
    }

    /// The raw bytes.
    pub fn as_bytes(&self) -> &[u8] {
        self.0.as_slice()
    }

    /// The text if it is valid UTF-8 (always, for ASCII).
    pub fn as_str(&self) -> Option<&str> {
        core::str::from_utf8(self.as_bytes()).ok()
    }

    /// Appends a byte (decoder internal); `false` when full or `0xFF`.
    pub(crate) fn push(&mut self, b: u8) -> bool {
        b != 0xFF && self.0.push(b).is_ok()
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Text {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "{=[u8]:a}", self.as_bytes());
    }
}

/// One decoded return frame (screen → MCU). The terminator is implied.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Frame {
    /// `0x00 0x00 0x00`: the screen has (re)started (sent before `0x88` by current firmware).
    Startup,
    /// `0x01`: instruction successful (only with `bkcmd` 1 or 3).
    Success,
    /// `0x00`, `0x02`–`0x24`: the screen rejected an instruction.
    Error(ErrorCode),
    /// `0x65 page component event`: "Send Component ID" of a touch event.
    Touch {
        /// Page id.
        page: u8,
        /// Component id on that page.
        component: u8,
        /// Press or release.
        event: TouchEvent,
    },
    /// `0x66 page`: reply to `sendme`.
    CurrentPage(u8),
    /// `0x67`/`0x68 xH xL yH yL event`: touch coordinates (`sendxy=1`), big-endian.
    TouchXy {
        /// X in pixels.
        x: u16,
        /// Y in pixels.
        y: u16,
        /// Press or release.
        event: TouchEvent,
        /// `true` for `0x68` (touch while the screen sleeps).
        asleep: bool,
    },
    /// `0x70 bytes…`: reply to `get obj.txt`.
    Text(Text),
    /// `0x71 b0 b1 b2 b3`: reply to `get obj.val`, little-endian signed 32-bit.
    Number(i32),
    /// `0x86`: the screen entered sleep on its own.
    AutoSleep,
    /// `0x87`: the screen woke on its own.
    AutoWake,
    /// `0x88`: the screen is ready after power-on.
    Ready,
    /// `0x89`: the screen started a microSD upgrade.
    Upgrade,
    /// `0xFD`: transparent data finished.
    TransparentFinished,
    /// `0xFE`: ready for transparent data.
    TransparentReady,
}

impl Frame {
    /// The header byte.
    pub fn header(&self) -> u8 {
        match self {
            Self::Startup => 0x00,
            Self::Success => 0x01,
            Self::Error(c) => c.code(),
            Self::Touch { .. } => HEADER_TOUCH,
            Self::CurrentPage(_) => HEADER_PAGE,
            Self::TouchXy { asleep: false, .. } => HEADER_XY_AWAKE,
            Self::TouchXy { asleep: true, .. } => HEADER_XY_ASLEEP,
            Self::Text(_) => HEADER_STRING,
            Self::Number(_) => HEADER_NUMBER,
            Self::AutoSleep => 0x86,
            Self::AutoWake => 0x87,
            Self::Ready => 0x88,
            Self::Upgrade => 0x89,
            Self::TransparentFinished => 0xFD,
            Self::TransparentReady => 0xFE,
        }
    }

    /// Writes the frame as the screen would send it, terminator included; returns the length.
    ///
    /// Used by the virtual screen and by tests; the firmware only decodes.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let mut c = Cursor::new(buf);
        c.byte(self.header())?;
        match self {
            Self::Startup => c.put(&[0x00, 0x00])?,
            Self::Touch {
                page,
                component,
                event,
            } => c.put(&[*page, *component, event.to_byte()])?,
            Self::CurrentPage(p) => c.byte(*p)?,
            Self::TouchXy { x, y, event, .. } => {
                c.put(&x.to_be_bytes())?;
                c.put(&y.to_be_bytes())?;
                c.byte(event.to_byte())?;
            }
            Self::Text(t) => c.put(t.as_bytes())?,
            Self::Number(n) => c.put(&n.to_le_bytes())?,
            _ => {}
        }
        c.terminator()?;
        Ok(c.len())
    }
}
