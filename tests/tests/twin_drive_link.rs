//! The RS-485 pin timing of the drum driver's Modbus link on the twin, with
//! the real board's image (USART2 on PA2/PA3, DE on PA1;
//! docs/drive-link.md "Board layer", docs/twin.md "The drive link").
//!
//! The image boots on a format-5 settings record (read-back feedback,
//! ZLAC8015D) written into its settings pages; a virtual ZLAC8015D
//! (`drive_link::virtual_driver`) answers on USART2's RX line 2 ms after
//! each request's last stop bit. The twin records PA1's level changes and
//! USART2's line events (each byte's start bit and stop-bit end from the
//! shift register's timing, the moments TC is set, each received byte's
//! stop-bit end), all in 72 MHz ticks.
//!
//! Expected values, never the firmware's own:
//! - RM0008 §27.3.4: baud = f_PCLK1 / (16 × USARTDIV), USARTDIV = BRR / 16,
//!   so one bit is BRR / 36 MHz; BRR = 36 MHz / baud rounded (9600: 3750;
//!   115 200: 312.5 → 313); a character is 1 start + 8 data + 1 stop = 10
//!   bits (M = 0). §27.6.1: TC is set when a stop bit ends with TXE = 1.
//! - Modbus over Serial Line V1.02 §2.5.1.1: a character is 11 bits (the
//!   spec's RTU character; an 8N1 frame is 10, so 11 is the stricter
//!   figure for silences); frames are separated by ≥ 3.5 characters
//!   (above 19 200 baud a fixed 1.75 ms); characters within a frame by
//!   ≤ 1.5 characters.
//! - The RS-485 direction rule (issue 17): DE high before the first start
//!   bit, low only once the last stop bit has left (TC), no transmission
//!   while DE is low; the bound on DE's fall after TC stated here is one
//!   character (10 bits): the driver may answer after 3.5 characters
//!   (§2.5.1.1), so a DE still high one character later would not yet
//!   collide, and on the twin the interrupt takes a few µs.
//! - The read-back: the virtual driver's 0x20AB value (0.1 r/min of the
//!   motor) × the settings' scale (5000 µr/min of the drum per count, the
//!   20:1 gearbox of `qemu_tests::drive`) must appear as the drum's actual
//!   speed in the status line (within the supervisor's report filter).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use drive_link::virtual_driver::VirtualZlac;
use supervisor::drive_link::{CommandPath, DriveLinkSettings, DriverKind, FeedbackSource};
use supervisor::settings::Settings;

#[path = "support/board.rs"]
mod board;
#[path = "support/pages.rs"]
mod pages;
use twin::periph::{Level, LineEvent, Ticks};
use twin::{Options, Twin, TICKS_PER_S};

/// Read-back feedback from a ZLAC8015D behind 20:1 at `baud`, PWM command.
fn settings(baud: u32) -> Settings {
    let mut s = Settings {
        drive_link: DriveLinkSettings {
            feedback: FeedbackSource::Driver,
            command: CommandPath::Pwm,
            kind: DriverKind::Zlac8015d,
            ..DriveLinkSettings::default()
        },
        ..Settings::default()
    };
    s.drive_link.generic.baud = baud;
    s.drive_link.generic.micro_rpm_per_count = MICRO_RPM_PER_COUNT;
    s
}

/// The settings' scale: 100 000 µr/min / 20 (the tests' 20:1 gearbox).
const MICRO_RPM_PER_COUNT: i32 = 5000;
/// The virtual driver's speed register: 40.0 r/min of the motor (2 r/min
/// of the drum behind 20:1).
const MOTOR_DECIRPM: i16 = 400;
/// The virtual driver's turnaround (request end → reply start), µs.
const TURNAROUND_US: u32 = 2_000;

const PCLK1_HZ: f64 = 36_000_000.0;

fn us(t: Ticks) -> f64 {
    t as f64 * 1e6 / TICKS_PER_S as f64
}

/// One request and its reply as seen on the pins.
#[derive(Debug)]
struct Transaction {
    de_rise: Ticks,
    de_fall: Ticks,
    /// (start bit, stop-bit end, byte) of each request byte.
    tx: Vec<(Ticks, Ticks, u8)>,
    tc: Option<Ticks>,
    /// (stop-bit end, byte) of each reply byte.
    rx: Vec<(Ticks, u8)>,
}

struct Run {
    twin: Twin,
    transactions: Vec<Transaction>,
    driver: VirtualZlac,
}

/// The request (counted from 0) the virtual driver leaves unanswered: the
/// link times out and sends it again.
const UNANSWERED: usize = 20;

/// Boots the image on the drive-link settings at `baud`, answers every
/// request but [`UNANSWERED`] for `ms` of firmware time and cuts the
/// recorded timeline into transactions.
fn run(baud: u32, ms: u64) -> Run {
    let elf = twin::image::elf().expect("build the real-board image");
    // The settings record, written by the supervisor's own store into the
    // board's settings pages (as a previous Save would have): the link is
    // in force because the settings name a driver.
    let options = Options {
        flash: Some(board::flash_with(&elf, &settings(baud))),
        ..Options::default()
    };
    let mut twin = Twin::new(&elf, options).unwrap();

    twin.trace_pin('A', 1);
    twin.state_mut().bus.usart[1].record = true;
    let mut driver = VirtualZlac::default();
    driver.actual_decirpm = MOTOR_DECIRPM;
    driver.turnaround_us = TURNAROUND_US;
    let until = twin.now() + ms * TICKS_PER_S / 1000;
    let step = TICKS_PER_S / 20_000; // 50 µs
    let mut seen = 0; // line events handled
    let mut requests = 0;
    while twin.now() < until {
        twin.run_ticks(step).unwrap();
        // A request is complete when TC is set (the firmware's requests are
        // 8 bytes: function 03 or 06).
        let log = &twin.state().bus.usart[1].line_log;
        let tc = log[seen..]
            .iter()
            .position(|e| matches!(e, LineEvent::TcSet { .. }));
        let Some(i) = tc else {
            seen = log.len();
            continue;
        };
        let end = log[seen + i].at();
        seen += i + 1;
        let request = twin.take_serial(1);
        requests += 1;
        if requests - 1 == UNANSWERED {
            continue;
        }
        let Some((reply, delay_us)) = driver.handle(&request) else {
            continue;
        };
        let due = end + u64::from(delay_us) * TICKS_PER_S / 1_000_000;
        if due > twin.now() {
            twin.run_ticks(due - twin.now()).unwrap();
        }
        twin.send_serial(1, &reply);
    }

    // Cut the timeline at DE's edges.
    let pins = &twin.state().bus.pin_log;
    let log = &twin.state().bus.usart[1].line_log;
    let edges: Vec<(Ticks, Level)> = pins
        .iter()
        .filter(|p| p.port == 0 && p.pin == 1)
        .map(|p| (p.at, p.level))
        .collect();
    let mut transactions = Vec::new();
    for (k, w) in edges.windows(2).enumerate() {
        let ((rise, a), (fall, b)) = (w[0], w[1]);
        if a != Level::High || b != Level::Low {
            continue;
        }
        let next_rise = edges.get(k + 2).map_or(Ticks::MAX, |&(t, _)| t);
        let mut tx = Vec::new();
        let mut tc = None;
        let mut rx = Vec::new();
        for e in log {
            match *e {
                LineEvent::TxStart { at, byte } if at >= rise && at < fall => {
                    tx.push((at, 0, byte));
                }
                LineEvent::TxEnd { at, byte } if at > rise && at <= fall => {
                    let slot = tx
                        .iter_mut()
                        .find(|s| s.1 == 0 && s.2 == byte)
                        .expect("a TX end matches its start");
                    slot.1 = at;
                }
                LineEvent::TcSet { at } if at > rise && at <= fall => tc = Some(at),
                LineEvent::RxEnd { at, byte } if at > fall && at < next_rise => rx.push((at, byte)),
                _ => {}
            }
        }
        transactions.push(Transaction {
            de_rise: rise,
            de_fall: fall,
            tx,
            tc,
            rx,
        });
    }
    Run {
        twin,
        transactions,
        driver,
    }
}

/// Every timing rule on every transaction of a run at `baud`; prints the
/// first read of 0x20AB as a timeline.
fn check(baud: u32, ms: u64) {
    let host = std::time::Instant::now();
    let Run {
        mut twin,
        transactions,
        driver,
    } = run(baud, ms);
    let host_s = host.elapsed().as_secs_f64();

    // RM0008 §27.3.4: BRR and the character time (10 bits) in ticks.
    let brr = (PCLK1_HZ / f64::from(baud)).round();
    assert_eq!(f64::from(twin.state().bus.usart[1].brr), brr, "BRR");
    let bit_s = brr / PCLK1_HZ;
    let char_ticks = 10.0 * bit_s * TICKS_PER_S as f64;
    let baud_err = (1.0 / bit_s - f64::from(baud)).abs() / f64::from(baud);
    assert!(baud_err < 0.005, "baud error {:.3} %", baud_err * 100.0);
    // Modbus §2.5.1.1: 11-bit characters; 3.5 of them, or 1.75 ms.
    let modbus_char_s = 11.0 / f64::from(baud);
    let silence_s = if baud > 19_200 {
        1.75e-3
    } else {
        3.5 * modbus_char_s
    };
    let silence = silence_s * TICKS_PER_S as f64;
    let within_frame = 1.5 * modbus_char_s * TICKS_PER_S as f64;

    // No byte leaves while DE is low: each start bit and stop-bit end lies
    // in an interval where PA1 is high (the last one may still be open at
    // the run's end).
    let st = twin.state();
    // From reset PA1 is a floating input (RM0008 §9.1.1) until `init`
    // drives it low; from then on it is always driven (no reset here).
    let de: Vec<_> = st
        .bus
        .pin_log
        .iter()
        .filter(|p| p.port == 0 && p.pin == 1)
        .collect();
    let driven = de
        .iter()
        .position(|p| p.level == Level::Low)
        .expect("PA1 driven low by init");
    assert!(
        de[..driven].iter().all(|p| p.level == Level::HiZ),
        "PA1 before init: {:?}",
        &de[..driven]
    );
    assert!(
        de[driven..]
            .iter()
            .all(|p| matches!(p.level, Level::High | Level::Low)),
        "PA1 floated after init"
    );
    let de_driven_at = de[driven].at;
    let mut high: Vec<(Ticks, Ticks)> = Vec::new();
    for p in st.bus.pin_log.iter().filter(|p| p.port == 0 && p.pin == 1) {
        match p.level {
            Level::High => high.push((p.at, Ticks::MAX)),
            _ => {
                if let Some(h) = high.last_mut().filter(|h| h.1 == Ticks::MAX) {
                    h.1 = p.at;
                }
            }
        }
    }
    for e in &st.bus.usart[1].line_log {
        if let LineEvent::TxStart { at, .. } | LineEvent::TxEnd { at, .. } = *e {
            assert!(
                high.iter().any(|&(r, f)| r <= at && at <= f),
                "TX at {:.2} µs while DE was low",
                us(at)
            );
        }
    }

    assert!(
        transactions.len() >= 10,
        "{} transactions in {ms} ms",
        transactions.len()
    );
    let mut lead = (f64::MAX, 0.0f64);
    let mut lag = (f64::MAX, 0.0f64);
    let mut gap_min = f64::MAX;
    let mut inter_max = 0.0f64;
    let mut retry_wait = 0.0f64;
    for (n, t) in transactions.iter().enumerate() {
        assert_eq!(t.tx.len(), 8, "transaction {n}: {t:?}");
        // DE high before the first start bit.
        let first = t.tx[0].0;
        assert!(
            t.de_rise < first,
            "transaction {n}: DE rose at/after the start bit"
        );
        lead.0 = lead.0.min(us(first - t.de_rise));
        lead.1 = lead.1.max(us(first - t.de_rise));
        for (k, &(start, end, _)) in t.tx.iter().enumerate() {
            // Each character 10 bit times (RM0008).
            assert!(
                ((end - start) as f64 - char_ticks).abs() < 1.0,
                "transaction {n} byte {k}: {} ticks, expected {char_ticks}",
                end - start
            );
            if k > 0 {
                let gap = (start - t.tx[k - 1].1) as f64;
                inter_max = inter_max.max(gap);
                assert!(
                    gap <= within_frame,
                    "transaction {n}: {gap} ticks between bytes"
                );
            }
        }
        // TC at the last stop bit's end; DE low only after it, within one
        // character.
        let last_end = t.tx[7].1;
        let tc = t.tc.expect("TC set while DE was high");
        assert_eq!(tc, last_end, "transaction {n}: TC not at the last stop bit");
        assert!(t.de_fall >= tc, "transaction {n}: DE fell before TC");
        let after = (t.de_fall - tc) as f64;
        assert!(
            after < char_ticks,
            "transaction {n}: DE low {after} ticks after TC"
        );
        lag.0 = lag.0.min(us(t.de_fall - tc));
        lag.1 = lag.1.max(us(t.de_fall - tc));
        // The reply: every byte after DE fell (a full frame: 7 bytes for a
        // read of one register, 8 for a write's echo).
        let expect = if t.tx[1].2 == 0x03 { 7 } else { 8 };
        if n == UNANSWERED {
            // No reply: the same request again once the reply timeout
            // (the longest reply, 9 characters of 11 bits, the silence
            // that ends it, + the driver's answer time, 60 ms by default:
            // docs/drive-link.md) and the retry gap of quiet line (20 ms)
            // have passed after TC, within two periods of the 1 ms link
            // task.
            assert!(t.rx.is_empty(), "transaction {n}: {:?}", t.rx);
            let next = &transactions[n + 1];
            let bytes = |t: &Transaction| t.tx.iter().map(|b| b.2).collect::<Vec<_>>();
            assert_eq!(bytes(next), bytes(t), "the same request again");
            let timing = drive_link::link::LinkTiming::DEFAULT;
            let answer_s = f64::from(timing.reply_timeout_ms) * 1e-3;
            let gap = (f64::from(timing.retry_gap_ms) * 1e-3 * TICKS_PER_S as f64).max(silence);
            let timeout = (9.0 * modbus_char_s + answer_s) * TICKS_PER_S as f64 + silence;
            let wait = (next.tx[0].0 - tc) as f64;
            retry_wait = wait / 72.0;
            assert!(
                wait >= timeout + gap && wait <= timeout + gap + 2.0 * 72_000.0,
                "retry {:.1} µs after TC, expected {:.1}..{:.1}",
                wait / 72.0,
                (timeout + gap) / 72.0,
                (timeout + gap) / 72.0 + 2000.0
            );
            continue;
        }
        assert_eq!(t.rx.len(), expect, "transaction {n}: reply {:?}", t.rx);
        let reply_start = t.rx[0].0 as f64 - char_ticks;
        assert!(
            reply_start > t.de_fall as f64,
            "transaction {n}: reply while DE high"
        );
        // The silence before the next request (from the reply's last stop
        // bit to DE and the next start bit).
        if let Some(next) = transactions.get(n + 1) {
            let reply_end = t.rx[expect - 1].0;
            let gap = (next.de_rise - reply_end) as f64;
            gap_min = gap_min.min(gap);
            assert!(
                gap >= silence,
                "transaction {n}: {:.1} µs of silence before the next request, need {:.1}",
                gap / 72.0,
                silence / 72.0
            );
        }
    }

    // The first read of the speed register, as a timeline.
    let t = transactions
        .iter()
        .find(|t| t.tx[1].2 == 0x03 && t.tx[2].2 == 0x20 && t.tx[3].2 == 0xAB)
        .expect("a read of 0x20AB");
    let t0 = t.de_rise;
    let rel = |x: Ticks| us(x - t0);
    eprintln!("USART2 at {baud} baud (BRR {brr}, character {:.2} µs), one read of 0x20AB, µs from DE's rise (t0 = {:.1} ms of firmware time):", us(char_ticks as u64), us(t0) / 1000.0);
    eprintln!("  {:>9.2}  PA1 (DE) high", 0.0);
    for &(s, e, b) in &t.tx {
        eprintln!(
            "  {:>9.2}  TX start bit {b:#04x} (stop bit ends {:.2})",
            rel(s),
            rel(e)
        );
    }
    eprintln!("  {:>9.2}  TC set", rel(t.tc.unwrap()));
    eprintln!("  {:>9.2}  PA1 (DE) low", rel(t.de_fall));
    for &(e, b) in &t.rx {
        eprintln!(
            "  {:>9.2}  RX {b:#04x} stop bit ends (start {:.2})",
            rel(e),
            rel(e) - us(char_ticks as u64)
        );
    }
    eprintln!(
        "PA1 (DE) floats from reset (input, RM0008 §9.1.1) until init drives it low at {:.3} ms",
        us(de_driven_at) / 1000.0
    );
    eprintln!("request {UNANSWERED} unanswered: sent again {retry_wait:.1} µs after its TC");
    assert_eq!(twin.state().bus.usart[1].overruns, 0, "USART2 overruns");
    eprintln!(
        "{} transactions in {ms} ms: DE lead before the first start bit {:.2}..{:.2} µs; DE low after TC {:.2}..{:.2} µs (bound < {:.2}); bytes back to back (largest gap {:.2} µs, bound {:.1}); silence before a request ≥ {:.1} µs (bound {:.1}); driver answered {}; {host_s:.2} s on the host",
        transactions.len(),
        lead.0,
        lead.1,
        lag.0,
        lag.1,
        us(char_ticks as u64),
        inter_max / 72.0,
        within_frame / 72.0,
        gap_min / 72.0,
        silence / 72.0,
        driver.answered
    );

    // The read-back reaches the firmware: the status line's actual drum
    // speed is the driver's register × the scale. The status line shows
    // the supervisor's report filter (REPORT_ALPHA = 0.0196 per 10 ms
    // control period, τ ≈ 0.50 s) from the first read-back at ≈ 0.06 s:
    // at 4 s it is within e^(-3.94 / 0.50) ≈ 0.04 % of its input, so 1 %
    // is the test's margin, not the filter's.
    let expected_milli = f64::from(MOTOR_DECIRPM) * f64::from(MICRO_RPM_PER_COUNT) / 1000.0;
    let status = twin.log_lines("status:");
    let last = status.last().expect("a status line");
    assert!(
        last.contains("uptime 4001 ms"),
        "the 4 s status line: {last}"
    );
    let actual: f64 = last
        .split("actual ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .expect("the actual drum speed");
    eprintln!(
        "read-back: status says {actual} mr/min, the driver's register gives {expected_milli:.1}"
    );
    assert!(
        (actual - expected_milli).abs() <= 0.01 * expected_milli,
        "status: {last}"
    );
    assert!(
        twin.log_lines(&format!("at {baud} baud")).len() == 1,
        "the link runs at {baud} baud"
    );
    // One timeout is within the retry budget: the link is not lost.
    assert!(twin.log_lines("drive link: lost").is_empty());
}

#[test]
fn rs485_de_and_usart2_timing_at_9600_baud() {
    check(9600, 4100);
}

#[test]
fn rs485_de_and_usart2_timing_at_115200_baud() {
    check(115_200, 4100);
}
