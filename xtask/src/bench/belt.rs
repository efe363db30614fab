//! Section 4: paper B's bench replicated on profile B's supervisor and the
//! machine model (X = 25 cm, B = 10 cm, 0.2 / 0.3 / 0.4 m/s), with and
//! without the roller-radius compensation of eq. 9.

use kinematics::profile_b::ProfileBSettings;
use machine_sim::{Config, Event, Inputs, Profile};
use supervisor::planter::{BeltPlanter, ProfileBConfig, ProfileBHardware, StepperCommand};

use crate::Result;

/// Paper B's figures: speed m/s, feeding-spacing error %, plant-spacing CV %.
const PAPER: [(f32, f64, f64); 3] = [(0.2, 5.1, 7.42), (0.3, 7.8, 9.34), (0.4, 11.4, 13.29)];
/// Ridges (seeds) per case, and metres of row each.
const RIDGES: u64 = 3;
const ROW_M: f64 = 30.0;

struct Row {
    error_pct: f64,
    cv_pct: f64,
    spacings: usize,
}

/// One row: the planter starts with the machine standing, then the tractor
/// travels at `v`; spacings after the first metre (the start-up).
fn row(v: f32, compensation: bool, lock: bool, seed: u64) -> Result<Row> {
    let config = ProfileBConfig::new(ProfileBSettings::default()).map_err(|e| e.to_string())?;
    let mut planter =
        BeltPlanter::new(config, ProfileBHardware::BOARD).map_err(|e| e.to_string())?;
    planter.set_radius_compensation(compensation);
    planter.set_position_lock(lock);
    let mut m = Config {
        profile: Profile::B,
        target_spacing_m: 0.25,
        seed,
        ..Config::default()
    }
    .build()
    .map_err(|e| e.to_string())?;
    let mut cmd = StepperCommand::OFF;
    let mut plants: Vec<f64> = Vec::new();
    planter.start();
    let mut first = true;
    while m.ground_position_m() < ROW_M + 1.0 {
        let inputs = Inputs {
            feed_step_rate_hz: cmd.feed_step_hz.to_f64() as f32,
            plant_step_rate_hz: cmd.plant_step_hz.to_f64() as f32,
            ..Inputs::default()
        };
        m.step_events(10_000, &inputs, &mut |e| {
            if let Event::Plant { ground_m, .. } = e {
                plants.push(ground_m);
            }
        });
        cmd = planter.control_step(m.ground_encoder_count(), m.feed_roller_turns());
        if first {
            m.set_travel_speed_m_s(v);
            first = false;
        }
    }
    let s: Vec<f64> = plants
        .windows(2)
        .filter(|w| w[0] >= 1.0)
        .map(|w| w[1] - w[0])
        .collect();
    let n = s.len() as f64;
    if n < 3.0 {
        return Err(format!(
            "profile B at {v} m/s planted {} seedlings",
            plants.len()
        ));
    }
    let mean = s.iter().sum::<f64>() / n;
    let sd = (s.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    Ok(Row {
        error_pct: (mean - 0.25).abs() / 0.25 * 100.0,
        cv_pct: sd / mean * 100.0,
        spacings: s.len(),
    })
}

/// Mean of the ridges of one case.
fn case(v: f32, compensation: bool, lock: bool, index: u64) -> Result<Row> {
    let mut sum = Row {
        error_pct: 0.0,
        cv_pct: 0.0,
        spacings: 0,
    };
    for ridge in 0..RIDGES {
        let r = row(v, compensation, lock, 4000 + 10 * index + ridge)?;
        sum.error_pct += r.error_pct / RIDGES as f64;
        sum.cv_pct += r.cv_pct / RIDGES as f64;
        sum.spacings += r.spacings;
    }
    Ok(sum)
}

/// Writes section 4.
pub fn section(doc: &mut String) -> Result {
    doc.push_str(
        "## 4. Profile B bench replica (paper B)\n\n\
         `supervisor::planter::BeltPlanter` (the firmware's profile B logic: windowed \
         ground speed from the 600 ppr encoder, the threshold-Y linkage, eq. 4 and eq. 9, \
         acceleration limits) against the machine model in profile B with its default \
         noise (terrain, slip), X = 25 cm, B = 10 cm and the other defaults of \
         `ProfileBSettings` (β 120°, N 2, r 25 mm, h 1 mm, Y 0.02 m/s). Each case is three \
         rows of 30 m (seeds 4000 + 10·case + row), spacings after the first metre. \
         Feeding-spacing error as paper B's Table 2: |mean spacing − X| / X; plant-spacing \
         CV as its Table 3: sample SD / mean. The QEMU test \
         `tests/tests/profile_b.rs` runs the same bench through the firmware. \
         \"Ours\" is position-locked feeding (the default: the belt fed since Start \
         kept at ground · B / X, docs/profile-b.md); \"linkage alone\" is paper B's speed \
         linkage without it, same seeds.\n\n\
         | travel speed | feeding-spacing error, ours (paper B) | plant-spacing CV, ours (paper B) | linkage alone: error / CV | without radius compensation: error / CV | spacings |\n\
         |---|---|---|---|---|---|\n",
    );
    let mut worst_gain = f64::INFINITY;
    for (i, (v, paper_err, paper_cv)) in PAPER.iter().enumerate() {
        let on = case(*v, true, true, 2 * i as u64)?;
        let free = case(*v, true, false, 2 * i as u64)?;
        let off = case(*v, false, true, 2 * i as u64 + 1)?;
        worst_gain = worst_gain.min(off.error_pct - on.error_pct);
        doc.push_str(&format!(
            "| {v:.1} m/s | {:.2} % ({paper_err} %) | {:.2} % ({paper_cv} %) | {:.2} % / {:.2} % | {:.1} % / {:.1} % | {} |\n",
            on.error_pct, on.cv_pct, free.error_pct, free.cv_pct, off.error_pct, off.cv_pct, on.spacings
        ));
    }
    doc.push_str(&format!(
        "\nReading: on the model, profile B beats paper B's bench at every speed, by a wide \
         margin. Most of the margin is the model's: it has no seedling slipping in the clamp, \
         no belt stretch and no lost steps, which are what spread paper B's spacings. What \
         the firmware does add is measurable: without the roller-radius compensation of \
         eq. 9 (r for every turn j) the feeding spacing drifts as the belt winds up, and the \
         error is at least {worst_gain:.0} percentage points worse in every case. With the \
         linkage alone most of the CV is the threshold Y (0.02 m/s) letting the terrain's \
         ±3 % speed variation through and the 200 ms speed window's lag; the position lock \
         feeds that lag back (at most ±10 % of the rate, taken up over 250 ms), which is \
         what the difference between the two columns measures.\n\n"
    ));
    Ok(())
}
