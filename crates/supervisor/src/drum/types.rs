//! The drum machine's vocabulary: its board, its errors, its run state,
//! what a step applies and reports, the calibration run's state.

use fixed::types::U16F16;
use hmi_proto::screen::CalibrationKind;

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

/// Errors building a [`Supervisor`](super::Supervisor).
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
    /// The track's live slip against the ground wheel, 0.1 % (both sensors
    /// fitted and turning).
    pub track_slip_x10: Option<i16>,
    /// The sensor giving the ground now.
    pub travel_source: hmi_proto::screen::TravelSourceInUse,
    /// Ground wheel counts since boot (after its direction setting).
    pub wheel_counts: i64,
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
        /// Ground wheel counts at the start (signed, after its direction).
        start_wheel_counts: i64,
    },
    /// Run ended: what it counted and how long it took.
    Measured {
        /// Hall edges in the run.
        edges: u32,
        /// Control steps the run lasted.
        steps: u32,
        /// Drum encoder counts in the run.
        drum_counts: u64,
        /// Ground wheel counts in the run (signed, after its direction).
        wheel_counts: i64,
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
    /// The ground wheel's run and its taped length: its counts per metre.
    WheelComputed {
        /// Counts per metre × 1000.
        counts_per_m_x1000: u32,
    },
}

/// Track per Hall edge: π·0.20 m / 25 = 25 133 µm.
pub(super) const EDGE_UM: u64 = 25_133;
/// Belt per drum turn: π·(D2 + 2·H2) = π·0.070 m = 219 911 µm.
pub(super) const BELT_PER_DRUM_TURN_UM: u64 = 219_911;
