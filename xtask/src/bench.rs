//! `cargo xtask bench`: regenerates `docs/PERFORMANCE.md` from measurements.

use std::path::Path;
use std::process::Command;

mod belt;
mod drum;
mod field;
mod legacy;
mod link;
mod placement;
mod row;
mod speed;
pub(crate) mod svg;
mod tables;
mod wheel;

use crate::{cargo, ensure_tools, footprint, root, Board, Result, TARGET};

/// One measured cost from the bench program.
struct Cost {
    name: String,
    instructions_x10: u64,
}

/// Builds `bench/` and runs it in QEMU with `-icount shift=0`.
fn target_costs() -> Result<Vec<Cost>> {
    let target_dir = root().join("target").join("bench");
    crate::run(
        "build bench (thumbv7m, release)",
        cargo()
            .args(["build", "-p", "bench", "--release", "--target", TARGET])
            .arg("--target-dir")
            .arg(&target_dir),
    )?;
    let elf = target_dir.join(TARGET).join("release").join("bench");
    eprintln!("xtask: run bench in QEMU (-icount shift=0)");
    let out = Command::new("qemu-system-arm")
        .args(["-machine", qemu_tests::QEMU_MACHINE, "-cpu", "cortex-m3"])
        .args(["-display", "none", "-monitor", "none", "-serial", "null"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0"])
        .arg("-kernel")
        .arg(&elf)
        .output()
        .map_err(|e| format!("qemu-system-arm: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(format!(
            "the bench program failed ({}):\n{text}{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(text
        .lines()
        .filter_map(|l| {
            let mut w = l.strip_prefix("cost ")?.split_whitespace();
            Some(Cost {
                name: w.next()?.to_string(),
                instructions_x10: w.next()?.parse().ok()?,
            })
        })
        .collect())
}

/// What each measured case is, and the aim it is held to.
fn cost_row(name: &str) -> (&'static str, &'static str) {
    match name {
        "fuzzy_infer_3x3" => ("fuzzy inference, 3×3 rule base (ΔKp, ΔKi, ΔKd)", "—"),
        "fuzzy_infer_5x5" => ("fuzzy inference, 5×5 rule base", "—"),
        "fuzzy_infer_7x7" => ("fuzzy inference, 7×7 rule base (the default)", "≤ 600"),
        "lut_infer_7x7" => (
            "lookup-table inference, 7×7 surface on a 13×13 grid",
            "≤ 200",
        ),
        "pid_step_conventional" => ("controller step, conventional fixed-gain PID", "—"),
        "pid_step_fuzzy_3x3" => ("controller step, fuzzy PID 3×3", "—"),
        "pid_step_fuzzy_5x5" => ("controller step, fuzzy PID 5×5", "—"),
        "pid_step_fuzzy_7x7" => ("controller step, fuzzy PID 7×7 (inference + PID)", "—"),
        "pid_step_lut_7x7" => (
            "controller step, fuzzy PID 7×7 from the lookup table (inference + PID)",
            "—",
        ),
        "control_step" => (
            "the whole 10 ms control step (`Supervisor::control_step`)",
            "≤ 40 000 (1 ms budget)",
        ),
        "hmi_wake" => (
            "the hmi task's heaviest wake: a touch decoded, the page change it makes (page 3, its values), the page's status at its widest, 379 bytes moved out (and a page change back to page 1)",
            "≤ 40 000 (1 ms budget)",
        ),
        _ => ("measured case of `bench/`", "—"),
    }
}

/// Writes `text` to `path` unless it already holds exactly that.
fn write_file(path: &Path, text: &str) -> Result {
    if std::fs::read_to_string(path).is_ok_and(|old| old == text) {
        return Ok(());
    }
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Section 7: the twin's speed (firmware seconds per host second), from
/// `twin`'s `speed` example on the real board's image, machine A (docs/twin.md).
fn twin_section(doc: &mut String) -> Result {
    eprintln!("xtask: bench 7 twin speed");
    let elf = Board::Stm32f103.build()?;
    let out =
        std::process::Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
            .current_dir(root())
            .args([
                "run",
                "--quiet",
                "-p",
                "twin",
                "--release",
                "--example",
                "speed",
                "--",
            ])
            .arg(&elf)
            .output()
            .map_err(|e| format!("twin speed: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with("twin-speed"))
        .ok_or_else(|| {
            format!(
                "twin speed: no result ({})",
                String::from_utf8_lossy(&out.stderr)
            )
        })?;
    let num = |key: &str| -> f64 {
        line.split(key)
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0)
    };
    let (fw, host) = (num("firmware_s="), num("host_s="));
    doc.push_str(&format!(
        "\n## 7. The twin's speed\n\n\
         The register-level twin of the real board (docs/twin.md) ran the profile A \
         release image with the machine at Low 2 and the drum running in Fixed mode: \
         {fw:.1} s of firmware time in {host:.1} s on this machine, **{:.2} firmware \
         seconds per host second** (the aim is at least 0.2). One executed instruction \
         counts as one 72 MHz cycle; `wfi` skips to the next event.\n",
        if host > 0.0 { fw / host } else { 0.0 }
    ));
    Ok(())
}

/// `cargo xtask bench --only NAME`: one section (`tables`, `placement`, `link`, `row`, `wheel`) alone, printed
/// and written to target/bench-NAME.md (its plots to target/img/);
/// docs/PERFORMANCE.md and docs/img/ are left as they are.
fn only(name: &str) -> Result {
    let started = std::time::Instant::now();
    let img = root().join("target").join("img");
    std::fs::create_dir_all(&img).map_err(|e| format!("{}: {e}", img.display()))?;
    let mut doc = String::new();
    match name {
        "tables" => tables::section(&mut doc, &img)?,
        "placement" => {
            placement::section(&mut doc, &img)?;
        }
        "link" => {
            link::section(&mut doc)?;
        }
        "row" => {
            row::section(&mut doc)?;
        }
        "wheel" => {
            wheel::section(&mut doc)?;
        }
        other => {
            return Err(format!(
            "bench --only: unknown section `{other}` (known: tables, placement, link, row, wheel)"
        ))
        }
    }
    let path = root().join("target").join(format!("bench-{name}.md"));
    write_file(&path, &doc)?;
    print!("{doc}");
    eprintln!(
        "xtask: wrote {} in {:.1} s",
        path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `cargo xtask bench [--only NAME]`: regenerates docs/PERFORMANCE.md and
/// docs/img/ (or runs one section, [`only`]).
pub fn run(args: &[String]) -> Result {
    match args {
        [] => {}
        [flag, name] if flag == "--only" => return only(name),
        _ => {
            return Err(format!(
                "bench: unexpected arguments {args:?} (usage: bench [--only tables|placement|link|row])"
            ))
        }
    }
    ensure_tools()?;
    let started = std::time::Instant::now();
    let costs = target_costs()?;
    let img = root().join("docs").join("img");
    std::fs::create_dir_all(&img).map_err(|e| format!("{}: {e}", img.display()))?;
    let mut doc = String::new();
    doc.push_str(
        "# Performance\n\n\
         Generated by `cargo xtask bench`; do not edit by hand. Every number below \
         comes from that command, with fixed inputs and fixed seeds (stated in each \
         section), so a rerun gives the same figures and the same plots (`docs/img/`). \
         The simulations run the product's own crates (`supervisor`, `fuzzy-pid`, \
         `kinematics`) against the machine model `machine-sim` (docs/machine-sim.md) on \
         the host; the costs on the target come from QEMU. Paper A's figures are those of \
         SPEC §5–6; its plant was never published, so its numbers and ours describe \
         different plants and are set side by side, not as a like-for-like contest.\n\n",
    );
    eprintln!("xtask: bench 1/3 drum speed loop");
    drum::section(&mut doc, &img)?;
    eprintln!("xtask: bench 2/3 speed measurement");
    speed::section(&mut doc)?;
    eprintln!("xtask: bench 3/3 field runs");
    field::section(&mut doc, &img)?;
    eprintln!("xtask: bench 4 profile B");
    belt::section(&mut doc)?;
    doc.push_str(
        "## 5. Cost on the target ISA (QEMU instruction counts)\n\n\
         `bench/` runs each case 1024 times over 64 varying inputs in \
         `qemu-system-arm -machine netduino2 -icount shift=0`, where one guest \
         instruction is one nanosecond of virtual time and SysTick counts at the machine's \
         120 MHz (1 tick = 8⅓ instructions). The loop's own cost (an empty body) is \
         subtracted. \
         These are Cortex-M3 (thumbv7m) instructions, not cycles: on a real F103 at \
         72 MHz with flash wait states an instruction takes roughly 1.2–1.8 cycles.\n\n\
         | code | instructions per call | aim |\n|---|---|---|\n",
    );
    for c in &costs {
        let (what, aim) = cost_row(&c.name);
        doc.push_str(&format!(
            "| {what} (`{}`) | {}.{} | {aim} |\n",
            c.name,
            c.instructions_x10 / 10,
            c.instructions_x10 % 10
        ));
    }
    doc.push_str(
        "\nThe aims of 600 and 200 are held against the inference alone (the fuzzy tuner's \
         share, what the rule-base size and the table change); a controller step adds the \
         PID itself (the conventional step's cost).\n\n",
    );
    let find = |n: &str| {
        costs
            .iter()
            .find(|c| c.name == n)
            .map(|c| c.instructions_x10)
    };
    let mut reading = String::from("Reading: ");
    if let (Some(f7), Some(f3), Some(lut)) = (
        find("fuzzy_infer_7x7"),
        find("fuzzy_infer_3x3"),
        find("lut_infer_7x7"),
    ) {
        reading.push_str(&format!(
            "the 7×7 inference costs {}.{} instructions, {} its aim of 600: only the four \
             active rules are evaluated and a triangular partition's weights sum to one, so \
             defuzzification needs no division. The rule-base size does not change the cost \
             (3×3: {}.{}; 2×2 active rules whatever the size). The lookup table costs {}.{}, \
             {}: it reads 2×2 precomputed Q15 entries and blends them in 32-bit integers (the \
             weights sum to exactly 2^16, so no sum can overflow), where the direct inference \
             looks up rule labels and their singletons and accumulates in 64 bits. With \
             product AND both compute the same bilinear surface between rule consequents \
             (section 1: same step response). ",
            f7 / 10,
            f7 % 10,
            if f7 <= 6000 { "within" } else { "over" },
            f3 / 10,
            f3 % 10,
            lut / 10,
            lut % 10,
            if lut <= 2000 {
                format!(
                    "within its aim of 200 and {:.1} times cheaper than the direct 7×7 inference",
                    f7 as f64 / lut as f64
                )
            } else {
                "over its aim of 200".to_string()
            }
        ));
    }
    if let Some(step) = find("control_step") {
        reading.push_str(&format!(
            "The whole control step costs {}.{} instructions, ≈ {:.0} µs at 72 MHz even at \
             1.8 cycles per instruction — {:.1} % of the 10 ms period. ",
            step / 10,
            step % 10,
            step as f64 / 10.0 * 1.8 / 72.0,
            step as f64 / 10.0 * 1.8 / 72.0 / 10_000.0 * 100.0
        ));
    }
    reading.push_str(
        "Paper A reports 15, 22 and 38 ms of *calculation time* for 3×3, 5×5 and 7×7 \
         (Table 8, measured on its PC model, not on the MCU); on the target the rule-base \
         size costs nothing and the inference is a fraction of a millisecond.\n\n",
    );
    doc.push_str(&reading);
    doc.push_str("## 6. Flash and RAM\n\n`cargo xtask size` (release, `opt-level = \"z\"` with the fuzzy PID at `\"s\"`, fat LTO):\n\n| board | flash | static RAM (data + bss) |\n|---|---|---|\n");
    for board in Board::ALL {
        let (flash, ram) = footprint(&board.build()?)?;
        doc.push_str(&format!("| {} | {flash} B | {ram} B |\n", board.name()));
    }
    twin_section(&mut doc)?;
    eprintln!("xtask: bench 8 paper A Tables 14 and 15");
    tables::section(&mut doc, &img)?;
    eprintln!("xtask: bench 9 placement");
    let secs = placement::section(&mut doc, &img)?;
    eprintln!("xtask: bench 9 took {secs:.0} s");
    eprintln!("xtask: bench 10 drive link");
    let secs = link::section(&mut doc)?;
    eprintln!("xtask: bench 10 took {secs:.1} s");
    eprintln!("xtask: bench 11 a row's checks");
    let secs = row::section(&mut doc)?;
    eprintln!("xtask: bench 11 took {secs:.0} s");
    eprintln!("xtask: bench 12 the ground wheel");
    let secs = wheel::section(&mut doc)?;
    eprintln!("xtask: bench 12 took {secs:.0} s");
    let path = root().join("docs").join("PERFORMANCE.md");
    write_file(&path, &doc)?;
    eprintln!(
        "xtask: wrote {} in {:.0} s",
        path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
