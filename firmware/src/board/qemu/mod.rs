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
//!   value, the driver enable pin, TIM3's encoder counter, machine A's
//!   ground-wheel counter (TIM4), TIM2's Hall captures and counter — by
//!   atomics and a simulated machine
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

use core::sync::atomic::Ordering::Relaxed;

use machine_sim::Machine;
use stm32f1xx_hal::{pac, serial};
use stm32f1xx_hal::{prelude::*, rcc};

use defmt_semihosting as _;

mod clocks;
mod drive_sim;
mod drum_pwm;
mod gate;
mod hall_capture;
mod outputs;
mod pins;
mod rs485;
mod scenario;
mod settings_flash;
mod sh;
mod sim;
mod stack_guard;
mod steppers;
mod truth;
mod usart1;
mod watchdog;
pub use clocks::*;
pub use drum_pwm::*;
pub use gate::*;
pub use hall_capture::*;
pub use outputs::*;
pub use pins::*;
pub use rs485::*;
pub use settings_flash::*;
pub use sim::*;
pub use steppers::*;
pub use watchdog::*;

use drive_sim::DriveSim;
use drum_pwm::{DRIVER_ENABLE, DRUM_CCR};
use gate::GateQueue;
use rs485::{DriveRxQueue, DriveTxQueue};
use scenario::{read_cmdline, CmdLine};
use sim::StopWatch;

/// USART1's transmit half, driven by [`super::HmiTx`].
pub type ScreenUsartTx = usart1::Tx;

/// QEMU's `netduino2` clocks the core, and SysTick's processor clock, at a
/// fixed 120 MHz (its SYSCLK; RCC is not modelled).
pub const SYSCLK_HZ: u32 = 120_000_000;

/// The sensors as the application holds them (a static on this board).
pub type SensorsRef = &'static mut Sensors;

/// The drum driver's line as the application holds it.
pub type DriveLineRef = &'static mut DriveLine;

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
    /// TIM4's stand-in: machine B's feeding step output or machine A's
    /// ground wheel.
    pub tim4: Tim4Pins,
    /// The settings flash stand-in, if the command line named a file.
    pub settings_flash: Option<SettingsFlash>,
    /// Run limit from the command line.
    pub run_limit_ms: Option<u32>,
    /// SysTick input frequency for the monotonic.
    pub sysclk_hz: u32,
}

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
        ground_wheel: false,
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
        tim4: Tim4Pins,
        settings_flash,
        run_limit_ms: cmd.run_ms,
        sysclk_hz: SYSCLK_HZ,
    }
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
