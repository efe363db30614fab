//! Instructions: what the MCU sends to the screen.
//!
//! Source: Nextion Instruction Set (<https://nextion.tech/instruction-set/>),
//! sections 1 (general rules: ASCII, lower case, `0xFF 0xFF 0xFF` terminator,
//! escapes `\r` `\"` `\\`), 2 (assignments), 3 (`page`, `get`, `vis`, `tsw`,
//! `ref`, `sendme`, `rest`) and 6 (system variables `bkcmd`, `dims`, `sleep`,
//! `baud`). TJC screens accept the same instructions.
//!
//! Construction is checked ([`ObjName::new`], [`Instruction::set_text`]);
//! [`Instruction::emit`] then only fails when the caller's buffer is too small.

use core::fmt;

use crate::cursor::{BufferFull, Cursor};

/// Longest object name segment accepted (the vendor editors allow 14 characters).
pub const MAX_NAME_SEGMENT: usize = 14;

/// Longest text (in characters, before escaping) sent by `obj.txt="…"`.
/// The screen's text components need `txt_maxl` ≥ this.
pub const MAX_TEXT_LEN: usize = 40;

/// Upper bound of one encoded instruction in bytes (a maximal escaped
/// `page.object.txt="…"` with its terminator). A buffer this long never
/// yields [`EncodeError::BufferTooSmall`].
pub const MAX_INSTRUCTION_LEN: usize = 2 * MAX_NAME_SEGMENT + 1 + 6 + 2 * MAX_TEXT_LEN + 1 + 3;

/// Why an instruction or frame could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The caller's buffer is too short; nothing useful was written.
    BufferTooSmall,
    /// Text longer than [`MAX_TEXT_LEN`] characters.
    TextTooLong,
    /// A numeric argument outside the instruction's range (e.g. `dims=101`).
    OutOfRange,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::BufferTooSmall => "output buffer too small",
            Self::TextTooLong => "text too long for the screen",
            Self::OutOfRange => "argument out of range",
        })
    }
}

impl From<BufferFull> for EncodeError {
    fn from(_: BufferFull) -> Self {
        Self::BufferTooSmall
    }
}

/// Why an object name was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NameError {
    /// Empty name or empty segment (`"a..b"`, `".a"`).
    Empty,
    /// A segment longer than [`MAX_NAME_SEGMENT`].
    TooLong,
    /// A character other than `A–Z a–z 0–9 _`, or a leading digit.
    InvalidChar,
    /// More than one `.` (only `page.object` qualification is allowed).
    TooManySegments,
}

impl fmt::Display for NameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Empty => "empty object name",
            Self::TooLong => "object name too long",
            Self::InvalidChar => "invalid character in object name",
            Self::TooManySegments => "object name has too many segments",
        })
    }
}

/// A validated object name: `t0`, `nspacing`, or page-qualified `fixed.nspeed`.
///
/// Each segment is 1–[`MAX_NAME_SEGMENT`] characters of `[A-Za-z_][A-Za-z0-9_]*`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObjName<'a>(&'a str);

impl<'a> ObjName<'a> {
    /// Checked construction (usable in `const` context).
    pub const fn new(name: &'a str) -> Result<Self, NameError> {
        let mut rest = name.as_bytes();
        let mut seg_len = 0usize;
        let mut dots = 0u8;
        while let Some((&c, tail)) = rest.split_first() {
            rest = tail;
            if c == b'.' {
                if seg_len == 0 {
                    return Err(NameError::Empty);
                }
                dots = dots.saturating_add(1);
                if dots > 1 {
                    return Err(NameError::TooManySegments);
                }
                seg_len = 0;
            } else {
                let ok =
                    c.is_ascii_alphabetic() || c == b'_' || (c.is_ascii_digit() && seg_len > 0);
                if !ok {
                    return Err(NameError::InvalidChar);
                }
                seg_len = seg_len.saturating_add(1);
                if seg_len > MAX_NAME_SEGMENT {
                    return Err(NameError::TooLong);
                }
            }
        }
        if seg_len == 0 {
            return Err(NameError::Empty);
        }
        Ok(Self(name))
    }

    /// Unchecked construction, for names already validated (the screen
    /// contract's table is checked by a test). Emitting an invalid name cannot
    /// panic; the screen would answer `0x1A`.
    pub const fn new_unchecked(name: &'a str) -> Self {
        Self(name)
    }

    /// The name.
    pub const fn as_str(&self) -> &'a str {
        self.0
    }
}

/// Attribute read by `get`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Attr {
    /// `.val`: numeric, answered with `0x71`.
    Val,
    /// `.txt`: text, answered with `0x70`.
    Txt,
}

impl Attr {
    const fn suffix(self) -> &'static [u8] {
        match self {
            Self::Val => b".val",
            Self::Txt => b".txt",
        }
    }
}

/// `bkcmd` levels: which results the screen reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BkCmd {
    /// 0: no results.
    Off = 0,
    /// 1: success (`0x01`) only.
    OnSuccess = 1,
    /// 2: failures only (power-on default).
    OnFailure = 2,
    /// 3: every result.
    Always = 3,
}

/// Baud rates the screen accepts for `baud=`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BaudRate {
    /// 2400.
    B2400,
    /// 4800.
    B4800,
    /// 9600 (factory default).
    B9600,
    /// 19200.
    B19200,
    /// 38400.
    B38400,
    /// 57600.
    B57600,
    /// 115200 (this project).
    B115200,
    /// 230400.
    B230400,
    /// 256000.
    B256000,
    /// 512000.
    B512000,
    /// 921600.
    B921600,
}

impl BaudRate {
    /// Bits per second.
    pub const fn bps(self) -> u32 {
        match self {
            Self::B2400 => 2400,
            Self::B4800 => 4800,
            Self::B9600 => 9600,
            Self::B19200 => 19200,
            Self::B38400 => 38400,
            Self::B57600 => 57600,
            Self::B115200 => 115_200,
            Self::B230400 => 230_400,
            Self::B256000 => 256_000,
            Self::B512000 => 512_000,
            Self::B921600 => 921_600,
        }
    }

    /// Checked construction from bits per second.
    pub const fn from_bps(bps: u32) -> Option<Self> {
        Some(match bps {
            2400 => Self::B2400,
            4800 => Self::B4800,
            9600 => Self::B9600,
            19200 => Self::B19200,
            38400 => Self::B38400,
            57600 => Self::B57600,
            115_200 => Self::B115200,
            230_400 => Self::B230400,
            256_000 => Self::B256000,
            512_000 => Self::B512000,
            921_600 => Self::B921600,
            _ => return None,
        })
    }
}

/// A validated screen text: at most [`MAX_TEXT_LEN`] characters.
///
/// Emitted with `"` → `\"`, `\` → `\\`, line feed → `\r` (the screen's line
/// break), other control characters dropped, and every non-ASCII character
/// replaced by `?` — so the bytes on the wire are 7-bit ASCII whatever font
/// encoding the screen project uses, and can never contain `0xFF`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScreenText<'a>(&'a str);

impl<'a> ScreenText<'a> {
    /// The empty text.
    pub const EMPTY: ScreenText<'static> = ScreenText("");

    /// Checked construction.
    pub fn new(text: &'a str) -> Result<Self, EncodeError> {
        if char_count(text) > MAX_TEXT_LEN {
            Err(EncodeError::TextTooLong)
        } else {
            Ok(Self(text))
        }
    }

    /// The unescaped text.
    pub const fn as_str(&self) -> &'a str {
        self.0
    }
}

/// The number of characters of `text`: its bytes that start a character
/// (UTF-8 continuation bytes are `0b10xx_xxxx`). The same count as
/// `text.chars().count()`, whose unrolled version costs ≈ 300 B of flash.
pub(crate) fn char_count(text: &str) -> usize {
    text.bytes().filter(|&b| b & 0xC0 != 0x80).count()
}

/// `text` cut to its first `n` characters (all of it if shorter): the same
/// cut as through `char_indices().nth(n)`, without its decoder.
pub(crate) fn first_chars(text: &str, n: usize) -> &str {
    let mut seen = 0usize;
    for (i, b) in text.bytes().enumerate() {
        if b & 0xC0 != 0x80 {
            if seen == n {
                return text.get(..i).unwrap_or("");
            }
            seen = seen.wrapping_add(1);
        }
    }
    text
}

/// One instruction to the screen. Build it, then [`emit`](Self::emit) it.
///
/// ```
/// use hmi_proto::{Instruction, ObjName};
///
/// let mut buf = [0u8; 32];
/// let n = Instruction::Page(1).emit(&mut buf).unwrap();
/// assert_eq!(&buf[..n], b"page 1\xff\xff\xff");
/// let t0 = ObjName::new("t0").unwrap();
/// let n = Instruction::set_text(t0, "say \"hi\"").unwrap().emit(&mut buf).unwrap();
/// assert_eq!(&buf[..n], b"t0.txt=\"say \\\"hi\\\"\"\xff\xff\xff");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Instruction<'a> {
    /// `page N`: show page N.
    Page(u8),
    /// `obj.txt="…"`.
    SetText(ObjName<'a>, ScreenText<'a>),
    /// `obj.val=N`.
    SetValue(ObjName<'a>, i32),
    /// `get obj.val` / `get obj.txt`.
    Get(ObjName<'a>, Attr),
    /// `vis obj,0|1`.
    Visible(ObjName<'a>, bool),
    /// `tsw obj,0|1`; `None` is every component of the page (`tsw 255,…`).
    TouchEnable(Option<ObjName<'a>>, bool),
    /// `ref obj`.
    Refresh(ObjName<'a>),
    /// `sendme`: the screen answers `0x66 page`.
    SendMe,
    /// `bkcmd=N`.
    BkCmd(BkCmd),
    /// `dims=N` (0–100, persisted by the screen).
    Dims(u8),
    /// `sleep=0|1`.
    Sleep(bool),
    /// `rest`: reset the screen.
    Reset,
    /// `baud=N` (not persisted; `bauds=` would be).
    Baud(BaudRate),
    /// A lone `0xFF 0xFF 0xFF`: ends whatever partial instruction the screen holds.
    Flush,
}

impl<'a> Instruction<'a> {
    /// `obj.txt="text"`, checking the text length.
    pub fn set_text(obj: ObjName<'a>, text: &'a str) -> Result<Self, EncodeError> {
        Ok(Self::SetText(obj, ScreenText::new(text)?))
    }

    /// Writes the instruction and its terminator into `buf`; returns the length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let mut c = Cursor::new(buf);
        match *self {
            Self::Page(p) => {
                c.put(b"page ")?;
                c.u32(u32::from(p))?;
            }
            Self::SetText(obj, text) => {
                c.put(obj.as_str().as_bytes())?;
                c.put(b".txt=\"")?;
                // By bytes (no UTF-8 decoder): a non-ASCII character is one
                // start byte (0xC0..) and continuation bytes (0x80..0xBF), so
                // `?` per start byte is `?` per character.
                for &b in text.as_str().as_bytes() {
                    match b {
                        b'"' => c.put(b"\\\"")?,
                        b'\\' => c.put(b"\\\\")?,
                        b'\n' => c.put(b"\\r")?,
                        b' '..=b'~' => c.byte(b)?,
                        0xC0.. => c.byte(b'?')?,
                        // ASCII control characters, DEL, continuation bytes.
                        _ => {}
                    }
                }
                c.byte(b'"')?;
            }
            Self::SetValue(obj, v) => {
                c.put(obj.as_str().as_bytes())?;
                c.put(b".val=")?;
                c.i32(v)?;
            }
            Self::Get(obj, attr) => {
                c.put(b"get ")?;
                c.put(obj.as_str().as_bytes())?;
                c.put(attr.suffix())?;
            }
            Self::Visible(obj, on) => {
                c.put(b"vis ")?;
                c.put(obj.as_str().as_bytes())?;
                c.put(if on { b",1" } else { b",0" })?;
            }
            Self::TouchEnable(obj, on) => {
                c.put(b"tsw ")?;
                match obj {
                    Some(o) => c.put(o.as_str().as_bytes())?,
                    None => c.put(b"255")?,
                }
                c.put(if on { b",1" } else { b",0" })?;
            }
            Self::Refresh(obj) => {
                c.put(b"ref ")?;
                c.put(obj.as_str().as_bytes())?;
            }
            Self::SendMe => c.put(b"sendme")?,
            Self::BkCmd(level) => {
                c.put(b"bkcmd=")?;
                c.u32(level as u32)?;
            }
            Self::Dims(d) => {
                if d > 100 {
                    return Err(EncodeError::OutOfRange);
                }
                c.put(b"dims=")?;
                c.u32(u32::from(d))?;
            }
            Self::Sleep(on) => c.put(if on { b"sleep=1" } else { b"sleep=0" })?,
            Self::Reset => c.put(b"rest")?,
            Self::Baud(rate) => {
                c.put(b"baud=")?;
                c.u32(rate.bps())?;
            }
            Self::Flush => {}
        }
        c.terminator()?;
        Ok(c.len())
    }

    /// Emits into a fresh `heapless::Vec` of capacity `N`.
    pub fn to_vec<const N: usize>(&self) -> Result<heapless::Vec<u8, N>, EncodeError> {
        let mut buf = [0u8; N];
        let n = self.emit(&mut buf)?;
        heapless::Vec::from_slice(buf.get(..n).unwrap_or(&[]))
            .map_err(|_| EncodeError::BufferTooSmall)
    }
}

#[cfg(test)]
mod tests {
    use super::{char_count, first_chars};
    use proptest::prelude::*;

    proptest! {
        /// The byte-level count and cut against the standard library's
        /// UTF-8 decoder (the reference), on any text, ASCII or not.
        #[test]
        fn count_and_cut_match_the_decoder(text in "\\PC{0,60}", n in 0usize..64) {
            prop_assert_eq!(char_count(&text), text.chars().count());
            let reference = text
                .char_indices()
                .nth(n)
                .map_or(text.as_str(), |(i, _)| &text[..i]);
            prop_assert_eq!(first_chars(&text, n), reference);
        }
    }

    /// The text escaping as it was written per character (`chars()`), the
    /// reference for the per-byte one.
    fn escaped_per_char(text: &str) -> std::vec::Vec<u8> {
        let mut out = b"t0.txt=\"".to_vec();
        for ch in text.chars() {
            match ch {
                '"' => out.extend_from_slice(b"\\\""),
                '\\' => out.extend_from_slice(b"\\\\"),
                '\n' => out.extend_from_slice(b"\\r"),
                ' '..='~' => out.push(ch as u8),
                _ if ch.is_ascii_control() => {}
                _ => out.push(b'?'),
            }
        }
        out.extend_from_slice(b"\"\xff\xff\xff");
        out
    }

    proptest! {
        /// Any text up to the limit, ASCII, controls or not: the bytes sent
        /// are those of the per-character escaping.
        #[test]
        fn text_escaping_matches_the_per_character_rules(text in "(\\PC|[\\x00-\\x7f\"\\\\\n]){0,40}") {
            let obj = super::ObjName::new("t0").unwrap();
            let ins = super::Instruction::set_text(obj, &text).unwrap();
            let mut buf = [0u8; super::MAX_INSTRUCTION_LEN];
            let n = ins.emit(&mut buf).unwrap();
            let expected = escaped_per_char(&text);
            prop_assert_eq!(&buf[..n], expected.as_slice());
        }
    }

    #[test]
    fn multibyte_text_is_counted_in_characters() {
        // "é" is 2 bytes, "€" 3, "𝄞" 4 (UTF-8, RFC 3629 §3).
        assert_eq!(char_count("aé€𝄞"), 4);
        assert_eq!(first_chars("aé€𝄞", 2), "aé");
        assert_eq!(first_chars("abc", 5), "abc");
    }
}
