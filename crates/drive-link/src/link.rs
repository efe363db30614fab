//! The Modbus master's link supervision: what to ask next, when a reply is
//! late, retries, link loss and recovery, and the counters.
//!
//! Sans-IO: the board layer sends the frames [`Link::next_frame`] gives
//! (driver-enable high before the first bit), calls [`Link::sent`] at the
//! transmission-complete interrupt (TC, not TXE: the last stop bit has left;
//! then driver-enable low), hands every received frame (bytes ended by a
//! 3.5-character silence) to [`Link::received`], tells it while bytes are
//! arriving ([`Link::line_busy`]) and calls [`Link::tick`] from its timer.
//! Time is in µs of a monotonic clock. Nothing here blocks.
//!
//! Rules (docs/drive-link.md):
//! - one request at a time; the next one no earlier than the 3.5-character
//!   silent interval after the last frame on the line, and never while
//!   bytes arrive;
//! - a reply is due within [`LinkConfig::reply_timeout_us`] of the request's
//!   end (the driver's answer time, a setting, plus the reply's time on the
//!   line); a corrupt frame ends nothing (the valid reply may follow); an
//!   exception or no valid reply by then is a failed attempt, and the same
//!   request is sent again once the line has been quiet for the retry gap,
//!   up to [`LinkConfig::retries`] times;
//! - the fault word is read every [`FAULT_POLL_EVERY`]th poll whatever else
//!   is due; control words are written in the order asked;
//! - the driver's set-up (mode, offline time, speed resolution, maximum
//!   speed) is done at start and after every loss, and can refuse it
//!   ([`LossCause::Setup`]);
//! - when a request's retries are used up the link is **lost**: latched
//!   ([`Event::Lost`]) until it answers again ([`Event::Restored`]) **and**
//!   the operator acknowledges ([`Link::acknowledge`]); polling goes on
//!   meanwhile so that recovery is seen;
//! - a valid frame that does not answer the outstanding request (a reply
//!   that arrived after its timeout) is counted as late and ignored.
//!
//! The speed read-back is stamped with the time its request ended (the
//! driver samples after it has the request), so its age at use includes the
//! reply's own time on the line.

use core::fmt;

use heapless::Deque;

use crate::profile::{DriverProfile, MAX_RESOLUTION};
use crate::rtu::{self, Reply, ReplyError, Request};
use crate::timing;

/// The link's timing settings, as the operator enters them (page 10 of
/// the screen, docs/drive-link.md), validated into a [`LinkConfig`] by
/// [`LinkConfig::for_profile`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkTiming {
    /// The driver's answer time allowed: from the request's last bit to
    /// the reply's first, ms ([`REPLY_TIMEOUT_MS`]). The reply's own time
    /// on the line and the silence that ends it are added.
    pub reply_timeout_ms: u16,
    /// The quiet line a failed request waits for before it is sent again,
    /// ms ([`RETRY_GAP_MS`]): a late reply, or the rest of a noise burst,
    /// passes first instead of colliding with the retry.
    pub retry_gap_ms: u16,
    /// The driver's own communication-loss time, ms, written to its
    /// offline-time register at start-up (profiles that name one): the
    /// driver stops its motor when no request has come for this long.
    /// At least [`LinkConfig::longest_request_interval_us`] (a link
    /// within its retry budget never trips it), at most 32 767.
    pub offline_time_ms: u16,
}

/// The fault word is read on every 6th poll, whatever else is due (the
/// speed read, the speed command): a fault set at any moment is read
/// within 6 polls and the reply. Every 6th and not every 4th: at 9600
/// baud, with the driver's read-back as the only feedback and its speed
/// command over the bus, the read-back and the command share the line with
/// the fault reads, and every 4th poll made the drum's control loop trip
/// its instability supervisor in 10 of 90 rows of the full noise model
/// (every 6th: 0 of 180; docs/drive-link.md).
pub const FAULT_POLL_EVERY: u8 = 6;

/// The drum's top speed a driver must reach by default: paper A's
/// 44.7 r/min (eq. 7's cap, `kinematics::consts::N_MAX`), milli-r/min.
pub const TOP_DRUM_MILLI_RPM: u32 = 44_700;

/// The range of [`LinkTiming::reply_timeout_ms`].
pub const REPLY_TIMEOUT_MS: core::ops::RangeInclusive<u16> = 5..=1000;
/// The range of [`LinkTiming::retry_gap_ms`].
pub const RETRY_GAP_MS: core::ops::RangeInclusive<u16> = 2..=1000;
/// The largest [`LinkTiming::offline_time_ms`] (the register is signed).
pub const OFFLINE_TIME_MAX_MS: u16 = 32_767;

impl LinkTiming {
    /// The defaults: a driver may take 60 ms to answer (slow drivers
    /// answer in up to 50 ms), a retry waits for 20 ms of quiet line, and
    /// the driver stops its motor after 500 ms without a request.
    pub const DEFAULT: Self = Self {
        reply_timeout_ms: 60,
        retry_gap_ms: 20,
        offline_time_ms: 500,
    };
}

impl Default for LinkTiming {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why link timing settings were refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TimingError {
    /// The baud rate is 0.
    Baud,
    /// The reply timeout is outside [`REPLY_TIMEOUT_MS`].
    ReplyTimeout(u16),
    /// The retry gap is outside [`RETRY_GAP_MS`].
    RetryGap(u16),
    /// The offline time is shorter than the link's longest interval
    /// between two requests (the driver would stop its motor while the
    /// link retries), or beyond [`OFFLINE_TIME_MAX_MS`].
    OfflineTime {
        /// The value set, ms.
        set: u16,
        /// The least it may be with this timing, ms.
        least: u32,
    },
}

impl fmt::Display for TimingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Baud => f.write_str("baud rate 0"),
            Self::ReplyTimeout(ms) => write!(f, "reply timeout {ms} ms outside 5..1000 ms"),
            Self::RetryGap(ms) => write!(f, "retry gap {ms} ms outside 2..1000 ms"),
            Self::OfflineTime { set, least } => write!(
                f,
                "offline time {set} ms outside {least}..32767 ms (the link may be silent {least} ms while it retries)"
            ),
        }
    }
}

/// Timing of the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkConfig {
    /// A reply must be complete (its closing silence included) within
    /// this time of the request's end (µs).
    pub reply_timeout_us: u32,
    /// Extra attempts of a failed request before the link is lost.
    pub retries: u8,
    /// Every n-th poll reads the fault register, whatever else is due.
    pub fault_poll_every: u8,
    /// The 3.5-character silence (µs).
    pub silent_interval_us: u32,
    /// Quiet line before a failed request is sent again (µs, at least the
    /// 3.5-character silence).
    pub retry_gap_us: u32,
    /// Written to the profile's offline-time register at start-up, ms.
    pub offline_time_ms: u16,
    /// The drum's top speed the driver must be able to reach, milli-r/min
    /// (checked against its maximum-speed register). Default
    /// [`TOP_DRUM_MILLI_RPM`].
    pub top_drum_milli_rpm: u32,
    /// A request's time on the line (8 characters), µs.
    request_us: u32,
}

impl LinkConfig {
    /// The timing for a baud rate with `timing`: the reply timeout is the
    /// answer time plus the longest reply's time on the line (9
    /// characters) plus the 3.5-character silence after it, without which
    /// the reply's end is not seen (§2.5.1.1); two retries; the fault
    /// word every [`FAULT_POLL_EVERY`]th poll.
    ///
    /// ```
    /// use drive_link::link::{LinkConfig, LinkTiming, TimingError};
    /// let c = LinkConfig::new(9600, LinkTiming::DEFAULT).unwrap();
    /// // 60 ms + 9 × 1145.8 µs = 10 313 µs on the line + 4011 µs of silence.
    /// assert_eq!(c.reply_timeout_us, 74_324);
    /// let slow = LinkTiming { reply_timeout_ms: 1001, ..LinkTiming::DEFAULT };
    /// assert_eq!(LinkConfig::new(9600, slow), Err(TimingError::ReplyTimeout(1001)));
    /// ```
    pub fn new(baud: u32, timing: LinkTiming) -> Result<Self, TimingError> {
        let LinkTiming {
            reply_timeout_ms,
            retry_gap_ms,
            offline_time_ms,
        } = timing;
        if !REPLY_TIMEOUT_MS.contains(&reply_timeout_ms) {
            return Err(TimingError::ReplyTimeout(reply_timeout_ms));
        }
        if !RETRY_GAP_MS.contains(&retry_gap_ms) {
            return Err(TimingError::RetryGap(retry_gap_ms));
        }
        let reply = timing::frame_time_us(baud, 9).ok_or(TimingError::Baud)?;
        let request_us = timing::frame_time_us(baud, 8).ok_or(TimingError::Baud)?;
        let silent = timing::silent_interval_us(baud).ok_or(TimingError::Baud)?;
        let answer = u32::from(reply_timeout_ms).saturating_mul(1000);
        Ok(Self {
            reply_timeout_us: reply.saturating_add(silent).saturating_add(answer),
            retries: 2,
            fault_poll_every: FAULT_POLL_EVERY,
            silent_interval_us: silent,
            retry_gap_us: u32::from(retry_gap_ms).saturating_mul(1000).max(silent),
            offline_time_ms,
            top_drum_milli_rpm: TOP_DRUM_MILLI_RPM,
            request_us,
        })
    }

    /// [`LinkConfig::new`] at the profile's baud rate, with the offline
    /// time checked too when the profile writes it to the driver: at least
    /// [`LinkConfig::longest_request_interval_us`], so that the driver
    /// never stops its motor while the link is within its retry budget.
    ///
    /// ```
    /// use drive_link::link::{LinkConfig, LinkTiming, TimingError};
    /// use drive_link::profile::ZLAC8015D;
    /// let short = LinkTiming { offline_time_ms: 100, ..LinkTiming::DEFAULT };
    /// // 115 200 baud: 2 × 62.6 ms (reply timeout) + 20 ms + 0.8 ms.
    /// assert_eq!(
    ///     LinkConfig::for_profile(&ZLAC8015D, short),
    ///     Err(TimingError::OfflineTime { set: 100, least: 146 })
    /// );
    /// ```
    pub fn for_profile(profile: &DriverProfile, timing: LinkTiming) -> Result<Self, TimingError> {
        let c = Self::new(profile.baud, timing)?;
        if profile.offline_register.is_some() {
            let least = c.longest_request_interval_us().div_ceil(1000);
            if u32::from(timing.offline_time_ms) < least
                || timing.offline_time_ms > OFFLINE_TIME_MAX_MS
            {
                return Err(TimingError::OfflineTime {
                    set: timing.offline_time_ms,
                    least,
                });
            }
        }
        Ok(c)
    }

    /// The default timing ([`LinkTiming::DEFAULT`]) at a baud rate;
    /// `None` for a baud rate of 0.
    #[must_use]
    pub fn for_baud(baud: u32) -> Option<Self> {
        Self::new(baud, LinkTiming::DEFAULT).ok()
    }

    /// The longest time between the ends of two requests while the driver
    /// answers nothing (µs): a request timed out, the wait for its late
    /// reply (one more reply timeout), the quiet gap, the next request.
    #[must_use]
    pub fn longest_request_interval_us(&self) -> u32 {
        self.reply_timeout_us
            .saturating_mul(2)
            .saturating_add(self.retry_gap_us)
            .saturating_add(self.request_us)
    }

    /// One failed attempt, from the request's first bit until the retry
    /// may go out (µs): the request, its reply timeout, the quiet gap.
    #[must_use]
    pub fn failed_attempt_us(&self) -> u32 {
        self.request_us
            .saturating_add(self.reply_timeout_us)
            .saturating_add(self.retry_gap_us)
    }
}

/// Control words queued at most (a clear between two enable states, and
/// one more).
pub const CONTROL_QUEUE: usize = 4;

/// What happened on the link that the supervisor must act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// No valid reply within the retry budget: the link is lost (latched).
    /// Reported again while lost when the cause changes
    /// ([`Link::loss_cause`]).
    Lost,
    /// The driver answers again (the alarm stays until acknowledged).
    Restored,
    /// The fault word changed; nonzero = the driver reports faults.
    Faults(u16),
}

/// Why the link was lost: how the last attempt of the retry budget failed
/// ([`Link::loss_cause`]), so that the screen and the log can say what to
/// check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LossCause {
    /// No reply within the reply timeout: wiring, power, slave id or baud.
    NoReply,
    /// Replies failed their CRC or length: noise, termination, baud.
    Corrupt,
    /// The driver refused the request with a Modbus exception: its profile
    /// names a register (or function) this driver does not have.
    Refused {
        /// The request's function code (3 read, 6 write).
        function: u8,
        /// The request's register.
        register: u16,
        /// The exception code (1 function, 2 register, 3 value, 4 device).
        code: u8,
    },
    /// The driver answered the last attempt from its slave id with a reply
    /// that does not fit the request (a byte count for another register
    /// width, a write echoed with another register or value): its profile
    /// names the wrong register width or function.
    Unfit {
        /// The request's function code (3 read, 6 write).
        function: u8,
        /// The request's register.
        register: u16,
    },
    /// The driver answers, but its set-up refuses it: the link writes no
    /// speed command and the supervisor stops the drum until the driver's
    /// register is corrected (read again every poll cycle).
    Setup(SetupFault),
}

/// Why the driver's set-up, read at start-up, refuses it
/// ([`LossCause::Setup`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SetupFault {
    /// The speed-resolution register holds a value the link cannot use: 0,
    /// above [`MAX_RESOLUTION`], or one at which the drum's top speed
    /// needs more command counts than the register holds.
    Resolution(u16),
    /// The driver's maximum speed (its register, in command counts at a
    /// resolution of 1: r/min of the ZLAC8015D's motor) is below what the
    /// drum's top speed needs through the gearbox.
    MaxSpeed {
        /// The driver's maximum speed, command counts.
        driver: u16,
        /// What the drum's top speed needs, command counts (rounded up).
        needed: u32,
    },
}

/// Counters since start (wrapping at u32::MAX, never panicking).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Transactions answered correctly.
    pub replies: u32,
    /// Replies with a CRC error.
    pub crc_errors: u32,
    /// Requests that got no reply in time.
    pub timeouts: u32,
    /// Valid frames that answered no outstanding request.
    pub late_replies: u32,
    /// Exception replies.
    pub exceptions: u32,
    /// Times the link was lost.
    pub losses: u32,
    /// Fault words read (a new reading re-raises a fault the operator
    /// acknowledged while it was still there).
    pub fault_reads: u32,
    /// Attempts sent again after a failed one.
    pub retries: u32,
}

/// A speed read back from the driver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedSample {
    /// Drum speed, milli-r/min.
    pub drum_milli_rpm: i32,
    /// When the driver sampled it (the end of the request), µs.
    pub sampled_at_us: u64,
}

/// The driver's enable through its control word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlAction {
    /// Enable the motor.
    Enable,
    /// Disable it.
    Disable,
    /// Clear a latched driver alarm.
    ClearAlarm,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Job {
    Speed,
    Faults,
    Control,
    Mode,
    Offline,
    Resolution,
    MaxSpeed,
    Command,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// The line is free from `at` on.
    Idle { at: u64 },
    /// A frame is on its way out.
    Sending { job: Job, request: Request },
    /// Waiting for the reply until `deadline`.
    Awaiting {
        job: Job,
        request: Request,
        sent_at: u64,
        deadline: u64,
    },
}

/// The master's state.
#[derive(Debug, Clone)]
pub struct Link {
    profile: DriverProfile,
    config: LinkConfig,
    state: State,
    /// The request being retried, with its failures so far.
    retry: Option<(Job, Request, u8)>,
    /// Control words to write, oldest first (the head is the one on the
    /// line while a control write is outstanding).
    control: Deque<u16, CONTROL_QUEUE>,
    /// The speed command, drum milli-r/min.
    command: Option<i32>,
    command_sent: Option<u16>,
    /// Start-up steps still to do (again after a loss): the mode and
    /// offline-time writes, the resolution and maximum-speed reads.
    mode_due: bool,
    offline_due: bool,
    resolution_due: bool,
    max_speed_due: bool,
    /// The driver's speed resolution (1 without a resolution register;
    /// none until read).
    resolution: Option<u16>,
    /// Why the driver's set-up refuses it, while it does.
    setup_fault: Option<SetupFault>,
    /// The last poll wrote the speed command.
    commanded: bool,
    polls: u8,
    /// Polls since the speed command was last written.
    since_command: u8,
    /// Until when (µs) reads must be of the register of a read that timed
    /// out and was then answered, with its job and request.
    drain: Option<(u64, Job, Request)>,
    lost: bool,
    answering: bool,
    counters: Counters,
    speed: Option<SpeedSample>,
    faults: u16,
    loss: Option<LossCause>,
    /// An attempt of the current request timed out: its reply may still
    /// come, late.
    timed_out: bool,
    /// When the current request's first attempt ended (µs).
    first_sent_at: u64,
    /// When its last attempt ended (µs).
    last_sent_at: u64,
    /// The current attempt met a corrupt frame (noise, or its reply hit).
    corrupt: bool,
    /// The function and register of the request whose retries ran out,
    /// until it is answered.
    lost_on: Option<(u8, u16)>,
    /// The current attempt got a reply from the slave that does not fit
    /// it (not a late reply to it: that would fit).
    unfit: bool,
}

impl Link {
    /// A link to the driver `profile` describes, with `config`'s timing.
    #[must_use]
    pub fn new(profile: DriverProfile, config: LinkConfig) -> Self {
        Self {
            profile,
            config,
            state: State::Idle { at: 0 },
            retry: None,
            control: Deque::new(),
            command: None,
            command_sent: None,
            mode_due: profile.velocity_mode.is_some(),
            offline_due: profile.offline_register.is_some(),
            resolution_due: profile.resolution_register.is_some(),
            max_speed_due: profile.max_speed_register.is_some(),
            resolution: if profile.resolution_register.is_some() {
                None
            } else {
                Some(1)
            },
            setup_fault: None,
            commanded: false,
            polls: 0,
            since_command: 0,
            drain: None,
            lost: false,
            answering: false,
            counters: Counters::default(),
            speed: None,
            faults: 0,
            loss: None,
            timed_out: false,
            first_sent_at: 0,
            last_sent_at: 0,
            corrupt: false,
            lost_on: None,
            unfit: false,
        }
    }

    /// Queues a control-word write (ignored when the profile has none; the
    /// enable pin still acts). Control words are written in the order
    /// asked: a clear-alarm is never overtaken by the enable state that
    /// follows it. A new enable state replaces one still queued behind
    /// the last clear (only the newest state matters), and a value equal
    /// to the newest queued is not queued twice.
    pub fn control(&mut self, action: ControlAction) {
        let Some(cw) = self.profile.control else {
            return;
        };
        let value = match action {
            ControlAction::Enable => cw.enable,
            ControlAction::Disable => cw.disable,
            ControlAction::ClearAlarm => cw.clear_alarm,
        };
        let is_state = |v: u16| v != cw.clear_alarm;
        if self.control.back() == Some(&value) {
            return;
        }
        if is_state(value) {
            if let Some(last) = self.control.back_mut().filter(|v| is_state(**v)) {
                // Replaced even on the line: its reply pops it only if it
                // is still the value written, so the new one goes next.
                *last = value;
                return;
            }
        }
        if self.control.is_full() {
            // Four changes within one transaction: keep the head (it may
            // be on the line) and the clears, in order; the new state
            // supersedes the queued ones.
            let mut kept: Deque<u16, CONTROL_QUEUE> = Deque::new();
            for (i, &v) in self.control.iter().enumerate() {
                if (i == 0 || !is_state(v)) && kept.back() != Some(&v) {
                    let _ = kept.push_back(v);
                }
            }
            self.control = kept;
        }
        let _ = self.control.push_back(value);
    }

    /// Sets the speed command (drum milli-r/min); written when it changes
    /// and written again every [`LinkConfig::fault_poll_every`] polls.
    /// `None` stops commanding.
    pub fn set_speed_command(&mut self, drum_milli_rpm: Option<i32>) {
        self.command = drum_milli_rpm.filter(|_| self.profile.speed_command.is_some());
    }

    /// The next frame to send, if the line is free; encodes it into `buf`
    /// and returns its length.
    pub fn next_frame(&mut self, now_us: u64, buf: &mut [u8]) -> Option<usize> {
        let State::Idle { at } = self.state else {
            return None;
        };
        if now_us < at {
            return None;
        }
        // A speed command's retry carries the newest command; with none
        // any more (stopped) it is not sent again.
        if let Some((Job::Command, ..)) = self.retry {
            if self.command_counts().is_none() {
                self.retry = None;
            }
        }
        if self.retry.is_some() {
            self.counters.retries = self.counters.retries.wrapping_add(1);
        }
        let (job, request) = match self.retry {
            // A control write is retried with the newest value queued (an
            // Enable retried after a Disable was queued would re-enable).
            Some((Job::Control, Request::Write { address, value }, _)) => (
                Job::Control,
                Request::Write {
                    address,
                    value: self.control.front().copied().unwrap_or(value),
                },
            ),
            // So is the speed command: a retry with the speed of before
            // would leave the driver behind.
            Some((Job::Command, Request::Write { address, value }, _)) => (
                Job::Command,
                Request::Write {
                    address,
                    value: self.command_counts().unwrap_or(value),
                },
            ),
            Some((job, request, _)) => (job, request),
            None => self.choose_draining(now_us),
        };
        let n = rtu::encode(self.profile.slave, request, buf).ok()?;
        self.state = State::Sending { job, request };
        Some(n)
    }

    /// [`Link::choose`], but while a timed-out read's reply may still
    /// come, a read of another register becomes a read of that one (a
    /// fault turn or a set-up read so displaced comes after the drain).
    fn choose_draining(&mut self, now_us: u64) -> (Job, Request) {
        if self.drain.is_some_and(|(until, ..)| now_us >= until) {
            self.drain = None;
        }
        let (job, request) = self.choose();
        match self.drain {
            Some((_, drained_job, drained))
                if matches!(request, Request::Read { .. }) && request != drained =>
            {
                if job == Job::Faults {
                    // The fault turn is next again.
                    self.polls = self.config.fault_poll_every.saturating_sub(1);
                }
                (drained_job, drained)
            }
            _ => (job, request),
        }
    }

    fn choose(&mut self) -> (Job, Request) {
        // The driver's set-up first: it takes an enable only in a mode.
        if let Some(step) = self.setup_step() {
            return step;
        }
        if let (Some(&value), Some(cw)) = (self.control.front(), self.profile.control) {
            return (
                Job::Control,
                Request::Write {
                    address: cw.address,
                    value,
                },
            );
        }
        let every = self.config.fault_poll_every;
        // Counts 1, 2, …, every, 1, …
        self.polls = if self.polls >= every {
            1
        } else {
            self.polls.saturating_add(1)
        };
        self.since_command = self.since_command.saturating_add(1);
        // The fault word has its own turn, every `every`-th poll, whatever
        // else is due: a fault must be seen while the speed is commanded.
        if every != 0 && self.polls == every {
            // The set-up is read again every cycle while it refuses the
            // driver (the operator may correct its registers).
            if self.setup_fault.is_some() {
                self.resolution_due = self.profile.resolution_register.is_some();
                self.max_speed_due = self.profile.max_speed_register.is_some();
            }
            return (
                Job::Faults,
                Request::Read {
                    address: self.profile.fault_register,
                    count: 1,
                },
            );
        }
        // A changed command is written, but never twice in a row: the
        // speed read that follows keeps the read-back fresh while the
        // command changes every control period. An unchanged one is
        // written again once every `every` polls (a driver that lost it).
        if let (Some(value), Some((address, _))) =
            (self.command_counts(), self.profile.speed_command)
        {
            let due = self.command_sent != Some(value) || self.since_command >= every.max(1);
            if due && !self.commanded {
                self.commanded = true;
                self.since_command = 0;
                return (Job::Command, Request::Write { address, value });
            }
        }
        self.commanded = false;
        (
            Job::Speed,
            Request::Read {
                address: self.profile.speed_feedback,
                count: 1,
            },
        )
    }

    /// The speed command register's value for the command in force (none
    /// without one, before the resolution is known, or while the set-up
    /// refuses the driver).
    fn command_counts(&self) -> Option<u16> {
        match (self.command, self.resolution, self.setup_fault) {
            (Some(milli), Some(resolution), None) => {
                self.profile.command_counts_at(milli, resolution)
            }
            _ => None,
        }
    }

    /// The next start-up step, if one is due.
    fn setup_step(&self) -> Option<(Job, Request)> {
        let p = &self.profile;
        if let (true, Some((address, value))) = (self.mode_due, p.velocity_mode) {
            return Some((Job::Mode, Request::Write { address, value }));
        }
        if let (true, Some(address)) = (self.offline_due, p.offline_register) {
            let value = self.config.offline_time_ms;
            return Some((Job::Offline, Request::Write { address, value }));
        }
        let read = |job, address| Some((job, Request::Read { address, count: 1 }));
        if let (true, Some(address)) = (self.resolution_due, p.resolution_register) {
            return read(Job::Resolution, address);
        }
        if let (true, Some(address)) = (self.max_speed_due, p.max_speed_register) {
            return read(Job::MaxSpeed, address);
        }
        None
    }

    /// A set-up register read back: the resolution must be one the link
    /// can use, and the maximum speed must let the drum reach its top
    /// speed. Returns the event when the refusal starts or ends.
    fn check_setup(&mut self, job: Job, value: u16) -> Option<Event> {
        let top = self.config.top_drum_milli_rpm;
        let needed = self.profile.command_counts_needed(top).unwrap_or(0);
        let fault = match job {
            Job::Resolution => {
                self.resolution_due = false;
                let fits = u64::from(needed).saturating_mul(u64::from(value))
                    <= i16::MAX.unsigned_abs().into();
                if (1..=MAX_RESOLUTION).contains(&value) && fits {
                    self.resolution = Some(value);
                    None
                } else {
                    self.resolution = None;
                    Some(SetupFault::Resolution(value))
                }
            }
            Job::MaxSpeed => {
                self.max_speed_due = false;
                (needed > u32::from(value)).then_some(SetupFault::MaxSpeed {
                    driver: value,
                    needed,
                })
            }
            _ => return None,
        };
        // The other check's refusal stands until it is read again.
        let other = self.setup_fault.filter(|f| {
            !matches!(
                (f, job),
                (SetupFault::Resolution(_), Job::Resolution)
                    | (SetupFault::MaxSpeed { .. }, Job::MaxSpeed)
            )
        });
        let fault = fault.or(other);
        let was = self.setup_fault;
        self.setup_fault = fault;
        match (was, fault) {
            (_, Some(f)) if was != fault => {
                self.command_sent = None;
                self.answering = false;
                self.loss = Some(LossCause::Setup(f));
                if !self.lost {
                    self.lost = true;
                    self.counters.losses = self.counters.losses.wrapping_add(1);
                }
                Some(Event::Lost)
            }
            (Some(_), None) => {
                self.answering = true;
                Some(Event::Restored)
            }
            _ => None,
        }
    }

    /// The request's last bit has left (TC).
    pub fn sent(&mut self, now_us: u64) {
        if let State::Sending { job, request } = self.state {
            if self.retry.is_none() {
                self.first_sent_at = now_us;
            }
            self.last_sent_at = now_us;
            self.unfit = false;
            self.corrupt = false;
            let deadline = now_us.saturating_add(u64::from(self.config.reply_timeout_us));
            self.state = State::Awaiting {
                job,
                request,
                sent_at: now_us,
                deadline,
            };
        }
    }

    /// Bytes are arriving on the line (a frame not yet ended by its
    /// silence): no request goes out until the line has been quiet for
    /// the 3.5-character silence, or for the retry gap before a retry.
    /// The board layer calls it on every tick while it holds received
    /// bytes not yet handed over.
    pub fn line_busy(&mut self, now_us: u64) {
        self.quiet_from(now_us);
    }

    /// The line was busy until `t`: the next request waits for the quiet
    /// it needs after it.
    fn quiet_from(&mut self, t: u64) {
        let need = if self.retry.is_some() {
            self.config.retry_gap_us
        } else {
            self.config.silent_interval_us
        };
        if let State::Idle { at } = &mut self.state {
            *at = (*at).max(t.saturating_add(u64::from(need)));
        }
    }

    /// A frame came in (ended by the silent interval).
    ///
    /// A frame that fails its CRC or its length (noise, a reply hit on the
    /// line) ends nothing: the valid reply may still follow, so the wait
    /// goes on until the reply timeout, and only then is the request sent
    /// again, on a quiet line (wait and flush). While a failed request
    /// waits for its retry, a valid reply to it is still its answer.
    pub fn received(&mut self, now_us: u64, frame: &[u8]) -> Option<Event> {
        let (job, request, sent_at, late) = match (self.state, self.retry) {
            (
                State::Awaiting {
                    job,
                    request,
                    sent_at,
                    ..
                },
                _,
            ) => (job, request, sent_at, false),
            (State::Idle { .. }, Some((job, request, _))) => {
                // The frame ended 3.5 characters ago.
                self.quiet_from(now_us.saturating_sub(u64::from(self.config.silent_interval_us)));
                (job, request, self.last_sent_at, true)
            }
            _ => {
                // Nothing outstanding: a reply after its timeout.
                self.counters.late_replies = self.counters.late_replies.wrapping_add(1);
                return None;
            }
        };
        match rtu::parse_reply(self.profile.slave, request, frame) {
            Ok(reply) => self.answered(now_us, job, request, sent_at, reply, late),
            // Noise or a reply hit on the line: the wait goes on (a
            // fragment under 4 bytes is no RTU frame at all: the bus heard
            // while DE drops).
            Err(ReplyError::Crc | ReplyError::Length(_)) => {
                self.counters.crc_errors = self.counters.crc_errors.wrapping_add(1);
                self.corrupt |= !late;
                None
            }
            Err(ReplyError::Exception(code)) if !late => {
                self.counters.exceptions = self.counters.exceptions.wrapping_add(1);
                let (function, register) = request.function_and_register();
                self.failed(
                    now_us,
                    LossCause::Refused {
                        function,
                        register,
                        code,
                    },
                )
            }
            Err(e) => {
                // A late reply to an earlier request: keep waiting. From
                // this slave it may also be its answer, unfit (the cause
                // if this attempt fails).
                self.unfit |= e == ReplyError::Mismatch && !late;
                self.counters.late_replies = self.counters.late_replies.wrapping_add(1);
                None
            }
        }
    }

    /// Timer: ends an unanswered request at its deadline.
    pub fn tick(&mut self, now_us: u64) -> Option<Event> {
        match self.state {
            State::Awaiting {
                deadline, request, ..
            } if now_us >= deadline => {
                let (function, register) = request.function_and_register();
                let cause = if self.corrupt {
                    // Its reply came, hit on the line: none is due any more.
                    LossCause::Corrupt
                } else {
                    self.counters.timeouts = self.counters.timeouts.wrapping_add(1);
                    self.timed_out = true;
                    if self.unfit {
                        LossCause::Unfit { function, register }
                    } else {
                        LossCause::NoReply
                    }
                };
                self.failed(now_us, cause)
            }
            _ => None,
        }
    }

    fn line_free(&mut self, now_us: u64) {
        self.state = State::Idle {
            at: now_us.saturating_add(u64::from(self.config.silent_interval_us)),
        };
    }

    /// The request is done (answered or given up) after `sent_at`, its
    /// last attempt's end. When an attempt of it timed out, a reply to it
    /// may still be on its way, and a reply to function 03 does not name
    /// its register (a write's echo does): until that reply is over due,
    /// one more reply timeout after the last attempt's deadline, what is
    /// read must be the same register, so that a late reply answers a
    /// request for its own register (the libmodbus recovery waits a
    /// response timeout and flushes; reading the same register meanwhile
    /// keeps the read-back flowing). Given up, nothing goes out until then.
    fn request_done(
        &mut self,
        now_us: u64,
        job: Job,
        request: Request,
        sent_at: u64,
        answered: bool,
    ) {
        self.line_free(now_us);
        if core::mem::take(&mut self.timed_out) {
            let until = sent_at
                .saturating_add(u64::from(self.config.reply_timeout_us).saturating_mul(2))
                .saturating_add(u64::from(self.config.silent_interval_us));
            if !answered {
                if let State::Idle { at } = &mut self.state {
                    *at = (*at).max(until);
                }
            } else if let Request::Read { .. } = request {
                self.drain = Some((until, job, request));
            }
        }
    }

    fn answered(
        &mut self,
        now_us: u64,
        job: Job,
        request: Request,
        sent_at: u64,
        reply: Reply,
        late: bool,
    ) -> Option<Event> {
        // A reply taken after its attempt failed answers an earlier
        // attempt: the driver sampled after the first one's end. One
        // within an attempt's own reply timeout is that attempt's.
        let sampled_at = if late { self.first_sent_at } else { sent_at };
        self.request_done(now_us, job, request, sent_at, true);
        self.retry = None;
        self.counters.replies = self.counters.replies.wrapping_add(1);
        let mut event = None;
        match (job, reply) {
            (Job::Speed, Reply::Registers { first, .. }) => {
                self.speed = Some(SpeedSample {
                    drum_milli_rpm: self.profile.speed_from_register(first),
                    sampled_at_us: sampled_at,
                });
            }
            (Job::Faults, Reply::Registers { first, .. }) => {
                self.counters.fault_reads = self.counters.fault_reads.wrapping_add(1);
                if first != self.faults {
                    event = Some(Event::Faults(first));
                }
                self.faults = first;
            }
            // What the driver now has is the value written: a control word
            // or a command queued while it was on its way is still due.
            (Job::Control, _) => {
                if let Request::Write { value, .. } = request {
                    if self.control.front() == Some(&value) {
                        self.control.pop_front();
                    }
                }
            }
            (Job::Mode, _) => self.mode_due = false,
            (Job::Offline, _) => self.offline_due = false,
            (Job::Resolution | Job::MaxSpeed, Reply::Registers { first, .. }) => {
                event = self.check_setup(job, first);
                if self.setup_fault.is_some() || event.is_some() {
                    return event;
                }
            }
            (Job::Command, Reply::Written) => {
                if let Request::Write { value, .. } = request {
                    self.command_sent = Some(value);
                }
            }
            _ => {}
        }
        // After a loss the driver answers again when the request that was
        // lost is answered: a driver that answers some registers and
        // refuses one of its profile's is not answering.
        if self
            .lost_on
            .is_some_and(|k| k != request.function_and_register())
        {
            return event;
        }
        self.lost_on = None;
        let was_answering = self.answering;
        self.answering = true;
        if self.setup_fault.is_some() {
            self.answering = false;
            return event;
        }
        if self.lost && !was_answering {
            // The driver may have been power-cycled: its set-up again.
            self.setup_again();
            return Some(Event::Restored);
        }
        event
    }

    /// Every start-up step due again (after a loss: the driver may have
    /// been power-cycled).
    fn setup_again(&mut self) {
        let p = &self.profile;
        self.mode_due = p.velocity_mode.is_some();
        self.offline_due = p.offline_register.is_some();
        self.resolution_due = p.resolution_register.is_some();
        self.max_speed_due = p.max_speed_register.is_some();
        if p.resolution_register.is_some() {
            self.resolution = None;
        }
    }

    fn failed(&mut self, now_us: u64, cause: LossCause) -> Option<Event> {
        let State::Awaiting {
            job,
            request,
            sent_at,
            ..
        } = self.state
        else {
            return None;
        };
        self.line_free(now_us);
        let failures = self.retry.map_or(1, |(_, _, n)| n.saturating_add(1));
        if failures <= self.config.retries {
            // Again once the line has been quiet for the retry gap.
            self.retry = Some((job, request, failures));
            self.quiet_from(now_us);
            return None;
        }
        self.request_done(now_us, job, request, sent_at, false);
        self.retry = None;
        self.answering = false;
        self.lost_on = Some(request.function_and_register());
        self.speed = None;
        self.command_sent = None;
        if self.lost {
            // Still lost: a new cause (a driver powered up with a profile it
            // refuses, after silence) is reported again.
            if self.loss == Some(cause) {
                return None;
            }
            self.loss = Some(cause);
            return Some(Event::Lost);
        }
        self.lost = true;
        self.loss = Some(cause);
        self.counters.losses = self.counters.losses.wrapping_add(1);
        Some(Event::Lost)
    }

    /// The operator acknowledges a link loss: cleared only when the driver
    /// answers again. Returns whether the alarm is gone.
    pub fn acknowledge(&mut self) -> bool {
        if self.answering {
            self.lost = false;
            self.loss = None;
        }
        !self.lost
    }

    /// Whether the link is lost (latched until answered and acknowledged).
    #[must_use]
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// Why the link was lost (none while it is not): how the last attempt
    /// of the retry budget failed.
    #[must_use]
    pub fn loss_cause(&self) -> Option<LossCause> {
        if self.lost {
            self.loss
        } else {
            None
        }
    }

    /// Whether the last transaction was answered.
    #[must_use]
    pub fn is_answering(&self) -> bool {
        self.answering
    }

    /// The last speed read back (none while the link is down).
    #[must_use]
    pub fn speed(&self) -> Option<SpeedSample> {
        self.speed
    }

    /// The last fault word read.
    #[must_use]
    pub fn fault_word(&self) -> u16 {
        self.faults
    }

    /// The counters.
    #[must_use]
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The profile in use.
    #[must_use]
    pub fn profile(&self) -> &DriverProfile {
        &self.profile
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
mod tests {
    use super::*;
    use crate::profile::ZLAC8015D;
    use std::vec::Vec;

    /// Runs the link against an echoing driver until it has nothing but
    /// polls left; the control words written, in order.
    fn written(link: &mut Link, t: &mut u64) -> Vec<u16> {
        let mut out = Vec::new();
        for _ in 0..20 {
            *t += 10_000;
            let mut buf = [0u8; rtu::MAX_FRAME];
            let n = link.next_frame(*t, &mut buf).unwrap();
            link.sent(*t);
            let frame = &buf[..n];
            let reply: Vec<u8> = if frame[1] == 0x06 {
                if frame[2..4] == [0x20, 0x0E] {
                    out.push(u16::from_be_bytes([frame[4], frame[5]]));
                }
                frame.to_vec()
            } else {
                let mut r = std::vec![1, 3, 2, 0, 0];
                r.extend_from_slice(&rtu::crc16(&r).to_le_bytes());
                r
            };
            *t += 5_000;
            link.received(*t, &reply);
        }
        out
    }

    #[test]
    fn control_words_keep_their_order_and_the_newest_state() {
        let mut link = Link::new(ZLAC8015D, LinkConfig::for_baud(115_200).unwrap());
        let mut t = 0;
        written(&mut link, &mut t);
        // Enable, clear, disable, enable, clear, disable, clear: the
        // states between two clears collapse to the newest.
        for a in [
            ControlAction::Enable,
            ControlAction::ClearAlarm,
            ControlAction::Disable,
            ControlAction::Enable,
            ControlAction::ClearAlarm,
            ControlAction::ClearAlarm,
            ControlAction::Disable,
        ] {
            link.control(a);
        }
        // Five entries after collapsing (E C E C D) in a queue of four:
        // the head kept, the superseded state dropped, the two clears
        // then next to each other written once, the newest state last.
        assert_eq!(written(&mut link, &mut t), [0x08, 0x06, 0x07]);
        // Within the queue's room nothing is dropped.
        for a in [
            ControlAction::ClearAlarm,
            ControlAction::Enable,
            ControlAction::ClearAlarm,
            ControlAction::Disable,
        ] {
            link.control(a);
        }
        assert_eq!(written(&mut link, &mut t), [0x06, 0x08, 0x06, 0x07]);
    }
}
