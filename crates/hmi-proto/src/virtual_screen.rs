//! A virtual Nextion/TJC touchscreen for the host (feature `std`).
//!
//! It holds pages and component values, executes the MCU's instruction
//! stream (fed in arbitrary pieces), answers `get`/`sendme` with return
//! frames, reports errors per `bkcmd`, and produces touch events for named
//! components. It talks bytes only, so the same object serves QEMU tests
//! (socket to the emulated USART) and, later, a real serial port.
//!
//! Behaviour modelled on the Nextion Instruction Set
//! (<https://nextion.tech/instruction-set/>): a `page` load resets the page's
//! components to their editor defaults (0 / empty); `bkcmd` defaults to 2
//! (failures only); `rest` answers with the startup frame and `0x88`; text
//! longer than `txt_maxl` is cut; an instruction longer than the serial
//! buffer gives `0x24`. Not modelled: sleep timers, transparent data, `prints`.
//!
//! ```
//! use hmi_proto::virtual_screen::VirtualScreen;
//!
//! let mut screen = VirtualScreen::with_contract();
//! screen.feed(b"page 3\xff\xff\xffnspacing.val=70\xff");
//! screen.feed(b"\xff\xffget nspacing.val\xff\xff\xff");
//! assert_eq!(screen.take_output(), b"\x71\x46\x00\x00\x00\xff\xff\xff");
//! screen.release("bapply").unwrap();
//! assert_eq!(screen.take_output(), b"\x65\x03\x02\x00\xff\xff\xff");
//! ```

// Host-only test tool: plain indexing/arithmetic on `Vec`s is acceptable here;
// it never runs on the MCU.
#![allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation
)]

use std::collections::VecDeque;
use std::fmt;
use std::string::{String, ToString};
use std::vec::Vec;

use crate::frame::{ErrorCode, Frame, Text, TouchEvent};
use crate::screen::{Action, Kind, Page, Role, COMPONENTS};
use crate::TERMINATOR;

/// Size of the screen's serial instruction buffer (Nextion: 1024 bytes).
pub const SERIAL_BUFFER: usize = 1024;
/// `txt_maxl` of every text component of the virtual screen.
pub const TXT_MAXL: usize = 40;

/// Misuse of the virtual screen by a test.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VirtualError {
    /// No component of that name on the current page.
    NoSuchComponent(String),
    /// Touch is disabled for the component (`tsw … ,0`) or it is hidden.
    NotTouchable(String),
}

impl fmt::Display for VirtualError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoSuchComponent(n) => write!(f, "no component {n:?} on the current page"),
            Self::NotTouchable(n) => write!(f, "component {n:?} is hidden or touch-disabled"),
        }
    }
}

impl std::error::Error for VirtualError {}

/// One component of the virtual screen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VirtualComponent {
    /// Page id.
    pub page: u8,
    /// Component id.
    pub id: u8,
    /// Object name.
    pub name: String,
    /// `true` if it has `.txt` (else `.val`).
    pub is_text: bool,
    /// Sends its id on press.
    pub send_on_press: bool,
    /// Sends its id on release.
    pub send_on_release: bool,
    /// Current `.val`.
    pub val: i32,
    /// Current `.txt`.
    pub txt: String,
    /// `vis` state.
    pub visible: bool,
    /// `tsw` state.
    pub touch: bool,
}

/// The simulated screen.
#[derive(Debug, Clone)]
pub struct VirtualScreen {
    pages: Vec<String>,
    comps: Vec<VirtualComponent>,
    page: u8,
    rx: Vec<u8>,
    out: VecDeque<u8>,
    log: Vec<String>,
    bkcmd: u8,
    dims: u8,
    sleeping: bool,
    baud: u32,
}

impl VirtualScreen {
    /// A screen with the given page names (id = index) and components.
    pub fn new(pages: Vec<String>, comps: Vec<VirtualComponent>) -> Self {
        Self {
            pages,
            comps,
            page: 0,
            rx: Vec::new(),
            out: VecDeque::new(),
            log: Vec::new(),
            bkcmd: 2,
            dims: 100,
            sleeping: false,
            baud: 115_200,
        }
    }

    /// The transplanter's screen file ([`crate::screen::COMPONENTS`]): buttons
    /// send their id on release, Stop buttons and the motor-starting
    /// buttons (Start, Identify: [`Action::starts_motor`]) on press too
    /// (docs/hmi.md §3).
    /// Shows page 0; call [`boot`](Self::boot)
    /// to emit the power-on frames.
    pub fn with_contract() -> Self {
        let pages = Page::ALL.iter().map(|p| p.name().to_string()).collect();
        let comps = COMPONENTS
            .iter()
            .map(|c| VirtualComponent {
                page: c.page.id(),
                id: c.id(),
                name: c.name().to_string(),
                is_text: c.kind() == Kind::Text,
                send_on_press: matches!(
                    c.role,
                    Role::Action(a) if a == Action::Stop || a.starts_motor()
                ),
                send_on_release: c.kind() == Kind::Button,
                val: 0,
                txt: String::new(),
                visible: true,
                touch: true,
            })
            .collect();
        Self::new(pages, comps)
    }

    /// Power-on: page 0, defaults, then the startup frame and `0x88` ready.
    pub fn boot(&mut self) {
        self.page = 0;
        self.rx.clear();
        self.bkcmd = 2;
        self.sleeping = false;
        for c in &mut self.comps {
            c.val = 0;
            c.txt.clear();
            c.visible = true;
            c.touch = true;
        }
        self.send(&Frame::Startup);
        self.send(&Frame::Ready);
    }

    /// Bytes from the MCU, split anywhere.
    pub fn feed(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.rx.push(b);
            if self.rx.ends_with(&TERMINATOR) {
                let n = self.rx.len() - 3;
                let ins: Vec<u8> = self.rx.drain(..).take(n).collect();
                if ins.len() > SERIAL_BUFFER {
                    self.fail(ErrorCode::BufferOverflow);
                } else {
                    self.execute(&ins);
                }
            } else if self.rx.len() > SERIAL_BUFFER + 3 {
                // The real screen drops what does not fit.
                self.rx.clear();
                self.fail(ErrorCode::BufferOverflow);
            }
        }
    }

    /// Bytes the screen wants to send to the MCU (drained).
    pub fn take_output(&mut self) -> Vec<u8> {
        self.out.drain(..).collect()
    }

    /// Queues raw bytes as if the screen sent them (error injection).
    pub fn send_raw(&mut self, bytes: &[u8]) {
        self.out.extend(bytes.iter().copied());
    }

    /// Queues a return frame.
    pub fn send(&mut self, frame: &Frame) {
        let mut buf = [0u8; 64];
        if let Ok(n) = frame.emit(&mut buf) {
            self.out.extend(buf[..n].iter().copied());
        }
    }

    /// The page shown.
    pub fn page(&self) -> u8 {
        self.page
    }

    /// Every instruction executed, as (lossy) text, oldest first.
    pub fn instructions(&self) -> &[String] {
        &self.log
    }

    /// Forgets the instruction log.
    pub fn clear_log(&mut self) {
        self.log.clear();
    }

    /// Current `bkcmd`.
    pub fn bkcmd(&self) -> u8 {
        self.bkcmd
    }

    /// Current brightness (`dims`).
    pub fn brightness(&self) -> u8 {
        self.dims
    }

    /// Current baud rate.
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// `true` after `sleep=1`.
    pub fn is_sleeping(&self) -> bool {
        self.sleeping
    }

    /// A component on the current page, or `page.name` anywhere.
    pub fn component(&self, name: &str) -> Option<&VirtualComponent> {
        self.find(name).map(|i| &self.comps[i])
    }

    /// `.val` of a component on the current page (or `page.name`).
    pub fn value(&self, name: &str) -> Option<i32> {
        self.component(name).map(|c| c.val)
    }

    /// `.txt` of a component on the current page (or `page.name`).
    pub fn text(&self, name: &str) -> Option<&str> {
        self.component(name).map(|c| c.txt.as_str())
    }

    /// The operator types a number into a field (no frame is sent).
    pub fn set_value(&mut self, name: &str, val: i32) -> Result<(), VirtualError> {
        let i = self.find_or_err(name)?;
        self.comps[i].val = val;
        Ok(())
    }

    /// The operator types a text into a field (no frame is sent).
    pub fn set_text(&mut self, name: &str, txt: &str) -> Result<(), VirtualError> {
        let i = self.find_or_err(name)?;
        self.comps[i].txt = txt.to_string();
        Ok(())
    }

    /// The operator presses a component on the current page.
    pub fn press(&mut self, name: &str) -> Result<(), VirtualError> {
        self.touch(name, TouchEvent::Press)
    }

    /// The operator releases a component on the current page.
    pub fn release(&mut self, name: &str) -> Result<(), VirtualError> {
        self.touch(name, TouchEvent::Release)
    }

    /// Press then release.
    pub fn tap(&mut self, name: &str) -> Result<(), VirtualError> {
        self.press(name)?;
        self.release(name)
    }

    fn touch(&mut self, name: &str, event: TouchEvent) -> Result<(), VirtualError> {
        let i = self.find_or_err(name)?;
        let c = &self.comps[i];
        if c.page != self.page || !c.visible || !c.touch {
            return Err(VirtualError::NotTouchable(name.to_string()));
        }
        let sends = match event {
            TouchEvent::Press => c.send_on_press,
            TouchEvent::Release => c.send_on_release,
        };
        if sends {
            let f = Frame::Touch {
                page: c.page,
                component: c.id,
                event,
            };
            self.send(&f);
        }
        Ok(())
    }

    fn find_or_err(&self, name: &str) -> Result<usize, VirtualError> {
        self.find(name)
            .ok_or_else(|| VirtualError::NoSuchComponent(name.to_string()))
    }

    fn find(&self, name: &str) -> Option<usize> {
        let (page, obj) = match name.split_once('.') {
            Some((p, o)) => (self.page_id(p)?, o),
            None => (self.page, name),
        };
        self.comps
            .iter()
            .position(|c| c.page == page && c.name == obj)
    }

    fn page_id(&self, s: &str) -> Option<u8> {
        match s.parse::<u8>() {
            Ok(n) if usize::from(n) < self.pages.len() => Some(n),
            Ok(_) => None,
            Err(_) => self
                .pages
                .iter()
                .position(|p| p == s)
                .and_then(|i| u8::try_from(i).ok()),
        }
    }

    fn ok(&mut self) {
        if self.bkcmd == 1 || self.bkcmd == 3 {
            self.send(&Frame::Success);
        }
    }

    fn fail(&mut self, code: ErrorCode) {
        if self.bkcmd >= 2 {
            self.send(&Frame::Error(code));
        }
    }

    fn load_page(&mut self, id: u8) {
        self.page = id;
        for c in self.comps.iter_mut().filter(|c| c.page == id) {
            c.val = 0;
            c.txt.clear();
            c.visible = true;
            c.touch = true;
        }
    }

    fn execute(&mut self, ins: &[u8]) {
        let s = String::from_utf8_lossy(ins).into_owned();
        self.log.push(s.clone());
        if s.is_empty() {
            return;
        }
        match self.run(&s) {
            Ok(()) => {}
            Err(code) => self.fail(code),
        }
    }

    fn run(&mut self, s: &str) -> Result<(), ErrorCode> {
        use ErrorCode as E;
        if let Some(arg) = s.strip_prefix("page ") {
            let id = self.page_id(arg.trim()).ok_or(E::InvalidPage)?;
            self.load_page(id);
            self.ok();
            return Ok(());
        }
        if let Some(arg) = s.strip_prefix("get ") {
            let (obj, attr) = arg.rsplit_once('.').ok_or(E::InvalidVariable)?;
            let i = self.find(obj).ok_or(E::InvalidVariable)?;
            let c = &self.comps[i];
            let frame = match attr {
                "val" if !c.is_text => Frame::Number(c.val),
                "txt" if c.is_text => {
                    let t: Vec<u8> = c.txt.bytes().take(crate::MAX_STRING_LEN).collect();
                    Frame::Text(Text::new(&t).map_err(|_| E::InvalidVariable)?)
                }
                _ => return Err(E::InvalidVariable),
            };
            self.send(&frame);
            return Ok(());
        }
        if s == "sendme" {
            let p = self.page;
            self.send(&Frame::CurrentPage(p));
            return Ok(());
        }
        if s == "rest" {
            self.boot();
            return Ok(());
        }
        for (cmd, is_vis) in [("vis ", true), ("tsw ", false)] {
            if let Some(arg) = s.strip_prefix(cmd) {
                let (obj, on) = arg.split_once(',').ok_or(E::InvalidParameterCount)?;
                let on = match on.trim() {
                    "0" => false,
                    "1" => true,
                    _ => return Err(E::InvalidOperation),
                };
                let obj = obj.trim();
                if obj == "255" {
                    let page = self.page;
                    for c in self.comps.iter_mut().filter(|c| c.page == page) {
                        if is_vis {
                            c.visible = on;
                        } else {
                            c.touch = on;
                        }
                    }
                } else {
                    let i = self.find(obj).ok_or(E::InvalidComponent)?;
                    if is_vis {
                        self.comps[i].visible = on;
                    } else {
                        self.comps[i].touch = on;
                    }
                }
                self.ok();
                return Ok(());
            }
        }
        if let Some(arg) = s.strip_prefix("ref ") {
            self.find(arg.trim()).ok_or(E::InvalidComponent)?;
            self.ok();
            return Ok(());
        }
        if let Some((lhs, rhs)) = s.split_once('=') {
            return self.assign(lhs, rhs);
        }
        Err(E::InvalidInstruction)
    }

    fn assign(&mut self, lhs: &str, rhs: &str) -> Result<(), ErrorCode> {
        use ErrorCode as E;
        let num = || rhs.parse::<i64>().map_err(|_| E::InvalidOperation);
        match lhs {
            "bkcmd" => {
                let v = num()?;
                self.bkcmd = u8::try_from(v)
                    .ok()
                    .filter(|v| *v <= 3)
                    .ok_or(E::AssignmentFailed)?;
            }
            "dims" | "dim" => {
                let v = num()?;
                self.dims = u8::try_from(v.clamp(0, 100)).unwrap_or(100);
            }
            "sleep" => self.sleeping = num()? != 0,
            "baud" | "bauds" => {
                let v = u32::try_from(num()?).map_err(|_| E::InvalidBaudRate)?;
                crate::BaudRate::from_bps(v).ok_or(E::InvalidBaudRate)?;
                self.baud = v;
            }
            _ => {
                let (obj, attr) = lhs.rsplit_once('.').ok_or(E::InvalidVariable)?;
                let i = self.find(obj).ok_or(E::InvalidVariable)?;
                match attr {
                    "val" if !self.comps[i].is_text => {
                        let v = num()?;
                        self.comps[i].val = v as i32; // the screen wraps to 32 bits
                    }
                    "txt" if self.comps[i].is_text => {
                        let t = unescape(rhs).ok_or(E::InvalidEscape)?;
                        self.comps[i].txt = t.chars().take(TXT_MAXL).collect();
                    }
                    _ => return Err(E::InvalidVariable),
                }
            }
        }
        self.ok();
        Ok(())
    }
}

/// `"…"` with `\"`, `\\`, `\r` escapes → the text (`\r` becomes a line feed).
fn unescape(rhs: &str) -> Option<String> {
    let inner = rhs.strip_prefix('"')?.strip_suffix('"')?;
    let mut out = String::new();
    let mut chars = inner.chars();
    while let Some(c) = chars.next() {
        match c {
            '\\' => match chars.next()? {
                '"' => out.push('"'),
                '\\' => out.push('\\'),
                'r' => out.push('\n'),
                _ => return None,
            },
            '"' => return None,
            c => out.push(c),
        }
    }
    Some(out)
}
