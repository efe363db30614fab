//! The operating logic of profile A: modes, faults, calibration and the 10 ms
//! control step.
//!
//! [`Supervisor`] owns everything the control path needs — the Hall speed
//! estimator, the calibration, the drum plan (eq. 7–10) and the fuzzy PID —
//! and is driven by three calls:
//!
//! - [`Supervisor::hall_edge`] for each captured Hall edge (1 MHz ticks);
//! - [`Supervisor::control_step`] every control period with the drum encoder
//!   counter, returning the PWM compare value and the driver enable;
//! - [`Supervisor::command`] for each validated operator command from the
//!   screen, returning what the screen should show next.
//!
//! # Faults and safe states
//!
//! | fault | detected when | action |
//! |---|---|---|
//! | drum stall (or encoder lost) | the drum is commanded ≥ 1 r/min and the encoder has not moved for 200 ms | PWM 0, driver off, latched alarm until acknowledged |
//! | Hall signal lost | Speed-Adaptive, drum running, and the next Hall edge is later than a chassis braking at its physical limit allows ([`HALL_SILENCE_DECEL_MM_S2`]; evidence exists only above ≈ 3.4 km/h) | PWM 0, driver off, latched alarm until acknowledged |
//! | too fast for the spacing | eq. 7 asks for more than `n_max` | drum held at `n_max`, warning with the allowed maximum (not latched) |
//!
//! A stalled drum and a lost encoder look the same from here (commanded, no
//! counts); the alarm names both. A silent Hall sensor is a lost signal only
//! when the chassis cannot have stopped before the next tooth: below
//! ≈ 3.4 km/h it can (1 g stops it within a millimetre at Low 2), so there
//! the silence is taken for a stop — the travel speed decays to zero, the
//! drum follows it and runs again with the next edges, without an alarm
//! (docs/firmware.md, "Faults"). After an acknowledged alarm the machine is
//! stopped: the operator presses Start again.

use fixed::types::U16F16;
use fuzzy_pid::{Controller, I16F16};
use hmi_proto::screen::{self, CalibrationKind, Command, Mode};
use kinematics::{
    consts,
    drum::{DrumPlan, DrumSettings, DrumTarget},
    speed::{DecelerationBound, EstimatorSettings, MotionState, MtEstimator},
    table::{CoeffTable, TablePoint},
    travel,
    units::{Metres, RevPerMin, Ticks},
};

use crate::drive::{exp_neg_q30, DriveModel, Identifier, IdentifyError, IdentifyState};
use crate::phase::{first_plant_place_um, Phase, PlantEvent};
use crate::settings::{self, Placement, Settings};

/// Fixed facts of the board the supervisor runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hardware {
    /// Drum encoder counts per drum revolution (motor encoder × gearbox).
    pub encoder_counts_per_drum_rev: u32,
    /// Control period, µs (the Hall timer's ticks are µs too).
    pub control_period_us: u32,
    /// PWM timer auto-reload value (compare value for 100 % duty is ARR + 1).
    pub pwm_arr: u16,
}

impl Hardware {
    /// The STM32F103 board: a 100-line encoder in ×4 quadrature behind the
    /// 118:1 gearbox, a 10 ms control period, TIM1 at 20 kHz from 72 MHz.
    pub const BOARD: Self = Self {
        encoder_counts_per_drum_rev: 400 * 118,
        control_period_us: 10_000,
        pwm_arr: 3599,
    };
}

/// Errors building a [`Supervisor`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// The hardware description is unusable (zero counts or period).
    Hardware,
    /// The Hall estimator's settings were rejected.
    Estimator,
    /// The drum plan (spacing, ARR) was rejected.
    DrumPlan,
    /// The controller configuration was rejected.
    Controller,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Hardware => "bad hardware description",
            Self::Estimator => "bad Hall estimator settings",
            Self::DrumPlan => "bad drum plan (spacing or PWM period)",
            Self::Controller => "bad controller configuration",
        })
    }
}

/// A condition the operator must see.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Alarm {
    /// Commanded drum with no encoder motion: jammed drum, or encoder lost.
    /// Latched.
    DrumStall,
    /// Commanded drum whose feedback turned backwards for the whole stall
    /// time (encoder: ≥ 2 counts a period the wrong way; driver read-back:
    /// below −1 r/min): the motor's wiring or direction, the encoder's A/B
    /// (the encoder direction setting) or the driver scale's sign. Latched.
    DrumBackwards,
    /// The next Hall edge is later than any stop of the chassis allows
    /// (module docs) while the drum was running. Latched.
    HallLost,
    /// No Hall edge for [`NO_PULSES_US`] while the drum runs in
    /// Speed-Adaptive mode with the unit down: the tractor has stopped, or
    /// the Hall sensor (or its wire) is dead and the machine plants
    /// nothing while it moves. One sensor cannot tell them apart below
    /// High 3 (module docs), so this is a warning, not a stop: it clears
    /// with the next edges.
    NoTravelPulses,
    /// Travel speed too high for the spacing; the drum is held at `n_max`.
    /// Clears by itself. Carries the allowed maximum, km/h × 100.
    TooFast {
        /// The highest travel speed this spacing allows, km/h × 100.
        max_kmh_x100: u16,
    },
    /// The drum speed oscillated, or missed the drive model's response by
    /// more than 5 % for more than 1 s: the controller switched to its
    /// conservative mode (see [`Supervisor`]'s instability supervisor). A
    /// warning: the drum keeps running. Run the drive identification again.
    DrumUnstable,
    /// The drive identification ended without a model (a warning).
    IdentifyFailed(IdentifyError),
    /// The drum driver reports a fault over its link (the first named
    /// one). Latched.
    DriverFault(drive_link::profile::DriverFault),
    /// No valid reply from the drum driver within the link's retry budget.
    /// Latched; acknowledged only once the driver answers again.
    LinkLost,
    /// The link is lost because the driver answers with Modbus exceptions:
    /// its profile names a register or function this driver does not have
    /// (a generic profile's registers, most often). As [`Alarm::LinkLost`]
    /// otherwise.
    LinkRefused,
    /// The driver answers, but its set-up refuses it: its maximum speed
    /// is below what the drum's top speed needs through the gearbox, or
    /// its speed resolution is unusable
    /// ([`drive_link::link::SetupFault`]). As [`Alarm::LinkLost`]
    /// otherwise; cleared once the driver's register is corrected.
    DriverSetup(crate::drive_link::SetupRefusal),
    /// Encoder and driver read-back disagree beyond the cross-check's
    /// margin for its hold time ([`drive_link::cross_check`]): a lost
    /// encoder, or a driver reporting wrong. Latched.
    SpeedMismatch,
}

impl Alarm {
    /// Latched alarms stop the drum and need an acknowledgement.
    pub const fn is_latched(&self) -> bool {
        matches!(
            self,
            Self::DrumStall
                | Self::DrumBackwards
                | Self::HallLost
                | Self::DriverFault(_)
                | Self::LinkLost
                | Self::LinkRefused
                | Self::DriverSetup(_)
                | Self::SpeedMismatch
        )
    }

    /// The text for the screen (ASCII, at most 40 characters).
    pub fn write_text(&self, w: &mut impl core::fmt::Write) -> core::fmt::Result {
        match self {
            Self::DrumStall => w.write_str("Drum stalled or encoder lost"),
            Self::DrumBackwards => w.write_str("Drum turns backwards: check direction"),
            Self::HallLost => w.write_str("Hall speed signal lost"),
            Self::NoTravelPulses => w.write_str(NO_PULSES_TEXT),
            Self::DrumUnstable => w.write_str(DRUM_UNSTABLE_TEXT),
            Self::IdentifyFailed(e) => w.write_str(e.text()),
            Self::DriverFault(f) => {
                use drive_link::profile::DriverFault as F;
                w.write_str(match f {
                    F::OverCurrent => "Driver fault: over-current",
                    F::OverVoltage => "Driver fault: over-voltage",
                    F::UnderVoltage => "Driver fault: under-voltage",
                    F::Overload => "Driver fault: overload",
                    F::HallOrEncoder => "Driver fault: Hall/encoder",
                    F::OverTemperature => "Driver fault: over-temperature",
                    F::Other(_) => "Driver fault (unnamed)",
                })
            }
            Self::LinkLost => w.write_str("Drum driver link lost"),
            Self::LinkRefused => w.write_str("Driver refuses register: check profile"),
            Self::DriverSetup(crate::drive_link::SetupRefusal::MaxSpeed) => {
                w.write_str("Driver max speed too low for gearbox")
            }
            Self::DriverSetup(crate::drive_link::SetupRefusal::Resolution) => {
                w.write_str("Driver speed resolution unusable")
            }
            Self::SpeedMismatch => w.write_str("Encoder or driver speed wrong"),
            Self::TooFast { max_kmh_x100 } => {
                // Digits by hand: `write!` with integers would pull in
                // `core::fmt`'s number formatting (~2 KB of flash), and
                // `str::from_utf8` on a digit buffer 300 B more.
                const DIGITS: [&str; 10] = ["0", "1", "2", "3", "4", "5", "6", "7", "8", "9"];
                let v = *max_kmh_x100;
                w.write_str("Too fast: max ")?;
                // km/h × 100 ≤ 655.35: up to three integer digits, no
                // leading zeros, then always two decimals.
                let mut started = false;
                for (place, point) in [
                    (10_000, false),
                    (1000, false),
                    (100, true),
                    (10, false),
                    (1, false),
                ] {
                    let d = usize::from(v.checked_div(place).unwrap_or(0) % 10);
                    if d > 0 || started || place <= 100 {
                        w.write_str(DIGITS.get(d).copied().unwrap_or("?"))?;
                        started = true;
                    }
                    if point {
                        w.write_str(".")?;
                    }
                }
                w.write_str(" km/h")
            }
        }
    }
}

/// The answer to a link setting on an image without the drum driver's link
/// (feature `drive-link` off): page 10 is read-only there.
pub const NO_DRIVE_LINK: &str = "Drive link not in this image";

/// The message shown when the drive identification starts.
pub const IDENTIFY_MESSAGE: &str = "Identifying drive: keep belt empty";

/// The warning text of [`Alarm::NoTravelPulses`] (the screen's 40
/// characters).
pub const NO_PULSES_TEXT: &str = "No travel pulses: check Hall, or Stop";

/// The warning text of [`Alarm::DrumUnstable`].
pub const DRUM_UNSTABLE_TEXT: &str = "Drum unstable: safe mode, identify";

/// Whether the drum is running.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RunState {
    /// Drum off (driver disabled, PWM 0).
    Stopped,
    /// Drum under control in the current mode.
    Running,
    /// The drive identification steps the drum (page 9, belt empty).
    Identifying,
}

/// What the board must apply after a control step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Actuation {
    /// PWM compare value (duty = `ccr / (ARR + 1)`).
    pub ccr: u16,
    /// Motor driver enable.
    pub driver_enabled: bool,
}

impl Actuation {
    /// Drum off.
    pub const OFF: Self = Self {
        ccr: 0,
        driver_enabled: false,
    };
}

/// What the screen should do after a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Effect {
    /// Nothing beyond the live status.
    None,
    /// The settings shown changed (write them back to the screen).
    SettingsChanged,
    /// Persist the settings now (the drum is stopped).
    Save,
    /// Show this message in the message box.
    Message(&'static str),
    /// The alarm was acknowledged: leave the alarm page.
    AlarmCleared,
}

/// Live values for the screen and the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Snapshot {
    /// Corrected travel speed, km/h × 1000.
    pub travel_speed_kmh_x1000: u32,
    /// Hall gear speed as measured (M/T, before the prediction across the
    /// gap since the last edge), r/min × 1000.
    pub measured_gear_rpm_x1000: u32,
    /// Hall gear speed after the prediction, r/min × 1000.
    pub predicted_gear_rpm_x1000: u32,
    /// Target drum speed, r/min × 1000.
    pub target_drum_rpm_x1000: u32,
    /// Measured drum speed, smoothed over ≈ 0.5 s, r/min × 1000.
    pub actual_drum_rpm_x1000: u32,
    /// PWM compare value applied.
    pub ccr: u16,
    /// Plants planted since Start (belt partitions passed).
    pub plants: u32,
    /// Ground distance since Start, mm.
    pub distance_mm: u32,
    /// Hall edges counted since boot.
    pub hall_edges: u32,
    /// Control steps since boot.
    pub steps: u32,
}

/// State of the on-screen calibration run (k1, k2 or k3, docs/hmi.md page 4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationRun {
    /// No run.
    Idle,
    /// Counting since these totals.
    Counting {
        /// Hall edges at the start.
        start_edges: u32,
        /// Control steps at the start.
        start_steps: u32,
        /// Drum encoder counts at the start.
        start_drum_counts: u64,
    },
    /// Run ended: what it counted and how long it took.
    Measured {
        /// Hall edges in the run.
        edges: u32,
        /// Control steps the run lasted.
        steps: u32,
        /// Drum encoder counts in the run.
        drum_counts: u64,
    },
    /// The operator entered the taped length; the coefficient is computed.
    Computed {
        /// Which coefficient.
        kind: CalibrationKind,
        /// Where it goes in its table: monitored km/h (k1), wheel km/h (k2)
        /// or drum r/min (k3).
        at: U16F16,
        /// The coefficient.
        k: kinematics::units::Coefficient,
    },
}

/// Stall: commanded drum speed from which the encoder must move.
const STALL_MIN_COMMAND: I16F16 = I16F16::lit("1");
/// Stall: time without encoder motion, µs.
const STALL_TIME_US: u32 = 200_000;
/// Backwards: encoder counts a period against the drum's direction that
/// count as turning backwards (the drum at the stall command of 1 r/min
/// makes 7.9 a period, 47 200 counts a turn; a still drum's jitter is ±1).
const BACKWARD_MIN_COUNTS: u16 = 2;
/// Hall silence: the fastest the Hall gear's speed can fall when the
/// tractor stops, mm/s² of monitored track speed: the chassis limit of 1 g
/// ([`consts::CHASSIS_DECEL_LIMIT_MM_S2`]) seen through a k1 down to 0.934
/// (9.81 / 0.934 = 10.5; paper A's Table 11 has k1 = 0.966 … 1.031), so
/// that no stop the chassis can make reads as a lost signal.
pub const HALL_SILENCE_DECEL_MM_S2: u32 = 10_500;
/// Ground distance: a Hall edge the speed estimator drops as a glitch for
/// its ¼-period rule still counts as a tooth when it comes at least this
/// long (µs) after the previous counted edge. The ¼ rule protects the speed
/// estimate, but it also drops real teeth: a tractor pulling away from a
/// crawl (a last gap of 1 s or more) makes its next gap shorter than a
/// quarter of it, and each dropped tooth cost the distance 25 mm
/// (measured on the stop-and-go profile: 86 mm lost in 60 s at Low 2, 61 mm
/// with the estimator's bounded glitch reference of aa1e4a8, test
/// `the_ground_distance_keeps_every_tooth_through_stops`; docs/placement.md). 5 ms is ten times the switch's
/// hard glitch limit (500 µs) and below the shortest real gap (9 ms at
/// 10 km/h).
pub const DISTANCE_EDGE_MIN_GAP_US: u32 = 5_000;
/// No Hall edge for this long (µs), while the drum runs in Speed-Adaptive
/// mode with the unit down, raises [`Alarm::NoTravelPulses`]: 2.5 s, nine
/// edge periods of the slowest gear (Low 1, 0.32 km/h at the gear: 283 ms
/// an edge; 300 ms on the terrain's −5 %), so that no working speed leaves
/// such a silence, and short enough that the warning is up within 3 s of a
/// sensor's death (the last edge came before it). A 2 s rest of a
/// stop-and-go is shorter (at most 2.4 s between edges at Low 1 with a
/// 0.5 s chassis); a longer one shows the warning, which clears with the
/// first edges after it.
pub const NO_PULSES_US: u32 = 2_500_000;
/// Hall silence: the tolerance on a gap's length, % — pitch errors of
/// teeth whose share is not learned yet (±2 % of a pitch per tooth, so
/// ±4 % per gap) and the capture jitter.
pub const HALL_SILENCE_GAP_TOLERANCE_PCT: u8 = 5;
/// Smoothing of the reported drum speed: `Ts / (Ts + τ)` with `τ` = 0.5 s.
/// The seedlings load the drum once per partition (1.5 Hz at 20 r/min), a
/// ripple of about ±1 % that the operator need not watch; the mean, which the
/// controller holds, is what the screen and the log show.
const REPORT_ALPHA: I16F16 = I16F16::lit("0.0196");

/// Smoothing of the drum speed k3 is looked up at: `Ts / (Ts + τ)` with
/// `τ` = 30 ms. One encoder count in 10 ms is 0.13 r/min; across a corner
/// of the k3 table (20 r/min) that quantisation biased the mean k3 and moved
/// the belt's phase by 2.2 mm per 300 m of ground (40 cm at High 2,
/// noiseless). Short enough that the lookup follows a start (the reported
/// speed's 0.5 s held k3 at its rest value while the drum ran up, 1.3 %).
const K3_SPEED_ALPHA: I16F16 = I16F16::lit("0.25");

/// The machine's operating logic (profile A).
pub struct Supervisor {
    hw: Hardware,
    pub(crate) settings: Settings,
    plan: DrumPlan,
    estimator: MtEstimator,
    /// The drum controller, or, while the drive is identified, the
    /// identification in its place (they are never needed together; sharing
    /// the space keeps the supervisor small).
    drum: Drum,
    /// The last identification's outcome (its model until saved).
    identified: IdentifyState,
    run: RunState,
    alarm: Option<Alarm>,
    calibration_run: CalibrationRun,
    calibration_kind: CalibrationKind,
    /// The link setting page 10 shows and sets.
    link_parameter: screen::LinkParameter,
    /// The link settings in force: those the supervisor was built with.
    /// Page 10 edits `settings.drive_link`, which the board's link task
    /// takes only at the next start (docs/drive-link.md).
    link_in_force: crate::drive_link::LinkInForce,
    /// Drum encoder counts since boot.
    drum_counts_total: u64,
    last_encoder: Option<u16>,
    /// The Hall timer's time at the last control step.
    last_step_at: Option<Ticks>,
    stall_us: u32,
    /// The part of the stall time so far in which the drum turned
    /// backwards, µs.
    stall_back_us: u32,
    /// Encoder counts of the last period against the drum's direction.
    encoder_back: u16,
    /// The reported (smoothed) drum speed, r/min.
    reported: I16F16,
    /// The drum speed k3 is looked up at, r/min ([`K3_SPEED_ALPHA`]).
    k3_speed: I16F16,
    /// The phase loop's correction, smoothed when the link delays the
    /// control (distance-locked placement, [`PHASE_SMOOTHING`]), r/min.
    phase_smoothed: I16F16,
    /// The smoothing's factor in force ([`PHASE_SMOOTHING`] … 1).
    phase_alpha: I16F16,
    /// Hall edges since boot.
    edges: u32,
    /// Hall edges counted for the ground distance since boot (the accepted
    /// ones and the plausible teeth the estimator dropped), and the time of
    /// the last one.
    teeth: u32,
    /// The teeth's learned pitches summed, Q16 (wraps; differences only).
    pitches_q16: u32,
    last_tooth_at: Option<u32>,
    /// Ground distance since Start (∫ V1 dt), µm, and its fraction (Q24).
    pub(crate) distance_um: u64,
    distance_frac: u64,
    /// The chassis's deceleration limit at the Hall gear, for the silence
    /// rule.
    hall_silence: DecelerationBound,
    /// When the Hall silence began to count for [`Alarm::NoTravelPulses`]
    /// (Start, a lowering, Speed-Adaptive chosen), Hall timer ticks.
    quiet_from: u32,
    /// Drum encoder counts since Start, each weighted by the belt slip k3
    /// (U2F30, its full precision) at the drum speed measured when it was
    /// counted: Σ Δcounts · k3(n) · 2³⁰. The plant count follows from it
    /// ([`Supervisor::partitions_x1e6`]).
    belt_counts_k3: u64,
    /// The drum speed the feed-forward alone should produce by now: the
    /// target through a model of the drum's response (see
    /// [`REFERENCE_ALPHA`]). The PID corrects the measurement towards it.
    reference: I16F16,
    /// The targets of the last periods, newest at `ref_head`: the reference
    /// model's input, delayed by the drive's dead time. In r/min × 256
    /// (±127 r/min: every accepted `n_max`), to keep the supervisor small.
    ref_history: [i16; REF_HISTORY],
    ref_head: usize,
    /// What follows from the drive model in force.
    law: DriveLaw,
    /// Whether the controller is scheduled from the drive model
    /// ([`Supervisor::new`]) or was given ([`Supervisor::with_controller`]).
    scheduled: bool,
    /// The conservative mode after an instability (until a new drive model).
    fallback: bool,
    monitor: Monitor,
    predictor: Predictor,
    snapshot: Snapshot,
    /// Distance-locked placement: ground and belt positions, the phase
    /// loop and the partitions' events ([`crate::phase`]).
    pub(crate) phase: Phase,
    /// The work switch's effect on the drum and the count
    /// ([`crate::planting`]).
    pub(crate) work: crate::planting::Work,
    /// Live planting quality ([`crate::quality`]).
    pub(crate) quality: crate::quality::Quality,
    /// The drum driver's link: its newest sample, the read-back's
    /// integration, the cross-check ([`crate::drive_link`]).
    pub(crate) link: crate::drive_link::Feedback,
}

/// Bridges the Hall sensor's sparse updates (one edge every 170 ms at Low 2)
/// by extrapolating the gear speed along its last slope.
///
/// The M/T estimate describes the middle of its window, which by the next
/// control period is already half a tooth period (plus the time since the
/// edge) old; while the tractor accelerates the drum would lag by that age
/// times the acceleration. The slope between the last two estimates, applied
/// over the estimate's age, removes most of that lag. The correction is
/// bounded (±10 % of the estimate, and never beyond two tooth periods of
/// age) so that one bad edge cannot run away; at standstill or after a
/// restart it is zero.
#[derive(Clone, Copy, Debug, Default)]
struct Predictor {
    /// Last estimate (U12F20 bits) and the time its window's middle
    /// represents (ticks).
    last: Option<(i64, u32)>,
    /// Slope: change of the estimate (bits) over that many ticks.
    slope: (i64, i64),
    /// Mean tooth period of the last window, ticks.
    period: u32,
    /// The last window's gaps read noisy
    /// ([`kinematics::speed::TravelMeasurement::noisy`]).
    noisy: bool,
}

impl Predictor {
    fn predict(&mut self, m: &kinematics::speed::TravelMeasurement, now: Ticks) -> RevPerMin {
        match m.state {
            MotionState::Measured if m.edges > 0 => {
                // A fresh window: its middle is `since_edge + window/2` ago.
                let v = i64::from(m.gear_speed.to_bits());
                let center = now
                    .0
                    .wrapping_sub(m.since_edge_ticks)
                    .wrapping_sub(m.window_ticks / 2);
                if let Some((v0, t0)) = self.last {
                    let dt = i64::from(center.wrapping_sub(t0));
                    // A change beyond what unlearnt teeth make (each gap
                    // ±4 %: two differ by at most 8 %; a start from rest
                    // changes by tens of %) is the speed's.
                    let b0 = u32::try_from(v0).unwrap_or(0);
                    let real = m.gear_speed.to_bits().abs_diff(b0) > b0 / 25;
                    // The slope only between two windows whose teeth are
                    // learnt, or for a real change: otherwise it is the
                    // tooth errors', which the extrapolation multiplied.
                    let clean = !m.noisy && !self.noisy;
                    let (trend, trend_ticks) = m.trend;
                    self.slope = if dt > 0 && (clean || real) {
                        (v.saturating_sub(v0), dt)
                    } else if trend_ticks > 0 && dt > 0 {
                        // The speed changes beyond what the teeth make (the
                        // estimator's change between two adjacent runs of
                        // gaps): the slope between the windows, kept to the
                        // trend's sign and at most its size (the trend
                        // describes the runs' middles, further back).
                        let (dv, tt) = (v.saturating_sub(v0), i64::from(trend_ticks));
                        let trend = i64::from(trend);
                        if dv.signum() != trend.signum() {
                            (0, 1)
                        } else if dv.saturating_mul(tt).abs() <= trend.saturating_mul(dt).abs() {
                            (dv, dt)
                        } else {
                            (trend, tt)
                        }
                    } else if !m.noisy && self.noisy {
                        // The first window after the teeth were learnt:
                        // the last slope goes on.
                        self.slope
                    } else {
                        (0, 1)
                    };
                }
                self.noisy = m.noisy;
                self.last = Some((v, center));
                self.period = m.window_ticks.checked_div(m.edges).unwrap_or(0);
            }
            MotionState::Measured | MotionState::Holding | MotionState::Decaying => {}
            MotionState::Stopped | MotionState::Starting => {
                *self = Self::default();
                return m.gear_speed;
            }
        }
        let Some((v, center)) = self.last else {
            return m.gear_speed;
        };
        let age =
            i64::from(now.0.wrapping_sub(center)).min(i64::from(self.period).saturating_mul(2));
        let (dv, dt) = self.slope;
        // `max`/`min` rather than `clamp`: the bounds are not constant, and
        // `clamp` would carry a (never taken) panic with formatted values.
        let bound = v.checked_div(10).unwrap_or(0).max(0);
        let step = dv
            .saturating_mul(age)
            .checked_div(dt)
            .unwrap_or(0)
            .max(bound.saturating_neg())
            .min(bound);
        let bits = v.saturating_add(step).clamp(0, i64::from(u32::MAX));
        let predicted = RevPerMin::from_bits(u32::try_from(bits).unwrap_or(0));
        if m.state == MotionState::Decaying {
            // Overdue edge: the estimator's bound (one gap over the elapsed
            // time) caps the estimate; it is no estimate of its own (above
            // a smoothed value it would raise it).
            predicted.min(m.gear_speed)
        } else {
            predicted
        }
    }
}

/// Smoothing factor of the reference model of the drum on the default drive,
/// `1 − e^(−Ts/τ)` with `Ts` = 10 ms and the motor's `τ` = 25 ms. With a
/// drive model ([`DriveModel`], identified on page 9) the factor is computed
/// from its τ and the model's input is delayed by its dead time
/// (docs/firmware.md, "The drum drive model"); on the default model that
/// is this value and two periods.
///
/// The model predicts what the *measurement* (encoder counts over the period
/// that just ended) should read if the feed-forward alone drove the drum:
/// a first-order lag on the command of two periods ago. Two periods because
/// the command set at step k acts after the drive's 5 ms dead time and is
/// seen averaged over the period ending at step k + 1. For a step command
/// this reproduces the averaged response of a 25 ms lag with 5 ms dead time
/// to within 1 % of the step from the second period on (0, 0.33, 0.55, 0.70
/// of the step against the exact 0.05, 0.33, 0.55, 0.70).
///
/// Why: the feed-forward already drives the drum to the target; comparing the
/// measurement with the *target* during a speed change would feed the PID an
/// error that only reflects the drum's lag, wind up the integral and
/// overshoot. Comparing it with the modelled response leaves the PID only the
/// part of the error the feed-forward cannot explain (load, slip, model
/// mismatch): a two-degree-of-freedom structure.
pub const REFERENCE_ALPHA: I16F16 = I16F16::lit("0.3297");

/// Targets the reference model remembers: a dead time up to 200 ms
/// ([`DriveModel::DEAD_TIME_MAX`]) is 1 + 21 periods of 10 ms.
const REF_HISTORY: usize = 24;

/// The drum controller, or the drive identification in its place.
// The variants differ in size by design: the point is sharing the space
// (no heap to box into).
#[allow(clippy::large_enum_variant)]
enum Drum {
    /// Not built yet ([`Supervisor::new`]): built at the first control step.
    Unbuilt,
    Control(Controller),
    Identify(Identifier),
}

/// What the controller takes from the drive model: the feed-forward gain
/// (`n_max`), the reference model's smoothing and delay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct DriveLaw {
    /// Drum speed at 100 % duty, r/min × 100.
    n_max_x100: u16,
    /// `n_max` in r/min.
    n_max: I16F16,
    /// `1 − e^(−T/τ)`.
    ref_alpha: I16F16,
    /// Periods from a target to the reference model's lag input:
    /// `1 + round((L + T/2)/T)` (the command acts after the dead time `L`
    /// and is seen in the mean of the period it falls in, half a period
    /// later on average). 2 on the default drive, as before the model.
    ref_delay: usize,
}

impl DriveLaw {
    fn of(model: &DriveModel, period_us: u32) -> Self {
        let t_x10 = i64::from(period_us / 100).max(1);
        let tau_x10 = i64::from(model.tau_x10_ms()).max(1);
        let dead_x10 = i64::from(model.dead_time_x10_ms());
        // T/τ in Q30 (T ≤ 6553.5 ms, τ ≥ 1 ms: ≤ 2^16 · 2^30).
        let x = (t_x10 << 30).checked_div(tau_x10).unwrap_or(0);
        let alpha_q30 = (1i64 << 30).saturating_sub(exp_neg_q30(x));
        let ref_alpha = I16F16::from_bits(i32::try_from(alpha_q30 >> 14).unwrap_or(i32::MAX));
        let periods = dead_x10
            .saturating_add(t_x10 / 2)
            .saturating_add(t_x10 / 2)
            .checked_div(t_x10)
            .unwrap_or(0);
        let ref_delay = usize::try_from(periods.saturating_add(1))
            .unwrap_or(REF_HISTORY)
            .clamp(2, REF_HISTORY);
        Self {
            n_max_x100: model.n_max_x100(),
            n_max: centi_to_fix(model.n_max_x100()),
            ref_alpha,
            ref_delay,
        }
    }
}

/// The controller scheduled from the drive model: [`drum_controller_config`]
/// with every gain (base gains, fuzzy ranges, floors) scaled by
/// `s = min(1, (τ/θ) / (τ₀/θ₀))`, output limited to the model's `n_max`.
///
/// `θ = L + T` is the loop's effective dead time (the drive's dead time
/// plus half a period of PWM hold and half a period of measurement mean),
/// `τ₀/θ₀ = 25/15` the drive the fuzzy PID was tuned on. The proportional
/// gain SIMC gives a first-order-plus-dead-time plant, `Kc = τ/(K·2θ)`
/// (τc = θ), scales with `τ/θ`; so does the integral gain at a fixed
/// `τI = τ` and the ultimate gain when θ ≫ τ. Keeping the product's
/// proven gains where the drive is as fast as or slower than the design
/// (`s = 1`) and shrinking all of them in the SIMC ratio where the dead time
/// grows or τ shrinks keeps the fuzzy tuner's shape and the nominal
/// behaviour (bench §1) unchanged. docs/fuzzy-pid.md has the table.
pub fn scheduled_config(model: &DriveModel, period_us: u32) -> fuzzy_pid::Config {
    let mut config = drum_controller_config();
    let s = schedule_scale(model, period_us);
    let scale = |g: fuzzy_pid::Gains| fuzzy_pid::Gains {
        kp: g.kp.saturating_mul(s),
        ki: g.ki.saturating_mul(s),
        kd: g.kd.saturating_mul(s),
    };
    config.base = scale(config.base);
    config.min_gains = scale(config.min_gains);
    if let fuzzy_pid::Schedule::Fuzzy(fuzzy) = &mut config.schedule {
        fuzzy.range = scale(fuzzy.range);
    }
    config.output_max = centi_to_fix(model.n_max_x100());
    config
}

/// The scale `s` of [`scheduled_config`], in (0, 1].
pub fn schedule_scale(model: &DriveModel, period_us: u32) -> I16F16 {
    // In 0.1 ms: τ₀ = 250, θ₀ = 50 + 100 (5 ms dead time + 10 ms period).
    let t_x10 = i64::from(period_us / 100);
    let theta = i64::from(model.dead_time_x10_ms())
        .saturating_add(t_x10)
        .max(1);
    let theta0 = 50i64.saturating_add(t_x10);
    let s = i64::from(model.tau_x10_ms())
        .saturating_mul(theta0)
        .saturating_mul(1 << 16)
        .checked_div(theta.saturating_mul(250))
        .unwrap_or(0)
        .clamp(1, 1 << 16);
    I16F16::from_bits(i32::try_from(s).unwrap_or(1 << 16))
}

/// Smoothing of the phase loop's correction when the drum's loop runs
/// through the drive link (`DriveLinkSettings::delays_control`):
/// `1 − e^(−10 ms / 100 ms)`. The correction steps at every Hall edge (the
/// ground is exact there and extrapolated between edges); a loop that sees
/// the drum 30–90 ms late (the read-back) or moves it a transaction late
/// (the bus command) answers such steps with an overshoot, and the
/// instability supervisor tripped in 6 of 80 rows of 70 m at 9600 baud (seeds
/// 1–40, PWM and Modbus command)
/// (test `distance_locked_rows_on_the_readback_raise_no_instability_warning`).
/// 100 ms is the slowest link's delay; against the phase loop's 0.5 s it
/// costs at most atan(0.2) ≈ 11° of phase margin.
const PHASE_SMOOTHING: I16F16 = I16F16::lit("0.0952");
/// How fast the phase correction's smoothing fades out when it is no longer
/// needed: its factor rises by this much a period, from [`PHASE_SMOOTHING`]
/// to 1 in 0.5 s, so that the correction does not jump to its unsmoothed
/// value.
const PHASE_FADE: I16F16 = I16F16::lit("0.02");

/// The conservative mode after an instability: no proportional or
/// derivative action, integral only with `Ki` = [`FALLBACK_KI`] per period,
/// on top of the feed-forward and the reference model.
///
/// An integrator with gain `Ki/T` behind a delay θ has its crossover at
/// `Ki/T` rad/s and a phase margin of `90° − Ki·θ/T`: with `Ki` = 0.02 and
/// up to 200 ms of effective dead time (the longest a drive model holds)
/// that is ≥ 67°, and ≥ 44° with a drive twice as strong as its model. The
/// price: load changes are corrected in about `T/Ki` = 0.5 s.
pub fn fallback_config(model: &DriveModel) -> fuzzy_pid::Config {
    let mut config = fuzzy_pid::Config::conventional(fuzzy_pid::Gains {
        kp: I16F16::ZERO,
        ki: FALLBACK_KI,
        kd: I16F16::ZERO,
    });
    config.output_max = centi_to_fix(model.n_max_x100());
    config
}

/// Integral gain per period of the conservative mode ([`fallback_config`]).
pub const FALLBACK_KI: I16F16 = I16F16::lit("0.02");

/// Instability supervisor: the tracking error (measurement against the
/// reference model) smoothed over 0.25 s beyond 5 % of the target for more
/// than 1 s, or the unsmoothed error swinging by more than 25 % of the
/// target within each of two consecutive 0.5 s windows.
#[derive(Clone, Copy, Debug, Default)]
struct Monitor {
    /// Smoothed tracking error, r/min.
    error: I16F16,
    /// Time the smoothed error has been beyond the band, µs.
    beyond_us: u32,
    /// Extremes of the error in the current window, and its length.
    low: I16F16,
    high: I16F16,
    periods: u8,
    /// Consecutive windows with a swing beyond the limit.
    swinging: u8,
}

/// Smoothing of the monitored tracking error: `1 − e^(−10 ms / 0.25 s)`. The
/// seedlings' load (up to ±5 % at 1.5–3 Hz) is damped to about a third, so
/// it does not count as a tracking error.
const MONITOR_ALPHA: I16F16 = I16F16::lit("0.0392");
/// The slowest target the instability supervisor judges: 3 r/min. Below it
/// the driver's dead band (3 % duty, 1.3 r/min on the design drive) and the
/// encoder's resolution (one count per 10 ms is 0.13 r/min) make 5 % of the
/// target meaningless; a tractor coming to rest passes there (test
/// `no_false_instability_warning_in_the_field_at_every_gear`: at High 1 the
/// drum sat at 1.5 r/min under a 1.15 r/min target for more than 1 s).
const MONITOR_MIN_TARGET: I16F16 = I16F16::lit("3");
/// Band of the smoothed tracking error: 5 % of the target.
const MONITOR_BAND: I16F16 = I16F16::lit("0.05");
/// Time beyond the band that is an instability, µs.
const MONITOR_TIME_US: u32 = 1_000_000;
/// Swing (max − min) of the error in a window that counts as an
/// oscillation: 25 % of the target. The seedlings' load swings the speed by
/// up to 10 %; the limit cycle of issue 16 (a 20 ms drive on the 5 ms
/// tuning) by 80 %.
const MONITOR_SWING: I16F16 = I16F16::lit("0.25");
/// Window of the swing, periods (0.5 s at 10 ms), and how many windows in a
/// row make an oscillation (1 s).
const MONITOR_WINDOW: u8 = 50;
const MONITOR_WINDOWS: u8 = 2;

impl Monitor {
    /// One running period; `true` when the drum is unstable. `saturated`:
    /// the last output was 0 or 100 % duty — a drum that cannot follow
    /// (a target at `n_max` under load: the Too fast warning's business) is
    /// not a tracking error of the loop.
    fn step(
        &mut self,
        expected: I16F16,
        measured: I16F16,
        target: I16F16,
        elapsed_us: u32,
        saturated: bool,
    ) -> bool {
        if target < MONITOR_MIN_TARGET {
            *self = Self::default();
            return false;
        }
        let dev = expected.saturating_sub(measured);
        self.error = smooth(self.error, dev, MONITOR_ALPHA);
        if !saturated && self.error.saturating_abs() > target.saturating_mul(MONITOR_BAND) {
            self.beyond_us = self.beyond_us.saturating_add(elapsed_us);
        } else {
            self.beyond_us = 0;
        }
        if self.periods == 0 {
            self.low = dev;
            self.high = dev;
        }
        self.low = self.low.min(dev);
        self.high = self.high.max(dev);
        self.periods = self.periods.saturating_add(1);
        if self.periods >= MONITOR_WINDOW {
            if self.high.saturating_sub(self.low) > target.saturating_mul(MONITOR_SWING) {
                self.swinging = self.swinging.saturating_add(1);
            } else {
                self.swinging = 0;
            }
            self.periods = 0;
        }
        self.beyond_us > MONITOR_TIME_US || self.swinging >= MONITOR_WINDOWS
    }
}

/// One step of a first-order filter: `acc + (x − acc)·alpha`, saturating.
#[inline(never)]
fn smooth(acc: I16F16, x: I16F16, alpha: I16F16) -> I16F16 {
    acc.saturating_add(x.saturating_sub(acc).saturating_mul(alpha))
}

/// A drum speed in r/min as the tables' `RevPerMin` (I16F16 → U12F20: 4
/// more fractional bits, exact; negative as 0).
fn fix_to_rpm(n: I16F16) -> RevPerMin {
    RevPerMin::from_bits(
        u32::try_from(n.to_bits().max(0))
            .unwrap_or(0)
            .min(u32::MAX >> 4)
            << 4,
    )
}

fn rpm_to_fix(n: RevPerMin) -> I16F16 {
    // U12F20 → I16F16: drop 4 fractional bits (rounding down, as `fixed`'s
    // conversions); below 4096 r/min it always fits (test
    // `rpm_to_fix_is_fixeds_conversion`).
    I16F16::from_bits(i32::try_from(n.to_bits() >> 4).unwrap_or(i32::MAX))
}

/// `x × 1000`, rounded to nearest (halves up), negative values as 0:
/// computed from the raw bits in `i64`, so every `I16F16` (up to
/// 32 767.99 r/min) is reported exactly. Multiplying in `I16F16` itself
/// saturated at 32.767 r/min (issue 16 item 4). Rounding (not flooring)
/// gives back the decimal a speed was set from: 25.21 r/min is
/// 1 652 163 / 65 536 = 25.210 005 in I16F16, and 25.209 995 when truncated.
pub fn milli(x: I16F16) -> u32 {
    // |bits| < 2^31, × 1000 < 2^41: no overflow; `>>` floors.
    let v = i64::from(x.to_bits())
        .saturating_mul(1000)
        .saturating_add(1 << 15)
        >> 16;
    u32::try_from(v.max(0)).unwrap_or(u32::MAX)
}

/// A speed as r/min × 256 in an `i16` (saturating at ±127.99 r/min).
fn to_i16_x256(x: I16F16) -> i16 {
    let v = x.to_bits() >> 8;
    i16::try_from(v).unwrap_or(if v < 0 { i16::MIN } else { i16::MAX })
}

/// A speed in r/min × 100 (the screen's unit) as the nearest `I16F16`.
fn centi_to_fix(raw: u16) -> I16F16 {
    // raw · 65 536 / 100, rounded: ≤ 65 535 · 65 536 < 2^32, fits i64.
    let bits = i64::from(raw)
        .saturating_mul(65_536)
        .saturating_add(50)
        .checked_div(100)
        .unwrap_or(0);
    I16F16::from_bits(i32::try_from(bits).unwrap_or(i32::MAX))
}

impl Supervisor {
    /// Builds the supervisor from validated settings, stopped, with the
    /// drum controller tuned for this machine ([`drum_controller_config`]).
    ///
    /// The controller itself is built at the first control step (or Start),
    /// not here: building the fuzzy tuner takes 1.3 KB of stack, which at
    /// boot would sit on top of the supervisor's own 1.5 KB being built, in
    /// `init`. The scheduled configuration is valid for every valid drive
    /// model (its gains are scaled by `s ∈ (0, 1]`, test
    /// `scheduled_configs_build_for_extreme_models`).
    pub fn new(hw: Hardware, settings: Settings) -> Result<Self, Error> {
        Self::build(hw, settings, Drum::Unbuilt, true)
    }

    /// As [`Supervisor::new`] with another drum controller (for comparisons:
    /// the conventional PID, other rule-base sizes).
    pub fn with_controller(
        hw: Hardware,
        settings: Settings,
        controller: &fuzzy_pid::Config,
    ) -> Result<Self, Error> {
        let controller = controller.build().map_err(|_| Error::Controller)?;
        Self::build(hw, settings, Drum::Control(controller), false)
    }

    fn build(hw: Hardware, settings: Settings, drum: Drum, scheduled: bool) -> Result<Self, Error> {
        if hw.encoder_counts_per_drum_rev == 0 || hw.control_period_us == 0 {
            return Err(Error::Hardware);
        }
        let estimator = EstimatorSettings::default()
            .build()
            .map_err(|_| Error::Estimator)?;
        let hall_silence = DecelerationBound::new(
            HALL_SILENCE_DECEL_MM_S2,
            consts::HALL_GAP_UM,
            estimator.settings().timer_hz,
            HALL_SILENCE_GAP_TOLERANCE_PCT,
        )
        .map_err(|_| Error::Estimator)?;
        let plan = Self::plan_for(&settings, hw)?;
        let law = DriveLaw::of(&settings.drive, hw.control_period_us);
        // Without the link in the image: encoder and PWM, the saved link
        // settings kept for the record.
        let link_in_force = if cfg!(feature = "drive-link") {
            crate::drive_link::LinkInForce::from(&settings.drive_link)
        } else {
            crate::drive_link::LinkInForce::default()
        };
        let phase = Phase::new(hw.encoder_counts_per_drum_rev, settings.spacing.raw());
        Ok(Self {
            hw,
            settings,
            plan,
            estimator,
            drum,
            identified: IdentifyState::Idle,
            run: RunState::Stopped,
            alarm: None,
            calibration_run: CalibrationRun::Idle,
            calibration_kind: CalibrationKind::SlipK2,
            link_parameter: screen::LinkParameter::Feedback,
            link_in_force,
            drum_counts_total: 0,
            last_encoder: None,
            last_step_at: None,
            stall_us: 0,
            stall_back_us: 0,
            encoder_back: 0,
            reported: I16F16::ZERO,
            k3_speed: I16F16::ZERO,
            phase_smoothed: I16F16::ZERO,
            phase_alpha: I16F16::ONE,
            edges: 0,
            teeth: 0,
            pitches_q16: 0,
            last_tooth_at: None,
            distance_um: 0,
            distance_frac: 0,
            hall_silence,
            quiet_from: 0,
            belt_counts_k3: 0,
            reference: I16F16::ZERO,
            ref_history: [0; REF_HISTORY],
            ref_head: 0,
            law,
            scheduled,
            fallback: false,
            monitor: Monitor::default(),
            predictor: Predictor::default(),
            snapshot: Snapshot::default(),
            phase,
            work: crate::planting::Work::new(),
            quality: crate::quality::Quality::new(),
            link: crate::drive_link::Feedback::default(),
        })
    }

    /// Whether [`Supervisor::new`] accepts these settings (the drum plan is
    /// the only part that depends on them), without building anything.
    pub fn check(hw: Hardware, settings: &Settings) -> Result<(), Error> {
        Self::plan_for(settings, hw).map(|_| ())
    }

    fn plan_for(settings: &Settings, hw: Hardware) -> Result<DrumPlan, Error> {
        Self::plan_of(settings.spacing, hw)
    }

    /// The drum plan of a spacing (all of the settings it depends on).
    fn plan_of(spacing: screen::Spacing, hw: Hardware) -> Result<DrumPlan, Error> {
        let spacing = Metres::from_mm(u32::from(spacing.raw()));
        DrumSettings::new(spacing, hw.pwm_arr)
            .build()
            .map_err(|_| Error::DrumPlan)
    }

    /// The settings in force.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Running or stopped.
    pub fn run_state(&self) -> RunState {
        self.run
    }

    /// The alarm shown, if any.
    pub fn alarm(&self) -> Option<Alarm> {
        self.alarm
    }

    /// The on-screen calibration run.
    pub fn calibration_run(&self) -> CalibrationRun {
        self.calibration_run
    }

    /// The drum controller's state (gains, error terms, output) after the
    /// last step, for logs and comparisons.
    pub fn controller_status(&self) -> fuzzy_pid::Status {
        match &self.drum {
            Drum::Control(c) => *c.status(),
            Drum::Unbuilt | Drum::Identify(_) => fuzzy_pid::Status::default(),
        }
    }

    /// Live values after the last step.
    pub fn snapshot(&self) -> Snapshot {
        self.snapshot
    }

    /// The highest travel speed the current spacing allows, km/h × 100:
    /// the plan's (eq. 7 at the paper's `n_max`) scaled to the drum's
    /// limit in force (a drive identified slower) and divided by the motor
    /// coefficient (the target is eq. 7 times it).
    pub fn max_travel_kmh_x100(&self) -> u16 {
        let cal = &self.settings.calibration;
        let cap = self.drum_cap();
        let rpm_milli = |n: I16F16| {
            let m = milli(n);
            let k3 = cal
                .k3_at(RevPerMin::from_ratio(m, 1000).unwrap_or(RevPerMin::ZERO))
                .to_milli();
            u64::from(m).saturating_mul(u64::from(k3))
        };
        // V_max ∝ n·k3(n) (eq. 7 solved for the travel speed).
        let num = rpm_milli(cap).saturating_mul(100);
        let den = rpm_milli(rpm_to_fix(consts::N_MAX))
            .saturating_mul(u64::from(self.settings.motor_coefficient.raw()));
        self.plan
            .max_travel_speed(cal)
            .ok()
            .and_then(|v| u64::from(v.to_milli()).saturating_mul(num).checked_div(den))
            .map_or(0, |v| u16::try_from(v / 10).unwrap_or(u16::MAX))
    }

    /// The drum speed the target is held at: the paper's `n_max`, or a
    /// drive identified slower its own.
    fn drum_cap(&self) -> I16F16 {
        rpm_to_fix(kinematics::consts::N_MAX).min(self.law.n_max)
    }

    /// Takes one Hall edge (1 MHz capture ticks, extended to 32 bits).
    pub fn hall_edge(&mut self, t: Ticks) {
        let before = self.estimator.accepted_edges();
        let verdict = self.estimator.push_edge(t);
        // One edge, or two: a suspect edge confirmed by this one
        // ([`MtEstimator::push_edge`]); none for a glitch or a suspect.
        let accepted = self.estimator.accepted_edges().wrapping_sub(before);
        self.edges = self.edges.wrapping_add(accepted);
        let mut teeth = accepted;
        let mut pitches = 0u32;
        for back in 0..accepted {
            pitches = pitches.wrapping_add(self.estimator.gap_pitches_q16(back as usize));
        }
        // The ground distance also counts an edge the estimator drops for
        // its ¼-period rule when it is a plausible tooth
        // ([`DISTANCE_EDGE_MIN_GAP_US`]), at a nominal pitch.
        let gap = self.last_tooth_at.map_or(u32::MAX, |l| t.0.wrapping_sub(l));
        if accepted == 0
            && verdict == kinematics::speed::EdgeVerdict::Early
            && gap >= DISTANCE_EDGE_MIN_GAP_US
        {
            teeth = 1;
            pitches = 1 << 16;
        }
        if teeth > 0 {
            self.teeth = self.teeth.wrapping_add(teeth);
            self.pitches_q16 = self.pitches_q16.wrapping_add(pitches);
            self.last_tooth_at = Some(t.0);
        }
    }

    /// Says that Hall edges were lost before the next one (the capture
    /// timer's overcapture flag): the interval ending at the next edge is not
    /// measured ([`kinematics::speed::MtEstimator::edges_lost`]).
    pub fn hall_edges_lost(&mut self) {
        self.estimator.edges_lost();
    }

    /// Stops the drum (no alarm).
    pub fn stop(&mut self) {
        if self.run == RunState::Running {
            // The pass in progress ends here, with its partitions still
            // waiting for a tooth.
            self.flush_pending();
            self.quality.end_pass(self.distance_um);
        }
        self.run = RunState::Stopped;
        match &mut self.drum {
            Drum::Control(c) => c.stop(),
            Drum::Unbuilt => {}
            Drum::Identify(_) => {
                self.identified = IdentifyState::Failed(IdentifyError::Aborted);
                // Rebuilt by the next control step, not here: a Stop comes
                // through the screen task, and building the
                // fuzzy controller (≈ 1.4 KB of stack) on top of its frame
                // reached 4.7 KB of stack (static analysis of the image:
                // handle_event → command → stop → restore_controller →
                // Config::build).
                self.drum = Drum::Unbuilt;
            }
        }
        self.stall_us = 0;
    }

    fn start(&mut self) -> Effect {
        if let Some(alarm) = self.alarm {
            if alarm.is_latched() {
                return Effect::Message("Acknowledge the alarm first");
            }
        }
        if self.run == RunState::Stopped {
            match &mut self.drum {
                Drum::Identify(_) => return Effect::Message("Drive identification running"),
                Drum::Control(c) => c.start(),
                // Built (and started, since running) by the next control
                // step's `ensure_controller`, not here on the screen task's
                // stack (see `stop`).
                Drum::Unbuilt => {}
            }
            self.run = RunState::Running;
            self.stall_us = 0;
            self.distance_um = 0;
            self.distance_frac = 0;
            self.belt_counts_k3 = 0;
            self.phase.start(self.teeth, self.pitches_q16);
            self.realign_next_plant(first_plant_place_um(self.settings.spacing.raw()));
            self.start_planting();
        }
        Effect::None
    }

    /// Ground distance since Start, µm: Hall edges since the first one
    /// after Start × the calibrated distance per edge, extrapolated between
    /// edges ([`crate::phase`]).
    pub fn ground_distance_um(&self) -> u64 {
        self.phase.ground_um()
    }

    /// The next partition to leave shall leave at ground distance
    /// `at_ground_distance_um` (since Start), then one every spacing; a new
    /// pass. Start calls it with [`first_plant_place_um`] (the spacing plus
    /// one Hall pitch, docs/placement.md).
    pub fn realign_next_plant(&mut self, at_ground_distance_um: u64) {
        self.phase.realign(at_ground_distance_um);
    }

    /// The partitions that left in the last control step, each with the
    /// ground distance at that moment.
    pub fn plants_left(&self) -> impl Iterator<Item = PlantEvent> + '_ {
        self.phase.events()
    }

    /// The belt moved since Start as the firmware measures it, µm (drum
    /// encoder × belt per count × k3, docs/placement.md "Positions").
    pub fn belt_distance_um(&self) -> u64 {
        self.phase.belt_um()
    }

    /// The phase error after the last step, µm of ground (positive: the belt
    /// is ahead, plants land short of their places). Also computed in
    /// speed-following placement, where nothing corrects it.
    pub fn phase_error_um(&self) -> i64 {
        self.phase.error_ground_um()
    }

    fn latch(&mut self, alarm: Alarm) {
        self.alarm = Some(alarm);
        self.stop();
    }

    /// Applies one operator command from the screen (already range-checked
    /// by the screen contract).
    #[inline(never)]
    pub fn command(&mut self, cmd: Command) -> Effect {
        match cmd {
            Command::Start => self.start(),
            Command::Stop => {
                self.stop();
                Effect::None
            }
            Command::SelectMode(mode) => {
                if mode != self.settings.mode {
                    // Bumpless: the controller restarts from its output.
                    self.settings.mode = mode;
                    if let (RunState::Running, Drum::Control(c)) = (self.run, &mut self.drum) {
                        c.start();
                    }
                }
                Effect::SettingsChanged
            }
            Command::SetSpacing(spacing) => {
                // The plan depends on the spacing alone: no copy of the
                // settings to try it on (≈ 130 B of flash).
                match Self::plan_of(spacing, self.hw) {
                    Ok(plan) => {
                        self.plan = plan;
                        self.settings.spacing = spacing;
                        self.phase.set_spacing(spacing.raw());
                        if self.run == RunState::Running {
                            // The new spacing from one spacing ahead.
                            let at = self
                                .ground_distance_um()
                                .saturating_add(u64::from(spacing.raw()).saturating_mul(1000));
                            self.realign_next_plant(at);
                        }
                        Effect::SettingsChanged
                    }
                    Err(_) => Effect::Message("Spacing rejected"),
                }
            }
            Command::SetFixedDrumSpeed(speed) => {
                self.settings.fixed_drum_speed = speed;
                Effect::SettingsChanged
            }
            Command::SetMotorCoefficient(k) => {
                self.settings.motor_coefficient = k;
                Effect::SettingsChanged
            }
            Command::SelectGear(gear) => {
                self.settings.gear = settings::gear_from_screen(gear);
                Effect::SettingsChanged
            }
            Command::SelectCalibration(kind) => {
                self.calibration_kind = kind;
                self.calibration_run = CalibrationRun::Idle;
                Effect::SettingsChanged
            }
            Command::CalibrationStart => {
                self.calibration_run = CalibrationRun::Counting {
                    start_edges: self.edges,
                    start_steps: self.snapshot.steps,
                    start_drum_counts: self.drum_counts_total,
                };
                Effect::None
            }
            Command::CalibrationStop => {
                if let CalibrationRun::Counting {
                    start_edges,
                    start_steps,
                    start_drum_counts,
                } = self.calibration_run
                {
                    self.calibration_run = CalibrationRun::Measured {
                        edges: self.edges.wrapping_sub(start_edges),
                        steps: self.snapshot.steps.wrapping_sub(start_steps),
                        drum_counts: self.drum_counts_total.saturating_sub(start_drum_counts),
                    };
                }
                Effect::None
            }
            Command::CalibrationActualDistance(distance) => {
                self.compute_coefficient(distance.raw())
            }
            Command::CalibrationAccept => self.accept_coefficient(),
            Command::SetCalibrationCoefficient(k) => {
                let k = kinematics::units::Coefficient::from_ratio(u32::from(k.raw()), 1000);
                let at = self.hand_set_abscissa();
                match k.map(|k| self.set_table_point(self.calibration_kind, at, k)) {
                    Some(Ok(())) => Effect::SettingsChanged,
                    _ => Effect::Message("Coefficient rejected"),
                }
            }
            Command::AcknowledgeAlarm => {
                if let Some(effect) = self.acknowledge_link_alarm() {
                    return effect;
                }
                if self.alarm.is_some() {
                    self.alarm = None;
                    Effect::AlarmCleared
                } else {
                    Effect::None
                }
            }
            Command::SaveSettings => {
                if self.run == RunState::Running {
                    // A flash erase stalls the CPU for up to 40 ms.
                    Effect::Message("Stop the drum before saving")
                } else {
                    Effect::Save
                }
            }
            Command::SetBrightness(b) => {
                self.settings.brightness = b;
                Effect::SettingsChanged
            }
            Command::IdentifyDrive => {
                if self.run != RunState::Stopped {
                    return Effect::Message("Stop the drum first");
                }
                if self.alarm.is_some_and(|a| a.is_latched()) {
                    return Effect::Message("Acknowledge the alarm first");
                }
                if matches!(self.alarm, Some(Alarm::IdentifyFailed(_))) {
                    self.alarm = None;
                }
                let mut id = Identifier::new(self.hw.control_period_us);
                id.start();
                self.drum = Drum::Identify(id);
                self.identified = IdentifyState::Running;
                self.run = RunState::Identifying;
                self.stall_us = 0;
                self.belt_counts_k3 = 0;
                Effect::Message(IDENTIFY_MESSAGE)
            }
            Command::AcceptDriveModel => match self.identify_state() {
                IdentifyState::Done(model) if self.run == RunState::Stopped => {
                    self.use_drive(model);
                    self.identified = IdentifyState::Idle;
                    if self.alarm == Some(Alarm::DrumUnstable) {
                        self.alarm = None;
                    }
                    // Persisted at once (the drum is stopped).
                    Effect::Save
                }
                _ => Effect::Message("Identify the drive first"),
            },
            // Applies from the next control step (the counter's raw value
            // is kept, only the sign of its delta changes).
            Command::SetDrumEncoderReversed(reversed) => {
                self.settings.drum_encoder_reversed = reversed;
                Effect::SettingsChanged
            }
            // Apply at once (crate::planting); persisted by Save.
            Command::SetWorkSwitchFitted(fitted) => {
                self.set_work_switch_fitted(fitted);
                Effect::SettingsChanged
            }
            Command::SetFirstPlantDistance(d) => {
                self.settings.first_plant_distance = d;
                Effect::SettingsChanged
            }
            // Only with the drum stopped: switched while running, the phase
            // error that speed-following let build up would be made up at
            // the loop's bounded rate over the next plants (docs/placement.md).
            Command::SetSpeedFollowing(f) => {
                if self.run == RunState::Running {
                    return Effect::Message(crate::machine::PLACEMENT_WHILE_RUNNING);
                }
                self.settings.placement = Placement::from_speed_following(f);
                Effect::SettingsChanged
            }
            // The machine profile applies after Save and a restart
            // (crate::machine).
            Command::SelectProfile(p) => {
                // The screen link shows the "restart" message itself.
                self.settings.profile = crate::machine::profile_from_screen(p);
                Effect::None
            }
            Command::SelectLinkParameter(p) => {
                self.link_parameter = p;
                Effect::SettingsChanged
            }
            // Into the settings (saved by Save), not into the link in
            // force: the board sets its link up at start (page 10).
            #[cfg(not(feature = "drive-link"))]
            Command::SetLinkValue(_) => Effect::Message(NO_DRIVE_LINK),
            #[cfg(feature = "drive-link")]
            Command::SetLinkValue(v) => {
                if self.run != RunState::Stopped {
                    return Effect::Message("Stop the drum first");
                }
                match self.settings.drive_link.with(self.link_parameter, v) {
                    Some(Ok(link)) => {
                        self.settings.drive_link = link;
                        Effect::SettingsChanged
                    }
                    Some(Err(e)) => Effect::Message(e.text()),
                    None => Effect::Message("Value out of range"),
                }
            }
            // Page 7's *New roll* (the belt roller's turn count).
            Command::NewRoll => Effect::Message(crate::machine::BELT_MACHINE_ONLY),
            // Profile B's parameters are kept (and saved) here too, so that
            // they survive a switch of machine.
            Command::SetBeltSpacing(_)
            | Command::SetSeedlingPitch(_)
            | Command::SetClampAngle(_)
            | Command::SetClampCount(_)
            | Command::SetRollerRadius(_)
            | Command::SetBeltThickness(_)
            | Command::SetSpeedThreshold(_) => {
                match crate::machine::belt_with(&self.settings.belt, cmd) {
                    Some(Ok(belt)) => {
                        self.settings.belt = belt;
                        Effect::SettingsChanged
                    }
                    _ => Effect::Message("Parameters rejected"),
                }
            }
        }
    }

    /// Replaces the settings wholesale (e.g. after loading them), keeping the
    /// run state; rejected settings change nothing.
    pub fn apply_settings(&mut self, settings: Settings) -> Result<(), Error> {
        let plan = Self::plan_for(&settings, self.hw)?;
        let drive = settings.drive;
        let old = self.settings.drive;
        self.plan = plan;
        self.phase.set_spacing(settings.spacing.raw());
        self.settings = settings;
        if drive != old {
            self.use_drive(drive);
        }
        Ok(())
    }

    /// Where a coefficient typed by hand goes in its table: at the selected
    /// gear's monitored (k1) or actual (k2) speed, at the Fixed-mode drum
    /// speed (k3).
    fn hand_set_abscissa(&self) -> U16F16 {
        let gear = self.settings.gear;
        match self.calibration_kind {
            CalibrationKind::SpeedK1 => gear.monitored().table_x(),
            CalibrationKind::SlipK2 => gear.actual().table_x(),
            CalibrationKind::BeltK3 => {
                U16F16::saturating_from_num(self.settings.fixed_drum_speed.raw())
                    .checked_div_int(100)
                    .unwrap_or(U16F16::ZERO)
            }
        }
    }

    /// Duration of `steps` control periods, µs, in `u64`: a calibration
    /// run of paper A's 400 m at Low 1 lasts 4645 s, beyond the 4295 s of
    /// a `u32`.
    fn run_us(&self, steps: u32) -> u64 {
        u64::from(steps).saturating_mul(u64::from(self.hw.control_period_us))
    }

    /// The coefficient of the selected kind from the last run and the taped
    /// length (docs/hmi.md page 4).
    fn compute_coefficient(&mut self, taped_cm: u32) -> Effect {
        let CalibrationRun::Measured {
            edges,
            steps,
            drum_counts,
        } = self.calibration_run
        else {
            return Effect::Message("Run a calibration first");
        };
        let us = self.run_us(steps);
        let taped_um = taped_cm.saturating_mul(10_000);
        let kind = self.calibration_kind;
        let result = match kind {
            CalibrationKind::SlipK2 => {
                // k2 = taped / (wheel turns · π·0.20 m), turns = edges / Z1.
                let turns = U16F16::checked_from_num(edges)
                    .and_then(|e| e.checked_div_int(u32::from(consts::Z1)));
                let ms = u32::try_from(us / 1000).unwrap_or(u32::MAX);
                let time = kinematics::units::Seconds::from_ratio(ms, 1000);
                let distance = Metres::from_mm(taped_cm.saturating_mul(10));
                turns.zip(time).and_then(|(turns, time)| {
                    kinematics::calib::k2_from_wheel_turns(turns, distance, time)
                        .ok()
                        .map(|r| (r.wheel_speed.table_x(), r.k2))
                })
            }
            CalibrationKind::SpeedK1 => {
                // Speeds in m/h (km/h × 1000): µm / µs · 3600.
                let mph = |um: u64| u32::try_from(um.saturating_mul(3_600).checked_div(us)?).ok();
                let monitored = mph(u64::from(edges).saturating_mul(EDGE_UM));
                let actual = mph(u64::from(taped_um));
                monitored.zip(actual).and_then(|(monitored, actual)| {
                    let monitored =
                        kinematics::units::KilometresPerHour::from_ratio(monitored, 1000)?;
                    let actual = kinematics::units::KilometresPerHour::from_ratio(actual, 1000)?;
                    // k1 takes what k2 does not explain, so that the shown
                    // travel speed (k2·k1·monitored) equals the taped speed.
                    let k2 = self.settings.calibration.k2_at(monitored).to_fixed();
                    let corrected = kinematics::units::KilometresPerHour::from_fixed(
                        monitored
                            .to_fixed()
                            // U2F30 → U10F22: drop 8 fractional bits
                            // (rounding down, as `fixed`'s conversion); k2 < 4
                            // always fits.
                            .saturating_mul(fixed::types::U10F22::from_bits(k2.to_bits() >> 8)),
                    );
                    kinematics::calib::k1_from_speeds(actual, corrected)
                        .ok()
                        .map(|r| (monitored.table_x(), r.k1))
                })
            }
            CalibrationKind::BeltK3 => {
                // Mean drum speed: counts · 60 / (counts per turn · s).
                let rpm_x1000 = drum_counts
                    .saturating_mul(60_000_000_000)
                    .checked_div(u64::from(self.hw.encoder_counts_per_drum_rev).saturating_mul(us))
                    .and_then(|v| u32::try_from(v).ok());
                // µm / µs = m/s, U8F24 bits (taped_um < 2³⁰: no overflow).
                let belt = (u64::from(taped_um) << 24)
                    .checked_div(us)
                    .and_then(|bits| u32::try_from(bits).ok())
                    .map(kinematics::units::MetresPerSecond::from_bits);
                rpm_x1000
                    .and_then(|n| RevPerMin::from_ratio(n, 1000))
                    .zip(belt)
                    .and_then(|(n, belt)| {
                        kinematics::calib::k3_from_belt_test(n, belt)
                            .ok()
                            .map(|r| (n.table_x(), r.k3))
                    })
            }
        };
        match result {
            Some((at, k)) => {
                self.calibration_run = CalibrationRun::Computed { kind, at, k };
                Effect::None
            }
            None => Effect::Message("Calibration run too short"),
        }
    }

    fn accept_coefficient(&mut self) -> Effect {
        let CalibrationRun::Computed { kind, at, k } = self.calibration_run else {
            return Effect::Message("Nothing to accept");
        };
        match self.set_table_point(kind, at, k) {
            Ok(()) => {
                self.calibration_run = CalibrationRun::Idle;
                Effect::SettingsChanged
            }
            Err(()) => Effect::Message("Coefficient out of range 0.8-1.2"),
        }
    }

    /// Puts `(at, k)` into the table of `kind`: replaces the point nearest to
    /// `at` when within 0.05 (km/h or r/min), otherwise inserts it (a table
    /// holds at most 8 points; the validated table is built before anything
    /// changes, so a rejected point changes nothing).
    fn set_table_point(
        &mut self,
        kind: CalibrationKind,
        x: U16F16,
        k: kinematics::units::Coefficient,
    ) -> Result<(), ()> {
        let cal = &mut self.settings.calibration;
        let table = match kind {
            CalibrationKind::SpeedK1 => &mut cal.k1,
            CalibrationKind::SlipK2 => &mut cal.k2,
            CalibrationKind::BeltK3 => &mut cal.k3,
        };
        let near = const { U16F16::lit("0.05") };
        let mut points: heapless::Vec<TablePoint, 8> = heapless::Vec::new();
        let mut placed = false;
        for p in table.points() {
            if !placed && p.x.abs_diff(x) <= near {
                points.push(TablePoint::new(x, k)).map_err(|_| ())?;
                placed = true;
            } else if !placed && p.x > x {
                points.push(TablePoint::new(x, k)).map_err(|_| ())?;
                points.push(*p).map_err(|_| ())?;
                placed = true;
            } else {
                points.push(*p).map_err(|_| ())?;
            }
        }
        if !placed {
            points.push(TablePoint::new(x, k)).map_err(|_| ())?;
        }
        *table = CoeffTable::new(&points).map_err(|_| ())?;
        Ok(())
    }

    /// The time since the last control step, µs, from the Hall timer: the
    /// encoder delta is divided by the time it really took, so a control
    /// step released late (a busy CPU, an emulator's host) does not read as
    /// a speed change. The nominal period when there is no previous step, or
    /// when the timer disagrees with the schedule by more than ×4 either way
    /// (a timer fault must not scale the measurement).
    fn elapsed_us(&self, now: Ticks) -> u32 {
        let nominal = self.hw.control_period_us;
        match self.last_step_at {
            Some(prev) => {
                let e = now.0.wrapping_sub(prev.0);
                if e >= nominal / 4 && e <= nominal.saturating_mul(4) {
                    e
                } else {
                    nominal
                }
            }
            None => nominal,
        }
    }

    /// Measured drum speed from the encoder delta over `elapsed_us`.
    fn drum_speed_of(&self, counts: u16, elapsed_us: u32) -> I16F16 {
        // r/min = counts · 60 / (counts_per_rev · period): I16F16 bits.
        let num = i64::from(counts)
            .saturating_mul(60 * 65_536)
            .saturating_mul(1_000_000);
        let den =
            i64::from(self.hw.encoder_counts_per_drum_rev).saturating_mul(i64::from(elapsed_us));
        let bits = num.checked_div(den).unwrap_or(0);
        I16F16::from_bits(i32::try_from(bits).unwrap_or(i32::MAX))
    }

    /// The control step, once per control period.
    ///
    /// `now` is the Hall timer's time (1 MHz, extended); `drum_encoder` the
    /// free-running encoder counter.
    ///
    /// ```
    /// use hmi_proto::screen::{Command, DrumSpeed, Mode};
    /// use kinematics::units::Ticks;
    /// use supervisor::control::{Alarm, Hardware, Supervisor};
    /// use supervisor::settings::Settings;
    ///
    /// let settings = Settings {
    ///     mode: Mode::Fixed,
    ///     fixed_drum_speed: DrumSpeed::new(2000).expect("20.00 r/min is in range"),
    ///     ..Settings::default()
    /// };
    /// let mut sup = Supervisor::new(Hardware::BOARD, settings).expect("default settings");
    /// sup.command(Command::Start);
    /// // First period, drum at rest as the drum model expects: no error, so
    /// // the output is the feed-forward alone, eq. 10 with TIM1's ARR 3599:
    /// // 20 / 44.7 × 3600 = 1610.74 → compare value 1611.
    /// let act = sup.control_step(Ticks(0), 0);
    /// assert!(act.driver_enabled);
    /// assert_eq!(act.ccr, 1611);
    /// // The encoder never moves: after more than 200 ms (21 periods of
    /// // 10 ms on the Hall timer's clock) without a count the drum is
    /// // stalled: PWM 0, latched alarm.
    /// for period in 2..=21 {
    ///     let act = sup.control_step(Ticks((period - 1) * 10_000), 0);
    ///     assert_eq!(act.ccr == 0, period == 21, "period {period}");
    /// }
    /// assert_eq!(sup.alarm(), Some(Alarm::DrumStall));
    /// ```
    #[inline(never)]
    pub fn control_step(&mut self, now: Ticks, drum_encoder: u16) -> Actuation {
        self.ensure_controller();
        self.snapshot.steps = self.snapshot.steps.wrapping_add(1);
        let delta = match self.last_encoder {
            // Forward only: a backwards jitter reads as standstill. With the
            // encoder reversed (A/B swapped, `Settings::drum_encoder_reversed`)
            // the delta is negated first, so that the drum turning forward
            // counts forward.
            Some(prev) => {
                let d = if self.settings.drum_encoder_reversed {
                    prev.wrapping_sub(drum_encoder)
                } else {
                    drum_encoder.wrapping_sub(prev)
                };
                if d > u16::MAX / 2 {
                    self.encoder_back = d.wrapping_neg();
                    0
                } else {
                    self.encoder_back = 0;
                    d
                }
            }
            None => 0,
        };
        self.last_encoder = Some(drum_encoder);
        self.phase.clear_events();
        let elapsed_us = self.elapsed_us(now);
        self.last_step_at = Some(now);
        let encoder_delta = delta;
        let delta = self.feedback_counts(encoder_delta, elapsed_us);
        self.link.bus = false;
        let measured = self.drum_speed_of(delta, elapsed_us);
        self.reported = smooth(self.reported, measured, REPORT_ALPHA);

        // Travel speed (eq. 1–3) and the drum target (eq. 7).
        let m = self.estimator.update(now);
        let gear_speed = self.predictor.predict(&m, now);
        self.snapshot.measured_gear_rpm_x1000 = m.gear_speed.to_milli();
        self.snapshot.predicted_gear_rpm_x1000 = gear_speed.to_milli();
        let travel = travel::travel_speed(gear_speed, &self.settings.calibration).ok();
        // Shown to a person: rounded to m/h. The distance below integrates
        // the speed itself.
        let travel_kmh_x1000 = travel
            .and_then(|t| t.travel_speed_kmh().ok())
            .map_or(0, |v| v.to_milli());
        let travel_mps = travel.map_or(0, |t| t.travel_speed.to_bits());

        // k3 at the drum speed these counts were turned at (measured, not
        // the target: the belt slips at the speed it turns, and after a Stop
        // the counts still coasting in keep the k3 of their own speed),
        // smoothed over a few periods ([`K3_SPEED_ALPHA`]), at the
        // coefficient's full precision.
        self.k3_speed = smooth(self.k3_speed, measured, K3_SPEED_ALPHA);
        let k3 = self.settings.calibration.k3_at(fix_to_rpm(self.k3_speed));
        // Positions for the phase loop: the ground while running, the belt
        // always (a coasting drum still moves partitions).
        if self.run == RunState::Running {
            let k1k2 = travel.map(|t| crate::phase::k1k2_q30(t.k1, t.k2));
            // The ground moves on between edges at the M/T speed (the last
            // tooth gap's), not at the predictor's: the slope between two
            // single-gap estimates is mostly the gear's ±2 % tooth errors,
            // which the feed-forward can average but a position cannot
            // (docs/placement.md, "Positions").
            let raw = travel::travel_speed(m.gear_speed, &self.settings.calibration)
                .map_or(0, |t| t.travel_speed.to_bits());
            self.phase.advance_ground(
                self.teeth,
                self.pitches_q16,
                self.estimator.next_gap_pitches_q16(),
                m.since_edge_ticks,
                raw,
                k1k2,
            );
        }
        self.phase.advance_belt(delta, k3);

        let mut too_fast = None;
        let target = match self.settings.mode {
            // Capped at the drive's n_max (a drive slower than the screen's
            // 44.70 r/min range cannot do more).
            Mode::Fixed => centi_to_fix(self.settings.fixed_drum_speed.raw()).min(self.law.n_max),
            Mode::SpeedAdaptive => {
                match travel.map(|t| self.plan.target(&t, &self.settings.calibration)) {
                    Some(Ok(target)) => {
                        // Eq. 7 as asked (also beyond the plan's n_max)
                        // times the motor coefficient, then held at the
                        // drum's limit: the paper's 44.7 r/min, or a drive
                        // identified slower its own. (Holding eq. 7 at
                        // n_max before the coefficient ran the drum slow
                        // under a coefficient below 1.)
                        let asked = match target {
                            DrumTarget::Follow(c) => c.drum_speed,
                            DrumTarget::Saturated { requested, .. } => requested,
                        };
                        let n = rpm_to_fix(asked)
                            .saturating_mul_int(i32::from(self.settings.motor_coefficient.raw()))
                            .checked_div_int(100)
                            .unwrap_or(I16F16::ZERO);
                        let cap = self.drum_cap();
                        if n > cap {
                            too_fast = Some(Alarm::TooFast {
                                max_kmh_x100: self.max_travel_kmh_x100(),
                            });
                        }
                        let n = n.min(cap);
                        let correction = if self.settings.placement == Placement::DistanceLocked
                            && self.run == RunState::Running
                        {
                            let c = self.phase.correction(n);
                            // Smoothed through the link, and while the Hall
                            // gaps read noisy (teeth not learnt yet): an
                            // unlearnt edge is up to ±2 % of a pitch off its
                            // place, and the ground's step there moved the
                            // drum by up to 3 % in one period (not before a
                            // pass's first plant: the drum catches up with
                            // it at up to +100 %, late if smoothed). Leaving
                            // it, the smoothing fades out over 0.5 s.
                            self.phase_alpha = if self.link_in_force.delays_control()
                                || (self.estimator.is_noisy() && self.phase.pass_started())
                            {
                                PHASE_SMOOTHING
                            } else {
                                self.phase_alpha.saturating_add(PHASE_FADE).min(I16F16::ONE)
                            };
                            self.phase_smoothed = smooth(self.phase_smoothed, c, self.phase_alpha);
                            self.phase_smoothed
                        } else {
                            self.phase.update_error();
                            self.phase_smoothed = I16F16::ZERO;
                            I16F16::ZERO
                        };
                        // The next edge is long overdue (four gaps: the tractor
                        // has come to rest, or the sensor died) and the next
                        // plant's place lies beyond that edge: the drum waits
                        // at rest for it, so that no plant leaves for a place
                        // the ground may never reach (on the decaying speed
                        // the belt crept on and dropped plants anywhere).
                        if m.state == MotionState::Decaying
                            && m.since_edge_ticks / 4 > self.predictor.period
                            && self.settings.placement == Placement::DistanceLocked
                            && self.phase.partitions_left() > 0
                            && self.phase.next_place_beyond_reach()
                        {
                            I16F16::ZERO
                        } else {
                            n.saturating_add(correction).max(I16F16::ZERO).min(cap)
                        }
                    }
                    _ => I16F16::ZERO,
                }
            }
        };

        // The too-fast warning follows the speed (with the unit down: a
        // lifted unit plants nothing); latched alarms and the instability
        // warning stay.
        let too_fast = too_fast.filter(|_| self.unit_down());
        // No travel pulses: the Hall silent for NO_PULSES_US since the last
        // edge, or since the watch began (Start, a lowering,
        // Speed-Adaptive chosen), with the drum running in Speed-Adaptive
        // and the unit down. Before it (and otherwise) the watch restarts.
        let watching = self.run == RunState::Running
            && self.settings.mode == Mode::SpeedAdaptive
            && self.unit_down();
        if !watching {
            self.quiet_from = now.0;
        }
        let since_edge = if self.edges == 0 {
            u32::MAX
        } else {
            m.since_edge_ticks
        };
        let quiet = since_edge.min(now.0.wrapping_sub(self.quiet_from));
        let warning = if watching && quiet > NO_PULSES_US {
            Some(Alarm::NoTravelPulses)
        } else {
            too_fast
        };
        match (self.alarm, warning) {
            (Some(a), _) if a.is_latched() || a == Alarm::DrumUnstable => {}
            (_, Some(w)) if self.run == RunState::Running => self.alarm = Some(w),
            (Some(Alarm::TooFast { .. } | Alarm::NoTravelPulses), _) => self.alarm = None,
            _ => {}
        }
        // The work switch up: the target ramps to rest (crate::planting).
        let target = self.work_ramp(target, elapsed_us);

        // The link's alarms first: one that latches stops the drum (also
        // an identification) in this very step.
        self.link_alarms(encoder_delta, elapsed_us);
        let mut actuation = Actuation::OFF;
        if self.run == RunState::Identifying {
            actuation = self.identify_step(measured, delta, elapsed_us);
        }
        if self.run == RunState::Running {
            // Fault: drum commanded but not turning (with both feedbacks:
            // neither turning; the encoder alone still is the cross-check's).
            let stalled = self.stall_watch(
                target >= STALL_MIN_COMMAND && delta == 0 && !self.driver_turning(),
                elapsed_us,
            );
            // Fault: in Speed-Adaptive mode, the next Hall edge is later
            // than any stop the chassis can make allows. Without such
            // evidence the silence is a stop: the estimator's speed decays
            // to zero and the drum with it.
            let hall_lost = self.settings.mode == Mode::SpeedAdaptive
                && self
                    .estimator
                    .next_edge_overdue(m.since_edge_ticks, &self.hall_silence);
            if let Some(alarm) = stalled {
                self.latch(alarm);
            } else if hall_lost {
                self.latch(Alarm::HallLost);
            } else {
                // What the measurement should read from the feed-forward
                // alone; then advance the model with the target of
                // `ref_delay − 1` periods ago (the drive's dead time).
                let expected = self.reference;
                // The read-back as feedback is older by its age: the model's
                // input is delayed by as many periods more.
                let back = self
                    .law
                    .ref_delay
                    .saturating_sub(2)
                    .saturating_add(self.readback_delay_periods())
                    .min(REF_HISTORY - 1);
                let delayed = self
                    .ref_history
                    .get(
                        self.ref_head
                            .wrapping_add(REF_HISTORY)
                            .wrapping_sub(back)
                            .checked_rem(REF_HISTORY)
                            .unwrap_or(0),
                    )
                    .map_or(target, |&v| I16F16::from_bits(i32::from(v) << 8));
                self.reference = smooth(self.reference, delayed, self.law.ref_alpha);
                self.push_reference_input(target);
                let saturated = self.snapshot.ccr == 0
                    || u32::from(self.snapshot.ccr) > u32::from(self.hw.pwm_arr);
                if !self.fallback
                    && self
                        .monitor
                        .step(expected, measured, target, elapsed_us, saturated)
                {
                    self.fall_back();
                }
                let out = match &mut self.drum {
                    Drum::Control(c) => c.step(expected, measured, target),
                    Drum::Unbuilt | Drum::Identify(_) => I16F16::ZERO,
                };
                actuation = self.drum_output(out);
            }
        }
        if self.run != RunState::Running {
            // Restart from the drum's actual speed (it may still coast).
            self.reference = measured;
            self.ref_history = [to_i16_x256(measured); REF_HISTORY];
            self.monitor = Monitor::default();
        }

        self.belt_counts_k3 = self
            .belt_counts_k3
            .saturating_add(u64::from(delta).wrapping_mul(u64::from(k3.to_bits())));
        self.drum_counts_total = self.drum_counts_total.saturating_add(u64::from(delta));
        self.snapshot.travel_speed_kmh_x1000 = travel_kmh_x1000;
        self.snapshot.target_drum_rpm_x1000 = if self.run == RunState::Running {
            milli(target)
        } else {
            0
        };
        self.snapshot.actual_drum_rpm_x1000 = milli(self.reported);
        self.snapshot.ccr = actuation.ccr;
        if self.link.bus {
            // The Modbus command path: the PWM is 0; the log and the
            // instability supervisor see the equivalent duty.
            self.snapshot.ccr = self.link.bus_ccr;
        }
        self.snapshot.hall_edges = self.edges;
        let partitions_x1e6 = self.partitions_x1e6();
        self.snapshot.plants = u32::try_from(partitions_x1e6 / 1_000_000).unwrap_or(u32::MAX);
        if self.run == RunState::Running {
            // ∫ V1 dt: m/s (U8F24) · µs = µm · 2²⁴, the fraction (< 2²⁴)
            // carried: < 2⁶⁴. µm since Start wrap after 1.8·10¹³ m.
            let acc = u64::from(travel_mps)
                .wrapping_mul(u64::from(elapsed_us))
                .wrapping_add(self.distance_frac);
            self.distance_um = self.distance_um.wrapping_add(acc >> 24);
            self.distance_frac = acc & 0xFF_FFFF;
        }
        self.snapshot.distance_mm = u32::try_from(self.distance_um / 1000).unwrap_or(u32::MAX);
        self.count_plants(
            partitions_x1e6,
            (self.teeth, self.last_tooth_at),
            now.0,
            elapsed_us,
        );
        actuation
    }

    /// The drum link's newest sample (one more sensor sample, with the
    /// read-back's age): call before [`Supervisor::control_step`].
    pub fn set_link_sample(&mut self, sample: crate::drive_link::LinkSample) {
        // Field by field: a whole-struct assignment here compiled to a
        // `memmove` call, which linked 1.6 KB of compiler-builtins.
        let s = &mut self.link.sample;
        let (milli, age) = sample
            .speed
            .map_or((None, 0), |r| (Some(r.drum_milli_rpm), r.age_us));
        s.speed = milli.map(|drum_milli_rpm| crate::drive_link::ReadBack {
            drum_milli_rpm,
            age_us: age,
        });
        s.lost = sample.lost;
        s.setup = sample.setup;
        s.refused = sample.refused;
        s.answering = sample.answering;
        s.fault_word = sample.fault_word;
        s.fault_reads = sample.fault_reads;
    }

    /// The speed command for the driver's bus (drum milli-r/min) when the
    /// command path is Modbus and the drum runs; `None` otherwise.
    pub fn bus_speed_command(&self) -> Option<i32> {
        self.link.bus.then_some(self.link.bus_command)
    }

    /// Whether the operator's acknowledgement asked the driver to clear its
    /// latched alarm (taken once).
    pub fn take_driver_clear(&mut self) -> bool {
        core::mem::take(&mut self.link.clear_request)
    }

    /// Whether the link is in use (a driver profile and a feedback or
    /// command that needs it, or a profile at all: its faults are read).
    fn link_in_use(&self) -> bool {
        cfg!(feature = "drive-link")
            && self.link_in_force.kind != crate::drive_link::DriverKind::None
    }

    /// This period's drum counts from the feedback source in force: the
    /// encoder's, or the read-back integrated over the period.
    fn feedback_counts(&mut self, encoder_delta: u16, elapsed_us: u32) -> u16 {
        use crate::drive_link::FeedbackSource;
        match self.link_in_force.feedback {
            FeedbackSource::Encoder | FeedbackSource::Both => encoder_delta,
            FeedbackSource::Driver => self.link.readback_counts(
                elapsed_us,
                self.hw.encoder_counts_per_drum_rev,
                self.link_in_force.readback_max_age_us(),
            ),
        }
    }

    /// The drive model the controller is scheduled from: the drive's own,
    /// with the driver read-back as the feedback, or the bus command, its
    /// dead time lengthened by one link transaction each ([`crate::drive_link::DriveLinkSettings::readback_delay_us`]),
    /// so that the gains shrink in the SIMC ratio (docs/drive-link.md).
    fn control_model(&self) -> DriveModel {
        use crate::drive_link::{CommandPath, FeedbackSource};
        let m = self.settings.drive;
        let link = &self.link_in_force;
        // One transaction's delay for the read-back as the feedback, one
        // more for the bus command (written about every other transaction).
        let transactions = u32::from(link.feedback == FeedbackSource::Driver)
            .saturating_add(u32::from(link.command == CommandPath::Modbus));
        if transactions == 0 {
            return m;
        }
        let extra = u16::try_from(link.readback_delay_us().saturating_mul(transactions) / 100)
            .unwrap_or(u16::MAX);
        let dead = m
            .dead_time_x10_ms()
            .saturating_add(extra)
            .min(DriveModel::DEAD_TIME_MAX);
        DriveModel::new(m.n_max_x100(), m.tau_x10_ms(), dead).unwrap_or(m)
    }

    /// Control periods the measurement lags the command by, beyond the
    /// drive's own: the read-back's age when it is the feedback, and one
    /// link transaction for the bus command (rounded).
    fn readback_delay_periods(&self) -> usize {
        use crate::drive_link::{CommandPath, FeedbackSource};
        let link = &self.link_in_force;
        let period = self.hw.control_period_us.max(1);
        let periods = |us: u32| {
            us.saturating_add(period / 2)
                .checked_div(period)
                .unwrap_or(0)
        };
        let feedback = if link.feedback == FeedbackSource::Driver {
            self.link.sample.speed.map_or(0, |r| periods(r.age_us))
        } else {
            0
        };
        // The bus command reaches the driver one transaction later (on
        // average; written about every other transaction).
        let command = if link.command == CommandPath::Modbus {
            periods(link.readback_delay_us())
        } else {
            0
        };
        feedback.saturating_add(command) as usize
    }

    /// With both feedbacks: the driver's read-back says the drum turns (at
    /// least the cross-check's floor, 1 r/min), so a still encoder is the
    /// cross-check's alarm, not a stall.
    /// One period of the stall watch: `still`, the drum commanded shows no
    /// forward motion. The alarm once the stall time is over: turning
    /// backwards if it did for more than half of it
    /// ([`Alarm::DrumBackwards`]; the first period after Start has no
    /// encoder difference yet), else [`Alarm::DrumStall`].
    fn stall_watch(&mut self, still: bool, elapsed_us: u32) -> Option<Alarm> {
        if !still {
            self.stall_us = 0;
            return None;
        }
        if self.stall_us == 0 {
            self.stall_back_us = 0;
        }
        if self.turning_backwards() {
            self.stall_back_us = self.stall_back_us.saturating_add(elapsed_us);
        }
        self.stall_us = self.stall_us.saturating_add(elapsed_us);
        (self.stall_us > STALL_TIME_US).then_some(if self.stall_back_us > self.stall_us / 2 {
            Alarm::DrumBackwards
        } else {
            Alarm::DrumStall
        })
    }

    /// The feedback in force moved against the drum's direction this
    /// period: the encoder (alone or with the driver) by
    /// [`BACKWARD_MIN_COUNTS`], the driver's read-back below −1 r/min.
    fn turning_backwards(&self) -> bool {
        if self.link_in_force.feedback == crate::drive_link::FeedbackSource::Driver
            && self.link_in_use()
        {
            self.link
                .readback_milli_rpm(self.link_in_force.readback_max_age_us())
                .is_some_and(|n| i64::from(n) < -drive_link::cross_check::MARGIN_FLOOR_MILLI_RPM)
        } else {
            self.encoder_back >= BACKWARD_MIN_COUNTS
        }
    }

    fn driver_turning(&self) -> bool {
        self.link_in_force.feedback == crate::drive_link::FeedbackSource::Both
            && self
                .link
                .readback_milli_rpm(self.link_in_force.readback_max_age_us())
                .is_some_and(|n| i64::from(n) > drive_link::cross_check::MARGIN_FLOOR_MILLI_RPM)
    }

    /// The link's alarms: lost, a driver fault, the cross-check.
    fn link_alarms(&mut self, encoder_delta: u16, elapsed_us: u32) {
        if !self.link_in_use() {
            return;
        }
        let sample = self.link.sample;
        if sample.lost {
            self.latch(match sample.setup {
                Some(fault) => Alarm::DriverSetup(fault),
                None if sample.refused => Alarm::LinkRefused,
                None => Alarm::LinkLost,
            });
            return;
        }
        if sample.fault_word != 0
            && !(self.link.acked && self.link.acked_fault_reads == sample.fault_reads)
        {
            let fault = drive_link::profile::first_fault(
                &self.link_in_force.fault_masks(),
                sample.fault_word,
            );
            if self.alarm != Some(Alarm::DriverFault(fault)) {
                self.latch(Alarm::DriverFault(fault));
            }
            return;
        }
        if self.link_in_force.feedback == crate::drive_link::FeedbackSource::Both
            && self.run == RunState::Running
        {
            let encoder = milli(self.drum_speed_of(encoder_delta, elapsed_us));
            let driver = self
                .link
                .readback_milli_rpm(self.link_in_force.readback_max_age_us());
            let wrong = match driver {
                Some(d) => self.link.cross.update(
                    elapsed_us,
                    i32::try_from(encoder).unwrap_or(i32::MAX),
                    d,
                ),
                None => false,
            };
            if wrong {
                self.latch(Alarm::SpeedMismatch);
            }
        } else {
            self.link.cross = drive_link::cross_check::CrossCheck::new();
        }
    }

    /// The operator acknowledges a link alarm: a lost link only once the
    /// driver answers again; a driver fault asks the driver to clear its
    /// alarm (a fault still there comes back with the next fault read).
    fn acknowledge_link_alarm(&mut self) -> Option<Effect> {
        match self.alarm {
            Some(Alarm::LinkLost | Alarm::LinkRefused | Alarm::DriverSetup(_))
                if !self.link.sample.answering || self.link.sample.lost =>
            {
                Some(Effect::Message("Drum driver still not answering"))
            }
            Some(Alarm::DriverFault(_)) => {
                self.link.acked_fault_reads = self.link.sample.fault_reads;
                self.link.acked = true;
                self.link.clear_request = true;
                self.alarm = None;
                Some(Effect::AlarmCleared)
            }
            _ => None,
        }
    }

    /// The drum's output for the controller's `out` (r/min): the PWM
    /// compare value, or with the Modbus command path the driver's speed
    /// command (PWM 0).
    fn drum_output(&mut self, out: I16F16) -> Actuation {
        let ccr = self.ccr_of(out);
        if self.link_in_force.command == crate::drive_link::CommandPath::Modbus {
            self.link.bus_command = i32::try_from(milli(out)).unwrap_or(i32::MAX);
            self.link.bus_ccr = ccr;
            self.link.bus = true;
            Actuation {
                ccr: 0,
                driver_enabled: true,
            }
        } else {
            Actuation {
                ccr,
                driver_enabled: true,
            }
        }
    }

    fn push_reference_input(&mut self, target: I16F16) {
        self.ref_head = self
            .ref_head
            .wrapping_add(1)
            .checked_rem(REF_HISTORY)
            .unwrap_or(0);
        if let Some(slot) = self.ref_history.get_mut(self.ref_head) {
            *slot = to_i16_x256(target);
        }
    }

    /// Eq. 10 with the drive model's gain: the compare value for `out`
    /// r/min, `out / n_max · (ARR + 1)`, rounded, within 0 … ARR + 1.
    fn ccr_of(&self, out: I16F16) -> u16 {
        let arr1 = i64::from(self.hw.pwm_arr).saturating_add(1);
        let ccr = i64::from(out.to_bits())
            .max(0)
            .saturating_mul(arr1)
            .saturating_mul(100)
            .checked_div(i64::from(self.law.n_max_x100))
            .unwrap_or(0)
            .saturating_add(1 << 15)
            >> 16;
        u16::try_from(ccr.min(arr1)).unwrap_or(0)
    }

    /// The instability supervisor fired: the conservative controller takes
    /// over (bumpless from the feed-forward), the warning goes up. Not
    /// inlined: the controller it builds (≈ 0.6 KB with its configuration)
    /// must not widen `control_step`'s own stack frame on every period.
    #[inline(never)]
    fn fall_back(&mut self) {
        self.fallback = true;
        self.restore_controller();
        if let Drum::Control(c) = &mut self.drum {
            c.start();
        }
        if !self.alarm.is_some_and(|a| a.is_latched()) {
            self.alarm = Some(Alarm::DrumUnstable);
        }
    }

    /// Whether the conservative mode is on ([`fallback_config`]).
    pub fn in_fallback(&self) -> bool {
        self.fallback
    }

    /// The drive model in force, with the controller scheduled from it (or
    /// the given controller kept, for [`Supervisor::with_controller`]).
    ///
    /// The controller is not built here but by the next control step
    /// ([`Supervisor::ensure_controller`], in the control task): built here,
    /// in the screen task (the operator's *Save* on page 9), its frames
    /// (≈ 2.6 KB: the command, the build, the fuzzy tuner) would sit under
    /// the control task preempting it. Every model [`DriveModel`] accepts builds
    /// (`scheduled_configs_build_for_extreme_models`).
    #[inline(never)]
    fn use_drive(&mut self, model: DriveModel) {
        self.settings.drive = model;
        self.fallback = false;
        if self.scheduled {
            self.drum = Drum::Unbuilt;
        }
        self.law = DriveLaw::of(&model, self.hw.control_period_us);
        self.monitor = Monitor::default();
    }

    /// Builds the controller if it is not yet ([`Supervisor::new`]).
    fn ensure_controller(&mut self) {
        if matches!(self.drum, Drum::Unbuilt) {
            self.restore_controller();
            // A drive model changed while running (`apply_settings`).
            if let (RunState::Running, Drum::Control(c)) = (self.run, &mut self.drum) {
                c.start();
            }
        }
    }

    /// The controller back in place of an identification that ended: the
    /// one scheduled from the drive model in force (a controller given to
    /// [`Supervisor::with_controller`] is not kept across an
    /// identification).
    #[inline(never)]
    fn restore_controller(&mut self) {
        let model = self.control_model();
        let config = if self.fallback {
            fallback_config(&model)
        } else {
            let mut c = scheduled_config(&model, self.hw.control_period_us);
            // Through the link: the integral gain is not tuned
            // (`DriveLinkSettings::delays_control`).
            if self.link_in_force.delays_control() {
                if let fuzzy_pid::Schedule::Fuzzy(f) = &mut c.schedule {
                    // The smallest range `FuzzyConfig` accepts (> 0):
                    // ΔKi within ±1/65 536, Ki its base.
                    f.range.ki = I16F16::DELTA;
                }
            }
            c
        };
        if let Ok(c) = config.build() {
            self.drum = Drum::Control(c);
        }
    }

    /// One period of the drive identification.
    #[inline(never)]
    fn identify_step(&mut self, measured: I16F16, delta: u16, elapsed_us: u32) -> Actuation {
        let duty = match &mut self.drum {
            Drum::Identify(id) => {
                let duty = id.step(measured.to_bits());
                if duty.is_none() {
                    self.identified = id.state();
                }
                duty
            }
            Drum::Unbuilt | Drum::Control(_) => None,
        };
        match duty {
            Some(permille) => {
                // Stall: the drum does not move under a 25 % or 75 % duty.
                if let Some(alarm) = self.stall_watch(delta == 0, elapsed_us) {
                    self.latch(alarm);
                    return Actuation::OFF;
                }
                let arr1 = u32::from(self.hw.pwm_arr).saturating_add(1);
                let ccr = arr1.saturating_mul(u32::from(permille)) / 1000;
                Actuation {
                    ccr: u16::try_from(ccr).unwrap_or(0),
                    driver_enabled: true,
                }
            }
            None => {
                self.run = RunState::Stopped;
                self.stall_us = 0;
                self.restore_controller();
                if let IdentifyState::Failed(e) = self.identified {
                    if !self.alarm.is_some_and(|a| a.is_latched()) {
                        self.alarm = Some(Alarm::IdentifyFailed(e));
                    }
                }
                Actuation::OFF
            }
        }
    }

    /// The drive identification's state (page 9).
    pub fn identify_state(&self) -> IdentifyState {
        match &self.drum {
            Drum::Identify(id) => id.state(),
            Drum::Unbuilt | Drum::Control(_) => self.identified,
        }
    }

    /// Belt partitions passed since Start × 10⁶ (the plant count is its
    /// integer part): Σ drum turns · k3(n) · π·(D2+2H2) / Lclap, each turn
    /// with the belt slip k3 at the drum speed it was turned at.
    #[inline(never)]
    pub(crate) fn partitions_x1e6(&self) -> u64 {
        // Partitions per drum turn · 1e6 = π·0.070/0.050 · 1e6 = 4 398 230.
        const PARTITIONS_PER_TURN_X1E6: u64 = 4_398_230;
        // Σ Δcounts·k3 (Q30) / counts per turn = turns · k3 in Q30.
        self.belt_counts_k3
            .checked_div(u64::from(self.hw.encoder_counts_per_drum_rev))
            .and_then(|turns_k3_q30| {
                kinematics::mul_shr(turns_k3_q30, PARTITIONS_PER_TURN_X1E6, 30)
            })
            .unwrap_or(u64::MAX)
    }

    /// The status as the screen shows it.
    #[inline(never)]
    pub fn screen_status(&self) -> screen::Status {
        let s = self.snapshot;
        // Thousandths to hundredths for a person: rounded.
        let x100 = |v: u32| u16::try_from(v.saturating_add(5) / 10).unwrap_or(u16::MAX);
        let (measured_distance_cm, calibration_result_x1000) = match self.calibration_run {
            CalibrationRun::Measured {
                edges, drum_counts, ..
            } => {
                let um = match self.calibration_kind {
                    // The Hall teeth counted, as track.
                    CalibrationKind::SpeedK1 | CalibrationKind::SlipK2 => {
                        u64::from(edges).saturating_mul(EDGE_UM)
                    }
                    // The belt the drum turns imply: π·0.070 m per turn.
                    CalibrationKind::BeltK3 => drum_counts
                        .saturating_mul(BELT_PER_DRUM_TURN_UM)
                        .checked_div(u64::from(self.hw.encoder_counts_per_drum_rev))
                        .unwrap_or(0),
                };
                (u32::try_from(um / 10_000).unwrap_or(u32::MAX), 0)
            }
            CalibrationRun::Computed { k, .. } => {
                (0, u16::try_from(coefficient_milli(k)).unwrap_or(u16::MAX))
            }
            _ => (0, 0),
        };
        // The model measured (until saved) or the one in force.
        let q = self.quality_since_start();
        let shown_drive = match self.identify_state() {
            IdentifyState::Done(model) => model,
            _ => self.settings.drive,
        };
        screen::Status {
            travel_speed_kmh_x100: x100(s.travel_speed_kmh_x1000),
            target_drum_rpm_x100: x100(s.target_drum_rpm_x1000),
            actual_drum_rpm_x100: x100(s.actual_drum_rpm_x1000),
            plants: s.plants,
            distance_dm: s.distance_mm / 100,
            measured_distance_cm,
            calibration_result_x1000,
            drive_n_max_x100: shown_drive.n_max_x100(),
            drive_tau_x10_ms: shown_drive.tau_x10_ms(),
            drive_dead_time_x10_ms: shown_drive.dead_time_x10_ms(),
            drive_identification: match self.identify_state() {
                IdentifyState::Idle => 0,
                IdentifyState::Running => 1,
                IdentifyState::Done(_) => 2,
                IdentifyState::Failed(_) => 3,
            },
            quality_of_feed_x10: q.quality_of_feed_x10,
            multiples_x10: q.multiples_x10,
            misses_x10: q.misses_x10,
            precision_cv_x10: q.cv_x10,
            within_10_pct_x10: q.within_10_pct_x10,
            plants_per_m_x100: u16::try_from(q.plants_per_m_x100).unwrap_or(u16::MAX),
            // Profile B's live values: not this machine's.
            ..screen::Status::default()
        }
    }
}

/// A coefficient in thousandths, rounded to the nearest (the screen's
/// unit): `Coefficient::to_milli` rounds down, and a value set from a
/// decimal (0.800 is 0.799 999 999 8 in 2⁻³⁰ steps) read one less.
fn coefficient_milli(k: kinematics::units::Coefficient) -> u32 {
    // bits < 2³², × 1000 < 2⁴².
    let m = (u64::from(k.to_bits())
        .saturating_mul(1000)
        .saturating_add(1 << 29))
        >> 30;
    u32::try_from(m).unwrap_or(u32::MAX)
}

/// Track per Hall edge: π·0.20 m / 25 = 25 133 µm.
const EDGE_UM: u64 = 25_133;
/// Belt per drum turn: π·(D2 + 2·H2) = π·0.070 m = 219 911 µm.
const BELT_PER_DRUM_TURN_UM: u64 = 219_911;

impl Supervisor {
    /// The settings as the screen shows them (its own scaled integers); the
    /// calibration coefficient shown is the selected one (k1, k2 or k3) at
    /// the selected gear's speed (k3: at the Fixed-mode drum speed).
    pub fn screen_settings(&self) -> screen::Settings {
        let settings = &self.settings;
        let at = self.hand_set_abscissa();
        let table = match self.calibration_kind {
            CalibrationKind::SpeedK1 => &settings.calibration.k1,
            CalibrationKind::SlipK2 => &settings.calibration.k2,
            CalibrationKind::BeltK3 => &settings.calibration.k3,
        };
        let k_x1000 = i32::try_from(coefficient_milli(table.eval(at))).unwrap_or(i32::MAX);
        screen::Settings {
            spacing: settings.spacing,
            fixed_drum_speed: settings.fixed_drum_speed,
            motor_coefficient: settings.motor_coefficient,
            gear: settings::gear_to_screen(settings.gear),
            calibration_coefficient: screen::CalibrationCoefficient::new(k_x1000)
                .unwrap_or_default(),
            calibration_distance: screen::CalibrationDistance::default(),
            brightness: settings.brightness,
            calibration_kind: self.calibration_kind,
            profile: crate::machine::screen_profile(settings.profile),
            belt: crate::machine::belt_to_screen(&settings.belt),
            drum_encoder_reversed: settings.drum_encoder_reversed,
            work_switch_fitted: settings.work_switch_fitted,
            first_plant_distance: settings.first_plant_distance,
            speed_following: settings.placement == Placement::SpeedFollowing,
            link_parameter: self.link_parameter,
            link_value: settings.drive_link.value(self.link_parameter),
        }
    }
}

/// Half-width of the product's ΔKp domain (per sample): `Kp ∈ [1, 3]`
/// around `Kp0` = 2, where paper A allows ±5 (`Kp` up to 7).
///
/// Chosen from the robustness sweep of `cargo xtask bench` (docs/PERFORMANCE.md
/// §1): with ±5 the 7×7 tuner raises `Kp` to ≈ 5 at an overspeed error, which
/// is beyond the loop's margin (5 ms dead time, 10 ms measurement) once the
/// motor is faster than the drum model — on a drive with half the model's
/// 25 ms lag the drum oscillated between 17 and 36 r/min and never settled.
/// ±1.5 and below settle there (±1: 13 % overshoot, 1.1 s) and change nothing
/// on the nominal drum (1.2 % overshoot, 0.10 s, as with ±5), on a plant with
/// 20 % less or more gain, or on a slower motor. ±1 leaves a margin below
/// the ±1.5 edge. ΔKi and ΔKd keep the paper's ranges: they did not move the
/// limit.
pub const PRODUCT_DELTA_KP_RANGE: fuzzy_pid::I16F16 = fuzzy_pid::I16F16::ONE;

/// The drum controller: paper A's fuzzy self-tuning PID (7×7 rules,
/// `Kp0` = 2, `Ki0` = 0.1, `Kd0` = 0.05, the paper's rule tables and the
/// ΔKi, ΔKd ranges of SPEC §5) with the ΔKp range narrowed to
/// [`PRODUCT_DELTA_KP_RANGE`] for robustness against a faster drive.
///
/// The paper's base gains work on this drum as they stand because the PID
/// sees only the error the feed-forward cannot explain (the drum model of
/// `Supervisor::control_step`).
/// Compared against its measurement-vs-target form, with which the same gains
/// swung the drum between 0 and 100 % duty, and against ¼ and ½ of the gains,
/// which could not hold the seedlings' per-partition load (±5 % at 1.5 Hz)
/// within 0.5 % (`tests/closed_loop.rs`).
pub fn drum_controller_config() -> fuzzy_pid::Config {
    let mut config = fuzzy_pid::Config::default();
    if let fuzzy_pid::Schedule::Fuzzy(fuzzy) = &mut config.schedule {
        fuzzy.range.kp = PRODUCT_DELTA_KP_RANGE;
    }
    config
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;
    use hmi_proto::screen::DrumSpeed;
    use proptest::prelude::*;

    /// Reference: `floor(x · 1000 + 0.5)` in f64 (exact: `bits / 65536 ·
    /// 1000` has at most 41 significant bits), negative values as 0.
    fn milli_f64(bits: i32) -> u32 {
        let v = (f64::from(bits) / 65_536.0 * 1000.0 + 0.5).floor();
        if v < 0.0 {
            0
        } else {
            v as u32
        }
    }

    #[test]
    fn milli_above_32_767_r_min_is_exact() {
        // Failed before the fix: I16F16 × 1000 saturated to 32 767.99…, so
        // 40 r/min read 32 767 (issue 16 item 4).
        assert_eq!(milli(I16F16::from_num(40)), 40_000);
        assert_eq!(
            milli(I16F16::from_num(44.7)),
            milli_f64(I16F16::from_num(44.7).to_bits())
        );
        // The largest I16F16, 32 767 + 65 535/65 536 r/min, rounds up.
        assert_eq!(milli(I16F16::MAX), 32_768_000);
        assert_eq!(milli(I16F16::from_num(-1)), 0);
    }

    /// Page 10 (docs/hmi.md): the selector shows each setting's saved
    /// value; a value goes into the saved link settings only when the whole
    /// passes `DriveLinkSettings::build`, refused by name otherwise; the
    /// link in force stays the one the supervisor was built with until a
    /// restart: with the read-back chosen as the feedback on the page, the
    /// drum still runs on its encoder (no stall alarm: before
    /// `link_in_force`, the read-back that no link delivers counted 0 and
    /// the stall alarm latched 0.2 s after Start).
    #[test]
    #[cfg(feature = "drive-link")]
    fn page_10_edits_the_saved_link_settings_not_the_link_in_force() {
        use crate::drive_link::FeedbackSource;
        use hmi_proto::screen::{LinkParameter as P, Mode};
        let settings = Settings {
            mode: Mode::Fixed,
            fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
            ..Settings::default()
        };
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        let set = |sup: &mut Supervisor, p: P, v: i32| {
            assert_eq!(
                sup.command(Command::SelectLinkParameter(p)),
                Effect::SettingsChanged
            );
            sup.command(Command::SetLinkValue(v))
        };
        // The ZLAC8015D's default line: 115 200 baud, slave 1.
        sup.command(Command::SelectLinkParameter(P::Baud));
        assert_eq!(sup.screen_settings().link_value, 115_200);
        assert_eq!(
            set(&mut sup, P::Feedback, 1),
            Effect::Message("Needs a driver (Driver 1 or 2)")
        );
        // Paper A's 118:1 behind the driver's 0.1 r/min (847 µr/min per
        // count) reads at most 27.75 r/min: refused until the scale is set.
        assert_eq!(
            set(&mut sup, P::Driver, 1),
            Effect::Message("Scale under 1365: reads < 44.7 r/min")
        );
        // Behind 59:1 (1695) the drum's 44.7 r/min needs 2638 motor r/min,
        // beyond the ZLAC8015D's 1000 (0x2008): refused by name; behind
        // 20:1 (5000) it needs 894: taken.
        assert_eq!(set(&mut sup, P::Scale, 1695), Effect::SettingsChanged);
        assert_eq!(
            set(&mut sup, P::Driver, 1),
            Effect::Message("Gearbox needs over 1000 motor r/min")
        );
        assert_eq!(set(&mut sup, P::Scale, 5000), Effect::SettingsChanged);
        assert_eq!(set(&mut sup, P::Driver, 1), Effect::SettingsChanged);
        // A reply timeout beyond 1000 ms is refused; the saved one stays.
        assert_eq!(
            set(&mut sup, P::ReplyTimeout, 1001),
            Effect::Message("Reply timeout: 5-1000 ms")
        );
        assert_eq!(sup.settings().drive_link.timing.reply_timeout_ms, 60);
        assert_eq!(set(&mut sup, P::ReplyTimeout, 80), Effect::SettingsChanged);
        assert_eq!(sup.settings().drive_link.timing.reply_timeout_ms, 80);
        assert_eq!(set(&mut sup, P::Feedback, 1), Effect::SettingsChanged);
        assert_eq!(sup.settings().drive_link.feedback, FeedbackSource::Driver);
        assert_eq!(sup.screen_settings().link_value, 1);
        assert_eq!(
            sup.command(Command::SetLinkValue(3)),
            Effect::Message("Value out of range")
        );
        assert_eq!(
            set(&mut sup, P::SpeedRegister, 65_536),
            Effect::Message("Value out of range")
        );
        assert_eq!(
            set(&mut sup, P::Baud, 4800),
            Effect::Message("Baud: 9600 19200 38400 57600 115200")
        );
        assert_eq!(
            set(&mut sup, P::Slave, 0),
            Effect::Message("Slave id must be 1-247")
        );
        assert_eq!(sup.settings().drive_link.generic.baud, 115_200);
        // Fixed 20 r/min on the encoder: 20 / 60 rev/s × 47 200 counts ×
        // 0.01 s = 157.3 counts per period.
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        for period in 0..50u32 {
            sup.control_step(Ticks(period * 10_000), encoder);
            encoder = encoder.wrapping_add(157);
        }
        assert_eq!(sup.alarm(), None);
        assert_eq!(
            sup.command(Command::SetLinkValue(1)),
            Effect::Message("Stop the drum first")
        );
    }

    /// Without the feature `drive-link` (the real board's default image):
    /// saved settings that name the ZLAC8015D as the only feedback and its
    /// Modbus command are kept as they are, but the drum runs on its
    /// encoder and the PWM (20 r/min fixed: 157 counts a period, no stall
    /// alarm, a PWM compare value); page 10 refuses values.
    #[test]
    #[cfg(not(feature = "drive-link"))]
    fn without_the_link_the_saved_link_settings_are_kept_and_not_used() {
        use crate::drive_link::{CommandPath, DriveLinkSettings, DriverKind, FeedbackSource};
        use hmi_proto::screen::Mode;
        let mut settings = Settings {
            mode: Mode::Fixed,
            fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
            ..Settings::default()
        };
        settings.drive_link = DriveLinkSettings {
            feedback: FeedbackSource::Driver,
            command: CommandPath::Modbus,
            kind: DriverKind::Zlac8015d,
            ..DriveLinkSettings::default()
        };
        settings.drive_link.generic.micro_rpm_per_count = 5000;
        assert!(settings.drive_link.build().is_ok());
        let saved = settings.drive_link;
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        assert_eq!(
            sup.command(Command::SetLinkValue(1)),
            Effect::Message(NO_DRIVE_LINK)
        );
        assert_eq!(sup.settings().drive_link, saved);
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        let mut last = Actuation::OFF;
        for period in 0..50u32 {
            last = sup.control_step(Ticks(period * 10_000), encoder);
            encoder = encoder.wrapping_add(157);
        }
        assert_eq!(sup.alarm(), None);
        assert_eq!(sup.run_state(), RunState::Running);
        assert!(last.ccr > 0 && last.driver_enabled, "{last:?}");
        assert_eq!(sup.bus_speed_command(), None);
    }

    /// A commissioning error: the drum turns (20 r/min fixed: 157 counts a
    /// period) but the encoder counts backwards (A/B swapped, or the motor
    /// wired the wrong way). Before, this latched "Drum stalled or encoder
    /// lost" and sent the technician looking for a jam; now the alarm says
    /// backwards, after the same 200 ms, outputs off. With the encoder
    /// direction setting reversed the same counts run the drum; a still
    /// drum whose encoder jitters one count back is a stall.
    #[test]
    fn an_encoder_counting_backwards_is_named_not_a_stall() {
        use hmi_proto::screen::Mode;
        let run = |reversed: bool, per_period: i32| {
            let settings = Settings {
                mode: Mode::Fixed,
                fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
                drum_encoder_reversed: reversed,
                ..Settings::default()
            };
            let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
            sup.command(Command::Start);
            let mut encoder: u16 = 30_000;
            let mut alarm_at = None;
            let mut act = Actuation::OFF;
            for period in 0..50u32 {
                act = sup.control_step(Ticks(period * 10_000), encoder);
                if alarm_at.is_none() && sup.alarm().is_some() {
                    alarm_at = Some(period);
                }
                // A jitter of one count back every other period.
                let step = if per_period == -1 && period % 2 == 1 {
                    0
                } else {
                    per_period
                };
                encoder = encoder.wrapping_add_signed(step as i16);
            }
            (sup.alarm(), alarm_at, act)
        };
        let (alarm, at, act) = run(false, -157);
        assert_eq!(alarm, Some(Alarm::DrumBackwards));
        // 200 ms of stall time, counted from the first step: 21 periods.
        assert_eq!(at, Some(20));
        assert_eq!(act, Actuation::OFF);
        let mut text = heapless::String::<40>::new();
        Alarm::DrumBackwards.write_text(&mut text).unwrap();
        assert_eq!(text.as_str(), "Drum turns backwards: check direction");
        assert_eq!(run(true, -157).0, None);
        assert_eq!(run(false, -1).0, Some(Alarm::DrumStall));
        assert_eq!(run(false, 0).0, Some(Alarm::DrumStall));
    }

    /// Speed-Adaptive at a constant travel speed (one Hall edge every
    /// 90 ms: ≈ 26.7 r/min at the gear, ≈ 1 km/h), speed-following
    /// placement; returns the drum target of the last step (r/min) and the
    /// alarm.
    #[allow(clippy::arithmetic_side_effects)]
    fn adaptive_target(spacing_mm: i32, coefficient: i32) -> (f64, Option<Alarm>) {
        use hmi_proto::screen::{MotorCoefficient, Spacing};
        let settings = Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(spacing_mm).unwrap(),
            motor_coefficient: MotorCoefficient::new(coefficient).unwrap(),
            placement: Placement::SpeedFollowing,
            ..Settings::default()
        };
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        let mut next_edge = 5_000u32;
        for period in 0..300u32 {
            let now = period * 10_000;
            while next_edge <= now {
                sup.hall_edge(Ticks(next_edge));
                next_edge += 90_000;
            }
            // The drum follows its target (no stall alarm).
            let n = f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0;
            encoder = encoder.wrapping_add((n / 60.0 * 47_200.0 * 0.01).round() as u16);
            sup.control_step(Ticks(now), encoder);
        }
        (
            f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0,
            sup.alarm(),
        )
    }

    /// docs/firmware.md, control step 3: the target is eq. 7 *times the
    /// motor coefficient*, held at `n_max` (with the warning) only when that
    /// product exceeds it. Eq. 7 is inversely proportional to the spacing,
    /// so eq. 7 at 7 cm is twice eq. 7 at 14 cm (k3 is flat at 0.980 above
    /// 25 r/min, Table 13 clamped): at ≈ 26 r/min for 14 cm, eq. 7 at 7 cm
    /// asks ≈ 52 r/min, beyond 44.7; with a coefficient of 0.80 the drum
    /// must run at 0.80 × 52 ≈ 41.6 r/min, within `n_max`, without a
    /// warning. Before: eq. 7 was held at 44.7 first, then × 0.80 = 35.76
    /// r/min (14 % slow: plants 16 % too far apart) under a *Too fast*
    /// warning.
    #[test]
    fn the_motor_coefficient_applies_before_the_n_max_limit() {
        let (n14, alarm) = adaptive_target(140, 100);
        assert_eq!(alarm, None);
        assert!(n14 > 25.0 && n14 < 27.0, "{n14}");
        let (n7, alarm) = adaptive_target(70, 80);
        let expected = 0.8 * 2.0 * n14;
        assert!((n7 - expected).abs() < 0.02, "{n7} vs {expected}");
        assert_eq!(alarm, None);
        // A coefficient of 1.20 at 14 cm (≈ 31 r/min) still follows …
        let (n, alarm) = adaptive_target(140, 120);
        assert!((n - 1.2 * n14).abs() < 0.02, "{n}");
        assert_eq!(alarm, None);
        // … and at 7 cm (≈ 62 r/min) is held at n_max with the warning.
        let (n, alarm) = adaptive_target(70, 120);
        assert!((n - 44.7).abs() < 0.01, "{n}");
        // The maximum shown is the speed at which 1.20 × eq. 7 reaches
        // 44.7 r/min: V = k3·n_max·π·0.070 m/60 · X/Lclap / 1.20 =
        // 0.980 · 44.7 · 0.219 911 / 60 · 1.4 / 1.2 = 0.1873 m/s =
        // 0.674 km/h (hand-computed; Table 13's k3 clamped at 0.980).
        assert!(
            matches!(
                alarm,
                Some(Alarm::TooFast {
                    max_kmh_x100: 66..=68
                })
            ),
            "{alarm:?}"
        );
    }

    /// A coefficient typed on page 4 is shown back as typed, over the
    /// whole range the screen accepts (0.800–1.200, docs/hmi.md), for each
    /// table. Before: `Coefficient` holds 0.800 as 0.799 999 99… (2⁻³⁰
    /// steps) and the screen value was its thousandths rounded *down*:
    /// 1.200 showed 1.199, 0.980 showed 0.979, and 0.800 read 799, outside
    /// the screen's range, so the screen showed the default 1.000.
    #[test]
    fn a_coefficient_set_on_the_screen_is_shown_as_set() {
        use hmi_proto::screen::CalibrationCoefficient;
        let mut sup = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
        for kind in [
            CalibrationKind::SpeedK1,
            CalibrationKind::SlipK2,
            CalibrationKind::BeltK3,
        ] {
            sup.command(Command::SelectCalibration(kind));
            for v in [800, 801, 980, 993, 1000, 1031, 1199, 1200] {
                let k = CalibrationCoefficient::new(v).unwrap();
                assert_eq!(
                    sup.command(Command::SetCalibrationCoefficient(k)),
                    Effect::SettingsChanged
                );
                assert_eq!(
                    sup.screen_settings().calibration_coefficient.raw(),
                    v as u16,
                    "{kind:?}"
                );
            }
        }
    }

    /// Paper A's own k2 procedure (Table 12, SPEC §4) at Low 1: 400 m
    /// taped, 655.08 wheel turns (16 377 Hall edges) in 4645.16 s — longer
    /// than the 4295 s a `u32` of µs holds. Expected (Table 12, by hand):
    /// k2 = 400 / (655.08 · π · 0.20) = 0.9719, at the wheel speed
    /// 3.6 · 411.61 / 4645.16 = 0.3190 km/h (`PAPER_K2`'s abscissa). Before,
    /// the run's duration saturated at 4295 s: the point went in at
    /// 0.345 km/h, 8 % off. The k1 and k3 runs shared the duration.
    #[test]
    #[allow(clippy::arithmetic_side_effects)]
    fn a_calibration_run_longer_than_71_minutes_keeps_its_duration() {
        use hmi_proto::screen::CalibrationDistance;
        let mut sup = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
        sup.command(Command::SelectCalibration(CalibrationKind::SlipK2));
        let steps = 464_516u32; // 4645.16 s of 10 ms periods
        let gap = 4_645_160_000u64 / 16_377; // µs per Hall edge
        let mut next_edge = 0u64;
        sup.control_step(Ticks(0), 0);
        sup.command(Command::CalibrationStart);
        for period in 1..=steps {
            let now = u64::from(period) * 10_000;
            while next_edge + gap <= now {
                next_edge += gap;
                sup.hall_edge(Ticks(next_edge as u32));
            }
            sup.control_step(Ticks(now as u32), 0);
        }
        sup.command(Command::CalibrationStop);
        let CalibrationRun::Measured {
            edges, steps: s, ..
        } = sup.calibration_run()
        else {
            panic!("{:?}", sup.calibration_run());
        };
        assert_eq!((edges, s), (16_377, steps));
        sup.command(Command::CalibrationActualDistance(
            CalibrationDistance::new(40_000).unwrap(),
        ));
        let CalibrationRun::Computed { at, k, .. } = sup.calibration_run() else {
            panic!("{:?}", sup.calibration_run());
        };
        let k2 = 400.0 / (655.08 * core::f64::consts::PI * 0.20);
        assert!((k.to_f64() - k2).abs() < 0.0005, "k2 {}", k.to_f64());
        let v = 3.6 * 16_377.0 / 25.0 * core::f64::consts::PI * 0.20 / 4645.16;
        assert!((at.to_num::<f64>() - v).abs() < 0.002, "at {at} vs {v}");
    }

    /// The drive identification (page 9) steps the drum at 25 % and 75 %
    /// duty; the drum driver's link is lost in the middle of it (or the
    /// driver reports a fault). The alarm latches and stops the drum
    /// (module docs: latched alarms mean PWM 0, driver off) — in the same
    /// control step. Before: the step's identification duty had been
    /// computed before the link's alarms were checked and was applied with
    /// the driver enabled for that period, the alarm already up.
    #[test]
    #[cfg(feature = "drive-link")]
    fn a_link_alarm_during_the_identification_switches_the_drum_off_at_once() {
        use crate::drive_link::{DriveLinkSettings, DriverKind, LinkSample};
        for fault in [false, true] {
            let mut drive_link = DriveLinkSettings {
                kind: DriverKind::Zlac8015d,
                ..DriveLinkSettings::default()
            };
            drive_link.generic.micro_rpm_per_count = 5000;
            let settings = Settings {
                drive_link,
                ..Settings::default()
            };
            assert!(settings.drive_link.build().is_ok());
            let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
            assert_eq!(
                sup.command(Command::IdentifyDrive),
                Effect::Message(IDENTIFY_MESSAGE)
            );
            let answering = LinkSample {
                answering: true,
                ..LinkSample::default()
            };
            let mut encoder: u16 = 0;
            for period in 0..30u32 {
                sup.set_link_sample(answering);
                let act = sup.control_step(Ticks(period * 10_000), encoder);
                assert!(act.driver_enabled && act.ccr > 0, "{act:?}");
                encoder = encoder.wrapping_add(100);
            }
            sup.set_link_sample(if fault {
                LinkSample {
                    fault_word: 1,
                    fault_reads: 1,
                    ..answering
                }
            } else {
                LinkSample {
                    lost: true,
                    ..LinkSample::default()
                }
            });
            let act = sup.control_step(Ticks(300_000), encoder);
            assert!(
                sup.alarm().is_some_and(|a| a.is_latched()),
                "{:?}",
                sup.alarm()
            );
            assert_eq!(act, Actuation::OFF, "fault {fault}");
        }
    }

    /// The work switch up (the unit lifted on the headland or between
    /// rows): the drum ramps to rest and nothing is planted, so no travel
    /// speed is too fast for the spacing and the *Too fast* warning (page
    /// 2) stays down; lowered at the same speed, it comes up. Edges every
    /// 40 ms (2.26 km/h at the gear) against the ≈ 0.81 km/h 7 cm allows.
    /// Before: the warning stood the whole headland.
    #[test]
    #[allow(clippy::arithmetic_side_effects)]
    fn a_lifted_unit_raises_no_too_fast_warning() {
        use hmi_proto::screen::Spacing;
        let settings = Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(70).unwrap(),
            work_switch_fitted: true,
            ..Settings::default()
        };
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        let mut next_edge = 5_000u32;
        for period in 0..400u32 {
            let now = period * 10_000;
            // Lowered for the last second.
            sup.set_work_switch(period >= 300);
            while next_edge <= now {
                sup.hall_edge(Ticks(next_edge));
                next_edge += 40_000;
            }
            let n = f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0;
            encoder = encoder.wrapping_add((n / 60.0 * 47_200.0 * 0.01).round() as u16);
            sup.control_step(Ticks(now), encoder);
            if period == 299 {
                assert_eq!(sup.alarm(), None);
            }
        }
        assert!(
            matches!(sup.alarm(), Some(Alarm::TooFast { .. })),
            "{:?}",
            sup.alarm()
        );
    }

    #[test]
    fn the_default_drive_model_reproduces_the_design_controller() {
        // The default model (44.70 r/min, 25 ms, 5 ms) is the drive the
        // controller was tuned on: scale 1, the same configuration, the
        // reference model's 2 periods and α = 1 − e^(−10/25) = 0.329 680.
        let model = DriveModel::DEFAULT;
        assert_eq!(schedule_scale(&model, 10_000), I16F16::ONE);
        let mut design = drum_controller_config();
        design.output_max = I16F16::from_num(44.7);
        let scheduled = scheduled_config(&model, 10_000);
        assert_eq!(scheduled.base, design.base);
        assert_eq!(scheduled.schedule, design.schedule);
        assert_eq!(scheduled.min_gains, design.min_gains);
        assert!((scheduled.output_max - design.output_max).abs() < I16F16::from_num(0.0001));
        let law = DriveLaw::of(&model, 10_000);
        assert_eq!(law.ref_delay, 2);
        let alpha = 1.0 - (-0.4f64).exp();
        assert!((law.ref_alpha.to_num::<f64>() - alpha).abs() < 2e-5);
        assert!((REFERENCE_ALPHA.to_num::<f64>() - alpha).abs() < 1e-4);
    }

    #[test]
    fn scheduled_configs_build_for_extreme_models() {
        // The corners of DriveModel's ranges: every scheduled configuration
        // (and the fallback) builds, so the controller `new` defers can
        // always be built.
        for n in [1000u16, 9000] {
            for tau in [10u16, 5000] {
                for dead in [0u16, 2000] {
                    let m = DriveModel::new(n, tau, dead).unwrap();
                    assert!(scheduled_config(&m, 10_000).build().is_ok(), "{m:?}");
                    assert!(fallback_config(&m).build().is_ok(), "{m:?}");
                }
            }
        }
    }

    #[test]
    fn the_schedule_shrinks_with_dead_time_and_a_faster_drive() {
        // s = min(1, (τ/θ)/(25/15)), θ = L + 10 ms (hand-computed).
        let s = |tau_x10, dead_x10| {
            schedule_scale(&DriveModel::new(4470, tau_x10, dead_x10).unwrap(), 10_000)
                .to_num::<f64>()
        };
        assert!((s(250, 200) - 0.5).abs() < 1e-4); // 25/30 / (25/15)
        assert!((s(88, 600) - 8.8 / 70.0 * 15.0 / 25.0).abs() < 1e-4);
        assert_eq!(s(750, 0), 1.0); // slower drive: the design gains
                                    // Reference delay 1 + round((L + 5 ms)/10 ms): 60 ms → 7 + 1 = 8.
        let law = DriveLaw::of(&DriveModel::new(4470, 250, 600).unwrap(), 10_000);
        assert_eq!(law.ref_delay, 8);
    }

    proptest! {
        /// The shift conversions that replace `fixed`'s generic ones give
        /// `fixed`'s results (the reference) for every representable value:
        /// drum speeds U12F20 → I16F16, k2 U2F30 → U10F22, and (machine.rs)
        /// the clamping angle's whole degrees U16F16 → u32.
        #[test]
        fn shift_conversions_are_fixeds_conversions(bits in any::<u32>()) {
            let n = RevPerMin::from_bits(bits);
            prop_assert_eq!(rpm_to_fix(n), I16F16::saturating_from_num(n.to_fixed()));
            let k2 = fixed::types::U2F30::from_bits(bits);
            prop_assert_eq!(
                fixed::types::U10F22::from_bits(k2.to_bits() >> 8),
                fixed::types::U10F22::saturating_from_num(k2)
            );
            let angle = U16F16::from_bits(bits);
            prop_assert_eq!(angle.to_bits() >> 16, angle.to_num::<u32>());
        }

        /// Every `I16F16` the supervisor can hold (the whole type, so any
        /// drum speed up to any `n_max`) against the f64 reference.
        #[test]
        fn milli_matches_f64_over_the_whole_type(bits in any::<i32>()) {
            prop_assert_eq!(milli(I16F16::from_bits(bits)), milli_f64(bits));
        }

        /// Fixed mode, every drum speed the screen accepts (0–44.70 r/min):
        /// the target in the snapshot (log) and on the screen is the set
        /// speed itself (r/min × 100 from the screen, × 10 for the log).
        #[test]
        fn every_fixed_drum_speed_is_reported_as_set(raw in DrumSpeed::MIN..=DrumSpeed::MAX) {
            let settings = Settings {
                mode: Mode::Fixed,
                fixed_drum_speed: DrumSpeed::new(i32::from(raw)).unwrap(),
                ..Settings::default()
            };
            let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
            sup.command(Command::Start);
            sup.control_step(Ticks(0), 0);
            prop_assert_eq!(sup.snapshot().target_drum_rpm_x1000, u32::from(raw) * 10);
            prop_assert_eq!(sup.screen_status().target_drum_rpm_x100, raw);
        }
    }

    /// Page 4: a coefficient typed by hand (0.800–1.200, docs/hmi.md §4)
    /// and taken is shown back as typed, for each kind. Measured before the
    /// fix: 0.800 was taken and the screen then showed 1.000 (0.8 in U2F30
    /// is 1 bit below 0.8, `to_milli` rounds down to 799, out of range,
    /// and the screen got the default), and 0.801 showed 0.800.
    #[test]
    fn every_hand_set_coefficient_is_shown_as_typed() {
        let mut wrong = std::vec::Vec::new();
        for kind in [
            CalibrationKind::SpeedK1,
            CalibrationKind::SlipK2,
            CalibrationKind::BeltK3,
        ] {
            for raw in 800..=1200 {
                let mut sup = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
                sup.command(Command::SelectCalibration(kind));
                let k = screen::CalibrationCoefficient::new(raw).unwrap();
                let effect = sup.command(Command::SetCalibrationCoefficient(k));
                let shown = sup.screen_settings().calibration_coefficient.raw();
                if effect != Effect::SettingsChanged || i32::from(shown) != raw {
                    wrong.push((kind, raw, effect, shown));
                }
            }
        }
        assert!(
            wrong.is_empty(),
            "{} wrong, e.g. {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(4)]
        );
    }
}
