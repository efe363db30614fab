//! The serial path to the touchscreen, end to end: bytes out of and into the
//! emulated USART1, through the firmware's interrupt handler, byte queue and
//! HMI task. Expected bytes are written by hand from the Nextion instruction
//! set and the handshake of docs/hmi.md §2, not produced by the codec.

use std::time::Duration;

use qemu_tests::{instructions, qemu_firmware_elf, BootOptions, Firmware};

fn text(i: &[u8]) -> String {
    String::from_utf8_lossy(i).into_owned()
}

#[test]
fn the_firmware_handshakes_with_a_silent_screen_then_sets_it_up() {
    let elf = qemu_firmware_elf().expect("QEMU firmware build");
    let mut fw = Firmware::boot(&elf, &BootOptions::default()).expect("boot QEMU");

    // 1. A silent screen: the MCU ends any half-received instruction with a
    //    lone terminator and asks for the page, every 500 ms (§2.2).
    let got = fw
        .read_serial_until(Duration::from_secs(5), |b| {
            instructions(b).iter().filter(|i| *i == b"sendme").count() >= 2
        })
        .unwrap();
    assert!(
        got.starts_with(b"\xff\xff\xffsendme\xff\xff\xff"),
        "{got:02x?}"
    );

    // 2. The screen answers `sendme` with 0x66 (current page 0). The MCU sets
    //    it up: report level 2, brightness 100 %, the mode page, its values.
    fw.send(&[0x66, 0x00, 0xFF, 0xFF, 0xFF]).unwrap();
    let got = fw
        .read_serial_until(Duration::from_secs(5), |b| {
            instructions(b).iter().any(|i| *i == b"page 1")
        })
        .unwrap();
    let sent: Vec<String> = instructions(&got).into_iter().map(text).collect();
    let after = sent
        .iter()
        .position(|i| i == "bkcmd=2")
        .expect("bkcmd=2 sent");
    assert_eq!(sent[after + 1], "dims=100", "{sent:?}");
    assert_eq!(sent[after + 2], "page 1", "{sent:?}");
    // Page 1 shows the motor coefficient (×100, default 1.00).
    fw.read_serial_until(Duration::from_secs(5), |b| {
        instructions(b).iter().any(|i| *i == b"ncoef.val=100")
    })
    .unwrap();

    // 3. No more handshakes once connected; the log says so.
    let line = fw
        .wait_log(Duration::from_secs(5), |l| {
            l.contains("touchscreen connected")
        })
        .expect("connected log line");
    assert!(line.contains("INFO"), "{line}");
}

#[test]
fn a_touch_event_split_across_writes_reaches_the_firmware() {
    let elf = qemu_firmware_elf().expect("QEMU firmware build");
    let mut fw = Firmware::boot(&elf, &BootOptions::default()).expect("boot QEMU");
    fw.read_serial_until(Duration::from_secs(5), |b| {
        instructions(b).iter().any(|i| *i == b"sendme")
    })
    .unwrap();
    // Ready frame (0x88): the screen booted after the MCU.
    fw.send(&[0x88, 0xFF, 0xFF, 0xFF]).unwrap();
    fw.read_serial_until(Duration::from_secs(5), |b| {
        instructions(b).iter().any(|i| *i == b"page 1")
    })
    .unwrap();
    // Touch release of page 1 component 2 (`badapt`), split in two writes:
    // 0x65 page id event(0 = release) + terminator.
    fw.send(&[0x65, 0x01, 0x02]).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    fw.send(&[0x00, 0xFF, 0xFF, 0xFF]).unwrap();
    // The firmware selects Speed-Adaptive and shows its page (3).
    fw.read_serial_until(Duration::from_secs(5), |b| {
        instructions(b).iter().any(|i| *i == b"page 3")
    })
    .unwrap();
    fw.wait_log(Duration::from_secs(5), |l| {
        l.contains("screen: SelectMode(SpeedAdaptive)")
    })
    .expect("command logged");
}

#[test]
fn the_firmware_ends_its_run_with_success_and_logs_the_control_task() {
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
        .split("loops ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .expect("loop count in status line");
    assert!((199..=202).contains(&loops), "{status_line}");
    assert!(status_line.contains("(overruns 0)"), "{status_line}");
    assert!(logs
        .iter()
        .any(|l| l.contains("run limit of 2500 ms reached")));
}
