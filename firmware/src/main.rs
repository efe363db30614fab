//! Transplanter controller firmware: keeps plant spacing exact whatever the
//! travel speed.
//!
//! An RTIC 2 application. The hardware lives behind [`board`]: the real
//! STM32F103RB (default) or the QEMU board (`netduino2`) with a simulated
//! machine (`--no-default-features --features board-qemu`). The operating
//! logic is the host-tested `supervisor` crate. This file declares the app:
//! its resources, `init` and the tasks, whose bodies, priorities, periods
//! and budgets are in [`tasks`]; [`boot`] builds what `init` hands them.
#![no_std]
#![no_main]

mod board;
mod boot;
mod edge_queue;
mod screen_line;
mod stats;
mod tasks;

use rtic_monotonics::systick::prelude::*;

systick_monotonic!(Mono, 1_000);

defmt::timestamp!("{=u32:ms}", uptime_ms());

/// Milliseconds since boot (the monotonic runs at 1 kHz; wraps after 49 days).
fn uptime_ms() -> u32 {
    Mono::now().duration_since_epoch().as_millis()
}

/// Bytes queued between the USART interrupt and the HMI task.
const RX_QUEUE: usize = 64;
/// The ring of bytes from the HMI task to the USART interrupt's transmitter
/// (it holds one less): all the screen link can have queued
/// (`TX_CAPACITY`), so one move of the HMI task empties the link's queue.
const TX_RING: usize = hmi_proto::hmi::TX_CAPACITY + 1;
/// Hall edges queued between the capture interrupt and the control task
/// (the QEMU board's edges come with the sensor sample, not this queue).
const EDGE_QUEUE: usize = 16;

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [CAN_RX1, CAN_SCE, ADC1_2])]
mod app {
    use super::{board, Mono, EDGE_QUEUE, RX_QUEUE, TX_RING};
    use crate::boot::{build_drive, build_hmi, load_settings};
    use crate::edge_queue::DropMark;
    use crate::screen_line::LineItem;
    use crate::tasks::control::{control, Actuators};
    use crate::tasks::drive_link::{drive_link, usart2, DriveState};
    use crate::tasks::hall_capture::hall_capture;
    use crate::tasks::hmi::hmi;
    use crate::tasks::screen_bytes::usart1;
    use crate::tasks::settings::{settings, Store};
    use crate::tasks::status::status;
    use crate::tasks::stop_input::{stop_input, StopCircuit};
    use core::mem::MaybeUninit;
    use heapless::spsc::{Consumer, Producer, Queue};
    use hmi_proto::hmi::Hmi;
    use rtic_sync::{
        channel::{Receiver, Sender},
        make_channel,
    };
    use supervisor::{machine::Machine, stop_input::StopLatch};

    // The large objects live in `static`s owned by `init` and are shared by
    // reference.
    #[shared]
    struct Shared {
        /// The operating logic (profile A or B): control (2), hmi (1), status (1).
        machine: &'static mut Machine,
        /// The screen link: control (2, alarms), hmi (1), status (1), settings (1).
        hmi: &'static mut Hmi,
        /// TIM2: its interrupt (3) and the control task's clock (2).
        hall: board::HallCapture,
        /// The stop input: its interrupt (5), the control task (2, which
        /// writes the outputs under this lock) and Start (hmi, 1).
        stop: StopCircuit,
        /// The drum driver's Modbus master: its task (3) and the control
        /// task (2, the read-back in, the command and enable out).
        drive: &'static mut DriveState,
        /// USART2 and DE (PA1): its interrupt (3) and the link task (3).
        drive_line: board::DriveLineRef,
    }

    #[local]
    struct Local {
        hmi_rx: board::HmiRx,
        hmi_tx: board::HmiTx,
        bytes_in: Sender<'static, LineItem, RX_QUEUE>,
        bytes_out: Receiver<'static, LineItem, RX_QUEUE>,
        tx_in: Producer<'static, u8>,
        tx_out: Consumer<'static, u8>,
        edges_in: Producer<'static, board::HallEdge>,
        edges_out: Consumer<'static, board::HallEdge>,
        drop_mark: DropMark,
        saves_in: Sender<'static, (), 1>,
        saves_out: Receiver<'static, (), 1>,
        sensors: board::SensorsRef,
        work_switch: board::WorkSwitchInput,
        actuators: Actuators,
        watchdog: board::Watchdog,
        led: board::StatusLed,
        store: Option<Store>,
        boot_notice: Option<&'static str>,
        run_limit_ms: Option<u32>,
    }

    #[init(local = [
        drive_slot: MaybeUninit<DriveState> = MaybeUninit::uninit(),
        edge_queue: Queue<board::HallEdge, EDGE_QUEUE> = Queue::new(),
        machine_slot: MaybeUninit<Machine> = MaybeUninit::uninit(),
        hmi_slot: MaybeUninit<Hmi> = MaybeUninit::uninit(),
        tx_ring: Queue<u8, TX_RING> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let board = board::init(cx.device);
        Mono::start(cx.core.SYST, board.sysclk_hz);
        let (bytes_in, bytes_out) = make_channel!(LineItem, RX_QUEUE);
        let (tx_in, tx_out) = cx.local.tx_ring.split();
        let (saves_in, saves_out) = make_channel!((), 1);
        let (edges_in, edges_out) = cx.local.edge_queue.split();
        defmt::info!(
            "boot: transplanter firmware {=str}, sysclk {=u32} Hz, run limit {=?} ms",
            env!("CARGO_PKG_VERSION"),
            board.sysclk_hz,
            board.run_limit_ms
        );

        let (store, machine, boot_notice) =
            load_settings(board.settings_flash, cx.local.machine_slot);
        let hmi = build_hmi(cx.local.hmi_slot, machine);
        let drive = build_drive(cx.local.drive_slot, machine);
        let mut drum = board.drum;
        drum.set_enabled(false);
        // TIM4 by machine: A counts its ground wheel, B steps its feeding
        // motor.
        let (sensors, actuators) = match machine {
            Machine::DrumBelt(_) => (
                board.sensors.with_ground_wheel(board.tim4),
                Actuators::Drum(drum),
            ),
            Machine::SeedlingBelt(_) => (
                board.sensors,
                Actuators::Steppers(board::Steppers::new(drum, board.tim4)),
            ),
        };
        // The boot is the deepest part of a run: checked by the QEMU tests.
        #[cfg(feature = "board-qemu")]
        board::log_stack();
        // Spawning at init cannot fail: each task is spawned once.
        control::spawn().ok();
        status::spawn().ok();
        hmi::spawn().ok();
        settings::spawn().ok();
        if drive.link.is_some() {
            drive_link::spawn().ok();
        }
        (
            Shared {
                machine,
                hmi,
                drive,
                drive_line: board.drive_line,
                hall: board.hall,
                stop: StopCircuit {
                    pin: board.stop_input,
                    latch: StopLatch::new(),
                },
            },
            Local {
                hmi_rx: board.hmi_rx,
                hmi_tx: board.hmi_tx,
                bytes_in,
                bytes_out,
                tx_in,
                tx_out,
                edges_in,
                edges_out,
                drop_mark: DropMark::new(),
                saves_in,
                saves_out,
                sensors,
                work_switch: board.work_switch,
                actuators,
                watchdog: board.watchdog,
                led: board.led,
                store,
                boot_notice,
                run_limit_ms: board.run_limit_ms,
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

    // The tasks' bodies and their priorities, periods and budgets: crate::tasks.
    extern "Rust" {
        #[task(binds = EXTI15_10, priority = 5, shared = [stop])]
        fn stop_input(_: stop_input::Context);

        #[task(binds = USART1, priority = 4, local = [hmi_rx, hmi_tx, bytes_in, tx_out])]
        fn usart1(_: usart1::Context);

        #[task(binds = USART2, priority = 3, shared = [drive_line])]
        fn usart2(_: usart2::Context);

        #[task(priority = 3, shared = [drive, drive_line])]
        async fn drive_link(_: drive_link::Context);

        #[task(binds = TIM2, priority = 3, local = [edges_in, drop_mark], shared = [hall])]
        fn hall_capture(_: hall_capture::Context);

        #[task(priority = 2, local = [sensors, work_switch, actuators, watchdog, edges_out], shared = [machine, hmi, hall, stop, drive])]
        async fn control(_: control::Context);

        #[task(priority = 1, local = [bytes_out, tx_in, saves_in, boot_notice], shared = [machine, hmi, stop])]
        async fn hmi(_: hmi::Context);

        #[task(priority = 1, local = [led, run_limit_ms], shared = [machine, hmi])]
        async fn status(_: status::Context);

        #[task(priority = 1, local = [saves_out, store], shared = [machine, hmi])]
        async fn settings(_: settings::Context);
    }
}

/// Panic: outputs to their safe state first, then a log line, then a
/// HardFault (an attached probe-rs halts there and prints the backtrace).
///
/// The real board logs no panic location or message: the defmt log is only
/// ever read with a probe attached, which prints the backtrace of the `udf`
/// below anyway, and the locations would link every panic site's file path
/// and `core::fmt` into the image. The QEMU board logs the location for the
/// tests.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    board::safe_state();
    // A panic while panicking (the log itself failing, e.g. a panic raised
    // inside a defmt call) goes straight to the end state.
    if PANICKED.swap(true, core::sync::atomic::Ordering::Relaxed) {
        board::fatal();
    }
    #[cfg(feature = "board-qemu")]
    {
        let message = info.message().as_str().unwrap_or("(formatted message)");
        match info.location() {
            Some(l) => defmt::error!(
                "panic at {=str}:{=u32}: {=str}",
                l.file(),
                l.line(),
                message
            ),
            None => defmt::error!("panic: {=str}", message),
        }
    }
    #[cfg(not(feature = "board-qemu"))]
    {
        let _ = info;
        defmt::error!("panic: outputs off (the probe's backtrace shows where)");
    }
    cortex_m::asm::udf()
}

/// Set by the first panic.
static PANICKED: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);

// The fatal exception entries (HardFault, NMI, unused interrupts) are in
// the board layer: `board::fault`.
