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
//!
//! # Layout
//!
//! The state lives in [`Supervisor`] (this module); its methods are split by
//! concern over facet modules, each an `impl Supervisor`: the control step
//! (`step`: sense → estimate → plan → supervise → control → report), the
//! operator's commands (`command`), the calibration (`calibration`), the
//! drive model and its identification (`identify`), the driver's link
//! (`link`), the work switch and the plant count (`pass`), the screen
//! mapping (`status`). The parts they keep and compute with are leaf
//! modules that know nothing of the supervisor: [`alarm`], [`drive_law`],
//! `monitor`, `predictor`, `fix` and the vocabulary in `types`.

pub mod alarm;
mod calibration;
mod command;
pub mod drive_law;
mod fix;
mod identify;
mod link;
mod monitor;
mod pass;
mod predictor;
mod status;
mod step;
mod types;
pub mod work;

/// What the screen should do after a command (both machines).
pub use crate::effect::Effect;
pub use alarm::{
    Alarm, DISTANCE_EDGE_MIN_GAP_US, DRUM_UNSTABLE_TEXT, HALL_SILENCE_DECEL_MM_S2,
    HALL_SILENCE_GAP_TOLERANCE_PCT, IDENTIFY_MESSAGE, NO_PULSES_TEXT, NO_PULSES_US,
};
pub use drive_law::{
    drum_controller_config, fallback_config, schedule_scale, scheduled_config, FALLBACK_KI,
    PRODUCT_DELTA_KP_RANGE, REFERENCE_ALPHA,
};
pub use fix::milli;
pub use types::{Actuation, CalibrationRun, Error, Hardware, RunState, Snapshot};

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

use crate::drive::{DriveModel, Identifier, IdentifyError, IdentifyState};
use crate::phase::{first_plant_place_fine_um, first_plant_place_um, Phase, PlantEvent};
use crate::settings::{self, Placement, Settings};

use alarm::*;
use drive_law::{DriveLaw, PHASE_FADE, PHASE_SMOOTHING, REF_HISTORY};
use fix::*;
use monitor::Monitor;
use predictor::Predictor;
use types::{BELT_PER_DRUM_TURN_UM, EDGE_UM};
use work::Work;

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
    /// ([`crate::drum::work`]).
    pub(crate) work: Work,
    /// Live planting quality ([`crate::quality`]).
    pub(crate) quality: crate::quality::Quality,
    /// The drum driver's link: its newest sample, the read-back's
    /// integration, the cross-check ([`crate::drive_link`]).
    pub(crate) link: crate::drive_link::Feedback,
    /// The travel source: the ground wheel, its cross-check with the Hall
    /// gear, the live slip ([`crate::ground`]).
    pub(crate) ground: crate::ground::Ground,
}

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
        let link_in_force = crate::drive_link::LinkInForce::from(&settings.drive_link);
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
            work: Work::new(),
            quality: crate::quality::Quality::new(),
            link: crate::drive_link::Feedback::default(),
            ground: crate::ground::Ground::new(),
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

    /// The ground wheel's encoder counter (wraps at 2¹⁶), read once a control
    /// period before [`Supervisor::control_step`] (machine A with a ground
    /// wheel, docs/ground-wheel.md).
    pub fn ground_wheel_count(&mut self, counter: u16) {
        self.ground.wheel_count(counter);
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
            let spacing = self.settings.spacing.raw();
            self.realign_next_plant(if self.settings.ground_wheel.source.uses_wheel() {
                first_plant_place_fine_um(spacing)
            } else {
                first_plant_place_um(spacing)
            });
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
}
