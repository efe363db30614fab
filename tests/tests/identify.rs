//! The drum drive's identification (page 9) end to end on the QEMU board:
//! a machine whose drum drive is not the default one (the field report:
//! "the loop oscillated on a slower drive"), identified through the
//! touchscreen, saved, used, and still there after a reboot.
//!
//! The simulated drive: τ 60 ms (2.4 × the default 25 ms), dead time 12 ms
//! (default 5), 38.00 r/min at full duty (default 44.70) — scenario words
//! `drive_tau`, `drive_dead`, `drive_nmax` of the QEMU board. The expected
//! values are those scenario numbers, not the firmware's. Tolerances: the
//! host tests' worst identification errors over 45 model drives (n_max
//! 0.2 %, τ 6.3 %, dead time 1.3 ms, docs/fuzzy-pid.md) with room for the
//! default noise model's ±0.3 % speed ripple and ±5 % seedling load: n_max
//! 1 %, τ 10 %, dead time 3 ms.

use std::path::PathBuf;
use std::time::Duration;

use qemu_tests::{sim_samples, Bench, BootOptions};

/// The operator empties the belt before identifying (page 9's message):
/// `load=0`, no seedlings' load; the speed ripple and noise stay.
const SCENARIO: [&str; 5] = [
    "gear=2",
    "drive_tau=60",
    "drive_dead=12",
    "drive_nmax=3800",
    "load=0",
];

fn boot(run_ms: u32, flash: PathBuf) -> Bench {
    let options = BootOptions {
        run_ms: Some(run_ms),
        flash: Some(flash),
        scenario: SCENARIO.iter().map(|s| s.to_string()).collect(),
        ..BootOptions::default()
    };
    let mut bench = Bench::boot(&options).expect("boot QEMU");
    // Firmware time, not host time: the boot handshake is done by then.
    bench.pump(Duration::from_secs(2)).unwrap();
    assert_eq!(
        bench.screen.page(),
        1,
        "the screen never reached the mode page"
    );
    bench
}

/// Mode page → settings (page 6) → drive (page 9).
fn to_drive_page(bench: &mut Bench) {
    bench.tap("bset").unwrap();
    assert_eq!(bench.screen.page(), 6);
    bench.tap("bdrive").unwrap();
    bench.pump(Duration::from_millis(200)).unwrap();
    assert_eq!(bench.screen.page(), 9);
}

/// The firmware's log without the simulator's lines, for failure messages.
fn events(bench: &Bench) -> Vec<String> {
    bench
        .fw
        .logs()
        .into_iter()
        .filter(|l| !l.contains("sim:"))
        .collect()
}

/// The drive shown on page 9: (n_max r/min, τ ms, dead time ms).
fn shown(bench: &Bench) -> (f64, f64, f64) {
    let v = |n: &str| f64::from(bench.screen.value(n).unwrap_or(-1));
    (v("xnmax") / 100.0, v("xtau") / 10.0, v("xdead") / 10.0)
}

#[test]
fn a_slower_drive_is_identified_on_the_screen_saved_used_and_kept_after_a_reboot() {
    let flash =
        std::env::temp_dir().join(format!("transplanter-identify-{}.bin", std::process::id()));
    let _ = std::fs::remove_file(&flash);
    let mut bench = boot(40_000, flash.clone());
    to_drive_page(&mut bench);
    // Before: the default drive is in force.
    let (n0, tau0, dead0) = shown(&bench);
    assert!(
        (n0 - 44.70).abs() < 0.01 && (tau0 - 25.0).abs() < 0.1 && (dead0 - 5.0).abs() < 0.1,
        "{n0} {tau0} {dead0}"
    );

    bench.tap("bident").unwrap();
    assert_eq!(
        bench.screen.value("nidstate"),
        Some(1),
        "tmsg {:?}",
        bench.screen.text("tmsg")
    );
    // The identification takes 7 s of drum steps.
    bench.pump(Duration::from_secs(9)).unwrap();
    assert_eq!(
        bench.screen.value("nidstate"),
        Some(2),
        "page {}, log: {:#?}",
        bench.screen.page(),
        events(&bench)
    );
    let (n, tau, dead) = shown(&bench);
    eprintln!("identified: n_max {n:.2} r/min, tau {tau:.1} ms, dead time {dead:.1} ms");
    assert!((n - 38.0).abs() / 38.0 <= 0.01, "n_max {n}");
    assert!((tau - 60.0).abs() / 60.0 <= 0.10, "tau {tau}");
    assert!((dead - 12.0).abs() <= 3.0, "dead time {dead}");

    // Save: used from now on. Then a Fixed 20 r/min run on it.
    bench.tap("bidsave").unwrap();
    bench.pump(Duration::from_millis(500)).unwrap();
    // Before the fix: a HardFault here (the controller was rebuilt in the
    // screen task; with the control task preempting it the QEMU board's
    // stack overflowed).
    assert_eq!(bench.screen.text("tmsg"), Some("Settings saved"));
    assert!(
        !bench
            .fw
            .logs_caught_up()
            .iter()
            .any(|l| l.contains("HardFault")),
        "{:#?}",
        events(&bench)
    );
    bench.tap("bback").unwrap();
    bench.tap("bback").unwrap();
    assert_eq!(bench.screen.page(), 1);
    bench.tap("bfixed").unwrap();
    bench.enter("nspeed", 2000, "bapply").unwrap();
    bench.tap("bstart").unwrap();
    bench.pump(Duration::from_secs(6)).unwrap();
    let logs = bench.fw.logs_caught_up();
    assert!(
        !logs.iter().any(|l| l.contains("unstable")),
        "instability on the identified drive: {:?}",
        logs.iter()
            .filter(|l| l.contains("unstable"))
            .collect::<Vec<_>>()
    );
    let start = logs
        .iter()
        .find(|l| l.contains("drum: Running"))
        .and_then(|l| qemu_tests::log_time_ms(l))
        .expect("the drum started");
    // The last 3 s: mean true drum speed within 0.5 % of 20 r/min (the
    // Fixed-mode test's bound on the default drive).
    let tail: Vec<f64> = sim_samples(&logs)
        .into_iter()
        .filter(|s| s.t_ms >= start + 3000)
        .map(|s| s.drum_rpm)
        .collect();
    assert!(tail.len() >= 20, "{} samples", tail.len());
    let mean = tail.iter().sum::<f64>() / tail.len() as f64;
    eprintln!(
        "Fixed 20 r/min on the identified drive: mean {mean:.3} r/min over {} samples",
        tail.len()
    );
    assert!((mean - 20.0).abs() / 20.0 <= 0.005, "mean {mean}");
    drop(bench);

    // After a reboot from the same flash: the identified drive is shown.
    let mut again = boot(5_000, flash.clone());
    to_drive_page(&mut again);
    let kept = shown(&again);
    assert_eq!(kept, (n, tau, dead), "after the reboot");
    let _ = std::fs::remove_file(&flash);
}
