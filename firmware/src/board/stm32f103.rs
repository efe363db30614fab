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

use super::{
    check_flash_access, check_flash_erase, FlashError, SensorSample, DRUM_PWM_HZ,
    SETTINGS_FLASH_BYTES, SETTINGS_PAGE_BYTES,
};

/// Frequency of the Hall capture timer: one tick is 1 µs.
const HALL_TIMER_HZ: u32 = 1_000_000;

/// USART1's transmit half, driven by [`super::HmiTx`].
pub type ScreenUsartTx = Tx<USART1>;
/// Receive half of the touchscreen UART.
pub type HmiRx = Rx<USART1>;

/// System clock.
pub const SYSCLK_HZ: u32 = 72_000_000;
/// TIM1 runs from PCLK2 = 72 MHz, TIM2/TIM3 from 2 × PCLK1 = 72 MHz.
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
    /// driver-enable on PA1, receiving until a frame is sent; in a static.
    pub drive_line: DriveLineRef,
    /// Status LED.
    pub led: StatusLed,
    /// The stop input (its interrupt is EXTI15_10).
    pub stop_input: StopInput,
    /// The work switch (polled by the control task).
    pub work_switch: WorkSwitchInput,
    /// The independent watchdog (running).
    pub watchdog: Watchdog,
    /// Profile B's feeding-motor step output (TIM4 CH1 on PB6), idle. The
    /// profile A image leaves TIM4 and its pins in their reset state.
    #[cfg(feature = "profile-b")]
    pub feed_step: FeedStep,
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

/// The drum driver's line as the application holds it (the same with or
/// without the feature `drive-link`: USART2 is set up either way, idle
/// without it).
pub type DriveLineRef = &'static mut DriveLine;

/// Longest Modbus RTU frame this link sends or takes (its replies are at
/// most 9 bytes; anything longer is garbage and fails its CRC).
const DRIVE_FRAME_MAX: usize = 16;

/// USART2, the RS-485 line to the drum driver, interrupt-driven
/// (docs/drive-link.md, "Board layer"):
///
/// - [`DriveLine::send`] drives DE (PA1) high *before* the first byte is
///   written, then enables TXEIE; the interrupt writes each next byte on
///   TXE, and after the last one switches from TXEIE to TCIE;
/// - on TC (the last stop bit has left the shift register: RM0008 §27.3.2,
///   "TC … set when the transmission of a frame containing data is
///   complete"), not TXE (which only says the data register is free while
///   the last byte is still shifting out), DE goes low and the time is
///   noted for [`DriveLine::sent`];
/// - each received byte is stored with its time; a frame ends after 3.5
///   characters of silence ([`DriveLine::receive`], polled by the link task
///   every 1 ms: the F103's idle-line flag is one character, too short for
///   RTU). Bytes while DE is high (an echo) are dropped.
#[cfg_attr(not(feature = "drive-link"), allow(dead_code))]
pub struct DriveLine {
    _tx: Tx<USART2>,
    _rx: Rx<USART2>,
    de: PA1<Output<PushPull>>,
    out: [u8; DRIVE_FRAME_MAX],
    out_len: u8,
    out_pos: u8,
    sent_at: Option<u64>,
    sending: bool,
    rx: [u8; DRIVE_FRAME_MAX],
    rx_len: u8,
    rx_last_us: u64,
    silent_us: u32,
}

/// USART_SR / USART_CR1 bits (RM0008 §27.6.1, §27.6.4).
#[cfg(feature = "drive-link")]
const SR_RXNE: u16 = 1 << 5;
#[cfg(feature = "drive-link")]
const SR_TC: u16 = 1 << 6;
#[cfg(feature = "drive-link")]
const SR_TXE: u16 = 1 << 7;
#[cfg(feature = "drive-link")]
const CR1_TCIE: u16 = 1 << 6;
#[cfg(feature = "drive-link")]
const CR1_TXEIE: u16 = 1 << 7;
/// USART2's clock: PCLK1 = 36 MHz.
#[cfg(feature = "drive-link")]
const PCLK1_HZ: u32 = 36_000_000;

#[cfg(feature = "drive-link")]
impl DriveLine {
    fn regs() -> &'static pac::usart1::RegisterBlock {
        // SAFETY: USART2's registers; only this type touches them after
        // `init` (it owns USART2's Tx and Rx).
        unsafe { &*USART2::ptr() }
    }

    /// Sets the line's speed: BRR = PCLK1 / baud, rounded (RM0008
    /// §27.3.4: 36 MHz / 9600 = 3750.0; / 115 200 = 312.5 → 313, +0.16 %).
    /// Called while the line is idle.
    pub fn set_baud(&mut self, baud: u32) {
        let brr = PCLK1_HZ.saturating_add(baud / 2) / baud.max(1);
        self.silent_us = drive_link::timing::silent_interval_us(baud).unwrap_or(4_011);
        // SAFETY: any 16-bit value is a valid BRR.
        Self::regs()
            .brr()
            .write(|w| unsafe { w.bits(u16::try_from(brr).unwrap_or(u16::MAX)) });
    }

    /// Sends a request frame: DE high, then the bytes from the interrupt.
    pub fn send(&mut self, frame: &[u8], _now_us: u64) {
        let n = frame.len().min(DRIVE_FRAME_MAX);
        if let (Some(dst), Some(src)) = (self.out.get_mut(..n), frame.get(..n)) {
            dst.copy_from_slice(src);
        }
        self.out_len = n as u8;
        self.out_pos = 0;
        self.sending = true;
        self.rx_len = 0;
        // DE high before the first bit: the byte is written only by the
        // TXE interrupt this enables.
        self.de.set_high();
        // SAFETY: setting TXEIE in CR1 (read-modify-write from priority 3,
        // the only task that touches CR1 after `init`).
        Self::regs()
            .cr1()
            .modify(|r, w| unsafe { w.bits(r.bits() | CR1_TXEIE) });
    }

    /// The request's last stop bit has left (TC; DE is low): its time, once.
    pub fn sent(&mut self, _now_us: u64) -> Option<u64> {
        self.sent_at.take()
    }

    /// A received frame, once 3.5 characters of silence have followed its
    /// last byte.
    pub fn receive(&mut self, now_us: u64, buf: &mut [u8]) -> Option<usize> {
        if self.rx_len == 0 || now_us.saturating_sub(self.rx_last_us) < u64::from(self.silent_us) {
            return None;
        }
        let n = usize::from(self.rx_len).min(buf.len());
        buf.get_mut(..n)?.copy_from_slice(self.rx.get(..n)?);
        self.rx_len = 0;
        Some(n)
    }

    /// Whether bytes have arrived that no frame has been handed over with
    /// yet (a frame on the line, not yet ended by its silence).
    pub fn receiving(&mut self, _now_us: u64) -> bool {
        self.rx_len > 0
    }

    /// USART2's interrupt.
    pub fn on_interrupt(&mut self, now_us: u64) {
        let r = Self::regs();
        let sr = r.sr().read().bits();
        let cr1 = r.cr1().read().bits();
        if sr & SR_RXNE != 0 {
            // Reading DR after SR clears RXNE and the error flags.
            let byte = r.dr().read().bits() as u8;
            if !self.sending {
                if let Some(slot) = self.rx.get_mut(usize::from(self.rx_len)) {
                    *slot = byte;
                    self.rx_len += 1;
                }
                self.rx_last_us = now_us;
            }
        }
        if cr1 & CR1_TXEIE != 0 && sr & SR_TXE != 0 {
            match self.out.get(usize::from(self.out_pos)) {
                Some(&b) if self.out_pos < self.out_len => {
                    // SAFETY: a byte into DR (clears TC after the SR read).
                    r.dr().write(|w| unsafe { w.bits(u16::from(b)) });
                    self.out_pos += 1;
                }
                _ => {
                    // All bytes are in: wait for TC, not TXE.
                    // SAFETY: CR1 bits of this USART only.
                    r.cr1()
                        .modify(|r, w| unsafe { w.bits((r.bits() & !CR1_TXEIE) | CR1_TCIE) });
                }
            }
        } else if cr1 & CR1_TCIE != 0 && sr & SR_TC != 0 {
            self.de.set_low();
            // SAFETY: CR1 bits of this USART only.
            r.cr1()
                .modify(|r, w| unsafe { w.bits(r.bits() & !CR1_TCIE) });
            self.sending = false;
            self.sent_at = Some(now_us);
        }
    }
}

/// HSE start-up bound, in cycles of the 8 MHz HSI the core runs on until
/// the PLL is up: 100 ms. The datasheet gives tSU(HSE) = 2 ms typical for an
/// 8 MHz crystal (STM32F103xB, "High-speed external user clock generated from
/// a crystal/ceramic resonator"); ST's own HAL waits 100 ms
/// (`HSE_STARTUP_TIMEOUT`). It must stay well below the watchdog's shortest
/// timeout (166 ms) so that the error is logged before the reset.
const HSE_TIMEOUT_CYCLES: u32 = 800_000;
/// Cycles between two reads of HSERDY while waiting (125 µs at 8 MHz).
const HSE_POLL_CYCLES: u32 = 1_000;

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
    let (tx, mut rx) = rs.split();
    // DE low (receive) from the start.
    let de = gpioa.pa1.into_push_pull_output(&mut gpioa.crl);
    rx.listen();

    // Drum PWM, TIM1 CH1 on PA8; driver enable and direction. PA8 is handed
    // to the timer only once the timer drives it low (PA8 stays a GPIO
    // output low until then).
    let enable = gpiob.pb12.into_push_pull_output(&mut gpiob.crh);
    let direction = gpiob.pb13.into_push_pull_output(&mut gpiob.crh);
    let tim1 = Timer::new(dp.TIM1, &mut rcc).release();
    let drum = DrumDrive::new(tim1, enable, direction);
    let _pwm_pin = gpioa.pa8.into_alternate_push_pull(&mut gpioa.crh);

    // Profile B: feeding STEP on PB6 (TIM4 CH1), directions on PB14/PB15.
    #[cfg(feature = "profile-b")]
    let feed_step = {
        let feed_dir = gpiob.pb14.into_push_pull_output(&mut gpiob.crh);
        let plant_dir = gpiob.pb15.into_push_pull_output(&mut gpiob.crh);
        let tim4 = Timer::new(dp.TIM4, &mut rcc).release();
        let feed_step = FeedStep::new(tim4, feed_dir, plant_dir);
        let _feed_pin = gpiob.pb6.into_alternate_push_pull(&mut gpiob.crl);
        feed_step
    };

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

    let Some(drive_line) = cortex_m::singleton!(: DriveLine = DriveLine {
            _tx: tx,            _rx: rx,
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
        #[cfg(feature = "profile-b")]
        feed_step,
        settings_flash: Some(SettingsFlash { flash }),
        run_limit_ms: None,
        sysclk_hz: SYSCLK_HZ,
    }
}

// Timer register bits (RM0008 §14.4 for TIM1, §15.4 for TIM2–TIM4; the
// bits used here sit at the same places in both).
/// TIMx_CR1 CEN (bit 0): counter enable.
const CR1_CEN: u32 = 1;
/// TIMx_CR1 UDIS (bit 1): update events disabled, the shadow registers
/// (PSC, ARR, CCRx) keep their values (§15.4.1).
#[cfg(feature = "profile-b")]
const CR1_UDIS: u32 = 1 << 1;
/// TIMx_CR1 ARPE (bit 7): ARR preloaded.
const CR1_ARPE: u32 = 1 << 7;
/// TIMx_EGR UG (bit 0): update generation (shadows loaded, counter 0).
const EGR_UG: u32 = 1;
/// TIMx_CCMR1 (output) OC1PE (bit 3): CCR1 preloaded.
const CCMR1_OC1PE: u32 = 1 << 3;
/// TIMx_CCMR1 OC1M (bits 6:4) = 110: PWM mode 1 (OC1REF high while CNT < CCR1).
const CCMR1_OC1M_PWM1: u32 = 0b110 << 4;
/// TIMx_CCMR1 OC1M = 100: force inactive level, OC1REF low at once
/// (§15.4.7: the mode bits are not preloaded).
const CCMR1_OC1M_FORCE_INACTIVE: u32 = 0b100 << 4;
/// TIMx_CCMR1 OC1M field mask.
#[cfg(feature = "profile-b")]
const CCMR1_OC1M_MASK: u32 = 0b111 << 4;
/// TIMx_CCER CC1E (bit 0): OC1 output enabled, CC1P = 0 (active high).
const CCER_CC1E: u32 = 1;
/// TIM1_BDTR MOE (bit 15): main output enable.
const BDTR_MOE: u32 = 1 << 15;
/// TIM1_BDTR OSSR (bit 11) and OSSI (bit 10): with MOE = 0 the output stays
/// enabled at its idle level OIS1 (TIM1_CR2 bit 8, left 0: low) instead of
/// being released (RM0008 §14.4.18 and Table 83). MOE is cleared by the
/// debug halt (DBG_TIM1_STOP) and by [`safe_state`].
const BDTR_OSSR_OSSI: u32 = (1 << 11) | (1 << 10);
/// TIMx_SR UIF (bit 0), CC1IF (bit 1), CC1OF (bit 9) (§15.4.5).
const SR_UIF: u32 = 1;
const SR_CC1IF: u32 = 1 << 1;
const SR_CC1OF: u32 = 1 << 9;

/// Drum motor PWM (TIM1 CH1) with the driver's enable and direction pins.
pub struct DrumDrive {
    tim: TIM1,
    enable: PB12<Output<PushPull>>,
    _direction: PB13<Output<PushPull>>,
}

/// TIM1 auto-reload value: 72 MHz / 20 kHz − 1.
const DRUM_ARR: u16 = (TIMER_CLOCK_HZ / DRUM_PWM_HZ - 1) as u16;

impl DrumDrive {
    fn new(
        tim: TIM1,
        mut enable: PB12<Output<PushPull>>,
        mut direction: PB13<Output<PushPull>>,
    ) -> Self {
        enable.set_low();
        direction.set_low();
        // SAFETY: raw register values for PWM mode 1 on CH1 (RM0008 §14.4);
        // TIM1 is owned by this struct. ARR (§14.4.12) is non-zero before
        // the update and the counter start: a null ARR blocks the counter.
        tim.psc().write(|w| w.psc().set(0));
        tim.arr().write(|w| w.arr().set(DRUM_ARR));
        tim.ccr1().write(|w| w.ccr().set(0));
        // CCMR1 (§14.4.7): OC1M = 110 (PWM mode 1), OC1PE = 1 (preload).
        tim.ccmr1_output()
            .write(|w| unsafe { w.bits(CCMR1_OC1M_PWM1 | CCMR1_OC1PE) });
        // CCER (§14.4.9): CC1E = 1, active high.
        tim.ccer().write(|w| unsafe { w.bits(CCER_CC1E) });
        // BDTR (§14.4.18): MOE = 1, OSSI = OSSR = 1 (off state = driven to
        // OIS1 = low, not released), no break, no lock.
        tim.bdtr()
            .write(|w| unsafe { w.bits(BDTR_MOE | BDTR_OSSR_OSSI) });
        // EGR UG (§14.4.6): PSC, ARR and CCR1 into their shadows.
        tim.egr().write(|w| unsafe { w.bits(EGR_UG) });
        // CR1 (§14.4.1): ARPE = 1, CEN = 1.
        tim.cr1().write(|w| unsafe { w.bits(CR1_ARPE | CR1_CEN) });
        Self {
            tim,
            enable,
            _direction: direction,
        }
    }

    /// Compare value that gives 100 % duty (ARR + 1).
    pub const fn period(&self) -> u16 {
        DRUM_ARR + 1
    }

    /// Sets the compare value (duty = `ccr / period()`), clamped to the period.
    pub fn set_compare(&mut self, ccr: u16) {
        let ccr = ccr.min(self.period());
        // TIM1_CCR1 (RM0008 §14.4.14), preloaded (OC1PE): applies at the
        // next update, within one 50 µs PWM period. (Stopping does not rely
        // on it: `set_enabled(false)` drops PB12 at once.)
        self.tim.ccr1().write(|w| w.ccr().set(ccr));
    }

    /// Switches the motor driver on or off; off also zeroes the duty.
    pub fn set_enabled(&mut self, on: bool) {
        if on {
            self.enable.set_high();
        } else {
            self.set_compare(0);
            self.enable.set_low();
        }
    }
}

/// Timer settings for a square wave of `rate` (U16F16 Hz) from 72 MHz:
/// `(PSC, ARR)`, the finest prescaler that keeps ARR within 16 bits; `None`
/// for 0 Hz (or a rate below 0.14 Hz).
#[cfg(feature = "profile-b")]
fn step_timing(rate_bits: u32) -> Option<(u16, u16)> {
    if rate_bits == 0 {
        return None;
    }
    for psc in [0u32, 71, 7199] {
        // ARR + 1 = clk / (PSC + 1) / f, f = bits / 65536.
        let ticks = (u64::from(TIMER_CLOCK_HZ / (psc + 1)) << 16) / u64::from(rate_bits);
        if (2..=65_536).contains(&ticks) {
            return Some((psc as u16, (ticks - 1) as u16));
        }
    }
    None
}

/// Programs a timer's CH1 for step pulses at `rate` (50 % duty), or off.
///
/// - Off: OC1M = 100, forced inactive: the output goes low at once (RM0008
///   §14.4.7 / §15.4.7: OC1M is not preloaded), not at the next update,
///   which at a slow step rate can be seconds away.
/// - From off: PSC, ARR and CCR1, PWM mode 1, then UG (§15.4.6): the
///   shadows load together, the counter restarts at 0 and the first pulse
///   starts now.
/// - A change while pulsing: PSC, ARR (ARPE = 1) and CCR1 (OC1PE = 1) are
///   all preloaded, but an update between two of the three writes would
///   start a period with some old and some new values. UDIS = 1 while
///   writing (§15.4.1: no update event, the shadows keep their values; the
///   counter still wraps on the old ARR), then UDIS = 0: the first update
///   after that loads all three together. The current pulse finishes on the
///   old values, so a change takes effect within one old period.
#[cfg(feature = "profile-b")]
macro_rules! set_step_rate {
    ($tim:expr, $rate_bits:expr) => {{
        let tim = &$tim;
        match step_timing($rate_bits) {
            Some((psc, arr)) => {
                let mode = tim.ccmr1_output().read().bits() & CCMR1_OC1M_MASK;
                // SAFETY: register values from RM0008 §15.4 (see above); the
                // timer is owned by the caller.
                unsafe {
                    if mode == CCMR1_OC1M_PWM1 {
                        tim.cr1().write(|w| w.bits(CR1_ARPE | CR1_UDIS | CR1_CEN));
                        tim.psc().write(|w| w.psc().set(psc));
                        tim.arr().write(|w| w.arr().set(arr));
                        tim.ccr1().write(|w| w.ccr().set(arr / 2 + 1));
                        tim.cr1().write(|w| w.bits(CR1_ARPE | CR1_CEN));
                    } else {
                        tim.psc().write(|w| w.psc().set(psc));
                        tim.arr().write(|w| w.arr().set(arr));
                        tim.ccr1().write(|w| w.ccr().set(arr / 2 + 1));
                        tim.ccmr1_output()
                            .write(|w| w.bits(CCMR1_OC1M_PWM1 | CCMR1_OC1PE));
                        tim.egr().write(|w| w.bits(EGR_UG));
                    }
                }
            }
            None => {
                // SAFETY: as above.
                tim.ccmr1_output()
                    .write(|w| unsafe { w.bits(CCMR1_OC1M_FORCE_INACTIVE | CCMR1_OC1PE) });
            }
        }
    }};
}

/// Profile B's feeding-motor step output, TIM4 CH1 on PB6, with both
/// motors' direction pins (forward = low).
#[cfg(feature = "profile-b")]
pub struct FeedStep {
    tim: pac::TIM4,
    _feed_dir: stm32f1xx_hal::gpio::PB14<Output<PushPull>>,
    _plant_dir: stm32f1xx_hal::gpio::PB15<Output<PushPull>>,
}

#[cfg(feature = "profile-b")]
impl FeedStep {
    fn new(
        tim: pac::TIM4,
        mut feed_dir: stm32f1xx_hal::gpio::PB14<Output<PushPull>>,
        mut plant_dir: stm32f1xx_hal::gpio::PB15<Output<PushPull>>,
    ) -> Self {
        feed_dir.set_low();
        plant_dir.set_low();
        // SAFETY: raw register values from RM0008 §15.4; TIM4 is owned by
        // this struct. ARR (§15.4.12) must be non-zero before the update and
        // the counter start: "the counter is blocked while the auto-reload
        // value is null", and with it every later preload (PSC, ARR, CCR1)
        // would wait for an update that never comes. The idle values (PSC 0,
        // ARR 0xFFFF) are replaced by `set_step_rate!` when pulses start.
        tim.psc().write(|w| w.psc().set(0));
        tim.arr().write(|w| w.arr().set(u16::MAX));
        tim.ccr1().write(|w| w.ccr().set(0));
        // CCMR1 (§15.4.7): OC1M = 100 (forced inactive: no pulses), OC1PE = 1.
        tim.ccmr1_output()
            .write(|w| unsafe { w.bits(CCMR1_OC1M_FORCE_INACTIVE | CCMR1_OC1PE) });
        // CCER (§15.4.9): CC1E = 1, active high.
        tim.ccer().write(|w| unsafe { w.bits(CCER_CC1E) });
        // EGR UG (§15.4.6), then CR1 (§15.4.1): ARPE = 1, CEN = 1.
        tim.egr().write(|w| unsafe { w.bits(EGR_UG) });
        tim.cr1().write(|w| unsafe { w.bits(CR1_ARPE | CR1_CEN) });
        Self {
            tim,
            _feed_dir: feed_dir,
            _plant_dir: plant_dir,
        }
    }
}

/// Profile B's two step outputs: the planting motor on TIM1 CH1 (PA8, the
/// drum PWM pin of profile A) and the feeding motor on TIM4 CH1 (PB6); the
/// drivers share the enable on PB12.
#[cfg(feature = "profile-b")]
pub struct Steppers {
    drum: DrumDrive,
    feed: FeedStep,
}

#[cfg(feature = "profile-b")]
impl Steppers {
    /// Takes over the drum PWM's timer for step pulses (profile B), forced
    /// inactive (no pulses) until a rate is set.
    pub fn new(drum: DrumDrive, feed: FeedStep) -> Self {
        set_step_rate!(drum.tim, 0);
        Self { drum, feed }
    }

    /// Sets both pulse rates (U16F16 Hz) and the drivers' enable.
    pub fn set(
        &mut self,
        feed: kinematics::units::Hertz,
        plant: kinematics::units::Hertz,
        enabled: bool,
    ) {
        let (feed, plant) = if enabled {
            (feed.to_bits(), plant.to_bits())
        } else {
            (0, 0)
        };
        set_step_rate!(self.feed.tim, feed);
        set_step_rate!(self.drum.tim, plant);
        if enabled {
            self.drum.enable.set_high();
        } else {
            self.drum.enable.set_low();
        }
    }
}

/// Polled sensors: the drum encoder counter.
pub struct Sensors {
    tim3: TIM3,
}

impl Sensors {
    fn new(tim3: TIM3) -> Self {
        // SAFETY: raw register values for encoder mode 3 (RM0008 §15.3.12).
        // CCMR1 (§15.4.7, input): CC1S = 01 (IC1 on TI1), CC2S = 01 (IC2 on
        // TI2), IC1F = IC2F = 0011: sampled at fCK_INT (72 MHz), N = 8, i.e.
        // a level must hold 8 samples = 111 ns to count. (The encoder's
        // fastest edges, 23.6 kHz per channel at 7080 motor r/min, are 21 µs
        // apart.)
        tim3.ccmr1_input()
            .write(|w| unsafe { w.bits((0b0011 << 12) | (0b01 << 8) | (0b0011 << 4) | 0b01) });
        // CCER (§15.4.9): both polarities non-inverted, captures off.
        tim3.ccer().write(|w| unsafe { w.bits(0) });
        // SMCR (§15.4.3): SMS = 011, encoder mode 3 (both edges of both inputs).
        tim3.smcr().write(|w| unsafe { w.bits(0b011) });
        // ARR (§15.4.12) non-zero before CEN: the counter wraps at 2^16.
        tim3.arr().write(|w| w.arr().set(u16::MAX));
        tim3.cr1().write(|w| unsafe { w.bits(CR1_CEN) });
        Self { tim3 }
    }

    /// Reads the sensors for one control period.
    pub fn sample(&mut self, _now_ms: u32) -> SensorSample {
        SensorSample {
            drum_encoder: self.tim3.cnt().read().cnt().bits(),
            hall_edges: heapless::Vec::new(),
        }
    }
}

/// TIM2 CH1 input capture of Hall edges at 1 MHz, extended to 32 bits with
/// the timer's update (overflow) events.
pub struct HallCapture {
    tim2: TIM2,
    extender: CaptureExtender,
}

impl HallCapture {
    fn new(tim2: TIM2) -> Self {
        let psc = (TIMER_CLOCK_HZ / HALL_TIMER_HZ - 1) as u16;
        // PSC = 71 (1 MHz) and ARR = 0xFFFF, non-zero before UG and CEN
        // (RM0008 §15.4.11, §15.4.12).
        tim2.psc().write(|w| w.psc().set(psc));
        tim2.arr().write(|w| w.arr().set(u16::MAX));
        // SAFETY: raw register values (RM0008 §15.4): CCMR1 (§15.4.7) CC1S =
        // 01 (IC1 on TI1), IC1F = 1111 (fDTS/32 with fDTS = fCK_INT = 72 MHz,
        // N = 8: a level must hold 8 × 0.44 µs = 3.6 µs); CCER (§15.4.9) CC1E,
        // CC1P (falling edge); DIER (§15.4.4) CC1IE and UIE.
        tim2.ccmr1_input()
            .write(|w| unsafe { w.bits((0b1111 << 4) | 0b01) });
        tim2.ccer().write(|w| unsafe { w.bits(0b11) });
        tim2.egr().write(|w| unsafe { w.bits(EGR_UG) });
        tim2.sr().write(|w| unsafe { w.bits(0) });
        tim2.dier().write(|w| unsafe { w.bits(0b11) });
        tim2.cr1().write(|w| unsafe { w.bits(CR1_CEN) });
        Self {
            tim2,
            extender: CaptureExtender::new(),
        }
    }

    /// Handles the TIM2 interrupt: returns the edge captured, if any, as a
    /// 32-bit timestamp in 1 µs ticks, and whether edges were lost before it.
    ///
    /// Reads, in this order (RM0008 §15.4.5 TIMx_SR, §15.4.13 TIMx_CCR1):
    /// SR; CCR1 if CC1IF (the read clears CC1IF, so the flag is never
    /// written: a capture landing between the read and a write would be
    /// lost); SR again (UIF and CC1OF as they stand after the capture
    /// read); CNT. The capture is extended with UIF and the counter read
    /// after it (`CaptureExtender::extend_at`: exact up to a whole wrap,
    /// 65.5 ms, of interrupt delay — a 40 ms flash erase stall included);
    /// then UIF and CC1OF are cleared (rc_w0: only the bits seen are written
    /// 0, the others 1) and the overflow is accounted.
    ///
    /// CC1OF set means a capture came while the previous one was unread: at
    /// least one Hall edge was lost, and CCR1 holds the newest capture, so
    /// the edge read here follows the loss (`after_lost`) and the estimator
    /// must not measure the interval ending at it. If CC1IF is set again at
    /// the second SR read, the loss may instead lie after the edge just read
    /// (two captures since): CC1OF is then left set, so that the next edge
    /// (its interrupt is already pending) is marked too — one window too
    /// many discarded rather than one measured wrong.
    pub fn on_interrupt(&mut self) -> Option<super::HallEdge> {
        let sr = self.tim2.sr().read().bits();
        let ccr = (sr & SR_CC1IF != 0).then(|| self.tim2.ccr1().read().bits() as u16);
        let sr = self.tim2.sr().read().bits();
        let counter = self.tim2.cnt().read().bits() as u16;
        let overflowed = sr & SR_UIF != 0;
        let lost = sr & SR_CC1OF != 0;
        let clear = if sr & SR_CC1IF == 0 {
            sr & (SR_UIF | SR_CC1OF)
        } else {
            sr & SR_UIF
        };
        if clear != 0 {
            // SAFETY: rc_w0 flags: 0 clears exactly the flags seen, 1 leaves
            // the others (CC1IF included) untouched.
            self.tim2.sr().write(|w| unsafe { w.bits(!clear & 0xFFFF) });
        }
        let edge = ccr.map(|ccr| super::HallEdge {
            stamp: self.extender.extend_at(ccr, overflowed, counter).0,
            after_lost: lost,
        });
        if overflowed {
            self.extender.on_overflow();
        }
        edge
    }

    /// The capture timer's time, 1 MHz, extended to 32 bits: the counter
    /// read between two reads of UIF (`CaptureExtender::now_between`).
    pub fn now(&self) -> u32 {
        let before = self.tim2.sr().read().bits() & SR_UIF != 0;
        let counter = self.tim2.cnt().read().bits() as u16;
        let after = self.tim2.sr().read().bits() & SR_UIF != 0;
        self.extender.now_between(before, counter, after).0
    }
}

/// IWDG prescaler: PR = 011, LSI / 32 (RM0008 §19.4.2).
const IWDG_PR_DIV32: u16 = 0b011;
/// IWDG reload: 313 counts of LSI / 32, i.e. 10 016 LSI cycles.
const IWDG_RELOAD: u16 = 312;
/// Bound on the wait for the prescaler and reload to reach the LSI domain
/// (PVU, RVU: "up to 5 RC 40 kHz oscillator cycles", RM0008 §19.4.4: 167 µs
/// at the LSI's slowest 30 kHz); each poll is a few cycles of the 8 MHz HSI.
const IWDG_UPDATE_POLLS: u32 = 20_000;

/// The independent watchdog: 313 × 32 = 10 016 LSI cycles, 250 ms at the
/// LSI's nominal 40 kHz, 166.9–333.9 ms over its 30–60 kHz spread
/// (datasheet STM32F103xB, "LSI oscillator characteristics"). Fed only by
/// the control task when it ran on time (every 10 ms). The longest time the
/// CPU cannot feed it is a flash page erase: tERASE ≤ 40 ms (datasheet,
/// "Flash memory characteristics"), far inside the shortest 166.9 ms.
pub struct Watchdog {
    iwdg: IWDG,
}

impl Watchdog {
    /// Starts the watchdog first thing at boot (RM0008 §19.3.2), the
    /// sequence of ST's reference driver: 0xCCCC starts it (LSI on; it
    /// counts from 0xFFF at the reset prescaler /4, 273–546 ms) and cannot
    /// be stopped again; 0x5555 unlocks PR and RLR; once PVU and RVU clear,
    /// 0xAAAA reloads the counter with the new timeout.
    fn start(iwdg: IWDG) -> Self {
        // SAFETY: the key values and register fields of RM0008 §19.4.1–§19.4.4.
        iwdg.kr().write(|w| unsafe { w.bits(0xCCCC) });
        iwdg.kr().write(|w| unsafe { w.bits(0x5555) });
        iwdg.pr().write(|w| unsafe { w.bits(IWDG_PR_DIV32) });
        iwdg.rlr().write(|w| unsafe { w.bits(IWDG_RELOAD) });
        let mut polls = 0;
        while iwdg.sr().read().bits() & 0b11 != 0 {
            polls += 1;
            if polls >= IWDG_UPDATE_POLLS {
                // The LSI does not run: the watchdog cannot either. Said
                // once; the machine still works.
                defmt::error!(
                    "watchdog: prescaler/reload update did not complete (LSI not running?)"
                );
                break;
            }
        }
        iwdg.kr().write(|w| unsafe { w.bits(0xAAAA) });
        Self { iwdg }
    }

    /// Reloads the watchdog counter.
    pub fn feed(&mut self) {
        // SAFETY: 0xAAAA is the reload key (RM0008 §19.4.1 IWDG_KR).
        self.iwdg.kr().write(|w| unsafe { w.bits(0xAAAA) });
    }
}

/// Offset of the settings pages from the start of flash (0x0800E000, see
/// memory-stm32f103.x).
#[cfg(not(feature = "drive-link"))]
const SETTINGS_OFFSET: u32 = 0xE000;
/// With the drive link, the 128 KB parts' layout: 0x0801E000, see
/// memory-stm32f103-128k.x.
#[cfg(feature = "drive-link")]
const SETTINGS_OFFSET: u32 = 0x1_E000;
/// The flash the HAL's writer may reach: the settings pages at 0x0800E000
/// lie in the first 64 KB, those of the image with the drive link in the
/// 128 KB parts' last 8 KB.
#[cfg(not(feature = "drive-link"))]
const FLASH_SIZE: FlashSize = FlashSize::Sz64K;
/// See above.
#[cfg(feature = "drive-link")]
const FLASH_SIZE: FlashSize = FlashSize::Sz128K;
/// The settings pages of the MCU's own flash as a NOR flash.
pub struct SettingsFlash {
    flash: flash::Parts,
}

impl ErrorType for SettingsFlash {
    type Error = FlashError;
}

impl ReadNorFlash for SettingsFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 1)?;
        let writer = self.flash.writer(SectorSize::Sz1K, FLASH_SIZE);
        let data = writer
            .read(SETTINGS_OFFSET + offset, bytes.len())
            .map_err(|_| FlashError::Device)?;
        bytes.copy_from_slice(data);
        Ok(())
    }

    fn capacity(&self) -> usize {
        SETTINGS_FLASH_BYTES as usize
    }
}

impl NorFlash for SettingsFlash {
    const WRITE_SIZE: usize = 2;
    const ERASE_SIZE: usize = SETTINGS_PAGE_BYTES as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_flash_erase(from, to)?;
        let mut writer = self.flash.writer(SectorSize::Sz1K, FLASH_SIZE);
        writer
            .erase(SETTINGS_OFFSET + from, (to - from) as usize)
            .map_err(|_| FlashError::Device)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_flash_access(offset, bytes.len(), 2)?;
        let mut writer = self.flash.writer(SectorSize::Sz1K, FLASH_SIZE);
        writer
            .write(SETTINGS_OFFSET + offset, bytes)
            .map_err(|_| FlashError::Device)
    }
}

/// The stop input on PB10: a normally closed contact to ground with the
/// internal pull-up (datasheet: PB10 is a 5 V tolerant "FT" pin). An open
/// contact, a cut wire or an unplugged connector read high: stop.
pub struct StopInput {
    pin: PB10<Input<PullUp>>,
}

impl StopInput {
    /// The contact is open (the pin reads high): stop.
    pub fn is_open(&self) -> bool {
        self.pin.is_high()
    }

    /// Acknowledges the pin's EXTI interrupt.
    pub fn clear_interrupt(&mut self) {
        self.pin.clear_interrupt_pending_bit();
    }
}

/// The work switch on PB11: a contact to ground that closes while the
/// planting unit is down, with the internal pull-up (PB11 is a 5 V
/// tolerant "FT" pin). An open contact, a cut wire or an unplugged
/// connector read high: up, not planting (the safe side).
pub struct WorkSwitchInput {
    pin: PB11<Input<PullUp>>,
}

impl WorkSwitchInput {
    /// The contact is closed (the pin reads low): the unit is down.
    pub fn is_closed(&self) -> bool {
        self.pin.is_low()
    }
}

/// The stop input's response, from its interrupt: drum PWM compare 0 now
/// (the preloaded CCR1 = 0 is loaded at once by an update event, UG), the
/// drivers' enable PB12 low; profile B's feed step timer (TIM4) likewise.
/// Unlike [`safe_state`], the outputs stay armed: the control task drives
/// them again once the operator restarts.
pub fn stop_outputs() {
    // SAFETY: single writes to TIM1/TIM4 CCR1 and EGR and to GPIOB's BSRR,
    // which are write-only in effect (no read-modify-write), from the
    // highest-priority interrupt; the control task re-writes CCR1 and PB12
    // only when the stop latch allows it (under the same lock).
    unsafe {
        let gpiob = &*pac::GPIOB::ptr();
        gpiob.bsrr().write(|w| w.bits(1 << (12 + 16)));
        let tim1 = &*TIM1::ptr();
        tim1.ccr1().write(|w| w.ccr().set(0));
        tim1.egr().write(|w| w.ug().set_bit());
        #[cfg(feature = "profile-b")]
        {
            let tim4 = &*pac::TIM4::ptr();
            tim4.ccr1().write(|w| w.ccr().set(0));
            tim4.egr().write(|w| w.ug().set_bit());
        }
    }
}

/// The status LED on PC13 (active low).
pub struct StatusLed(PC13<Output<PushPull>>);

impl StatusLed {
    /// Lights or darkens the LED.
    pub fn set(&mut self, on: bool) {
        if on {
            self.0.set_low();
        } else {
            self.0.set_high();
        }
    }
}

/// GPIOx_CRL/CRH nibble (RM0008 §9.2.1, §9.2.2) for a general-purpose
/// push-pull output at 2 MHz: CNF = 00, MODE = 10.
const GPIO_OUT_PP_2MHZ: u32 = 0b0010;
/// RCC_APB2ENR IOPAEN (bit 2) and IOPBEN (bit 3) (RM0008 §7.3.7).
const APB2ENR_IOPA_IOPB: u32 = (1 << 2) | (1 << 3);

/// Drives the outputs to their safe state at once, with raw register writes
/// and no stack of its own to speak of, from any context (boot before the
/// clocks, panic, HardFault after a stack overflow, NMI, an unexpected
/// interrupt):
///
/// 1. PA8 (drum PWM / profile B planting STEP), PB12 (drivers' enable),
///    profile B's PB6 (feeding STEP) and PA1 (the RS-485 transceiver's
///    driver-enable: low receives and releases the motor driver's bus;
///    it floated from reset until `init` when the clock never came up)
///    become general-purpose push-pull
///    outputs driven low: ODR bits cleared through BRR (RM0008 §9.2.6), then
///    the pins' CRH/CRL nibbles = 0010 (§9.2.1, §9.2.2), the port clocks
///    switched on first (§7.3.7). This holds whatever state the timers are
///    in (unconfigured, clock off, stopped by a debug halt).
/// 2. The timers agree: TIM1 CH1 (and TIM4 CH1 on profile B) forced
///    inactive, OC1M = 100 (§14.4.7, §15.4.7: takes effect immediately,
///    unlike CCR1, which is preloaded and would wait for the next update —
///    up to a whole step period on TIM4); CCR1 = 0; TIM1's MOE cleared with
///    OSSI = OSSR = 1 so that its output stays driven at OIS1 = low
///    (§14.4.18, Table 83) rather than released (Hi-Z) as with OSSI = 0.
///    Writes to a timer whose clock is off are ignored, harmlessly.
///
/// Either step alone holds the pins low; the GPIO one does not depend on
/// any timer setting and the timer one keeps the pins low if a pin is ever
/// handed back to its timer.
#[inline(always)]
pub fn safe_state() {
    // SAFETY: single writes (and read-modify-writes of registers no
    // interrupt handler touches) of documented values; every caller either
    // never returns to the application or runs before it exists (boot).
    unsafe {
        let rcc = &*pac::RCC::ptr();
        rcc.apb2enr()
            .modify(|r, w| w.bits(r.bits() | APB2ENR_IOPA_IOPB));
        let gpioa = &*pac::GPIOA::ptr();
        let gpiob = &*pac::GPIOB::ptr();
        gpioa.brr().write(|w| w.bits((1 << 8) | (1 << 1)));
        gpiob.brr().write(|w| w.bits((1 << 12) | (1 << 6)));
        gpioa
            .crh()
            .modify(|r, w| w.bits((r.bits() & !0xF) | GPIO_OUT_PP_2MHZ));
        gpioa
            .crl()
            .modify(|r, w| w.bits((r.bits() & !(0xF << 4)) | (GPIO_OUT_PP_2MHZ << 4)));
        gpiob
            .crh()
            .modify(|r, w| w.bits((r.bits() & !(0xF << 16)) | (GPIO_OUT_PP_2MHZ << 16)));
        #[cfg(feature = "profile-b")]
        gpiob
            .crl()
            .modify(|r, w| w.bits((r.bits() & !(0xF << 24)) | (GPIO_OUT_PP_2MHZ << 24)));
        let tim1 = &*TIM1::ptr();
        tim1.ccmr1_output()
            .write(|w| w.bits(CCMR1_OC1M_FORCE_INACTIVE | CCMR1_OC1PE));
        tim1.ccr1().write(|w| w.ccr().set(0));
        tim1.bdtr().write(|w| w.bits(BDTR_OSSR_OSSI));
        #[cfg(feature = "profile-b")]
        {
            let tim4 = &*pac::TIM4::ptr();
            tim4.ccmr1_output()
                .write(|w| w.bits(CCMR1_OC1M_FORCE_INACTIVE | CCMR1_OC1PE));
            tim4.ccr1().write(|w| w.ccr().set(0));
        }
    }
}

/// Whether the motor drivers' enable (PB12) is high, read back from its
/// output data register (RM0008 §9.2.4): the settings task erases flash only
/// while it is low.
pub fn drivers_enabled() -> bool {
    // SAFETY: a read of GPIOB_ODR, no side effect.
    unsafe { (*pac::GPIOB::ptr()).odr().read().bits() & (1 << 12) != 0 }
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

/// DBGMCU_CR (RM0008 §31.16.3), for a debug probe halting the core:
///
/// - DBG_SLEEP: the debug connection (RTT) stays alive in `wfi`.
/// - DBG_TIM1_STOP, DBG_TIM4_STOP: the step/PWM timers stop with the core.
///   TIM1 has complementary outputs, so stopping it also disables its
///   outputs "as if the MOE bit was reset" (§31.16.2), which with OSSI = 1
///   drives PA8 low; TIM4's PB6 holds its level, and no further step pulse
///   comes. Without these bits a halted core would leave the drum PWM (and
///   the steppers) running under no control.
/// - DBG_IWDG_STOP: the watchdog stops too, so that a breakpoint (or the
///   probe's halt on a HardFault) does not reset the board under the
///   debugger. The bits act only while a debugger holds the core halted; in
///   the field nothing halts it, so the watchdog keeps its full effect.
/// - TIM2 and TIM3 keep counting: TIM3 follows the machine's real motion,
///   and TIM2's time stays the machine's; a halt breaks the Hall
///   measurement either way (its overflows go unserviced).
fn debug_freeze(dbgmcu: &pac::DBGMCU) {
    dbgmcu.cr().modify(|_, w| {
        w.dbg_sleep()
            .set_bit()
            .dbg_tim1_stop()
            .set_bit()
            .dbg_tim4_stop()
            .set_bit()
            .dbg_iwdg_stop()
            .set_bit()
    });
}

/// SCB_CCR STKALIGN (bit 9, PM0056 §4.4.7).
const SCB_CCR_STKALIGN: u32 = 1 << 9;

/// Makes exception entry align the stacked frame, and so every handler's
/// stack, to 8 bytes (SCB_CCR STKALIGN), as the AAPCS the handlers are
/// compiled to requires. The F103's Cortex-M3 r1p1 (CPUID 0x411FC231)
/// resets the bit to 0 (Cortex-M3 TRM r1p1; ARM's ABI advisory IHI 0046B
/// asks startup code to set it), and neither cortex-m-rt nor RTIC sets it:
/// an interrupt that comes while SP is 4 mod 8 — inside the many functions
/// that push five registers before the rest of their frame — would run its
/// handler on a 4-byte aligned stack.
fn align_exception_frames() {
    // SAFETY: a read-modify-write of SCB_CCR in `init` (interrupts off, no
    // exception active): the next exception entry uses the new alignment.
    unsafe {
        (*cortex_m::peripheral::SCB::PTR)
            .ccr
            .modify(|r| r | SCB_CCR_STKALIGN);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// Switches the HSE on (RM0008 §7.3.1 RCC_CR HSEON, bit 16) and waits for
/// HSERDY (bit 17) at most [`HSE_TIMEOUT_CYCLES`]; false if it never came.
fn start_hse(rcc: &pac::RCC) -> bool {
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    let mut waited = 0;
    while rcc.cr().read().hserdy().bit_is_clear() {
        if waited >= HSE_TIMEOUT_CYCLES {
            rcc.cr().modify(|_, w| w.hseon().clear_bit());
            return false;
        }
        cortex_m::asm::delay(HSE_POLL_CYCLES);
        waited += HSE_POLL_CYCLES;
    }
    true
}

/// Whether the clock security system saw the HSE fail (RM0008 §7.3.3
/// RCC_CIR CSSF, bit 7): the cause of an NMI.
pub fn clock_failed() -> bool {
    // SAFETY: a read of RCC_CIR, no side effect.
    unsafe { (*pac::RCC::ptr()).cir().read().cssf().bit_is_set() }
}

/// Ends a run that reached its limit (never on the real board).
pub fn exit_success() -> ! {
    fatal()
}
