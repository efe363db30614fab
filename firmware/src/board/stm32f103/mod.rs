//! The real board: STM32F103RB at 72 MHz.
//!
//! Pin map (see README.md):
//!
//! | pin | function |
//! |---|---|
//! | PA0 | Hall proximity switch (NPN, pulled up), TIM2 CH1 input capture, falling edge |
//! | PA8 | drum motor PWM, TIM1 CH1, 20 kHz |
//! | PB12 | drum driver enable (high = run) |
//! | PB13 | drum driver direction (low = forward) |
//! | PA6 / PA7 | drum motor encoder A/B, TIM3 encoder mode |
//! | PB6 / PB7 | machine A: ground-wheel encoder A/B, TIM4 encoder mode, internal pull-ups (FT pins); machine B: PB6 the feeding motor's STEP, TIM4 CH1 |
//! | PA9 / PA10 | USART1 TX/RX, touchscreen, 115200 8N1 |
//! | PA2 / PA3 / PA1 | USART2 TX/RX and driver-enable (high while sending, low after TC), RS-485 to the motor driver, Modbus RTU at the settings' baud rate, 8N1 |
//! | PB10 | stop input: NC contact to ground, internal pull-up (FT pin), EXTI10 on both edges |
//! | PB11 | work switch: contact to ground closed while the planting unit is down, internal pull-up (FT pin), polled every 10 ms |
//! | PC13 | status LED (low = on) |
//!
//! PA0–PA7 are not 5 V tolerant (datasheet STM32F103xB, Table 5, "FT"
//! column): the Hall switch and the encoders must reach them at 3.3 V (see
//! README.md, pin map).
//!
//! Every register value written here is taken from RM0008 (reference
//! manual of the STM32F101/102/103/105/107, rev. 21) and the STM32F103xB
//! datasheet; each write names its section.
//!
//! One module per peripheral, each with a small API: `clocks` (the HSE
//! start), `system` (debug freeze, exception-frame alignment), `drum_pwm`
//! (TIM1 CH1), `steppers` (profile B's step timers), `hall_capture`
//! (TIM2 CH1), `encoder` (TIM3), `ground_wheel` (machine A's TIM4),
//! `rs485` (USART2 and DE),
//! `watchdog` (IWDG), `settings_flash`, `pins` (stop input, work
//! switch, LED), `outputs` (the outputs' safe states). Registers are
//! written through the PAC's field writers.
//! This module wires them up in `init`.

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use kinematics::speed::CaptureExtender;
use stm32f1xx_hal::{
    afio::AfioExt,
    flash::{self, FlashSize, SectorSize},
    gpio::{Edge, ExtiPin, Input, Output, PullUp, PushPull, PA1, PB10, PB11, PB12, PB13, PC13},
    pac::{self, IWDG, TIM1, TIM2, TIM3, USART1, USART2},
    prelude::*,
    rcc,
    serial::{self, Rx, Tx},
    timer::Timer,
};

use defmt_rtt as _;

mod clocks;
mod drum_pwm;
mod encoder;
mod ground_wheel;
mod hall_capture;
mod outputs;
mod pins;
mod rs485;
mod settings_flash;
mod steppers;
mod system;
mod watchdog;
pub use clocks::*;
pub use drum_pwm::*;
pub use encoder::*;
pub use ground_wheel::*;
pub use hall_capture::*;
pub use outputs::*;
pub use pins::*;
pub use rs485::*;
pub use settings_flash::*;
pub use steppers::*;
use system::*;
pub use watchdog::*;

use super::{
    check_flash_access, check_flash_erase, FlashError, SensorSample, DRUM_PWM_HZ,
    SETTINGS_FLASH_BYTES, SETTINGS_PAGE_BYTES,
};

/// USART1's transmit half, driven by [`super::HmiTx`].
pub type ScreenUsartTx = Tx<USART1>;
/// Receive half of the touchscreen UART.
pub type HmiRx = Rx<USART1>;

/// System clock.
pub const SYSCLK_HZ: u32 = 72_000_000;
/// TIM1 runs from PCLK2 = 72 MHz, TIM2–TIM4 from 2 × PCLK1 = 72 MHz.
const TIMER_CLOCK_HZ: u32 = 72_000_000;

/// Everything the application owns after [`init`].
pub struct Board {
    /// Touchscreen transmitter.
    pub hmi_tx: super::HmiTx,
    /// Touchscreen receiver, with its RX-not-empty interrupt enabled.
    pub hmi_rx: HmiRx,
    /// Drum motor PWM and driver pins.
    pub drum: DrumDrive,
    /// Encoder and other polled sensors.
    pub sensors: SensorsRef,
    /// Hall capture timer (its interrupt is TIM2).
    pub hall: HallCapture,
    /// RS-485 link to the motor driver (docs/drive-link.md): USART2 with
    /// driver-enable on PA1, idle until the link task sets its baud rate;
    /// in a static.
    pub drive_line: DriveLineRef,
    /// Status LED.
    pub led: StatusLed,
    /// The stop input (its interrupt is EXTI15_10).
    pub stop_input: StopInput,
    /// The work switch (polled by the control task).
    pub work_switch: WorkSwitchInput,
    /// The independent watchdog (running).
    pub watchdog: Watchdog,
    /// TIM4 and its pins, in their reset state until the settings' machine
    /// takes them: machine B's feeding-motor step output (TIM4 CH1 on PB6)
    /// and direction pins, or machine A's ground wheel (PB6/PB7).
    pub tim4: Tim4Pins,
    /// The settings pages of the MCU's flash.
    pub settings_flash: Option<SettingsFlash>,
    /// The real board runs until it is switched off.
    pub run_limit_ms: Option<u32>,
    /// SysTick input frequency for the monotonic.
    pub sysclk_hz: u32,
}

/// The sensors as the application holds them (small on this board: by
/// value).
pub type SensorsRef = Sensors;

/// The drum driver's line as the application holds it.
pub type DriveLineRef = &'static mut DriveLine;

/// Brings up clocks and peripherals. Called once from `init`, interrupts off.
///
/// Order (docs/firmware.md, "Boards"): the outputs driven safe (PA8, PB12,
/// PA1 and profile B's PB6 push-pull low), then the watchdog, both before
/// any clock work, then the HSE with a bounded wait; a crystal that never
/// starts ends in [`fatal`] (outputs safe, the watchdog resets and the boot
/// tries again). Then the PLL, the clock security system and the
/// peripherals, each output pin switched to its timer only after the timer
/// drives it low.
#[inline(never)]
pub fn init(dp: pac::Peripherals) -> Board {
    // The outputs first: starting the watchdog waits for the LSI
    // (RM0008 §19.4.4, up to `IWDG_UPDATE_POLLS` when it does not run), and
    // until then PA8, PB12 and PA1 would float (reset state, §9.1.1).
    safe_state();
    align_exception_frames();
    let mut watchdog = Watchdog::start(dp.IWDG);
    // RM0008 §7.3.10 RCC_CSR: IWDGRSTF (bit 29) says the last reset came
    // from the watchdog; RMVF (bit 24) clears the reset flags.
    if dp.RCC.csr().read().iwdgrstf().bit_is_set() {
        defmt::warn!("boot: reset by the independent watchdog");
    }
    dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());
    debug_freeze(&dp.DBGMCU);
    if !start_hse(&dp.RCC) {
        defmt::error!(
            "clock: the 8 MHz crystal (HSE) did not start within 100 ms: outputs off, waiting for the watchdog reset"
        );
        fatal();
    }
    let mut flash = dp.FLASH.constrain();
    // The HSE is running: the HAL's own (unbounded) wait on HSERDY returns
    // at once; it then starts the PLL (×9), sets two flash wait states
    // (RM0008 §3.3.3, FLASH_ACR LATENCY = 010 for 48 < SYSCLK ≤ 72 MHz) and
    // switches SYSCLK to the PLL.
    let mut rcc = dp.RCC.freeze(
        rcc::Config::hse(8.MHz())
            .sysclk(SYSCLK_HZ.Hz())
            .pclk1(36.MHz())
            .pclk2(72.MHz()),
        &mut flash.acr,
    );
    // RM0008 §7.2.7 and §7.3.1 RCC_CR CSSON (bit 19): the clock security
    // system watches the HSE; a failure switches SYSCLK to the HSI and
    // raises the NMI (CSSF), whose handler drives the outputs safe and ends
    // in `fatal`. (The CSS also signals TIM1's break input, but only with
    // BKE = 1, and TIM1_BKIN is PB12, the driver enable output: the break
    // stays off and the NMI does the job.)
    rcc.cr().modify(|_, w| w.csson().set_bit());
    watchdog.feed();

    // The pins configured by `safe_state` (PA8, PB12, PB6) are each
    // reconfigured below before use, every mode bit rewritten by the HAL;
    // resetting the ports (`split`) would let them float meanwhile.
    // SAFETY: the other pins of ports A and B are in their reset state.
    let mut gpioa = unsafe { dp.GPIOA.split_without_reset(&mut rcc) };
    // SAFETY: as above.
    let mut gpiob = unsafe { dp.GPIOB.split_without_reset(&mut rcc) };
    let mut gpioc = dp.GPIOC.split(&mut rcc);

    // Touchscreen, USART1 on PA9/PA10.
    let tx_pin = gpioa.pa9.into_alternate_push_pull(&mut gpioa.crh);
    // RX with the pull-up (RM0008 §9.1.11, Table 24): an unplugged screen
    // reads as an idle line, not as noise.
    let rx_pin = gpioa.pa10.into_pull_up_input(&mut gpioa.crh);
    let hmi = dp.USART1.serial(
        (tx_pin, rx_pin),
        serial::Config::default()
            .baudrate(115_200.bps())
            .parity_none(),
        &mut rcc,
    );
    let (tx, mut hmi_rx) = hmi.split();
    let hmi_tx = super::HmiTx::new(tx);
    hmi_rx.listen();

    // RS-485, USART2 on PA2/PA3, DE on PA1.
    let tx2 = gpioa.pa2.into_alternate_push_pull(&mut gpioa.crl);
    // RX with the pull-up: the transceiver releases RO while it sends (DE
    // and /RE tied), and a floating PA3 would frame noise into bytes.
    let rx2 = gpioa.pa3.into_pull_up_input(&mut gpioa.crl);
    let rs = dp.USART2.serial(
        (tx2, rx2),
        serial::Config::default()
            .baudrate(9_600.bps())
            .parity_none(),
        &mut rcc,
    );
    // Idle, receive interrupt off, until the link task sets the baud rate
    // (only when the settings name a driver).
    let (tx, rx) = rs.split();
    // DE low (receive) from the start.
    let de = gpioa.pa1.into_push_pull_output(&mut gpioa.crl);

    // Drum PWM, TIM1 CH1 on PA8; driver enable and direction. PA8 is handed
    // to the timer only once the timer drives it low (PA8 stays a GPIO
    // output low until then).
    let enable = gpiob.pb12.into_push_pull_output(&mut gpiob.crh);
    let direction = gpiob.pb13.into_push_pull_output(&mut gpiob.crh);
    let tim1 = Timer::new(dp.TIM1, &mut rcc).release();
    let drum = DrumDrive::new(tim1, enable, direction);
    let _pwm_pin = gpioa.pa8.into_alternate_push_pull(&mut gpioa.crh);

    // TIM4: clocked here (RCC_APB1ENR TIM4EN, RM0008 §7.3.8, and a reset
    // pulse), set up once the settings name the machine: profile B's
    // feeding STEP on PB6 with the directions on PB14/PB15
    // (`Steppers::new`), or machine A's ground wheel on PB6/PB7
    // (`Sensors::with_ground_wheel`).
    let tim4 = Timer::new(dp.TIM4, &mut rcc).release();

    // Hall input capture, TIM2 CH1 on PA0 (NPN switch: pull-up, falling edge).
    let _hall_pin = gpioa.pa0.into_pull_up_input(&mut gpioa.crl);
    let tim2 = Timer::new(dp.TIM2, &mut rcc).release();
    let hall = HallCapture::new(tim2);

    // Drum encoder, TIM3 encoder mode on PA6/PA7 (inputs are the reset state).
    let _enc_a = gpioa.pa6.into_floating_input(&mut gpioa.crl);
    let _enc_b = gpioa.pa7.into_floating_input(&mut gpioa.crl);
    let tim3 = Timer::new(dp.TIM3, &mut rcc).release();
    let sensors = Sensors::new(tim3);

    let led = StatusLed(gpioc.pc13.into_push_pull_output(&mut gpioc.crh));

    // Stop input, PB10 (5 V tolerant): NC contact to ground, pulled up, so
    // open contact or broken wire = high = stop. EXTI10 on both edges.
    let mut afio = dp.AFIO.constrain(&mut rcc);
    let mut exti = dp.EXTI;
    let mut stop_pin = gpiob.pb10.into_pull_up_input(&mut gpiob.crh);
    stop_pin.make_interrupt_source(&mut afio);
    stop_pin.trigger_on_edge(&mut exti, Edge::RisingFalling);
    stop_pin.enable_interrupt(&mut exti);
    let stop_input = StopInput { pin: stop_pin };
    // Work switch, PB11 (5 V tolerant): contact to ground, closed while the
    // planting unit is down, pulled up, so a broken wire reads up (not
    // planting). Polled, no interrupt.
    let work_switch = WorkSwitchInput {
        pin: gpiob.pb11.into_pull_up_input(&mut gpiob.crh),
    };
    let tim4 = Tim4Pins {
        tim: tim4,
        pb6: gpiob.pb6,
        pb7: gpiob.pb7,
        pb14: gpiob.pb14,
        pb15: gpiob.pb15,
        crl: gpiob.crl,
        crh: gpiob.crh,
    };

    let Some(drive_line) = cortex_m::singleton!(: DriveLine = DriveLine {
            _tx: tx,
            usart_rx: rx,
            de,
            out: [0; DRIVE_FRAME_MAX],
            out_len: 0,
            out_pos: 0,
            sent_at: None,
            sending: false,
            rx: [0; DRIVE_FRAME_MAX],
            rx_len: 0,
            rx_last_us: 0,
            silent_us: 4_011,
    }) else {
        fatal()
    };
    Board {
        hmi_tx,
        hmi_rx,
        drum,
        sensors,
        hall,
        drive_line,
        led,
        stop_input,
        work_switch,
        watchdog,
        tim4,
        settings_flash: Some(SettingsFlash { flash }),
        run_limit_ms: None,
        sysclk_hz: SYSCLK_HZ,
    }
}

/// The end state after a fatal error (panic, HardFault, NMI, an unexpected
/// interrupt, no crystal): interrupts off, outputs safe, then spin without
/// feeding the independent watchdog until it resets the MCU (166–333 ms
/// after its last feed). At boot the outputs are driven safe again and the
/// drum stays stopped until the operator presses Start, so the reset cannot
/// restart the machine by itself. (A probe attached with `probe-rs run` has
/// already halted the core on the HardFault and printed a backtrace; with
/// DBG_IWDG_STOP the watchdog then waits too.)
pub fn fatal() -> ! {
    cortex_m::interrupt::disable();
    safe_state();
    loop {
        cortex_m::asm::nop();
    }
}

/// Ends a run that reached its limit (never on the real board).
pub fn exit_success() -> ! {
    fatal()
}
