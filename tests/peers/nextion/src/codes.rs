//! Nextion Return Data (NIS §7, "Format of Nextion Return Data").
//!
//! Table 1 (codes 0x00–0x23) depends on `bkcmd` (NIS 6.13): level 0 sends
//! none, 1 only 0x01 success, 2 only failures (the power-on default), 3 both.
//! Table 2 (startup, 0x24 overflow, 0x65 touch, 0x66 page, 0x67/0x68
//! coordinates, 0x70/0x71 data, 0x86–0x89, 0xFD/0xFE) is sent whatever
//! `bkcmd` is.

/// The terminator of every instruction and every return frame (NIS 1.1).
pub const TERMINATOR: [u8; 3] = [0xFF, 0xFF, 0xFF];

/// 0x00 Invalid Instruction.
pub const INVALID_INSTRUCTION: u8 = 0x00;
/// 0x01 Instruction Successful (bkcmd 1 and 3).
pub const SUCCESS: u8 = 0x01;
/// 0x02 Invalid Component ID (invalid component id or name).
pub const INVALID_COMPONENT: u8 = 0x02;
/// 0x03 Invalid Page ID (invalid page id or name).
pub const INVALID_PAGE: u8 = 0x03;
/// 0x11 Invalid Baud rate Setting.
pub const INVALID_BAUD: u8 = 0x11;
/// 0x1A Invalid Variable name or attribute.
pub const INVALID_VARIABLE: u8 = 0x1A;
/// 0x1B Invalid Variable Operation (`t0.txt=abc`, `t0.txt=23`, `j0.val="50"`).
pub const INVALID_OPERATION: u8 = 0x1B;
/// 0x1C Assignment failed to assign.
pub const ASSIGNMENT_FAILED: u8 = 0x1C;
/// 0x1E Invalid Quantity of Parameters.
pub const INVALID_PARAMETER_COUNT: u8 = 0x1E;
/// 0x20 Escape Character Invalid.
pub const INVALID_ESCAPE: u8 = 0x20;
/// 0x23 Variable name too long (more than 29 characters: 14 + "." + 14).
pub const NAME_TOO_LONG: u8 = 0x23;
/// 0x24 Serial Buffer Overflow (not subject to bkcmd).
pub const BUFFER_OVERFLOW: u8 = 0x24;
/// 0x65 Touch Event header: page, component, event (1 press, 0 release).
pub const TOUCH_EVENT: u8 = 0x65;
/// 0x66 Current Page Number header (reply to `sendme`).
pub const CURRENT_PAGE: u8 = 0x66;
/// 0x70 String Data header (reply to `get` of a text).
pub const STRING_DATA: u8 = 0x70;
/// 0x71 Numeric Data header: 4 bytes little-endian (reply to `get` of a number).
pub const NUMERIC_DATA: u8 = 0x71;
/// 0x86 Auto Entered Sleep Mode.
pub const AUTO_SLEEP: u8 = 0x86;
/// 0x87 Auto Wake from Sleep.
pub const AUTO_WAKE: u8 = 0x87;
/// 0x88 Nextion Ready.
pub const READY: u8 = 0x88;

/// The startup frame `00 00 00 FF FF FF` (NIS 7.19).
pub const STARTUP: [u8; 6] = [0x00, 0x00, 0x00, 0xFF, 0xFF, 0xFF];

/// A frame: `header payload FF FF FF`.
pub fn frame(header: u8, payload: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(payload.len() + 4);
    f.push(header);
    f.extend_from_slice(payload);
    f.extend_from_slice(&TERMINATOR);
    f
}

/// Whether the result of an instruction (`None` success, `Some(code)`
/// failure) is reported at this `bkcmd` level (NIS 6.13, §7 table 1).
pub fn reported(bkcmd: u8, failure: Option<u8>) -> bool {
    match failure {
        None => bkcmd == 1 || bkcmd == 3,
        Some(_) => bkcmd == 2 || bkcmd == 3,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bkcmd_levels_follow_nis_6_13() {
        let e = Some(INVALID_VARIABLE);
        assert_eq!(
            (0..=3u8)
                .map(|l| (reported(l, None), reported(l, e)))
                .collect::<Vec<_>>(),
            vec![(false, false), (true, false), (false, true), (true, true)]
        );
    }
}
