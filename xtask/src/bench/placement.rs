//! Item 9: distance-locked vs speed-following placement, side by
//! side on the machine model, landing scatter off.

use hmi_proto::screen::{Command, Mode, Spacing, TravelSource};
use kinematics::consts::Gear;
use kinematics::units::Ticks;
use machine_sim::{Config, Event, Inputs};
use supervisor::drum::{Actuation, Hardware, Supervisor};
use supervisor::settings::wheel::GroundWheelSettings;
use supervisor::settings::{Placement, Settings};

use crate::Result;

const HW: Hardware = Hardware::BOARD;
/// Row length, m, and rows per case.
const ROW_M: f64 = 70.0;
pub(super) const ROWS: u64 = 6;
/// One Hall pitch at k1 = k2 = 1, m (the first place's allowance).
const EDGE_M: f64 = std::f64::consts::PI * 0.20 / 25.0;

#[derive(Clone, Copy, PartialEq)]
pub(super) enum Profile {
    Default,
    Hills,
    StopGo,
}

impl Profile {
    pub(super) const ALL: [Self; 3] = [Self::Default, Self::Hills, Self::StopGo];
    pub(super) fn name(self) -> &'static str {
        match self {
            Self::Default => "default terrain",
            Self::Hills => "hills",
            Self::StopGo => "stop-and-go",
        }
    }
    fn config(self, c: Config) -> Config {
        match self {
            Self::Default => c,
            Self::Hills => c.hills(),
            Self::StopGo => c.stop_and_go(),
        }
    }
}

/// Where the firmware takes the ground from in a row: the travel source and
/// the wheel's calibration (counts per metre × 1000).
#[derive(Clone, Copy, PartialEq)]
pub(super) struct Source {
    pub travel: TravelSource,
    pub counts_per_m_x1000: u32,
}

impl Source {
    /// The Hall gear alone (paper A; the settings' default).
    pub const HALL: Self = Self {
        travel: TravelSource::HallGear,
        counts_per_m_x1000: supervisor::settings::wheel::NOMINAL_COUNTS_PER_M_X1000,
    };
}

/// The machine's ground wheel in every row (the Hall gear's rows do not
/// read it; its clods draw from their own random stream, so the terrain is
/// the same): 1.5 % larger than the nominal 250 mm (wear, soil on the
/// tread), 0.5 % own slip varying with the soil (SD 0.25 %: 0–1 %), a clod
/// lifting it for 2 cm every 20 m on average.
pub(super) fn with_wheel(c: Config) -> Config {
    Config {
        ground_wheel_diameter_error: 0.015,
        ground_wheel_slip: 0.005,
        ground_wheel_slip_noise: 0.5,
        ground_wheel_clod_rate_per_m: 0.05,
        ground_wheel_clod_m: 0.02,
        ..c
    }
}

/// One row's record.
pub(super) struct Row {
    /// True drop positions, m from the ground at Start.
    drops: Vec<f64>,
    /// True ground at the first Hall edge after Start (the origin), m from
    /// the ground at Start.
    origin: f64,
    /// Measured ground (µm) of each partition event.
    events: Vec<u64>,
    /// (measured ground m, true ground m from the origin) per step.
    pairs: Vec<(f64, f64)>,
    alarm: bool,
    /// The live slip shown, % (each new value), against the model's true
    /// slip over the same three gear turns of track, %.
    pub slip: Vec<(f64, f64)>,
    /// The model's true slip over the row, %, and the mean slip shown, %.
    pub pass_slip: (f64, f64),
}

fn row(
    placement: Placement,
    profile: Profile,
    gear: Gear,
    spacing_mm: u16,
    seed: u64,
    source: Source,
) -> Result<Row> {
    let cfg = profile.config(with_wheel(Config {
        seed,
        initial_gear: Some(gear),
        plant_scatter_m: 0.0,
        target_spacing_m: f32::from(spacing_mm) / 1000.0,
        ..Config::default()
    }));
    let mut m = cfg.build().map_err(|e| format!("machine: {e}"))?;
    let settings = Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(i32::from(spacing_mm)).map_err(|e| format!("{e:?}"))?,
        gear,
        placement,
        ground_wheel: GroundWheelSettings {
            source: source.travel,
            counts_per_m_x1000: source.counts_per_m_x1000,
            reversed: false,
        },
        ..Settings::default()
    };
    let mut sup = Supervisor::new(HW, settings).map_err(|e| format!("supervisor: {e:?}"))?;
    let wheel = source.travel.uses_wheel();
    let mut act = Actuation::OFF;
    m.stop_travel();
    let mut out = Row {
        drops: Vec::new(),
        origin: f64::NAN,
        events: Vec::new(),
        pairs: Vec::new(),
        alarm: false,
        slip: Vec::new(),
        pass_slip: (f64::NAN, f64::NAN),
    };
    let mut g_start = 0.0;
    let mut t_start = 0.0;
    // (track, ground) per step since Start, m: the true slip over the last
    // three gear turns of track.
    let mut path: Vec<(f64, f64)> = Vec::new();
    let mut shown_last = None;
    let mut shown: Vec<f64> = Vec::new();
    let three_turns = 3.0 * std::f64::consts::PI * 0.20;
    let mut started = false;
    let mut k = 0u32;
    loop {
        if k == 20 {
            sup.command(Command::Start);
            m.resume_travel();
            g_start = m.ground_position_m();
            t_start = m.track_position_m();
            started = true;
        }
        k += 1;
        if started && m.ground_position_m() - g_start >= ROW_M {
            break;
        }
        let inputs = Inputs {
            drum_duty: f32::from(act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: act.driver_enabled,
            ..Inputs::default()
        };
        let g0 = m.ground_position_m();
        let t0 = m.capture_ticks();
        let w0 = m.ground_encoder_count();
        let mut first_edge = None;
        m.step_events(10_000, &inputs, &mut |e| match e {
            Event::HallEdge(ticks) => {
                first_edge.get_or_insert(ticks);
                sup.hall_edge(Ticks(ticks));
            }
            Event::Plant { ground_m, .. } => out.drops.push(ground_m - g_start),
        });
        let g1 = m.ground_position_m();
        if started && out.origin.is_nan() {
            if wheel {
                // The wheel's origin: the end of the first step it counted
                // in (supervisor::phase, `advance_ground_by`).
                if m.ground_encoder_count() != w0 {
                    out.origin = g1 - g_start;
                }
            } else if let Some(ticks) = first_edge {
                let f = f64::from(ticks.wrapping_sub(t0)) / 10_000.0;
                out.origin = g0 + f * (g1 - g0) - g_start;
            }
        }
        sup.ground_wheel_count(m.ground_encoder_count());
        act = sup.control_step(Ticks(m.capture_ticks()), m.drum_encoder_count());
        if started {
            let track = m.track_position_m() - t_start;
            let ground = g1 - g_start;
            path.push((track, ground));
            let now = sup.snapshot().track_slip_x10;
            if now.is_some() && now != shown_last {
                let back = path
                    .iter()
                    .rev()
                    .find(|p| track - p.0 >= three_turns)
                    .copied();
                if let (Some(s), Some((t3, g3))) = (now, back) {
                    let truth = 100.0 * (1.0 - (ground - g3) / (track - t3));
                    out.slip.push((f64::from(s) / 10.0, truth));
                }
            }
            if let Some(s) = now {
                shown.push(f64::from(s) / 10.0);
            }
            shown_last = now;
        }
        if started {
            out.events
                .extend(sup.plants_left().map(|e| e.ground_distance_um));
            if !out.origin.is_nan() {
                #[allow(clippy::cast_precision_loss)]
                let measured = sup.ground_distance_um() as f64 / 1e6;
                out.pairs.push((measured, g1 - g_start - out.origin));
            }
            if sup.alarm().is_some() {
                out.alarm = true;
            }
        }
    }
    if let Some(&(track, ground)) = path.last() {
        #[allow(clippy::cast_precision_loss)]
        let mean = shown.iter().sum::<f64>() / shown.len().max(1) as f64;
        out.pass_slip = (100.0 * (1.0 - ground / track), mean);
    }
    Ok(out)
}

#[derive(Default)]
pub(super) struct Stats {
    spacings: Vec<f64>,
    err_measured: Vec<f64>,
    err_true: Vec<f64>,
    first_true: Vec<f64>,
    counts: Vec<f64>,
    drift: Vec<f64>,
    /// Measured − true ground at the end of each row, mm.
    ground_err: Vec<f64>,
    alarms: u32,
    /// Position error (vs measured) along the first row: (m, mm).
    trace: Vec<(f64, f64)>,
    /// Live slip shown − true over the same three turns, percentage points.
    pub slip_err: Vec<f64>,
    /// Per row: mean slip shown over the pass − the pass's true slip, points.
    pub pass_slip_err: Vec<f64>,
}

impl Stats {
    /// Rows with any alarm.
    pub(super) fn alarms(&self) -> u32 {
        self.alarms
    }
}

pub(super) fn pct(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    #[allow(
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss
    )]
    let i = ((v.len().saturating_sub(1)) as f64 * q).round() as usize;
    v.get(i).copied().unwrap_or(f64::NAN)
}

pub(super) fn case(
    placement: Placement,
    profile: Profile,
    gear: Gear,
    spacing_mm: u16,
    ci: u64,
    source: Source,
) -> Result<Stats> {
    let x = f64::from(spacing_mm) / 1000.0;
    let mut s = Stats::default();
    for r in 0..ROWS {
        // Both modes see the same machine (seed) per row.
        let row = row(
            placement,
            profile,
            gear,
            spacing_mm,
            8000 + 100 * ci + r,
            source,
        )?;
        s.slip_err.extend(row.slip.iter().map(|(a, b)| a - b));
        if !row.pass_slip.1.is_nan() && !row.slip.is_empty() {
            s.pass_slip_err.push(row.pass_slip.1 - row.pass_slip.0);
        }
        // The first place: X + one Hall pitch past the first edge, X past
        // the wheel's first count (supervisor::phase).
        let first = if source.travel.uses_wheel() {
            x
        } else {
            x + EDGE_M
        };
        let in_row: Vec<f64> = row
            .drops
            .iter()
            .copied()
            .filter(|d| (0.0..=ROW_M).contains(d))
            .collect();
        #[allow(clippy::cast_precision_loss)]
        s.counts.push(in_row.len() as f64 - ROW_M / x);
        s.spacings.extend(in_row.windows(2).map(|w| w[1] - w[0]));
        let mut em = Vec::new();
        for (n, g) in row.events.iter().enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let place = first + n as f64 * x;
            #[allow(clippy::cast_precision_loss)]
            let e = (*g as f64 / 1e6 - place) * 1000.0;
            em.push(e);
            if r == 0 {
                s.trace.push((place, e));
            }
        }
        for (n, d) in row.drops.iter().enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let place = first + n as f64 * x;
            let e = (d - row.origin - place) * 1000.0;
            if n == 0 {
                s.first_true.push(e);
            }
            s.err_true.push(e);
        }
        let k = em.len().min(50);
        if k > 0 {
            #[allow(clippy::cast_precision_loss)]
            let head = em.iter().take(k).sum::<f64>() / k as f64;
            #[allow(clippy::cast_precision_loss)]
            let tail = em.iter().rev().take(k).sum::<f64>() / k as f64;
            s.drift.push(tail - head);
        }
        s.err_measured.extend(em);
        // The Hall-measured ground against the true one at the row's end.
        if let Some((g, t)) = row.pairs.last() {
            s.ground_err.push((g - t) * 1000.0);
        }
        s.alarms += u32::from(row.alarm);
    }
    Ok(s)
}

/// A case's figures (the table's columns).
pub(super) struct Figures {
    pub cv: f64,
    pub p95s: f64,
    pub outside: f64,
    pub cmean: f64,
    pub cworst: f64,
    /// Position error vs the measured ground: mean, p95 |·|, max |·|, mm.
    pub measured: (f64, f64, f64),
    /// Position error vs the true ground: mean, p95 |·|, max |·|, mm.
    pub truth: (f64, f64, f64),
    pub gerr: f64,
    pub first: f64,
    pub drift: f64,
}

/// The figures of a case's rows at spacing `x` mm.
pub(super) fn figures(s: &Stats, x: u16) -> Figures {
    let xf = f64::from(x) / 1000.0;
    #[allow(clippy::cast_precision_loss)]
    let n = s.spacings.len().max(1) as f64;
    let mean = s.spacings.iter().sum::<f64>() / n;
    let var = s.spacings.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    let cv = 100.0 * var.sqrt() / mean;
    let mut rel: Vec<f64> = s
        .spacings
        .iter()
        .map(|v| 100.0 * (v - xf).abs() / xf)
        .collect();
    #[allow(clippy::cast_precision_loss)]
    let outside = 100.0 * rel.iter().filter(|r| **r > 5.0).count() as f64 / n;
    let p95s = pct(&mut rel, 0.95);
    #[allow(clippy::cast_precision_loss)]
    let cmean = s.counts.iter().sum::<f64>() / s.counts.len().max(1) as f64;
    let cworst = s
        .counts
        .iter()
        .copied()
        .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
    let stat = |v: &[f64]| {
        #[allow(clippy::cast_precision_loss)]
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let mut a: Vec<f64> = v.iter().map(|e| e.abs()).collect();
        let p95 = pct(&mut a, 0.95);
        let max = a.last().copied().unwrap_or(f64::NAN);
        (mean, p95, max)
    };
    let (mm, pm, xm) = stat(&s.err_measured);
    let (mt, pt, xt) = stat(&s.err_true);
    let gerr = s
        .ground_err
        .iter()
        .copied()
        .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
    let first = s.first_true.iter().map(|e| e.abs()).fold(0.0, f64::max);
    let drift = s
        .drift
        .iter()
        .copied()
        .fold(0.0f64, |a, b| if b.abs() > a.abs() { b } else { a });
    let measured = (mm, pm, xm);
    let truth = (mt, pt, xt);
    Figures {
        cv,
        p95s,
        outside,
        cmean,
        cworst,
        measured,
        truth,
        gerr,
        first,
        drift,
    }
}

/// The cases of §9 and §12: gear, its name, spacing mm.
pub(super) const CASES: [(Gear, &str, u16); 4] = [
    (Gear::Low1, "Low 1", 70),
    (Gear::Low2, "Low 2", 70),
    (Gear::Low1, "Low 1", 180),
    (Gear::Low2, "Low 2", 180),
];

/// `f` over `jobs` on two threads (the rows are independent), in order; an
/// empty result when a worker failed.
pub(super) fn on_two_threads<J: Sync, R: Send>(
    jobs: &[J],
    f: impl Fn(&J) -> Result<R> + Sync,
) -> Vec<Result<R>> {
    let (a, b): (Vec<_>, Vec<_>) = jobs.iter().enumerate().partition(|(i, _)| i % 2 == 0);
    let run = |js: Vec<(usize, &J)>| js.into_iter().map(|(i, j)| (i, f(j))).collect::<Vec<_>>();
    let mut all: Vec<(usize, Result<R>)> = std::thread::scope(|sc| {
        let ha = sc.spawn(|| run(a));
        let hb = sc.spawn(|| run(b));
        let mut all = ha.join().unwrap_or_default();
        all.extend(hb.join().unwrap_or_default());
        all
    });
    all.sort_by_key(|p| p.0);
    all.into_iter().map(|p| p.1).collect()
}

/// One case of the table: profile, gear (and its name), spacing mm,
/// placement, case index (seeds).
type Job = (Profile, Gear, &'static str, u16, Placement, u64);

/// A case's figures for the reading: profile, X mm, distance-locked?,
/// spacing p95 %, position p95 vs measured mm, ground error mm, mean count
/// error.
type Summary = (Profile, u16, bool, f64, f64, f64, f64);

/// The section; returns its run time, s.
pub fn section(doc: &mut String, img: &std::path::Path) -> Result<f64> {
    use std::fmt::Write as _;
    let started = std::time::Instant::now();
    let _ = write!(
        doc,
        "## 9. Distance-locked vs speed-following placement\n\n\
         Profile A, Speed-Adaptive, the product's closed loop (`Supervisor`) on the machine \
         model with the landing scatter **off** (`plant_scatter_m` 0: the figures are the \
         control's). Per case {ROWS} rows of {ROW_M:.0} m from rest (the drum started with \
         the tractor, as §3); the same seeds for both modes (row r of case c: \
         `8000 + 100·c + r`). Travel-speed profiles (`machine_sim::Config`): the default \
         terrain (§3's noise); `hills()` — random steps of ±20 % around the gear's speed \
         (one every 3 s on average), chassis τ 0.5 s; `stop_and_go()` — to rest for 2 s \
         every 10 s, chassis τ 0.5 s, default terrain. The first plant's place is one \
         spacing X plus one Hall pitch (25.1 mm) past the first Hall edge after Start \
         (docs/placement.md), then one every X.\n\n\
         Columns: spacing CV and p95 of |spacing − X| / X over all spacings of the six rows; \
         share of spacings outside ±5 %; count error = plants on the row's 70 m − 70 m / X \
         (mean and worst row); position error of each partition = the ground distance \
         measured by the firmware when it left − its place (*vs measured*), and of each \
         plant = where it landed − its place on the true ground, counted from the true \
         position of the first Hall edge (*vs true*: the Hall measurement's own error — \
         k1·k2 tables against the model's varying slip — stays in it); mean, p95 |·| and \
         max |·|, mm; ground err = Hall-measured − true ground at the row's end (worst \
         row), mm; first plant \
         = worst |error| of the first plant over the rows (vs true); drift = mean error \
         of the last 50 partitions − first 50 (vs measured, worst row); alarms = rows with \
         any alarm.\n\n\
         | profile | X, gear | mode | CV % | p95 spacing err % | outside ±5 % | count err (worst) | pos. err vs measured: mean / p95 / max mm | vs true: mean / p95 / max mm | ground err mm | first plant mm | drift mm | alarms |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    );
    let mut jobs: Vec<Job> = Vec::new();
    let mut ci = 0u64;
    for profile in Profile::ALL {
        for (gear, gname, x) in CASES {
            for placement in [Placement::SpeedFollowing, Placement::DistanceLocked] {
                jobs.push((profile, gear, gname, x, placement, ci));
            }
            ci += 1;
        }
    }
    // Two threads: the cases are independent.
    let results = on_two_threads(&jobs, |j| case(j.4, j.0, j.1, j.3, j.5, Source::HALL));
    if results.len() != jobs.len() {
        return Err("placement bench: a worker failed".into());
    }
    let mut traces = Vec::new();
    let mut checks = Vec::new();
    // (profile, X mm, distance-locked?) → (spacing p95 %, pos. p95 vs measured
    // mm, ground err mm, mean count err).
    let mut summary: Vec<Summary> = Vec::new();
    for (j, res) in jobs.iter().zip(results) {
        let (profile, _gear, gname, x, placement, _) = *j;
        let mut s = res?;
        let Figures {
            cv,
            p95s,
            outside,
            cmean,
            cworst,
            measured: (mm, pm, xm),
            truth: (mt, pt, xt),
            gerr,
            first,
            drift,
        } = figures(&s, x);
        let mode = match placement {
            Placement::DistanceLocked => "**distance-locked**",
            Placement::SpeedFollowing => "speed-following",
        };
        let _ = writeln!(
            doc,
            "| {} | {} cm, {gname} | {mode} | {cv:.2} | {p95s:.2} | {outside:.2} % | {cmean:+.1} ({cworst:+.0}) | {mm:+.1} / {pm:.1} / {xm:.1} | {mt:+.1} / {pt:.1} / {xt:.1} | {gerr:+.0} | {first:.1} | {drift:+.1} | {} |",
            profile.name(),
            x / 10,
            s.alarms
        );
        summary.push((
            profile,
            x,
            placement == Placement::DistanceLocked,
            p95s,
            pm,
            gerr,
            cmean,
        ));
        if placement == Placement::DistanceLocked {
            checks.push((profile, x, gname, first, pm, drift, cworst, p95s, s.alarms));
        }
        if gname == "Low 2" && x == 70 {
            traces.push((profile, placement, std::mem::take(&mut s.trace)));
        }
    }
    // Plots: the position error along the first row, both modes, per profile.
    for profile in Profile::ALL {
        let mut series = Vec::new();
        let mut lo = -5.0f64;
        let mut hi = 5.0f64;
        for (i, (p, pl, tr)) in traces.iter().enumerate() {
            if *p != profile {
                continue;
            }
            for (_, e) in tr {
                lo = lo.min(*e);
                hi = hi.max(*e);
            }
            series.push(super::svg::Series {
                name: match pl {
                    Placement::DistanceLocked => "distance-locked".into(),
                    Placement::SpeedFollowing => "speed-following".into(),
                },
                colour: super::svg::PALETTE[i % 2],
                points: tr.clone(),
                dashed: *pl == Placement::SpeedFollowing,
            });
        }
        let step = if hi - lo > 100.0 {
            20.0
        } else if hi - lo > 40.0 {
            10.0
        } else {
            5.0
        };
        let lo = (lo / step).floor() * step;
        let hi = (hi / step).ceil() * step;
        let slug = match profile {
            Profile::Default => "default",
            Profile::Hills => "hills",
            Profile::StopGo => "stop-go",
        };
        let chart = super::svg::Chart {
            title: format!(
                "Position error along a row, 7 cm, Low 2, {}",
                profile.name()
            ),
            x_label: "place of the plant, m".into(),
            y_label: "ground at leaving − place, mm (measured ground)".into(),
            x: (0.0, ROW_M),
            y: (lo, hi),
            x_ticks: super::svg::ticks(0.0, ROW_M, 10.0),
            y_ticks: super::svg::ticks(lo, hi, step),
            series,
            bars: Vec::new(),
            v_lines: Vec::new(),
            h_lines: vec![(0.0, String::new())],
        };
        super::write_file(&img.join(format!("placement-{slug}.svg")), &chart.render())?;
        let _ = write!(
            doc,
            "\n![Position error, {}](img/placement-{slug}.svg)\n",
            profile.name()
        );
    }
    // The targets for distance-locked, case by case.
    let _ = write!(
        doc,
        "\nTargets for distance-locked (first plant ±3 mm; phase vs measured \
         ground p95 ≤ 5 mm and no drift; count within one plant of 70 m / X; hills p95 \
         |spacing error| ≤ 1.0 % at 7 cm; stop-and-go ≤ 3 % with no alarm):\n\n\
         | profile | X, gear | first ≤ 3 mm | p95 vs measured ≤ 5 mm | drift ≤ 2 mm | count within 1 | spacing p95 target | no alarm |\n|---|---|---|---|---|---|---|---|\n"
    );
    let yes = |b: bool| if b { "yes" } else { "**no**" };
    for &(profile, x, gname, first, pm, drift, cworst, p95s, alarms) in &checks {
        let sp = match (profile, x) {
            (Profile::Hills, 70) => format!("{p95s:.2} % ≤ 1.0: {}", yes(p95s <= 1.0)),
            (Profile::StopGo, _) => format!("{p95s:.2} % ≤ 3: {}", yes(p95s <= 3.0)),
            _ => "—".into(),
        };
        let _ = writeln!(
            doc,
            "| {} | {} cm, {gname} | {first:.1}: {} | {pm:.1}: {} | {drift:+.1}: {} | {cworst:+.0}: {} | {sp} | {} |",
            profile.name(),
            x / 10,
            yes(first <= 3.0),
            yes(pm <= 5.0),
            yes(drift.abs() <= 2.0),
            yes(cworst.abs() <= 1.0 + 1e-9),
            yes(alarms == 0)
        );
    }
    // The reading, from the figures above.
    let range = |f: &dyn Fn(&Summary) -> Option<f64>| {
        let v: Vec<f64> = summary.iter().filter_map(f).collect();
        (
            v.iter().copied().fold(f64::INFINITY, f64::min),
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        )
    };
    let (pm_lo, pm_hi) = range(&|r| (r.0 != Profile::StopGo && r.2).then_some(r.4));
    let (sf_lo, sf_hi) = range(&|r| (r.0 != Profile::StopGo && !r.2).then_some(r.4));
    let (g_lo, g_hi) = range(&|r| Some(r.5));
    let (h7d_lo, h7d_hi) = range(&|r| (r.0 == Profile::Hills && r.1 == 70 && r.2).then_some(r.3));
    let (h7s_lo, h7s_hi) = range(&|r| (r.0 == Profile::Hills && r.1 == 70 && !r.2).then_some(r.3));
    let (sg_lo, sg_hi) = range(&|r| (r.0 == Profile::StopGo && r.2).then_some(r.4));
    let (sgs_lo, sgs_hi) = range(&|r| (r.0 == Profile::StopGo && r.2).then_some(r.3));
    let (c7_lo, c7_hi) = range(&|r| (r.1 == 70 && r.2).then_some(r.6));
    let first_ok = checks.iter().filter(|c| c.3 <= 3.0).count();
    let first_worst = checks.iter().map(|c| c.3).fold(0.0f64, f64::max);
    let _ = write!(
        doc,
        "\nReading. **Phase.** Outside stop-and-go the distance-locked belt holds the \
         measured ground within p95 {pm_lo:.1}–{pm_hi:.1} mm with no drift, where \
         speed-following leaves {sf_lo:.0}–{sf_hi:.0} mm and drifts by tens of mm over the \
         row. The first plant is within ±3 mm of its place in {first_ok} of the {} \
         distance-locked cases, worst {first_worst:.1} mm (at Low 2: the drum starts \
         from rest at the second Hall edge and the phase loop has one spacing, 0.5 s, to \
         absorb its start lag). **The measured ground** (docs/placement.md, \
         \"Positions\") is exact at each Hall edge and moves on between edges at the last \
         M/T window's speed, up to the next edge's position. \
         **Against the true ground** every row carries the Hall measurement's own \
         error: the measured distance ends {g_lo:+.0} … {g_hi:+.0} mm off the true 70 m \
         (the k1·k2 tables against the model's slip), in both modes; \
         distance-locked removes the control's share, not the sensor's. **Count**: the \
         first place is X + 25 mm past the first Hall edge, which itself is 0–25 mm past \
         the Start point, so a 70 m row holds one place less than 70 m / X; add the \
         sensor's −0.07 … −0.14 % (up to 1.4 plants of 7 cm) and distance-locked rows at 7 cm come \
         out {c7_lo:+.1} … {c7_hi:+.1} plants: the target \"within one plant\" holds \
         against the measured distance, not against the true one at 7 cm. The first \
         place stays where it is: at X past the Start point it would ask the drum, which \
         learns the speed at the second edge (25–50 mm past Start), to lay 50 mm of belt \
         over the next 20–45 mm of ground at 7 cm (1.6–3.5 × the matched speed, beyond \
         n_max at Low 2), and half a pitch earlier gains 0.2 plant on average, not the \
         1–2 missing. **Hills spacing** (p95 at 7 cm): distance-locked \
         {h7d_lo:.2}–{h7d_hi:.2} %, speed-following {h7s_lo:.2}–{h7s_hi:.2} %: the 1.0 % \
         target is not reached. The same rows with the model's error sources switched \
         off in turn (bench variants, not in the table): without the Hall gear's ±2 % \
         tooth errors (`hall_pitch_error` 0) 2.53 / 1.69 %; without them and without the \
         belt's and track's slip noise 2.41 / 1.64 %; without the random speed steps \
         (`terrain_step_amplitude` 0) ≈ 1.0 % (measured with the predictor's speed in the ground). What is left \
         is the speed steps: the gear reports the ground every 25 mm (0.30 s at Low 1, \
         0.18 s at Low 2), a step of up to 40 % of v through τ 0.5 s changes the speed by \
         up to 0.8·v per second, and between edges the ground is extrapolated at the last \
         gap's mean speed, so by the next edge it is off by up to ½·a·t² (t = 0.45 s, \
         0.27 s with the half gap of age: 7 mm and 4 mm for the largest steps); the belt \
         follows that ground until the edge shows the error. Carrying the speed along \
         its slope (second order) would remove part of it on a perfect gear, but on this \
         gear the slope of two single-gap speeds is mostly the tooth errors: in the \
         ground (the predictor's speed × the time since the edge, with nominal tooth \
         pitches) it gave 2.95 / 1.91 %; in the feed-forward it is worth its \
         noise (the M/T value alone there: hills 3.43 / 2.61 %, default terrain 1.53 / \
         1.35 %; the slope over two windows: 3.22 / 2.15 % and 1.86 / 1.67 %); the phase \
         loop's time constant does not move it (0.25 s: 2.82 / 1.92 %). The gear's \
         tooth errors are learnt under the varying speed and each edge counts at its \
         learnt pitch without the table's first harmonic, which the learning cannot \
         tell from a speed ripple (docs/kinematics.md); that does not take the \
         hills below 2.5 % at 7 cm Low 1: reaching 1 % there needs a finer ground sensor (a Hall gear of 100 teeth, or profile B's \
         600 ppr encoder). **Stop-and-go**: the phase against the measured ground is \
         {sg_lo:.1}–{sg_hi:.1} mm p95 and the spacing p95 {sgs_lo:.0}–{sgs_hi:.0} %, \
         beyond the targets of 5 mm and 3 %, with no alarm. Followed step by step on one \
         row (7 cm, Low 2, seed 8900): (1) while the tractor slows to rest (τ 0.5 s from \
         0.14 m/s: 70 mm of ground, under three teeth) the drum's feed-forward follows \
         the lagging M/T speed and the phase loop may slow it by at most 33 % of that (the \
         1.5 X miss rule), so the belt ends up to 30 mm ahead of the measured ground and \
         the last plant before the rest lands ≈ 10 mm early (its spacing −20 %); letting \
         the loop stop the drum (−100 %) halves that lead, but the restart's lag then \
         shows in full (phase p95 16.0 / 24.6 / 16.1 / 21.5 mm against 7.4 / 17.0 / 6.7 / \
         15.9 mm): not taken. (2) A 2 s rest is often shorter than the estimator's 1.5 s \
         stop timeout counted from the last edge before it, so the first edge after the \
         rest closes an M/T window that spans the rest: the first speed is a fraction of \
         the real one, the drum starts late and is ≈ 25 mm behind at the next edge. A rest (travel speed 0, or no edge for 1 s) \
         gives the next plant the first plant's allowance (+100 %, T/2), so that lag is \
         caught up before it instead of over half a metre of 0.91 X spacings (phase p95 \
         5.3 / 11.9 / 4.8 / 8.1 mm with the 1 s rule, 5.4 / 16.6 / 4.8 / 15.5 mm with travel \
         speed 0 alone). Tried and not taken: starting the drum at the first edge after a rest \
         with the speed of the run before it, at most one gap / time since the edge \
         (phase p95 6.0 / 17.3 / 5.2 / 14.9 mm, spacing p95 30.3 / 30.5 / 10.5 / 13.8 % \
         against 6.0 / 16.8 / 5.4 / 16.3 mm and 29.6 / 29.8 / 11.1 / 12.9 %: the belt is \
         then ahead while the tractor is still slow); absorbing a lag after a rest in one \
         long spacing by re-phasing the plan (the realign machinery) instead of catching \
         it up: spacing p95 34.1 / 30.8 / 13.5 / 14.7 % and the count −9.2 / −4.8 / −4.1 / \
         −1.9 plants (each re-phase moves every later place and drops part of a plant): \
         worse on every figure but the share outside ±5 % at 7 cm. A 3 % spacing at 7 cm \
         is 2 mm, and where the tractor stands between two teeth is unknown by up to 25 mm: \
         with this sensor the stop-and-go targets are out of reach. The stop-and-go phase \
         figures are decided by the few partitions that leave while the tractor slows to \
         rest (those beyond 5 mm are 5 % of them): the same rows started 0.17–0.77 s later \
         give a p95 against the measured ground at 18 cm Low 1 of 3.7–5.8 mm (6 rows) and \
         4.4–5.3 mm (30 rows), and the worst row's drift moves by ±1.5 mm, so differences \
         below that between two versions are sampling, not control.\n",
        checks.len()
    );
    let secs = started.elapsed().as_secs_f64();
    let _ = write!(
        doc,
        "\nThis section ran {} rows in {secs:.0} s (two threads).\n\n",
        jobs.len() as u64 * ROWS
    );
    Ok(secs)
}
