//! Machine A's ground wheel on the real board's release image, on the twin:
//! TIM4 in encoder mode on PB6/PB7 (README pin map), driven by the
//! simulated machine's ground-wheel encoder through the twin's encoder
//! interface (RM0008 §15.3.12, `twin::periph::Bus::encoder_input`).
//!
//! Expected values: TIM4's and the pins' registers from RM0008 and the
//! README's pin map; the ground speed from the model's truth; the wheel's
//! calibration chosen here, never read from the firmware.

#[path = "support/board.rs"]
mod board;
#[path = "support/pages.rs"]
mod pages;

use hmi_proto::screen::TravelSource;
use kinematics::consts::Gear;
use supervisor::settings::wheel::{GroundWheelSettings, NOMINAL_COUNTS_PER_M_X1000};
use supervisor::settings::Settings;
use twin::plant::Wiring;
use twin::{External, Level, Options, Twin};

const TIM4: u32 = 0x4000_0800;
const GPIOB_CRL: u32 = 0x4001_0C00;
const GPIOB_ODR: u32 = 0x4001_0C0C;
const AFIO_MAPR: u32 = 0x4001_0004;
const RCC_APB1ENR: u32 = 0x4002_101C;

/// The wheel's calibration in the settings: 10 % more counts per metre
/// than the model's wheel gives (2400 counts a turn of π · 0.25 m, the
/// nominal wheel). A firmware that measures the ground with the wheel
/// reads it 1/1.1 of the truth; one that measures it with the Hall gear
/// (its k1 and k2 tables describe the model's track) reads the truth.
const COUNTS_PER_M_X1000: u32 = NOMINAL_COUNTS_PER_M_X1000 / 10 * 11;

fn field(v: u32, shift: u32, bits: u32) -> u32 {
    (v >> shift) & ((1 << bits) - 1)
}

/// The real board's image with saved settings naming `source`, machine A
/// (noiseless) at High 1 on the pins, the stop contact closed; run `ms`.
fn boot(source: TravelSource, ms: u64) -> Twin {
    let elf = twin::image::elf().expect("build the real-board image");
    let settings = Settings {
        ground_wheel: GroundWheelSettings {
            source,
            counts_per_m_x1000: COUNTS_PER_M_X1000,
            reversed: false,
        },
        ..Settings::default()
    };
    let options = Options {
        flash: Some(board::flash_with(&elf, &settings)),
        ..Options::default()
    };
    let mut twin = Twin::new(&elf, options).expect("load the ELF");
    twin.set_external('B', 10, External::Low);
    let machine = machine_sim::Config {
        initial_gear: Some(Gear::High1),
        ..machine_sim::Config::noiseless()
    }
    .build()
    .expect("machine");
    twin.attach_plant(machine, Wiring::ProfileA);
    twin.run_ms(ms).expect("run");
    twin
}

/// The firmware's travel speed in its last status line, m/s.
fn firmware_travel_m_s(twin: &mut Twin) -> f64 {
    let line = twin
        .log_lines("status: uptime")
        .pop()
        .expect("a status line");
    let mh: f64 = line
        .split("travel ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no travel in {line:?}"));
    mh / 3600.0
}

/// TIM4's counter as the CPU reads it, and the counts the plant's wheel
/// made TIM4 take (both from their starts).
fn wheel(twin: &Twin) -> (u32, i64) {
    let counted = twin.plant.as_ref().expect("plant").wheel_counted;
    (twin.peek(TIM4 + 0x24), counted)
}

/// Machine A's init programs TIM4 as the ground wheel's encoder (RM0008
/// §15.3.12 and the README pin map) and the firmware measures the ground
/// with what TIM4 counts: with the wheel as the travel source its travel
/// speed is the wheel's (the ground / 1.1 with this calibration), with
/// the Hall gear it is the ground's.
#[test]
fn machine_a_reads_its_ground_wheel_through_tim4_in_encoder_mode_on_pb6_pb7() {
    let mut twin = boot(TravelSource::GroundWheel, 3_000);
    // RCC_APB1ENR TIM4EN (bit 2, §7.3.8).
    assert_ne!(twin.peek(RCC_APB1ENR) & (1 << 2), 0, "TIM4EN");
    // AFIO_MAPR (§9.4.2): TIM4_REMAP (bit 12) = 0, TIM4 CH1/CH2 on
    // PB6/PB7 (§9.3.7); USART1_REMAP (bit 2) = 0, USART1 not on them.
    let mapr = twin.peek(AFIO_MAPR);
    assert_eq!(mapr & ((1 << 12) | (1 << 2)), 0, "AFIO_MAPR {mapr:#x}");
    // PB6/PB7: input with pull (CNF = 10, MODE = 00, §9.2.1), ODR = 1: up.
    let crl = twin.peek(GPIOB_CRL);
    assert_eq!(field(crl, 24, 4), 0b1000, "PB6 CRL nibble {crl:#x}");
    assert_eq!(field(crl, 28, 4), 0b1000, "PB7 CRL nibble {crl:#x}");
    assert_eq!(twin.peek(GPIOB_ODR) & 0xC0, 0xC0, "PB6/PB7 pulled up");
    // SMCR SMS = 011: encoder mode 3 (§15.4.3).
    assert_eq!(field(twin.peek(TIM4 + 0x08), 0, 3), 0b011, "TIM4 SMS");
    // CCMR1 (§15.4.7): CC1S = 01, CC2S = 01, IC1F = IC2F = 1111.
    let ccmr1 = twin.peek(TIM4 + 0x18);
    assert_eq!(field(ccmr1, 0, 2), 0b01, "CC1S {ccmr1:#x}");
    assert_eq!(field(ccmr1, 8, 2), 0b01, "CC2S {ccmr1:#x}");
    assert_eq!(field(ccmr1, 4, 4), 0b1111, "IC1F {ccmr1:#x}");
    assert_eq!(field(ccmr1, 12, 4), 0b1111, "IC2F {ccmr1:#x}");
    // CCER (§15.4.9): CC1P = CC2P = 0 (the settings turn a reversed wheel).
    assert_eq!(twin.peek(TIM4 + 0x20) & 0x22, 0, "CC1P, CC2P");
    // ARR = 0xFFFF (§15.4.12), CR1 CEN with CKD = 00 (§15.4.1).
    assert_eq!(twin.peek(TIM4 + 0x2C), 0xFFFF, "TIM4 ARR");
    let cr1 = twin.peek(TIM4);
    assert_eq!((cr1 & 1, field(cr1, 8, 2)), (1, 0), "TIM4 CR1 {cr1:#x}");

    // The wheel turned, TIM4 took every count, and the firmware's travel
    // speed is the wheel's.
    let (cnt, counted) = wheel(&twin);
    let truth = twin.plant.as_ref().unwrap().machine.travel_speed_m_s() as f64;
    let fw = firmware_travel_m_s(&mut twin);
    let on_wheel = truth / 1.1;
    eprintln!(
        "wheel source: TIM4 CNT {cnt}, counts taken {counted}; travel {fw:.4} m/s, ground {truth:.4} m/s, on the wheel {on_wheel:.4} m/s"
    );
    assert!(counted > 1000, "the wheel barely turned: {counted}");
    assert_eq!(i64::from(cnt), counted.rem_euclid(1 << 16), "TIM4 CNT");
    assert!(
        (fw - on_wheel).abs() <= 0.01 * on_wheel,
        "travel {fw} m/s, the wheel's {on_wheel} m/s"
    );

    // The same machine with the Hall gear as the source: the ground's.
    let mut twin = boot(TravelSource::HallGear, 3_000);
    let truth = twin.plant.as_ref().unwrap().machine.travel_speed_m_s() as f64;
    let fw = firmware_travel_m_s(&mut twin);
    eprintln!("Hall gear source: travel {fw:.4} m/s, ground {truth:.4} m/s");
    assert!(
        (fw - truth).abs() <= 0.02 * truth,
        "travel {fw} m/s, ground {truth} m/s"
    );
}

/// The stop input's interrupt stops the step timers at once with an update
/// event (EGR UG); on machine A TIM4 is the wheel's counter and an update
/// event would reset it (§15.4.6), which the supervisor would read as the
/// wheel running backwards. Opened while the wheel turns: TIM4 keeps every
/// count, PB6/PB7 stay pulled-up inputs, and no alarm comes of it.
#[test]
fn the_stop_input_leaves_machine_a_s_wheel_count_alone() {
    let mut twin = boot(TravelSource::GroundWheel, 1_500);
    twin.set_external('B', 10, External::Open);
    twin.run_ms(500).unwrap();
    let (cnt, counted) = wheel(&twin);
    eprintln!("after the stop input: TIM4 CNT {cnt}, counts taken {counted}");
    assert!(
        twin.log_lines("stop input: open").len() == 1,
        "the firmware saw the stop input open"
    );
    assert_eq!(i64::from(cnt), counted.rem_euclid(1 << 16), "TIM4 CNT");
    assert_eq!(twin.pin('B', 6), Level::PullUp, "PB6");
    assert_eq!(twin.pin('B', 7), Level::PullUp, "PB7");
    let alarms = twin.log_lines("alarm: ");
    assert!(alarms.is_empty(), "{alarms:?}");
}

/// A fatal error's safe state (here the crystal failing: the clock
/// security system's NMI) drives PA8 and PB12 low, and on machine A leaves
/// PB6 a pulled-up input: driving it low would short the wheel sensor's
/// output until the watchdog resets the board.
#[test]
fn a_fatal_error_on_machine_a_leaves_the_wheel_inputs_alone() {
    let mut twin = boot(TravelSource::GroundWheel, 500);
    twin.fail_crystal();
    twin.run_ms(20).unwrap();
    assert_eq!(twin.resets.len(), 1, "reset already: {:?}", twin.resets);
    assert_eq!(twin.pin('A', 8), Level::Low, "PA8");
    assert_eq!(twin.pin('B', 12), Level::Low, "PB12");
    assert_eq!(twin.pin('B', 6), Level::PullUp, "PB6");
    assert_eq!(twin.pin('B', 7), Level::PullUp, "PB7");
}
