//! Section 8: paper A's Table 14 (drum speed accuracy) and Table 15 (drum
//! response to travel-speed steps) reproduced with the product's control
//! (`supervisor::drum::Supervisor`, exactly as the firmware's 10 ms task
//! runs it) on the machine model, side by side with the paper's figures.
//!
//! Every product figure comes from the runs below; the paper's figures are
//! the constants [`PAPER_TABLE_14`] and [`PAPER_TABLE_15`], transcribed from
//! paper A (Agriculture 2025, 15, 621, section 3.6) and labelled as the
//! paper's wherever they are printed.

use hmi_proto::screen::{Command, DrumSpeed, Mode, Spacing};
use kinematics::consts::Gear;
use kinematics::units::Ticks;
use machine_sim::{Config, Event, Inputs, Machine};
use supervisor::drum::{Actuation, Hardware, RunState, Supervisor};
use supervisor::settings::Settings;

use crate::Result;

const HW: Hardware = Hardware::BOARD;

/// One row of paper A's Table 14 ("Motor accuracy table").
pub struct PaperAccuracy {
    /// Desired (set) drum speed, r/min.
    pub desired_rpm: f64,
    /// The five measured speeds, r/min.
    pub readings: [f64; 5],
    /// Their mean as printed, r/min.
    pub mean_rpm: f64,
    /// Relative error as printed, % (`|desired − mean| / desired`).
    pub rel_error_pct: f64,
}

/// Paper A Table 14. The extracted text of the 25.21 r/min row lists its
/// readings out of order (24.38, 25.08, 25.19, 25.16, then the mean and
/// error, then 25.12); the five values and the printed mean 24.99 agree
/// (124.93 / 5 = 24.986), the order of the last reading is uncertain.
pub const PAPER_TABLE_14: [PaperAccuracy; 5] = [
    PaperAccuracy {
        desired_rpm: 5.21,
        readings: [5.12, 5.20, 5.18, 5.19, 5.18],
        mean_rpm: 5.17,
        rel_error_pct: 0.77,
    },
    PaperAccuracy {
        desired_rpm: 10.21,
        readings: [10.09, 10.14, 10.11, 10.16, 10.20],
        mean_rpm: 10.14,
        rel_error_pct: 0.69,
    },
    PaperAccuracy {
        desired_rpm: 15.21,
        readings: [14.89, 15.09, 15.18, 15.12, 15.18],
        mean_rpm: 15.09,
        rel_error_pct: 0.79,
    },
    PaperAccuracy {
        desired_rpm: 20.21,
        readings: [20.10, 20.09, 20.05, 20.14, 20.11],
        mean_rpm: 20.10,
        rel_error_pct: 0.54,
    },
    PaperAccuracy {
        desired_rpm: 25.21,
        readings: [24.38, 25.08, 25.19, 25.16, 25.12],
        mean_rpm: 24.99,
        rel_error_pct: 0.87,
    },
];

/// One row of paper A's Table 15 ("Motor response time").
pub struct PaperResponse {
    /// Travel-speed increment from the 0.30 km/h base, km/h.
    pub increment_kmh: f64,
    /// The five measured response times, ms.
    pub readings_ms: [u32; 5],
    /// The maximum as printed, ms.
    pub max_ms: u32,
}

/// Paper A Table 15.
pub const PAPER_TABLE_15: [PaperResponse; 5] = [
    PaperResponse {
        increment_kmh: 0.5,
        readings_ms: [48, 51, 52, 50, 50],
        max_ms: 52,
    },
    PaperResponse {
        increment_kmh: 1.0,
        readings_ms: [47, 50, 48, 49, 48],
        max_ms: 50,
    },
    PaperResponse {
        increment_kmh: 1.5,
        readings_ms: [53, 53, 50, 52, 54],
        max_ms: 54,
    },
    PaperResponse {
        increment_kmh: 2.0,
        readings_ms: [48, 50, 50, 48, 47],
        max_ms: 50,
    },
    PaperResponse {
        increment_kmh: 2.5,
        readings_ms: [52, 51, 52, 53, 50],
        max_ms: 53,
    },
];

/// Paper A's travel speed before each step of Table 15, km/h.
pub const PAPER_BASE_KMH: f64 = 0.30;

// ---------------------------------------------------------------------
// Table 14: drum speed accuracy, Fixed mode
// ---------------------------------------------------------------------

/// Time from Start to the first reading, ms (the drum settles in < 1 s:
/// section 1).
pub const ACCURACY_SETTLE_MS: u32 = 4_000;
/// Length of one reading (mean true drum speed over it), ms.
pub const ACCURACY_READING_MS: u32 = 1_000;
/// Readings per row (paper A: five).
pub const REPEATS: usize = 5;

/// Seed of repeat `r` of Table 14 row `row`: `1400 + 10·row + r`.
#[must_use]
pub fn accuracy_seed(row: usize, r: usize) -> u64 {
    1400 + 10 * row as u64 + r as u64
}

/// One control period (10 ms) of the machine with the product's step at its
/// end, as the firmware's task runs it; `on_ms` sees the machine after each
/// millisecond and every Hall edge is handed to the supervisor.
fn period(
    m: &mut Machine,
    sup: &mut Supervisor,
    act: &mut Actuation,
    on_ms: &mut dyn FnMut(&mut Machine, &[u32]),
) {
    let inputs = Inputs {
        drum_duty: f32::from(act.ccr) / f32::from(HW.pwm_arr + 1),
        driver_enabled: act.driver_enabled,
        ..Inputs::default()
    };
    for _ in 0..10 {
        let mut edges: Vec<u32> = Vec::new();
        m.step_events(1_000, &inputs, &mut |e| {
            if let Event::HallEdge(t) = e {
                edges.push(t);
            }
        });
        for t in &edges {
            sup.hall_edge(Ticks(*t));
        }
        on_ms(m, &edges);
    }
    *act = sup.control_step(Ticks(m.capture_ticks()), m.drum_encoder_count());
}

/// One reading of Table 14: the product in Fixed mode at `set_centi_rpm`
/// (hundredths of r/min, as the screen enters it) on the default noisy
/// machine with `seed`, the belt starting `belt_phase` (0 … 1) of a
/// partition pitch along (where the seedlings' load cycle starts); the mean
/// *true* drum speed (the model's shaft, not the product's encoder estimate)
/// over [`ACCURACY_READING_MS`] after [`ACCURACY_SETTLE_MS`], r/min.
pub fn accuracy_reading(set_centi_rpm: u16, seed: u64, belt_phase: f32) -> Result<f64> {
    let mut m = Config {
        seed,
        belt_initial_phase: belt_phase,
        ..Config::default()
    }
    .build()
    .map_err(|e| format!("machine: {e}"))?;
    let settings = Settings {
        mode: Mode::Fixed,
        fixed_drum_speed: DrumSpeed::new(i32::from(set_centi_rpm)).map_err(|e| format!("{e:?}"))?,
        ..Settings::default()
    };
    let mut sup = Supervisor::new(HW, settings).map_err(|e| format!("supervisor: {e}"))?;
    let mut act = Actuation::OFF;
    sup.command(Command::Start);
    let mut none = |_: &mut Machine, _: &[u32]| {};
    for _ in 0..ACCURACY_SETTLE_MS / 10 {
        period(&mut m, &mut sup, &mut act, &mut none);
    }
    let turns0 = m.drum_turns();
    for _ in 0..ACCURACY_READING_MS / 10 {
        period(&mut m, &mut sup, &mut act, &mut none);
    }
    if sup.run_state() != RunState::Running {
        return Err(format!(
            "Table 14 at {set_centi_rpm} (seed {seed}): the drum stopped ({:?})",
            sup.alarm()
        ));
    }
    Ok((m.drum_turns() - turns0) * 60_000.0 / f64::from(ACCURACY_READING_MS))
}

/// One product row of Table 14.
pub struct AccuracyRow {
    /// The set drum speed, r/min.
    pub desired_rpm: f64,
    /// The five readings, r/min.
    pub readings: [f64; REPEATS],
}

impl AccuracyRow {
    /// Mean of the readings, r/min.
    pub fn mean(&self) -> f64 {
        self.readings.iter().sum::<f64>() / REPEATS as f64
    }
    /// Paper A's accuracy figure: `|desired − mean| / desired`, %.
    pub fn rel_error_pct(&self) -> f64 {
        relative_error_pct(self.desired_rpm, &self.readings)
    }
    /// The largest error of a single reading, %.
    pub fn worst_reading_pct(&self) -> f64 {
        self.readings
            .iter()
            .map(|r| 100.0 * (r - self.desired_rpm).abs() / self.desired_rpm)
            .fold(0.0, f64::max)
    }
}

/// Paper A's relative error of Table 14: `|desired − mean(readings)| /
/// desired`, %.
#[must_use]
pub fn relative_error_pct(desired: f64, readings: &[f64]) -> f64 {
    let mean = readings.iter().sum::<f64>() / readings.len().max(1) as f64;
    100.0 * (desired - mean).abs() / desired
}

/// Runs Table 14: every row of [`PAPER_TABLE_14`], [`REPEATS`] readings
/// each (one run per reading, seeds [`accuracy_seed`]).
pub fn table14() -> Result<Vec<AccuracyRow>> {
    let mut rows = Vec::new();
    for (i, p) in PAPER_TABLE_14.iter().enumerate() {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let centi = (p.desired_rpm * 100.0).round() as u16;
        let mut readings = [0.0; REPEATS];
        for (r, slot) in readings.iter_mut().enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let phase = r as f32 / REPEATS as f32;
            *slot = accuracy_reading(centi, accuracy_seed(i, r), phase)?;
        }
        rows.push(AccuracyRow {
            desired_rpm: p.desired_rpm,
            readings,
        });
    }
    Ok(rows)
}

// ---------------------------------------------------------------------
// Table 15: response to travel-speed steps, Speed-Adaptive mode
// ---------------------------------------------------------------------

/// Plant spacing of the Table 15 runs, mm: the smallest round spacing at
/// which the largest step (0.30 + 2.5 = 2.80 km/h) stays below the drum's
/// 44.7 r/min (`cargo xtask plan --spacing 25cm --speed 2.8km/h`: 40.9 r/min;
/// at paper A's 18 cm the drum would saturate from 2.1 km/h, at 7 cm from
/// 0.81 km/h). Paper A does not say which spacing it used.
pub const STEP_SPACING_MM: u16 = 250;
/// Time at 0.30 km/h before the step (drum and estimator settled), ms.
pub const STEP_AT_MS: u32 = 8_000;
/// The five repeats put the step `k · STEP_OFFSET_MS` later (k = 0 … 4):
/// about a fifth of the Hall period at 0.30 km/h (311 ms in the runs), so the
/// steps fall at five phases of the tooth period and of the 10 ms control
/// period.
pub const STEP_OFFSET_MS: u32 = 61;
/// Observation window after the step, ms.
pub const STEP_WINDOW_MS: u32 = 3_000;
/// Settling band, relative to the new target (the bench's ±2 %, section 1).
pub const SETTLE_BAND: f64 = 0.02;
/// Rise criterion: share of the change the drum has made.
pub const RISE_SHARE: f64 = 0.9;

/// The plant of the Table 15 runs: the machine model without random noise,
/// terrain or sensor errors (a bench test, like paper A's), with the
/// seedlings' load (5 % droop per partition) and the chassis's step
/// instantaneous (`track_tau_s` 0: the wheel speed jumps at the step).
#[must_use]
pub fn step_plant() -> Config {
    Config {
        load_droop: 0.05,
        track_tau_s: 0.0,
        ..Config::noiseless()
    }
}

/// The product's settings for Table 15: Speed-Adaptive at
/// [`STEP_SPACING_MM`], the Low 1 preset, everything else the defaults
/// (so the Speed-Adaptive control law is whichever the product ships as its
/// default; paper A's is speed following, the drum speed following the
/// measured travel speed).
///
/// Speed-following placement: Table 15 is the drum's *speed* response, the
/// paper's law. The distance-locked default deliberately moves the
/// drum off the speed target while it recovers the phase lost during the
/// step (docs/placement.md), so its "settle within ±2 %" would measure the
/// phase recovery, not the speed loop.
pub fn step_settings() -> Result<Settings> {
    Ok(Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(i32::from(STEP_SPACING_MM)).map_err(|e| format!("{e:?}"))?,
        gear: Gear::Low1,
        placement: supervisor::settings::Placement::SpeedFollowing,
        ..Settings::default()
    })
}

/// A step run's record.
pub struct StepRun {
    /// `(t ms, true drum speed r/min)` after each millisecond from 500 ms
    /// before the step to the end of the window.
    pub samples: Vec<(f64, f64)>,
    /// When the wheel speed changed, ms.
    pub change_ms: f64,
    /// The first Hall edge at or after the change, ms.
    pub first_edge_ms: Option<f64>,
    /// The product's drum target before the step, r/min.
    pub target_before: f64,
    /// The product's drum target at the end of the window, r/min.
    pub target_after: f64,
    /// Mean interval of the Hall edges in the second before the step, ms.
    pub hall_period_before_ms: f64,
    /// `(t ms, the product's drum target r/min)` at each control step after
    /// the change.
    pub targets: Vec<(f64, f64)>,
    /// Hall edges the model produced after the change.
    pub edges_after: u32,
    /// Of those, the ones the product's estimator accepted (the others it
    /// dropped as glitches).
    pub edges_accepted: u32,
}

/// The product in Speed-Adaptive mode ([`STEP_SPACING_MM`], Low 1 preset)
/// with the wheel at `PAPER_BASE_KMH`, stepped by `increment_kmh` at
/// `STEP_AT_MS + k · STEP_OFFSET_MS`.
pub fn step_run(increment_kmh: f64, k: u32) -> Result<StepRun> {
    let mut m = step_plant().build().map_err(|e| format!("machine: {e}"))?;
    #[allow(clippy::cast_possible_truncation)]
    m.set_travel_speed_m_s((PAPER_BASE_KMH / 3.6) as f32);
    let mut sup = Supervisor::new(HW, step_settings()?).map_err(|e| format!("supervisor: {e}"))?;
    let mut act = Actuation::OFF;
    sup.command(Command::Start);
    let change_ms = STEP_AT_MS + k * STEP_OFFSET_MS;
    let end_ms = change_ms + STEP_WINDOW_MS;
    let new_m_s = (PAPER_BASE_KMH + increment_kmh) / 3.6;
    let mut samples = Vec::new();
    let mut edges_before: Vec<f64> = Vec::new();
    let mut first_edge_ms = None;
    let mut target_before = None;
    let mut late_targets = Vec::new();
    let mut targets = Vec::new();
    let (mut edges_after, mut accepted_at_change) = (0u32, 0u32);
    let mut t_ms = 0u32;
    while t_ms < end_ms {
        let mut on_ms = |m: &mut Machine, edges: &[u32]| {
            let now = m.now_us();
            #[allow(clippy::cast_precision_loss)]
            let now_ms = now as f64 / 1000.0;
            for e in edges {
                let e_ms = f64::from(*e) / 1000.0;
                if e_ms >= f64::from(change_ms) {
                    first_edge_ms.get_or_insert(e_ms);
                    edges_after += 1;
                } else if e_ms >= f64::from(change_ms) - 1_000.0 {
                    edges_before.push(e_ms);
                }
            }
            if now_ms + 500.0 >= f64::from(change_ms) {
                samples.push((now_ms, f64::from(m.drum_speed_rpm())));
            }
            if now == u64::from(change_ms) * 1000 {
                #[allow(clippy::cast_possible_truncation)]
                m.set_travel_speed_m_s(new_m_s as f32);
            }
        };
        period(&mut m, &mut sup, &mut act, &mut on_ms);
        t_ms += 10;
        let target = f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0;
        if t_ms <= change_ms {
            target_before = Some(target);
            accepted_at_change = sup.snapshot().hall_edges;
        } else {
            targets.push((f64::from(t_ms), target));
        }
        if t_ms + 500 > end_ms {
            late_targets.push(target);
        }
    }
    if sup.run_state() != RunState::Running || sup.alarm().is_some() {
        return Err(format!(
            "Table 15 step +{increment_kmh} km/h: the product stopped or warned ({:?})",
            sup.alarm()
        ));
    }
    let hall_period_before_ms = match (edges_before.first(), edges_before.last()) {
        #[allow(clippy::cast_precision_loss)]
        (Some(a), Some(b)) if edges_before.len() > 1 => (b - a) / (edges_before.len() - 1) as f64,
        _ => 0.0,
    };
    #[allow(clippy::cast_precision_loss)]
    let target_after = late_targets.iter().sum::<f64>() / late_targets.len().max(1) as f64;
    Ok(StepRun {
        samples,
        change_ms: f64::from(change_ms),
        first_edge_ms,
        target_before: target_before.unwrap_or(0.0),
        target_after,
        hall_period_before_ms,
        targets,
        edges_after,
        edges_accepted: sup.snapshot().hall_edges.wrapping_sub(accepted_at_change),
    })
}

/// Response times of a step, ms from the reference instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Response {
    /// Time until the speed first reaches `from + RISE_SHARE·(to − from)`.
    pub rise_ms: Option<f64>,
    /// Time until the speed is within `±band·to` of `to` and stays there
    /// to the end of the record (the first sample of that final stretch).
    pub settle_ms: Option<f64>,
}

/// Measures a step response on `samples` (`(t ms, value)`, in time order)
/// from the reference instant `t_ref_ms`: the value was `from` before the
/// step and should go to `to`. Samples before `t_ref_ms` are ignored.
/// Rise: the first sample at or beyond `from + rise_share·(to − from)`
/// (either direction of step). Settle: the first sample after the last one
/// outside `to ± band·|to|`; `None` when the last sample is outside (never
/// settled within the record); 0 when none is outside.
#[must_use]
pub fn response(
    samples: &[(f64, f64)],
    t_ref_ms: f64,
    from: f64,
    to: f64,
    rise_share: f64,
    band: f64,
) -> Response {
    let after: Vec<(f64, f64)> = samples
        .iter()
        .copied()
        .filter(|(t, _)| *t >= t_ref_ms)
        .collect();
    let span = to - from;
    let rise_ms = after
        .iter()
        .find(|(_, v)| span != 0.0 && (v - from) / span >= rise_share)
        .map(|(t, _)| t - t_ref_ms);
    let settle_ms = match after
        .iter()
        .rposition(|(_, v)| (v - to).abs() > band * to.abs())
    {
        None => Some(0.0),
        Some(i) => after.get(i + 1).map(|(t, _)| t - t_ref_ms),
    };
    Response { rise_ms, settle_ms }
}

/// One repeat of Table 15, measured both ways.
pub struct StepResult {
    /// The run.
    pub run: StepRun,
    /// (a) from the physical change of travel speed.
    pub from_change: Response,
    /// (b) from the first Hall edge after the change.
    pub from_edge: Response,
    /// (c) from the first control step whose target has made
    /// [`RISE_SHARE`] of its change: the drum loop alone.
    pub from_target: Response,
    /// When that control step came, ms after the change.
    pub target_moved_ms: Option<f64>,
}

/// Measures one step run from the three instants. `from` of the rise is the true drum
/// speed at the change, `to` the product's new target.
pub fn measure(run: StepRun) -> StepResult {
    let from = run
        .samples
        .iter()
        .rev()
        .find(|(t, _)| *t <= run.change_ms)
        .map_or(run.target_before, |(_, v)| *v);
    let to = run.target_after;
    let from_change = response(
        &run.samples,
        run.change_ms,
        from,
        to,
        RISE_SHARE,
        SETTLE_BAND,
    );
    let from_edge = run.first_edge_ms.map_or(
        Response {
            rise_ms: None,
            settle_ms: None,
        },
        |e| response(&run.samples, e, from, to, RISE_SHARE, SETTLE_BAND),
    );
    let (tb, ta) = (run.target_before, run.target_after);
    let moved = run
        .targets
        .iter()
        .find(|(_, v)| ta != tb && (v - tb) / (ta - tb) >= RISE_SHARE)
        .map(|(t, _)| *t);
    let none = Response {
        rise_ms: None,
        settle_ms: None,
    };
    let from_target = moved.map_or(none, |t| {
        response(&run.samples, t, from, to, RISE_SHARE, SETTLE_BAND)
    });
    StepResult {
        target_moved_ms: moved.map(|t| t - run.change_ms),
        from_change,
        from_edge,
        from_target,
        run,
    }
}

/// Runs Table 15: per increment of [`PAPER_TABLE_15`], [`REPEATS`] steps.
pub fn table15() -> Result<Vec<Vec<StepResult>>> {
    PAPER_TABLE_15
        .iter()
        .map(|p| {
            (0..REPEATS as u32)
                .map(|k| step_run(p.increment_kmh, k).map(measure))
                .collect()
        })
        .collect()
}

/// Chassis lags of the stop-and-go check of the glitch filter, s.
pub const STOP_AND_GO_TAUS: [f32; 3] = [0.0, 0.2, 0.5];

/// The glitch filter on stop-and-go: the product (Table 15's settings) on
/// the default noisy machine (seed 3) at Low 2 with the chassis lag
/// `track_tau_s`, stops of 1 s every 10 s (regular, deceleration at most
/// 1 g), 60 s: Hall edges the model produced and the estimator accepted.
pub fn stop_and_go_edges(track_tau_s: f32) -> Result<(u32, u32)> {
    let mut m = Config {
        seed: 3,
        initial_gear: Some(Gear::Low2),
        track_tau_s,
        track_decel_limit_mm_s2: 9_810,
        terrain_stop_interval_s: 10.0,
        terrain_stop_duration_s: 1.0,
        terrain_stops_regular: true,
        ..Config::default()
    }
    .build()
    .map_err(|e| format!("machine: {e}"))?;
    let mut sup = Supervisor::new(HW, step_settings()?).map_err(|e| format!("supervisor: {e}"))?;
    let mut act = Actuation::OFF;
    sup.command(Command::Start);
    let mut produced = 0u32;
    let mut count = |_: &mut Machine, e: &[u32]| {
        produced += u32::try_from(e.len()).unwrap_or(u32::MAX);
    };
    for _ in 0..6_000 {
        period(&mut m, &mut sup, &mut act, &mut count);
    }
    Ok((produced, sup.snapshot().hall_edges))
}

// ---------------------------------------------------------------------
// The document section
// ---------------------------------------------------------------------

fn opt_ms(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_string(), |x| format!("{x:.0}"))
}

fn max_opt(mut v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    v.try_fold(0.0f64, |acc, x| x.map(|x| acc.max(x)))
}

fn join<T>(v: impl Iterator<Item = T>, f: impl Fn(T) -> String) -> String {
    v.map(f).collect::<Vec<_>>().join(", ")
}

/// The five repeats of one quantity and their maximum, `a, b, c, d, e (max)`.
fn five(reps: &[StepResult], f: &dyn Fn(&StepResult) -> Option<f64>) -> String {
    format!(
        "{} (**{}**)",
        join(reps.iter(), |r| opt_ms(f(r))),
        opt_ms(max_opt(reps.iter().map(f)))
    )
}

/// Smallest and largest of the repeats' values (`None`s left out).
fn range(t15: &[Vec<StepResult>], f: &dyn Fn(&StepResult) -> Option<f64>) -> (f64, f64) {
    t15.iter()
        .flatten()
        .filter_map(f)
        .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)))
}

/// The highest drum target of the repeats after the change, r/min.
fn peak_target(reps: &[StepResult]) -> f64 {
    reps.iter()
        .flat_map(|r| r.run.targets.iter().map(|(_, v)| *v))
        .fold(0.0, f64::max)
}

/// The plot of the slowest repeat (largest t90 from the change) of each
/// increment: true drum speed and the product's target against the time
/// since the change.
fn step_plot(t15: &[Vec<StepResult>]) -> super::svg::Chart {
    use super::svg::{Series, PALETTE};
    const FROM_MS: f64 = -50.0;
    const TO_MS: f64 = 500.0;
    let mut series = Vec::new();
    for (i, (p, reps)) in PAPER_TABLE_15.iter().zip(t15).enumerate() {
        let Some(r) = reps.iter().max_by(|a, b| {
            let key = |r: &StepResult| r.from_change.rise_ms.unwrap_or(f64::MAX);
            key(a).total_cmp(&key(b))
        }) else {
            continue;
        };
        let c = r.run.change_ms;
        let colour = PALETTE.get(i).copied().unwrap_or("#000000");
        series.push(Series {
            name: format!("+{:.1} km/h, drum", p.increment_kmh),
            colour,
            points: r
                .run
                .samples
                .iter()
                .map(|(t, v)| (t - c, *v))
                .filter(|(t, _)| (FROM_MS..=TO_MS).contains(t))
                .collect(),
            dashed: false,
        });
        let mut stairs = vec![(FROM_MS, r.run.target_before)];
        let mut prev = r.run.target_before;
        for (t, v) in &r.run.targets {
            if t - c > TO_MS {
                break;
            }
            stairs.push((t - c, prev));
            stairs.push((t - c, *v));
            prev = *v;
        }
        stairs.push((TO_MS, prev));
        series.push(Series {
            name: format!("+{:.1} km/h, target", p.increment_kmh),
            colour,
            points: stairs,
            dashed: true,
        });
    }
    super::svg::Chart {
        title: "Table 15: the slowest of five steps per increment".into(),
        x_label: "time since the travel speed changed, ms".into(),
        y_label: "drum speed r/min (true; dashed: target)".into(),
        x: (FROM_MS, TO_MS),
        y: (0.0, 50.0),
        x_ticks: super::svg::ticks(0.0, TO_MS, 100.0),
        y_ticks: super::svg::ticks(0.0, 50.0, 10.0),
        series,
        bars: Vec::new(),
        v_lines: vec![(0.0, "change".into())],
        h_lines: Vec::new(),
    }
}

/// Section 8 of the document; writes its plot into `img`.
#[allow(clippy::too_many_lines)]
pub fn section(doc: &mut String, img: &std::path::Path) -> Result {
    use std::fmt::Write as _;
    let t14 = table14()?;
    let t15 = table15()?;
    let _ = write!(
        doc,
        "\n## 8. Paper A Tables 14 and 15: drum speed accuracy and response time\n\n\
         What paper A measured (section 3.6). **Table 14** (\"Motor accuracy table\"): \"the \
         control board is used as the lower-level controller to drive the motor. The motor is \
         connected to a photoelectric encoder through coupling to detect the actual speed during \
         operation. […] Different control-speed programs are burned into the control board via \
         the laptop, and the encoder's feedback data are recorded and analyzed\"; \"within the \
         expected speed range of 5.21 r/min to 25.21 r/min, the absolute value of the control \
         error for the system's overall motor accuracy remains below 0.9%\". Each row gives the \
         desired speed, five measured speeds, their mean and a *relative error*, which is \
         |desired − mean| / desired computed from the mean rounded to 0.01 r/min ((5.21 − 5.17) \
         / 5.21 = 0.77 %). **Table 15** (\"Motor response time\"): \"With the base traveling \
         speed of the chassis of the transplanting equipment set at 0.30 km/h, the motor \
         response time of the system was tested using speed increments of 0.5, 1.0, 1.5, 2.0, \
         and 2.5 km/h. […] the response time is not greater than 54 milliseconds.\" Five \
         readings per increment and their maximum. The paper says neither from which instant \
         the response time is counted nor when it ends, nor how the increment was applied, nor \
         the plant spacing: the choices below are ours.\n\n\
         ### Table 14: drum speed accuracy (Fixed mode)\n\n\
         The product runs in **Fixed mode** at each of the paper's set speeds (`Settings::\
         fixed_drum_speed` 5.21 … 25.21 r/min, as entered on the screen): paper A burned \
         fixed control-speed programs into its board, a set drum speed, not a travel speed; \
         Speed-Adaptive mode would add the travel-speed measurement's own errors, which the \
         paper measures separately (Tables 11 and 12). Machine: `machine_sim` with its default \
         noise (`Config::default()`: the seedlings' load, up to 5 % droop as each partition \
         passes; 0.3 % speed ripple; the 25 ms lag, 5 ms dead time and 3 % dead band of the \
         drive), the tractor standing. Reading k (k = 0 … 4) of row i is its own run (seed \
         1400 + 10·i + k, `belt_initial_phase` k/5, so that the five readings meet the load at \
         five phases of a partition): the mean **true** drum speed (the model's shaft, the \
         counterpart of the paper's separate photoelectric encoder, not the product's own \
         estimate) over {reading_s} s from {settle_s} s after Start. Error as the paper's: \
         |set − mean of the five| / set (from the unrounded mean); worst reading: the largest \
         |set − reading| / set of the five.\n\n\
         | set drum speed r/min | paper A: readings r/min | paper A: mean, error | product: readings r/min | product: mean r/min | product: error | product: worst reading |\n\
         |---|---|---|---|---|---|---|\n",
        reading_s = ACCURACY_READING_MS / 1000,
        settle_s = ACCURACY_SETTLE_MS / 1000,
    );
    for (p, r) in PAPER_TABLE_14.iter().zip(&t14) {
        let _ = writeln!(
            doc,
            "| {:.2} | {} | {:.2}, {:.2} % | {} | {:.3} | **{:.3} %** | {:.2} % |",
            p.desired_rpm,
            join(p.readings.iter(), |v| format!("{v:.2}")),
            p.mean_rpm,
            p.rel_error_pct,
            join(r.readings.iter(), |v| format!("{v:.3}")),
            r.mean(),
            r.rel_error_pct(),
            r.worst_reading_pct()
        );
    }
    let hall = t15
        .first()
        .and_then(|r| r.first())
        .map_or(0.0, |r| r.run.hall_period_before_ms);
    let _ = write!(
        doc,
        "\n### Table 15: response to travel-speed steps (Speed-Adaptive mode)\n\n\
         The product runs in **Speed-Adaptive mode** (the paper: \"the system controls the \
         motor's operation based on the feedback of the traveling speed\"), spacing \
         {spacing} cm, gear preset Low 1, every other setting at its default (the calibration: \
         paper A's tables; the Speed-Adaptive control law: the product's default, speed \
         following when this section was written, as paper A's). Paper A \
         does not print the spacing; {spacing} cm is the smallest round spacing at which the \
         largest step (0.30 + 2.5 = 2.80 km/h) stays below the drum's 44.7 r/min (`cargo xtask \
         plan --spacing 25cm --speed 2.8km/h`: 40.9 r/min; at the paper's 18 cm the drum \
         saturates from 2.1 km/h, at 7 cm from 0.81 km/h). Machine: `machine_sim` without \
         random noise, terrain, tooth pitch errors or capture jitter (`Config::noiseless()`), \
         with the seedlings' load (5 % droop per partition): a bench run, so that the five \
         repeats differ only by where the step falls. The track rolls at 0.30 km/h (the \
         model's wheel speed; Table 12's slip applies on top) and the product is started; at \
         {at_s} s + k·{off} ms (k = 0 … 4: about a fifth of the Hall period at 0.30 km/h, measured \
         {hall:.0} ms in the runs, and not a multiple of 10 ms, so the five steps fall at five phases of the tooth \
         period and of the 10 ms control period) the wheel speed **jumps** to 0.30 + increment: \
         `machine_sim`'s chassis has no lag by default (`track_tau_s` 0) and the paper does not \
         say how its increments were applied; an instantaneous step is the hardest case for a \
         Hall-based speed. Each run goes on {win_s} s after the step; the true drum speed is \
         sampled every 1 ms.\n\n\
         Criteria (ours): **t90**, the time until the drum speed first reaches 90 % of the way \
         from its speed at the change to the product's new target (the target's mean over the \
         run's last 0.5 s); **settle**, the time until the drum speed is within ±2 % of the new \
         target and stays there to the end of the run. Each is counted from three instants: \
         **(a)** the physical change of the travel speed; **(b)** the first Hall edge at or \
         after the change, the earliest moment the firmware can know of it; **(c)** the first \
         control step at which the product's drum target has made 90 % of its change: the \
         drum loop alone, what a bench that steps the speed *command* measures. Bold: the \
         maximum of the five, as the paper's last column.\n\n\
         | increment km/h | paper A: readings ms (max) | product t90 (a) from the change, ms | (b) from the first Hall edge, ms | (c) from the target's change, ms |\n\
         |---|---|---|---|---|\n",
        spacing = STEP_SPACING_MM / 10,
        at_s = STEP_AT_MS / 1000,
        off = STEP_OFFSET_MS,
        win_s = STEP_WINDOW_MS / 1000,
    );
    for (p, reps) in PAPER_TABLE_15.iter().zip(&t15) {
        let _ = writeln!(
            doc,
            "| +{:.1} | {} (**{}**) | {} | {} | {} |",
            p.increment_kmh,
            join(p.readings_ms.iter(), u32::to_string),
            p.max_ms,
            five(reps, &|r| r.from_change.rise_ms),
            five(reps, &|r| r.from_edge.rise_ms),
            five(reps, &|r| r.from_target.rise_ms),
        );
    }
    let _ = write!(
        doc,
        "\nThe same runs, further figures (per repeat k = 0 … 4 where listed, else the maximum \
         of the five):\n\n\
         | increment km/h | travel speed km/h | product's drum target r/min (highest on the way) | first Hall edge after the change, ms | Hall edges after the change: accepted / produced (3 s) | target made 90 % of its change, ms after the change | settle ±2 % (a) / (b) / (c), ms (max) |\n\
         |---|---|---|---|---|---|---|\n"
    );
    for (p, reps) in PAPER_TABLE_15.iter().zip(&t15) {
        let (tb, ta) = reps
            .first()
            .map_or((0.0, 0.0), |r| (r.run.target_before, r.run.target_after));
        let max = |f: &dyn Fn(&StepResult) -> Option<f64>| opt_ms(max_opt(reps.iter().map(f)));
        let _ = writeln!(
            doc,
            "| +{:.1} | {PAPER_BASE_KMH:.2} → {:.2} | {tb:.2} → {ta:.2} ({:.2}) | {} | {} | {} | {} / {} / {} |",
            p.increment_kmh,
            PAPER_BASE_KMH + p.increment_kmh,
            peak_target(reps),
            join(reps.iter(), |r| opt_ms(
                r.run.first_edge_ms.map(|e| e - r.run.change_ms)
            )),
            join(reps.iter(), |r| format!(
                "{}/{}",
                r.run.edges_accepted, r.run.edges_after
            )),
            join(reps.iter(), |r| opt_ms(r.target_moved_ms)),
            max(&|r| r.from_change.settle_ms),
            max(&|r| r.from_edge.settle_ms),
            max(&|r| r.from_target.settle_ms),
        );
    }
    super::write_file(&img.join("tables-step.svg"), &step_plot(&t15).render())?;
    doc.push_str("\n![Table 15 steps](img/tables-step.svg)\n");
    // Reading, from the figures above.
    let worst14 = t14
        .iter()
        .map(AccuracyRow::rel_error_pct)
        .fold(0.0, f64::max);
    let best14 = t14
        .iter()
        .map(AccuracyRow::rel_error_pct)
        .fold(f64::MAX, f64::min);
    let worst_reading = t14
        .iter()
        .map(AccuracyRow::worst_reading_pct)
        .fold(0.0, f64::max);
    let fast = t14.iter().filter(|r| r.mean() > r.desired_rpm).count();
    let (a_lo, a_hi) = range(&t15, &|r| r.from_change.rise_ms);
    let (b_lo, b_hi) = range(&t15, &|r| r.from_edge.rise_ms);
    let (c_lo, c_hi) = range(&t15, &|r| r.from_target.rise_ms);
    let (e_lo, e_hi) = range(&t15, &|r| r.run.first_edge_ms.map(|e| e - r.run.change_ms));
    let (m_lo, m_hi) = range(&t15, &|r| r.target_moved_ms);
    let dropped: Vec<String> = PAPER_TABLE_15
        .iter()
        .zip(&t15)
        .filter_map(|(p, reps)| {
            let d: u32 = reps
                .iter()
                .map(|r| r.run.edges_after.saturating_sub(r.run.edges_accepted))
                .sum();
            (d > 0).then(|| format!("+{:.1} km/h: {d}", p.increment_kmh))
        })
        .collect();
    let paper_max = PAPER_TABLE_15.iter().map(|p| p.max_ms).max().unwrap_or(0);
    let stop_and_go = STOP_AND_GO_TAUS
        .iter()
        .map(|tau| {
            stop_and_go_edges(*tau)
                .map(|(p, a)| format!("τ {tau} s: {} of {p} dropped", p.saturating_sub(a)))
        })
        .collect::<Result<Vec<_>>>()?
        .join("; ");
    let _ = write!(
        doc,
        "\nReading. **Table 14**: the product's error of the mean is {best14:.3} … \
         {worst14:.3} % over 5.21 … 25.21 r/min, {} paper A's 0.87 %; the worst single 1 s \
         reading is {worst_reading:.2} % off. {fast} of 5 means lie above the set speed{}; the spread between the readings is the seedlings' load, which a 1 s window \
         at a few r/min does not average out (a partition passes every 0.5–2.6 s). The model's \
         drive has no error source beyond its dead band, lag and load, and the true speed is \
         read without an encoder coupling's error: the margin shows that the control adds \
         next to nothing to paper A's error, not that the real machine would measure \
         {worst14:.2} %.\n\n\
         **Table 15**: counted from the physical change (a) the drum needs {a_lo:.0} … \
         {a_hi:.0} ms to make 90 % of the change, against paper A's ≤ {paper_max} ms. Most of \
         that is the Hall sensor, not the drum: at 0.30 km/h a tooth passes every {hall:.0} ms, \
         so the first edge comes {e_lo:.0} … {e_hi:.0} ms after the change (the rest of the \
         tooth at the new speed); that edge closes a gap that was mostly run at the old speed \
         (the M/T window is the time since the previous edge), so the target moves only a \
         little; the next edge measures the new speed, and the target makes 90 % of its change \
         {m_lo:.0} … {m_hi:.0} ms after the change. {} Counted from the first Hall edge (b), \
         which removes the wait the firmware cannot shorten, t90 is {b_lo:.0} … {b_hi:.0} ms. \
         The drum loop alone (c), from the control step whose target has moved, needs \
         {c_lo:.0} … {c_hi:.0} ms: the drive's 5 ms dead time and 25 ms lag (90 % of a \
         first-order step takes 2.3 τ = 58 ms after the dead time; the feed-forward jumps at \
         once, the PID adds little). It is shorter here because the speed predictor (which \
         extrapolates the Hall speed along its last slope, bounded to ±10 %) sets the first \
         targets above the new one (the highest target column), which drives the drum faster \
         at first; the shortest are runs where the first edge had already moved the target most \
         of the way, so the drum was under way before the reference instant. That is the \
         same order as paper A's 47 … 54 ms. Paper A's figures barely depend on \
         the increment and stay far below one Hall period at 0.30 km/h ({hall:.0} ms), so they \
         cannot include the wait for the sensor: they are most likely counted from the moment \
         the board's speed value changed, i.e. comparable with (c), not (a).\n\n",
        if worst14 <= 0.87 {
            "within"
        } else {
            "**over**"
        },
        if fast >= 4 {
            " (the drum PID holds the drum slightly fast; ≈ 0.1 % with a perfect \
             speed signal)"
        } else {
            ""
        },
        if dropped.is_empty() {
            "No Hall edge was dropped.".to_string()
        } else {
            format!(
                "For the larger steps the estimator also **drops edges as glitches** (an edge \
                 closer than ¼ of the last gap is a glitch, `EstimatorSettings::glitch_shift` 2; \
                 a jump of more than 4× within one gap trips it), which delays the target by a few \
                 further teeth at the new speed (edges dropped in the five runs: {}). To trip \
                 the filter a real chassis would have to quadruple its speed within one tooth \
                 period, from 0.30 km/h an acceleration of at least {accel:.2} m/s² held for \
                 {hall:.0} ms. Here it comes from the instantaneous step, but the same rule \
                 drops real edges in a plainer case: after a stop shorter than the estimator's \
                 1.5 s timeout the gap that spans the stop becomes the reference, and the first \
                 full-speed gap after it is shorter than a quarter of it when the chassis pulls \
                 away briskly. Measured on the model (Low 2, 1 s stops every 10 s, 60 s, default \
                 noise, chassis lag τ): {stop_and_go}. Each dropped edge is a Hall pitch the \
                 estimator does not see: the two gaps around it read as one, at half the speed, \
                 and a ground distance counted from edges comes out a pitch (≈ 25 mm) short: a \
                 limit of the estimator that matters for the distance-locked mode above all.",
                dropped.join("; "),
                accel = 3.0 * PAPER_BASE_KMH / 3.6 / (hall / 1000.0).max(1e-3)
            )
        }
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn response_on_a_synthetic_first_order_step() {
        // A 1 ms trace: 10 r/min until t = 100 ms, then a first-order rise to
        // 20 r/min with τ = 20 ms starting 5 ms late (dead time).
        let samples: Vec<(f64, f64)> = (0..400)
            .map(|i| {
                let t = f64::from(i);
                let v = if t <= 105.0 {
                    10.0
                } else {
                    20.0 - 10.0 * (-(t - 105.0) / 20.0).exp()
                };
                (t, v)
            })
            .collect();
        // Hand computation. Rise to 90 %: 1 − e^(−x/20) ≥ 0.9 ⇔ x ≥ 20·ln 10
        // = 46.05 ms → first 1 ms sample at t = 105 + 47 = 152 → 52 ms from
        // the step at 100 ms, 32 ms from a reference at 120 ms.
        // Settle into ±2 % of 20 (0.4 r/min): 10·e^(−x/20) ≤ 0.4 ⇔ x ≥
        // 20·ln 25 = 64.38 ms → first sample t = 105 + 65 = 170 → 70 ms.
        let r = response(&samples, 100.0, 10.0, 20.0, 0.9, 0.02);
        assert_eq!(r.rise_ms, Some(52.0));
        assert_eq!(r.settle_ms, Some(70.0));
        let r = response(&samples, 120.0, 10.0, 20.0, 0.9, 0.02);
        assert_eq!(r.rise_ms, Some(32.0));
        assert_eq!(r.settle_ms, Some(50.0));
        // A record that ends outside the band has not settled.
        let short = samples.get(..150).unwrap_or(&[]);
        assert_eq!(
            response(short, 100.0, 10.0, 20.0, 0.9, 0.02).settle_ms,
            None
        );
        // A downward step is measured the same way: mirror the trace.
        let down: Vec<(f64, f64)> = samples.iter().map(|(t, v)| (*t, 30.0 - v)).collect();
        let r = response(&down, 100.0, 20.0, 10.0, 0.9, 0.02);
        assert_eq!(r.rise_ms, Some(52.0));
        // Band ±2 % of 10 is ±0.2: 10·e^(−x/20) ≤ 0.2 ⇔ x ≥ 20·ln 50 = 78.24
        // → t = 105 + 79 = 184 → 84 ms.
        assert_eq!(r.settle_ms, Some(84.0));
    }

    #[test]
    fn paper_tables_transcribed_consistently() {
        // Each row of paper A Table 14: the five readings average to the
        // printed mean (to its 2 decimals), and the printed error is
        // |desired − printed mean| / desired (the paper divides by the
        // rounded mean: row 5.21 gives 0.77 %, not the 0.69 % of 5.174).
        for p in &PAPER_TABLE_14 {
            let mean = p.readings.iter().sum::<f64>() / 5.0;
            assert!(
                (mean - p.mean_rpm).abs() <= 0.005,
                "{} {mean}",
                p.desired_rpm
            );
            let e = relative_error_pct(p.desired_rpm, &[p.mean_rpm]);
            assert!(
                (e - p.rel_error_pct).abs() <= 0.005,
                "{} {e}",
                p.desired_rpm
            );
        }
        // Table 15: the printed maximum is the largest of the five.
        for p in &PAPER_TABLE_15 {
            assert_eq!(p.readings_ms.iter().max(), Some(&p.max_ms));
        }
    }

    #[test]
    fn product_table_14_within_the_papers_accuracy() {
        // Paper A Table 14: the relative error of the mean of five readings
        // is at most 0.87 % (row 25.21 r/min) over 5.21 … 25.21 r/min. The
        // product, run as in `cargo xtask bench` (Fixed mode, default noisy
        // machine, true drum speed), must do at least as well at every row.
        // About 0.1 s of host time (25 runs of 5 s of machine time).
        let rows = table14().expect("Table 14 runs");
        assert_eq!(rows.len(), PAPER_TABLE_14.len());
        for r in &rows {
            let e = r.rel_error_pct();
            assert!(
                e <= 0.87,
                "{} r/min: {e:.3} % (readings {:?})",
                r.desired_rpm,
                r.readings
            );
        }
    }

    #[test]
    fn product_table_15_drum_loop_and_causality() {
        // Table 15 as `cargo xtask bench` runs it (25 steps, about 0.1 s of
        // host time). Independent reference for (c): once the target has
        // moved, the drum is a first-order drive with the model's 5 ms dead
        // time and τ = 25 ms (`Config::default()`), so 90 % of a step takes
        // 5 + 25·ln 10 = 62.6 ms, plus at most one 10 ms control period
        // before the new duty is applied: 72.6 ms. A product whose drum
        // loop only followed through the PID (no feed-forward) would be far
        // slower. Causality: the drum cannot make 90 % of the change before
        // the first Hall edge tells the firmware of it.
        let bound = 5.0 + 25.0 * 10f64.ln() + 10.0;
        for (p, reps) in PAPER_TABLE_15.iter().zip(table15().expect("Table 15 runs")) {
            for (k, r) in reps.iter().enumerate() {
                let c = r.from_target.rise_ms.expect("rises after the target moved");
                assert!(c <= bound, "+{} k {k}: (c) t90 {c} ms", p.increment_kmh);
                let a = r.from_change.rise_ms.expect("rises");
                let edge = r.run.first_edge_ms.expect("an edge") - r.run.change_ms;
                assert!(
                    a >= edge,
                    "+{} k {k}: t90 {a} ms before the edge at {edge}",
                    p.increment_kmh
                );
            }
        }
    }
}
