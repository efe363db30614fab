//! The browser screen in `cargo xtask` (docs/screen-web.md): the page's
//! build (`cargo xtask screen`), `cargo xtask qemu --screen` (the firmware
//! in real time, the page served on localhost, driven by a person) and
//! the screenshots in docs/img (`cargo xtask screenshots`).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use qemu_tests::screen_web::ScreenServer;
use qemu_tests::{BootOptions, Firmware};

use crate::{apt_install, have, root, Result};

/// Debian's `chromium` for the browser tests and the screenshots,
/// installed when missing (like QEMU).
pub fn ensure_browser() -> Result {
    if have(&qemu_tests::browser::chromium_path().display().to_string()) {
        return Ok(());
    }
    apt_install(&["chromium"], "the browser screen's tests")
}

/// Where the built page goes.
pub fn page_path() -> PathBuf {
    root()
        .join("target")
        .join("screen")
        .join("transplanter-screen.html")
}

/// `cargo xtask screen`: builds the page (one self-contained HTML file)
/// and prints its path.
pub fn build() -> Result<PathBuf> {
    let html = qemu_tests::screen_web::page_html()?;
    let path = page_path();
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::write(&path, html).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path)
}

/// `cargo xtask screenshots`: every page at 1280×800 and 800×480 into
/// docs/img.
pub fn screenshots() -> Result {
    ensure_browser()?;
    let dir = root().join("docs").join("img");
    let files = qemu_tests::screen_shots::take(&dir).map_err(|e| e.to_string())?;
    for f in files {
        println!("{}", f.display());
    }
    Ok(())
}

/// `cargo xtask qemu --screen`: the firmware in real time (one control
/// period every 10 ms of host time, `Firmware::pace_in_real_time`; no
/// test pumping it) against the simulated machine, its USART1
/// joined to the page on `http://127.0.0.1:PORT/`. Runs until Ctrl-C, or
/// `seconds` of firmware time.
pub fn qemu_screen(elf: &std::path::Path, seconds: Option<u32>, port: u16) -> Result {
    let options = BootOptions {
        run_ms: seconds.map(|s| s.saturating_mul(1000)),
        echo_logs: true,
        flash: Some(
            root()
                .join("target")
                .join("qemu")
                .join("settings-flash-screen.bin"),
        ),
        scenario: vec!["gear=2".into()],
        ..BootOptions::default()
    };
    let mut fw = Firmware::boot(elf, &options).map_err(|e| e.to_string())?;
    // Real time, paced by the wall clock (`Firmware::pace_in_real_time`).
    fw.pace_in_real_time().map_err(|e| e.to_string())?;
    let serial = fw.serial_stream().map_err(|e| e.to_string())?;
    let server = ScreenServer::start(port, Some(serial))
        .or_else(|_| ScreenServer::start(0, fw.serial_stream().ok()))
        .map_err(|e| e.to_string())?;
    let page = build()?;
    eprintln!(
        "xtask: the firmware runs in real time against the simulated machine (travel gear \
         Low 2); drive it from the page. The same page for a real board (USB serial): {}",
        page.display()
    );
    eprintln!(
        "xtask: open the operator's screen in Chrome, Edge or Chromium (Ctrl-C ends the run):"
    );
    println!("{}", server.url());
    let started = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(200));
        let logs = fw.logs();
        if logs
            .iter()
            .any(|l| l.contains("run limit of") || l.contains("HardFault") || l.contains("panic"))
        {
            break;
        }
        if let Some(s) = seconds {
            if started.elapsed() > Duration::from_secs(u64::from(s) * 3 + 30) {
                break;
            }
        }
    }
    let (status, _logs) = fw
        .wait_exit(Duration::from_secs(30))
        .map_err(|e| e.to_string())?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("QEMU exited with {status}"))
    }
}
