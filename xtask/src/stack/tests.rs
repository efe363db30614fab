//! The analysis of small images assembled from the fixtures in
//! `xtask/tests/data/stack/` (each states the depths it should give), with
//! the pinned toolchain's `rustc` and `rust-lld`.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::{analyse, Chip, Level, Report};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/stack")
}

/// Assembles and links `name.s` into an ELF (a `no_std` crate holding it
/// as `global_asm!`).
fn build(name: &str) -> PathBuf {
    static BUILDS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("xtask-stack-{}-{n}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let source = fixtures().join(format!("{name}.s"));
    let main = dir.join("main.rs");
    std::fs::write(
        &main,
        format!(
            "#![no_std]\n#![no_main]\ncore::arch::global_asm!(include_str!({:?}), options(raw));\n\
             #[panic_handler]\nfn panic(_: &core::panic::PanicInfo) -> ! {{ loop {{}} }}\n",
            source.display()
        ),
    )
    .unwrap();
    let elf = dir.join(name);
    let out = Command::new("rustc")
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "--edition",
            "2021",
            "--crate-type",
            "bin",
            "--target",
            "thumbv7m-none-eabi",
        ])
        .args([
            "-C",
            "panic=abort",
            "-C",
            "opt-level=1",
            "-C",
            "debuginfo=0",
        ])
        .arg("-C")
        .arg(format!(
            "link-arg=-T{}",
            fixtures().join("link.ld").display()
        ))
        .arg("-o")
        .arg(&elf)
        .arg(&main)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rustc {name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    elf
}

fn chip() -> Chip {
    Chip {
        ram: 0x2000_0000..0x2000_2000,
        nvic_prio_bits: 4,
        overflow_on_purpose: &[],
    }
}

fn run(name: &str) -> Result<Report, String> {
    run_on(name, &chip())
}

fn run_on(name: &str, chip: &Chip) -> Result<Report, String> {
    let objdump = crate::llvm_tool("llvm-objdump").unwrap();
    let elf = build(name);
    let report = analyse(&elf, &objdump, chip);
    if let Some(dir) = elf.parent() {
        let _ = std::fs::remove_dir_all(dir);
    }
    report
}

fn entry<'a>(r: &'a Report, name: &str) -> &'a super::Entry {
    r.entries
        .iter()
        .find(|e| e.name.starts_with(name))
        .unwrap_or_else(|| panic!("no entry {name}: {:?}", r.entries))
}

#[test]
fn frames_calls_priorities_and_preemption() {
    let r = run("basic").unwrap();
    let reset = entry(&r, "Reset");
    assert_eq!((reset.depth.below, reset.depth.open), (104, Some(16)));
    assert_eq!(
        reset.path,
        [
            ("Reset".to_string(), 0),
            ("init".into(), 64),
            ("leaf".into(), 40)
        ]
    );
    let irq0 = entry(&r, "Irq0");
    assert_eq!(
        (irq0.level, irq0.depth.below),
        (Level::Priority(Some(0xe0), 0), 176)
    );
    let irq1 = entry(&r, "Irq1");
    assert_eq!(irq1.level, Level::Priority(Some(0xc0), 0));
    assert_eq!((irq1.depth.below, irq1.depth.open), (1216, Some(208)));
    let systick = entry(&r, "SysTick");
    assert_eq!(
        (systick.level, systick.depth.below),
        (Level::Priority(Some(0x80), 0), 8)
    );
    for fatal in ["HardFault", "NMI"] {
        let e = entry(&r, fatal);
        assert_eq!((e.depth.below, e.depth.fresh), (0, 72), "{fatal}");
    }
    assert_eq!(r.stack_size(), 4096);
    assert_eq!(r.worst, 1552, "{}", r.table());
    assert!(r.check_margin().is_ok());
}

#[test]
fn recursion_is_an_error_naming_the_function() {
    let e = run("recursion").unwrap_err();
    assert!(e.contains("recursion: countdown → countdown"), "{e}");
}

#[test]
fn a_function_that_overflows_on_purpose_counts_its_frame_not_its_recursion() {
    let chip = Chip {
        overflow_on_purpose: &["countdown"],
        ..chip()
    };
    let r = run_on("recursion", &chip).unwrap();
    let reset = entry(&r, "Reset");
    let names: Vec<&str> = reset.path.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names.last(), Some(&"countdown"), "{}", r.table());
}

#[test]
fn a_call_through_an_unresolved_pointer_reaches_every_stored_function() {
    let r = run("pointer").unwrap();
    let reset = entry(&r, "Reset");
    assert_eq!(reset.depth.below, 8 + 16 + 8 + 512, "{}", r.table());
    let names: Vec<&str> = reset.path.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["Reset", "dispatch", "(function pointer)", "big"]);
}

#[test]
fn recursion_through_a_pointer_is_an_error_naming_the_functions() {
    let e = run("pointer-recursion").unwrap_err();
    assert!(e.contains("recursion"), "{e}");
    assert!(
        e.contains("run") && e.contains("again") && e.contains("(function pointer)"),
        "{e}"
    );
}

#[test]
fn a_frame_sized_at_run_time_is_an_error_naming_the_function() {
    let e = run("unbounded").unwrap_err();
    assert!(e.contains("scratch") && e.contains("cannot bound"), "{e}");
}

#[test]
fn the_margin_rule() {
    assert_eq!(super::required_margin(15_656), 1_565);
    assert_eq!(super::required_margin(4_096), 1_024);
}

#[test]
fn measured_depths_within_the_static_worst_case() {
    let r = run("basic").unwrap();
    let log = |used: u32, size: u32| vec![format!("0.000 INFO  stack: {used} B used of {size} B")];
    assert!(super::check_measured(&r, &log(1200, 4096)).is_ok());
    let over = super::check_measured(&r, &log(1600, 4096)).unwrap_err();
    assert!(over.contains("misses a path"), "{over}");
    let other = super::check_measured(&r, &log(1200, 4000)).unwrap_err();
    assert!(other.contains("4096"), "{other}");
    assert!(super::check_measured(&r, &[]).is_err());
}

#[test]
fn an_unresolved_call_with_nothing_to_reach_is_an_error_naming_the_function() {
    let e = run("unresolved").unwrap_err();
    assert!(
        e.contains("dispatch+0x2") && e.contains("cannot resolve"),
        "{e}"
    );
}
