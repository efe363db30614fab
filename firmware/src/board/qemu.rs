//! The QEMU board: `qemu-system-arm -machine stm32vldiscovery` (QEMU 7.2).
//!
//! QEMU emulates the Cortex-M3 core, SysTick, the NVIC and USART1–3, but not
//! RCC, GPIO, timers, the flash controller or the watchdog (writes ignored,
//! reads zero; HSE and PLL never become ready). So this board:
//!
//! - runs from the HSI (the HAL believes 8 MHz; QEMU's SysTick counts at a
//!   fixed 24 MHz, which is what the monotonic is started with);
//! - talks to the touchscreen over the real emulated USART1;
//! - replaces the TIM1 compare register, the TIM3 encoder counter and the
//!   TIM2 Hall captures by a simulated machine that the control task steps
//!   every period, so the same control code runs against it;
//! - writes defmt frames to the host over semihosting and ends a run through
//!   semihosting `exit`, with a time limit read from the semihosting command
//!   line (`run_ms=N`).
//!
//! What only the real board can show: clocks, pin levels, timer capture
//! latency, PWM on the pin, encoder noise, the flash controller, the watchdog.

use core::sync::atomic::{AtomicU16, Ordering::Relaxed};

use stm32f1xx_hal::{
    pac::{self, USART1},
    prelude::*,
    rcc,
    serial::{self, Rx, Tx},
};

use defmt_semihosting as _;

use super::{SensorSample, DRUM_ENCODER_COUNTS_PER_REV, DRUM_PWM_HZ, HALL_TIMER_HZ};

/// Transmit half of the touchscreen UART.
pub type HmiTx = Tx<USART1>;
/// Receive half of the touchscreen UART.
pub type HmiRx = Rx<USART1>;

/// QEMU's `stm32vldiscovery` clocks SysTick at a fixed 24 MHz.
pub const SYSCLK_HZ: u32 = 24_000_000;

/// The stand-in for TIM1's CCR1 register: written by [`DrumDrive`], read by
/// the machine model, zeroed by [`safe_state`].
static DRUM_CCR: AtomicU16 = AtomicU16::new(0);

/// Everything the application owns after [`init`].
pub struct Board {
    /// Touchscreen transmitter.
    pub hmi_tx: HmiTx,
    /// Touchscreen receiver, with its RX-not-empty interrupt enabled.
    pub hmi_rx: HmiRx,
    /// Drum PWM stand-in.
    pub drum: DrumDrive,
    /// The simulated machine behind the sensor interface.
    pub sensors: Sensors,
    /// Hall capture (never interrupts on this board).
    pub hall: HallCapture,
    /// Status LED stand-in.
    pub led: StatusLed,
    /// SysTick input frequency for the monotonic.
    pub sysclk_hz: u32,
}

/// Brings up the emulated peripherals. Called once from `init`.
pub fn init(dp: pac::Peripherals) -> Board {
    let mut flash = dp.FLASH.constrain();
    let mut rcc = dp.RCC.freeze(rcc::Config::hsi(), &mut flash.acr);
    let mut gpioa = dp.GPIOA.split(&mut rcc);
    let tx_pin = gpioa.pa9.into_alternate_push_pull(&mut gpioa.crh);
    let rx_pin = gpioa.pa10;
    let hmi = dp.USART1.serial(
        (tx_pin, rx_pin),
        serial::Config::default()
            .baudrate(115_200.bps())
            .parity_none(),
        &mut rcc,
    );
    let (hmi_tx, mut hmi_rx) = hmi.split();
    hmi_rx.listen();
    DRUM_CCR.store(0, Relaxed);
    Board {
        hmi_tx,
        hmi_rx,
        drum: DrumDrive { enabled: false },
        sensors: Sensors {
            machine: Machine::new(),
        },
        hall: HallCapture,
        led: StatusLed,
        sysclk_hz: SYSCLK_HZ,
    }
}

/// Compare value for 100 % duty, the same as the real board's TIM1 (72 MHz /
/// 20 kHz), so that the control code computes identical compare values.
const DRUM_PERIOD: u16 = (72_000_000 / DRUM_PWM_HZ) as u16;

/// Drum PWM stand-in.
pub struct DrumDrive {
    enabled: bool,
}

impl DrumDrive {
    /// Compare value that gives 100 % duty.
    pub const fn period(&self) -> u16 {
        DRUM_PERIOD
    }

    /// Sets the compare value (duty = `ccr / period()`), clamped to the period.
    pub fn set_compare(&mut self, ccr: u16) {
        let ccr = if self.enabled {
            ccr.min(DRUM_PERIOD)
        } else {
            0
        };
        DRUM_CCR.store(ccr, Relaxed);
    }

    /// Switches the motor driver on or off; off also zeroes the duty.
    pub fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
        if !on {
            DRUM_CCR.store(0, Relaxed);
        }
    }
}

/// The simulated machine, read like the real board's sensors.
pub struct Sensors {
    machine: Machine,
}

impl Sensors {
    /// Advances the machine to `now_ms` under the current PWM compare value and
    /// reads the encoder and the Hall edges that happened meanwhile.
    pub fn sample(&mut self, now_ms: u32) -> SensorSample {
        let mut edges = heapless::Vec::new();
        let duty = f32::from(DRUM_CCR.load(Relaxed)) / f32::from(DRUM_PERIOD);
        self.machine.advance_to(now_ms, duty, &mut edges);
        SensorSample {
            drum_encoder: self.machine.encoder_count(),
            hall_edges: edges,
        }
    }
}

/// Hall capture: edges come from [`Sensors::sample`] on this board.
pub struct HallCapture;

impl HallCapture {
    /// TIM2 never interrupts under QEMU.
    pub fn on_interrupt(&mut self) -> Option<u32> {
        None
    }
}

/// Status LED stand-in (GPIO is not emulated).
pub struct StatusLed;

impl StatusLed {
    /// Does nothing: QEMU has no LED.
    pub fn set(&mut self, _on: bool) {}
}

/// Zeroes the PWM stand-in (the model then coasts the drum to a stop).
pub fn safe_state() {
    DRUM_CCR.store(0, Relaxed);
}

/// Ends the emulation with a failure exit code after a fatal error.
pub fn fatal() -> ! {
    safe_state();
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Ends the emulation successfully (the run reached its time limit).
pub fn exit_success() -> ! {
    safe_state();
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

/// The run's time limit, from a `run_ms=N` word on the semihosting command
/// line (`-semihosting-config enable=on,target=native,arg=firmware,arg=run_ms=N`);
/// `None` runs until QEMU is killed.
pub fn run_limit_ms() -> Option<u32> {
    let mut buf = [0u8; 64];
    // SYS_GET_CMDLINE takes a two-word block {buffer, length} and writes the
    // used length back into it.
    let block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: the block points at a live buffer of the length it states; the
    // host writes at most that many bytes.
    let rc =
        unsafe { cortex_m_semihosting::syscall(cortex_m_semihosting::nr::GET_CMDLINE, &block) };
    if rc != 0 {
        return None;
    }
    // SAFETY: the host updated the length word behind a shared reference.
    let len = unsafe { core::ptr::read_volatile(&block[1]) }.min(buf.len());
    let line = buf.get(..len)?;
    line.split(|&b| b == b' ')
        .find_map(|word| word.strip_prefix(b"run_ms="))
        .and_then(parse_u32)
}

fn parse_u32(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u32, |acc, &d| {
        if d.is_ascii_digit() {
            acc.checked_mul(10)?.checked_add(u32::from(d - b'0'))
        } else {
            None
        }
    })
}

/// Placeholder machine: constant travel at 0.52 km/h (paper A's Low 2) and a
/// drum motor that follows its duty through a 25 ms first-order lag. The full
/// machine simulator replaces it.
struct Machine {
    now_ms: u32,
    /// Travel speed, m/s.
    travel_speed: f32,
    /// Track travelled since the last Hall edge, m.
    since_edge_m: f32,
    /// Microseconds since start, in Hall timer ticks.
    ticks: u32,
    /// Drum speed, r/min.
    drum_speed: f32,
    /// Encoder position, counts (fractional).
    encoder: f32,
}

/// Track per Hall edge: π·(0.16 + 2·0.02) m / 25 teeth.
const TOOTH_PITCH_M: f32 = core::f32::consts::PI * 0.20 / 25.0;
/// Drum speed at 100 % duty, r/min (SPEC §3).
const DRUM_MAX_RPM: f32 = 44.7;
/// Motor time constant, s.
const DRUM_TAU_S: f32 = 0.025;

impl Machine {
    fn new() -> Self {
        Self {
            now_ms: 0,
            travel_speed: 0.52 / 3.6,
            since_edge_m: 0.0,
            ticks: 0,
            drum_speed: 0.0,
            encoder: 0.0,
        }
    }

    fn advance_to(
        &mut self,
        now_ms: u32,
        duty: f32,
        edges: &mut heapless::Vec<u32, { super::MAX_EDGES_PER_SAMPLE }>,
    ) {
        const DT: f32 = 0.001;
        const TICKS_PER_MS: u32 = HALL_TIMER_HZ / 1_000;
        while self.now_ms < now_ms {
            self.now_ms += 1;
            self.ticks = self.ticks.wrapping_add(TICKS_PER_MS);
            self.since_edge_m += self.travel_speed * DT;
            if self.since_edge_m >= TOOTH_PITCH_M {
                self.since_edge_m -= TOOTH_PITCH_M;
                let late_us = (self.since_edge_m / self.travel_speed * 1e6) as u32;
                let _ = edges.push(self.ticks.wrapping_sub(late_us));
            }
            let target = duty.clamp(0.0, 1.0) * DRUM_MAX_RPM;
            self.drum_speed += (target - self.drum_speed) * (DT / DRUM_TAU_S);
            self.encoder += self.drum_speed / 60.0 * DRUM_ENCODER_COUNTS_PER_REV as f32 * DT;
            if self.encoder >= 65_536.0 {
                self.encoder -= 65_536.0;
            }
        }
    }

    fn encoder_count(&self) -> u16 {
        self.encoder as u16
    }
}
