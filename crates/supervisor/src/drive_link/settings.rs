//! The drum driver's link settings: feedback source, command path, driver
//! profile and link timing, their validation, their bytes in the settings
//! record and page 10's values.

use drive_link::link::{LinkConfig, LinkTiming, TimingError};
use drive_link::profile::{
    check_line, ControlWord, DriverProfile, GenericSettings, ProfileError, ZLAC8015D,
};
use hmi_proto::screen::LinkParameter;

/// Where the drum's measured speed comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FeedbackSource {
    /// The drum encoder (TIM3), as before the link existed. The default.
    #[default]
    Encoder,
    /// The driver's speed read-back alone (no encoder fitted, paper A).
    Driver,
    /// The encoder controls; the read-back cross-checks it.
    Both,
}

/// How the drum speed is commanded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandPath {
    /// PWM duty on PA8, as before the link existed. The default.
    #[default]
    Pwm,
    /// The driver's speed command register over Modbus.
    Modbus,
}

/// Which driver is on the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriverKind {
    /// No driver on the link (the link stays idle). The default.
    #[default]
    None,
    /// A ZLTECH ZLAC8015D ([`ZLAC8015D`]'s registers) with the slave id,
    /// baud rate and feedback scale of [`DriveLinkSettings::generic`] (the
    /// scale carries the gearbox; the ZLAC's speed command counts whole
    /// r/min where its feedback counts 0.1 r/min, so the command scale is
    /// ten times the feedback's).
    Zlac8015d,
    /// Any driver, described by [`DriveLinkSettings::generic`].
    Generic,
}

/// The link's persisted settings (settings format 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveLinkSettings {
    /// Feedback source. Default: the encoder.
    pub feedback: FeedbackSource,
    /// Command path. Default: PWM.
    pub command: CommandPath,
    /// The driver. Default: none.
    pub kind: DriverKind,
    /// Slave id and baud rate (both kinds) and the registers and scaling
    /// (the generic kind). Default: the ZLAC8015D's.
    pub generic: GenericSettings,
    /// Reply timeout, retry gap and the driver's offline time (both
    /// kinds). Default: [`LinkTiming::DEFAULT`].
    pub timing: LinkTiming,
}

/// Paper A's drum gearbox (118:1) behind a driver counting 0.1 r/min of its
/// motor: 100 000 µr/min / 118 = 847 µr/min of the drum per count (0.05 %
/// rounding).
pub const PAPER_A_MICRO_RPM_PER_COUNT: i32 = 847;

/// The ZLAC8015D's maximum motor speed (its register 0x2008 takes 1–1000
/// r/min, ZLTECH's RS485 Communication Instruction V1.06 §4): the drum's
/// top speed through the gearbox must fit under it.
pub const ZLAC8015D_MAX_RPM: u32 = 1000;

/// The generic block's defaults: the ZLAC8015D's registers (control word,
/// velocity mode, offline time, speed resolution, maximum speed), paper
/// A's gearbox in the scales (the command's counts whole r/min: ten times
/// the feedback's), no command register.
pub const GENERIC_DEFAULT: GenericSettings = GenericSettings {
    slave: ZLAC8015D.slave,
    baud: ZLAC8015D.baud,
    speed_feedback: ZLAC8015D.speed_feedback,
    micro_rpm_per_count: PAPER_A_MICRO_RPM_PER_COUNT,
    fault_register: ZLAC8015D.fault_register,
    fault_masks: ZLAC8015D.fault_masks,
    speed_command: None,
    command_scale: PAPER_A_MICRO_RPM_PER_COUNT * 10,
    control: ZLAC8015D.control,
    velocity_mode: ZLAC8015D.velocity_mode,
    offline_register: ZLAC8015D.offline_register,
    resolution_register: ZLAC8015D.resolution_register,
    max_speed_register: ZLAC8015D.max_speed_register,
};

impl Default for DriveLinkSettings {
    fn default() -> Self {
        Self {
            feedback: FeedbackSource::Encoder,
            command: CommandPath::Pwm,
            kind: DriverKind::None,
            generic: GENERIC_DEFAULT,
            timing: LinkTiming::DEFAULT,
        }
    }
}

/// Why link settings were refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveLinkError {
    /// The driver read-back or the Modbus command chosen with no driver.
    NoDriver,
    /// The Modbus command chosen with a driver that takes none.
    NoSpeedCommand,
    /// The driver's profile was refused.
    Profile(ProfileError),
    /// The link's timing was refused.
    Timing(TimingError),
    /// A byte of the stored block is not a known value.
    Byte(u8),
    /// The driver's speed register (signed 16 bit) ends below the drum's
    /// top speed at this scale: a read-back there would be saturated, not
    /// the drum's speed. Carries where it ends, milli-r/min of the drum.
    SpeedRange {
        /// 32 767 counts × the scale, milli-r/min.
        top_milli_rpm: u32,
    },
    /// The drum's top speed needs more speed-command counts than the
    /// command register (signed 16 bit) holds at this command scale.
    CommandRange {
        /// The counts the top speed needs.
        needed: u32,
    },
    /// The drum's top speed through the gearbox needs more motor speed
    /// than the ZLAC8015D allows ([`ZLAC8015D_MAX_RPM`]): it would limit
    /// the motor, not run it at the command.
    MotorSpeed {
        /// The motor r/min the drum's 44.7 r/min needs.
        needed_rpm: u32,
    },
}

impl DriveLinkError {
    /// The screen's text (page 10's `tmsg`, ≤ 40 characters).
    #[must_use]
    pub const fn text(&self) -> &'static str {
        match self {
            Self::NoDriver => "Needs a driver (Driver 1 or 2)",
            Self::NoSpeedCommand => "Driver takes no speed command",
            Self::Profile(ProfileError::SlaveId(_)) => "Slave id must be 1-247",
            Self::Profile(ProfileError::Baud(_)) => "Baud: 9600 19200 38400 57600 115200",
            Self::Profile(ProfileError::Scale(_)) => "Scale must be nonzero",
            Self::Profile(ProfileError::CommandScale(_)) => "Command scale must be nonzero",
            Self::Profile(ProfileError::FaultMasksOverlap) => "Fault masks overlap",
            Self::Profile(ProfileError::RegisterClash) => "Registers must differ",
            Self::Profile(ProfileError::ControlValues) => "Control values must differ",
            Self::Timing(TimingError::ReplyTimeout(_) | TimingError::Baud) => {
                "Reply timeout: 5-1000 ms"
            }
            Self::Timing(TimingError::RetryGap(_)) => "Retry gap: 2-1000 ms",
            Self::Timing(TimingError::OfflineTime { .. }) => "Offline time too short for retries",
            Self::SpeedRange { .. } => "Scale under 1365: reads < 44.7 r/min",
            Self::CommandRange { .. } => "Command scale under 1365 (44.7 r/min)",
            Self::MotorSpeed { .. } => "Gearbox needs over 1000 motor r/min",
            Self::Byte(_) => "Value out of range",
        }
    }
}

impl core::fmt::Display for DriveLinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoDriver => f.write_str("driver feedback or command needs a driver profile"),
            Self::NoSpeedCommand => f.write_str("this driver takes no speed command"),
            Self::Profile(e) => write!(f, "driver profile: {e}"),
            Self::Timing(e) => write!(f, "link timing: {e}"),
            Self::Byte(b) => write!(f, "invalid drive link byte {b}"),
            Self::SpeedRange { top_milli_rpm } => write!(
                f,
                "driver speed register ends at {}.{:03} r/min, below the drum's 44.7",
                top_milli_rpm / 1000,
                top_milli_rpm % 1000
            ),
            Self::CommandRange { needed } => write!(
                f,
                "the drum's 44.7 r/min needs {needed} speed command counts, beyond 32767"
            ),
            Self::MotorSpeed { needed_rpm } => write!(
                f,
                "the drum's 44.7 r/min needs {needed_rpm} motor r/min through the gearbox; the ZLAC8015D runs at most 1000"
            ),
        }
    }
}

/// Bytes of [`DriveLinkSettings::to_bytes`] (settings format 6).
pub const DRIVE_LINK_BYTES: usize = 59;

/// Bytes of the block in settings format 5 (before the link's timing and
/// the generic profile's command scale and optional registers).
pub const DRIVE_LINK_V5_BYTES: usize = 31;

impl DriveLinkSettings {
    /// The driver's profile (`None`: no driver), validated: a generic
    /// profile through [`GenericSettings::build`], the ZLAC8015D with the
    /// slave id and baud of the generic block (checked the same way), and
    /// the link's timing.
    pub fn build(&self) -> Result<Option<DriverProfile>, DriveLinkError> {
        Ok(self.config()?.map(|(p, _)| p))
    }

    /// The masks of the named driver faults: the ZLAC8015D's, or the
    /// generic profile's (without building the profile: the control task
    /// names a fault with them).
    #[must_use]
    pub fn fault_masks(&self) -> [u16; 6] {
        match self.kind {
            DriverKind::Zlac8015d => ZLAC8015D.fault_masks,
            DriverKind::None | DriverKind::Generic => self.generic.fault_masks,
        }
    }

    /// [`Self::build`] with the link's timing: what the link task runs.
    pub fn config(&self) -> Result<Option<(DriverProfile, LinkConfig)>, DriveLinkError> {
        let top = kinematics::consts::N_MAX.to_milli();
        let profile = match self.kind {
            DriverKind::None => None,
            DriverKind::Zlac8015d => {
                // The ZLAC8015D's registers and fault bits with the generic
                // block's slave id, baud and feedback scale; its speed
                // command counts whole r/min (ten feedback counts).
                let g = &self.generic;
                let scale = g.micro_rpm_per_count;
                check_line(g.slave, g.baud, scale).map_err(DriveLinkError::Profile)?;
                let command = scale
                    .checked_mul(10)
                    .ok_or(DriveLinkError::Profile(ProfileError::Scale(scale)))?;
                let p = DriverProfile {
                    slave: g.slave,
                    baud: g.baud,
                    micro_rpm_per_count: scale,
                    speed_command: ZLAC8015D.speed_command.map(|(r, _)| (r, command)),
                    ..ZLAC8015D
                };
                Some(p)
            }
            DriverKind::Generic => Some(self.generic.build().map_err(DriveLinkError::Profile)?),
        };
        if let Some(p) = profile {
            // Every drum speed the machine runs (up to N_MAX, eq. 7's cap)
            // must be read back exactly: 32 767 counts × scale ≥ 44.7 r/min,
            // i.e. |scale| ≥ 1365 µr/min per count (a ZLAC8015D's 0.1 r/min
            // behind paper A's 118:1 gearbox, 847, ends at 27.75 r/min).
            let top_micro = u64::from(p.micro_rpm_per_count.unsigned_abs())
                .saturating_mul(i16::MAX.unsigned_abs().into());
            let need_micro = u64::from(top).saturating_mul(1000);
            if top_micro < need_micro {
                return Err(DriveLinkError::SpeedRange {
                    top_milli_rpm: u32::try_from(top_micro / 1000).unwrap_or(u32::MAX),
                });
            }
            // And commanded: the command register holds the top speed.
            if let Some(needed) = p.command_counts_needed(top) {
                if needed > u32::from(i16::MAX.unsigned_abs()) {
                    return Err(DriveLinkError::CommandRange { needed });
                }
                // The ZLAC8015D's motor runs at most 1000 r/min (0x2008):
                // a gearbox that needs more for the drum's top speed is
                // refused here, not limited by the driver in the field.
                if self.kind == DriverKind::Zlac8015d && needed > ZLAC8015D_MAX_RPM {
                    return Err(DriveLinkError::MotorSpeed { needed_rpm: needed });
                }
            }
        }
        let uses_link =
            self.feedback != FeedbackSource::Encoder || self.command == CommandPath::Modbus;
        let config = match profile {
            None if uses_link => return Err(DriveLinkError::NoDriver),
            Some(p) if self.command == CommandPath::Modbus && p.speed_command.is_none() => {
                return Err(DriveLinkError::NoSpeedCommand)
            }
            Some(p) => {
                let mut c =
                    LinkConfig::for_profile(&p, self.timing).map_err(DriveLinkError::Timing)?;
                c.top_drum_milli_rpm = top;
                Some((p, c))
            }
            None => None,
        };
        Ok(config)
    }

    /// Where page 10's setting `p` sits in [`Self::to_bytes`]: offset and
    /// width (1, 2 or 4 bytes, little-endian).
    const fn field(p: LinkParameter) -> (usize, usize) {
        match p {
            LinkParameter::Feedback => (0, 1),
            LinkParameter::Command => (1, 1),
            LinkParameter::Driver => (2, 1),
            LinkParameter::Slave => (3, 1),
            LinkParameter::Baud => (4, 4),
            LinkParameter::SpeedRegister => (8, 2),
            LinkParameter::Scale => (10, 4),
            LinkParameter::FaultRegister => (14, 2),
            LinkParameter::CommandRegister => (29, 2),
            LinkParameter::ReplyTimeout => (31, 2),
            LinkParameter::RetryGap => (33, 2),
            LinkParameter::OfflineTime => (35, 2),
            LinkParameter::CommandScale => (37, 4),
            LinkParameter::ControlRegister => (41, 2),
            LinkParameter::EnableValue => (43, 2),
            LinkParameter::DisableValue => (45, 2),
            LinkParameter::ClearValue => (47, 2),
            LinkParameter::ModeRegister => (49, 2),
            LinkParameter::ModeValue => (51, 2),
            LinkParameter::OfflineRegister => (53, 2),
            LinkParameter::ResolutionRegister => (55, 2),
            LinkParameter::MaxSpeedRegister => (57, 2),
        }
    }

    /// The value page 10 shows for `p` (docs/hmi.md): the choices as their
    /// codes, the numbers as they are (a missing register as 0).
    #[must_use]
    pub fn value(&self, p: LinkParameter) -> i32 {
        let (at, width) = Self::field(p);
        let mut word = [0u8; 4];
        let bytes = self.to_bytes();
        if let (Some(dst), Some(src)) = (
            word.get_mut(..width),
            bytes.get(at..at.saturating_add(width)),
        ) {
            dst.copy_from_slice(src);
        }
        // The scales are the only signed values; the widest unsigned one,
        // the baud, is ≤ 115 200.
        i32::from_le_bytes(word)
    }

    /// These settings with `p` set to `v` (page 10), validated whole the
    /// way a stored block is ([`Self::from_bytes`], [`Self::build`]):
    /// `None` when `v` is no value of `p` (a code beyond the choices, a
    /// value wider than its field). A generic block no driver uses is
    /// checked when a driver is picked.
    ///
    /// ```
    /// use hmi_proto::screen::LinkParameter;
    /// use supervisor::drive_link::{DriveLinkError, DriveLinkSettings};
    /// let s = DriveLinkSettings::default();
    /// // Slave id 12: taken.
    /// assert_eq!(s.with(LinkParameter::Slave, 12).unwrap().unwrap().generic.slave, 12);
    /// // The driver's read-back as the feedback without a driver: refused.
    /// assert_eq!(s.with(LinkParameter::Feedback, 1), Some(Err(DriveLinkError::NoDriver)));
    /// // Feedback code 3 does not exist; a register has 16 bits.
    /// assert_eq!(s.with(LinkParameter::Feedback, 3), None);
    /// assert_eq!(s.with(LinkParameter::SpeedRegister, 65_536), None);
    /// ```
    pub fn with(&self, p: LinkParameter, v: i32) -> Option<Result<Self, DriveLinkError>> {
        let (at, width) = Self::field(p);
        let le = v.to_le_bytes();
        // Narrower fields take only values that fit them.
        let fits = match width {
            1 => u8::try_from(v).is_ok(),
            2 => u16::try_from(v).is_ok(),
            _ => true,
        };
        let mut bytes = self.to_bytes();
        bytes
            .get_mut(at..at.saturating_add(width))
            .zip(le.get(..width))
            .filter(|_| fits)
            .map(|(dst, src)| dst.copy_from_slice(src))?;
        if p == LinkParameter::CommandRegister {
            // Its presence byte: 0 is "no command register".
            *bytes.get_mut(28)? = u8::from(v != 0);
        }
        match Self::from_bytes(&bytes) {
            Err(DriveLinkError::Byte(_)) => None,
            other => Some(other),
        }
    }

    /// How old a read-back may be and still be used, µs: the link may be
    /// within its retry budget that long. Five link transactions
    /// ([`Self::readback_delay_us`]) — between two speed reads the master
    /// may write the command and read the fault word, and the read-back
    /// waits up to a control period more — never less than
    /// [`READBACK_MAX_AGE_US`], and at least one failed attempt (request,
    /// reply timeout, retry gap: [`LinkConfig::failed_attempt_us`]) and
    /// three transactions (the answered retry, a fault turn, the next
    /// speed read): 185 ms at 9600 baud with the default timing, 104 ms at
    /// 115 200. (A fixed 100 ms dropped the read-back at 9600 baud with
    /// the Modbus command: the drum was measured at 0 for a period and the
    /// controller commanded +51 %.)
    #[must_use]
    pub fn readback_max_age_us(&self) -> u32 {
        let one = self.readback_delay_us();
        let retry = LinkConfig::new(self.generic.baud, self.timing).map_or(0, |c| {
            c.failed_attempt_us().saturating_add(one.saturating_mul(3))
        });
        one.saturating_mul(5).max(READBACK_MAX_AGE_US).max(retry)
    }

    /// The read-back's typical delay the controller allows for, µs: one
    /// speed transaction on the line — request (8 characters), the
    /// driver's 2 ms turnaround, reply (7 characters) and the two
    /// 3.5-character gaps (27.2 ms at 9600 baud, 6.9 ms at 115 200).
    #[must_use]
    pub fn readback_delay_us(&self) -> u32 {
        let baud = self.generic.baud;
        let frames = drive_link::timing::frame_time_us(baud, 15).unwrap_or(0);
        let gap = drive_link::timing::silent_interval_us(baud).unwrap_or(0);
        frames
            .saturating_add(2_000)
            .saturating_add(gap.saturating_mul(2))
    }

    /// Whether the control loop runs through the link: the read-back as
    /// the feedback or the bus speed command. The drum controller is then
    /// the conventional PID (the fuzzy tuner's base gains, scaled by the
    /// lengthened dead time), not the fuzzy self-tuning one: the tuner's
    /// `Ki` follows the error and its change, and with a read-back held
    /// for a poll period (or a command the driver takes every other
    /// transaction) the error's change is a staircase; the integral then
    /// settles where `Σ Ki(e, ec)·e = 0`, not where the mean error is 0.
    /// Measured (70 m row, 9600 baud, read-back only, PWM): the read-back
    /// held 0.41 % above the drum model's reference on average and the row
    /// got 1003 plants; the conventional PID: mean error 0.00 %, 999
    /// plants (docs/drive-link.md, "The 70 m row at 9600 baud").
    #[must_use]
    pub fn delays_control(&self) -> bool {
        self.feedback == FeedbackSource::Driver || self.command == CommandPath::Modbus
    }

    /// Little-endian bytes (settings format 6): feedback (0 encoder, 1
    /// driver, 2 both), command (0 PWM, 1 Modbus), kind (0 none, 1
    /// ZLAC8015D, 2 generic), slave, baud (u32), speed register, scale
    /// (i32, µr/min per count), fault register, six fault masks, speed
    /// command register with a presence byte (1) before it — the 31 bytes
    /// of format 5 — then reply timeout, retry gap and offline time (ms,
    /// u16 each), command scale (i32), control register (0: none) with its
    /// enable, disable and clear values, mode register (0: none) and value,
    /// offline-time, speed-resolution and maximum-speed registers (0: none).
    #[must_use]
    pub fn to_bytes(&self) -> [u8; DRIVE_LINK_BYTES] {
        let g = &self.generic;
        let t = &self.timing;
        let c = g.control.unwrap_or(ControlWord {
            address: 0,
            ..CONTROL_DEFAULT
        });
        let (mode_register, mode_value) = g.velocity_mode.unwrap_or((0, MODE_DEFAULT));
        let [b0, b1, b2, b3] = g.baud.to_le_bytes();
        let [k0, k1, k2, k3] = g.micro_rpm_per_count.to_le_bytes();
        let [q0, q1, q2, q3] = g.command_scale.to_le_bytes();
        let w = |v: u16| v.to_le_bytes();
        let [sf0, sf1] = w(g.speed_feedback);
        let [fr0, fr1] = w(g.fault_register);
        let [[m0, m1], [m2, m3], [m4, m5], [m6, m7], [m8, m9], [m10, m11]] =
            g.fault_masks.map(u16::to_le_bytes);
        let [c0, c1] = w(g.speed_command.unwrap_or(0));
        let [r0, r1] = w(t.reply_timeout_ms);
        let [g0, g1] = w(t.retry_gap_ms);
        let [o0, o1] = w(t.offline_time_ms);
        let [cw0, cw1] = w(c.address);
        let [e0, e1] = w(c.enable);
        let [d0, d1] = w(c.disable);
        let [x0, x1] = w(c.clear_alarm);
        let [mr0, mr1] = w(mode_register);
        let [mv0, mv1] = w(mode_value);
        let [or0, or1] = w(g.offline_register.unwrap_or(0));
        let [rr0, rr1] = w(g.resolution_register.unwrap_or(0));
        let [xr0, xr1] = w(g.max_speed_register.unwrap_or(0));
        [
            self.feedback as u8,
            self.command as u8,
            self.kind as u8,
            g.slave,
            b0,
            b1,
            b2,
            b3,
            sf0,
            sf1,
            k0,
            k1,
            k2,
            k3,
            fr0,
            fr1,
            m0,
            m1,
            m2,
            m3,
            m4,
            m5,
            m6,
            m7,
            m8,
            m9,
            m10,
            m11,
            u8::from(g.speed_command.is_some()),
            c0,
            c1,
            r0,
            r1,
            g0,
            g1,
            o0,
            o1,
            q0,
            q1,
            q2,
            q3,
            cw0,
            cw1,
            e0,
            e1,
            d0,
            d1,
            x0,
            x1,
            mr0,
            mr1,
            mv0,
            mv1,
            or0,
            or1,
            rr0,
            rr1,
            xr0,
            xr1,
        ]
    }

    /// Reads [`Self::to_bytes`] and validates the result with
    /// [`Self::build`].
    pub fn from_bytes(b: &[u8; DRIVE_LINK_BYTES]) -> Result<Self, DriveLinkError> {
        let s = Self::parse(b)?;
        s.check()?;
        Ok(s)
    }

    /// [`Self::build`]'s checks, the profile and timing built and dropped.
    #[inline(never)]
    pub fn check(&self) -> Result<(), DriveLinkError> {
        self.config().map(|_| ())
    }

    /// Reads [`Self::to_bytes`] without validating more than its bytes
    /// (the choices' codes, the presence byte): [`Self::check`] the result.
    #[inline(never)]
    pub fn parse(b: &[u8; DRIVE_LINK_BYTES]) -> Result<Self, DriveLinkError> {
        let [f, c, k, slave, b0, b1, b2, b3, sf0, sf1, k0, k1, k2, k3, fr0, fr1, m0, m1, m2, m3, m4, m5, m6, m7, m8, m9, m10, m11, has, c0, c1, r0, r1, g0, g1, o0, o1, q0, q1, q2, q3, cw0, cw1, e0, e1, d0, d1, x0, x1, mr0, mr1, mv0, mv1, or0, or1, rr0, rr1, xr0, xr1] =
            *b;
        let w = |lo: u8, hi: u8| u16::from_le_bytes([lo, hi]);
        let register = |lo: u8, hi: u8| Some(w(lo, hi)).filter(|&r| r != 0);
        let feedback = match f {
            0 => FeedbackSource::Encoder,
            1 => FeedbackSource::Driver,
            2 => FeedbackSource::Both,
            other => return Err(DriveLinkError::Byte(other)),
        };
        let command = match c {
            0 => CommandPath::Pwm,
            1 => CommandPath::Modbus,
            other => return Err(DriveLinkError::Byte(other)),
        };
        let kind = match k {
            0 => DriverKind::None,
            1 => DriverKind::Zlac8015d,
            2 => DriverKind::Generic,
            other => return Err(DriveLinkError::Byte(other)),
        };
        let speed_command = match has {
            0 => None,
            1 => Some(w(c0, c1)),
            other => return Err(DriveLinkError::Byte(other)),
        };
        Ok(Self {
            feedback,
            command,
            kind,
            generic: GenericSettings {
                slave,
                baud: u32::from_le_bytes([b0, b1, b2, b3]),
                speed_feedback: w(sf0, sf1),
                micro_rpm_per_count: i32::from_le_bytes([k0, k1, k2, k3]),
                fault_register: w(fr0, fr1),
                fault_masks: [
                    w(m0, m1),
                    w(m2, m3),
                    w(m4, m5),
                    w(m6, m7),
                    w(m8, m9),
                    w(m10, m11),
                ],
                speed_command,
                command_scale: i32::from_le_bytes([q0, q1, q2, q3]),
                control: register(cw0, cw1).map(|address| ControlWord {
                    address,
                    enable: w(e0, e1),
                    disable: w(d0, d1),
                    clear_alarm: w(x0, x1),
                }),
                velocity_mode: register(mr0, mr1).map(|r| (r, w(mv0, mv1))),
                offline_register: register(or0, or1),
                resolution_register: register(rr0, rr1),
                max_speed_register: register(xr0, xr1),
            },
            timing: LinkTiming {
                reply_timeout_ms: w(r0, r1),
                retry_gap_ms: w(g0, g1),
                offline_time_ms: w(o0, o1),
            },
        })
    }

    /// Reads a block of settings format 5 ([`DRIVE_LINK_V5_BYTES`]): the
    /// link's timing gets its defaults; a generic profile keeps what it
    /// did — its command in the feedback's scale, no control word, mode
    /// write, offline time, resolution or maximum-speed register.
    pub fn from_v5_bytes(b: &[u8; DRIVE_LINK_V5_BYTES]) -> Result<Self, DriveLinkError> {
        let s = Self::parse_v5(b)?;
        s.check()?;
        Ok(s)
    }

    /// [`Self::from_v5_bytes`] without [`Self::check`].
    #[inline(never)]
    pub fn parse_v5(b: &[u8; DRIVE_LINK_V5_BYTES]) -> Result<Self, DriveLinkError> {
        let mut full = [0u8; DRIVE_LINK_BYTES];
        let (old, new) = full.split_at_mut(DRIVE_LINK_V5_BYTES);
        old.copy_from_slice(b);
        let t = LinkTiming::DEFAULT;
        let scale = b.get(10..14).unwrap_or(&[0; 4]);
        let mut at = 0usize;
        let mut put = |bytes: &[u8]| {
            let end = at.saturating_add(bytes.len());
            if let Some(dst) = new.get_mut(at..end) {
                dst.copy_from_slice(bytes);
            }
            at = end;
        };
        put(&t.reply_timeout_ms.to_le_bytes());
        put(&t.retry_gap_ms.to_le_bytes());
        put(&t.offline_time_ms.to_le_bytes());
        put(scale);
        // The registers stay 0: none.
        Self::parse(&full)
    }
}

/// The control word's values stored when a generic profile names no
/// control register (the ZLAC8015D's).
const CONTROL_DEFAULT: ControlWord = ControlWord {
    address: 0x200E,
    enable: 0x08,
    disable: 0x07,
    clear_alarm: 0x06,
};

/// The mode value stored when a generic profile names no mode register.
const MODE_DEFAULT: u16 = 3;

/// The read-back older than this is never used (the link is failing; the
/// link-lost alarm follows): three reply timeouts at 9600 baud. At low
/// baud rates the allowance is longer ([`DriveLinkSettings::readback_max_age_us`]).
pub const READBACK_MAX_AGE_US: u32 = 100_000;

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;

    /// Page 10's offsets (`field`) restate the block's layout: each
    /// setting written through `with` must land in its own struct field and
    /// read back through `value`, the others unchanged. Values by hand,
    /// each valid with a generic driver on a 20:1 gearbox.
    #[test]
    fn page_10_reaches_each_setting_through_the_bytes() {
        let base = DriveLinkSettings {
            kind: DriverKind::Generic,
            generic: GenericSettings {
                micro_rpm_per_count: 5000,
                command_scale: 50_000,
                speed_command: Some(0x2088),
                ..GENERIC_DEFAULT
            },
            ..DriveLinkSettings::default()
        };
        assert!(base.build().is_ok());
        type Field = fn(&DriveLinkSettings) -> i32;
        let control = |s: &DriveLinkSettings| s.generic.control.unwrap();
        let cases: [(LinkParameter, i32, Field); 22] = [
            (LinkParameter::Feedback, 2, |s| s.feedback as i32),
            (LinkParameter::Command, 1, |s| s.command as i32),
            (LinkParameter::Driver, 1, |s| s.kind as i32),
            (LinkParameter::Slave, 247, |s| i32::from(s.generic.slave)),
            (LinkParameter::Baud, 38_400, |s| {
                s.generic.baud.cast_signed()
            }),
            (LinkParameter::ReplyTimeout, 100, |s| {
                i32::from(s.timing.reply_timeout_ms)
            }),
            (LinkParameter::RetryGap, 50, |s| {
                i32::from(s.timing.retry_gap_ms)
            }),
            (LinkParameter::OfflineTime, 1000, |s| {
                i32::from(s.timing.offline_time_ms)
            }),
            (LinkParameter::Scale, -2_000, |s| {
                s.generic.micro_rpm_per_count
            }),
            (LinkParameter::SpeedRegister, 0xFFFE, |s| {
                i32::from(s.generic.speed_feedback)
            }),
            (LinkParameter::FaultRegister, 0x0102, |s| {
                i32::from(s.generic.fault_register)
            }),
            (LinkParameter::CommandRegister, 0x0300, |s| {
                i32::from(s.generic.speed_command.unwrap_or(0))
            }),
            (LinkParameter::CommandScale, -40_000, |s| {
                s.generic.command_scale
            }),
            (LinkParameter::ControlRegister, 0x0400, |s| {
                i32::from(s.generic.control.map_or(0, |c| c.address))
            }),
            (LinkParameter::EnableValue, 0x0F, |s| {
                i32::from(s.generic.control.unwrap().enable)
            }),
            (LinkParameter::DisableValue, 0x0E, |s| {
                i32::from(s.generic.control.unwrap().disable)
            }),
            (LinkParameter::ClearValue, 0x80, |s| {
                i32::from(s.generic.control.unwrap().clear_alarm)
            }),
            (LinkParameter::ModeRegister, 0x0500, |s| {
                i32::from(s.generic.velocity_mode.map_or(0, |m| m.0))
            }),
            (LinkParameter::ModeValue, 2, |s| {
                i32::from(s.generic.velocity_mode.unwrap().1)
            }),
            (LinkParameter::OfflineRegister, 0x0600, |s| {
                i32::from(s.generic.offline_register.unwrap_or(0))
            }),
            (LinkParameter::ResolutionRegister, 0x0700, |s| {
                i32::from(s.generic.resolution_register.unwrap_or(0))
            }),
            (LinkParameter::MaxSpeedRegister, 0x0800, |s| {
                i32::from(s.generic.max_speed_register.unwrap_or(0))
            }),
        ];
        // Every parameter of the page, once.
        assert_eq!(cases.map(|c| c.0), LinkParameter::ALL);
        for (p, v, field) in cases {
            let s = base.with(p, v).unwrap().unwrap();
            assert_eq!(field(&s), v, "{p:?}");
            assert_eq!(s.value(p), v, "{p:?}");
            for (q, _, other) in cases {
                if q != p {
                    assert_eq!(other(&s), other(&base), "{p:?} moved {q:?}");
                }
            }
        }
        // 0 is "no register" for the optional ones.
        let s = base
            .with(LinkParameter::CommandRegister, 0)
            .unwrap()
            .unwrap();
        assert_eq!(s.generic.speed_command, None);
        type Check = fn(&DriveLinkSettings) -> bool;
        let nones: [(LinkParameter, Check); 5] = [
            (LinkParameter::ControlRegister, |s| {
                s.generic.control.is_none()
            }),
            (LinkParameter::ModeRegister, |s| {
                s.generic.velocity_mode.is_none()
            }),
            (LinkParameter::OfflineRegister, |s| {
                s.generic.offline_register.is_none()
            }),
            (LinkParameter::ResolutionRegister, |s| {
                s.generic.resolution_register.is_none()
            }),
            (LinkParameter::MaxSpeedRegister, |s| {
                s.generic.max_speed_register.is_none()
            }),
        ];
        for (p, none) in nones {
            assert!(none(&base.with(p, 0).unwrap().unwrap()), "{p:?}");
        }
        assert_eq!(control(&base), GENERIC_DEFAULT.control.unwrap());
    }

    /// Values page 10 refuses, by name; the settings they were offered to
    /// stay as they were (`with` returns the error, nothing else).
    #[test]
    fn page_10_refuses_bad_link_timing_and_profiles_by_name() {
        let zlac = DriveLinkSettings {
            kind: DriverKind::Zlac8015d,
            generic: GenericSettings {
                micro_rpm_per_count: 5000,
                ..GENERIC_DEFAULT
            },
            ..DriveLinkSettings::default()
        };
        assert!(zlac.build().is_ok());
        let refused = |p, v| zlac.with(p, v).unwrap().unwrap_err().text();
        assert_eq!(
            refused(LinkParameter::ReplyTimeout, 4),
            "Reply timeout: 5-1000 ms"
        );
        assert_eq!(
            refused(LinkParameter::ReplyTimeout, 1001),
            "Reply timeout: 5-1000 ms"
        );
        assert_eq!(refused(LinkParameter::RetryGap, 1), "Retry gap: 2-1000 ms");
        // 115 200 baud: the link may be silent 2 × 62.6 + 20 + 0.8 = 146 ms
        // while it retries; the driver's offline time must not be shorter.
        assert_eq!(
            zlac.with(LinkParameter::OfflineTime, 145).unwrap(),
            Err(DriveLinkError::Timing(TimingError::OfflineTime {
                set: 145,
                least: 146
            }))
        );
        assert_eq!(
            refused(LinkParameter::OfflineTime, 145),
            "Offline time too short for retries"
        );
        assert!(zlac.with(LinkParameter::OfflineTime, 146).unwrap().is_ok());
        // A longer reply timeout lengthens that silence: 300 ms needs an
        // offline time of 626 ms (2 × 302.6 + 20.8), so the default 500 is
        // raised first.
        assert_eq!(
            refused(LinkParameter::ReplyTimeout, 300),
            "Offline time too short for retries"
        );
        let long = zlac.with(LinkParameter::OfflineTime, 626).unwrap().unwrap();
        let slow = long
            .with(LinkParameter::ReplyTimeout, 300)
            .unwrap()
            .unwrap();
        assert!(slow.with(LinkParameter::OfflineTime, 625).unwrap().is_err());
        // The ZLAC8015D behind 59:1 (1695 µr/min per count): 44.7 r/min
        // × 59 = 2637 motor r/min, beyond its 1000 (0x2008).
        assert_eq!(
            zlac.with(LinkParameter::Scale, 1695).unwrap(),
            Err(DriveLinkError::MotorSpeed { needed_rpm: 2638 })
        );
        assert_eq!(
            refused(LinkParameter::Scale, 1695),
            "Gearbox needs over 1000 motor r/min"
        );
        // 22:1 (4545): 44.7 × 22.002 = 983.5 r/min, taken.
        assert!(zlac.with(LinkParameter::Scale, 4545).unwrap().is_ok());
        // A generic profile: its control values must differ, its registers
        // too, its command scale be nonzero.
        let generic = DriveLinkSettings {
            kind: DriverKind::Generic,
            command: CommandPath::Modbus,
            generic: GenericSettings {
                speed_command: Some(0x2088),
                command_scale: 50_000,
                ..zlac.generic
            },
            ..zlac
        };
        assert!(generic.build().is_ok());
        let refused = |p, v| generic.with(p, v).unwrap().unwrap_err().text();
        assert_eq!(
            refused(LinkParameter::ClearValue, 8),
            "Control values must differ"
        );
        assert_eq!(
            refused(LinkParameter::ModeRegister, 0x20AB),
            "Registers must differ"
        );
        assert_eq!(
            refused(LinkParameter::CommandScale, 0),
            "Command scale must be nonzero"
        );
        // The drum's top speed (N_MAX, 44.700 r/min to the nearest
        // thousandth) at 1364 µr/min per count is 32 771.3 counts, rounded
        // up to 32 772: beyond the register.
        assert_eq!(
            generic.with(LinkParameter::CommandScale, 1364).unwrap(),
            Err(DriveLinkError::CommandRange { needed: 32_772 })
        );
    }

    #[test]
    fn link_settings_are_validated_and_round_trip() {
        let mut s = DriveLinkSettings::default();
        assert_eq!(s.build(), Ok(None));
        s.feedback = FeedbackSource::Driver;
        assert_eq!(s.build(), Err(DriveLinkError::NoDriver));
        s.kind = DriverKind::Zlac8015d;
        // Paper A's 118:1 gearbox behind the ZLAC8015D's 0.1 r/min: its
        // speed register ends at 32 767 × 847 µr/min = 27.753 r/min, below
        // the drum's 44.7 (hand-computed): refused.
        assert_eq!(
            s.build(),
            Err(DriveLinkError::SpeedRange {
                top_milli_rpm: 27_753
            })
        );
        assert_eq!(
            std::format!("{}", s.build().unwrap_err()),
            "driver speed register ends at 27.753 r/min, below the drum's 44.7"
        );
        // The edge: 44.7 r/min / 32 767 = 1364.18 µr/min per count, so
        // 1364 ends at 44.694 r/min (refused) and 1365 at 44.727 (read
        // back, but 44.7 r/min needs 3275 motor r/min then: beyond the
        // ZLAC8015D's 1000).
        s.generic.micro_rpm_per_count = 1364;
        assert!(matches!(s.build(), Err(DriveLinkError::SpeedRange { .. })));
        s.generic.micro_rpm_per_count = -1364;
        assert!(matches!(s.build(), Err(DriveLinkError::SpeedRange { .. })));
        s.generic.micro_rpm_per_count = 1365;
        assert_eq!(
            s.build(),
            Err(DriveLinkError::MotorSpeed { needed_rpm: 3275 })
        );
        // A 20:1 gearbox: 100 000 / 20 = 5000.
        s.generic.micro_rpm_per_count = 5000;
        let p = s.build().unwrap().unwrap();
        // The ZLAC8015D's registers, the gearbox in the scale, the command
        // in whole r/min: ten times the feedback's scale; its resolution,
        // maximum speed and offline time registers.
        assert_eq!(p.speed_feedback, 0x20AB);
        assert_eq!(p.micro_rpm_per_count, 5000);
        assert_eq!(p.speed_command, Some((0x2088, 50_000)));
        assert_eq!(
            (
                p.resolution_register,
                p.max_speed_register,
                p.offline_register
            ),
            (Some(0x2022), Some(0x2008), Some(0x2000))
        );
        assert_eq!(p.baud, 115_200);
        let (_, c) = s.config().unwrap().unwrap();
        assert_eq!(c.top_drum_milli_rpm, kinematics::consts::N_MAX.to_milli());
        assert_eq!(c.offline_time_ms, 500);
        s.command = CommandPath::Modbus;
        s.kind = DriverKind::Generic;
        assert_eq!(s.build(), Err(DriveLinkError::NoSpeedCommand));
        s.generic.speed_command = Some(0x0300);
        s.generic.micro_rpm_per_count = 1695;
        assert!(s.build().is_ok());
        assert_eq!(DriveLinkSettings::from_bytes(&s.to_bytes()), Ok(s));
        s.generic.baud = 4800;
        assert_eq!(
            s.build(),
            Err(DriveLinkError::Profile(ProfileError::Baud(4800)))
        );
        assert_eq!(
            std::format!("{}", s.build().unwrap_err()),
            "driver profile: baud 4800 not 9600/19200/38400/57600/115200"
        );
        // The read-back's allowance: 15 characters + 2 ms + two gaps:
        // 9600: 17 188 + 2 000 + 2 × 4 011 = 27 210 µs.
        s.generic.baud = 9600;
        assert_eq!(s.readback_delay_us(), 27_210);
        s.generic.baud = 115_200;
        // 1 433 + 2 000 + 2 × 1 750.
        assert_eq!(s.readback_delay_us(), 6_933);
    }

    #[test]
    fn link_bytes_follow_the_documented_layout() {
        // The layout of `to_bytes`' rustdoc, little-endian, written by hand:
        // feedback 2 (both), command 1 (Modbus), kind 2 (generic), slave 7,
        // baud 19 200 = 0x4B00, speed register 0x0102, scale −1695 =
        // 0xFFFFF961, fault register 0x0304, masks 0x0001, 0x0002, 0x0004,
        // 0x0008, 0x0010, 0x0020, command present, register 0x0506; then
        // reply timeout 80 ms, retry gap 30 ms, offline time 600 ms = 0x0258,
        // command scale −16 950 = 0xFFFFBDCA, control register 0x0607 with
        // 0x11, 0x22, 0x33, mode register 0x0708 = 4, offline register
        // 0x0809, resolution register none, maximum speed register 0x0A0B.
        let s = DriveLinkSettings {
            feedback: FeedbackSource::Both,
            command: CommandPath::Modbus,
            kind: DriverKind::Generic,
            generic: GenericSettings {
                slave: 7,
                baud: 19_200,
                speed_feedback: 0x0102,
                micro_rpm_per_count: -1695,
                fault_register: 0x0304,
                fault_masks: [1, 2, 4, 8, 16, 32],
                speed_command: Some(0x0506),
                command_scale: -16_950,
                control: Some(ControlWord {
                    address: 0x0607,
                    enable: 0x11,
                    disable: 0x22,
                    clear_alarm: 0x33,
                }),
                velocity_mode: Some((0x0708, 4)),
                offline_register: Some(0x0809),
                resolution_register: None,
                max_speed_register: Some(0x0A0B),
            },
            timing: LinkTiming {
                reply_timeout_ms: 80,
                retry_gap_ms: 30,
                offline_time_ms: 600,
            },
        };
        let bytes: [u8; DRIVE_LINK_BYTES] = [
            2, 1, 2, 7, 0x00, 0x4B, 0, 0, 0x02, 0x01, 0x61, 0xF9, 0xFF, 0xFF, 0x04, 0x03, 1, 0, 2,
            0, 4, 0, 8, 0, 16, 0, 32, 0, 1, 0x06, 0x05, // format 5's 31 bytes
            80, 0, 30, 0, 0x58, 0x02, 0xCA, 0xBD, 0xFF, 0xFF, 0x07, 0x06, 0x11, 0, 0x22, 0, 0x33,
            0, 0x08, 0x07, 4, 0, 0x09, 0x08, 0, 0, 0x0B, 0x0A,
        ];
        assert_eq!(s.to_bytes(), bytes);
        assert_eq!(DriveLinkSettings::from_bytes(&bytes), Ok(s));
        // An unknown presence byte is refused, not read as "none".
        let mut bad = bytes;
        bad[28] = 2;
        assert_eq!(
            DriveLinkSettings::from_bytes(&bad),
            Err(DriveLinkError::Byte(2))
        );
    }

    /// A block of settings format 5 (31 bytes): the generic profile does
    /// what it did — its command in the feedback's scale, no control word,
    /// mode write, offline, resolution or maximum-speed register — and the
    /// link's timing gets its defaults. A ZLAC8015D block keeps its kind
    /// (its registers come from the profile).
    #[test]
    fn a_format_5_block_migrates_to_what_it_did() {
        let v5: [u8; DRIVE_LINK_V5_BYTES] = [
            1, 1, 2, 7, 0x00, 0x4B, 0, 0, 0x02, 0x01, 0x9F, 0x06, 0, 0, 0x04, 0x03, 1, 0, 2, 0, 4,
            0, 8, 0, 16, 0, 32, 0, 1, 0x06, 0x05,
        ];
        let s = DriveLinkSettings::from_v5_bytes(&v5).unwrap();
        assert_eq!(s.timing, LinkTiming::DEFAULT);
        assert_eq!(s.kind, DriverKind::Generic);
        assert_eq!(s.generic.micro_rpm_per_count, 1695);
        assert_eq!(s.generic.command_scale, 1695);
        assert_eq!(s.generic.speed_command, Some(0x0506));
        let p = s.build().unwrap().unwrap();
        assert_eq!(p.speed_command, Some((0x0506, 1695)));
        assert_eq!(
            (
                p.control,
                p.velocity_mode,
                p.offline_register,
                p.resolution_register,
                p.max_speed_register
            ),
            (None, None, None, None, None)
        );
        // Its first 31 bytes are the record's.
        assert_eq!(s.to_bytes()[..DRIVE_LINK_V5_BYTES], v5);
        // A bad format-5 block stays refused.
        let mut bad = v5;
        bad[3] = 0;
        assert_eq!(
            DriveLinkSettings::from_v5_bytes(&bad),
            Err(DriveLinkError::Profile(ProfileError::SlaveId(0)))
        );
    }
}
