//! Transplanter controller firmware: keeps plant spacing exact whatever the
//! travel speed.
//!
//! An RTIC 2 application. The hardware lives behind [`board`]: the real
//! STM32F103RB (default) or the QEMU `stm32vldiscovery` board with a simulated
//! machine (`--no-default-features --features board-qemu`). The operating
//! logic is the host-tested `supervisor` crate; this file wires it to
//! interrupts, timers and the screen.
//!
//! Task map (higher number = higher priority):
//!
//! | task | priority | release | budget |
//! |---|---|---|---|
//! | [`app::usart1_rx`] | 4 | each touchscreen byte (≤ 11.5 kHz) | 2 µs |
//! | [`app::hall_capture`] | 3 | each Hall edge (≤ 1 kHz) and TIM2 overflow | 2 µs |
//! | [`app::control`] | 2 | every 10 ms | 1 ms |
//! | [`app::hmi`] | 1 | each touchscreen byte, at least every 20 ms | 3 ms |
//! | [`app::status`] | 1 | every 200 ms (5 Hz) | 2 ms |
//! | [`app::settings`] | 1 | each Save (drum stopped) | 50 ms (a flash page erase) |
//! | `idle` | 0 | — | sleeps in `wfi` |
#![no_std]
#![no_main]

mod board;
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
/// The HMI task ticks the screen link at least this often.
const HMI_TICK_MS: u32 = 20;
/// Bytes queued between the USART interrupt and the HMI task.
const RX_QUEUE: usize = 64;
/// Hall edges queued between the capture interrupt and the control task.
const EDGE_QUEUE: usize = 16;

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [CAN_RX1, CAN_SCE, ADC1_2])]
mod app {
    use super::{
        board, stats, uptime_ms, Mono, CONTROL_PERIOD_MS, EDGE_QUEUE, HMI_TICK_MS, RX_QUEUE,
        STATUS_LOG_EVERY, STATUS_PERIOD_MS,
    };
    use core::mem::MaybeUninit;
    use heapless::spsc::{Consumer, Producer, Queue};
    use hmi_proto::hmi::{Event, Hmi};
    use kinematics::units::Ticks;
    use rtic::Mutex as _;
    use rtic_monotonics::systick::prelude::*;
    use rtic_sync::{
        channel::{Receiver, Sender},
        make_channel,
    };
    use supervisor::{
        control::{Alarm, Effect, RunState, Supervisor},
        settings::Settings,
        store::{Loaded, SettingsStore},
    };

    type Store = SettingsStore<board::SettingsFlash>;

    // The large objects live in `static`s owned by `init` and are shared by
    // reference: returning them by value from `init` would need their size
    // twice over on the QEMU board's 8 KB of RAM.
    #[shared]
    struct Shared {
        /// The operating logic: control (2), hmi (1), status (1).
        supervisor: &'static mut Supervisor,
        /// The screen link: control (2, alarms), hmi (1), status (1), settings (1).
        hmi: &'static mut Hmi,
        /// TIM2: its interrupt (3) and the control task's clock (2).
        hall: board::HallCapture,
    }

    #[local]
    struct Local {
        hmi_rx: board::HmiRx,
        hmi_tx: board::HmiTx,
        bytes_in: Sender<'static, u8, RX_QUEUE>,
        bytes_out: Receiver<'static, u8, RX_QUEUE>,
        edges_in: Producer<'static, u32>,
        edges_out: Consumer<'static, u32>,
        saves_in: Sender<'static, Settings, 1>,
        saves_out: Receiver<'static, Settings, 1>,
        sensors: board::Sensors,
        drum: board::DrumDrive,
        watchdog: board::Watchdog,
        led: board::StatusLed,
        store: Option<Store>,
        boot_notice: Option<&'static str>,
        run_limit_ms: Option<u32>,
    }

    #[init(local = [
        edge_queue: Queue<u32, EDGE_QUEUE> = Queue::new(),
        supervisor_slot: MaybeUninit<Supervisor> = MaybeUninit::uninit(),
        hmi_slot: MaybeUninit<Hmi> = MaybeUninit::uninit(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let board = board::init(cx.device);
        Mono::start(cx.core.SYST, board.sysclk_hz);
        let (bytes_in, bytes_out) = make_channel!(u8, RX_QUEUE);
        let (saves_in, saves_out) = make_channel!(Settings, 1);
        let (edges_in, edges_out) = cx.local.edge_queue.split();
        defmt::info!(
            "boot: transplanter firmware {=str}, sysclk {=u32} Hz, run limit {=?} ms",
            env!("CARGO_PKG_VERSION"),
            board.sysclk_hz,
            board.run_limit_ms
        );

        let (store, settings, boot_notice) = load_settings(board.settings_flash);
        let supervisor = build_supervisor(cx.local.supervisor_slot, settings);
        let hmi = build_hmi(cx.local.hmi_slot, supervisor);
        let mut drum = board.drum;
        drum.set_enabled(false);
        // Spawning at init cannot fail: each task is spawned once.
        control::spawn().ok();
        status::spawn().ok();
        hmi::spawn().ok();
        settings::spawn().ok();
        (
            Shared {
                supervisor,
                hmi,
                hall: board.hall,
            },
            Local {
                hmi_rx: board.hmi_rx,
                hmi_tx: board.hmi_tx,
                bytes_in,
                bytes_out,
                edges_in,
                edges_out,
                saves_in,
                saves_out,
                sensors: board.sensors,
                drum,
                watchdog: board.watchdog,
                led: board.led,
                store,
                boot_notice,
                run_limit_ms: board.run_limit_ms,
            },
        )
    }

    // Init helpers, each in its own stack frame: inlined into `init`, their
    // temporaries would all be live at once (3.4 KB of stack on a board with
    // 8 KB of RAM).

    /// Settings: the newest valid record, or the defaults, said out loud.
    #[inline(never)]
    fn load_settings(
        flash: Option<board::SettingsFlash>,
    ) -> (Option<Store>, Settings, Option<&'static str>) {
        let mut store = flash.and_then(|flash| SettingsStore::new(flash, 0).ok());
        let (settings, notice) = match store.as_mut().map(|s| s.load()) {
            Some(Loaded::Saved { settings, sequence }) => {
                defmt::info!("settings: loaded record {=u32}", sequence);
                (settings, None)
            }
            Some(Loaded::Defaults { settings, reason }) => {
                defmt::warn!("settings: defaults in use ({})", reason);
                (settings, Some(reason.message()))
            }
            None => {
                defmt::warn!("settings: no settings store, defaults in use");
                (Settings::default(), Some("No settings store: defaults"))
            }
        };
        (store, settings, notice)
    }

    /// Builds the supervisor in its static slot.
    #[inline(never)]
    fn build_supervisor(
        slot: &'static mut MaybeUninit<Supervisor>,
        settings: Settings,
    ) -> &'static mut Supervisor {
        let settings = match Supervisor::check(board::HARDWARE, &settings) {
            Ok(()) => settings,
            Err(e) => {
                defmt::error!("settings rejected ({}), defaults in use", e);
                Settings::default()
            }
        };
        match Supervisor::new(board::HARDWARE, settings) {
            Ok(s) => slot.write(s),
            Err(e) => {
                // The defaults are valid by construction: a build-time bug,
                // caught on the first boot of any board.
                defmt::error!("default settings rejected: {}", e);
                board::fatal()
            }
        }
    }

    /// Builds the screen link in its static slot.
    #[inline(never)]
    fn build_hmi(slot: &'static mut MaybeUninit<Hmi>, supervisor: &Supervisor) -> &'static mut Hmi {
        slot.write(Hmi::new(
            supervisor.screen_settings(),
            env!("CARGO_PKG_VERSION"),
        ))
    }

    /// Sleeps between interrupts.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// Touchscreen bytes: drains USART1 into the queue of [`hmi`].
    ///
    /// - Priority 4 (highest): the F103's USART has no FIFO, so a byte must
    ///   be read within one character time (87 µs at 115200 baud).
    /// - Released by USART1 RXNE, at most 11.5 k times a second.
    /// - Budget: 2 µs per byte.
    #[task(binds = USART1, priority = 4, local = [hmi_rx, bytes_in])]
    fn usart1_rx(cx: usart1_rx::Context) {
        // A few bytes at most are pending; the bound keeps an error storm
        // from holding the CPU.
        for _ in 0..4 {
            match cx.local.hmi_rx.read() {
                Ok(byte) => {
                    stats::HMI_RX_BYTES.inc();
                    if cx.local.bytes_in.try_send(byte).is_err() {
                        stats::HMI_RX_DROPPED.inc();
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
    #[task(binds = TIM2, priority = 3, local = [edges_in], shared = [hall])]
    fn hall_capture(mut cx: hall_capture::Context) {
        if let Some(edge) = cx.shared.hall.lock(|h| h.on_interrupt()) {
            stats::HALL_EDGES.inc();
            if cx.local.edges_in.enqueue(edge).is_err() {
                stats::HALL_EDGES_DROPPED.inc();
            }
        }
    }

    /// The drum speed control loop: sensors → supervisor (kinematic target,
    /// fuzzy PID, fault checks) → PWM.
    ///
    /// - Priority 2: preempted only by the byte and edge interrupts.
    /// - Period 10 ms, released on an absolute schedule (no drift); a run that
    ///   ends after its next release is counted as an overrun and does not
    ///   feed the watchdog.
    /// - Budget: 1 ms (measured cost: docs/PERFORMANCE.md).
    #[task(priority = 2, local = [sensors, drum, watchdog, edges_out], shared = [supervisor, hmi, hall])]
    async fn control(mut cx: control::Context) {
        let mut next = Mono::now();
        let mut last_alarm: Option<Alarm> = None;
        let mut last_run = RunState::Stopped;
        loop {
            let sample = cx.local.sensors.sample(uptime_ms());
            let now = Ticks(cx.shared.hall.lock(|h| h.now()));
            let edges_out = &mut cx.local.edges_out;
            let (actuation, alarm, run) = cx.shared.supervisor.lock(|sup| {
                while let Some(edge) = edges_out.dequeue() {
                    sup.hall_edge(Ticks(edge));
                }
                for &edge in &sample.hall_edges {
                    sup.hall_edge(Ticks(edge));
                }
                let a = sup.control_step(now, sample.drum_encoder);
                (a, sup.alarm(), sup.run_state())
            });
            cx.local.drum.set_enabled(actuation.driver_enabled);
            cx.local.drum.set_compare(actuation.ccr);
            stats::HALL_EDGES.add(sample.hall_edges.len() as u32);

            if alarm != last_alarm {
                match alarm {
                    Some(a) => {
                        defmt::warn!("alarm: {}", a);
                        let mut text: heapless::String<40> = heapless::String::new();
                        let _ = a.write_text(&mut text);
                        cx.shared.hmi.lock(|hmi| {
                            if hmi.show_alarm(&text).is_err() {
                                stats::HMI_TX_DROPPED.inc();
                            }
                        });
                    }
                    None => defmt::info!("alarm cleared"),
                }
                last_alarm = alarm;
            }
            if run != last_run {
                defmt::info!("drum: {}", run);
                last_run = run;
            }

            // The simulated machine's own view next to the firmware's, ten
            // times a second, for the QEMU tests and the main job's log (the
            // real board has no such truth, and logs only its 1 Hz summary).
            #[cfg(feature = "board-qemu")]
            if stats::CONTROL_LOOPS.get().is_multiple_of(10) {
                let (v, n, plants, pos) = cx.local.sensors.truth();
                let target = cx
                    .shared
                    .supervisor
                    .lock(|sup| sup.snapshot().target_drum_rpm_x1000);
                defmt::info!(
                    "sim: ground {=u32} mm/s, drum {=u32} mr/min, target {=u32} mr/min, ccr {=u16}, plants {=u32}, ground position {=u32} mm",
                    v,
                    n,
                    target,
                    actuation.ccr,
                    plants,
                    pos
                );
            }

            stats::CONTROL_LOOPS.inc();
            next += CONTROL_PERIOD_MS.millis();
            if Mono::now() > next {
                stats::CONTROL_OVERRUNS.inc();
            } else {
                cx.local.watchdog.feed();
            }
            Mono::delay_until(next).await;
        }
    }

    /// The touchscreen: bytes in, events to the supervisor, instructions out.
    ///
    /// - Priority 1.
    /// - Released by received bytes, and at least every 20 ms to time the
    ///   link (handshake retries, `get` timeouts).
    /// - Budget: 3 ms, most of it writing instructions at 115200 baud.
    #[task(priority = 1, local = [bytes_out, hmi_tx, saves_in, boot_notice], shared = [supervisor, hmi])]
    async fn hmi(mut cx: hmi::Context) {
        let mut connected = false;
        loop {
            let first = Mono::timeout_after(HMI_TICK_MS.millis(), cx.local.bytes_out.recv()).await;
            let bytes_out = &mut cx.local.bytes_out;
            cx.shared.hmi.lock(|hmi| {
                if let Ok(Ok(byte)) = first {
                    hmi.push(byte);
                    while let Ok(byte) = bytes_out.try_recv() {
                        hmi.push(byte);
                    }
                }
                hmi.tick(uptime_ms());
            });
            while let Some(event) = cx.shared.hmi.lock(|hmi| hmi.poll_event()) {
                handle_event(&mut cx, event);
            }
            let now_connected = cx.shared.hmi.lock(|hmi| hmi.is_connected());
            if now_connected != connected {
                if now_connected {
                    defmt::info!("touchscreen connected");
                    if let Some(notice) = cx.local.boot_notice.take() {
                        cx.shared.hmi.lock(|hmi| {
                            let _ = hmi.show_message(notice);
                        });
                    }
                } else {
                    defmt::warn!("touchscreen silent: running on the last settings");
                }
                connected = now_connected;
            }
            // Drain the transmit queue (blocking writes at priority 1).
            let mut buf = [0u8; 32];
            loop {
                let n = cx.shared.hmi.lock(|hmi| hmi.poll_transmit(&mut buf));
                if n == 0 {
                    break;
                }
                for &b in buf.get(..n).unwrap_or(&[]) {
                    let _ = nb::block!(cx.local.hmi_tx.write_u8(b));
                }
            }
        }
    }

    #[inline(never)]
    fn handle_event(cx: &mut hmi::Context, event: Event) {
        match event {
            Event::Command(cmd) => {
                defmt::info!("screen: {}", cmd);
                let effect = cx.shared.supervisor.lock(|sup| sup.command(cmd));
                match effect {
                    Effect::None => {}
                    Effect::SettingsChanged => {
                        let screen = cx.shared.supervisor.lock(|sup| sup.screen_settings());
                        cx.shared.hmi.lock(|hmi| {
                            let _ = hmi.set_settings(screen);
                        });
                    }
                    Effect::Save => {
                        let settings = cx.shared.supervisor.lock(|sup| sup.settings().clone());
                        if cx.local.saves_in.try_send(settings).is_err() {
                            cx.shared.hmi.lock(|hmi| {
                                let _ = hmi.show_message("Save already in progress");
                            });
                        }
                    }
                    Effect::Message(text) => {
                        defmt::warn!("screen message: {=str}", text);
                        cx.shared.hmi.lock(|hmi| {
                            let _ = hmi.show_message(text);
                        });
                    }
                    Effect::AlarmCleared => {
                        defmt::info!("alarm acknowledged");
                    }
                }
            }
            Event::Rejected(e) => {
                defmt::warn!(
                    "screen value rejected: {=str} (got {=i32})",
                    e.message(),
                    e.value
                );
            }
            Event::Connected => {
                let screen = cx.shared.supervisor.lock(|sup| sup.screen_settings());
                cx.shared.hmi.lock(|hmi| {
                    let _ = hmi.set_settings(screen);
                });
            }
            Event::ScreenError(code) => defmt::warn!("screen error: {}", code),
            Event::ReplyTimeout(field) => defmt::warn!("screen reply timeout: {}", field),
        }
    }

    /// Live status on the screen and a 1 Hz summary in the log; ends a QEMU
    /// run at its time limit.
    ///
    /// - Priority 1.
    /// - Period 200 ms (5 Hz).
    /// - Budget: 2 ms.
    #[task(priority = 1, local = [led, run_limit_ms], shared = [supervisor, hmi])]
    async fn status(mut cx: status::Context) {
        let mut next = Mono::now();
        let mut runs: u32 = 0;
        loop {
            let uptime = uptime_ms();
            cx.local.led.set(runs.is_multiple_of(2));
            let (snapshot, screen, alarm, run, mode) = cx.shared.supervisor.lock(|sup| {
                (
                    sup.snapshot(),
                    sup.screen_status(),
                    sup.alarm(),
                    sup.run_state(),
                    sup.settings().mode,
                )
            });
            cx.shared.hmi.lock(|hmi| {
                if hmi.write_status(&screen).is_err() {
                    stats::HMI_TX_DROPPED.inc();
                }
            });
            if runs.is_multiple_of(STATUS_LOG_EVERY) {
                defmt::info!(
                    "status: uptime {=u32} ms, {} {}, travel {=u32} m/h, drum target {=u32} actual {=u32} mr/min, ccr {=u16}, plants {=u32}, distance {=u32} mm, alarm {}, loops {=u32} (overruns {=u32}), hall edges {=u32}, hmi rx {=u32} B",
                    uptime,
                    mode,
                    run,
                    snapshot.travel_speed_kmh_x1000,
                    snapshot.target_drum_rpm_x1000,
                    snapshot.actual_drum_rpm_x1000,
                    snapshot.ccr,
                    snapshot.plants,
                    snapshot.distance_mm,
                    alarm,
                    stats::CONTROL_LOOPS.get(),
                    stats::CONTROL_OVERRUNS.get(),
                    stats::HALL_EDGES.get(),
                    stats::HMI_RX_BYTES.get()
                );
            }
            if let Some(limit) = *cx.local.run_limit_ms {
                if uptime >= limit {
                    defmt::info!("run limit of {=u32} ms reached, exiting", limit);
                    board::exit_success();
                }
            }
            runs = runs.wrapping_add(1);
            next += STATUS_PERIOD_MS.millis();
            Mono::delay_until(next).await;
        }
    }

    /// Persists the settings when the operator saves (the drum is stopped:
    /// a flash page erase stalls the CPU for up to 40 ms).
    ///
    /// - Priority 1.
    /// - Released by each Save.
    /// - Budget: 50 ms (one page erase and ≤ 130 half-word programs).
    #[task(priority = 1, local = [saves_out, store], shared = [hmi])]
    async fn settings(mut cx: settings::Context) {
        while let Ok(settings) = cx.local.saves_out.recv().await {
            let text = match cx.local.store.as_mut().map(|s| s.save(&settings)) {
                Some(Ok(sequence)) => {
                    defmt::info!("settings: saved as record {=u32}", sequence);
                    "Settings saved"
                }
                Some(Err(e)) => {
                    defmt::error!("settings: save failed: {}", e);
                    "Save failed: settings not stored"
                }
                None => "No settings store on this board",
            };
            cx.shared.hmi.lock(|hmi| {
                let _ = hmi.show_message(text);
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
    // No `core::fmt` here (it costs ~3 KB of flash): the static message if
    // there is one, and the location.
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
