//! Nextion/TJC serial touchscreen protocol for the transplanter firmware.
//!
//! * [`Decoder`]: streaming, byte-at-a-time decoder of the screen's return
//!   frames ([`Frame`]), with resynchronisation and drop counters;
//! * [`Instruction`]: checked construction and emission of the MCU's instructions;
//! * [`screen`]: the machine's page/component contract, typed [`screen::Command`]s
//!   with validated parameters, and the status values written to the screen;
//! * [`hmi`]: the sans-IO application layer ([`hmi::Hmi`]) joining the two;
//! * `virtual_screen` (feature `std`): a host-side simulated touchscreen;
//! * `export` (feature `std`): the contract as JSON for screens built
//!   outside the firmware (the browser screen, docs/screen-web.md).
//!
//! `no_std`, no heap, and no reachable panic: every parse and emit returns a
//! typed error instead. See `docs/hmi.md` for the screen file a user builds.
//!
//! Wire format: every instruction and every return frame ends with
//! `0xFF 0xFF 0xFF` ([`TERMINATOR`]).
#![no_std]
#![forbid(unsafe_code)]

#[cfg(any(test, feature = "std"))]
extern crate std;

mod cursor;
pub mod decoder;
pub mod encoder;
#[cfg(feature = "std")]
pub mod export;
pub mod frame;
pub mod hmi;
pub mod screen;
#[cfg(feature = "std")]
pub mod virtual_screen;

pub use cursor::TERMINATOR;
pub use decoder::{DecodeError, Decoder, DecoderStats};
pub use encoder::{
    Attr, BaudRate, BkCmd, EncodeError, Instruction, NameError, ObjName, ScreenText,
    MAX_INSTRUCTION_LEN, MAX_NAME_SEGMENT, MAX_TEXT_LEN,
};
pub use frame::{ErrorCode, Frame, Text, TextError, TouchEvent, MAX_STRING_LEN};
