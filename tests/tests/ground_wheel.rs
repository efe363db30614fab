//! Machine A's ground wheel through the firmware on the QEMU board: the
//! saved settings make the wheel the travel source with the Hall gear as
//! its cross-check (both), the simulated machine's wheel counts in the
//! board's TIM4 stand-in, and the operator sees the live slip and, when the
//! wheel stops turning while the track moves on, the warning.
//!
//! Expected values: the machine's true track slip from paper A's Table 12
//! as the simulator applies it (`machine_sim::tables`, scaled by the
//! scenario's `slip=`), the plants the simulated belt drops and the ground
//! it covers (its `sim:` lines); times are the firmware's own log stamps.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use hmi_proto::screen::{Spacing, TravelSource};
use kinematics::consts::Gear;
use qemu_tests::{log_time_ms, number_after, sim_samples, Bench, BootOptions};
use supervisor::drum::alarm::{HALL_STOPPED_TEXT, WHEEL_STOPPED_TEXT};
use supervisor::settings::wheel::GroundWheelSettings;
use supervisor::settings::Settings;

#[path = "support/pages.rs"]
mod pages;

/// A flash file holding `settings` (a saved record).
fn flash_with(name: &str, settings: &Settings) -> PathBuf {
    let path = std::env::temp_dir().join(format!("ground-wheel-{name}-{}.bin", std::process::id()));
    std::fs::write(&path, pages::pages_with(settings)).unwrap();
    path
}

/// The first log line holding `needle` at or after `from_ms`: its time.
fn first_after(logs: &[String], from_ms: u32, needle: &str) -> Option<(u32, String)> {
    logs.iter()
        .filter(|l| l.contains(needle))
        .filter_map(|l| Some((log_time_ms(l)?, l.clone())))
        .find(|(t, _)| *t >= from_ms)
}

/// Planting goes on over `from_ms..to_ms`: no change of the drum's state,
/// and a plant per 35 cm of the true ground (within 1.5: a window cuts a
/// row of evenly spaced plants at any phase, ± one, plus the placement's
/// own millimetres).
fn assert_planting(logs: &[String], from_ms: u32, to_ms: u32, what: &str) {
    let changes: Vec<&String> = logs
        .iter()
        .filter(|l| l.contains("drum: "))
        .filter(|l| log_time_ms(l).is_some_and(|t| t > from_ms && t <= to_ms))
        .collect();
    assert!(
        changes.is_empty(),
        "{what}: the drum changed state: {changes:?}"
    );
    let samples = sim_samples(logs);
    let window: Vec<_> = samples
        .iter()
        .filter(|s| (from_ms..=to_ms).contains(&s.t_ms))
        .collect();
    let (first, last) = (window.first().unwrap(), window.last().unwrap());
    let plants = f64::from(last.plants - first.plants);
    let ground = last.ground_m - first.ground_m;
    let expected = ground / 0.35;
    eprintln!("{what}: {plants} plants over {ground:.3} m of ground ({expected:.2} at 35 cm)");
    assert!(expected > 2.0, "{what}: the tractor barely moved");
    assert!(
        (plants - expected).abs() <= 1.5,
        "{what}: {plants} plants over ground for {expected:.2}"
    );
}

/// Both sensors, High 3 at 35 cm (the gear fast enough to measure the
/// slip over a few metres; 35 cm is allowed up to ≈ 4 km/h), a track that
/// slips twice paper A's Table 12 (`slip=200`: not what the firmware's k2
/// table says), noiseless. The wheel stops turning at 4 s (`wheel_loss`)
/// while the track runs on and turns again at 6.5 s (`wheel_back`); the
/// Hall gear goes silent at 7.5 s (`hall_loss`) while the wheel rolls on.
/// 9.5 s of firmware time.
#[test]
fn both_sources_show_the_live_slip_and_a_wheel_or_hall_gear_that_stops_is_warned_of_within_half_a_second_while_planting_goes_on(
) {
    const LOSS_MS: u32 = 4_000;
    const BACK_MS: u32 = 6_500;
    const HALL_LOSS_MS: u32 = 7_500;
    const SLIP_SCALE: f64 = 2.0;
    let settings = Settings {
        spacing: Spacing::new(350).unwrap(),
        gear: Gear::High3,
        ground_wheel: GroundWheelSettings {
            source: TravelSource::Both,
            ..GroundWheelSettings::default()
        },
        ..Settings::default()
    };
    let flash = flash_with("both", &settings);
    let options = BootOptions {
        run_ms: Some(9_500),
        flash: Some(flash.clone()),
        scenario: vec![
            "gear=6".to_string(),
            "noise=0".to_string(),
            "slip=200".to_string(),
            format!("wheel_loss={LOSS_MS}"),
            format!("wheel_back={BACK_MS}"),
            format!("hall_loss={HALL_LOSS_MS}"),
        ],
        ..BootOptions::default()
    };
    let mut bench = Bench::boot(&options).expect("boot QEMU");
    assert!(
        bench
            .pump_until(Duration::from_secs(30), |s| s.page() == 1)
            .unwrap(),
        "the screen never reached the mode page"
    );
    bench.tap("badapt").unwrap();
    bench.tap("bstart").unwrap();
    // To the run limit, in firmware periods (host time only guards a
    // hang), keeping every alarm text the screen showed.
    let guard = Instant::now() + Duration::from_secs(300);
    let mut shown: Vec<String> = Vec::new();
    while !bench
        .fw
        .logs_caught_up()
        .iter()
        .any(|l| l.contains("run limit of"))
    {
        assert!(Instant::now() < guard, "the run never ended");
        bench.pump(Duration::from_millis(50)).unwrap();
        if let Some(t) = bench.screen.text("talarm") {
            if shown.last().is_none_or(|l| l != t) {
                shown.push(t.to_string());
            }
        }
    }
    let (status, logs) = bench.fw.wait_exit(Duration::from_secs(30)).unwrap();
    let _ = std::fs::remove_file(&flash);
    assert!(status.success(), "QEMU: {status}");

    // The wheel in use, and the live slip before the wheel stopped against
    // the model's (Table 12 at High 3's wheel speed, × 2).
    let (on_wheel, _) = first_after(&logs, 0, "travel source: GroundWheel")
        .expect("the firmware never said the wheel is in use");
    let slips: Vec<(u32, f64)> = logs
        .iter()
        .filter(|l| l.contains("track slip: "))
        .filter_map(|l| Some((log_time_ms(l)?, number_after(l, "track slip: ")? / 10.0)))
        .filter(|(t, _)| *t < LOSS_MS)
        .collect();
    let wheel_kmh = Gear::High3.preset().actual_kmh_f64;
    let true_slip =
        SLIP_SCALE * f64::from(machine_sim::tables::track_slip_at(wheel_kmh as f32)) * 100.0;
    eprintln!(
        "wheel in use at {on_wheel} ms; live slip (ms, %): {slips:?}; the model's {true_slip:.2} %"
    );
    let &(_, last_slip) = slips.last().expect("no live slip before the wheel stopped");
    assert!(
        (last_slip - true_slip).abs() <= 0.5,
        "live slip {last_slip} % against the model's {true_slip:.2} %"
    );

    // The wheel stops: the Hall gear stands in and the warning comes
    // within 0.5 s, on the screen and in the log.
    let (stand_in, _) = first_after(&logs, LOSS_MS, "travel source: HallStandIn")
        .expect("the Hall gear never stood in");
    let (warned, _) = first_after(&logs, LOSS_MS, "alarm: GroundWheelStopped")
        .expect("no warning of the stopped wheel");
    eprintln!(
        "wheel stopped at {LOSS_MS} ms: Hall gear in at {stand_in} ms, warning at {warned} ms"
    );
    assert!(stand_in <= warned, "stand-in at {stand_in} ms");
    assert!(
        warned > LOSS_MS && warned <= LOSS_MS + 500,
        "warning at {warned} ms"
    );
    assert_planting(&logs, warned, BACK_MS, "on the Hall gear");

    // The wheel turns again: back on it (after 0.2 s of rolling).
    let (back, _) =
        first_after(&logs, BACK_MS, "travel source: GroundWheel").expect("never back on the wheel");
    eprintln!("wheel turns again at {BACK_MS} ms: on the wheel at {back} ms");
    assert!(back <= BACK_MS + 500, "back on the wheel at {back} ms");

    // The Hall gear goes silent: warned of within 0.5 s, the wheel goes on.
    let (hall, _) = first_after(&logs, HALL_LOSS_MS, "alarm: HallGearStopped")
        .expect("no warning of the silent Hall gear");
    eprintln!(
        "Hall gear silent at {HALL_LOSS_MS} ms: warning at {hall} ms; screen showed {shown:?}"
    );
    assert!(
        hall > HALL_LOSS_MS && hall <= HALL_LOSS_MS + 500,
        "warning at {hall} ms"
    );
    assert!(
        first_after(&logs, HALL_LOSS_MS, "travel source: ").is_none(),
        "the wheel stays the source"
    );
    assert_planting(&logs, hall, 9_500, "on the wheel alone");
    let wheel_at = shown.iter().position(|t| t == WHEEL_STOPPED_TEXT);
    let hall_at = shown.iter().position(|t| t == HALL_STOPPED_TEXT);
    assert!(
        wheel_at.is_some() && hall_at > wheel_at,
        "the screen's alarms: {shown:?}"
    );
}
