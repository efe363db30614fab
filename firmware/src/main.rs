//! Transplanter controller firmware: keeps plant spacing exact whatever the
//! travel speed.
//!
//! An RTIC 2 application. The hardware lives behind [`board`]: the real
//! STM32F103RB (default) or the QEMU `stm32vldiscovery` board with a simulated
//! machine (`--no-default-features --features board-qemu`).
//!
//! Task map (higher number = higher priority):
//!
//! | task | priority | release | budget |
//! |---|---|---|---|
//! | [`app::usart1_rx`] | 4 | each touchscreen byte (≤ 11.5 kHz) | 2 µs |
//! | [`app::hall_capture`] | 3 | each Hall edge (≤ 1 kHz) and TIM2 overflow | 2 µs |
//! | [`app::control`] | 2 | every 10 ms | 1 ms |
//! | [`app::hmi`] | 1 | each touchscreen frame | 3 ms (reply on the wire) |
//! | [`app::status`] | 1 | every 200 ms | 5 ms |
//! | `idle` | 0 | — | sleeps in `wfi` |
#![no_std]
#![no_main]

mod board;
mod link;
mod stats;

use rtic_monotonics::systick::prelude::*;

systick_monotonic!(Mono, 1_000);

defmt::timestamp!("{=u32:ms}", uptime_ms());

/// Milliseconds since boot (the monotonic runs at 1 kHz; wraps after 49 days).
fn uptime_ms() -> u32 {
    Mono::now().duration_since_epoch().as_millis()
}

/// Control period.
const CONTROL_PERIOD_MS: u32 = 10;
/// Status period (5 Hz).
const STATUS_PERIOD_MS: u32 = 200;
/// The status task logs every this many runs (1 Hz).
const STATUS_LOG_EVERY: u32 = 5;
/// Frames queued between the USART interrupt and the HMI task.
const FRAME_QUEUE: usize = 4;

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [CAN_RX1, CAN_SCE, ADC1_2])]
mod app {
    use super::{
        board, link, stats, Mono, CONTROL_PERIOD_MS, FRAME_QUEUE, STATUS_LOG_EVERY,
        STATUS_PERIOD_MS,
    };
    use core::fmt::Write as _;
    use rtic_monotonics::systick::prelude::*;
    use rtic_sync::{
        channel::{Receiver, Sender},
        make_channel,
    };

    #[shared]
    struct Shared {
        /// Touchscreen transmitter (HMI replies, status pages).
        hmi_tx: board::HmiTx,
        /// The latest Hall edge timestamp, in 1 µs ticks.
        last_hall_edge: Option<u32>,
    }

    #[local]
    struct Local {
        hmi_rx: board::HmiRx,
        splitter: link::FrameSplitter,
        frames_in: Sender<'static, link::Frame, FRAME_QUEUE>,
        frames_out: Receiver<'static, link::Frame, FRAME_QUEUE>,
        hall: board::HallCapture,
        sensors: board::Sensors,
        drum: board::DrumDrive,
        led: board::StatusLed,
        run_limit_ms: Option<u32>,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let board = board::init(cx.device);
        Mono::start(cx.core.SYST, board.sysclk_hz);
        let (frames_in, frames_out) = make_channel!(link::Frame, FRAME_QUEUE);
        let run_limit_ms = board::run_limit_ms();
        defmt::info!(
            "boot: transplanter firmware {=str}, sysclk {=u32} Hz, run limit {=?} ms",
            env!("CARGO_PKG_VERSION"),
            board.sysclk_hz,
            run_limit_ms
        );
        let mut drum = board.drum;
        drum.set_enabled(false);
        // Note(unwrap): nothing is spawned twice; a failure here is a bug
        // found on the first boot.
        control::spawn().ok();
        status::spawn().ok();
        hmi::spawn().ok();
        (
            Shared {
                hmi_tx: board.hmi_tx,
                last_hall_edge: None,
            },
            Local {
                hmi_rx: board.hmi_rx,
                splitter: link::FrameSplitter::new(),
                frames_in,
                frames_out,
                hall: board.hall,
                sensors: board.sensors,
                drum,
                led: board.led,
                run_limit_ms,
            },
        )
    }

    /// Sleeps between interrupts.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// Touchscreen bytes: drains USART1 into the frame splitter and queues
    /// each complete frame for [`hmi`].
    ///
    /// - Priority 4 (highest): the F103's USART has no FIFO, so a byte must
    ///   be read within one character time (87 µs at 115200 baud).
    /// - Released by USART1 RXNE, at most 11.5 k times a second.
    /// - Budget: 2 µs per byte.
    #[task(binds = USART1, priority = 4, local = [hmi_rx, splitter, frames_in])]
    fn usart1_rx(cx: usart1_rx::Context) {
        // A few bytes at most are pending; the bound keeps an error storm
        // from holding the CPU.
        for _ in 0..4 {
            match cx.local.hmi_rx.read() {
                Ok(byte) => {
                    stats::HMI_RX_BYTES.inc();
                    match cx.local.splitter.push(byte) {
                        link::Push::Pending => {}
                        link::Push::Frame(frame) => {
                            stats::HMI_RX_FRAMES.inc();
                            if cx.local.frames_in.try_send(frame).is_err() {
                                stats::HMI_RX_FRAMES_DROPPED.inc();
                            }
                        }
                        link::Push::Overlong => stats::HMI_RX_FRAMES_DROPPED.inc(),
                    }
                }
                Err(nb::Error::WouldBlock) => break,
                Err(nb::Error::Other(_)) => stats::HMI_RX_ERRORS.inc(),
            }
        }
    }

    /// Hall edges: timestamps each tooth of the 25-tooth gear.
    ///
    /// - Priority 3: the capture register latches the edge time in hardware,
    ///   so latency only has to stay below the shortest period (1 ms).
    /// - Released by TIM2 capture (≤ 1 kHz) and overflow (15.3 Hz).
    /// - Budget: 2 µs.
    #[task(binds = TIM2, priority = 3, local = [hall], shared = [last_hall_edge])]
    fn hall_capture(mut cx: hall_capture::Context) {
        if let Some(edge) = cx.local.hall.on_interrupt() {
            stats::HALL_EDGES.inc();
            cx.shared.last_hall_edge.lock(|last| *last = Some(edge));
        }
    }

    /// The drum speed control loop.
    ///
    /// - Priority 2: preempted only by the byte and edge interrupts.
    /// - Period 10 ms, released on an absolute schedule (no drift); a run that
    ///   ends after its next release is counted as an overrun.
    /// - Budget: 1 ms.
    #[task(priority = 2, local = [sensors, drum], shared = [last_hall_edge])]
    async fn control(mut cx: control::Context) {
        let mut next = Mono::now();
        let mut last_encoder: Option<u16> = None;
        loop {
            let now_ms = super::uptime_ms();
            let sample = cx.local.sensors.sample(now_ms);
            if let Some(&edge) = sample.hall_edges.last() {
                stats::HALL_EDGES.add(sample.hall_edges.len() as u32);
                cx.shared.last_hall_edge.lock(|last| *last = Some(edge));
            }
            if let Some(prev) = last_encoder {
                DRUM_COUNTS.store(
                    u32::from(sample.drum_encoder.wrapping_sub(prev)),
                    core::sync::atomic::Ordering::Relaxed,
                );
            }
            last_encoder = Some(sample.drum_encoder);
            // The drum stays stopped until the operator starts it.
            cx.local.drum.set_compare(0);

            stats::CONTROL_LOOPS.inc();
            next += CONTROL_PERIOD_MS.millis();
            if Mono::now() > next {
                stats::CONTROL_OVERRUNS.inc();
            }
            Mono::delay_until(next).await;
        }
    }

    /// Drum speed in 0.01 r/min from encoder counts in one control period.
    fn drum_speed_centi_rpm(counts_per_period: u32) -> u32 {
        let per_minute = u64::from(counts_per_period) * u64::from(60_000 / CONTROL_PERIOD_MS);
        let centi = per_minute * 100 / u64::from(board::DRUM_ENCODER_COUNTS_PER_REV);
        u32::try_from(centi).unwrap_or(u32::MAX)
    }

    /// Encoder counts in the last control period (for the status log).
    static DRUM_COUNTS: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

    /// Live status: logs a summary once a second and ends a QEMU run at its
    /// time limit.
    ///
    /// - Priority 1.
    /// - Period 200 ms (5 Hz).
    /// - Budget: 5 ms (a defmt frame over semihosting is the slow part).
    #[task(priority = 1, local = [led, run_limit_ms])]
    async fn status(cx: status::Context) {
        let mut next = Mono::now();
        let mut runs: u32 = 0;
        loop {
            let uptime_ms = super::uptime_ms();
            cx.local.led.set(runs.is_multiple_of(2));
            if runs.is_multiple_of(STATUS_LOG_EVERY) {
                defmt::info!(
                    "status: uptime {=u32} ms, control loops {=u32} (overruns {=u32}), hall edges {=u32}, drum {=u32} cr/min, hmi rx {=u32} B / {=u32} frames",
                    uptime_ms,
                    stats::CONTROL_LOOPS.get(),
                    stats::CONTROL_OVERRUNS.get(),
                    stats::HALL_EDGES.get(),
                    drum_speed_centi_rpm(DRUM_COUNTS.load(core::sync::atomic::Ordering::Relaxed)),
                    stats::HMI_RX_BYTES.get(),
                    stats::HMI_RX_FRAMES.get()
                );
            }
            if let Some(limit) = *cx.local.run_limit_ms {
                if uptime_ms >= limit {
                    defmt::info!("run limit of {=u32} ms reached, exiting", limit);
                    board::exit_success();
                }
            }
            runs = runs.wrapping_add(1);
            next += STATUS_PERIOD_MS.millis();
            Mono::delay_until(next).await;
        }
    }

    /// Touchscreen frames: answers each with the byte count received so far.
    ///
    /// - Priority 1.
    /// - Released by each complete frame from [`usart1_rx`].
    /// - Budget: 3 ms, most of it the reply on the wire at 115200 baud.
    #[task(priority = 1, local = [frames_out], shared = [hmi_tx])]
    async fn hmi(mut cx: hmi::Context) {
        while let Ok(frame) = cx.local.frames_out.recv().await {
            defmt::debug!("hmi frame {=[u8]}", frame.as_slice());
            let mut reply: heapless::String<32> = heapless::String::new();
            // Note(unwrap-free): the text is at most 24 bytes and fits.
            let _ = write!(reply, "rxcount.val={}", stats::HMI_RX_BYTES.get());
            cx.shared.hmi_tx.lock(|tx| {
                for &b in reply.as_bytes().iter().chain(&[0xFF, 0xFF, 0xFF]) {
                    let _ = nb::block!(tx.write_u8(b));
                }
            });
        }
    }
}

/// Panic: outputs to their safe state first, then the message, then a
/// HardFault (an attached probe-rs halts there and prints the backtrace).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    board::safe_state();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    cortex_m::asm::udf()
}

/// HardFault: outputs to their safe state first, then the board's end state
/// (the real board waits for the watchdog; QEMU exits with a failure code).
#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    board::safe_state();
    defmt::error!("HardFault at pc {=u32:#x}", frame.pc());
    board::fatal()
}
