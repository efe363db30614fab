//! The QEMU board: `qemu-system-arm -machine netduino2` (QEMU 7.2).
//!
//! The machine is QEMU's STM32F205 model, chosen for its memory: 128 KB of
//! SRAM, of which this board takes the real board's 20 KB at 0x2000_0000
//! (`memory-qemu.x`, the STM32F103RB's RAM layout), so that the statics and
//! the stack are laid out, and measured, as on the real board; its code may
//! use 256 KB of the model's 1 MB of flash, since it carries the simulated
//! machine. QEMU emulates
//! the Cortex-M3 core, SysTick, the NVIC and the USARTs (the same USART
//! model as its STM32F100's), but not RCC, GPIO, timers, the flash
//! controller or the watchdog of an F103: the F1 addresses of those read
//! zero and ignore writes. So this board:
//!
//! - runs from the HSI as far as the HAL knows (8 MHz); QEMU clocks the
//!   core and SysTick at the machine's fixed 120 MHz, which is what the
//!   monotonic is started with;
//! - talks to the touchscreen over the emulated USART1, at the F205's
//!   address ([`usart1`]), and to the drum driver over USART2 (the F1's
//!   address on both);
//! - replaces the registers the real board reads and writes — TIM1's compare
//!   value, the driver enable pin, TIM3's encoder counter, TIM2's Hall
//!   captures and counter — by atomics and a simulated machine
//!   ([`machine_sim`]) that the control task steps every period, so the same
//!   control code runs against it;
//! - keeps the settings in a host file through semihosting (`flash=PATH` on
//!   the semihosting command line), a stand-in for the NOR flash that behaves
//!   like the F103's (erase to 0xFF, half-word programming only onto erased
//!   half-words) and survives a reboot of the emulated board;
//! - takes a test scenario from the semihosting command line (gear, travel
//!   disturbances, injected faults at given firmware times);
//! - writes defmt frames to the host over semihosting and ends a run through
//!   semihosting `exit` at `run_ms=N`.
//!
//! What only the real board can show: see `docs/firmware.md`.

use core::sync::atomic::{AtomicBool, AtomicU16, AtomicU32, Ordering::Relaxed};

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use machine_sim::{Event, Fault, Inputs, Machine};
use stm32f1xx_hal::{
    pac::{self, USART2},
    serial::{self, Tx},
};
use stm32f1xx_hal::{prelude::*, rcc};

use defmt_semihosting as _;

use super::{
    check_flash_access, check_flash_erase, FlashError, SensorSample, DRUM_PWM_HZ,
    SETTINGS_FLASH_BYTES, SETTINGS_PAGE_BYTES,
};

mod stack_guard;
mod usart1;

/// USART1's transmit half, driven by [`super::HmiTx`].
pub type ScreenUsartTx = usart1::Tx;

/// Most screen bytes one lock-step period carries (a real line carries
/// ≈ 115 per 10 ms; the tests send at most this many).
const GATE_BYTES: usize = 32;
/// Screen bytes delivered through the lock-step gate, for [`HmiRx`].
type GateQueue = heapless::spsc::Queue<u8, { GATE_BYTES + 1 }>;

/// Receive half of the touchscreen UART. In lock-step the screen's bytes
/// come through the gate at the start of a control period (see
/// [`Sensors::sample`]) and are read here first, through the same USART1
/// interrupt task; otherwise from the emulated USART1.
pub struct HmiRx {
    uart: usart1::Rx,
    gate: heapless::spsc::Consumer<'static, u8>,
}

impl HmiRx {
    /// The next received byte.
    pub fn read(&mut self) -> nb::Result<u8, serial::Error> {
        match self.gate.dequeue() {
            Some(byte) => {
                if self.gate.ready() {
                    // More to come: the interrupt task runs again.
                    pac::NVIC::pend(pac::Interrupt::USART1);
                }
                Ok(byte)
            }
            None => self.uart.read(),
        }
    }
}

/// QEMU's `netduino2` clocks the core, and SysTick's processor clock, at a
/// fixed 120 MHz (its SYSCLK; RCC is not modelled).
pub const SYSCLK_HZ: u32 = 120_000_000;

/// Stand-in for TIM1's CCR1 register.
static DRUM_CCR: AtomicU16 = AtomicU16::new(0);
/// Stand-in for the driver enable pin.
static DRIVER_ENABLE: AtomicBool = AtomicBool::new(false);
/// Stand-in for TIM2's counter, extended to 32 bits (1 MHz).
static HALL_TIMER_NOW: AtomicU32 = AtomicU32::new(0);
/// Stand-ins for the step-pulse timers of profile B (rate, U16F16 Hz bits).
static FEED_STEP_BITS: AtomicU32 = AtomicU32::new(0);
static PLANT_STEP_BITS: AtomicU32 = AtomicU32::new(0);
/// Stand-in for the stop input pin PB10 (high = contact open = stop).
static STOP_INPUT_OPEN: AtomicBool = AtomicBool::new(false);
/// Stand-in for the work switch pin PB11 (low = contact closed = unit
/// down); the scenario moves it.
static WORK_SWITCH_CLOSED: AtomicBool = AtomicBool::new(false);
/// Truth: when the simulated contact opened, and when [`stop_outputs`] made
/// the outputs safe after it (µs of firmware time).
static STOP_OPENED_US: AtomicU32 = AtomicU32::new(0);
static STOP_SAFE_US: AtomicU32 = AtomicU32::new(0);

// The drum driver's line (docs/drive-link.md).

/// Longest frame the virtual driver's gate record carries (a Modbus RTU
/// reply of this link is at most 9 bytes; a corrupted one the same).
pub const DRIVE_FRAME_MAX: usize = drive_link::rtu::MAX_FRAME;

/// A reply frame from the host's virtual driver and the firmware time (µs,
/// wrapping 32-bit) at which its last byte has arrived.
#[derive(Clone, Copy)]
pub struct DriveFrame {
    end_us: u32,
    len: u8,
    bytes: [u8; DRIVE_FRAME_MAX],
}

/// The sensors as the application holds them (a static on this board).
pub type SensorsRef = &'static mut Sensors;

/// The drum driver's line as the application holds it.
pub type DriveLineRef = &'static mut DriveLine;

/// Reply frames from the gate to [`DriveLine`] (three at a time at most).
type DriveRxQueue = heapless::spsc::Queue<DriveFrame, 4>;
/// When each request frame's last bit left (firmware µs), for the truth
/// record (see [`Sensors::sample`]): at most two requests fit in a 10 ms
/// period at 115 200 baud.
type DriveTxQueue = heapless::spsc::Queue<u32, 4>;
/// Most request end times one truth record carries.
const TRUTH_MAX_FRAMES: usize = 3;

/// USART2, the RS-485 line to the drum driver (QEMU: DE on PA1 is a no-op).
///
/// QEMU's USART sends a byte the moment it is written, so the line's time
/// is modelled here: a request of `n` bytes ends `n` character times
/// (11 bits each, `drive_link::timing`) after it was started; the replies
/// come from the host's virtual driver through the lock-step gate, each
/// with the firmware time its last byte arrives (the host computes it from
/// the request's end, the driver's turnaround and the reply's own time on
/// the line), and are handed over from that time on.
pub struct DriveLine {
    tx: Tx<USART2>,
    baud: u32,
    sending_until: Option<u64>,
    rx: heapless::spsc::Consumer<'static, DriveFrame>,
    tx_ends: heapless::spsc::Producer<'static, u32>,
}

impl DriveLine {
    /// The line's speed (QEMU's USART ignores it; the model uses it).
    pub fn set_baud(&mut self, baud: u32) {
        self.baud = baud;
    }

    /// Sends a request frame (DE high first: no-op here).
    pub fn send(&mut self, frame: &[u8], now_us: u64) {
        for &b in frame {
            let _ = nb::block!(self.tx.write_u8(b));
        }
        let chars = u32::try_from(frame.len()).unwrap_or(u32::MAX);
        let on_line = drive_link::timing::frame_time_us(self.baud, chars).unwrap_or(0);
        let end = now_us.saturating_add(u64::from(on_line));
        self.sending_until = Some(end);
        let _ = self.tx_ends.enqueue(end as u32);
    }

    /// The request's last stop bit has left (TC; DE low): its time, once.
    pub fn sent(&mut self, now_us: u64) -> Option<u64> {
        match self.sending_until {
            Some(end) if now_us >= end => {
                self.sending_until = None;
                Some(end)
            }
            _ => None,
        }
    }

    /// A reply frame whose last byte has arrived by `now_us`, into `buf`.
    pub fn receive(&mut self, now_us: u64, buf: &mut [u8]) -> Option<usize> {
        let f = self.rx.peek()?;
        // Due when `end_us` is not after now (wrapping 32-bit µs).
        if (now_us as u32).wrapping_sub(f.end_us) >= 1 << 31 {
            return None;
        }
        let f = self.rx.dequeue()?;
        let n = usize::from(f.len).min(DRIVE_FRAME_MAX).min(buf.len());
        buf.get_mut(..n)?.copy_from_slice(f.bytes.get(..n)?);
        Some(n)
    }

    /// Whether a reply is on the line at `now_us`, its frame not yet ended
    /// by its silence (from its first byte: its end less its time on the
    /// line and the 3.5-character silence).
    pub fn receiving(&mut self, now_us: u64) -> bool {
        let Some(f) = self.rx.peek() else {
            return false;
        };
        let on_line = drive_link::timing::frame_time_us(self.baud, u32::from(f.len)).unwrap_or(0);
        let silent = drive_link::timing::silent_interval_us(self.baud).unwrap_or(0);
        let start = f.end_us.wrapping_sub(on_line).wrapping_sub(silent);
        // Started when `start` is not after now (wrapping 32-bit µs).
        (now_us as u32).wrapping_sub(start) < 1 << 31
    }

    /// USART2's interrupt: never enabled on this board.
    pub fn on_interrupt(&mut self, _now_us: u64) {}
}

/// Everything the application owns after [`init`].
pub struct Board {
    /// Touchscreen transmitter.
    pub hmi_tx: super::HmiTx,
    /// Touchscreen receiver, with its RX-not-empty interrupt enabled.
    pub hmi_rx: HmiRx,
    /// The drum driver's RS-485 line (USART2), in a static.
    pub drive_line: DriveLineRef,
    /// Drum PWM stand-in.
    pub drum: DrumDrive,
    /// The simulated machine behind the sensor interface, in a static.
    pub sensors: SensorsRef,
    /// Hall capture (never interrupts on this board).
    pub hall: HallCapture,
    /// Status LED stand-in.
    pub led: StatusLed,
    /// The stop input (the scenario opens and closes it and pends EXTI15_10).
    pub stop_input: StopInput,
    /// The work switch (the scenario closes and opens it).
    pub work_switch: WorkSwitchInput,
    /// The watchdog stand-in.
    pub watchdog: Watchdog,
    /// Profile B's feeding step output stand-in.
    pub feed_step: FeedStep,
    /// The settings flash stand-in, if the command line named a file.
    pub settings_flash: Option<SettingsFlash>,
    /// Run limit from the command line.
    pub run_limit_ms: Option<u32>,
    /// SysTick input frequency for the monotonic.
    pub sysclk_hz: u32,
}

/// Words of the semihosting command line this board understands.
#[derive(Default)]
struct CmdLine {
    run_ms: Option<u32>,
    scenario: Scenario,
    /// `gate=PATH`: the lock-step gate (see [`Sensors::sample`]).
    gate: [u8; GATE_PATH_MAX],
    gate_len: usize,
}

/// Longest lock-step gate path (the tests use a short one in `/tmp`;
/// 32 keeps `Default` derivable).
const GATE_PATH_MAX: usize = 32;

/// Scheduled changes to the simulated machine, in firmware milliseconds.
///
/// `gear=N` (1–6, Low 1 … High 3) sets the travel gear at boot;
/// `step=T:+P` / `step=T:-P` sets the travel speed P % off its gear speed at
/// T ms (`step=T:0` returns to it; up to four); `tau=MS` gives the chassis a
/// speed time constant;
/// `stop=T` stops the tractor at T ms; `stopgo=MS` drives it stop-and-go
/// (MS/2 of travel, MS/2 of rest, from boot); `stop_input=T` opens the stop
/// input's contact at T ms and `stop_input_close=T` closes it; `stall=T`, `hall_loss=T`,
/// `enc_loss=T` inject faults at T ms; `noise=0` makes the model noiseless;
/// `seed=N` seeds it; `slip=P` scales the track slip of paper A's Table 12
/// to P % (a machine whose calibration is not the paper's); `plant_log=1`
/// logs every plant the model drops (`sim: plant N at P um`, the main job's
/// report plots each spacing from them; off by default to keep the long
/// accelerated runs' logs short). The work switch (PB11): `work_down=T`
/// closes its contact (unit down) at T ms, `work_up=T` opens it; or, by
/// the simulated machine's true ground position, `work_down_mm=D` and
/// `work_up_mm=D` (up to four in all, each once; the contact starts open, as an
/// unwired input reads); `scatter=0` turns the landing scatter alone off
/// (the figures of the control, without the seedlings' fall) and
/// `slip_noise=0` the random variation of the track and belt slip around
/// their means (which no sensor of the machine sees). `drive_tau=MS`,
/// `drive_dead=MS` (0–63) and `drive_nmax=N` (r/min × 100) give the drum
/// another drive than the default 25 ms / 5 ms / 44.70 r/min (the drive
/// identification's test); `load=P` sets the seedlings' load droop to P ‰
/// (`load=0`: an empty belt). `stack_overflow=T` runs the control task's
/// stack off the bottom of RAM at T ms (the stack guard's test).
#[derive(Default, Clone, Copy)]
struct Scenario {
    gear: Option<u8>,
    step: [Option<(u32, i32)>; 4],
    tau_ms: Option<u32>,
    stop: Option<u32>,
    stop_input: Option<u32>,
    stop_input_close: Option<u32>,
    /// Stop-and-go period, ms (`stopgo=MS`).
    stop_go_ms: Option<u32>,
    /// The host runs a virtual drum driver on USART2 (`drive_link=1`,
    /// lock-step only): see [`Sensors::sample`].
    drive_link: bool,
    stall: Option<u32>,
    hall_loss: Option<u32>,
    enc_loss: Option<u32>,
    noiseless: bool,
    seed: Option<u32>,
    /// Profile B machine (`profile=b`).
    profile_b: bool,
    /// Travel speed override, mm/s (`speed=N`).
    speed_mm_s: Option<u32>,
    /// Restart the field metrics at this time (`metrics_from=T`).
    metrics_from: Option<u32>,
    /// Track slip, % of Table 12's (`slip=P`).
    slip_pct: Option<u32>,
    /// Log every plant's ground position (`plant_log=1`).
    plant_log: bool,
    /// The drum drive's time constant, ms (`drive_tau=MS`).
    drive_tau_ms: Option<u32>,
    /// Its dead time, ms (`drive_dead=MS`).
    drive_dead_ms: Option<u32>,
    /// Its speed at 100 % duty, r/min × 100 (`drive_nmax=N`).
    drive_nmax_centi: Option<u32>,
    /// The seedlings' load droop, ‰ (`load=P`).
    load_permille: Option<u32>,
    /// Work switch changes, packed to keep `init`'s stack small: bit 31
    /// closed (down), bit 30 the value is ground mm (else firmware ms),
    /// bits 0–29 the value; 0 = none.
    work: [u32; 4],
    /// No landing scatter (`scatter=0`).
    no_scatter: bool,
    /// No slip variation (`slip_noise=0`).
    no_slip_noise: bool,
    /// Run the stack off the bottom of RAM at this time
    /// (`stack_overflow=T`, the test of [`stack_guard`]).
    stack_overflow: Option<u32>,
}

/// [`Scenario::work`]: the contact closes (unit down).
const WORK_CLOSED: u32 = 1 << 31;
/// [`Scenario::work`]: the value is a ground position in mm.
const WORK_GROUND: u32 = 1 << 30;
/// [`Scenario::work`]: the value's bits.
const WORK_VALUE: u32 = WORK_GROUND - 1;

/// Brings up the emulated peripherals. Called once from `init`.
#[inline(never)]
pub fn init(dp: pac::Peripherals) -> Board {
    stack_guard::enable();
    let (tx, mut uart_rx) = usart1::split(dp.USART1);
    let hmi_tx = super::HmiTx::new(tx);
    uart_rx.listen();
    // Note: `init` runs once, so the singleton is still free.
    let Some(gate_queue) = cortex_m::singleton!(: GateQueue = GateQueue::new()) else {
        fatal()
    };
    let (gate_in, gate_out) = gate_queue.split();
    let hmi_rx = HmiRx {
        uart: uart_rx,
        gate: gate_out,
    };
    // The drum driver's line: USART2 on PA2/PA3 (8N1; QEMU ignores the
    // rate, the model in `DriveLine` uses the profile's), through the HAL
    // (the F1's USART2 address is the F205's too; its RCC, AFIO and GPIO
    // writes land on unmapped addresses, which this machine ignores, and
    // HSI is the one clock that needs no ready flag).
    let mut rcc = dp
        .RCC
        .freeze(rcc::Config::hsi(), &mut dp.FLASH.constrain().acr);
    let mut gpioa = dp.GPIOA.split(&mut rcc);
    let tx2 = gpioa.pa2.into_alternate_push_pull(&mut gpioa.crl);
    let drive_uart = dp.USART2.serial(
        (tx2, gpioa.pa3),
        serial::Config::default()
            .baudrate(9_600.bps())
            .parity_none(),
        &mut rcc,
    );
    let (drive_tx, _drive_rx) = drive_uart.split();
    let (Some(drive_rx_queue), Some(drive_tx_queue)) = (
        cortex_m::singleton!(: DriveRxQueue = DriveRxQueue::new()),
        cortex_m::singleton!(: DriveTxQueue = DriveTxQueue::new()),
    ) else {
        fatal()
    };
    let (drive_rx_in, drive_rx_out) = drive_rx_queue.split();
    let (drive_tx_in, drive_tx_out) = drive_tx_queue.split();
    DRUM_CCR.store(0, Relaxed);
    DRIVER_ENABLE.store(false, Relaxed);

    let mut path = [0u8; 96];
    let mut cmd = CmdLine::default();
    let path_len = read_cmdline(&mut cmd, &mut path);
    let settings_flash = path
        .get(..path_len)
        .filter(|p| !p.is_empty())
        .and_then(SettingsFlash::open);
    // Mode 1 = "rb".
    let gate_path = cmd.gate.get(..cmd.gate_len).filter(|p| !p.is_empty());
    let gate = gate_path.and_then(|p| sh::open(p, 1, None));
    // Mode 5 = "wb": the truth FIFO is the gate's path with a `t`.
    let truth = gate_path
        .filter(|_| cmd.scenario.drive_link && gate.is_some())
        .and_then(|p| sh::open(p, 5, Some(b't')));

    let scenario = cmd.scenario;
    let mut config = if scenario.noiseless {
        machine_sim::Config::noiseless()
    } else {
        machine_sim::Config::default()
    };
    if let Some(seed) = scenario.seed {
        config.seed = u64::from(seed);
    }
    if let Some(tau) = scenario.tau_ms {
        config.track_tau_s = tau as f32 / 1000.0;
    }
    if let Some(tau) = scenario.drive_tau_ms {
        config.motor_tau_s = tau as f32 / 1000.0;
    }
    if let Some(dead) = scenario.drive_dead_ms.and_then(|d| u8::try_from(d).ok()) {
        config.transport_delay_ms = dead.min(machine_sim::MAX_TRANSPORT_DELAY_MS);
    }
    if let Some(n) = scenario.drive_nmax_centi {
        config.n_max_rpm = n as f32 / 100.0;
    }
    if let Some(p) = scenario.load_permille {
        config.load_droop = p as f32 / 1000.0;
    }
    if let Some(period) = scenario.stop_go_ms {
        config.terrain_stop_interval_s = period as f32 / 2000.0;
        config.terrain_stop_duration_s = period as f32 / 2000.0;
        config.terrain_stops_regular = true;
    }
    if let Some(pct) = scenario.slip_pct {
        config.track_slip_scale = pct as f32 / 100.0;
    }
    if scenario.no_scatter {
        config.plant_scatter_m = 0.0;
    }
    if scenario.no_slip_noise {
        config.track_slip_noise = 0.0;
        config.belt_slip_noise = 0.0;
    }
    if scenario.profile_b {
        config.profile = machine_sim::Profile::B;
        // The metrics' target: profile B's default spacing X = 25 cm.
        config.target_spacing_m = 0.25;
    }
    config.initial_gear = scenario
        .gear
        .and_then(|g| kinematics::consts::Gear::ALL.get(usize::from(g).wrapping_sub(1)))
        .copied();
    // The model lives in a static (592 B): moving it through `init`'s
    // return value would need its size again on the stack.
    let machine = match config.build() {
        Ok(m) => cortex_m::singleton!(: Machine = m),
        Err(_) => None,
    };
    let Some(machine) = machine else {
        // The configurations above are valid: a build-time mistake.
        defmt::error!("machine model configuration rejected");
        fatal()
    };
    if let Some(v) = scenario.speed_mm_s {
        machine.set_travel_speed_m_s(v as f32 / 1000.0);
    }
    let Some(drive_line) = cortex_m::singleton!(: DriveLine = DriveLine {
        tx: drive_tx,
        baud: 9_600,
        sending_until: None,
        rx: drive_rx_out,
        tx_ends: drive_tx_in,
    }) else {
        fatal()
    };
    let drive = match truth {
        Some(truth) => cortex_m::singleton!(: DriveSim = DriveSim {
            truth,
            rx_in: drive_rx_in,
            tx_ends: drive_tx_out,
            flags: 0,
            command_milli_rpm: 0,
        }),
        None => None,
    };
    // In a static: moved through `init` by value, its ≈ 0.25 KB sat twice
    // in the frame under which RTIC runs the first tasks.
    let Some(sensors) = cortex_m::singleton!(: Sensors = Sensors {
        machine,
        scenario,
        now_ms: 0,
        roller_turns_seen: 0,
        stop_watch: StopWatch::default(),
        work_fired: 0,
        gate,
        gate_in,
        drive,
    }) else {
        fatal()
    };
    Board {
        hmi_tx,
        hmi_rx,
        drive_line,
        drum: DrumDrive { enabled: false },
        sensors,
        hall: HallCapture,
        led: StatusLed,
        stop_input: StopInput,
        work_switch: WorkSwitchInput,
        watchdog: Watchdog,
        feed_step: FeedStep,
        settings_flash,
        run_limit_ms: cmd.run_ms,
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
        DRUM_CCR.store(ccr.min(DRUM_PERIOD), Relaxed);
    }

    /// Switches the motor driver on or off; off also zeroes the duty.
    pub fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
        DRIVER_ENABLE.store(on, Relaxed);
        if !on {
            DRUM_CCR.store(0, Relaxed);
        }
    }

    /// The compare value and enable as the drive sees them (what a scope on
    /// PA8 and PB12 would show).
    pub fn output(&self) -> (u16, bool) {
        (DRUM_CCR.load(Relaxed), DRIVER_ENABLE.load(Relaxed))
    }
}

/// Profile B's two step-pulse outputs (stand-ins for TIM1 CH1 and TIM4 CH1)
/// and the drivers' enable.
pub struct Steppers {
    _drum: DrumDrive,
    _feed: FeedStep,
}

/// Profile B's feeding step output stand-in (TIM4 is not emulated).
pub struct FeedStep;

impl Steppers {
    /// Takes over the drum PWM's timer for step pulses (profile B).
    pub fn new(drum: DrumDrive, feed: FeedStep) -> Self {
        FEED_STEP_BITS.store(0, Relaxed);
        PLANT_STEP_BITS.store(0, Relaxed);
        Self {
            _drum: drum,
            _feed: feed,
        }
    }

    /// Sets both pulse rates (U16F16 Hz) and the drivers' enable.
    pub fn set(
        &mut self,
        feed: kinematics::units::Hertz,
        plant: kinematics::units::Hertz,
        enabled: bool,
    ) {
        DRIVER_ENABLE.store(enabled, Relaxed);
        let (feed, plant) = if enabled {
            (feed.to_bits(), plant.to_bits())
        } else {
            (0, 0)
        };
        FEED_STEP_BITS.store(feed, Relaxed);
        PLANT_STEP_BITS.store(plant, Relaxed);
    }
}

/// The simulated machine, read like the real board's sensors.
pub struct Sensors {
    machine: &'static mut Machine,
    scenario: Scenario,
    now_ms: u32,
    /// Feeding-roller turns already reported as index pulses (profile B).
    roller_turns_seen: u32,
    /// Profile B: when the steppers came to rest after the tractor stopped.
    stop_watch: StopWatch,
    /// The scenario's work switch changes done (bit i: entry i).
    work_fired: u8,
    /// The lock-step gate: a host FIFO read once per control period.
    gate: Option<usize>,
    /// Screen bytes from the gate, to [`HmiRx`].
    gate_in: heapless::spsc::Producer<'static, u8>,
    /// The host's virtual drum driver (`drive_link=1`), in a static.
    drive: Option<&'static mut DriveSim>,
}

/// The QEMU board's side of the host's virtual drum driver.
struct DriveSim {
    /// The truth FIFO (semihosting handle).
    truth: usize,
    /// Replies from the gate, to [`DriveLine`].
    rx_in: heapless::spsc::Producer<'static, DriveFrame>,
    /// Request end times from [`DriveLine`].
    tx_ends: heapless::spsc::Consumer<'static, u32>,
    /// The driver's state from the last gate record: bit 0 its motor is
    /// enabled (control word, no fault), bit 1 it runs on its bus speed
    /// command (velocity mode, a command received) rather than the PWM.
    flags: u8,
    /// Its bus speed command, drum milli-r/min.
    command_milli_rpm: i32,
}

/// [`DriveSim::flags`]: the driver's motor is enabled.
const DRIVE_ENABLED: u8 = 1;
/// [`DriveSim::flags`]: the driver follows its bus speed command.
const DRIVE_BUS_COMMAND: u8 = 2;

/// Profile B's stop check, on the simulator's side: after the scenario's
/// `stop`, the sample time of the last ground-encoder count and the first
/// sample that finds both step rates at zero, logged once as
/// `sim-b: steppers at rest at T ms, last ground count at C ms`.
#[derive(Default)]
struct StopWatch {
    last_ground_count: u16,
    last_count_ms: u32,
    reported: bool,
}

fn due(at: Option<u32>, from: u32, to: u32) -> bool {
    at.is_some_and(|t| t > from && t <= to)
}

/// The truth record of a control period, to the host's virtual driver:
/// the firmware time (µs, u32), the true drum speed (milli-r/min, i32),
/// then how many requests ended
/// since the last record and each one's end (firmware µs, u32); all little
/// endian. Written before the gate is read, so that the host, having read
/// it, knows the period before has ended and its requests are on USART2.
fn write_truth(d: &mut DriveSim, drum_rpm: f32) {
    const HEAD: usize = 9;
    let mut rec = [0u8; HEAD + 4 * TRUTH_MAX_FRAMES];
    let milli = (drum_rpm * 1000.0) as i32;
    let mut n = 0usize;
    if let Some(dst) = rec.get_mut(..4) {
        dst.copy_from_slice(&now_us().to_le_bytes());
    }
    if let Some(dst) = rec.get_mut(4..8) {
        dst.copy_from_slice(&milli.to_le_bytes());
    }
    while n < TRUTH_MAX_FRAMES {
        let Some(end) = d.tx_ends.dequeue() else {
            break;
        };
        if let Some(dst) = rec.get_mut(HEAD + 4 * n..HEAD + 4 + 4 * n) {
            dst.copy_from_slice(&end.to_le_bytes());
        }
        n += 1;
    }
    if let Some(c) = rec.get_mut(8) {
        *c = n as u8;
    }
    let _ = sh::write(d.truth, rec.get(..HEAD + 4 * n).unwrap_or(&[]));
}

/// The virtual driver's part of a gate record: a count (≤ 3) of reply
/// frames, each with the firmware time its last byte arrives (µs, u32),
/// its length and bytes; then the driver's flags and bus speed command
/// (drum milli-r/min, i32). False when the host's end is gone.
fn read_drive(h: usize, d: &mut DriveSim) -> bool {
    let mut count = [0u8; 1];
    if !sh::read(h, &mut count) {
        return false;
    }
    for _ in 0..count[0].min(3) {
        let mut head = [0u8; 5];
        if !sh::read(h, &mut head) {
            return false;
        }
        let [e0, e1, e2, e3, len] = head;
        let mut f = DriveFrame {
            end_us: u32::from_le_bytes([e0, e1, e2, e3]),
            len: len.min(DRIVE_FRAME_MAX as u8),
            bytes: [0; DRIVE_FRAME_MAX],
        };
        let n = usize::from(f.len);
        if n > 0 && !f.bytes.get_mut(..n).is_some_and(|b| sh::read(h, b)) {
            return false;
        }
        let _ = d.rx_in.enqueue(f);
    }
    let mut tail = [0u8; 5];
    if !sh::read(h, &mut tail) {
        return false;
    }
    let [flags, c0, c1, c2, c3] = tail;
    d.flags = flags;
    d.command_milli_rpm = i32::from_le_bytes([c0, c1, c2, c3]);
    true
}

impl Sensors {
    /// Advances the machine to `now_ms` under the current PWM output and
    /// reads the encoder and the Hall edges that happened meanwhile.
    ///
    /// Lock-step (`gate=PATH`, under QEMU's `-icount`): first reads the
    /// next message from the host FIFO — a count `n` (≤ 32) and `n` bytes
    /// the screen sent during the period — blocking the whole emulation
    /// until the test allows one more control period, so that firmware time
    /// never runs ahead of the virtual touchscreen and a busy host cannot
    /// make a period late. The screen's bytes then reach the USART1
    /// interrupt task (pended here) as if the emulated USART had received
    /// them. At end of file (the test closed its end) the board runs free.
    pub fn sample(&mut self, now_ms: u32) -> SensorSample {
        if let (Some(_), Some(d)) = (self.gate, self.drive.as_deref_mut()) {
            write_truth(d, self.machine.drum_speed_rpm());
        }
        if let Some(h) = self.gate {
            let mut count = [0u8; 1];
            let mut bytes = [0u8; GATE_BYTES];
            let ok = sh::read(h, &mut count)
                && {
                    let n = usize::from(count[0]).min(GATE_BYTES);
                    bytes
                        .get_mut(..n)
                        .is_some_and(|b| b.is_empty() || sh::read(h, b))
                }
                && self.drive.as_deref_mut().is_none_or(|d| read_drive(h, d));
            if ok {
                let n = usize::from(count[0]).min(GATE_BYTES);
                for &b in bytes.get(..n).unwrap_or(&[]) {
                    let _ = self.gate_in.enqueue(b);
                }
                if n > 0 {
                    pac::NVIC::pend(pac::Interrupt::USART1);
                }
            } else {
                self.gate = None;
            }
        }
        let mut edges = heapless::Vec::new();
        let (from, to) = (self.now_ms, now_ms);
        let s = self.scenario;
        for (at, pct) in s.step.iter().flatten() {
            if due(Some(*at), from, to) {
                self.machine.inject_speed_step(*pct as f32 / 100.0);
                defmt::info!("sim: travel speed step {=i32} %", pct);
            }
        }
        if due(s.metrics_from, from, to) {
            self.machine.reset_metrics();
            defmt::info!("sim: field metrics restarted");
        }
        if due(s.stop, from, to) {
            self.machine.stop_travel();
            defmt::info!("sim: tractor stops");
        }
        if due(s.stop_input, from, to) {
            // The contact opens now: the pin goes high and its interrupt is
            // pended (EXTI15_10, priority 5, runs before this returns).
            STOP_INPUT_OPEN.store(true, Relaxed);
            STOP_OPENED_US.store(now_us(), Relaxed);
            pac::NVIC::pend(pac::Interrupt::EXTI15_10);
            defmt::warn!(
                "sim: stop input opened at {=u32} us, outputs safe at {=u32} us",
                STOP_OPENED_US.load(Relaxed),
                STOP_SAFE_US.load(Relaxed)
            );
        }
        if due(s.stop_input_close, from, to) {
            STOP_INPUT_OPEN.store(false, Relaxed);
            pac::NVIC::pend(pac::Interrupt::EXTI15_10);
            defmt::info!("sim: stop input closed");
        }
        let ground_mm = (self.machine.ground_position_m() * 1000.0) as u32;
        for (i, &w) in s.work.iter().enumerate() {
            let bit = 1u8 << i;
            let value = w & WORK_VALUE;
            let now = if w & WORK_GROUND != 0 {
                ground_mm >= value
            } else {
                value <= to
            };
            if w != 0 && now && self.work_fired & bit == 0 {
                self.work_fired |= bit;
                let closed = w & WORK_CLOSED != 0;
                WORK_SWITCH_CLOSED.store(closed, Relaxed);
                defmt::info!(
                    "sim: work switch {=str} at ground {=u32} mm",
                    if closed { "closed (down)" } else { "open (up)" },
                    ground_mm
                );
            }
        }
        if due(s.stack_overflow, from, to) {
            defmt::warn!("sim: stack overflow injected");
            exhaust_stack(0);
        }
        if due(s.stall, from, to) {
            self.machine.inject_fault(Fault::DrumStall);
            defmt::warn!("sim: drum stall injected");
        }
        if due(s.hall_loss, from, to) {
            self.machine.inject_fault(Fault::HallLoss);
            defmt::warn!("sim: Hall signal loss injected");
        }
        if due(s.enc_loss, from, to) {
            self.machine.inject_fault(Fault::EncoderLoss);
            defmt::warn!("sim: encoder loss injected");
        }
        let hz = |bits: u32| bits as f32 / 65_536.0;
        let steppers_on = DRIVER_ENABLE.load(Relaxed);
        let mut drum_duty = f32::from(DRUM_CCR.load(Relaxed)) / f32::from(DRUM_PERIOD);
        let mut drum_on = steppers_on;
        if let Some(d) = self.drive.as_deref() {
            // The virtual driver's motor: enabled by PB12 and its control
            // word; on its bus command (its own speed loop, modelled as the
            // command over the drive's n_max) or the PWM duty.
            drum_on = drum_on && d.flags & DRIVE_ENABLED != 0;
            if d.flags & DRIVE_BUS_COMMAND != 0 {
                let n_max = self.machine.config().n_max_rpm;
                drum_duty = (d.command_milli_rpm as f32 / 1000.0 / n_max).clamp(0.0, 1.0);
            }
        }
        let inputs = Inputs {
            drum_duty,
            driver_enabled: drum_on,
            feed_step_rate_hz: if steppers_on {
                hz(FEED_STEP_BITS.load(Relaxed))
            } else {
                0.0
            },
            plant_step_rate_hz: if steppers_on {
                hz(PLANT_STEP_BITS.load(Relaxed))
            } else {
                0.0
            },
        };
        let dt_us = to.saturating_sub(from).saturating_mul(1000);
        // Plants dropped in this sample: one per 50 mm belt partition, so
        // at most one per 10 ms sample at any reachable belt speed.
        let mut plants: heapless::Vec<f64, 4> = heapless::Vec::new();
        self.machine.step_events(dt_us, &inputs, &mut |e| match e {
            Event::HallEdge(t) => {
                let _ = edges.push(t);
            }
            Event::Plant { ground_m, .. } => {
                let _ = plants.push(ground_m);
            }
        });
        if s.plant_log {
            let first = self
                .machine
                .plants_dropped()
                .wrapping_sub(plants.len() as u32);
            for (i, ground_m) in plants.iter().enumerate() {
                defmt::info!(
                    "sim: plant {=u32} at {=u32} um",
                    first.wrapping_add(i as u32).wrapping_add(1),
                    (ground_m * 1e6) as u32
                );
            }
        }
        self.now_ms = to;
        let now_ticks = self.machine.capture_ticks();
        HALL_TIMER_NOW.store(now_ticks, Relaxed);
        if self.scenario.profile_b {
            // Profile B wiring: TIM3 counts the ground-wheel encoder and TIM2
            // captures one index pulse per feeding-roller turn (there is no
            // Hall gear on this machine).
            edges.clear();
            let count = self.machine.ground_encoder_count();
            let watch = &mut self.stop_watch;
            if count != watch.last_ground_count {
                watch.last_ground_count = count;
                watch.last_count_ms = to;
            }
            let at_rest = inputs.feed_step_rate_hz == 0.0 && inputs.plant_step_rate_hz == 0.0;
            if s.stop.is_some_and(|t| to > t) && at_rest && !watch.reported {
                watch.reported = true;
                defmt::info!(
                    "sim-b: steppers at rest at {=u32} ms, last ground count at {=u32} ms",
                    to,
                    watch.last_count_ms
                );
            }
            let turns = self.machine.feed_roller_turns();
            while self.roller_turns_seen < turns {
                self.roller_turns_seen = self.roller_turns_seen.wrapping_add(1);
                let _ = edges.push(now_ticks);
            }
            return SensorSample {
                drum_encoder: self.machine.ground_encoder_count(),
                hall_edges: edges,
            };
        }
        SensorSample {
            drum_encoder: self.machine.drum_encoder_count(),
            hall_edges: edges,
        }
    }

    /// Profile B's truth for the log: plants, their mean spacing (µm) and
    /// CV (0.01 %) since the metrics were last reset, ground position (mm).
    pub fn truth_b(&self) -> (u32, u32, u32, u32) {
        let m = self.machine.metrics();
        (
            m.plants,
            (m.mean_spacing_m * 1e6) as u32,
            (m.cv_pct * 100.0) as u32,
            (self.machine.ground_position_m() * 1000.0) as u32,
        )
    }

    /// The model's own view, for the log: ground travel speed (µm/s: the
    /// tests compare the drum with eq. 7 to 0.1 %, finer than 1 mm/s of
    /// 140 mm/s), drum speed (r/min × 1000), plants dropped, ground
    /// position (mm), Hall edges delivered.
    pub fn truth(&self) -> (u32, u32, u32, u32, u32) {
        (
            (self.machine.travel_speed_m_s() * 1e6) as u32,
            (self.machine.drum_speed_rpm() * 1000.0) as u32,
            self.machine.plants_dropped(),
            (self.machine.ground_position_m() * 1000.0) as u32,
            self.machine.hall_edges(),
        )
    }
}

/// Recurses until the stack runs off the bottom of RAM (`stack_overflow=T`).
/// Each level writes a frame and reads it back only after the call below
/// it returns, which it never does: only a fault stops it.
#[inline(never)]
fn exhaust_stack(depth: u32) -> u32 {
    if depth == u32::MAX {
        return depth;
    }
    let mut frame = [depth; 16];
    core::hint::black_box(&mut frame);
    let below = exhaust_stack(depth.wrapping_add(1));
    frame
        .iter()
        .fold(below, |sum, &word| sum.wrapping_add(word))
}

/// Hall capture: edges come from [`Sensors::sample`] on this board.
pub struct HallCapture;

impl HallCapture {
    /// TIM2 never interrupts under QEMU.
    pub fn on_interrupt(&mut self) -> Option<super::HallEdge> {
        None
    }

    /// The capture timer's time, 1 MHz, extended to 32 bits.
    pub fn now(&self) -> u32 {
        HALL_TIMER_NOW.load(Relaxed)
    }
}

/// Status LED stand-in (GPIO is not emulated).
pub struct StatusLed;

impl StatusLed {
    /// Does nothing: QEMU has no LED.
    pub fn set(&mut self, _on: bool) {}
}

/// Watchdog stand-in: QEMU 7.2 does not emulate the IWDG.
pub struct Watchdog;

impl Watchdog {
    /// Nothing to feed under QEMU.
    pub fn feed(&mut self) {}
}

/// The stop input stand-in: PB10's level comes from the scenario.
pub struct StopInput;

impl StopInput {
    /// The contact is open: stop.
    pub fn is_open(&self) -> bool {
        STOP_INPUT_OPEN.load(Relaxed)
    }

    /// Nothing to acknowledge (the interrupt was pended by software).
    pub fn clear_interrupt(&mut self) {}
}

/// The work switch stand-in: PB11's level comes from the scenario.
pub struct WorkSwitchInput;

impl WorkSwitchInput {
    /// The contact is closed: the unit is down.
    pub fn is_closed(&self) -> bool {
        WORK_SWITCH_CLOSED.load(Relaxed)
    }
}

/// Firmware time in µs (32 bits, wrapping after 71 minutes).
fn now_us() -> u32 {
    super::now_us64() as u32
}

/// The stop input's response (see the real board's): zeroes the PWM and
/// step stand-ins and the enable, and notes the time for the simulator's
/// truth line.
pub fn stop_outputs() {
    safe_state();
    STOP_SAFE_US.store(now_us(), Relaxed);
}

/// Whether the drivers' enable stand-in is on (the settings task erases
/// flash only while it is off).
pub fn drivers_enabled() -> bool {
    DRIVER_ENABLE.load(Relaxed)
}

/// Whether the clock security system saw the HSE fail: QEMU runs on the
/// HSI and has no CSS.
pub fn clock_failed() -> bool {
    false
}

/// Zeroes the PWM and step stand-ins and the enable (the model coasts the
/// drum down; the steppers stop).
pub fn safe_state() {
    DRUM_CCR.store(0, Relaxed);
    FEED_STEP_BITS.store(0, Relaxed);
    PLANT_STEP_BITS.store(0, Relaxed);
    DRIVER_ENABLE.store(false, Relaxed);
}

/// How deep the stack has gone since reset, and its size, bytes.
///
/// cortex-m-rt paints the whole stack region (`_stack_end` up to
/// `_stack_start`, everything above the statics) with
/// `STACK_PAINT_VALUE` before `main` (feature `paint-stack`); the lowest
/// word that no longer holds the paint is the deepest the stack reached. A
/// result equal to the size means the stack ran into the statics.
pub fn stack_high_water() -> (u32, u32) {
    extern "C" {
        static _stack_start: u32;
        static _stack_end: u32;
    }
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut at = bottom;
    while at < top {
        // SAFETY: `at` is a word-aligned address inside the stack region
        // the linker reserved (RAM, always readable); a volatile read so
        // that the compiler cannot assume the paint is still there.
        let word = unsafe { core::ptr::read_volatile(at as *const u32) };
        if word != cortex_m_rt::STACK_PAINT_VALUE {
            break;
        }
        at += 4;
    }
    ((top - at) as u32, (top - bottom) as u32)
}

/// Logs [`stack_high_water`] (the QEMU tests check it after `init` and at
/// every exit).
pub fn log_stack() {
    let (used, size) = stack_high_water();
    defmt::info!("stack: {=u32} B used of {=u32} B", used, size);
}

/// Ends the emulation with a failure exit code after a fatal error.
pub fn fatal() -> ! {
    safe_state();
    log_stack();
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Ends the emulation successfully (the run reached its time limit).
pub fn exit_success() -> ! {
    safe_state();
    log_stack();
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Reads the semihosting command line into `cmd`; copies a `flash=PATH`
/// value into `path` and returns its length.
fn read_cmdline(cmd: &mut CmdLine, path: &mut [u8]) -> usize {
    let mut buf = [0u8; 192];
    // SYS_GET_CMDLINE takes a two-word block {buffer, length} and writes the
    // used length back into it.
    let block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: the block points at a live buffer of the length it states; the
    // host writes at most that many bytes.
    let rc =
        unsafe { cortex_m_semihosting::syscall(cortex_m_semihosting::nr::GET_CMDLINE, &block) };
    if rc != 0 {
        return 0;
    }
    // SAFETY: the host updated the length word behind a shared reference.
    let len = unsafe { core::ptr::read_volatile(&block[1]) }.min(buf.len());
    let mut path_len = 0;
    let line = buf.get(..len).unwrap_or(&[]);
    for word in line.split(|&b| b == b' ') {
        let Some(eq) = word.iter().position(|&b| b == b'=') else {
            continue;
        };
        let (key, value) = (
            word.get(..eq).unwrap_or(&[]),
            word.get(eq + 1..).unwrap_or(&[]),
        );
        let s = &mut cmd.scenario;
        match key {
            b"run_ms" => cmd.run_ms = parse_u32(value),
            b"flash" => {
                if let Some(dst) = path.get_mut(..value.len()) {
                    dst.copy_from_slice(value);
                    path_len = value.len();
                }
            }
            b"gate" => {
                if let Some(dst) = cmd.gate.get_mut(..value.len()) {
                    dst.copy_from_slice(value);
                    cmd.gate_len = value.len();
                }
            }
            b"gear" => s.gear = parse_u32(value).and_then(|g| u8::try_from(g).ok()),
            b"step" => {
                let slot = s.step.iter_mut().find(|x| x.is_none());
                if let (Some(slot), Some(colon)) = (slot, value.iter().position(|&b| b == b':')) {
                    let at = parse_u32(value.get(..colon).unwrap_or(&[]));
                    let pct = value.get(colon + 1..).and_then(parse_i32);
                    if let (Some(at), Some(pct)) = (at, pct) {
                        *slot = Some((at, pct));
                    }
                }
            }
            b"stop" => s.stop = parse_u32(value),
            b"stop_input" => s.stop_input = parse_u32(value),
            b"stop_input_close" => s.stop_input_close = parse_u32(value),
            b"stopgo" => s.stop_go_ms = parse_u32(value),
            b"drive_link" => s.drive_link = value == b"1",
            b"tau" => s.tau_ms = parse_u32(value),
            b"profile" => s.profile_b = value == b"b" || value == b"B",
            b"speed" => s.speed_mm_s = parse_u32(value),
            b"metrics_from" => s.metrics_from = parse_u32(value),
            b"stall" => s.stall = parse_u32(value),
            b"hall_loss" => s.hall_loss = parse_u32(value),
            b"enc_loss" => s.enc_loss = parse_u32(value),
            b"noise" => s.noiseless = value == b"0",
            b"seed" => s.seed = parse_u32(value),
            b"slip" => s.slip_pct = parse_u32(value),
            b"plant_log" => s.plant_log = value == b"1",
            b"drive_tau" => s.drive_tau_ms = parse_u32(value),
            b"drive_dead" => s.drive_dead_ms = parse_u32(value),
            b"drive_nmax" => s.drive_nmax_centi = parse_u32(value),
            b"load" => s.load_permille = parse_u32(value),
            b"scatter" => s.no_scatter = value == b"0",
            b"slip_noise" => s.no_slip_noise = value == b"0",
            b"stack_overflow" => s.stack_overflow = parse_u32(value),
            b"work_down" | b"work_up" | b"work_down_mm" | b"work_up_mm" => {
                let flags = if key.starts_with(b"work_down") {
                    WORK_CLOSED
                } else {
                    0
                } | if key.ends_with(b"_mm") {
                    WORK_GROUND
                } else {
                    0
                };
                let at = parse_u32(value).filter(|&v| v <= WORK_VALUE);
                if let (Some(slot), Some(at)) = (s.work.iter_mut().find(|x| **x == 0), at) {
                    *slot = flags | at;
                }
            }
            _ => {}
        }
    }
    path_len
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

fn parse_i32(text: &[u8]) -> Option<i32> {
    match text.split_first() {
        Some((b'-', rest)) => parse_u32(rest)
            .and_then(|v| i32::try_from(v).ok())
            .map(|v| -v),
        Some((b'+', rest)) => parse_u32(rest).and_then(|v| i32::try_from(v).ok()),
        _ => parse_u32(text).and_then(|v| i32::try_from(v).ok()),
    }
}

/// Where the settings store's two pages start in [`SettingsFlash`] (the
/// host file holds just those pages, the real board's 0x0801E000).
pub const SETTINGS_BASE: u32 = 0;
/// This board has no earlier layout's settings to move.
pub const OLD_SETTINGS_BASE: Option<u32> = None;
/// The pages [`SettingsFlash`] reaches.
#[allow(clippy::single_range_in_vec_init)] // one window, the file's two pages
const SETTINGS_WINDOWS: [core::ops::Range<u32>; 1] = [0..SETTINGS_FLASH_BYTES];

/// The settings flash stand-in: a host file through semihosting, with the
/// F103's NOR rules enforced (erase to 0xFF in 1 KB pages, programming in
/// half-words onto erased half-words only).
pub struct SettingsFlash {
    handle: usize,
}

mod sh {
    //! Semihosting file calls (ARM semihosting specification 2.0).
    use cortex_m_semihosting::{nr, syscall};

    /// Opens `path` (with `suffix` appended, if any).
    pub fn open(path: &[u8], mode: usize, suffix: Option<u8>) -> Option<usize> {
        // SYS_OPEN wants a NUL-terminated name.
        let mut name = [0u8; 98];
        let dst = name.get_mut(..path.len())?;
        dst.copy_from_slice(path);
        let mut len = path.len();
        if let Some(c) = suffix {
            *name.get_mut(len)? = c;
            len += 1;
        }
        let block = [name.as_ptr() as usize, mode, len];
        // SAFETY: the block describes a live NUL-terminated buffer.
        let h = unsafe { syscall(nr::OPEN, &block) };
        (h != usize::MAX).then_some(h)
    }

    pub fn seek(h: usize, pos: u32) -> bool {
        let block = [h, pos as usize];
        // SAFETY: plain values.
        unsafe { syscall(nr::SEEK, &block) == 0 }
    }

    pub fn read(h: usize, buf: &mut [u8]) -> bool {
        let block = [h, buf.as_mut_ptr() as usize, buf.len()];
        // SAFETY: the block describes a live, writable buffer.
        unsafe { syscall(nr::READ, &block) == 0 }
    }

    pub fn write(h: usize, buf: &[u8]) -> bool {
        let block = [h, buf.as_ptr() as usize, buf.len()];
        // SAFETY: the block describes a live buffer.
        unsafe { syscall(nr::WRITE, &block) == 0 }
    }

    pub fn flen(h: usize) -> usize {
        let block = [h];
        // SAFETY: plain value.
        unsafe { syscall(nr::FLEN, &block) }
    }
}

impl SettingsFlash {
    /// Opens (or creates, erased) the host file that backs the stand-in.
    fn open(path: &[u8]) -> Option<Self> {
        // Mode 3 = "r+b"; mode 7 = "w+b" (create).
        if let Some(handle) = sh::open(path, 3, None) {
            if sh::flen(handle) == SETTINGS_FLASH_BYTES as usize {
                return Some(Self { handle });
            }
        }
        let handle = sh::open(path, 7, None)?;
        let erased = [0xFFu8; 256];
        for _ in 0..(SETTINGS_FLASH_BYTES / 256) {
            if !sh::write(handle, &erased) {
                return None;
            }
        }
        defmt::info!("settings flash stand-in created (erased)");
        Some(Self { handle })
    }
}

impl ErrorType for SettingsFlash {
    type Error = FlashError;
}

impl ReadNorFlash for SettingsFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 1, &SETTINGS_WINDOWS)?;
        if sh::seek(self.handle, offset) && sh::read(self.handle, bytes) {
            Ok(())
        } else {
            Err(FlashError::Device)
        }
    }

    fn capacity(&self) -> usize {
        SETTINGS_FLASH_BYTES as usize
    }
}

impl NorFlash for SettingsFlash {
    const WRITE_SIZE: usize = 2;
    const ERASE_SIZE: usize = SETTINGS_PAGE_BYTES as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_flash_erase(from, to, &SETTINGS_WINDOWS)?;
        let erased = [0xFFu8; 256];
        let mut at = from;
        while at < to {
            if !(sh::seek(self.handle, at) && sh::write(self.handle, &erased)) {
                return Err(FlashError::Device);
            }
            at += 256;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 2, &SETTINGS_WINDOWS)?;
        // Check erased first, like the F103 refuses to program over data.
        let mut at = offset;
        for chunk in bytes.chunks(64) {
            let mut old = [0u8; 64];
            let old = old.get_mut(..chunk.len()).ok_or(FlashError::OutOfBounds)?;
            self.read(at, old)?;
            if old.iter().any(|&b| b != 0xFF) {
                return Err(FlashError::NotErased);
            }
            if !(sh::seek(self.handle, at) && sh::write(self.handle, chunk)) {
                return Err(FlashError::Device);
            }
            at += chunk.len() as u32;
        }
        Ok(())
    }
}
