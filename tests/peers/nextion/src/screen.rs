//! The screen: serial receive buffer, execution timing, pages and their
//! components, the operator's touches, and what the screen sends.

use std::collections::{HashMap, VecDeque};

use crate::codes;
use crate::contract::{self, ComponentSpec, PageSpec};
use crate::line::{self, Tx};

/// What happens when the serial buffer is full (NIS 7.20).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Overflow {
    /// Nextion: `0x24`; "Buffer will continue to receive the current
    /// instruction, all previous instructions are lost."
    Nextion,
    /// TJC (wiki2.tjc1688.com, return code 0x24): `0x24`; bytes received
    /// while the buffer is full are discarded until executing the queued
    /// instructions makes room.
    Tjc,
}

/// How the operator types into a number field with its `key` attribute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Keyboard {
    /// As the Nextion Editor builds it: touching the field loads the
    /// keyboard page (`keybdB`, page 11, `dp` = 11, no component of the
    /// user's pages addressable); OK writes the value and loads the field's
    /// page again (its local components back to their design values).
    Popup,
    /// The value appears in the field without a page change.
    InPlace,
}

/// The screen file and device settings the model runs with. `Default` is
/// the screen docs/hmi.md describes; the fields the documents give no
/// number for (times) default to 0.
#[derive(Clone, Debug)]
pub struct Config {
    /// Baud rate at power-on (docs/hmi.md §1: 115 200, set once with `bauds`).
    pub baud: u32,
    /// `bkcmd` at power-on (NIS 6.13: default 2).
    pub bkcmd: u8,
    /// `txt_maxl` of the text components (docs/hmi.md §5: at least 40).
    pub txt_maxl: usize,
    /// Serial buffer size in bytes (NIS 1.16: "all commands+terminations +
    /// data < 1024").
    pub buffer_size: usize,
    /// Behaviour at a full serial buffer.
    pub overflow: Overflow,
    /// Time one instruction takes to execute, µs (not documented: 0).
    pub instruction_us: u64,
    /// Time a page load takes, µs (not documented: 0).
    pub page_load_us: u64,
    /// Time from power-on or `rest` to the startup frames, µs; bytes
    /// received before are lost.
    pub boot_us: u64,
    /// Program.s sends `printh 00 00 00 FF FF FF 88 FF FF FF` at start-up
    /// (the Editor's default since v1.65.0, NIS 1.25, 7.19, 7.29).
    pub startup_frames: bool,
    /// Numeric keyboard.
    pub keyboard: Keyboard,
    /// Code sent for an empty instruction (`FF FF FF` alone), if any. The
    /// instruction set recommends sending one (NIS 6.32) and gives it no
    /// code: `None`.
    pub empty_instruction: Option<u8>,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            baud: line::DEFAULT_BAUD,
            bkcmd: 2,
            txt_maxl: 40,
            buffer_size: 1024,
            overflow: Overflow::Nextion,
            instruction_us: 0,
            page_load_us: 0,
            boot_us: 0,
            startup_frames: true,
            keyboard: Keyboard::Popup,
            empty_instruction: None,
        }
    }
}

/// The result of a touch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Touch {
    /// A `65 page id event FF FF FF` frame was sent.
    Sent,
    /// The component's event does not send its id: nothing sent.
    Silent,
    /// The numeric keyboard page was loaded (release of a keyboard field).
    Keyboard,
    /// No component of that name on the page shown.
    NotShown,
    /// Hidden with `vis`: touch disabled.
    Hidden,
    /// Disabled with `tsw`.
    Disabled,
    /// A release after the page was loaded again since the press.
    PageChanged,
    /// Asleep and `thup`=0: nothing happens.
    Asleep,
    /// Asleep and `thup`=1: the touch only woke the screen (0x87 sent).
    Woke,
    /// Still starting up.
    Booting,
}

/// An instruction the screen executed, and its result.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Executed {
    /// When it completed, µs.
    pub at_us: u64,
    /// The instruction, without its terminator.
    pub instruction: Vec<u8>,
    /// `None`: success; `Some(code)`: the failure code (sent or not).
    pub failure: Option<u8>,
}

/// A failure the screen detected (sent on the line if `bkcmd` allows).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ScreenError {
    /// When, µs.
    pub at_us: u64,
    /// Return code (0x00–0x23, or 0x24 for an overflow).
    pub code: u8,
    /// The instruction concerned (empty for an overflow).
    pub instruction: Vec<u8>,
    /// Whether the code was sent to the MCU.
    pub sent: bool,
}

/// What the model observed that a real screen does silently.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoteKind {
    /// A text longer than `txt_maxl` was cut.
    TextTruncated,
    /// A number constant outside 32 bits was wrapped.
    ValueWrapped,
    /// An instruction received asleep that sleep mode does not execute.
    IgnoredAsleep,
    /// Bytes received while starting up.
    DroppedWhileBooting,
    /// Instructions lost to a buffer overflow, or bytes dropped (TJC).
    LostToOverflow,
    /// An instruction the model accepts without modelling its effect.
    NotModelled,
    /// `code_c` cleared queued instructions.
    Cleared,
}

/// A note of the model (see [`NoteKind`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Note {
    /// When, µs.
    pub at_us: u64,
    /// What.
    pub kind: NoteKind,
    /// Details for a person.
    pub detail: String,
}

/// Why the operator cannot type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyboardError {
    /// No keyboard field of that name on the page shown.
    NotAField,
    /// No keyboard open (Popup mode).
    NotOpen,
    /// The screen does not react to touches (asleep, starting, hidden, disabled).
    NoTouch(Touch),
}

#[derive(Clone, Debug)]
pub(crate) struct CompState {
    pub(crate) val: i32,
    pub(crate) txt: Vec<u8>,
    pub(crate) visible: bool,
    pub(crate) touch: bool,
    pub(crate) attrs: HashMap<&'static str, i32>,
}

impl CompState {
    fn design(c: &ComponentSpec) -> Self {
        CompState {
            val: 0,
            txt: c.design_txt.as_bytes().to_vec(),
            visible: true,
            touch: true,
            attrs: HashMap::new(),
        }
    }
}

#[derive(Debug)]
struct Pending {
    bytes: Vec<u8>,
    received_us: u64,
}

/// System variables (NIS §6) the model keeps.
#[derive(Clone, Debug)]
pub(crate) struct Sys {
    pub(crate) bkcmd: u8,
    pub(crate) dim: i32,
    pub(crate) dims: i32,
    pub(crate) bauds: u32,
    pub(crate) sleep: bool,
    pub(crate) thup: i32,
    pub(crate) usup: i32,
    pub(crate) ussp: i32,
    pub(crate) thsp: i32,
    pub(crate) wup: i32,
    pub(crate) sendxy: i32,
    pub(crate) sys: [i32; 3],
    pub(crate) other: HashMap<&'static str, i32>,
    pub(crate) rand_state: u32,
}

/// A Nextion screen running the screen file of docs/hmi.md.
#[derive(Debug)]
pub struct Screen {
    pub(crate) cfg: Config,
    pub(crate) now_us: u64,
    pub(crate) booting_until: Option<u64>,
    pub(crate) dp: u8,
    /// Incremented at every page load (a release after it is no event).
    pub(crate) load_count: u64,
    pub(crate) sys: Sys,
    pub(crate) comps: HashMap<(u8, u8), CompState>,
    partial: Vec<u8>,
    ff_run: u8,
    queue: VecDeque<Pending>,
    queued_bytes: usize,
    overflowing: bool,
    pub(crate) busy_until: u64,
    pub(crate) com_stopped: bool,
    pub(crate) tx: Tx,
    pub(crate) errors: Vec<ScreenError>,
    pub(crate) notes: Vec<Note>,
    pub(crate) executed: Vec<Executed>,
    pub(crate) keyboard_origin: Option<(u8, u8)>,
    pub(crate) pressed: Option<(u8, u8, u64)>,
    last_serial_us: u64,
    pub(crate) last_touch_us: u64,
    dropped_booting: u64,
}

impl Default for Screen {
    fn default() -> Self {
        Screen::new()
    }
}

impl Screen {
    /// A screen with the default [`Config`], switched on at time 0. Its
    /// startup frames (`00 00 00 FF FF FF 88 FF FF FF`) are in the output.
    pub fn new() -> Self {
        Screen::with_config(Config::default())
    }

    /// A screen with `cfg`, switched on at time 0.
    pub fn with_config(cfg: Config) -> Self {
        let mut s = Screen {
            tx: Tx::new(cfg.baud),
            sys: Sys {
                bkcmd: cfg.bkcmd,
                dim: 100,
                dims: 100,
                bauds: cfg.baud,
                sleep: false,
                thup: 0,
                usup: 0,
                ussp: 0,
                thsp: 0,
                wup: 255,
                sendxy: 0,
                sys: [0; 3],
                other: HashMap::new(),
                rand_state: 0x2545_F491,
            },
            cfg,
            now_us: 0,
            booting_until: None,
            dp: 0,
            load_count: 0,
            comps: HashMap::new(),
            partial: Vec::new(),
            ff_run: 0,
            queue: VecDeque::new(),
            queued_bytes: 0,
            overflowing: false,
            busy_until: 0,
            com_stopped: false,
            errors: Vec::new(),
            notes: Vec::new(),
            executed: Vec::new(),
            keyboard_origin: None,
            pressed: None,
            last_serial_us: 0,
            last_touch_us: 0,
            dropped_booting: 0,
        };
        s.power_on(0);
        s
    }

    /// Switch the screen off and on at `now_us` (also what `rest` does):
    /// everything but `dims` and `bauds` back to power-on values.
    pub fn power_on(&mut self, now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        let at = self.now_us;
        self.sys.bkcmd = self.cfg.bkcmd;
        self.sys.dim = self.sys.dims;
        self.sys.sleep = false;
        self.sys.thup = 0;
        self.sys.usup = 0;
        self.sys.ussp = 0;
        self.sys.thsp = 0;
        self.sys.wup = 255;
        self.sys.sendxy = 0;
        self.sys.sys = [0; 3];
        self.sys.other.clear();
        if self.tx.baud() != self.sys.bauds {
            self.tx.set_baud(at, self.sys.bauds);
        }
        self.comps.clear();
        for p in contract::PAGES {
            for c in p.components {
                self.comps.insert((p.id, c.id), CompState::design(c));
            }
        }
        self.partial.clear();
        self.ff_run = 0;
        self.queue.clear();
        self.queued_bytes = 0;
        self.overflowing = false;
        self.com_stopped = false;
        self.keyboard_origin = None;
        self.pressed = None;
        self.dp = 0;
        self.load_count += 1;
        self.busy_until = at;
        self.last_serial_us = at;
        self.last_touch_us = at;
        self.booting_until = Some(at.saturating_add(self.cfg.boot_us));
        self.finish_boot(at);
    }

    fn finish_boot(&mut self, now_us: u64) {
        let Some(t) = self.booting_until else { return };
        if t > now_us {
            return;
        }
        self.booting_until = None;
        if self.cfg.startup_frames {
            self.tx.send(t, &codes::STARTUP);
            self.tx.send(t, &codes::frame(codes::READY, &[]));
        }
        self.load_page(t, 0);
    }

    // ----- serial input -------------------------------------------------

    /// Bytes from the MCU, all arrived at `now_us` (a caller that cares
    /// about their spacing uses [`Screen::receive_timed`]).
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) {
        for &b in bytes {
            self.receive_byte(now_us, b);
        }
    }

    /// Bytes from the MCU, each with the time it arrived (see
    /// [`crate::pace`]). Times must not decrease.
    pub fn receive_timed(&mut self, bytes: &[(u64, u8)]) {
        for &(t, b) in bytes {
            self.receive_byte(t, b);
        }
    }

    /// Bytes sent back to back by the MCU from `start_us` at the screen's
    /// baud rate; returns when the last one has arrived.
    pub fn receive_paced(&mut self, start_us: u64, bytes: &[u8]) -> u64 {
        let timed = line::pace(start_us, bytes, self.tx.baud());
        self.receive_timed(&timed);
        timed.last().map_or(start_us, |&(t, _)| t)
    }

    fn receive_byte(&mut self, t: u64, b: u8) {
        self.advance(t);
        let t = self.now_us;
        if self.booting_until.is_some() {
            if self.dropped_booting == 0 {
                self.note(
                    t,
                    NoteKind::DroppedWhileBooting,
                    "bytes lost while starting".into(),
                );
            }
            self.dropped_booting += 1;
            return;
        }
        self.last_serial_us = t;
        if self.sys.sleep && self.sys.usup == 1 {
            self.wake(t, true);
        }
        if self.queued_bytes + self.partial.len() >= self.cfg.buffer_size && !self.make_room(t) {
            return;
        }
        self.overflowing = false;
        self.partial.push(b);
        self.ff_run = if b == 0xFF { self.ff_run + 1 } else { 0 };
        if self.ff_run == 3 {
            let mut bytes = std::mem::take(&mut self.partial);
            bytes.truncate(bytes.len() - 3);
            self.ff_run = 0;
            if self.com_stopped && bytes == b"com_star" {
                // NIS 3.14: execution resumes when com_star is received.
                self.com_stopped = false;
            } else {
                self.queued_bytes += bytes.len() + 3;
                self.queue.push_back(Pending {
                    bytes,
                    received_us: t,
                });
            }
        }
        self.run(t);
    }

    /// The buffer is full as byte `t` arrives: report it and make room as
    /// the configured screen does. `false`: the byte is dropped.
    fn make_room(&mut self, t: u64) -> bool {
        if !self.overflowing {
            self.overflowing = true;
            self.tx.send(t, &codes::frame(codes::BUFFER_OVERFLOW, &[]));
            self.errors.push(ScreenError {
                at_us: t,
                code: codes::BUFFER_OVERFLOW,
                instruction: Vec::new(),
                sent: true,
            });
        }
        match self.cfg.overflow {
            Overflow::Nextion => {
                // The instruction being executed has left the buffer.
                let running = self
                    .queue
                    .front()
                    .filter(|p| p.received_us.max(self.busy_until) <= t)
                    .is_some();
                let keep = usize::from(running);
                let lost = self.queue.len() - keep;
                let dropped: usize = self.queue.drain(keep..).map(|p| p.bytes.len() + 3).sum();
                self.queued_bytes -= dropped;
                if self.partial.len() >= self.cfg.buffer_size {
                    self.partial.clear();
                    self.ff_run = 0;
                }
                self.note(
                    t,
                    NoteKind::LostToOverflow,
                    format!("{lost} queued instructions lost"),
                );
                true
            }
            Overflow::Tjc => {
                if self.queue.is_empty() {
                    // Nothing to execute to make room: the unfinished
                    // instruction goes.
                    self.partial.clear();
                    self.ff_run = 0;
                    self.note(
                        t,
                        NoteKind::LostToOverflow,
                        "unfinished instruction lost".into(),
                    );
                    true
                } else {
                    self.note(t, NoteKind::LostToOverflow, "byte dropped".into());
                    false
                }
            }
        }
    }

    /// How long an instruction takes.
    fn duration(&self, bytes: &[u8]) -> u64 {
        if bytes.starts_with(b"page ") || bytes.starts_with(b"dp=") {
            return self.cfg.page_load_us.max(self.cfg.instruction_us);
        }
        if let Some(ms) = bytes.strip_prefix(b"delay=") {
            // NIS 6.11: a halt of `delay` ms; received bytes wait.
            let ms = std::str::from_utf8(ms)
                .ok()
                .and_then(|m| m.parse::<i64>().ok())
                .map_or(0, |m| if m == -1 { 65_535 } else { m.clamp(0, 65_535) });
            return self.cfg.instruction_us + ms.unsigned_abs() * 1_000;
        }
        self.cfg.instruction_us
    }

    /// Execute the queued instructions that complete by `now_us`.
    fn run(&mut self, now_us: u64) {
        while self.booting_until.is_none() && !self.com_stopped {
            let Some(front) = self.queue.front() else {
                break;
            };
            let start = front.received_us.max(self.busy_until);
            let end = start + self.duration(&front.bytes);
            if end > now_us {
                break;
            }
            let Some(p) = self.queue.pop_front() else {
                break;
            };
            self.queued_bytes -= p.bytes.len() + 3;
            self.busy_until = end;
            self.execute(end, &p.bytes);
        }
    }

    /// Let time pass to `now_us`: instructions complete, timers expire.
    pub fn advance(&mut self, now_us: u64) {
        let now = self.now_us.max(now_us);
        self.finish_boot(now);
        // Auto sleep (NIS 6.7 ussp, 6.8 thsp) at the time it falls due.
        if !self.sys.sleep && self.booting_until.is_none() {
            let due = [
                (self.sys.ussp, self.last_serial_us),
                (self.sys.thsp, self.last_touch_us),
            ]
            .iter()
            .filter(|(s, _)| *s > 0)
            .map(|&(s, last)| last + u64::from(s.unsigned_abs()) * 1_000_000)
            .min();
            if let Some(due) = due.filter(|&d| d <= now) {
                self.run(due);
                self.sys.sleep = true;
                self.tx.send(due, &codes::frame(codes::AUTO_SLEEP, &[]));
            }
        }
        self.run(now);
        self.now_us = now;
    }

    /// `code_c`: drop the instructions waiting in the buffer.
    pub(crate) fn clear_queue(&mut self) {
        self.queue.clear();
        self.queued_bytes = 0;
    }

    /// Bytes received and not yet executed (the serial buffer's fill).
    pub fn buffered(&self) -> usize {
        self.queued_bytes + self.partial.len()
    }

    // ----- pages ----------------------------------------------------------

    /// The page spec of a page id the screen file has (with the keyboard
    /// page in Popup mode).
    pub(crate) fn page_spec(&self, id: u8) -> Option<&'static PageSpec> {
        contract::page(id).or((self.cfg.keyboard == Keyboard::Popup
            && id == contract::KEYBOARD_PAGE.id)
            .then_some(&contract::KEYBOARD_PAGE))
    }

    pub(crate) fn page_named(&self, name: &str) -> Option<&'static PageSpec> {
        contract::page_named(name).or((self.cfg.keyboard == Keyboard::Popup
            && name == contract::KEYBOARD_PAGE.name)
            .then_some(&contract::KEYBOARD_PAGE))
    }

    /// Load page `id`: `dp` changes; its local components get their design
    /// values back (global ones keep theirs); `vis`/`tsw` reset.
    pub(crate) fn load_page(&mut self, at_us: u64, id: u8) {
        let Some(p) = self.page_spec(id) else { return };
        for c in p.components {
            let st = self
                .comps
                .entry((p.id, c.id))
                .or_insert_with(|| CompState::design(c));
            if !c.global() {
                *st = CompState::design(c);
            }
            st.visible = true;
            st.touch = true;
        }
        if id != contract::KEYBOARD_PAGE.id {
            // Any other page load closes the keyboard.
            self.keyboard_origin = None;
        }
        self.dp = id;
        self.load_count += 1;
        self.busy_until = self.busy_until.max(at_us);
    }

    /// Leave sleep: `auto` sends 0x87 (NIS 7.28; `sleep=0` sends none).
    pub(crate) fn wake(&mut self, at_us: u64, auto: bool) {
        if !self.sys.sleep {
            return;
        }
        self.sys.sleep = false;
        self.last_serial_us = at_us;
        self.last_touch_us = at_us;
        if auto {
            self.tx.send(at_us, &codes::frame(codes::AUTO_WAKE, &[]));
        }
        // NIS 6.16: wake to page wup; 255: the current page, refreshed only.
        if let Ok(w) = u8::try_from(self.sys.wup) {
            if w != 255 {
                self.load_page(at_us, w);
            }
        }
    }

    pub(crate) fn note(&mut self, at_us: u64, kind: NoteKind, detail: String) {
        self.notes.push(Note {
            at_us,
            kind,
            detail,
        });
    }

    // ----- output ---------------------------------------------------------

    /// Every byte the screen has sent or is sending, in order.
    pub fn take_output(&mut self) -> Vec<u8> {
        self.tx.take_all().into_iter().map(|(_, b)| b).collect()
    }

    /// Every byte with the time its stop bit ends (µs, at the screen's baud).
    pub fn take_output_timed(&mut self) -> Vec<(u64, u8)> {
        self.tx.take_all()
    }

    /// The bytes fully sent by `now_us`; later ones stay queued.
    pub fn take_output_until(&mut self, now_us: u64) -> Vec<(u64, u8)> {
        self.advance(now_us);
        self.tx.take_until(now_us)
    }

    /// Bytes queued for sending and not yet taken.
    pub fn output_queued(&self) -> usize {
        self.tx.pending()
    }

    /// When the screen's transmitter has sent everything queued.
    pub fn output_idle_at_us(&self) -> u64 {
        self.tx.idle_at_us()
    }

    // ----- inspection -------------------------------------------------------

    /// The page shown (`dp`).
    pub fn page(&self) -> u8 {
        self.dp
    }

    /// The name of the page shown.
    pub fn page_name(&self) -> &'static str {
        self.page_spec(self.dp).map_or("", |p| p.name)
    }

    fn state(&self, name: &str) -> Option<(&'static ComponentSpec, &CompState)> {
        let c = self.shown_component(name)?;
        Some((c, self.comps.get(&(c.page, c.id))?))
    }

    /// `.val` of component `name` of the page shown.
    pub fn value(&self, name: &str) -> Option<i32> {
        self.state(name)
            .filter(|(c, _)| c.kind.has_val())
            .map(|(_, s)| s.val)
    }

    /// `.val` of a global component of any page (a keyboard field).
    pub fn global_value(&self, page: u8, name: &str) -> Option<i32> {
        let c = contract::page(page)?.component(name)?;
        c.global()
            .then(|| self.comps.get(&(c.page, c.id)).map(|s| s.val))
            .flatten()
    }

    /// `.txt` of component `name` of the page shown (bytes as stored;
    /// `\r` is stored as 0D 0A).
    pub fn text_bytes(&self, name: &str) -> Option<&[u8]> {
        self.state(name)
            .filter(|(c, _)| c.kind.has_txt())
            .map(|(_, s)| s.txt.as_slice())
    }

    /// `.txt` of component `name` of the page shown, as a string.
    pub fn text(&self, name: &str) -> Option<String> {
        self.text_bytes(name)
            .map(|t| String::from_utf8_lossy(t).into_owned())
    }

    /// What component `name` shows a person: its text, or its value with
    /// the Xfloat's decimals (`2521` with 2 decimals shows "25.21").
    pub fn shown(&self, name: &str) -> Option<String> {
        let (c, s) = self.state(name)?;
        Some(match c.kind {
            contract::Kind::Text | contract::Kind::Button => {
                String::from_utf8_lossy(&s.txt).into_owned()
            }
            contract::Kind::Number => s.val.to_string(),
            contract::Kind::Xfloat { decimals } => {
                let scale = 10u64.pow(u32::from(decimals));
                let a = u64::from(s.val.unsigned_abs());
                let sign = if s.val < 0 { "-" } else { "" };
                if decimals == 0 {
                    format!("{sign}{a}")
                } else {
                    format!(
                        "{sign}{}.{:0w$}",
                        a / scale,
                        a % scale,
                        w = usize::from(decimals)
                    )
                }
            }
        })
    }

    /// Whether component `name` of the page shown is visible (`vis`).
    pub fn visible(&self, name: &str) -> Option<bool> {
        self.state(name).map(|(_, s)| s.visible)
    }

    /// Whether component `name` of the page shown takes touches (`tsw`).
    pub fn touch_enabled(&self, name: &str) -> Option<bool> {
        self.state(name).map(|(_, s)| s.touch)
    }

    /// `bkcmd` in force.
    pub fn bkcmd(&self) -> u8 {
        self.sys.bkcmd
    }

    /// Backlight in percent (`dim`).
    pub fn brightness(&self) -> i32 {
        self.sys.dim
    }

    /// Saved power-on backlight (`dims`).
    pub fn saved_brightness(&self) -> i32 {
        self.sys.dims
    }

    /// Baud rate in force.
    pub fn baud(&self) -> u32 {
        self.tx.baud()
    }

    /// Whether the screen sleeps.
    pub fn asleep(&self) -> bool {
        self.sys.sleep
    }

    /// Whether the screen is still starting up.
    pub fn booting(&self) -> bool {
        self.booting_until.is_some()
    }

    /// Every failure the screen detected, reported or not.
    pub fn errors(&self) -> &[ScreenError] {
        &self.errors
    }

    /// What the model observed that a screen does silently.
    pub fn notes(&self) -> &[Note] {
        &self.notes
    }

    /// Every instruction executed, in order, with its result.
    pub fn executed(&self) -> &[Executed] {
        &self.executed
    }
}

/// How long [`Screen::tap`] holds the finger down, µs.
pub const TAP_HOLD_US: u64 = 100_000;
