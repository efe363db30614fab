//! The run report: one self-contained HTML file with inline SVG charts
//! (no scripts, fonts or anything fetched), built from a decoded defmt log.
//!
//! Two sources, one report:
//!
//! - `cargo xtask qemu` writes the QEMU run's log and its report at the end
//!   of the main job. Its log holds the firmware's own lines and the
//!   simulated machine's truth (`sim:` lines, ten a second, and one
//!   `sim: plant N at P um` per plant with `plant_log=1`), so the report
//!   shows true and estimated travel speed, the spacing of every plant and
//!   the ISO 7256-1 indices.
//! - `cargo xtask report FILE` reads a field capture (what `probe-rs run`
//!   prints: `<time> INFO  status: …` and `└─ module @ file:line` lines) and
//!   draws the same report from the firmware's lines alone: the 1 Hz
//!   `status:` summary, alarms, state changes and the operator's screen
//!   commands. A real machine logs counts, not plant positions, so the
//!   spacing shown is the firmware's mean (distance / plants) over its last
//!   ten or more plants, and the ISO indices are left out.
//!
//! The reader tolerates what a capture does: lines it does not know, the
//! probe's location lines and colour codes, a dropped RTT frame (a missing
//! status line is counted and breaks the lines of the charts), a truncated
//! line (the fields before the cut are used, a number cut short is not), a
//! capture that starts mid-run, and a reset (time going backwards: the time
//! axis continues and the reboot is marked).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use machine_sim::{FieldMetrics, SpacingAccumulator};

use crate::bench::svg::{self, esc, Bars, Chart, Series, PALETTE};
use crate::Result;

/// What an event on the time axis is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// The operator: screen commands, alarm acknowledgements.
    Operator,
    /// The firmware's state: drum running or stopped, boot, screen link.
    State,
    /// Alarms, the stop input, faults.
    Alarm,
    /// A disturbance the simulator injected (QEMU runs only).
    Simulator,
}

impl Kind {
    const ALL: [Kind; 4] = [Kind::Operator, Kind::State, Kind::Alarm, Kind::Simulator];

    fn name(self) -> &'static str {
        match self {
            Kind::Operator => "operator",
            Kind::State => "state",
            Kind::Alarm => "alarm",
            Kind::Simulator => "simulator",
        }
    }

    fn colour(self) -> &'static str {
        match self {
            Kind::Operator => PALETTE[0],
            Kind::State => PALETTE[2],
            Kind::Alarm => PALETTE[1],
            Kind::Simulator => PALETTE[4],
        }
    }
}

/// An event on the time axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Time, s (firmware time; continued across a reset).
    pub t_s: f64,
    /// What it is.
    pub kind: Kind,
    /// The log's text.
    pub text: String,
}

/// One `status:` line (1 Hz). Each field is `None` when the line was cut
/// before it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Status {
    /// Time, s.
    pub t_s: f64,
    /// Mode, as logged (`SpeedAdaptive`, `Fixed`).
    pub mode: Option<String>,
    /// Drum running.
    pub running: Option<bool>,
    /// The spacing setting X, mm.
    pub spacing_mm: Option<f64>,
    /// Estimated travel speed, km/h.
    pub travel_kmh: Option<f64>,
    /// Target drum speed, r/min.
    pub target_rpm: Option<f64>,
    /// Measured drum speed, r/min.
    pub actual_rpm: Option<f64>,
    /// PWM compare value.
    pub ccr: Option<f64>,
    /// Plants since Start (belt partitions counted by the firmware).
    pub plants: Option<f64>,
    /// Distance since Start, m.
    pub distance_m: Option<f64>,
    /// Alarm, as logged (`None`, `Some(DrumStall)`).
    pub alarm: Option<String>,
    /// Control-period overruns since boot.
    pub overruns: Option<f64>,
}

impl Status {
    fn complete(&self) -> bool {
        self.mode.is_some()
            && self.running.is_some()
            && self.spacing_mm.is_some()
            && self.travel_kmh.is_some()
            && self.target_rpm.is_some()
            && self.actual_rpm.is_some()
            && self.ccr.is_some()
            && self.plants.is_some()
            && self.distance_m.is_some()
            && self.alarm.is_some()
            && self.overruns.is_some()
    }
}

/// One `sim:` truth line of the QEMU board (10 Hz).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimPoint {
    /// Time, s.
    pub t_s: f64,
    /// True travel (ground) speed, km/h.
    pub travel_kmh: f64,
    /// True drum speed, r/min.
    pub drum_rpm: f64,
    /// The firmware's target drum speed, r/min.
    pub target_rpm: f64,
    /// The compare value applied.
    pub ccr: f64,
    /// Plants dropped since boot.
    pub plants: f64,
    /// Ground position, m.
    pub ground_m: f64,
}

/// One plant of the simulated machine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plant {
    /// Time of the log line, s.
    pub t_s: f64,
    /// Its number since boot (1, 2, …).
    pub n: u32,
    /// Ground position, m.
    pub ground_m: f64,
}

/// Everything read from a log.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Run {
    /// The 1 Hz status lines.
    pub status: Vec<Status>,
    /// The simulator's truth (empty for a field capture).
    pub sim: Vec<SimPoint>,
    /// The simulator's plants (empty for a field capture).
    pub plants: Vec<Plant>,
    /// Alarms, state changes, operator actions, disturbances.
    pub events: Vec<Event>,
    /// The last `screen: SetSpacing(Spacing(N))`, mm (before the first status line).
    pub spacing_cmd_mm: Option<f64>,
    /// Log lines read (location lines not counted).
    pub lines: usize,
    /// Lines that are not decoded defmt lines (the probe's own output, a
    /// decoder complaint, garbage): ignored.
    pub unknown: usize,
    /// The firmware's lines the report does not use (settings, stack, …).
    pub other: usize,
    /// Status lines cut short.
    pub truncated: usize,
    /// Status lines missing (a gap of more than 1.5 periods).
    pub dropped: usize,
    /// Resets seen (time going backwards).
    pub reboots: usize,
}

impl Run {
    /// The run as a real board's capture would show it: the simulator's
    /// lines (truth, plants, disturbances) left out. `cargo xtask report`
    /// always reads a log this way.
    #[must_use]
    pub fn firmware_only(mut self) -> Run {
        let sim_lines = self.sim.len()
            + self.plants.len()
            + self
                .events
                .iter()
                .filter(|e| e.kind == Kind::Simulator)
                .count();
        self.sim.clear();
        self.plants.clear();
        self.events.retain(|e| e.kind != Kind::Simulator);
        self.other += sim_lines;
        self
    }
}

/// Removes ANSI colour sequences (`ESC [ … letter`).
fn strip_ansi(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            if chars.peek() == Some(&'[') {
                chars.next();
                for c in chars.by_ref() {
                    if c.is_ascii_alphabetic() {
                        break;
                    }
                }
            }
            continue;
        }
        out.push(c);
    }
    out
}

const LEVELS: [&str; 5] = ["TRACE", "DEBUG", "INFO", "WARN", "ERROR"];

/// Splits a decoded defmt line into time (s) and message. Accepts
/// `0.123 INFO  msg`, `0.123 [INFO ] msg`, `[0.123] INFO msg`.
fn split_line(line: &str) -> Option<(f64, &str)> {
    let line = line.trim();
    let (time, rest) = line.split_once(char::is_whitespace)?;
    let t: f64 = time
        .trim_matches(|c| c == '[' || c == ']')
        .trim_end_matches('s')
        .parse()
        .ok()?;
    if !(t.is_finite() && t >= 0.0) {
        return None;
    }
    let rest = rest.trim_start();
    let (level, msg) = if let Some(bracketed) = rest.strip_prefix('[') {
        let (level, msg) = bracketed.split_once(']')?;
        (level.trim(), msg)
    } else {
        rest.split_once(char::is_whitespace).unwrap_or((rest, ""))
    };
    LEVELS.contains(&level).then(|| (t, msg.trim()))
}

/// The whole number after `key`, only when something follows it (a number
/// at the very end of a truncated line may be cut short).
fn number_after(text: &str, key: &str) -> Option<f64> {
    let rest = text.split_once(key)?.1;
    let digits = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter(|&end| end > 0)?;
    rest.get(..digits)?.parse().ok()
}

fn parse_status(t_s: f64, msg: &str) -> Status {
    let mut s = Status {
        t_s,
        ..Status::default()
    };
    // "uptime 1009 ms, SpeedAdaptive Running, spacing 70 mm, …"
    if let Some((_, after)) = msg.split_once(" ms, ") {
        if let Some((state, _)) = after.split_once(',') {
            let mut words = state.split_whitespace();
            if let (Some(mode), Some(run)) = (words.next(), words.next()) {
                s.mode = Some(mode.to_string());
                s.running = match run {
                    "Running" => Some(true),
                    "Stopped" => Some(false),
                    _ => None,
                };
            }
        }
    }
    s.spacing_mm = number_after(msg, "spacing ");
    s.travel_kmh = number_after(msg, "travel ").map(|v| v / 1000.0);
    s.target_rpm = number_after(msg, "drum target ").map(|v| v / 1000.0);
    s.actual_rpm = number_after(msg, " actual ").map(|v| v / 1000.0);
    s.ccr = number_after(msg, "ccr ");
    s.plants = number_after(msg, "plants ");
    s.distance_m = number_after(msg, "distance ").map(|v| v / 1000.0);
    s.alarm = msg
        .split_once("alarm ")
        .and_then(|(_, rest)| rest.split_once(", loops "))
        .map(|(alarm, _)| alarm.to_string());
    s.overruns = number_after(msg, "(overruns ");
    s
}

fn parse_sim(t_s: f64, msg: &str) -> Option<SimPoint> {
    Some(SimPoint {
        t_s,
        // µm/s → km/h
        travel_kmh: number_after(msg, "sim: ground ")? * 3.6e-6,
        drum_rpm: number_after(msg, "drum ")? / 1000.0,
        target_rpm: number_after(msg, "target ")? / 1000.0,
        ccr: number_after(msg, "ccr ")?,
        plants: number_after(msg, "plants ")?,
        ground_m: number_after(msg, "ground position ")? / 1000.0,
    })
}

fn classify(msg: &str) -> Option<Kind> {
    const TABLE: [(&str, Kind); 16] = [
        ("screen message: ", Kind::State),
        ("screen error", Kind::State),
        ("screen reply timeout", Kind::State),
        ("screen: ", Kind::Operator),
        ("alarm acknowledged", Kind::Operator),
        ("alarm", Kind::Alarm),
        ("stop input", Kind::Alarm),
        ("planter: ", Kind::State),
        ("drum: ", Kind::State),
        ("boot: ", Kind::State),
        ("touchscreen", Kind::State),
        ("settings: saved", Kind::Operator),
        ("settings: save failed", Kind::Alarm),
        ("panic", Kind::Alarm),
        ("HardFault", Kind::Alarm),
        ("sim: ", Kind::Simulator),
    ];
    TABLE
        .iter()
        .find(|(prefix, _)| msg.starts_with(prefix))
        .map(|&(_, kind)| kind)
}

/// Reads a decoded defmt log (a QEMU run's or a `probe-rs run` capture).
pub fn parse(text: &str) -> Run {
    let mut run = Run::default();
    let mut offset = 0.0;
    let mut last_t: Option<f64> = None;
    for raw in text.lines() {
        let line = strip_ansi(raw);
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('└') {
            continue;
        }
        run.lines += 1;
        let Some((t, msg)) = split_line(trimmed) else {
            run.unknown += 1;
            continue;
        };
        if last_t.is_some_and(|last| t + offset < last - 1.0) {
            // Time went backwards: the board was reset (watchdog, power).
            offset = last_t.unwrap_or(0.0);
            run.reboots += 1;
            run.events.push(Event {
                t_s: offset,
                kind: Kind::Alarm,
                text: "reset: firmware time restarts".into(),
            });
        }
        let t_s = t + offset;
        last_t = Some(t_s);
        if msg.starts_with("status: uptime ") {
            // Profile A's summary: it has a drum.
            if msg.contains("drum target") || !msg.contains("profile B") {
                let status = parse_status(t_s, msg);
                if !status.complete() {
                    run.truncated += 1;
                }
                run.status.push(status);
            } else {
                run.other += 1;
            }
        } else if msg.starts_with("sim: ground ") {
            match parse_sim(t_s, msg) {
                Some(p) => run.sim.push(p),
                None => run.unknown += 1,
            }
        } else if let Some(rest) = msg.strip_prefix("sim: plant ") {
            let n = number_after(rest, "");
            let um = number_after(rest, " at ");
            match (n, um) {
                (Some(n), Some(um)) => run.plants.push(Plant {
                    t_s,
                    n: n as u32,
                    ground_m: um / 1e6,
                }),
                _ => run.unknown += 1,
            }
        } else if let Some(kind) = classify(msg) {
            if let Some(mm) = msg
                .strip_prefix("screen: SetSpacing(Spacing(")
                .and_then(|r| r.strip_suffix("))"))
                .and_then(|v| v.parse().ok())
            {
                run.spacing_cmd_mm = Some(mm);
            }
            run.events.push(Event {
                t_s,
                kind,
                text: msg.to_string(),
            });
        } else {
            run.other += 1;
        }
    }
    // Dropped status lines: the summary comes once a second.
    run.dropped = run
        .status
        .windows(2)
        .map(|w| match w {
            [a, b] => {
                let gap = b.t_s - a.t_s;
                if gap > 1.5 {
                    (gap - 0.5).floor() as usize
                } else {
                    0
                }
            }
            _ => 0,
        })
        .sum();
    run
}

/// The spacing analysis of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct Spacing {
    /// The spacing setting X, m.
    pub target_m: f64,
    /// Where X came from.
    pub target_source: &'static str,
    /// Each plant's spacing to the one before, `(time s, spacing m)`
    /// (simulator only).
    pub per_plant: Vec<(f64, f64)>,
    /// ISO 7256-1 and the other field metrics of `per_plant`.
    pub metrics: Option<FieldMetrics>,
    /// The firmware's mean spacing over the last ≥ 10 plants it counted,
    /// at each status line, `(time s, m)`.
    pub per_interval: Vec<(f64, f64)>,
    /// Plants and distance the firmware counted while running.
    pub firmware_plants: f64,
    /// Metres.
    pub firmware_distance_m: f64,
}

impl Spacing {
    /// The firmware's count error: `(plants − L/X) / (L/X)`, percent.
    pub fn firmware_count_error_pct(&self) -> Option<f64> {
        let theoretical = self.firmware_distance_m / self.target_m;
        (theoretical > 0.0).then(|| 100.0 * (self.firmware_plants - theoretical) / theoretical)
    }
}

/// The spacing setting, the per-plant spacings and their metrics, and the
/// firmware's interval estimates.
pub fn spacing(run: &Run) -> Spacing {
    let from_status = run
        .status
        .iter()
        .rev()
        .find(|s| s.running == Some(true) && s.spacing_mm.is_some())
        .or_else(|| run.status.iter().rev().find(|s| s.spacing_mm.is_some()))
        .and_then(|s| s.spacing_mm);
    let (target_mm, target_source) = match (from_status, run.spacing_cmd_mm) {
        (Some(mm), _) => (mm, "status lines"),
        (None, Some(mm)) => (mm, "the operator's SetSpacing"),
        (None, None) => (70.0, "not in the log: the default 70 mm assumed"),
    };
    let target_m = target_mm / 1000.0;
    let mut per_plant = Vec::new();
    for w in run.plants.windows(2) {
        if let [a, b] = w {
            // Consecutive numbers only: a lost line would merge two spacings.
            if b.n == a.n.wrapping_add(1) {
                per_plant.push((b.t_s, b.ground_m - a.ground_m));
            }
        }
    }
    let tolerance = f64::from(machine_sim::Config::default().qualified_tolerance);
    let metrics = (!run.plants.is_empty())
        .then(|| SpacingAccumulator::new(target_m, tolerance).ok())
        .flatten()
        .map(|mut acc| {
            // The theoretical count L/X runs over the ground travelled from
            // the drum's start (the first Running) to the end of the log.
            let start_t = run
                .events
                .iter()
                .find(|e| e.text == "drum: Running")
                .map_or(0.0, |e| e.t_s);
            let start_m = run
                .sim
                .iter()
                .find(|p| p.t_s >= start_t)
                .or(run.sim.first())
                .map_or(0.0, |p| p.ground_m);
            let end_m = run.sim.last().map_or(0.0, |p| p.ground_m);
            acc.reset(start_m);
            // The plants as a chain of the spacings kept above (a lost
            // line's merged spacing is left out rather than counted as a miss).
            let mut pos = run.plants.first().map_or(0.0, |p| p.ground_m);
            acc.push_plant(pos);
            for &(_, s) in &per_plant {
                pos += s;
                acc.push_plant(pos);
            }
            acc.metrics(end_m)
        });
    // The firmware counts whole plants: one second holds about two, so a
    // one-second mean would be off by up to half a spacing from the drop
    // phase alone. The mean is taken over the shortest run of status
    // intervals (back from each line, while the drum runs) holding at least
    // WINDOW_PLANTS plants: at most 1/10 off from that.
    const WINDOW_PLANTS: f64 = 10.0;
    let mut per_interval = Vec::new();
    let (mut plants, mut distance) = (0.0, 0.0);
    // The valid intervals since the last break, (plants, metres).
    let mut segment: Vec<(f64, f64)> = Vec::new();
    for w in run.status.windows(2) {
        let [a, b] = w else { continue };
        let counts = (a.plants, b.plants, a.distance_m, b.distance_m);
        let (Some(p0), Some(p1), Some(d0), Some(d1)) = counts else {
            segment.clear();
            continue;
        };
        let (dp, dd) = (p1 - p0, d1 - d0);
        if a.running != Some(true) || b.running != Some(true) || dp < 0.0 || dd < 0.0 {
            // Stopped, or a new Start reset the counts.
            segment.clear();
            continue;
        }
        plants += dp;
        distance += dd;
        segment.push((dp, dd));
        let (mut wp, mut wd) = (0.0, 0.0);
        for &(p, d) in segment.iter().rev() {
            wp += p;
            wd += d;
            if wp >= WINDOW_PLANTS {
                per_interval.push((b.t_s, wd / wp));
                break;
            }
        }
    }
    Spacing {
        target_m,
        target_source,
        per_plant,
        metrics,
        per_interval,
        firmware_plants: plants,
        firmware_distance_m: distance,
    }
}

/// Names of the series, as they appear in the legends and in the
/// `data-series` attributes (the tests look for them).
pub mod names {
    /// The simulator's ground speed.
    pub const TRAVEL_TRUE: &str = "travel, true (sim)";
    /// The firmware's corrected travel speed.
    pub const TRAVEL_EST: &str = "travel, estimated (fw)";
    /// The firmware's target drum speed.
    pub const DRUM_TARGET: &str = "drum target (fw)";
    /// The simulator's drum speed.
    pub const DRUM_TRUE: &str = "drum, true (sim)";
    /// The firmware's measured drum speed.
    pub const DRUM_MEASURED: &str = "drum, measured (fw)";
    /// The compare value applied, from the simulator's 10 Hz lines.
    pub const CCR_APPLIED: &str = "CCR applied (10 Hz)";
    /// The compare value of the status lines.
    pub const CCR_STATUS: &str = "CCR in status (1 Hz)";
    /// Plants on the ground (simulator).
    pub const PLANTS_TRUE: &str = "plants, true (sim)";
    /// Plants the firmware counted since Start.
    pub const PLANTS_FW: &str = "plants counted (fw)";
    /// Each plant's spacing (simulator).
    pub const SPACING_PLANT: &str = "each plant (sim)";
    /// The firmware's mean spacing over its last ≥ 10 plants.
    pub const SPACING_INTERVAL: &str = "mean of ≥ 10 plants (fw)";
    /// Histogram of each plant's spacing.
    pub const HIST_PLANT: &str = "plant spacings (sim)";
    /// Histogram of the firmware's ≥ 10-plant means.
    pub const HIST_INTERVAL: &str = "means of ≥ 10 (fw)";
}

/// A tick step giving at most `max` ticks over `span`.
fn nice_step(span: f64, max: f64) -> f64 {
    let span = if span > 0.0 { span } else { 1.0 };
    let mut step = 10f64.powf((span / max).log10().floor());
    for m in [1.0, 2.0, 5.0, 10.0] {
        if span / (step * m) <= max {
            return step * m;
        }
    }
    step *= 10.0;
    step
}

/// An axis from 0 (or the data's minimum if below) to a round value above
/// the data's maximum.
fn y_axis(values: impl Iterator<Item = f64>) -> ((f64, f64), Vec<f64>) {
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if hi <= lo {
        hi = lo + 1.0;
    }
    let step = nice_step((hi - lo) * 1.1, 6.0);
    let lo = (lo / step).floor() * step;
    let hi = ((hi * 1.1) / step).ceil() * step;
    ((lo, hi), svg::ticks(lo, hi, step))
}

/// Status-line values as a series, broken (NaN) where a line is missing.
fn status_points(run: &Run, field: impl Fn(&Status) -> Option<f64>) -> Vec<(f64, f64)> {
    let mut points = Vec::new();
    let mut last_t: Option<f64> = None;
    for s in &run.status {
        if last_t.is_some_and(|t| s.t_s - t > 1.5) {
            points.push((s.t_s, f64::NAN));
        }
        last_t = Some(s.t_s);
        if let Some(v) = field(s) {
            points.push((s.t_s, v));
        }
    }
    points
}

fn series(name: &str, colour: &'static str, points: Vec<(f64, f64)>, dashed: bool) -> Series {
    Series {
        name: name.to_string(),
        colour,
        points,
        dashed,
    }
}

/// The time span of everything in the run.
fn time_span(run: &Run) -> (f64, f64) {
    let times = run
        .status
        .iter()
        .map(|s| s.t_s)
        .chain(run.sim.iter().map(|p| p.t_s))
        .chain(run.events.iter().map(|e| e.t_s));
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for t in times {
        lo = lo.min(t);
        hi = hi.max(t);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let step = nice_step(hi - lo, 10.0);
    // A run that ends a few ms past a round time (20.015 s) ends the axis there.
    let lo = (lo / step + 0.01).floor() * step;
    let hi = (hi / step - 0.01).ceil() * step;
    (lo, if hi > lo { hi } else { lo + step })
}

fn time_chart(
    run: &Run,
    title: &str,
    y_label: &str,
    series: Vec<Series>,
    h_lines: Vec<(f64, String)>,
) -> Chart {
    let (t0, t1) = time_span(run);
    let (y, y_ticks) = y_axis(
        series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.1))
            .chain(h_lines.iter().map(|h| h.0)),
    );
    // Alarms and state changes as dashed lines, numbered as in the event table.
    let v_lines = run
        .events
        .iter()
        .enumerate()
        .filter(|(_, e)| matches!(e.kind, Kind::Alarm | Kind::Simulator))
        .map(|(i, e)| (e.t_s, format!("{}", i + 1)))
        .collect();
    Chart {
        title: title.to_string(),
        x_label: "time, s".into(),
        y_label: y_label.to_string(),
        x: (t0, t1),
        y,
        x_ticks: svg::ticks(t0, t1, nice_step(t1 - t0, 10.0)),
        y_ticks,
        series,
        bars: Vec::new(),
        v_lines,
        h_lines,
    }
}

// The timeline's geometry: the same plot area as `svg::Chart`'s.
const TL_W: f64 = 760.0;
const TL_LEFT: f64 = 70.0;
const TL_RIGHT: f64 = 190.0;
const TL_TOP: f64 = 40.0;
const TL_ROW: f64 = 34.0;
const TL_BOTTOM: f64 = 45.0;

/// Alarms and operator actions on the time axis: one row per kind, each
/// event a numbered marker (the numbers are the event table's).
fn timeline(run: &Run) -> String {
    let (t0, t1) = time_span(run);
    let rows = Kind::ALL.len() as f64;
    let h = TL_TOP + rows * TL_ROW + TL_BOTTOM;
    let px = |t: f64| TL_LEFT + (t - t0) / (t1 - t0) * (TL_W - TL_LEFT - TL_RIGHT);
    let bottom = TL_TOP + rows * TL_ROW;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{TL_W:.0}\" height=\"{h:.0}\" \
         viewBox=\"0 0 {TL_W:.0} {h:.0}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"{TL_W:.0}\" height=\"{h:.0}\" fill=\"white\"/>\n\
         <text x=\"{:.1}\" y=\"22\" text-anchor=\"middle\" font-size=\"14\" font-weight=\"bold\">\
         Alarms, state changes and operator actions</text>",
        (TL_LEFT + TL_W - TL_RIGHT) / 2.0
    );
    for t in svg::ticks(t0, t1, nice_step(t1 - t0, 10.0)) {
        let x = px(t);
        let _ = writeln!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{TL_TOP:.1}\" x2=\"{x:.1}\" y2=\"{bottom:.1}\" stroke=\"#e0e0e0\"/>\
             <text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            bottom + 16.0,
            esc(&format!("{}", (t * 1000.0).round() / 1000.0))
        );
    }
    let _ = writeln!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">time, s</text>",
        (TL_LEFT + TL_W - TL_RIGHT) / 2.0,
        h - 8.0
    );
    for (row, kind) in Kind::ALL.iter().enumerate() {
        let y = TL_TOP + (row as f64 + 0.5) * TL_ROW;
        let _ = writeln!(
            s,
            "<line x1=\"{TL_LEFT:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"#bbbbbb\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            TL_W - TL_RIGHT,
            TL_LEFT - 6.0,
            y + 4.0,
            kind.name()
        );
        let _ = writeln!(s, "<g data-series=\"{}\">", kind.name());
        // Markers closer than a label's width share one label ("3–6"),
        // placed above the cluster's first marker, alternating below when
        // the previous cluster's label is near.
        let mut clusters: Vec<(f64, Vec<usize>)> = Vec::new();
        for (i, e) in run
            .events
            .iter()
            .enumerate()
            .filter(|(_, e)| e.kind == *kind)
        {
            let x = px(e.t_s);
            let _ = writeln!(
                s,
                "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"4\" fill=\"{}\"><title>{:.3} s: {}</title></circle>",
                kind.colour(),
                e.t_s,
                esc(&e.text)
            );
            match clusters.last_mut() {
                Some((x0, members))
                    if x - *x0 < 16.0
                        || members
                            .last()
                            .is_some_and(|&j| x - px(run.events[j].t_s) < 16.0) =>
                {
                    members.push(i);
                }
                _ => clusters.push((x, vec![i])),
            }
        }
        let mut last_label_x = f64::NEG_INFINITY;
        let mut below = false;
        for (x, members) in &clusters {
            let contiguous = members.windows(2).all(|w| w[1] == w[0] + 1);
            let label = match members.as_slice() {
                [] => continue,
                [one] => format!("{}", one + 1),
                [first, .., last] if contiguous => format!("{}–{}", first + 1, last + 1),
                _ => members
                    .iter()
                    .map(|i| (i + 1).to_string())
                    .collect::<Vec<_>>()
                    .join(","),
            };
            below = x - last_label_x < 30.0 && !below;
            last_label_x = *x;
            let _ = writeln!(
                s,
                "<text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"start\" font-size=\"10\">{label}</text>",
                if below { y + 15.0 } else { y - 7.0 }
            );
        }
        s.push_str("</g>\n");
    }
    let _ = writeln!(
        s,
        "<rect x=\"{TL_LEFT:.1}\" y=\"{TL_TOP:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"black\"/>",
        TL_W - TL_LEFT - TL_RIGHT,
        rows * TL_ROW
    );
    s.push_str("</svg>\n");
    s
}

/// The spacing histogram: bins of X/20 from 0 to 2.5·X (the last bin takes
/// everything above), ISO 7256-1's class limits 0.5·X and 1.5·X marked.
fn histogram(spacing: &Spacing, values: &[f64], name: &str) -> Chart {
    let x_cm = spacing.target_m * 100.0;
    let width = x_cm / 20.0;
    let mut counts = [0u32; 50];
    for &v in values {
        // v / (X/20), nudged so that a spacing on a bin edge (7.0 cm for
        // X = 7 cm) lands in the bin it starts, whatever the rounding.
        let bin = (v / spacing.target_m * 20.0 + 1e-9).floor();
        let bin = if bin < 0.0 { 0 } else { (bin as usize).min(49) };
        counts[bin] += 1;
    }
    let bars = counts
        .iter()
        .enumerate()
        .filter(|(_, &c)| c > 0)
        .map(|(i, &c)| {
            let l = i as f64 * width;
            (l, l + width, f64::from(c))
        })
        .collect::<Vec<_>>();
    let (y, y_ticks) = y_axis(bars.iter().map(|b| b.2));
    Chart {
        title: "Spacing histogram".into(),
        x_label: format!("spacing, cm (bins of X/20; X = {x_cm:.1} cm)"),
        y_label: "spacings".into(),
        x: (0.0, 2.5 * x_cm),
        y,
        x_ticks: svg::ticks(0.0, 2.5 * x_cm, nice_step(2.5 * x_cm, 10.0)),
        y_ticks,
        series: Vec::new(),
        bars: vec![Bars {
            name: name.to_string(),
            colour: PALETTE[0],
            bars,
        }],
        v_lines: vec![
            (0.5 * x_cm, "0.5 X".into()),
            (x_cm, "X".into()),
            (1.5 * x_cm, "1.5 X".into()),
        ],
        h_lines: Vec::new(),
    }
}

fn row(html: &mut String, name: &str, value: &str) {
    let _ = writeln!(
        html,
        "<tr><th>{}</th><td>{}</td></tr>",
        esc(name),
        esc(value)
    );
}

/// Renders the report of `run`. `title` heads it, `source` says where the
/// log came from.
pub fn render(run: &Run, title: &str, source: &str) -> String {
    let truth = !run.sim.is_empty();
    let sp = spacing(run);
    let x_cm = sp.target_m * 100.0;
    let mut charts: Vec<String> = Vec::new();

    charts.push(timeline(run));
    // Travel speed.
    let mut travel = Vec::new();
    if truth {
        travel.push(series(
            names::TRAVEL_TRUE,
            PALETTE[7],
            run.sim.iter().map(|p| (p.t_s, p.travel_kmh)).collect(),
            false,
        ));
    }
    travel.push(series(
        names::TRAVEL_EST,
        PALETTE[0],
        status_points(run, |s| s.travel_kmh),
        false,
    ));
    charts.push(time_chart(run, "Travel speed", "km/h", travel, Vec::new()).render());
    // Drum.
    let mut drum = Vec::new();
    drum.push(series(
        names::DRUM_TARGET,
        PALETTE[1],
        if truth {
            run.sim.iter().map(|p| (p.t_s, p.target_rpm)).collect()
        } else {
            status_points(run, |s| s.target_rpm)
        },
        true,
    ));
    if truth {
        drum.push(series(
            names::DRUM_TRUE,
            PALETTE[7],
            run.sim.iter().map(|p| (p.t_s, p.drum_rpm)).collect(),
            false,
        ));
    }
    drum.push(series(
        names::DRUM_MEASURED,
        PALETTE[0],
        status_points(run, |s| s.actual_rpm),
        false,
    ));
    charts.push(time_chart(run, "Drum speed", "r/min", drum, Vec::new()).render());
    // Compare value.
    let mut ccr = Vec::new();
    if truth {
        ccr.push(series(
            names::CCR_APPLIED,
            PALETTE[3],
            run.sim.iter().map(|p| (p.t_s, p.ccr)).collect(),
            false,
        ));
    }
    ccr.push(series(
        names::CCR_STATUS,
        PALETTE[4],
        status_points(run, |s| s.ccr),
        truth,
    ));
    charts.push(
        time_chart(
            run,
            "PWM compare value (3600 = 100 % duty)",
            "CCR",
            ccr,
            Vec::new(),
        )
        .render(),
    );
    // Plants.
    let mut plants = Vec::new();
    if truth {
        plants.push(series(
            names::PLANTS_TRUE,
            PALETTE[7],
            run.sim.iter().map(|p| (p.t_s, p.plants)).collect(),
            false,
        ));
    }
    plants.push(series(
        names::PLANTS_FW,
        PALETTE[2],
        status_points(run, |s| s.plants),
        false,
    ));
    charts.push(time_chart(run, "Plants over time", "plants", plants, Vec::new()).render());
    // Spacing over time.
    let mut spacing_series = Vec::new();
    if !sp.per_plant.is_empty() {
        spacing_series.push(series(
            names::SPACING_PLANT,
            PALETTE[0],
            sp.per_plant.iter().map(|&(t, s)| (t, s * 100.0)).collect(),
            false,
        ));
    }
    spacing_series.push(series(
        names::SPACING_INTERVAL,
        PALETTE[2],
        sp.per_interval
            .iter()
            .map(|&(t, s)| (t, s * 100.0))
            .collect(),
        !sp.per_plant.is_empty(),
    ));
    charts.push(
        time_chart(
            run,
            "Plant spacing",
            "cm",
            spacing_series,
            vec![
                (0.5 * x_cm, "0.5 X".into()),
                (x_cm, "X".into()),
                (1.5 * x_cm, "1.5 X".into()),
            ],
        )
        .render(),
    );
    // Histogram.
    let hist = if sp.per_plant.is_empty() {
        let v: Vec<f64> = sp.per_interval.iter().map(|p| p.1).collect();
        histogram(&sp, &v, names::HIST_INTERVAL)
    } else {
        let v: Vec<f64> = sp.per_plant.iter().map(|p| p.1).collect();
        histogram(&sp, &v, names::HIST_PLANT)
    };
    charts.push(hist.render());

    let mut html = String::new();
    let _ = writeln!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n\
         <title>{t}</title>\n<style>\n\
         body {{ font-family: sans-serif; margin: 16px; color: #222; }}\n\
         h1 {{ font-size: 20px; margin: 0 0 4px 0; }}\n\
         h2 {{ font-size: 16px; margin: 14px 0 6px 0; }}\n\
         .src {{ color: #555; margin: 0 0 8px 0; }}\n\
         .row {{ display: flex; flex-wrap: wrap; gap: 12px; align-items: flex-start; }}\n\
         svg {{ width: 660px; height: auto; border: 1px solid #ddd; }}\n\
         table {{ border-collapse: collapse; font-size: 13px; }}\n\
         th, td {{ border: 1px solid #ccc; padding: 2px 8px; text-align: left; }}\n\
         th {{ background: #f4f4f4; font-weight: normal; }}\n\
         .note {{ color: #555; font-size: 12px; max-width: 1380px; }}\n\
         </style>\n</head>\n<body>\n<h1>{t}</h1>\n<p class=\"src\">{s}</p>",
        t = esc(title),
        s = esc(source)
    );
    html.push_str("<div class=\"row\">\n<div>\n<h2>Run</h2>\n<table>\n");
    let (t0, t1) = (
        run.status.first().map_or(0.0, |s| s.t_s),
        run.status.last().map_or(0.0, |s| s.t_s),
    );
    row(
        &mut html,
        "status lines",
        &format!("{} ({t0:.1} … {t1:.1} s)", run.status.len()),
    );
    if let Some(last) = run.status.iter().rev().find(|s| s.mode.is_some()) {
        row(
            &mut html,
            "mode, state (last)",
            &format!(
                "{} {}",
                last.mode.as_deref().unwrap_or("?"),
                match last.running {
                    Some(true) => "Running",
                    Some(false) => "Stopped",
                    None => "?",
                }
            ),
        );
    }
    row(
        &mut html,
        "spacing setting X",
        &format!("{x_cm:.1} cm (from {})", sp.target_source),
    );
    if let Some(s) = run.status.iter().rev().find(|s| s.plants.is_some()) {
        row(
            &mut html,
            "plants, distance since Start (firmware, last)",
            &format!(
                "{:.0}, {:.2} m",
                s.plants.unwrap_or(0.0),
                s.distance_m.unwrap_or(0.0)
            ),
        );
    }
    let alarms = run.events.iter().filter(|e| e.kind == Kind::Alarm).count();
    let operator = run
        .events
        .iter()
        .filter(|e| e.kind == Kind::Operator)
        .count();
    row(
        &mut html,
        "alarms, operator actions",
        &format!("{alarms}, {operator}"),
    );
    if let Some(o) = run.status.iter().rev().find_map(|s| s.overruns) {
        row(
            &mut html,
            "control overruns (since boot)",
            &format!("{o:.0}"),
        );
    }
    row(
        &mut html,
        "log lines read, not defmt lines, not used",
        &format!("{}, {}, {}", run.lines, run.unknown, run.other),
    );
    row(
        &mut html,
        "status lines missing, cut short",
        &format!("{}, {}", run.dropped, run.truncated),
    );
    row(&mut html, "resets", &format!("{}", run.reboots));
    html.push_str("</table>\n</div>\n<div>\n<h2>Plant spacing</h2>\n<table>\n");
    if let Some(m) = sp.metrics {
        row(
            &mut html,
            "plants (simulator), spacings",
            &format!("{}, {}", m.plants, m.spacings),
        );
        row(
            &mut html,
            "mean, SD, CV of all spacings",
            &format!(
                "{:.2} cm, {:.2} cm, {:.1} %",
                m.mean_spacing_m * 100.0,
                m.sd_spacing_m * 100.0,
                m.cv_pct
            ),
        );
        row(
            &mut html,
            "ISO 7256-1 multiples index D (s ≤ 0.5 X)",
            &format!("{:.1} %", m.multiple_index_pct),
        );
        row(
            &mut html,
            "ISO 7256-1 miss index M (s > 1.5 X)",
            &format!("{:.1} %", m.miss_index_pct),
        );
        row(
            &mut html,
            "ISO 7256-1 quality of feed A = 100 − D − M",
            &format!("{:.1} %", m.quality_of_feed_pct),
        );
        row(
            &mut html,
            "ISO 7256-1 precision C (CV of the singles)",
            &format!("{:.1} %", m.precision_pct),
        );
        row(
            &mut html,
            "qualified (|s − X| ≤ 20 % X)",
            &format!("{:.1} %", m.qualified_pct),
        );
        row(
            &mut html,
            "count error vs ground / X (from the drum's start)",
            &format!("{:+.1} % over {:.2} m", m.count_error_pct, m.distance_m),
        );
    } else {
        row(
            &mut html,
            "ISO 7256-1 indices",
            "need each plant's position: the simulator's (cargo xtask qemu), not in a field log",
        );
    }
    if sp.firmware_plants > 0.0 {
        row(
            &mut html,
            "firmware: plants / distance while running",
            &format!(
                "{:.0} / {:.2} m = {:.2} cm mean",
                sp.firmware_plants,
                sp.firmware_distance_m,
                100.0 * sp.firmware_distance_m / sp.firmware_plants
            ),
        );
    }
    if let Some(e) = sp.firmware_count_error_pct() {
        row(
            &mut html,
            "firmware: count error vs its distance / X",
            &format!("{e:+.1} %"),
        );
    }
    html.push_str("</table>\n</div>\n</div>\n<h2>Charts</h2>\n<div class=\"row\">\n");
    for c in &charts {
        html.push_str("<div>\n");
        html.push_str(c);
        html.push_str("</div>\n");
    }
    html.push_str("</div>\n");
    let _ = writeln!(
        html,
        "<p class=\"note\">Firmware series come from the 1 Hz <code>status:</code> lines \
         (a missing line breaks the line); {} Dashed vertical lines: alarms{}, numbered as in \
         the table below. Compare value: TIM1 CCR1 of 3600 (20 kHz).</p>",
        if truth {
            "simulator series from the QEMU board's <code>sim:</code> lines (10 Hz) and one \
             <code>sim: plant</code> line per plant: the machine's truth, which a real board \
             does not have."
        } else {
            "a field capture has no simulator truth: the spacing is the firmware's mean \
             (distance / plants) over its last ten or more plants at each status line, and the \
             ISO indices need each plant's position."
        },
        if truth {
            " and simulator disturbances"
        } else {
            ""
        }
    );
    html.push_str(
        "<h2>Events</h2>\n<table>\n<tr><th>#</th><th>time, s</th><th>kind</th><th>log</th></tr>\n",
    );
    for (i, e) in run.events.iter().enumerate() {
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{:.3}</td><td>{}</td><td>{}</td></tr>",
            i + 1,
            e.t_s,
            e.kind.name(),
            esc(&e.text)
        );
    }
    html.push_str("</table>\n</body>\n</html>\n");
    html
}

/// What [`check`] found: each `data-series` and its number of points (path
/// vertices, bars, or markers).
pub type SeriesPoints = Vec<(String, usize)>;

/// Checks that `html` is well-formed (parsed as XML: every tag closed in
/// order, attributes quoted, only XML's own entities) and returns its
/// series.
pub fn check(html: &str) -> Result<SeriesPoints> {
    use quick_xml::events::Event as X;
    let mut reader = quick_xml::Reader::from_str(html);
    reader.config_mut().check_end_names = true;
    let mut stack: Vec<String> = Vec::new();
    let mut found: SeriesPoints = Vec::new();
    // The open `<g data-series>`: its index in `found` and its depth.
    let mut open_group: Option<(usize, usize)> = None;
    loop {
        let event = reader.read_event().map_err(|e| {
            format!(
                "report HTML not well-formed at byte {}: {e}",
                reader.error_position()
            )
        })?;
        let (element, opens) = match event {
            X::Start(e) => (e, true),
            X::Empty(e) => (e, false),
            X::End(e) => {
                let name = e.name().as_ref().to_string();
                if stack.pop().as_deref() != Some(name.as_str()) {
                    return Err(format!("report HTML: unexpected </{name}>"));
                }
                if open_group.is_some_and(|(_, depth)| depth == stack.len()) {
                    open_group = None;
                }
                continue;
            }
            X::GeneralRef(r) => {
                let known = matches!(r.as_ref(), "amp" | "lt" | "gt" | "quot" | "apos");
                if !(known || r.resolve_char_ref().ok().flatten().is_some()) {
                    return Err(format!("report HTML: unknown entity &{};", r.as_ref()));
                }
                continue;
            }
            X::Eof => break,
            _ => continue,
        };
        let name = element.name().as_ref().to_string();
        let mut series = None;
        let mut d = None;
        for a in element.attributes() {
            let a = a.map_err(|e| format!("report HTML: bad attribute in <{name}>: {e}"))?;
            let value = a
                .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                .map_err(|e| format!("report HTML: bad attribute value in <{name}>: {e}"))?
                .into_owned();
            match a.key.as_ref() {
                "data-series" => series = Some(value),
                "d" => d = Some(value),
                _ => {}
            }
        }
        if let Some(series) = series {
            // A path's vertices (its M and L commands).
            let points = d.map_or(0, |d| d.matches(['M', 'L']).count());
            found.push((series, points));
            if opens {
                open_group = Some((found.len() - 1, stack.len()));
            }
        } else if let Some((i, depth)) = open_group {
            // A group's bars or markers.
            if stack.len() == depth + 1 && (name == "rect" || name == "circle") {
                if let Some(f) = found.get_mut(i) {
                    f.1 += 1;
                }
            }
        }
        if opens {
            stack.push(name);
        }
    }
    if let Some(open) = stack.last() {
        return Err(format!("report HTML: <{open}> never closed"));
    }
    Ok(found)
}

/// The names in `wanted` that `found` lacks or holds without a point.
pub fn missing<'a>(found: &SeriesPoints, wanted: &[&'a str]) -> Vec<&'a str> {
    wanted
        .iter()
        .copied()
        .filter(|w| !found.iter().any(|(n, p)| n == w && *p > 0))
        .collect()
}

/// Writes `html` to `path` after checking it.
pub fn write(path: &Path, html: &str) -> Result<PathBuf> {
    check(html)?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::write(path, html).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path.to_path_buf())
}

/// `cargo xtask report FILE [--out PATH]`: a field capture into a report.
pub fn run(args: &[String]) -> Result {
    let mut input = None;
    let mut out = None;
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--out" | "-o" => out = Some(PathBuf::from(it.next().ok_or("--out takes a path")?)),
            other if input.is_none() && !other.starts_with('-') => {
                input = Some(PathBuf::from(other));
            }
            other => return Err(format!("report: unknown argument `{other}`")),
        }
    }
    let input = input.ok_or("usage: cargo xtask report CAPTURE.txt [--out REPORT.html]")?;
    let bytes = std::fs::read(&input).map_err(|e| format!("{}: {e}", input.display()))?;
    let text = String::from_utf8_lossy(&bytes);
    let run = parse(&text).firmware_only();
    if run.status.is_empty() {
        let why = if text.contains("status: uptime") && text.contains("profile B") {
            "it is profile B's (the report covers profile A, the drum-belt machine)"
        } else {
            "is this a decoded defmt capture (probe-rs run … > capture.txt)?"
        };
        return Err(format!(
            "{}: no profile A `status:` line in {} lines: {why}",
            input.display(),
            run.lines
        ));
    }
    let out = out.unwrap_or_else(|| input.with_extension("html"));
    let html = render(
        &run,
        "Transplanter run report (field capture)",
        &format!(
            "{}: {} lines, {} status lines ({} missing, {} cut short), {} lines that are not \
             defmt lines",
            input.display(),
            run.lines,
            run.status.len(),
            run.dropped,
            run.truncated,
            run.unknown
        ),
    );
    let path = write(&out, &html)?;
    eprintln!(
        "xtask: report: {} status lines, {} events, {} missing and {} cut-short status lines, {} \
         lines that are not defmt lines",
        run.status.len(),
        run.events.len(),
        run.dropped,
        run.truncated,
        run.unknown
    );
    println!("{}", path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A QEMU main-job log (`cargo xtask qemu`, 20 s, `plant_log=1`), as
    /// the xtask saves it in target/report/qemu-run.log.
    const QEMU_LOG: &str = include_str!("../tests/data/qemu-run.log");
    /// A hand-made `probe-rs run` capture: starts mid-run, has the probe's
    /// progress and location lines, a colour code, a decoder complaint, one
    /// status line dropped (103 s) and one cut short (104 s, inside a
    /// number), and a drum-stall alarm acknowledged and restarted.
    const FIELD: &str = include_str!("../tests/data/field-capture.txt");

    fn points(found: &SeriesPoints, name: &str) -> usize {
        found
            .iter()
            .filter(|(n, _)| n == name)
            .map(|(_, p)| *p)
            .sum()
    }

    #[test]
    fn field_capture_with_a_dropped_line_and_an_alarm() {
        let run = parse(FIELD);
        // Counted by hand in the file: 10 status lines (100–102, 104–110 s),
        // 19 lines that are not location lines, 3 of them not the
        // firmware's (two probe progress lines, the decoder's complaint).
        assert_eq!(run.status.len(), 10);
        assert_eq!(run.lines, 19);
        assert_eq!(run.unknown, 3);
        assert_eq!(run.other, 0);
        assert_eq!(run.dropped, 1, "103 s is missing");
        assert_eq!(run.truncated, 1, "104 s is cut short");
        assert_eq!(run.reboots, 0);
        assert!(run.sim.is_empty() && run.plants.is_empty());
        // The cut line keeps what came before the cut, not the cut number
        // ("distance 52" was 52xx mm).
        let cut = &run.status[3];
        assert_eq!(cut.plants, Some(77.0));
        assert_eq!(cut.distance_m, None);
        assert_eq!(cut.alarm, None);
        // The colour-coded line was read.
        assert_eq!(run.status[2].ccr, Some(2340.0));
        let kinds: Vec<(Kind, &str)> = run
            .events
            .iter()
            .map(|e| (e.kind, e.text.as_str()))
            .collect();
        assert_eq!(
            kinds,
            [
                (Kind::Alarm, "alarm: DrumStall"),
                (Kind::State, "drum: Stopped"),
                (Kind::Operator, "alarm acknowledged"),
                (Kind::Alarm, "alarm cleared"),
                (Kind::Operator, "screen: Start"),
                (Kind::State, "drum: Running"),
            ]
        );
        assert_eq!(run.status[5].alarm.as_deref(), Some("Some(DrumStall)"));

        // Spacing from the firmware's counts, over the intervals where both
        // ends run and are complete: 100→101 s (5 plants, 350 mm), 101→102 s
        // (5, 360 mm), 108→109 s (5, 350 mm), 109→110 s (5, 350 mm); 102→104
        // and 104→105 have the cut line, 105→106 … 107→108 a stopped end.
        let sp = spacing(&run);
        assert_eq!(sp.target_m, 0.070);
        assert_eq!(sp.firmware_plants, 20.0);
        assert!((sp.firmware_distance_m - 1.410).abs() < 1e-12);
        // Means over ≥ 10 plants: at 102 s 710 mm / 10, at 110 s 700 mm / 10
        // (at 101 s and 109 s only 5 plants since a break).
        let means: Vec<(f64, f64)> = sp.per_interval.clone();
        assert_eq!(means.len(), 2, "{means:?}");
        assert!((means[0].0 - 102.009).abs() < 1e-9 && (means[0].1 - 0.071).abs() < 1e-12);
        assert!((means[1].0 - 110.009).abs() < 1e-9 && (means[1].1 - 0.070).abs() < 1e-12);
        // 20 plants against 1.410 m / 0.070 m = 20.14: 1400/1410 − 1 = −0.71 %.
        let e = sp.firmware_count_error_pct().unwrap();
        assert!((e - (1400.0 / 1410.0 - 1.0) * 100.0).abs() < 1e-9, "{e}");
        assert!(sp.metrics.is_none(), "no ISO indices without positions");

        let html = render(&run, "field", "test");
        let found = check(&html).unwrap();
        // Every firmware series, a vertex per status line (the cut line has
        // a travel speed, drum speeds, a compare value and plants).
        for name in [
            names::TRAVEL_EST,
            names::DRUM_TARGET,
            names::DRUM_MEASURED,
            names::CCR_STATUS,
            names::PLANTS_FW,
        ] {
            assert_eq!(points(&found, name), 10, "{name}");
        }
        assert_eq!(points(&found, names::SPACING_INTERVAL), 2);
        // 7.1 and 7.0 cm both fall in the bin [7.0, 7.35) cm.
        assert_eq!(points(&found, names::HIST_INTERVAL), 1);
        assert_eq!(points(&found, "operator"), 2);
        assert_eq!(points(&found, "alarm"), 2);
        assert_eq!(points(&found, "state"), 2);
        for truth in [names::TRAVEL_TRUE, names::DRUM_TRUE, names::SPACING_PLANT] {
            assert!(!found.iter().any(|(n, _)| n == truth), "{truth}");
        }
        assert!(html.contains("alarm: DrumStall"));
        // The dropped line breaks the estimated travel speed's line in two:
        // 100–102 s, then 104–110 s.
        let path = html
            .split(&format!("data-series=\"{}\"", esc(names::TRAVEL_EST)))
            .nth(1)
            .and_then(|rest| rest.split(" d=\"").nth(1))
            .and_then(|rest| rest.split('"').next())
            .unwrap();
        assert_eq!(path.matches('M').count(), 2, "{path}");
        assert_eq!(path.matches('L').count(), 8, "{path}");
    }

    #[test]
    fn probe_rs_formats_are_read() {
        // probe-rs's default "{t} {L} {s}" (level padded), a bracketed level,
        // a bracketed time, colour codes; lines without a time are not
        // defmt lines.
        let log = "0.500 INFO  drum: Running\n\
                   └─ firmware::app::control @ firmware/src/main.rs:553\n\
                   0.600 [WARN ] alarm: HallLost\n\
                   [0.700] ERROR HardFault at pc 0x8000123\n\
                   \u{1b}[2m0.800\u{1b}[0m \u{1b}[1;32mINFO \u{1b}[0m screen: Start\n\
                   INFO  drum: Stopped\n\
                   0.900 NOTE  drum: Stopped\n";
        let run = parse(log);
        let events: Vec<(f64, Kind, &str)> = run
            .events
            .iter()
            .map(|e| (e.t_s, e.kind, e.text.as_str()))
            .collect();
        assert_eq!(
            events,
            [
                (0.5, Kind::State, "drum: Running"),
                (0.6, Kind::Alarm, "alarm: HallLost"),
                (0.7, Kind::Alarm, "HardFault at pc 0x8000123"),
                (0.8, Kind::Operator, "screen: Start"),
            ]
        );
        assert_eq!((run.lines, run.unknown), (6, 2));
    }

    #[test]
    fn qemu_log_has_every_series_and_the_iso_indices() {
        let run = parse(QEMU_LOG);
        let lines = |needle: &str| QEMU_LOG.lines().filter(|l| l.contains(needle)).count();
        assert_eq!(run.status.len(), lines(" status: "));
        assert_eq!(run.sim.len(), lines(" sim: ground "));
        assert_eq!(run.plants.len(), lines(" sim: plant "));
        assert!(run.plants.len() >= 30, "{} plants", run.plants.len());
        // Semihosting loses nothing: a dropped line here would be a false alarm.
        assert_eq!((run.dropped, run.truncated, run.unknown), (0, 0, 0));
        // Not plotted: settings, machine, stack (twice), run limit.
        assert_eq!(run.other, 5);

        // The ISO 7256-1 indices again, by a plain loop over the plant lines
        // (the classes of ISO 7256-1: s ≤ 0.5 X multiple, s > 1.5 X miss).
        let x = 0.070;
        let pos: Vec<f64> = QEMU_LOG
            .lines()
            .filter_map(|l| l.split(" sim: plant ").nth(1))
            .map(|r| r.split(" at ").nth(1).unwrap())
            .map(|r| r.trim_end_matches(" um").parse::<f64>().unwrap() / 1e6)
            .collect();
        let s: Vec<f64> = pos.windows(2).map(|w| w[1] - w[0]).collect();
        let n = s.len() as f64;
        let multiples = s.iter().filter(|&&v| v <= 0.5 * x).count() as f64;
        let misses = s.iter().filter(|&&v| v > 1.5 * x).count() as f64;
        let singles: Vec<f64> = s
            .iter()
            .copied()
            .filter(|&v| v > 0.5 * x && v <= 1.5 * x)
            .collect();
        let mean = singles.iter().sum::<f64>() / singles.len() as f64;
        let sd = (singles.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
            / (singles.len() as f64 - 1.0))
            .sqrt();
        let sp = spacing(&run);
        let m = sp.metrics.expect("metrics from the plant lines");
        assert_eq!(sp.per_plant.len(), s.len());
        assert_eq!(m.spacings as usize, s.len());
        assert!((m.multiple_index_pct - 100.0 * multiples / n).abs() < 1e-9);
        assert!((m.miss_index_pct - 100.0 * misses / n).abs() < 1e-9);
        assert!((m.quality_of_feed_pct - 100.0 * singles.len() as f64 / n).abs() < 1e-9);
        assert!((m.precision_pct - 100.0 * sd / mean).abs() < 1e-9);

        let html = render(&run, "qemu", "test");
        let found = check(&html).unwrap();
        let vertices = |name| points(&found, name);
        assert_eq!(vertices(names::TRAVEL_TRUE), run.sim.len());
        assert_eq!(vertices(names::TRAVEL_EST), run.status.len());
        assert_eq!(vertices(names::DRUM_TARGET), run.sim.len());
        assert_eq!(vertices(names::DRUM_TRUE), run.sim.len());
        assert_eq!(vertices(names::DRUM_MEASURED), run.status.len());
        assert_eq!(vertices(names::CCR_APPLIED), run.sim.len());
        assert_eq!(vertices(names::CCR_STATUS), run.status.len());
        assert_eq!(vertices(names::PLANTS_TRUE), run.sim.len());
        assert_eq!(vertices(names::PLANTS_FW), run.status.len());
        assert_eq!(vertices(names::SPACING_PLANT), s.len());
        // One mean per status line once ten plants are counted (≈ 5 s in).
        assert!(vertices(names::SPACING_INTERVAL) >= run.status.len() / 2);
        assert!(vertices(names::HIST_PLANT) >= 1);
        // Operator: mode, spacing, gear, Start; state: boot, screen, drum;
        // simulator: the +10 % step.
        assert_eq!(vertices("operator"), lines(" screen: "));
        assert_eq!(vertices("simulator"), 1);
        assert!(vertices("state") >= 2);
    }

    #[test]
    fn qemu_log_read_as_a_field_capture() {
        let full = parse(QEMU_LOG);
        let run = full.clone().firmware_only();
        let html = render(&run, "qemu, firmware only", "test");
        let found = check(&html).unwrap();
        for name in [
            names::TRAVEL_EST,
            names::DRUM_TARGET,
            names::DRUM_MEASURED,
            names::CCR_STATUS,
            names::PLANTS_FW,
        ] {
            assert_eq!(points(&found, name), run.status.len(), "{name}");
        }
        assert!(points(&found, names::SPACING_INTERVAL) > 0);
        assert!(points(&found, names::HIST_INTERVAL) > 0);
        for truth in [
            names::TRAVEL_TRUE,
            names::DRUM_TRUE,
            names::CCR_APPLIED,
            names::PLANTS_TRUE,
            names::SPACING_PLANT,
            names::HIST_PLANT,
        ] {
            assert!(!found.iter().any(|(n, _)| n == truth), "{truth}");
        }
        assert_eq!(points(&found, "simulator"), 0);
        // The firmware's own mean spacing (its distance over its plant
        // count) against the simulator's (the plants' ground positions):
        // the count is whole plants, about 40 here, so ±1 plant is 2.5 %.
        let fw = spacing(&run);
        let truth = spacing(&full).metrics.unwrap();
        let fw_mean = fw.firmware_distance_m / fw.firmware_plants;
        let off = (fw_mean / truth.mean_spacing_m - 1.0).abs();
        assert!(
            off < 0.03,
            "firmware {fw_mean} m, truth {} m",
            truth.mean_spacing_m
        );
    }

    #[test]
    fn time_continues_across_a_reset() {
        let log = "5.000 INFO  drum: Running\n6.000 INFO  drum: Stopped\n\
                   0.001 INFO  boot: transplanter firmware\n1.000 INFO  drum: Running\n";
        let run = parse(log);
        assert_eq!(run.reboots, 1);
        let times: Vec<f64> = run.events.iter().map(|e| e.t_s).collect();
        // The reset is marked at the last time before it; after it the
        // board's times are shifted by that (6.000 s).
        assert_eq!(times, [5.0, 6.0, 6.0, 6.001, 7.0]);
    }

    #[test]
    fn the_checker_rejects_what_a_browser_would_misread() {
        assert!(check("<html><body><svg><g></svg></body></html>").is_err());
        assert!(check("<html><body><p>a &nbsp; b</p></body></html>").is_err());
        assert!(check("<html><body><rect width=3/></body></html>").is_err());
        assert!(check("<html><body>").is_err());
        let found = check(
            "<html><svg><g data-series=\"b\"><rect/><rect/></g>\
             <path data-series=\"p\" d=\"M1 2 L3 4 L5 6\"/></svg></html>",
        )
        .unwrap();
        assert_eq!(found, [("b".to_string(), 2), ("p".to_string(), 3)]);
    }
}
