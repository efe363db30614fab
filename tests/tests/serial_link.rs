//! The serial path to the touchscreen, end to end: bytes into the emulated
//! USART1, through the firmware's interrupt handler, frame splitter and HMI
//! task, and its answer back out.

use std::time::Duration;

use qemu_tests::{instructions, qemu_firmware_elf, BootOptions, Firmware, TERMINATOR};

/// Finds the last complete `rxcount.val=N` instruction in what the firmware
/// sent and returns N.
fn last_rxcount(bytes: &[u8]) -> Option<u32> {
    instructions(bytes).into_iter().rev().find_map(|i| {
        std::str::from_utf8(i)
            .ok()?
            .strip_prefix("rxcount.val=")?
            .parse()
            .ok()
    })
}

#[test]
fn firmware_counts_touchscreen_bytes_and_answers_each_frame() {
    let elf = qemu_firmware_elf().expect("QEMU firmware build");
    let mut fw = Firmware::boot(&elf, &BootOptions::default()).expect("boot QEMU");
    fw.wait_log(Duration::from_secs(10), |l| l.contains("boot:"))
        .expect("boot log line");

    // A Nextion "ready" frame (0x88), 4 bytes with its terminator.
    let mut ready = vec![0x88];
    ready.extend_from_slice(&TERMINATOR);
    fw.send(&ready).unwrap();
    let got = fw
        .read_serial_until(Duration::from_secs(5), |b| last_rxcount(b) == Some(4))
        .unwrap();
    // The reply is one instruction: text then the terminator.
    assert!(got.ends_with(b"rxcount.val=4\xff\xff\xff"), "{got:02x?}");

    // A number frame whose payload holds 0xFF bytes (0x71, -1 little-endian),
    // split across two writes: 8 more bytes, 12 in all, and a second answer.
    let number = [0x71, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF];
    fw.send(&number[..3]).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    fw.send(&number[3..]).unwrap();
    fw.read_serial_until(Duration::from_secs(5), |b| last_rxcount(b) == Some(12))
        .unwrap();

    // The status task's log counts the same bytes.
    let line = fw
        .wait_log(Duration::from_secs(5), |l| l.contains("hmi rx 12 B"))
        .expect("status line with 12 bytes received");
    assert!(line.contains("status:"), "{line}");
}

#[test]
fn firmware_ends_its_run_with_success_and_logs_the_control_task() {
    let elf = qemu_firmware_elf().expect("QEMU firmware build");
    let options = BootOptions {
        run_ms: Some(2_500),
        ..BootOptions::default()
    };
    let fw = Firmware::boot(&elf, &options).expect("boot QEMU");
    let (status, logs) = fw.wait_exit(Duration::from_secs(30)).unwrap();
    assert!(status.success(), "QEMU exit {status}; logs: {logs:#?}");
    // 2.5 s of firmware time; the status task logs at 0, 1 and 2 s. At a
    // 10 ms period the 2 s line counts 200 control loops (± 1 for which of
    // the two tasks released at 2 s runs first).
    let status_line = logs
        .iter()
        .rev()
        .find(|l| l.contains("status:"))
        .expect("a status line");
    let loops: u32 = status_line
        .split("control loops ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .expect("loop count in status line");
    assert!((199..=201).contains(&loops), "{status_line}");
    assert!(status_line.contains("uptime 2000 ms"), "{status_line}");
    assert!(logs
        .iter()
        .any(|l| l.contains("run limit of 2500 ms reached")));
}
