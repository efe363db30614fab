//! A power cut at every program and erase step of a Save, through the
//! image's own flash driver on the twin's FPEC model (RM0008 §3.3.3,
//! PM0075): the board boots on the old settings or the new ones — never a
//! mix, never silently on the defaults.
//!
//! The old settings are Fixed mode (saved as record 1), the new ones
//! Speed-Adaptive (record 2); the status line names the mode in force.
//! A cut during a page erase leaves the page half erased (neither old nor
//! blank); a cut before a half-word program leaves it unwritten.

use twin::{Options, Twin};

fn boot(flash: Option<Vec<u8>>) -> Twin {
    let elf = twin::image::elf().expect("build the real-board image");
    let mut twin = Twin::new(
        &elf,
        Options {
            flash,
            ..Options::default()
        },
    )
    .expect("load the ELF");
    twin.connect_screen();
    assert!(
        twin.run_until_screen(3000, |s| s.page() == 1).unwrap(),
        "the screen never reached the mode page"
    );
    twin
}

/// Mode page → a mode's page → back → settings page → Save.
fn save_mode(twin: &mut Twin, mode_button: &str) {
    twin.tap(mode_button).unwrap();
    twin.tap("bback").unwrap();
    twin.tap("bset").unwrap();
    twin.tap("bsave").unwrap();
}

fn saved(twin: &mut Twin) -> bool {
    twin.run_until_screen(3000, |s| s.text("tmsg") == Some("Settings saved"))
        .unwrap()
}

/// The lines of the last boot.
fn last_boot(logs: &[String]) -> Vec<String> {
    let start = logs
        .iter()
        .rposition(|l| l.contains("boot: transplanter"))
        .unwrap_or(0);
    logs[start..].to_vec()
}

#[test]
fn a_power_cut_at_every_flash_step_of_a_save_boots_old_or_new_settings() {
    // Record 1: Fixed mode.
    let mut twin = boot(None);
    save_mode(&mut twin, "bfixed");
    assert!(saved(&mut twin), "first save");
    let old_flash = twin.flash();
    drop(twin);

    // The board on record 1, the operator on the settings page with
    // Speed-Adaptive chosen, about to tap Save: kept as a snapshot.
    let mut twin = boot(Some(old_flash));
    twin.tap("badapt").unwrap();
    twin.tap("bback").unwrap();
    twin.tap("bset").unwrap();
    let before_save = twin.snapshot().unwrap();
    let base = twin.state().bus.flash.ops;

    // The Save of record 2 without a cut: how many flash steps.
    twin.tap("bsave").unwrap();
    assert!(saved(&mut twin), "second save");
    let n = twin.state().bus.flash.ops - base;
    let ops = twin.flash_ops().to_vec();
    eprintln!(
        "a Save is {n} flash steps: {:?} …",
        &ops[ops.len() - n as usize..][..3]
    );
    assert!(n >= 2, "the save programmed the flash");

    let mut outcomes = (0, 0);
    // Before each step k (during it, for an erase), and after the last.
    for k in 0..=n {
        twin.restore(&before_save).unwrap();
        if k < n {
            twin.cut_power_at_flash_op(base + k, false);
        } else {
            twin.cut_power_at_flash_op(base + n - 1, true);
        }
        let resets = twin.resets.len();
        twin.tap("bsave").unwrap();
        let cut = twin.run_until(2000, |t| t.resets.len() > resets).unwrap();
        assert!(cut, "step {k}: the power cut never happened");
        twin.run_ms(300).unwrap();
        let logs = last_boot(&twin.logs());
        let text = logs.join("\n");
        assert!(
            !text.contains("defaults in use"),
            "step {k}: booted on defaults:\n{text}"
        );
        let status = logs
            .iter()
            .find(|l| l.contains("status: uptime"))
            .unwrap_or_else(|| {
                panic!(
                    "step {k}: no status line (core {:?}, resets {:?}, {} RTT bytes, pc {:#x}):\n{text}",
                    twin.core,
                    twin.resets,
                    twin.rtt_bytes.len(),
                    twin.reg(twin::RegisterARM::PC)
                )
            });
        if text.contains("settings: loaded record 1") {
            assert!(
                status.contains(" Fixed "),
                "step {k}: record 1 but {status}"
            );
            outcomes.0 += 1;
        } else if text.contains("settings: loaded record 2") {
            assert!(
                status.contains(" SpeedAdaptive "),
                "step {k}: record 2 but {status}"
            );
            outcomes.1 += 1;
        } else {
            panic!("step {k}: neither record loaded:\n{text}");
        }
    }
    eprintln!(
        "{} cuts: old settings {} times, new {} times",
        n + 1,
        outcomes.0,
        outcomes.1
    );
    // The last cut is after the save completed: the new record.
    assert!(outcomes.1 >= 1 && outcomes.0 >= 1);
}
