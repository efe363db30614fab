//! An independent model of a Nextion (or TJC) touchscreen running the screen
//! file that docs/hmi.md describes, to test the firmware's screen line
//! against a peer it was not written with.
//!
//! Written only from two documents, never from the firmware's screen code:
//!
//! * **The Nextion Instruction Set** (NIS), <https://nextion.tech/instruction-set/>
//!   (mirror <https://nextion.ca/nis/>): §1 general rules, §2 assignments,
//!   §3 operational commands, §6 system variables, §7 return data. Section
//!   numbers in the code and the tests are the NIS's (e.g. "NIS 7.21").
//!   TJC's description of return code 0x24 (wiki2.tjc1688.com) for
//!   [`Overflow::Tjc`].
//! * **docs/hmi.md** §6 (pages, components, ids, types, which events send
//!   their id), typed by hand into [`contract::PAGES`];
//!   `tests/contract_doc.rs` parses the markdown and fails when they differ.
//!
//! # What it does
//!
//! * Receives the MCU's bytes ([`Screen::receive`], or paced at the baud rate
//!   with [`Screen::receive_paced`] / [`Screen::receive_timed`]); an
//!   instruction ends at three `FF` bytes (NIS 1.1) and is executed then
//!   (1.10); an unfinished one waits. The serial buffer holds 1024 bytes
//!   (1.16); when it is full the screen sends `24 FF FF FF` and, as NIS 7.20
//!   says, keeps the instruction being received and loses the queued ones.
//! * Executes `page`, assignments (`obj.val=`, `obj.txt="…"`, `+=`, `-=`,
//!   `page.obj.attr=` for global components only, `p[n].b[m]`), `get`,
//!   `sendme`, `print`/`prints`/`printh`, `vis`, `tsw`, `ref`, `click`,
//!   `rest`, `code_c`, `com_stop`/`com_star`, and the system variables
//!   (`bkcmd`, `dim`/`dims`, `baud`/`bauds`, `sleep`, `thup`, `usup`,
//!   `ussp`, `thsp`, `wup`, `sys0`–`sys2`, `delay`, …). A page load gives
//!   the page's local components their design values back.
//! * Reports each result as `bkcmd` says (NIS 6.13: 0 nothing, 1 success
//!   `01`, 2 failures, 3 both); data replies (`66`, `70`, `71`), touch
//!   events and `24` whatever `bkcmd` is.
//! * The operator: [`Screen::press`], [`Screen::release`], [`Screen::tap`]
//!   send `65 page id event FF FF FF` only where docs/hmi.md ticks "Send
//!   Component ID", only for the page shown, visible and touch-enabled;
//!   [`Screen::type_value`] types into a keyboard field.
//! * What the screen sends, in order, with when each byte has left at the
//!   baud rate (10 bits a byte): [`Screen::take_output`],
//!   [`Screen::take_output_timed`], [`Screen::take_output_until`].
//! * Time is only the caller's (`now_us` arguments; an earlier time than
//!   one already seen counts as the latest). Touches take effect at once,
//!   also while instructions wait to execute.
//!
//! # Choices where the documents are silent
//!
//! Each is a [`Config`] field or documented on the item:
//!
//! * No execution time is documented: instructions and page loads take 0 µs
//!   unless [`Config::instruction_us`] / [`Config::page_load_us`] say
//!   otherwise (then the buffer can fill and overflow).
//! * An empty instruction (`FF FF FF` alone) answers nothing
//!   ([`Config::empty_instruction`]).
//! * A text longer than `txt_maxl` (40, docs/hmi.md §5) is cut, and noted.
//! * Data instructions (`get`, `sendme`, `print*`) answer with their data,
//!   never with an extra `01` at `bkcmd` 3.
//! * Keyboard fields have `vscope` global (the Editor requires it for a
//!   `key`); every other component is local. With [`Keyboard::Popup`] (the
//!   default, as the Editor builds it) typing loads the keyboard page
//!   `keybdB` (id 11) and then the field's page again.
//! * Unknown single words answer 0x1A, other unknown instructions 0x00,
//!   a wrong parameter count 0x1E, a read-only attribute or a value out of a
//!   system variable's range 0x1C.
//!
//! # Example
//!
//! ```
//! use nextion_model::{Screen, Touch};
//!
//! let mut screen = Screen::new();
//! screen.take_output(); // 00 00 00 FF FF FF 88 FF FF FF at power-on
//! screen.receive(1_000, b"page 3\xFF\xFF\xFF");
//! assert_eq!(screen.tap(2_000, "bstart"), (Touch::Sent, Touch::Sent));
//! assert_eq!(
//!     screen.take_output(),
//!     [0x65, 3, 13, 1, 0xFF, 0xFF, 0xFF, 0x65, 3, 13, 0, 0xFF, 0xFF, 0xFF]
//! );
//! ```

pub mod codes;
pub mod contract;
mod exec;
pub mod line;
mod parse;
mod screen;
mod touch;

pub use line::pace;
pub use screen::{
    Config, Executed, Keyboard, KeyboardError, Note, NoteKind, Overflow, Screen, ScreenError,
    Touch, TAP_HOLD_US,
};
