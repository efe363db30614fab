//! Every page of the browser screen with plausible values, as the firmware
//! writes them (the contract's own instructions: `page N`, the settings of
//! the page, its live values and a message), for the screenshots in
//! docs/img (`cargo xtask screenshots`) and the browser tests' walk over
//! every page.

use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;

use hmi_proto::screen::{
    page_instructions, status_instructions, Gear, Page, Settings, Spacing, Status,
};
use hmi_proto::{Instruction, ObjName, ScreenText};

use crate::browser::Browser;
use crate::screen_web::ScreenServer;

/// The sizes of the screenshots: a 7" 1280×800 tablet and a 800×480
/// screen (the size of a 5" or 7" Nextion).
pub const SIZES: [(u32, u32); 2] = [(1280, 800), (800, 480)];

fn emit(out: &mut Vec<u8>, ins: &Instruction<'_>) {
    let mut buf = [0u8; hmi_proto::MAX_INSTRUCTION_LEN];
    if let Ok(n) = ins.emit(&mut buf) {
        out.extend_from_slice(buf.get(..n).unwrap_or(&[]));
    }
}

/// The settings shown: Speed-Adaptive at 7.0 cm, Low 2.
pub fn settings() -> Settings {
    Settings {
        spacing: Spacing::new(70).unwrap_or_default(),
        gear: Gear::Low2,
        ..Settings::default()
    }
}

/// Live values of a run at Low 2, 7 cm, after `t` seconds.
pub fn status(t: f64) -> Status {
    let travel = 1.52 + 0.04 * (t * 0.7).sin();
    let plants = (t * 6.0) as u32;
    Status {
        travel_speed_kmh_x100: (travel * 100.0) as u16,
        target_drum_rpm_x100: (travel * 808.0) as u16,
        actual_drum_rpm_x100: (travel * 808.0 - 8.0 + 10.0 * (t * 1.9).sin()) as u16,
        plants,
        distance_dm: (f64::from(plants) * 0.7) as u32,
        quality_of_feed_x10: 982,
        multiples_x10: 9,
        misses_x10: 9,
        precision_cv_x10: 41,
        within_10_pct_x10: 957,
        plants_per_m_x100: 1428,
        travel_speed_mps_x100: (travel / 3.6 * 100.0) as u16,
        plant_motor_rpm_x100: (travel * 310.0) as u16,
        feed_motor_rpm_x100: (travel * 420.0) as u16,
        roller_turns: 12,
        roller_radius_dmm: 262,
        drive_n_max_x100: 4470,
        drive_tau_x10_ms: 250,
        drive_dead_time_x10_ms: 50,
        measured_distance_cm: 4870,
        calibration_result_x1000: 1027,
        ..Status::default()
    }
}

/// A message for the page's `tmsg`, if it has one worth showing.
fn message(page: Page) -> Option<&'static str> {
    match page {
        Page::Boot => Some("Connecting..."),
        Page::Adaptive => Some("Too fast for the spacing: slow down"),
        Page::Settings => Some("Settings saved"),
        Page::BeltParameters => Some("Spacing X must be 10.0-100.0 cm"),
        Page::Drive => Some("Identifying drive: keep belt empty"),
        _ => None,
    }
}

/// The firmware's bytes that show `page` with its settings, the live
/// values of `t` seconds into a run, and a message.
pub fn page_bytes(page: Page, t: f64) -> Vec<u8> {
    let mut out = Vec::new();
    emit(&mut out, &Instruction::Page(page.id()));
    let Ok(version) = ScreenText::new("0.1.0") else {
        return out;
    };
    for ins in page_instructions(page, &settings(), version) {
        emit(&mut out, &ins);
    }
    out.extend(status_bytes(page, t));
    if let Some(m) = message(page) {
        if let Ok(ins) = Instruction::set_text(ObjName::new_unchecked("tmsg"), m) {
            emit(&mut out, &ins);
        }
    }
    if page == Page::Alarm {
        if let Ok(ins) =
            Instruction::set_text(ObjName::new_unchecked("talarm"), "Drum motor stalled")
        {
            emit(&mut out, &ins);
        }
    }
    out
}

/// The live values of `page` at `t` seconds.
pub fn status_bytes(page: Page, t: f64) -> Vec<u8> {
    let mut out = Vec::new();
    let s = status(t);
    for ins in status_instructions(page, &s) {
        emit(&mut out, &ins);
    }
    out
}

/// Shows `page` on the connected page (through `server`), with a few
/// seconds of live values for the monitor.
pub fn show(server: &ScreenServer, page: Page) -> io::Result<()> {
    if !server.inject(&page_bytes(page, 0.0)) {
        return Err(io::Error::other("no page connected"));
    }
    let samples = if matches!(page, Page::Fixed | Page::Adaptive | Page::Belt) {
        40
    } else {
        3
    };
    for i in 1..=samples {
        std::thread::sleep(Duration::from_millis(100));
        server.inject(&status_bytes(page, f64::from(i) * 0.5));
    }
    std::thread::sleep(Duration::from_millis(300));
    Ok(())
}

/// Takes a screenshot of every page at every size of [`SIZES`] into
/// `dir` (`screen-<page>-<w>x<h>.png`); returns the files.
pub fn take(dir: &Path) -> io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let server = ScreenServer::start(0, None)?;
    let mut files = Vec::new();
    for (w, h) in SIZES {
        let mut b = Browser::launch(w, h)?;
        b.goto(&server.url())?;
        if !b.wait_for(
            "transplanterScreen.link() !== 'off'",
            Duration::from_secs(10),
        )? {
            return Err(io::Error::other("the page did not connect"));
        }
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while !server.connected() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        for page in Page::ALL {
            show(&server, page)?;
            let png = b.screenshot()?;
            let file = dir.join(format!("screen-{}-{w}x{h}.png", page.name()));
            std::fs::write(&file, png)?;
            files.push(file);
        }
        let errors = b.exceptions();
        if !errors.is_empty() {
            return Err(io::Error::other(format!("page errors: {errors:?}")));
        }
        drop(b);
        // The next browser's page connects once this one has gone.
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        while server.connected() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok(files)
}
