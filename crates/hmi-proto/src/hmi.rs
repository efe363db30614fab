//! The application layer: a sans-IO state machine between the UART and the
//! machine, on top of [`Decoder`] and [`Instruction`].
//!
//! Data flow (documented in `docs/hmi.md`):
//! * buttons send "Send Component ID" on release (`0x65 page id 0x00`);
//!   Stop acts on its press too, from any page;
//! * touches count only from the page the MCU knows is shown (another
//!   page's: ignored, counted in [`HmiStats::foreign_page_touches`], and
//!   the screen asked `sendme`);
//! * a motor-starting button ([`Action::starts_motor`]: Start, Identify)
//!   acts only on its press then its release, no other touch frame between,
//!   within [`START_TAP_MS`], on the page shown: touch frames carry no CRC,
//!   and one hit bit turns another button's frame into a Start;
//! * an *Apply* button makes the MCU read the input with `get name.val`; the
//!   `0x71` reply is validated into a [`Command`] or rejected with a message in
//!   the page's `tmsg` box and the old value written back (nothing changes);
//! * while a `get` reply is awaited, further touch events are queued (up to
//!   [`TOUCH_QUEUE`]), never lost; *Stop* bypasses the queue;
//! * the MCU drives navigation (`page N`) and writes settings and live status;
//!   the `sendme` it queues are counted, and an answer owed by one queued
//!   before the last `page` instruction (it names the page before) is not
//!   taken as the page shown;
//! * received bytes come with their arrival time ([`Hmi::push_at`]): a
//!   partial frame followed by [`RX_GAP_MS`] of quiet line is forgotten; and
//!   while no `get` is awaited, a reply header (`70`, `71`, `67`, `68`) is
//!   read as a stray byte, so it never takes the touch frame after it.
//!
//! Boot handshake: until the screen answers, [`Hmi::tick`] sends a lone
//! terminator (to end any partial instruction) and `sendme` every
//! [`HANDSHAKE_RETRY_MS`]. The first `0x66` reply, or a `0x88` ready frame,
//! connects: the MCU sends `bkcmd=2`, `dims=…`, shows the home page of the
//! profile running ([`MachineProfile::home`]: page 1 `mode` for profile A,
//! page 7 `belt` for profile B) and reports [`Event::Connected`]. A later
//! `0x88`/startup frame (screen reset) repeats this.
//!
//! Link supervision: once connected, a screen that has sent nothing for
//! [`HEARTBEAT_MS`] is asked `sendme` (it answers with its page, `0x66`),
//! again every [`HEARTBEAT_MS`]; one that has sent nothing for
//! [`LINK_TIMEOUT_MS`] (a cut cable, a screen without power) is reported as
//! [`Event::Disconnected`] and the handshake starts over. Nothing about the
//! machine changes: the firmware keeps running on the settings in force.
//!
//! Machine profile: the profile running is the one in the settings given to
//! [`Hmi::new`] ([`Hmi::active_profile`]); it decides the home page, and
//! *Back* on page 6 goes there. The profile button on page 6 only changes the
//! selection in [`Settings::profile`] (reported as
//! [`Command::SelectProfile`]); while the selection differs from the profile
//! running, page 6's `tmsg` shows [`PROFILE_RESTART_MESSAGE`]: the firmware
//! applies the new profile after *Save settings* and a restart.
//!
//! ```
//! use hmi_proto::hmi::{Event, Hmi};
//! use hmi_proto::screen::{Command, Settings, Spacing};
//!
//! let mut hmi = Hmi::new(Settings::default(), "v0.1");
//! let mut tx = [0u8; 256];
//! hmi.tick(0);
//! let n = hmi.poll_transmit(&mut tx);
//! assert_eq!(&tx[..n], b"\xff\xff\xffsendme\xff\xff\xff");
//! // Screen: "current page is 0".
//! for b in [0x66, 0x00, 0xFF, 0xFF, 0xFF] { hmi.push(b); }
//! assert_eq!(hmi.poll_event(), Some(Event::Connected));
//! hmi.poll_transmit(&mut tx); // bkcmd=2, dims=100, page 1, ncoef.val=100
//! hmi.show_page(hmi_proto::screen::Page::Adaptive);
//! hmi.poll_transmit(&mut tx);
//! // Operator releases "Apply" (page 3, id 2): the MCU asks for the spacing.
//! for b in [0x65, 0x03, 0x02, 0x00, 0xFF, 0xFF, 0xFF] { hmi.push(b); }
//! let n = hmi.poll_transmit(&mut tx);
//! assert_eq!(&tx[..n], b"get nspacing.val\xff\xff\xff");
//! // Screen answers 180 (mm).
//! for b in [0x71, 180, 0, 0, 0, 0xFF, 0xFF, 0xFF] { hmi.push(b); }
//! assert_eq!(hmi.poll_event(), Some(Event::Command(Command::SetSpacing(Spacing::new(180).unwrap()))));
//! ```

use core::fmt;

use crate::decoder::{Decoder, DecoderStats};
use crate::encoder::{Attr, BkCmd, Instruction, ScreenText, MAX_INSTRUCTION_LEN};
use crate::frame::{ErrorCode, Frame, TouchEvent};
use crate::screen::{
    component_instruction, status_instruction, Action, Command, Component, Field, MachineProfile,
    Page, ParamError, Role, Settings, Status, StatusText, PROFILE_RESTART_MESSAGE, STATUS_TEXT_LEN,
};

/// Bytes the transmit queue holds (a page refresh plus a message fits: 379
/// bytes at most, the Adaptive page with every value at its widest,
/// `tests/tx_bound.rs`).
pub const TX_CAPACITY: usize = 384;
/// Touch events held while a `get` reply is awaited.
pub const TOUCH_QUEUE: usize = 4;
/// Events held until [`Hmi::poll_event`].
pub const EVENT_QUEUE: usize = 8;
/// A `get` unanswered for this long is abandoned.
pub const GET_TIMEOUT_MS: u32 = 200;
/// Handshake retry period while the screen is silent.
pub const HANDSHAKE_RETRY_MS: u32 = 500;
/// A connected screen that has sent nothing for this long is asked
/// `sendme`, and again every this long while it stays quiet.
pub const HEARTBEAT_MS: u32 = 1_000;
/// While the screen shows its numeric keyboard over the MCU's page, it is
/// asked its page this often (one `sendme`, 10 bytes): the page it loads
/// again when the keyboard closes is back to its design values until the
/// MCU writes them.
pub const COVER_POLL_MS: u32 = 200;
/// A connected screen that has sent nothing for this long is lost
/// ([`Event::Disconnected`]): two heartbeats went unanswered.
pub const LINK_TIMEOUT_MS: u32 = 2_500;
/// A partial frame is forgotten when the line has been quiet for this long
/// (a screen sends each frame in one go: 9 bytes take 0.8 ms at 115200 baud),
/// so the next byte is read as a header whatever came before it. Measured
/// between the bytes' arrival times ([`Hmi::push_at`]).
pub const RX_GAP_MS: u32 = 10;

/// A motor-starting button's release counts only this long after its press
/// (docs/hmi.md §3): a press held longer, or whose release was lost, is no
/// tap (a tap takes 0.1–0.5 s).
pub const START_TAP_MS: u32 = 2_000;

/// Shown in the page's `tmsg` when the screen did not answer the `get` of
/// an *Apply* within [`GET_TIMEOUT_MS`] (the field is set back to the value
/// in force).
pub const REPLY_LOST_MESSAGE: &str = "No answer from screen: Apply again";

/// What the application layer reports to the firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// The operator asked for something (already validated).
    Command(Command),
    /// An operator value was out of range; the screen shows the message and
    /// nothing changed.
    Rejected(ParamError),
    /// The screen answered the handshake (or restarted and was set up again);
    /// the firmware may write its settings with [`Hmi::set_settings`].
    Connected,
    /// The connected screen sent nothing for [`LINK_TIMEOUT_MS`]; the
    /// handshake starts over ([`Event::Connected`] when it answers).
    Disconnected,
    /// The screen reported an error (typed; `0x1A`, `0x24`, …).
    ScreenError(ErrorCode),
    /// A `get` for this field got no reply in [`GET_TIMEOUT_MS`].
    ReplyTimeout(Field),
}

/// The transmit queue had no room; the instruction was dropped (counted).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxFull;

impl fmt::Display for TxFull {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("screen transmit queue full")
    }
}

/// Counters of the application layer (wrapping).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HmiStats {
    /// Instructions dropped because the transmit queue was full.
    pub tx_dropped: u32,
    /// Events dropped because nobody polled them.
    pub events_dropped: u32,
    /// Touch events dropped because the touch queue was full.
    pub touches_dropped: u32,
    /// Touch events naming no component of the contract.
    pub unknown_touches: u32,
    /// `0x71`/`0x70` replies nobody asked for.
    pub unexpected_replies: u32,
    /// `get` requests that timed out.
    pub timeouts: u32,
    /// Frames the decoder dropped (see [`Hmi::decoder_stats`] for bytes).
    pub decode_errors: u32,
    /// Times a connected screen went silent for [`LINK_TIMEOUT_MS`].
    pub link_losses: u32,
    /// Partial frames forgotten after a quiet line ([`RX_GAP_MS`]).
    pub gap_resyncs: u32,
    /// Releases of another component while a Stop was held: the Stop's
    /// release hit on the line, ignored.
    pub mismatched_releases: u32,
    /// Touch events naming a page other than the one shown (or a
    /// motor-starting button while the page is not known): ignored, and
    /// the screen is asked its page.
    pub foreign_page_touches: u32,
    /// Releases of a motor-starting button without its press just before
    /// (another touch frame between them, a lost or hit press, or held
    /// longer than [`START_TAP_MS`]): ignored.
    pub unpaired_starts: u32,
    /// `0x66` answers to a `sendme` queued before a later `page`
    /// instruction (they name the page shown before it): not taken as the
    /// page shown.
    pub stale_page_answers: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Pending {
    field: Field,
    since_ms: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Link {
    Connecting {
        last_try_ms: Option<u32>,
    },
    /// `heard_ms`: the last frame from the screen; `probe_ms`: the last
    /// heartbeat `sendme` (or the connection).
    Connected {
        heard_ms: u32,
        probe_ms: u32,
    },
}

/// The screen link: feed it received bytes and the time; drain events and bytes.
///
/// Fixed size (≤ 808 bytes, asserted by a test: see the `*_QUEUE` and
/// [`TX_CAPACITY`] consts), no heap.
#[derive(Debug, Clone)]
pub struct Hmi {
    decoder: Decoder,
    link: Link,
    page: Page,
    page_before_alarm: Page,
    active_profile: MachineProfile,
    settings: Settings,
    version: ScreenText<'static>,
    pending: Option<Pending>,
    now_ms: u32,
    touches: heapless::Deque<(u8, u8), TOUCH_QUEUE>,
    events: heapless::Deque<Event, EVENT_QUEUE>,
    tx: heapless::Deque<u8, TX_CAPACITY>,
    stats: HmiStats,
    /// When the last byte arrived.
    last_rx_ms: u32,
    /// A startup frame came since the screen was last set up: a `0x66`
    /// answer naming page 0 then means the screen restarted (its `0x88`
    /// was lost).
    restart_seen: bool,
    /// The last touch frame was a Stop press: its release comes next.
    stop_held: bool,
    /// [`page`](Self::page) is the page the screen shows (or will show
    /// once it has read the `page` instruction queued): set by a `page`
    /// instruction queued and by a `0x66` answer; cleared before the
    /// handshake, on a lost link and when a `page` instruction did not fit
    /// the transmit queue.
    page_known: bool,
    /// The last touch frame was the press of a motor-starting button on
    /// the page shown: its page, id and the time.
    start_press: Option<(u8, u8, u32)>,
    /// `sendme` queued since the last `page` instruction, not answered yet.
    probes: u8,
    /// Answers still to come to `sendme` queued before the last `page`
    /// instruction: the screen answers them with the page it showed
    /// before, so they do not say which page is shown now.
    stale_answers: u8,
    /// What each status text of the page shown shows
    /// ([`StatusText::key`], by [`StatusText::index`]); `None`: not written
    /// since the page was shown, or maybe not taken by the screen.
    texts_shown: [Option<i16>; StatusText::ALL.len()],
    /// The screen answered `sendme` with a page of its own (the numeric
    /// keyboard, `keybdB`) over [`page`](Self::page): no status is written
    /// (its components are not shown), and the screen is asked its page
    /// every [`COVER_POLL_MS`] until it shows the MCU's page again.
    covered: bool,
}

impl Hmi {
    /// A link that will start the handshake at the first [`tick`](Self::tick).
    /// `version` (≤ 40 characters, else shown empty) goes to the `tver` boxes.
    /// `settings.profile` is the profile the machine runs
    /// ([`active_profile`](Self::active_profile)): it picks the home page.
    pub fn new(settings: Settings, version: &'static str) -> Self {
        Self {
            decoder: Decoder::new(),
            link: Link::Connecting { last_try_ms: None },
            page: Page::Boot,
            page_before_alarm: settings.profile.home(),
            active_profile: settings.profile,
            settings,
            version: ScreenText::new(version).unwrap_or(ScreenText::EMPTY),
            pending: None,
            now_ms: 0,
            touches: heapless::Deque::new(),
            events: heapless::Deque::new(),
            tx: heapless::Deque::new(),
            stats: HmiStats::default(),
            last_rx_ms: 0,
            restart_seen: false,
            stop_held: false,
            page_known: false,
            start_press: None,
            probes: 0,
            stale_answers: 0,
            texts_shown: [None; StatusText::ALL.len()],
            covered: false,
        }
    }

    /// `true` once the screen has answered, until it is silent for
    /// [`LINK_TIMEOUT_MS`].
    pub fn is_connected(&self) -> bool {
        matches!(self.link, Link::Connected { .. })
    }

    /// The page the MCU believes is shown.
    pub fn page(&self) -> Page {
        self.page
    }

    /// The profile the machine runs (from the settings given to
    /// [`new`](Self::new)); a profile selected later applies after a restart.
    pub fn active_profile(&self) -> MachineProfile {
        self.active_profile
    }

    /// The home page of the profile running (shown after the handshake).
    pub fn home_page(&self) -> Page {
        self.active_profile.home()
    }

    /// The settings as displayed.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// `true` while a `get` reply is awaited.
    pub fn awaiting_reply(&self) -> bool {
        self.pending.is_some()
    }

    /// Counters.
    pub fn stats(&self) -> HmiStats {
        self.stats
    }

    /// The frame decoder's counters.
    pub fn decoder_stats(&self) -> DecoderStats {
        self.decoder.stats()
    }

    /// Bytes waiting to be sent.
    pub fn tx_pending(&self) -> usize {
        self.tx.len()
    }

    /// Feeds one received byte that arrived at `at_ms` (the receive
    /// interrupt's time, however late the link gets it): a partial frame
    /// followed by [`RX_GAP_MS`] of quiet line is forgotten before the
    /// byte, which then starts a frame (docs/hmi.md §3, "Line errors").
    pub fn push_at(&mut self, byte: u8, at_ms: u32) {
        if !self.decoder.is_idle() && quiet_since(self.last_rx_ms, at_ms) >= RX_GAP_MS.cast_signed()
        {
            // The rest of that frame is not coming: this byte is a header.
            self.decoder.reset();
            self.stats.gap_resyncs = self.stats.gap_resyncs.wrapping_add(1);
        }
        self.last_rx_ms = at_ms;
        // A number reply is expected only while a `get` is awaited; a
        // string or touch coordinates never (the MCU asks for neither): a
        // stray `70`, `71`, `67` or `68` then never takes the touch frame
        // after it (docs/hmi.md §3, "Line errors").
        self.decoder.expect_replies(self.pending.is_some());
        self.decode(byte);
    }

    /// Feeds one received byte that arrived at the last [`tick`](Self::tick)'s
    /// time ([`push_at`](Self::push_at) with that time).
    pub fn push(&mut self, byte: u8) {
        self.push_at(byte, self.now_ms);
    }

    fn decode(&mut self, byte: u8) {
        let mut next = self.decoder.push(byte);
        while let Some(result) = next {
            match result {
                Ok(frame) => self.on_frame(frame),
                Err(_) => {
                    self.stats.decode_errors = self.stats.decode_errors.wrapping_add(1);
                }
            }
            next = self.decoder.poll();
        }
    }

    /// Feeds received bytes that arrived at the last
    /// [`tick`](Self::tick)'s time.
    pub fn push_slice(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.push(b);
        }
    }

    /// Advances time (milliseconds, wrapping): handshake retries, link
    /// supervision and `get` timeouts. Call it every 10–50 ms: a `get` is
    /// timed from the last `tick`.
    pub fn tick(&mut self, now_ms: u32) {
        self.now_ms = now_ms;
        if let Link::Connected { heard_ms, probe_ms } = self.link {
            let quiet = now_ms.wrapping_sub(heard_ms);
            if quiet >= LINK_TIMEOUT_MS {
                self.lose_link();
            } else if quiet >= HEARTBEAT_MS && now_ms.wrapping_sub(probe_ms) >= HEARTBEAT_MS {
                self.link = Link::Connected {
                    heard_ms,
                    probe_ms: now_ms,
                };
                self.ask_page();
            } else if self.covered {
                // Is the keyboard still over the page?
                self.probe_page_at_most_every(COVER_POLL_MS);
            }
        }
        if let Link::Connecting { last_try_ms } = self.link {
            let due = match last_try_ms {
                None => true,
                Some(t) => now_ms.wrapping_sub(t) >= HANDSHAKE_RETRY_MS,
            };
            if due {
                self.link = Link::Connecting {
                    last_try_ms: Some(now_ms),
                };
                // Drop stale handshake bytes not yet sent.
                self.tx.clear();
                let _ = self.send(&Instruction::Flush);
                self.ask_page();
            }
        }
        if let Some(p) = self.pending {
            if now_ms.wrapping_sub(p.since_ms) >= GET_TIMEOUT_MS {
                self.pending = None;
                self.stats.timeouts = self.stats.timeouts.wrapping_add(1);
                // Nothing changed: the field must not keep showing the
                // value typed as if it were in force, and the operator is
                // told to apply it again.
                let _ = self.show_message(REPLY_LOST_MESSAGE);
                if let Some(input) = Component::input(self.page, p.field) {
                    let _ = self.send(&Instruction::SetValue(
                        input.obj(),
                        p.field.current(&self.settings),
                    ));
                }
                self.event(Event::ReplyTimeout(p.field));
                self.drain_touches();
            }
        }
    }

    /// Next event for the firmware.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// Moves queued bytes to `buf`; returns how many (0 when idle).
    pub fn poll_transmit(&mut self, buf: &mut [u8]) -> usize {
        let mut n = 0usize;
        for slot in buf.iter_mut() {
            match self.tx.pop_front() {
                Some(b) => {
                    *slot = b;
                    n = n.saturating_add(1);
                }
                None => break,
            }
        }
        n
    }

    /// Next byte to send (for an interrupt-driven transmitter).
    pub fn pop_tx(&mut self) -> Option<u8> {
        self.tx.pop_front()
    }

    /// Shows `page` with its settings values.
    pub fn show_page(&mut self, page: Page) -> Result<(), TxFull> {
        self.page = page;
        // A `page` instruction also closes the screen's keyboard.
        self.covered = false;
        // A page load resets its texts to the editor's.
        self.texts_shown = [None; StatusText::ALL.len()];
        // Not queued: the screen may still show the page before.
        let sent = self.send(&Instruction::Page(page.id()));
        self.page_known = sent.is_ok();
        sent?;
        // The `sendme` queued before it are answered with the page before.
        self.stale_answers = self.stale_answers.wrapping_add(self.probes);
        self.probes = 0;
        self.write_page_values(true)
    }

    /// Writes the values of the page's components (`page_instructions`,
    /// component by component: no list on the stack), the numeric entry
    /// fields too when `inputs`.
    fn write_page_values(&mut self, inputs: bool) -> Result<(), TxFull> {
        for comp in Component::on_page(self.page) {
            if !inputs && matches!(comp.role, Role::Input(_)) {
                continue;
            }
            if let Some(ins) = component_instruction(comp, &self.settings, self.version) {
                self.send(&ins)?;
            }
        }
        Ok(())
    }

    /// Replaces the displayed settings, rewriting those shown on the current page.
    pub fn set_settings(&mut self, settings: Settings) -> Result<(), TxFull> {
        let old = self.settings;
        self.settings = settings;
        if self.is_connected() {
            // Only what changed: the rest is on the screen already (a page
            // change writes every value itself), and page 6's full set
            // twice plus two messages — the profile refusal — would not fit
            // the transmit queue. The version text never changes.
            // Component by component (no lists of both versions' page
            // instructions to compare: smaller in flash and on the stack).
            // Equal settings send nothing (every instruction compares
            // equal): no comparison of the settings first (its derived
            // `PartialEq` cost 150 B of flash).
            for comp in Component::on_page(self.page) {
                let ins = component_instruction(comp, &self.settings, self.version);
                if let Some(ins) = ins {
                    if component_instruction(comp, &old, self.version) != Some(ins) {
                        self.send(&ins)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Writes the live values shown on the current page: every number, and
    /// each status text ([`StatusText`]) that differs from what it shows
    /// (all of them after a page change, a screen error or a new link).
    pub fn write_status(&mut self, status: &Status) -> Result<(), TxFull> {
        if !self.is_connected() || self.covered {
            return Ok(());
        }
        for comp in Component::on_page(self.page) {
            let text = match comp.role {
                Role::StatusText(t) => {
                    let key = t.key(status);
                    if self.texts_shown.get(t.index()) == Some(&Some(key)) {
                        continue;
                    }
                    Some((t.index(), key))
                }
                _ => None,
            };
            let mut buf = [0u8; STATUS_TEXT_LEN];
            if let Some(ins) = status_instruction(comp, status, &mut buf) {
                self.send(&ins)?;
                if let Some((i, key)) = text {
                    if let Some(shown) = self.texts_shown.get_mut(i) {
                        *shown = Some(key);
                    }
                }
            }
        }
        Ok(())
    }

    /// Shows `text` in the current page's message box (if it has one).
    pub fn show_message(&mut self, text: &str) -> Result<(), TxFull> {
        let Some(comp) = Component::on_page(self.page).find(|c| matches!(c.role, Role::Message))
        else {
            return Ok(());
        };
        let t = ScreenText::new(text).or_else(|_| ScreenText::new("?"));
        match t {
            Ok(t) => self.send(&Instruction::SetText(comp.obj(), t)),
            Err(_) => Ok(()),
        }
    }

    /// Shows the alarm page with `text` (≤ 40 characters; longer is cut).
    /// Acknowledging returns to the page shown before.
    pub fn show_alarm(&mut self, text: &str) -> Result<(), TxFull> {
        if self.page != Page::Alarm {
            self.page_before_alarm = self.page;
        }
        self.show_page(Page::Alarm)?;
        let cut = crate::encoder::first_chars(text, crate::encoder::MAX_TEXT_LEN);
        if let (Ok(t), Some(comp)) = (
            ScreenText::new(cut),
            Component::on_page(Page::Alarm).find(|c| matches!(c.role, Role::AlarmText)),
        ) {
            self.send(&Instruction::SetText(comp.obj(), t))?;
        }
        Ok(())
    }

    /// The screen's keyboard closed and loaded the MCU's page again: its
    /// local components are back to their design values, so each is
    /// written again (the status texts at the next status write). The
    /// numeric entry fields are global in the screen file (the Nextion
    /// Editor requires it for a keyboard): they keep their values, and the
    /// one just typed must stay until its Apply reads it.
    fn uncover(&mut self) {
        self.covered = false;
        self.texts_shown = [None; StatusText::ALL.len()];
        let _ = self.write_page_values(false);
    }

    fn send(&mut self, ins: &Instruction<'_>) -> Result<(), TxFull> {
        let mut buf = [0u8; MAX_INSTRUCTION_LEN];
        let n = match ins.emit(&mut buf) {
            Ok(n) => n,
            Err(_) => return Ok(()), // invalid argument: nothing to send
        };
        let free = self.tx.capacity().saturating_sub(self.tx.len());
        if n > free {
            self.stats.tx_dropped = self.stats.tx_dropped.wrapping_add(1);
            return Err(TxFull);
        }
        for &b in buf.get(..n).unwrap_or(&[]) {
            let _ = self.tx.push_back(b);
        }
        Ok(())
    }

    /// A `0x66` answer came: counts it against the `sendme` queued;
    /// `true` when it answers one queued before the last `page`
    /// instruction (stale).
    fn answered(&mut self) -> bool {
        if self.stale_answers > 0 {
            self.stale_answers = self.stale_answers.wrapping_sub(1);
            true
        } else {
            self.probes = self.probes.saturating_sub(1);
            false
        }
    }

    /// Asks the screen its page (connected, no `sendme` unanswered) unless
    /// it was asked less than `period_ms` ago: the heartbeat's clock, so a
    /// flood of screen errors costs one `sendme` a period.
    fn probe_page_at_most_every(&mut self, period_ms: u32) {
        if let Link::Connected { heard_ms, probe_ms } = self.link {
            if self.probes == 0 && self.now_ms.wrapping_sub(probe_ms) >= period_ms {
                self.link = Link::Connected {
                    heard_ms,
                    probe_ms: self.now_ms,
                };
                self.ask_page();
            }
        }
    }

    /// Queues `sendme` (the screen answers `0x66 page`), counted so that
    /// an answer crossing a later `page` instruction is known as such.
    fn ask_page(&mut self) {
        if self.send(&Instruction::SendMe).is_ok() {
            self.probes = self.probes.wrapping_add(1);
        }
    }

    fn event(&mut self, e: Event) {
        // Room is kept so that a burst of screen errors (a screen file with
        // a wrong name answers `0x1A` to every status write) never costs an
        // operator's command, and nothing costs a Stop: the events the
        // firmware only logs leave the last three places free, every other
        // event but Stop the last one. (Making room by evicting queued
        // events cost 2.3 KB of flash.)
        let keep_free: usize = match e {
            Event::ScreenError(_) | Event::ReplyTimeout(_) | Event::Rejected(_) => 3,
            Event::Command(Command::Stop) => 0,
            _ => 1,
        };
        if self.events.len().saturating_add(keep_free) >= EVENT_QUEUE {
            self.stats.events_dropped = self.stats.events_dropped.wrapping_add(1);
            return;
        }
        if self.events.push_back(e).is_err() {
            self.stats.events_dropped = self.stats.events_dropped.wrapping_add(1);
        }
    }

    /// The screen went silent: forget what was in flight (queued bytes,
    /// an awaited reply, queued touches) and start the handshake over.
    fn lose_link(&mut self) {
        self.link = Link::Connecting { last_try_ms: None };
        self.pending = None;
        self.touches.clear();
        self.tx.clear();
        self.stop_held = false;
        self.start_press = None;
        self.page_known = false;
        self.probes = 0;
        self.stale_answers = 0;
        self.covered = false;
        self.stats.link_losses = self.stats.link_losses.wrapping_add(1);
        self.event(Event::Disconnected);
    }

    fn connect(&mut self) {
        self.link = Link::Connected {
            heard_ms: self.now_ms,
            probe_ms: self.now_ms,
        };
        self.pending = None;
        self.touches.clear();
        self.restart_seen = false;
        self.stop_held = false;
        self.start_press = None;
        // The handshake's `sendme` not answered by now were lost (the screen
        // was off or restarting); a late answer naming page 0 is ignored
        // below.
        self.probes = 0;
        self.stale_answers = 0;
        let _ = self.send(&Instruction::BkCmd(BkCmd::OnFailure));
        let _ = self.send(&Instruction::Dims(self.settings.brightness.raw()));
        let _ = self.show_page(self.home_page());
        self.event(Event::Connected);
    }

    fn on_frame(&mut self, frame: Frame) {
        // Any whole frame shows the screen is there.
        if let Link::Connected { probe_ms, .. } = self.link {
            self.link = Link::Connected {
                heard_ms: self.now_ms,
                probe_ms,
            };
        }
        match frame {
            Frame::Touch {
                page,
                component,
                event,
            } => self.on_touch(page, component, event),
            Frame::CurrentPage(p) => match (self.link, self.answered()) {
                (Link::Connecting { .. }, _) => self.connect(),
                (Link::Connected { .. }, stale) => match Page::from_id(p) {
                    // The screen shows page 0 `boot` only at power-on, before
                    // the handshake: a reply naming it now is a late answer
                    // to a handshake `sendme` (the screen booted and sent
                    // `0x88` before answering it) and would hide the home
                    // page's live status; ignore it — unless a startup
                    // frame came first: the screen restarted and its `0x88`
                    // was lost.
                    Some(Page::Boot) if self.restart_seen => self.connect(),
                    Some(Page::Boot) => {}
                    // A page of the screen's own (the numeric keyboard):
                    // the MCU's page is covered until the screen loads it
                    // again.
                    None if !stale && self.page_known => self.covered = true,
                    None => {}
                    // An answer to a `sendme` queued before the last `page`
                    // instruction names the page shown before it: not the
                    // page now.
                    Some(_) if stale => {
                        self.stats.stale_page_answers =
                            self.stats.stale_page_answers.wrapping_add(1);
                    }
                    Some(page) => {
                        if self.covered && page == self.page {
                            self.uncover();
                        }
                        self.covered = false;
                        self.page = page;
                        self.page_known = true;
                        self.restart_seen = false;
                    }
                },
            },
            // A restart announces itself with this frame, then `0x88`
            // (which sets the screen up). Alone it changes nothing: a `get`
            // reply whose header byte is hit decodes as one (`71 B4 00 00
            // 00 FF FF FF` without its header is `00 00 00 FF FF FF`), and
            // dropping the link for it threw the operator off the run page.
            Frame::Startup => self.restart_seen = true,
            Frame::Ready => self.connect(),
            Frame::Number(v) => match self.pending.take() {
                Some(p) => {
                    self.on_value(p.field, v);
                    self.drain_touches();
                }
                None => {
                    self.stats.unexpected_replies = self.stats.unexpected_replies.wrapping_add(1);
                }
            },
            Frame::Text(_) => {
                self.stats.unexpected_replies = self.stats.unexpected_replies.wrapping_add(1);
            }
            Frame::Error(code) => {
                // The failed instruction may have been a status text (a
                // byte hit on the line): each is written again.
                self.texts_shown = [None; StatusText::ALL.len()];
                // Or the screen shows a page of its own (the numeric
                // keyboard): asked, it says so. The errors that follow
                // while the answer is awaited are the rest of the same
                // status write (one `0x1A` per instruction): reported once.
                let asking = self.probes > 0;
                if self.page_known && !self.covered {
                    self.probe_page_at_most_every(COVER_POLL_MS);
                }
                if !asking {
                    self.event(Event::ScreenError(code));
                }
            }
            _ => {}
        }
    }

    /// One touch frame (docs/hmi.md §3). Frames carry no CRC: a motor
    /// starts only on evidence one hit frame cannot fake — the press and
    /// then the release of the same motor-starting button, no other touch
    /// frame between them, within [`START_TAP_MS`], both naming the page
    /// shown.
    fn on_touch(&mut self, page: u8, id: u8, event: TouchEvent) {
        // Whatever this frame is, a press waiting for its release is used.
        let press = self.start_press.take();
        let comp = Component::lookup(page, id);
        let role = comp.map(|c| c.role);
        // Stop counts on press and on release, from any page, connected or
        // not (a corrupted frame may have looked like a screen restart):
        // the screen file sends its ID on both, so one lost frame never
        // loses a Stop.
        if matches!(role, Some(Role::Action(Action::Stop))) {
            self.stop_held = event == TouchEvent::Press;
            self.event(Event::Command(Command::Stop));
            return;
        }
        let starts_motor = matches!(role, Some(Role::Action(a)) if a.starts_motor());
        let shown = self.page_known && page == self.page.id();
        if shown && self.covered {
            // The keyboard closed: its page is back (the touch came from
            // it).
            self.uncover();
        }
        if event == TouchEvent::Press {
            // Other buttons act on their release; their press is ignored.
            if starts_motor && shown && self.is_connected() {
                self.start_press = Some((page, id, self.now_ms));
            }
            return;
        }
        // A single-touch screen sends no other component's release
        // between a press and its release: after a Stop press, a release
        // naming another component is the Stop's release hit on the line
        // (page 3: `bstop` 7 and `bstart` 6 are one bit apart), never a
        // touch of it. Ignored; if the Stop's release was lost instead,
        // the operator's next touch is ignored once.
        if core::mem::take(&mut self.stop_held) {
            self.stats.mismatched_releases = self.stats.mismatched_releases.wrapping_add(1);
            return;
        }
        if !self.is_connected() {
            return;
        }
        let Some(comp) = comp else {
            self.stats.unknown_touches = self.stats.unknown_touches.wrapping_add(1);
            return;
        };
        if !shown {
            // Another page than the one shown (in flight across a page
            // change, or a hit page byte), or the page is not known: ask
            // the screen, so that a page believed wrongly is put right.
            self.ask_page();
            if self.page_known || starts_motor {
                self.stats.foreign_page_touches = self.stats.foreign_page_touches.wrapping_add(1);
                return;
            }
            // Page not known: the other buttons are taken from the page
            // they name, as before.
            self.page = comp.page;
        } else if starts_motor
            && !press.is_some_and(|(p, i, t)| {
                p == page && i == id && self.now_ms.wrapping_sub(t) <= START_TAP_MS
            })
        {
            self.stats.unpaired_starts = self.stats.unpaired_starts.wrapping_add(1);
            return;
        }
        if self.pending.is_some() {
            if self.touches.push_back((page, id)).is_err() {
                self.stats.touches_dropped = self.stats.touches_dropped.wrapping_add(1);
            }
            return;
        }
        self.act(comp);
    }

    fn drain_touches(&mut self) {
        while self.pending.is_none() {
            let Some((page, id)) = self.touches.pop_front() else {
                break;
            };
            if let Some(comp) = Component::lookup(page, id) {
                self.act(comp);
            }
        }
    }

    fn act(&mut self, comp: &'static Component) {
        // The page is not taken from the touch: it was checked on arrival
        // (`on_touch`), and a queued navigation acted on before this touch
        // has changed it since.
        let Role::Action(action) = comp.role else {
            return;
        };
        // The actions that change a setting shown on the screen change this
        // copy; it is written once below (one copy and one call in flash;
        // unchanged, it sends nothing).
        let mut s = self.settings;
        let cmd = match action {
            Action::ShowPage(p) => {
                let _ = self.show_page(p);
                None
            }
            Action::ShowHome => {
                let _ = self.show_page(self.home_page());
                None
            }
            Action::NextProfile => {
                s.profile = s.profile.next();
                Some(Command::SelectProfile(s.profile))
            }
            Action::SelectMode(m) => {
                let _ = self.show_page(m.page());
                Some(Command::SelectMode(m))
            }
            Action::Apply(field) => {
                if let Some(input) = Component::input(comp.page, field) {
                    if self.send(&Instruction::Get(input.obj(), Attr::Val)).is_ok() {
                        self.pending = Some(Pending {
                            field,
                            since_ms: self.now_ms,
                        });
                    }
                }
                None
            }
            Action::Start => Some(Command::Start),
            Action::Stop => Some(Command::Stop),
            Action::GearDown | Action::GearUp => {
                s.gear = if action == Action::GearUp {
                    s.gear.next()
                } else {
                    s.gear.prev()
                };
                Some(Command::SelectGear(s.gear))
            }
            Action::NextCalibration => {
                s.calibration_kind = s.calibration_kind.next();
                Some(Command::SelectCalibration(s.calibration_kind))
            }
            Action::CalibrationStart => Some(Command::CalibrationStart),
            Action::CalibrationStop => Some(Command::CalibrationStop),
            Action::CalibrationAccept => Some(Command::CalibrationAccept),
            Action::AcknowledgeAlarm => {
                let _ = self.show_page(self.page_before_alarm);
                Some(Command::AcknowledgeAlarm)
            }
            Action::SaveSettings => Some(Command::SaveSettings),
            Action::IdentifyDrive => Some(Command::IdentifyDrive),
            Action::AcceptDriveModel => Some(Command::AcceptDriveModel),
            Action::NewRoll => Some(Command::NewRoll),
            Action::ToggleEncoderDirection => {
                s.drum_encoder_reversed = !s.drum_encoder_reversed;
                Some(Command::SetDrumEncoderReversed(s.drum_encoder_reversed))
            }
            Action::ToggleWorkSwitch => {
                s.work_switch_fitted = !s.work_switch_fitted;
                Some(Command::SetWorkSwitchFitted(s.work_switch_fitted))
            }
            // The label changes when the supervisor's settings come back
            // (it refuses while the drum runs).
            Action::TogglePlacement => {
                Some(Command::SetSpeedFollowing(!self.settings.speed_following))
            }
            // The label changes when the supervisor's settings come back
            // (it refuses while the drum runs).
            Action::NextTravelSource => Some(Command::SelectTravelSource(
                self.settings.travel_source.next(),
            )),
            Action::ToggleGroundWheelDirection => {
                s.ground_wheel_reversed = !s.ground_wheel_reversed;
                Some(Command::SetGroundWheelReversed(s.ground_wheel_reversed))
            }
            // Its value comes back with the supervisor's settings.
            Action::NextLinkParameter => {
                s.link_parameter = s.link_parameter.next();
                Some(Command::SelectLinkParameter(s.link_parameter))
            }
        };
        let _ = self.set_settings(s);
        if action == Action::NextProfile {
            let _ = self.show_message(if s.profile == self.active_profile {
                ""
            } else {
                PROFILE_RESTART_MESSAGE
            });
        }
        if let Some(c) = cmd {
            self.event(Event::Command(c));
        }
    }

    fn on_value(&mut self, field: Field, raw: i32) {
        match field.validate(raw) {
            Ok(cmd) => {
                // In place: a copy of the settings out and back costs ≈ 300 B
                // of flash.
                let s = &mut self.settings;
                match cmd {
                    Command::SetSpacing(v) => s.spacing = v,
                    Command::SetFixedDrumSpeed(v) => s.fixed_drum_speed = v,
                    Command::SetMotorCoefficient(v) => s.motor_coefficient = v,
                    Command::CalibrationActualDistance(v) => s.calibration_distance = v,
                    Command::SetCalibrationCoefficient(v) => s.calibration_coefficient = v,
                    Command::SetBrightness(v) => s.brightness = v,
                    Command::SetBeltSpacing(v) => s.belt.spacing = v,
                    Command::SetSeedlingPitch(v) => s.belt.seedling_pitch = v,
                    Command::SetClampAngle(v) => s.belt.clamp_angle = v,
                    Command::SetClampCount(v) => s.belt.clamp_count = v,
                    Command::SetRollerRadius(v) => s.belt.roller_radius = v,
                    Command::SetBeltThickness(v) => s.belt.belt_thickness = v,
                    Command::SetSpeedThreshold(v) => s.belt.speed_threshold = v,
                    Command::SetFirstPlantDistance(v) => s.first_plant_distance = v,
                    Command::SetLinkValue(v) => s.link_value = v,
                    _ => {}
                }
                if let Command::SetBrightness(v) = cmd {
                    let _ = self.send(&Instruction::Dims(v.raw()));
                }
                // A link value applies after Save and a restart; the
                // supervisor's refusal, if any, replaces this message.
                let _ = self.show_message(if field == Field::LinkValue {
                    crate::screen::LINK_RESTART_MESSAGE
                } else {
                    ""
                });
                self.event(Event::Command(cmd));
            }
            Err(e) => {
                let _ = self.show_message(e.message());
                if let Some(input) = Component::input(self.page, field) {
                    let _ = self.send(&Instruction::SetValue(
                        input.obj(),
                        field.current(&self.settings),
                    ));
                }
                self.event(Event::Rejected(e));
            }
        }
    }
}

/// Milliseconds from `from` to `to` (wrapping clock); negative when `to`
/// is before `from` (a byte stamped before the last tick).
fn quiet_since(from: u32, to: u32) -> i32 {
    to.wrapping_sub(from).cast_signed()
}
