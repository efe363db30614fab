//! Syntax of one instruction (the bytes before its `FF FF FF`), after the
//! Nextion Instruction Set §1 (general rules) and §2 (assignments):
//!
//! * 1.3 instructions are lower case; 1.5 one space separates the command
//!   from its parameters; 1.6 no spaces in parameters (printh excepted,
//!   3.18); parameters are separated by commas.
//! * 1.12 no order of operations: `a+b*c` evaluates left to right; no
//!   parentheses.
//! * 1.14 text values in double quotes; 1.11 escapes `\r` (bytes 0D 0A),
//!   `\"`, `\\`; any other escape is 0x20.
//! * 1.18/1.26 hex constants `0x` with an even number of digits; odd: 0x1A.

use crate::codes;

/// Operators of an assignment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum AssignOp {
    Set,
    Add,
    Sub,
    Mul,
    Div,
    Rem,
    Inc,
    Dec,
}

/// An instruction, split.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Instr<'a> {
    /// No byte before the terminator.
    Empty,
    /// `target op value` (`value` empty for `++`/`--`).
    Assign {
        target: &'a [u8],
        op: AssignOp,
        value: &'a [u8],
    },
    /// `command params` with its parameters split.
    Command {
        name: &'a str,
        params: Vec<&'a [u8]>,
    },
    /// One word that is neither a command nor an assignment (a bare name
    /// or number): 0x1A.
    Bare,
    /// Anything else: 0x00.
    Invalid,
}

/// The commands of NIS §3 the model knows by name.
pub(crate) const COMMANDS: &[&str] = &[
    "page", "ref", "click", "ref_stop", "ref_star", "get", "sendme", "covx", "cov", "touch_j",
    "substr", "vis", "tsw", "com_stop", "com_star", "randset", "code_c", "prints", "print",
    "printh", "add", "addt", "cle", "rest", "doevents", "strlen", "btlen", "wepo", "repo", "wept",
    "rept", "cfgpio", "ucopy", "move", "play", "twfile", "delfile", "refile", "findfile", "rdfile",
    "setlayer", "newdir", "deldir", "redir", "finddir", "udelete", "crcrest", "crcputs", "crcputh",
    "crcputu", "spstr", "newfile", // GUI commands (NIS §4)
    "cls", "pic", "picq", "xpic", "xstr", "fill", "line", "draw", "draw3d", "cir", "cirs",
    "qrcode",
];

/// Index of the first byte `b` outside a quoted text.
fn find_outside_quotes(s: &[u8], want: impl Fn(u8) -> bool) -> Option<usize> {
    let mut quoted = false;
    let mut escaped = false;
    for (i, &b) in s.iter().enumerate() {
        if quoted {
            if escaped {
                escaped = false;
            } else if b == b'\\' {
                escaped = true;
            } else if b == b'"' {
                quoted = false;
            }
        } else if b == b'"' {
            quoted = true;
        } else if want(b) {
            return Some(i);
        }
    }
    None
}

/// Split `s` at every `sep` outside quotes.
pub(crate) fn split_outside_quotes(s: &[u8], sep: u8) -> Vec<&[u8]> {
    let mut parts = Vec::new();
    let mut rest = s;
    while let Some(i) = find_outside_quotes(rest, |b| b == sep) {
        parts.push(&rest[..i]);
        rest = &rest[i + 1..];
    }
    parts.push(rest);
    parts
}

/// Split an instruction.
pub(crate) fn instruction(s: &[u8]) -> Instr<'_> {
    if s.is_empty() {
        return Instr::Empty;
    }
    let space = find_outside_quotes(s, |b| b == b' ');
    let word = &s[..space.unwrap_or(s.len())];
    if let Ok(name) = std::str::from_utf8(word) {
        if let Some(&cmd) = COMMANDS.iter().find(|&&c| c == name) {
            let params = match space {
                None => Vec::new(),
                Some(i) => {
                    let rest = &s[i + 1..];
                    if cmd == "printh" {
                        rest.split(|&b| b == b' ').collect()
                    } else {
                        split_outside_quotes(rest, b',')
                    }
                }
            };
            return Instr::Command { name: cmd, params };
        }
    }
    if let Some(eq) = find_outside_quotes(s, |b| b == b'=') {
        let (target, op) = match eq.checked_sub(1).map(|i| s[i]) {
            Some(b'+') => (&s[..eq - 1], AssignOp::Add),
            Some(b'-') => (&s[..eq - 1], AssignOp::Sub),
            Some(b'*') => (&s[..eq - 1], AssignOp::Mul),
            Some(b'/') => (&s[..eq - 1], AssignOp::Div),
            Some(b'%') => (&s[..eq - 1], AssignOp::Rem),
            _ => (&s[..eq], AssignOp::Set),
        };
        return Instr::Assign {
            target,
            op,
            value: &s[eq + 1..],
        };
    }
    if space.is_none() {
        if let Some(t) = s.strip_suffix(b"++") {
            return Instr::Assign {
                target: t,
                op: AssignOp::Inc,
                value: b"",
            };
        }
        if let Some(t) = s.strip_suffix(b"--") {
            return Instr::Assign {
                target: t,
                op: AssignOp::Dec,
                value: b"",
            };
        }
        return Instr::Bare;
    }
    Instr::Invalid
}

/// One segment of a name: `name` or `p[3]` / `b[4]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Seg<'a> {
    Ident(&'a str),
    Index(u8, u32),
}

/// Longest page or component name (NIS 7.18: 14 + "." + 14).
pub(crate) const MAX_NAME: usize = 14;

/// Parse a dotted name (`sys0`, `t0.txt`, `page1.t0.txt`, `p[1].b[2].val`).
/// `Err(code)`: not a name (0x1A) or a segment too long (0x23).
pub(crate) fn name(s: &[u8]) -> Result<Vec<Seg<'_>>, u8> {
    let text = std::str::from_utf8(s).map_err(|_| codes::INVALID_VARIABLE)?;
    let mut segs = Vec::new();
    for part in text.split('.') {
        if part.is_empty() {
            return Err(codes::INVALID_VARIABLE);
        }
        if let Some(inner) = part
            .strip_suffix(']')
            .and_then(|p| p.strip_prefix("p[").or_else(|| p.strip_prefix("b[")))
        {
            let n: u32 = inner.parse().map_err(|_| codes::INVALID_VARIABLE)?;
            segs.push(Seg::Index(part.as_bytes()[0], n));
            continue;
        }
        if !part.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            || part.as_bytes()[0].is_ascii_digit()
        {
            return Err(codes::INVALID_VARIABLE);
        }
        if part.len() > MAX_NAME {
            return Err(codes::NAME_TOO_LONG);
        }
        segs.push(Seg::Ident(part));
    }
    Ok(segs)
}

/// A quoted text value with its escapes decoded (NIS 1.11).
pub(crate) fn text_literal(s: &[u8]) -> Result<Vec<u8>, u8> {
    let inner = s
        .strip_prefix(b"\"")
        .and_then(|r| r.strip_suffix(b"\""))
        .ok_or(codes::INVALID_OPERATION)?;
    let mut out = Vec::with_capacity(inner.len());
    let mut it = inner.iter();
    while let Some(&b) = it.next() {
        match b {
            b'\\' => match it.next() {
                Some(b'r') => out.extend_from_slice(b"\r\n"),
                Some(b'"') => out.push(b'"'),
                Some(b'\\') => out.push(b'\\'),
                _ => return Err(codes::INVALID_ESCAPE),
            },
            // An unescaped quote inside: two texts, not one.
            b'"' => return Err(codes::INVALID_OPERATION),
            _ => out.push(b),
        }
    }
    Ok(out)
}

/// A numeric constant: decimal with an optional `-`, or `0x` hex with an
/// even number of digits (NIS 1.26), wrapped to 32 bits. `Ok(None)`: not a
/// number at all. `Err`: a malformed hex constant (0x1A).
pub(crate) fn number(s: &[u8]) -> Result<Option<(i32, bool)>, u8> {
    if let Some(hex) = s.strip_prefix(b"0x") {
        if hex.is_empty() || hex.len() % 2 != 0 || hex.len() > 8 {
            return Err(codes::INVALID_VARIABLE);
        }
        let t = std::str::from_utf8(hex).map_err(|_| codes::INVALID_VARIABLE)?;
        let v = u32::from_str_radix(t, 16).map_err(|_| codes::INVALID_VARIABLE)?;
        return Ok(Some((v as i32, false)));
    }
    let digits = s.strip_prefix(b"-").unwrap_or(s);
    if digits.is_empty() || !digits.iter().all(u8::is_ascii_digit) {
        return Ok(None);
    }
    // Digits only: parse as wide as possible and wrap like a 32-bit register.
    let mut v: i128 = 0;
    for &d in digits {
        v = (v * 10 + i128::from(d - b'0')).min(i128::from(u64::MAX));
    }
    if s.starts_with(b"-") {
        v = -v;
    }
    let wrapped = v as i32;
    Ok(Some((wrapped, i128::from(wrapped) != v)))
}

/// A numeric expression split into operands and operators, evaluated left
/// to right (NIS 1.12). Operands are returned raw for the caller to resolve.
pub(crate) fn numeric_terms(s: &[u8]) -> Result<(Vec<&[u8]>, Vec<u8>), u8> {
    let mut operands = Vec::new();
    let mut ops = Vec::new();
    let mut start = 0;
    let mut i = 0;
    while i < s.len() {
        let b = s[i];
        // A '-' right at an operand's start is its sign.
        let is_sign = b == b'-' && i == start;
        if matches!(b, b'+' | b'-' | b'*' | b'/' | b'%') && !is_sign {
            operands.push(&s[start..i]);
            ops.push(b);
            start = i + 1;
        } else if matches!(b, b'(' | b')' | b'"' | b' ') {
            return Err(codes::INVALID_OPERATION);
        }
        i += 1;
    }
    operands.push(&s[start..]);
    if operands.iter().any(|o| o.is_empty()) {
        return Err(codes::INVALID_OPERATION);
    }
    Ok((operands, ops))
}

/// Apply one operator with 32-bit wrapping; `None` on division by zero.
pub(crate) fn apply(op: u8, a: i32, b: i32) -> Option<i32> {
    match op {
        b'+' => Some(a.wrapping_add(b)),
        b'-' => Some(a.wrapping_sub(b)),
        b'*' => Some(a.wrapping_mul(b)),
        b'/' => a
            .checked_div(b)
            .or_else(|| (b == -1).then(|| a.wrapping_neg())),
        b'%' => a.checked_rem(b).or((b == -1).then_some(0)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn assignments_and_commands_split() {
        assert_eq!(
            instruction(b"t0.txt=\"a b, c\""),
            Instr::Assign {
                target: b"t0.txt",
                op: AssignOp::Set,
                value: b"\"a b, c\""
            }
        );
        assert_eq!(
            instruction(b"n0.val+=4"),
            Instr::Assign {
                target: b"n0.val",
                op: AssignOp::Add,
                value: b"4"
            }
        );
        assert_eq!(
            instruction(b"vis b0,1"),
            Instr::Command {
                name: "vis",
                params: vec![&b"b0"[..], &b"1"[..]]
            }
        );
        assert_eq!(
            instruction(b"printh 0d 0a"),
            Instr::Command {
                name: "printh",
                params: vec![&b"0d"[..], &b"0a"[..]]
            }
        );
        assert_eq!(instruction(b"abc"), Instr::Bare);
        assert_eq!(instruction(b"PAGE 1"), Instr::Invalid);
        assert_eq!(instruction(b""), Instr::Empty);
    }

    #[test]
    fn text_escapes_follow_nis_1_11() {
        assert_eq!(text_literal(b"\"a\\rb\""), Ok(b"a\r\nb".to_vec()));
        assert_eq!(text_literal(b"\"\\\"\\\\\""), Ok(b"\"\\".to_vec()));
        assert_eq!(text_literal(b"\"\\n\""), Err(codes::INVALID_ESCAPE));
        assert_eq!(text_literal(b"abc"), Err(codes::INVALID_OPERATION));
    }

    #[test]
    fn numbers_follow_nis_1_18_and_1_26() {
        assert_eq!(number(b"0x01FF"), Ok(Some((0x01FF, false))));
        assert_eq!(number(b"0x123"), Err(codes::INVALID_VARIABLE));
        assert_eq!(number(b"-12"), Ok(Some((-12, false))));
        assert_eq!(number(b"4294967295"), Ok(Some((-1, true))));
        assert_eq!(number(b"abc"), Ok(None));
    }

    #[test]
    fn names_are_at_most_14_characters_a_segment() {
        assert!(name(b"page1.t0.txt").is_ok());
        assert_eq!(name(b"p[1].b[2].val").map(|s| s.len()), Ok(3));
        assert_eq!(name(b"abcdefghijklmno.val"), Err(codes::NAME_TOO_LONG));
        assert_eq!(name(b"t0..txt"), Err(codes::INVALID_VARIABLE));
    }
}
