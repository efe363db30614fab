//! The QEMU board's machine: it runs in the real board's RAM — 20 KB at
//! 0x2000_0000, the statics at its top and the stack (flip-link) below them
//! — so that a QEMU run's stack and static figures are the real board's.
//! The reference is the twin's memory map (`twin::RAM_BASE`,
//! `twin::RAM_SIZE`: the STM32F103RB's SRAM, written from its datasheet),
//! not the QEMU board's own linker script; the run shows that the emulated
//! machine holds that RAM (a machine with less locks up at reset, when the
//! statics are zeroed).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use object::{Object, ObjectSymbol};
use qemu_tests::{qemu_firmware_elf, BootOptions, Firmware};

/// The address of `name` in the ELF.
fn symbol(file: &object::File, name: &str) -> u64 {
    file.symbols()
        .find(|s| s.name() == Ok(name))
        .map(|s| s.address())
        .unwrap_or_else(|| panic!("the image has no symbol {name}"))
}

/// The number after `key` in `line` (`stack: 3232 B used of 15712 B`).
fn number_after(line: &str, key: &str) -> u64 {
    let rest = &line[line.find(key).unwrap() + key.len()..];
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse().unwrap()
}

#[test]
fn the_qemu_board_runs_in_the_real_boards_ram() {
    let elf = qemu_firmware_elf().unwrap();
    let bytes = std::fs::read(&elf).unwrap();
    let file = object::File::parse(&*bytes).unwrap();
    // cortex-m-rt's symbols: the RAM region's ends, and (flip-link) the
    // stack from the region's start up to the statics.
    let ram = (symbol(&file, "_stack_end"), symbol(&file, "_ram_end"));
    let base = u64::from(twin::RAM_BASE);
    assert_eq!(
        ram,
        (base, base + u64::from(twin::RAM_SIZE)),
        "the QEMU board's RAM (start, end) is not the real board's"
    );
    let stack = symbol(&file, "_stack_start") - ram.0;

    let options = BootOptions {
        run_ms: Some(100),
        lockstep: false,
        accelerated: true,
        ..BootOptions::default()
    };
    let fw = Firmware::boot(&elf, &options).expect("boot QEMU");
    let (status, logs) = fw.wait_exit(Duration::from_secs(30)).unwrap();
    assert!(
        status.success(),
        "the run failed ({status}):\n{}",
        logs.join("\n")
    );
    let reports: Vec<&String> = logs.iter().filter(|l| l.contains(" stack: ")).collect();
    // One after `init`, one at the run's end.
    assert_eq!(reports.len(), 2, "stack reports:\n{}", logs.join("\n"));
    for line in reports {
        assert_eq!(number_after(line, "B used of "), stack, "{line}");
    }
}

/// A stack that runs off the bottom of RAM faults at its first store below
/// RAM, and the fault entry reports it (`board/fault.rs`), as on the real
/// board. The QEMU machine itself drops stores outside memory and faults
/// only when an exception's entry cannot push its frame (measured without
/// the guard: at the next SysTick, 0.9 MB below RAM; with the interrupts
/// off, as in `init`, the run hung): the board's MPU guard
/// (`board/qemu/stack_guard.rs`) closes that gap.
#[test]
fn a_stack_overflow_faults_at_the_bottom_of_ram() {
    let elf = qemu_firmware_elf().unwrap();
    let bytes = std::fs::read(&elf).unwrap();
    let ram_start = symbol(&object::File::parse(&*bytes).unwrap(), "_stack_end");
    let options = BootOptions {
        run_ms: Some(1_000),
        lockstep: false,
        accelerated: true,
        scenario: vec!["stack_overflow=200".into()],
        ..BootOptions::default()
    };
    let fw = Firmware::boot(&elf, &options).expect("boot QEMU");
    let report = fw
        .wait_log(Duration::from_secs(30), |l| {
            l.contains("outside the stack: stack overflow")
        })
        .unwrap_or_else(|| panic!("no fault report; log:\n{}", fw.logs().join("\n")));
    let sp_hex = report
        .split("sp 0x")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap();
    let sp = u64::from_str_radix(sp_hex, 16).unwrap();
    // The exception frame (32 B) and at most one frame of the recursion
    // (its 64 B array and saved registers) below RAM.
    assert!(
        sp < ram_start && ram_start - sp <= 256,
        "the overflow was stopped at sp {sp:#x}, RAM starts at {ram_start:#x}: {report}"
    );
    assert!(
        !fw.logs().iter().any(|l| l.contains("reached, exiting")),
        "the run went on to its limit"
    );
}
