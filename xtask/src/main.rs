//! `cargo xtask`: the project's one entry point.
//!
//! ```text
//! cargo xtask qemu [--seconds N]   the firmware in QEMU against the simulated machine, with its logs
//!                                  and a run report (target/report/qemu-run.html)
//! cargo xtask qemu --screen [--port P] [--seconds N]
//!                                  the same in real time, driven by a person from the browser screen
//! cargo xtask screen               build the browser screen (one HTML file) and print its path
//! cargo xtask screenshots          every page of the browser screen into docs/img
//! cargo xtask report CAPTURE.txt   a field capture (probe-rs run's decoded defmt) into a run report
//! cargo xtask test                 all host tests, then the firmware in QEMU driven from tests/
//! cargo xtask ci                   fmt, clippy (host and thumbv7m), test, release builds, size, QEMU smoke run
//! cargo xtask size                 flash, RAM and the static stack worst case of every image
//! cargo xtask flash                build and flash a real board with probe-rs
//! cargo xtask bench [--only NAME]  regenerate docs/PERFORMANCE.md (QEMU instruction counts, sizes);
//!                                  NAME: tables, placement, link, row (one section, into target/)
//! cargo xtask plan --spacing 7cm --speed 0.51km/h [--gear low2] [--arr N]
//! ```

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use qemu_tests::{images, workspace_root, BootOptions};

mod bench;
mod plan;
mod report;
mod screen;
mod stack;

type Result<T = ()> = std::result::Result<T, String>;

const TARGET: &str = "thumbv7m-none-eabi";

/// Flash and static-RAM budgets of every image: the 128 KB parts (RB, CB)
/// less the last 8 KB, which hold the settings (memory-stm32f103.x). Where
/// the bytes are: docs/firmware.md, "Memory and flash".
const FLASH_BUDGET: u64 = 120 * 1024;
/// The QEMU board's code budget (memory-qemu.x): its image also carries the
/// simulated machine, in the emulated part's larger flash.
const QEMU_FLASH_BUDGET: u64 = 256 * 1024;
const RAM_BUDGET: u64 = 8 * 1024;
/// The real board's code regions (memory-stm32f103.x): below the hole
/// that keeps the earlier layout's settings pages, and above it.
const STM32F103_CODE_REGIONS: [(&str, std::ops::Range<u64>); 2] = [
    ("below the hole", 0x0800_0000..0x0800_E000),
    ("above the hole", 0x0800_E800..0x0801_E000),
];

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (cmd, rest) = match args.split_first() {
        Some((cmd, rest)) => (cmd.as_str(), rest),
        None => ("help", &[][..]),
    };
    let result = match cmd {
        "qemu" => qemu(rest),
        "test" => test().map(|_| ()),
        "ci" => ci(),
        "size" => size(),
        "flash" => flash(),
        "plan" => plan::run(rest),
        "report" => report::run(rest),
        "screen" => screen::build().map(|p| println!("{}", p.display())),
        "screenshots" => screen::screenshots(),
        "bench" => bench::run(rest),
        "help" | "--help" | "-h" => {
            println!("{}", include_str!("usage.txt"));
            Ok(())
        }
        other => Err(format!(
            "unknown command `{other}`\n\n{}",
            include_str!("usage.txt")
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e}");
            ExitCode::FAILURE
        }
    }
}

pub(crate) fn root() -> PathBuf {
    workspace_root()
}

fn cargo() -> Command {
    let mut cmd = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cmd.current_dir(root());
    cmd
}

fn run(what: &str, cmd: &mut Command) -> Result {
    eprintln!("xtask: {what}");
    let status = cmd
        .status()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what}: {status}"))
    }
}

/// The firmware images, one per board: each carries both machines and the
/// drum driver's link (the settings choose).
#[derive(Clone, Copy, Debug)]
enum Board {
    Stm32f103,
    Qemu,
}

impl Board {
    const ALL: [Board; 2] = [Board::Stm32f103, Board::Qemu];

    fn name(self) -> &'static str {
        match self {
            Board::Stm32f103 => "stm32f103",
            Board::Qemu => "qemu",
        }
    }

    fn features(self) -> &'static [&'static str] {
        match self {
            Board::Stm32f103 => &["--no-default-features", "--features", "board-stm32f103"],
            Board::Qemu => &[
                "--no-default-features",
                "--features",
                qemu_tests::QEMU_FEATURES,
            ],
        }
    }

    /// The name its ELF is kept under (`target/images/<name>/firmware`:
    /// every image builds in the one target directory `target/firmware`,
    /// so the dependencies compile once; `qemu_tests::images`).
    fn image_name(self) -> &'static str {
        match self {
            Board::Stm32f103 => "stm32f103",
            Board::Qemu => qemu_tests::QEMU_IMAGE,
        }
    }

    fn elf(self) -> PathBuf {
        images::elf_path(self.image_name())
    }

    /// The chip it runs on, for the stack analysis: its RAM (the board's
    /// `memory*.x`) and the NVIC's priority bits.
    fn chip(self) -> stack::Chip {
        // Both boards have the RB's 20 KB (the QEMU board's memory-qemu.x
        // lays out netduino2's RAM like the RB's).
        stack::Chip {
            ram: 0x2000_0000..0x2000_0000 + 20 * 1024,
            nvic_prio_bits: 4,
            // The QEMU board's injected stack overflow (`stack_overflow=T`).
            overflow_on_purpose: match self {
                Board::Qemu => &["board::qemu::sim::exhaust_stack"],
                _ => &[],
            },
        }
    }

    fn build(self) -> Result<PathBuf> {
        let what = format!("build firmware, board {}", self.name());
        let lock = images::lock().map_err(|e| format!("{what}: {e}"))?;
        run(&what, &mut images::build_command(self.features()))?;
        images::keep(&lock, self.image_name()).map_err(|e| format!("{what}: {e}"))
    }

    fn clippy(self) -> Result {
        run(
            &format!("clippy firmware, board {}", self.name()),
            cargo()
                .args(["clippy", "-p", "firmware", "--release", "--target", TARGET])
                .args(self.features())
                .arg("--target-dir")
                .arg(images::target_dir())
                .args(["--", "-D", "warnings"]),
        )
    }
}

pub(crate) fn have(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
}

/// Installs the host tools the QEMU runs need when they are missing, so that
/// the README's two commands work on a fresh machine: QEMU from Debian's
/// packages (as root) and `defmt-print` from crates.io.
fn ensure_tools() -> Result {
    if !have("qemu-system-arm") {
        apt_install(&["qemu-system-arm"], "QEMU")?;
    }
    if !have("defmt-print") {
        run(
            "cargo install defmt-print (once, about 3 minutes)",
            Command::new("cargo").args(["install", "defmt-print", "--locked"]),
        )?;
    }
    ensure_twin_tools()?;
    screen::ensure_browser()?;
    ensure_peer_tools()?;
    ensure_linker()
}

/// The pymodbus release the independent ZLAC8015D peer is written for
/// (tests/peers/zlac8015d).
const PYMODBUS: &str = "pymodbus[serial]==3.16.1";

/// Whether python3 has pymodbus 3.16.1 and pyserial (the peer's serial
/// server).
fn have_pymodbus() -> bool {
    Command::new("python3")
        .args([
            "-c",
            "import sys, serial, pymodbus; sys.exit(pymodbus.__version__ != '3.16.1')",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The drive link's conformance test (crates/supervisor/tests/conformance.rs)
/// runs the master against an independent Modbus RTU slave on a pty pair:
/// `socat` (Debian's package) and pymodbus (PyPI), installed here when
/// missing.
fn ensure_peer_tools() -> Result {
    let socat = Command::new("socat")
        .arg("-V")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    if !socat {
        apt_install(&["socat"], "the drive link's conformance test")?;
    }
    if have_pymodbus() {
        return Ok(());
    }
    let pip = |extra: &[&str]| {
        Command::new("python3")
            .args(["-m", "pip", "install", "--quiet"])
            .args(extra)
            .arg(PYMODBUS)
            .status()
            .is_ok_and(|s| s.success())
    };
    // Debian's own python3 refuses pip outside a venv (PEP 668) unless told.
    if (pip(&[]) || pip(&["--break-system-packages"])) && have_pymodbus() {
        return Ok(());
    }
    Err(format!(
        "the drive link's conformance test needs `python3 -m pip install '{PYMODBUS}'`"
    ))
}

/// Whether a file name is one that bindgen (clang-sys) loads as libclang.
fn is_libclang(name: &str) -> bool {
    name.starts_with("libclang.so")
        || name.strip_prefix("libclang-").is_some_and(|rest| {
            rest.starts_with(|c: char| c.is_ascii_digit()) && rest.contains(".so")
        })
}

/// Whether the libclang that bindgen loads (for unicorn's build) is
/// installed: `libclang.so*` or `libclang-<version>.so*`, in the library
/// directories or an `llvm-*/lib` below them. `libclang-cpp.so` (which
/// `llvm-dev` brings) is another library: bindgen cannot load it.
fn have_libclang() -> bool {
    fn dir_has_libclang(dir: &Path) -> bool {
        std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .flatten()
            .any(|e| is_libclang(&e.file_name().to_string_lossy()))
    }
    [
        "/usr/lib",
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
    ]
    .iter()
    .any(|d| {
        let d = Path::new(d);
        dir_has_libclang(d)
            || std::fs::read_dir(d)
                .into_iter()
                .flatten()
                .flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with("llvm-"))
                .any(|e| dir_has_libclang(&e.path().join("lib")))
    })
}

/// The twin (tests/tests/twin_*.rs) builds unicorn from source: cmake and
/// libclang (Debian's `cmake libclang-dev`), installed here when missing.
fn ensure_twin_tools() -> Result {
    if have("cmake") && have_libclang() {
        return Ok(());
    }
    apt_install(&["cmake", "libclang-dev"], "the twin's unicorn build")
}

/// Installs Debian packages (as root; otherwise says what to run).
pub(crate) fn apt_install(packages: &[&str], what: &str) -> Result {
    let root = Command::new("id")
        .arg("-u")
        .output()
        .map(|o| o.stdout.starts_with(b"0"))
        .unwrap_or(false);
    let list = packages.join(" ");
    if !root {
        return Err(format!("{what} needs `sudo apt-get install {list}`"));
    }
    run(
        "apt-get update",
        Command::new("apt-get").args(["update", "-qq"]),
    )?;
    run(
        &format!("apt-get install {list} ({what})"),
        Command::new("apt-get")
            .args(["install", "-y", "-qq"])
            .args(packages)
            .env("DEBIAN_FRONTEND", "noninteractive"),
    )
}

/// The thumbv7m target and llvm-tools of rust-toolchain.toml. rustup adds
/// them only when it installs the toolchain itself; a machine that already
/// had the pinned release without them gets them here.
fn ensure_target() -> Result {
    let libdir = Command::new("rustc")
        .current_dir(root())
        .args(["--print", "target-libdir", "--target", TARGET])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()));
    if libdir.is_some_and(|dir| dir.is_dir()) {
        return Ok(());
    }
    run(
        "rustup toolchain install (the target and components of rust-toolchain.toml)",
        Command::new("rustup")
            .current_dir(root())
            // cargo sets it for xtask; without it rustup reads the file.
            .env_remove("RUSTUP_TOOLCHAIN")
            .args(["toolchain", "install"]),
    )
}

/// `flip-link`, the linker of every thumbv7m build (`.cargo/config.toml`),
/// and the target itself.
fn ensure_linker() -> Result {
    ensure_target()?;
    if !have("flip-link") {
        run(
            "cargo install flip-link (once, about 15 s)",
            Command::new("cargo").args(["install", "flip-link", "--locked"]),
        )?;
    }
    Ok(())
}

/// `cargo xtask qemu`: the main job.
fn qemu(args: &[String]) -> Result {
    ensure_tools()?;
    let mut seconds: Option<u32> = None;
    let mut with_screen = false;
    let mut port: u16 = 8080;
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--seconds" => {
                seconds = Some(
                    it.next()
                        .and_then(|s| s.parse().ok())
                        .filter(|&s| s >= 3)
                        .ok_or("--seconds takes a whole number ≥ 3")?,
                );
            }
            "--screen" => with_screen = true,
            "--port" => {
                port = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--port takes a port number (0: any free port)")?;
            }
            other => return Err(format!("qemu: unknown argument `{other}`")),
        }
    }
    let elf = Board::Qemu.build()?;
    if with_screen {
        return screen::qemu_screen(&elf, seconds, port);
    }
    let seconds = seconds.unwrap_or(20);
    std::env::set_var("FIRMWARE_QEMU_ELF", &elf);
    eprintln!(
        "xtask: the firmware in qemu-system-arm -machine netduino2 for {seconds} s of \
         firmware time, against the simulated machine (Low 2, a +10 % travel-speed change at \
         {} s), with a virtual touchscreen on USART1",
        seconds / 2
    );
    let flash = root()
        .join("target")
        .join("qemu")
        .join("settings-flash.bin");
    let options = BootOptions {
        run_ms: Some(seconds.saturating_mul(1000)),
        echo_logs: true,
        flash: Some(flash),
        scenario: vec![
            "gear=2".into(),
            format!("step={}:+10", seconds.saturating_mul(500)),
            // One `sim: plant` line per plant, for the report's spacings.
            "plant_log=1".into(),
        ],
        // Lock-step (firmware time paced by the virtual screen,
        // deterministic whatever the host's load).
        ..BootOptions::default()
    };
    let mut bench = qemu_tests::Bench::boot(&options).map_err(|e| e.to_string())?;
    let io = |e: std::io::Error| e.to_string();
    // The operator: wait for the screen to come up on the mode page, choose
    // Speed-Adaptive, 7.0 cm, gear Low 2, Start.
    let up = bench
        .pump_until(Duration::from_secs(5), |s| s.page() == 1)
        .map_err(io)?;
    if !up {
        return Err("the touchscreen never reached the mode page".into());
    }
    eprintln!("xtask: screen: mode page; operator selects Speed-Adaptive, 7.0 cm, Low 2, Start");
    bench.tap("badapt").map_err(io)?;
    bench.enter("nspacing", 70, "bapply").map_err(io)?;
    bench.tap("bgearup").map_err(io)?;
    bench.tap("bstart").map_err(io)?;
    let deadline = std::time::Instant::now() + Duration::from_secs(u64::from(seconds) * 3 + 30);
    let mut last_report = std::time::Instant::now();
    loop {
        bench.pump(Duration::from_millis(100)).map_err(io)?;
        if last_report.elapsed() >= Duration::from_secs(2) {
            last_report = std::time::Instant::now();
            let v = |n: &str| bench.screen.value(n).unwrap_or(0);
            eprintln!(
                "xtask: screen shows travel {}.{:02} km/h, drum target {}.{:02} actual {}.{:02} r/min, plants {}",
                v("xtravel") / 100,
                v("xtravel") % 100,
                v("xtarget") / 100,
                v("xtarget") % 100,
                v("xdrum") / 100,
                v("xdrum") % 100,
                v("nplants")
            );
        }
        if bench
            .fw
            .logs()
            .iter()
            .any(|l| l.contains("run limit of") || l.contains("HardFault") || l.contains("panic"))
            || std::time::Instant::now() > deadline
        {
            break;
        }
    }
    let (status, logs) = bench
        .fw
        .wait_exit(Duration::from_secs(30))
        .map_err(|e| e.to_string())?;
    let report = write_qemu_report(&logs, seconds)?;
    // The run's measured stack depth against the static analysis.
    let stack = stack::analyse(&elf, &llvm_tool("llvm-objdump")?, &Board::Qemu.chip())?;
    eprintln!("xtask: {}", stack::check_measured(&stack, &logs)?);
    if status.success() && logs.iter().any(|l| l.contains("drum: Running")) {
        eprintln!("xtask: the firmware ended its run: {status}");
        eprintln!("xtask: run report (open it in a browser):");
        println!("{}", report.display());
        Ok(())
    } else {
        Err(format!("QEMU exited with {status}, or the drum never ran"))
    }
}

/// Where the main job leaves its log and its report.
fn report_dir() -> PathBuf {
    root().join("target").join("report")
}

/// Saves the main job's decoded log as `target/report/qemu-run.log` and its
/// report as `target/report/qemu-run.html`; returns the report's path.
fn write_qemu_report(logs: &[String], seconds: u32) -> Result<PathBuf> {
    let dir = report_dir();
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let log_path = dir.join("qemu-run.log");
    let mut text = logs.join("\n");
    text.push('\n');
    std::fs::write(&log_path, &text).map_err(|e| format!("{}: {e}", log_path.display()))?;
    let run = report::parse(&text);
    let html = report::render(
        &run,
        "Transplanter run report (QEMU main job)",
        &format!(
            "cargo xtask qemu --seconds {seconds}: the firmware (QEMU board) against the \
             simulated machine, Speed-Adaptive, Low 2, a +10 % travel-speed step at {} s; \
             log: {}",
            seconds / 2,
            log_path.display()
        ),
    );
    // The main job's report must hold every series (the run plants for
    // more than 3 s, so each has points).
    let lacking = report::missing(
        &report::check(&html)?,
        &[
            report::names::TRAVEL_TRUE,
            report::names::TRAVEL_EST,
            report::names::DRUM_TARGET,
            report::names::DRUM_TRUE,
            report::names::DRUM_MEASURED,
            report::names::CCR_APPLIED,
            report::names::CCR_STATUS,
            report::names::PLANTS_TRUE,
            report::names::PLANTS_FW,
            report::names::SPACING_PLANT,
            report::names::HIST_PLANT,
            "operator",
            "state",
        ],
    );
    if !lacking.is_empty() {
        return Err(format!(
            "the run report lacks {} (log: {})",
            lacking.join(", "),
            log_path.display()
        ));
    }
    report::write(&dir.join("qemu-run.html"), &html)
}

/// Test totals parsed from the runners' `test result:` lines.
#[derive(Default)]
struct Totals {
    passed: u64,
    failed: u64,
    ignored: u64,
}

impl Totals {
    fn absorb(&mut self, line: &str) {
        // "test result: ok. 12 passed; 0 failed; 0 ignored; 0 measured; ..."
        let Some(rest) = line.trim().strip_prefix("test result: ") else {
            return;
        };
        for part in rest.split(';') {
            let mut words = part.split_whitespace().rev();
            let (Some(kind), Some(n)) = (words.next(), words.next()) else {
                continue;
            };
            let Ok(n) = n.parse::<u64>() else { continue };
            match kind {
                "passed" => self.passed += n,
                "failed" => self.failed += n,
                "ignored" => self.ignored += n,
                _ => {}
            }
        }
    }
}

/// Runs a test command, echoing its output and adding up its results.
fn run_tests(what: &str, cmd: &mut Command, totals: &mut Totals) -> Result {
    eprintln!("xtask: {what}");
    let mut child = cmd
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    if let Some(out) = child.stdout.take() {
        for line in BufReader::new(out)
            .lines()
            .map_while(std::result::Result::ok)
        {
            println!("{line}");
            totals.absorb(&line);
        }
    }
    let status = child.wait().map_err(|e| e.to_string())?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what}: {status}"))
    }
}

/// The property tests' seed under `cargo xtask test` and CI: the same
/// cases on every run and machine, so a landing never turns on a draw (a
/// resync property test once failed on one case in 100 000 random ones, a
/// gap in its oracle). `cargo test` run by hand draws new cases each time
/// (proptest's default) and keeps what fails in `*.proptest-regressions`.
const PROPTEST_RNG_SEED: &str = "20261126";

/// `cargo xtask test`: host tests (unit, property, doc), then the QEMU tests.
fn test() -> Result<Totals> {
    ensure_tools()?;
    let mut totals = Totals::default();
    run_tests(
        "host tests (logic crates, xtask)",
        cargo()
            .args([
                "test",
                "--workspace",
                "--exclude",
                "firmware",
                "--exclude",
                "qemu-tests",
            ])
            .env("PROPTEST_RNG_SEED", PROPTEST_RNG_SEED),
        &mut totals,
    )?;
    let elf = Board::Qemu.build()?;
    // The twin tests (tests/tests/twin_*.rs) run the real board's release
    // image: the one `cargo xtask size` checks, built once here.
    let twin = Board::Stm32f103.build()?;
    run_tests(
        "QEMU and twin tests (tests/)",
        cargo()
            // Every QEMU test runs in lock-step (firmware time paced by the
            // test, tests/src/lib.rs): a busy host, or a second QEMU, makes
            // them slower, never different. Two at a time on two cores. The
            // twin tests are deterministic too (instruction-counted time).
            .args(["test", "-p", "qemu-tests", "--", "--test-threads=2"])
            .env("FIRMWARE_QEMU_ELF", &elf)
            .env("TWIN_ELF", &twin),
        &mut totals,
    )?;
    println!(
        "xtask test: {} passed, {} failed",
        totals.passed, totals.failed
    );
    if totals.passed == 0 {
        return Err("no test ran".into());
    }
    Ok(totals)
}

/// The `no_std` library crates (host-tested, built for thumbv7m too).
const LIBRARIES: &[&str] = &[
    "kinematics",
    "fuzzy-pid",
    "hmi-proto",
    "machine-sim",
    "supervisor",
    "drive-link",
];

/// `-p NAME` for each package.
fn packages(names: &[&str]) -> Vec<String> {
    names
        .iter()
        .flat_map(|n| ["-p".to_string(), (*n).to_string()])
        .collect()
}

/// `cargo xtask ci`: everything a submission must pass.
fn ci() -> Result {
    let started = Instant::now();
    // clippy builds the twin (unicorn, bindgen): its tools come first.
    ensure_tools()?;
    run("rustfmt check", cargo().args(["fmt", "--all", "--check"]))?;
    run(
        "clippy host (all targets)",
        cargo().args([
            "clippy",
            "--workspace",
            "--exclude",
            "firmware",
            "--exclude",
            "bench",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ]),
    )?;
    run(
        "clippy logic crates and the bench program for thumbv7m",
        cargo()
            .arg("clippy")
            .args(packages(LIBRARIES))
            .args(["-p", "bench"])
            .args([
                "--features",
                "kinematics/defmt,fuzzy-pid/defmt,hmi-proto/defmt,supervisor/defmt,drive-link/defmt",
                "--target",
                TARGET,
                "--",
                "-D",
                "warnings",
            ]),
    )?;
    for board in Board::ALL {
        board.clippy()?;
    }
    run(
        "rustdoc (warnings denied)",
        cargo()
            .args(["doc", "--no-deps"])
            .args(packages(LIBRARIES))
            .env("RUSTDOCFLAGS", "-D warnings"),
    )?;
    // The fuzz targets are their own workspace (cargo-fuzz, nightly to run);
    // type-check them here so that they cannot rot against the codec's API.
    run(
        "fuzz targets type-check (run them: cargo +nightly fuzz run decoder)",
        cargo().args([
            "check",
            "--manifest-path",
            "fuzz/Cargo.toml",
            "--bins",
            "--locked",
        ]),
    )?;
    let totals = test()?;
    // The operator's web screen for a real board (its tests ran above).
    eprintln!(
        "xtask: the operator's web screen: {}",
        screen::build()?.display()
    );
    size()?;
    eprintln!("xtask: QEMU smoke run (the main job, 6 s)");
    qemu(&["--seconds".into(), "6".into()])?;
    // The field report on the smoke run's fresh log (its firmware lines).
    report::run(&[
        report_dir().join("qemu-run.log").display().to_string(),
        "--out".into(),
        report_dir()
            .join("qemu-run-field.html")
            .display()
            .to_string(),
    ])?;
    eprintln!("xtask ci: all green in {:.0?}", started.elapsed());
    println!(
        "ci: {} passed, {} failed, {} skipped",
        totals.passed, totals.failed, totals.ignored
    );
    Ok(())
}

/// A tool of rustup's llvm-tools component (`llvm-size`, `llvm-nm`).
fn llvm_tool(name: &str) -> Result<PathBuf> {
    let sysroot = Command::new("rustc")
        .current_dir(root())
        .args(["--print", "sysroot"])
        .output()
        .map_err(|e| e.to_string())?;
    let sysroot = String::from_utf8_lossy(&sysroot.stdout).trim().to_string();
    let host = Command::new("rustc")
        .current_dir(root())
        .args(["--print", "host-tuple"])
        .output()
        .map_err(|e| e.to_string())?;
    let host = String::from_utf8_lossy(&host.stdout).trim().to_string();
    Ok(Path::new(&sysroot)
        .join("lib/rustlib")
        .join(host)
        .join("bin")
        .join(name))
}

/// Code that must never reach the real board's image: it costs kilobytes
/// and means a slip (a decimal literal parsed at run time instead of in a
/// `const`, or floating-point formatting).
const FORBIDDEN_SYMBOLS: &[(&str, &str)] = &[
    (
        "fixed::from_str",
        "a fixed-point literal parsed at run time: wrap `X::lit(\"…\")` in `const { … }`",
    ),
    ("core::fmt::float", "floating-point formatting"),
];

/// Fails when the image holds any of [`FORBIDDEN_SYMBOLS`].
fn check_forbidden_symbols(elf: &Path) -> Result {
    let nm = llvm_tool("llvm-nm")?;
    let out = Command::new(&nm)
        .args(["--demangle", "--defined-only"])
        .arg(elf)
        .output()
        .map_err(|e| format!("{}: {e}", nm.display()))?;
    let symbols = String::from_utf8_lossy(&out.stdout);
    for (needle, why) in FORBIDDEN_SYMBOLS {
        if let Some(line) = symbols.lines().find(|l| l.contains(needle)) {
            return Err(format!(
                "{} contains `{}` ({why})",
                elf.display(),
                line.split_whitespace()
                    .skip(2)
                    .collect::<Vec<_>>()
                    .join(" ")
            ));
        }
    }
    Ok(())
}

/// The pages of the real board's flash that no loaded byte of its image may
/// touch, because a board keeps data there across flashing (probe-rs and
/// cargo-flash erase only the pages a segment covers): the settings pages
/// (memory-stm32f103.x).
const STM32F103_KEPT_PAGES: &[(std::ops::Range<u64>, &str)] = &[
    (
        0x0800_E000..0x0800_E800,
        "the settings pages of the earlier layout",
    ),
    (0x0801_E000..0x0802_0000, "the settings pages"),
];

/// The loaded bytes of an ELF (`PT_LOAD` with file bytes): load address
/// and length, from `llvm-readobj -l` (rustup's llvm-tools).
fn loaded_ranges(elf: &Path) -> Result<Vec<std::ops::Range<u64>>> {
    let readobj = llvm_tool("llvm-readobj")?;
    let out = Command::new(&readobj)
        .args(["--elf-output-style=GNU", "-l"])
        .arg(elf)
        .output()
        .map_err(|e| format!("{}: {e}", readobj.display()))?;
    if !out.status.success() {
        return Err(format!("llvm-readobj failed on {}", elf.display()));
    }
    let hex = |w: &str| u64::from_str_radix(w.trim_start_matches("0x"), 16).ok();
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            // LOAD  Offset VirtAddr PhysAddr FileSiz MemSiz Flg Align
            let w: Vec<&str> = l.split_whitespace().collect();
            let (paddr, filesz) = match w.as_slice() {
                ["LOAD", _, _, p, f, ..] => (hex(p)?, hex(f)?),
                _ => return None,
            };
            (filesz > 0).then(|| paddr..paddr.saturating_add(filesz))
        })
        .collect())
}

/// The first loaded range that falls on `pages`: flashing the image would
/// erase what they hold (probe-rs and cargo-flash erase every page a
/// segment covers).
fn on_pages(
    loaded: &[std::ops::Range<u64>],
    pages: &std::ops::Range<u64>,
) -> Option<std::ops::Range<u64>> {
    loaded
        .iter()
        .find(|r| r.start < pages.end && pages.start < r.end)
        .cloned()
}

/// The free bytes at the end of each of the real board's code regions.
fn region_margins(elf: &Path) -> Result<Vec<(&'static str, u64)>> {
    let loaded = loaded_ranges(elf)?;
    Ok(STM32F103_CODE_REGIONS
        .iter()
        .map(|(name, region)| {
            let end = loaded
                .iter()
                .filter(|r| region.contains(&r.start))
                .map(|r| r.end)
                .max()
                .unwrap_or(region.start);
            (*name, region.end.saturating_sub(end))
        })
        .collect())
}

/// The real board's image must leave [`STM32F103_KEPT_PAGES`] unflashed.
fn check_kept_pages(elf: &Path) -> Result {
    let loaded = loaded_ranges(elf)?;
    for (pages, what) in STM32F103_KEPT_PAGES {
        if let Some(r) = on_pages(&loaded, pages) {
            return Err(format!(
                "{}: loaded bytes {:#010x}..{:#010x} fall on {what} \
                 {:#010x}..{:#010x}: flashing it would erase what a board \
                 keeps there (memory-stm32f103.x)",
                elf.display(),
                r.start,
                r.end,
                pages.start,
                pages.end
            ));
        }
    }
    Ok(())
}

/// Section sizes of an ELF, from `llvm-size -A` (rustup's llvm-tools).
fn sections(elf: &Path) -> Result<Vec<(String, u64)>> {
    let llvm_size = llvm_tool("llvm-size")?;
    let out = Command::new(&llvm_size)
        .arg("-A")
        .arg(elf)
        .output()
        .map_err(|e| {
            format!(
                "{}: {e} (rust-toolchain.toml installs the llvm-tools component)",
                llvm_size.display()
            )
        })?;
    if !out.status.success() {
        return Err(format!("llvm-size failed on {}", elf.display()));
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            let name = w.next()?;
            let size = w.next()?.parse().ok()?;
            name.starts_with('.').then(|| (name.to_string(), size))
        })
        .collect())
}

/// Flash (code, read-only data, initialised data) and static RAM (data, bss,
/// uninit) of an ELF.
fn footprint(elf: &Path) -> Result<(u64, u64)> {
    let mut flash = 0;
    let mut ram = 0;
    for (name, size) in sections(elf)? {
        match name.as_str() {
            // `.upper_text`: the code above the hole (memory-stm32f103.x).
            ".vector_table" | ".text" | ".upper_text" | ".rodata" | ".gnu.sgstubs" => flash += size,
            ".data" => {
                flash += size;
                ram += size;
            }
            ".bss" | ".uninit" => ram += size,
            _ => {}
        }
    }
    Ok((flash, ram))
}

/// `cargo xtask size`.
fn size() -> Result {
    ensure_linker()?;
    let mut over = Vec::new();
    println!("| board | flash | flash budget | flash margin | static RAM | RAM budget |");
    println!("|---|---|---|---|---|---|");
    for board in Board::ALL {
        let elf = board.build()?;
        let (flash, ram) = footprint(&elf)?;
        let (flash_budget, ram_budget) = match board {
            // The hole's 2 KB are not code.
            Board::Stm32f103 => (FLASH_BUDGET - 2 * 1024, RAM_BUDGET),
            Board::Qemu => (QEMU_FLASH_BUDGET, RAM_BUDGET),
        };
        println!(
            "| {} | {flash} B | {flash_budget} B | {} B | {ram} B | {ram_budget} B |",
            board.name(),
            i128::from(flash_budget) - i128::from(flash)
        );
        if flash > flash_budget {
            over.push(format!(
                "{}: flash {flash} B > {flash_budget} B",
                board.name()
            ));
        }
        if ram > ram_budget {
            over.push(format!("{}: RAM {ram} B > {ram_budget} B", board.name()));
        }
    }
    let objdump = llvm_tool("llvm-objdump")?;
    for board in Board::ALL {
        let elf = board.elf();
        let started = Instant::now();
        let report = stack::analyse(&elf, &objdump, &board.chip())
            .map_err(|e| format!("stack analysis, board {}: {e}", board.name()))?;
        println!(
            "\n### Stack: {} ({:.1} s)\n\n{}",
            board.name(),
            started.elapsed().as_secs_f64(),
            report.table()
        );
        if let Err(e) = report.check_margin() {
            over.push(format!("{}: {e}", board.name()));
        }
    }
    if !over.is_empty() {
        return Err(format!("over budget: {}", over.join("; ")));
    }
    let margins = region_margins(&Board::Stm32f103.elf())?;
    println!(
        "\n{}: {}",
        Board::Stm32f103.name(),
        margins
            .iter()
            .map(|(name, free)| format!("{free} B free {name}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    check_forbidden_symbols(&Board::Stm32f103.elf())?;
    check_kept_pages(&Board::Stm32f103.elf())
}

/// `cargo xtask flash`: a real board on a debug probe.
fn flash() -> Result {
    ensure_linker()?;
    let probe_rs = Command::new("probe-rs").arg("--version").output();
    if probe_rs.is_err() {
        return Err(
            "probe-rs is not installed: `cargo install probe-rs-tools --locked`, \
             connect an ST-Link or CMSIS-DAP probe to the board's SWD header, then run again"
                .into(),
        );
    }
    let elf = Board::Stm32f103.build()?;
    run(
        "probe-rs run (flash, then stream defmt logs; Ctrl-C to stop)",
        Command::new("probe-rs")
            .args(["run", "--chip", "STM32F103RB"])
            .arg(elf),
    )
}

#[cfg(test)]
mod tests {
    use super::{is_libclang, on_pages};

    /// Loaded bytes next to kept pages pass; one byte on them, at either
    /// end, is found.
    #[test]
    fn loaded_bytes_on_kept_pages_are_found() {
        let pages = 0x0800_E000..0x0800_E800;
        let below = 0x0800_0000..0x0800_E000;
        let above = 0x0800_E800..0x0801_1000;
        assert_eq!(on_pages(&[below.clone(), above.clone()], &pages), None);
        let first = 0x0800_C000..0x0800_E001;
        assert_eq!(
            on_pages(&[below.clone(), first.clone()], &pages),
            Some(first)
        );
        let last = 0x0800_E7FF..0x0800_E804;
        assert_eq!(on_pages(&[above, last.clone()], &pages), Some(last));
    }

    #[test]
    fn libclang_is_the_library_bindgen_loads_not_libclang_cpp() {
        for name in [
            "libclang.so",
            "libclang.so.1",
            "libclang-14.so.1",
            "libclang-16.so",
        ] {
            assert!(is_libclang(name), "{name}");
        }
        for name in [
            "libclang-cpp.so.14",
            "libclang-cpp.so",
            "libclangBasic.a",
            "libclang.a",
        ] {
            assert!(!is_libclang(name), "{name}");
        }
    }
}
