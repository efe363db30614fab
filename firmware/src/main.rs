//! Transplanter controller firmware: keeps plant spacing exact whatever the
//! travel speed.
//!
//! An RTIC 2 application. The hardware lives behind [`board`]: the real
//! STM32F103RB (default) or the QEMU board (`netduino2`) with a simulated
//! machine (`--no-default-features --features board-qemu`). The operating
//! logic is the host-tested `supervisor` crate; this file wires it to
//! interrupts, timers and the screen.
//!
//! Task map (higher number = higher priority):
//!
//! | task | priority | release | budget |
//! |---|---|---|---|
//! | [`app::stop_input`] | 5 | each edge of the stop input (PB10, EXTI10) | 1 µs |
//! | [`app::usart1`] | 4 | each touchscreen byte in or out (≤ 11.5 kHz each way) | 2 µs |
//! | [`app::hall_capture`] | 3 | each Hall edge (≤ 1 kHz) and TIM2 overflow | 2 µs |
//! | `app::usart2` | 3 | each RS-485 byte in or out (≤ 11.5 kHz), TC (feature `drive-link`) | 2 µs |
//! | `app::drive_link` | 3 | every 1 ms while a driver profile is set (feature `drive-link`) | 20 µs |
//! | [`app::control`] | 2 | every 10 ms | 1 ms |
//! | [`app::hmi`] | 1 | touchscreen bytes, the transmit ring at half, at least every 20 ms | 1 ms |
//! | [`app::status`] | 1 | every 200 ms (5 Hz) | 2 ms |
//! | [`app::settings`] | 1 | each Save (drum stopped) | 50 ms (a flash page erase) |
//! | `idle` | 0 | — | sleeps in `wfi` |
#![no_std]
#![no_main]

#[cfg(not(any(feature = "profile-a", feature = "profile-b")))]
compile_error!("enable at least one machine: feature `profile-a` or `profile-b`");

mod board;
mod div64;
mod edge_queue;
mod screen_line;
mod stats;

use rtic_monotonics::systick::prelude::*;

systick_monotonic!(Mono, 1_000);

defmt::timestamp!("{=u32:ms}", uptime_ms());

/// Milliseconds since boot (the monotonic runs at 1 kHz; wraps after 49 days).
fn uptime_ms() -> u32 {
    mono_now().duration_since_epoch().as_millis()
}

/// The monotonic's time. Not inlined: reading it takes a critical section
/// and an overflow check, ≈ 34 B of code at each of its calls.
#[inline(never)]
fn mono_now() -> <Mono as rtic_monotonics::Timebase>::Instant {
    Mono::now()
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
/// The ring of bytes from the HMI task to the USART interrupt's transmitter
/// (it holds one less): all the screen link can have queued
/// (`TX_CAPACITY`), so one move of the HMI task empties the link's queue.
const TX_RING: usize = hmi_proto::hmi::TX_CAPACITY + 1;
/// Hall edges queued between the capture interrupt and the control task
/// (the QEMU board's edges come with the sensor sample, not this queue).
const EDGE_QUEUE: usize = 16;

#[rtic::app(device = stm32f1xx_hal::pac, dispatchers = [CAN_RX1, CAN_SCE, ADC1_2])]
mod app {
    use super::{
        board, mono_now, screen_line, stats, uptime_ms, Mono, CONTROL_PERIOD_MS, EDGE_QUEUE,
        HMI_TICK_MS, RX_QUEUE, STATUS_LOG_EVERY, STATUS_PERIOD_MS, TX_RING,
    };
    use crate::edge_queue::DropMark;
    #[cfg(all(feature = "profile-a", feature = "drive-link"))]
    use ::drive_link::link::ControlAction;
    #[cfg(feature = "drive-link")]
    use ::drive_link::link::{Event as LinkEvent, Link, LossCause, SetupFault};
    use core::mem::MaybeUninit;
    use heapless::spsc::{Consumer, Producer, Queue};
    use hmi_proto::hmi::{Event, Hmi};
    use hmi_proto::screen::{Command, MachineProfile};
    #[cfg(feature = "profile-a")]
    use kinematics::units::Ticks;
    use rtic::Mutex as _;
    use rtic_monotonics::systick::prelude::*;
    use rtic_sync::{
        channel::{Receiver, Sender},
        make_channel,
    };
    use screen_line::LineItem;
    #[cfg(feature = "profile-a")]
    use supervisor::control::{Alarm, RunState, Supervisor};
    #[cfg(feature = "profile-a")]
    use supervisor::work_switch::{WorkChange, WorkSwitch};
    use supervisor::{
        control::Effect,
        machine::Machine,
        settings::{Profile, Settings},
        stop_input::{StopChange, StopLatch},
        store::{LoadStatus, SettingsStore},
    };
    #[cfg(feature = "profile-b")]
    use supervisor::{
        machine::BeltMachine,
        profile_b::{PlanterAlarm, PlanterState, ProfileBHardware},
    };

    type Store = SettingsStore<board::SettingsFlash>;

    /// The motor outputs of the profile in force.
    pub enum Actuators {
        /// Profile A: the drum motor's PWM and enable.
        #[cfg(feature = "profile-a")]
        Drum(board::DrumDrive),
        /// Profile B: the two step-pulse outputs.
        #[cfg(feature = "profile-b")]
        Steppers(board::Steppers),
    }

    /// What a control step decided, per profile.
    enum Step {
        #[cfg(feature = "profile-a")]
        Drum(
            supervisor::control::Actuation,
            Option<Alarm>,
            RunState,
            (Option<i32>, bool),
        ),
        #[cfg(feature = "profile-b")]
        Belt(
            supervisor::profile_b::StepperCommand,
            Option<PlanterAlarm>,
            PlanterState,
        ),
    }

    // The large objects live in `static`s owned by `init` and are shared by
    // reference: returning them by value from `init` would need their size
    // twice over on the stack.
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
        /// USART2 and DE (PA1): its interrupt (3) and the link task (3);
        /// `()` without the feature `drive-link`.
        #[cfg_attr(not(feature = "drive-link"), allow(dead_code))]
        drive_line: board::DriveLineRef,
    }

    /// The drum driver's link as the control task and the link task share
    /// it (docs/drive-link.md).
    pub struct DriveState {
        /// The master, when the settings name a driver (profile A).
        #[cfg(feature = "drive-link")]
        link: Option<Link>,
        /// The driver's enable as last asked through its control word.
        #[cfg(feature = "drive-link")]
        #[cfg_attr(not(feature = "profile-a"), allow(dead_code))]
        enabled: Option<bool>,
    }

    /// The stop input's pin and latch.
    pub struct StopCircuit {
        pin: board::StopInput,
        latch: StopLatch,
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
        saves_in: Sender<'static, (), 1>,
        saves_out: Receiver<'static, (), 1>,
        sensors: board::SensorsRef,
        #[cfg_attr(not(feature = "profile-a"), allow(dead_code))]
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
        let actuators = match machine {
            #[cfg(feature = "profile-a")]
            Machine::DrumBelt(_) => Actuators::Drum(drum),
            #[cfg(feature = "profile-b")]
            Machine::SeedlingBelt(_) => {
                Actuators::Steppers(board::Steppers::new(drum, board.feed_step))
            }
        };
        // The boot is the deepest part of a run: checked by the QEMU tests.
        #[cfg(feature = "board-qemu")]
        board::log_stack();
        // Spawning at init cannot fail: each task is spawned once.
        control::spawn().ok();
        status::spawn().ok();
        hmi::spawn().ok();
        settings::spawn().ok();
        #[cfg(feature = "drive-link")]
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
                saves_in,
                saves_out,
                sensors: board.sensors,
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

    // Init helpers, each in its own stack frame: inlined into `init`, their
    // temporaries would all be live at once (3.4 KB of stack).

    /// Settings: the newest valid record, or the defaults, said out loud;
    /// then the machine built from them. Two frames of their own: the
    /// loaded record (≈ 0.3 KB) never sits in `init`'s frame, under which
    /// RTIC runs the first tasks (it enables the interrupts inside it; the
    /// first control step builds the fuzzy controller on top: the deepest
    /// moment of a boot), and the load's deep decode path carries
    /// one record, not two.
    #[inline(never)]
    fn load_settings(
        flash: Option<board::SettingsFlash>,
        slot: &'static mut MaybeUninit<Machine>,
    ) -> (Option<Store>, &'static mut Machine, Option<&'static str>) {
        let mut store = flash.and_then(|flash| SettingsStore::new(flash, 0).ok());
        let mut notice = None;
        // The record returned straight into the call's argument: no copy
        // of it in this frame.
        let (machine, machine_notice) = build_machine(slot, load_record(&mut store, &mut notice));
        (store, machine, machine_notice.or(notice))
    }

    /// The saved settings (the defaults without a valid record or a
    /// store) and the screen's notice, loaded in place into the value
    /// returned: the machine is built from that one record (a second copy
    /// of it, 352 B, sat under the supervisor built on the stack, on the
    /// QEMU board's boot path).
    #[inline(never)]
    fn load_record(store: &mut Option<Store>, notice: &mut Option<&'static str>) -> Settings {
        let mut settings = Settings::default();
        *notice = match store.as_mut().map(|s| s.load_into(&mut settings)) {
            Some(LoadStatus::Saved { sequence }) => {
                defmt::info!("settings: loaded record {=u32}", sequence);
                None
            }
            Some(LoadStatus::Defaults { reason }) => {
                defmt::warn!("settings: defaults in use ({})", reason);
                Some(reason.message())
            }
            None => {
                defmt::warn!("settings: no settings store, defaults in use");
                Some("No settings store: defaults")
            }
        };
        settings
    }

    /// Whether this image carries the machine of `profile` (the real board
    /// takes one image per machine; the QEMU board carries both).
    const fn built_in(profile: Profile) -> bool {
        match profile {
            Profile::DrumBelt => cfg!(feature = "profile-a"),
            Profile::SeedlingBelt => cfg!(feature = "profile-b"),
        }
    }

    /// The screen's message when the operator picks, or the saved settings
    /// name, a machine this image does not carry.
    const NOT_BUILT_IN: &str = if cfg!(feature = "profile-a") {
        "This firmware runs profile A only"
    } else {
        "This firmware runs profile B only"
    };

    // The screen's message when the saved settings name a drum driver on
    // an image without the link.
    #[cfg(not(feature = "drive-link"))]
    const NO_DRIVE_LINK: &str = "Drive link not in this image";

    /// Builds the machine of the saved profile in its static slot; the
    /// notice says why it is not the saved one.
    #[inline(never)]
    fn build_machine(
        slot: &'static mut MaybeUninit<Machine>,
        mut settings: Settings,
    ) -> (&'static mut Machine, Option<&'static str>) {
        let mut notice = None;
        if !built_in(settings.profile) {
            // A saved record from the other machine's image: run this
            // image's machine, stopped, and say so; the record is kept
            // until the operator saves.
            defmt::warn!("settings: saved profile not in this image");
            settings.profile = if cfg!(feature = "profile-a") {
                Profile::DrumBelt
            } else {
                Profile::SeedlingBelt
            };
            notice = Some(NOT_BUILT_IN);
        }
        // Saved link settings on an image without the link (docs/drive-link.md,
        // "Images"): the drum runs on its encoder and the PWM, and the
        // screen says so; the record keeps them until the operator saves.
        #[cfg(not(feature = "drive-link"))]
        if settings.drive_link.kind != supervisor::drive_link::DriverKind::None {
            defmt::warn!("settings: the drive link is not in this image: encoder and PWM");
            settings.drive_link = supervisor::drive_link::DriveLinkSettings::default();
            notice = Some(NO_DRIVE_LINK);
        }
        let profile = settings.profile;
        match build_profile(slot, settings) {
            Ok(machine) => (machine, notice),
            Err(slot) => build_defaults(slot, profile),
        }
    }

    /// The machine with default settings, when the saved ones were
    /// rejected. Only a saved record can be (the store validates what it
    /// loads, so this is a last line of defence); the defaults are valid by
    /// construction, a failure with them is a build-time bug, caught on the
    /// first boot of any board. In its own stack frame: the defaults'
    /// temporaries must not add to `build_machine`'s.
    #[inline(never)]
    #[allow(clippy::field_reassign_with_default)] // see `defaults` below
    fn build_defaults(
        slot: &'static mut MaybeUninit<Machine>,
        profile: Profile,
    ) -> (&'static mut Machine, Option<&'static str>) {
        defmt::error!("machine settings rejected, defaults in use");
        // Built in place, then the profile set: the struct-update
        // expression clippy prefers copied every other field one by one
        // (120 B of flash).
        let mut defaults = Settings::default();
        defaults.profile = profile;
        match build_profile(slot, defaults) {
            Ok(machine) => (machine, Some("Saved settings rejected: defaults")),
            Err(_) => board::fatal(),
        }
    }

    /// Builds the machine of `settings.profile`; gives the slot back when
    /// the settings are rejected.
    fn build_profile(
        slot: &'static mut MaybeUninit<Machine>,
        settings: Settings,
    ) -> Result<&'static mut Machine, &'static mut MaybeUninit<Machine>> {
        #[allow(unreachable_patterns)]
        match settings.profile {
            #[cfg(feature = "profile-a")]
            Profile::DrumBelt => {
                defmt::info!("machine: profile A, drum-belt transplanter");
                build_drum_belt(slot, settings)
            }
            #[cfg(feature = "profile-b")]
            Profile::SeedlingBelt => {
                defmt::info!("machine: profile B, seedling-belt planter");
                build_seedling_belt(slot, settings)
            }
            _ => Err(slot),
        }
    }

    /// Profile A, in its own stack frame (the two profiles' temporaries
    /// must not add up).
    #[cfg(feature = "profile-a")]
    #[inline(never)]
    fn build_drum_belt(
        slot: &'static mut MaybeUninit<Machine>,
        settings: Settings,
    ) -> Result<&'static mut Machine, &'static mut MaybeUninit<Machine>> {
        match Supervisor::new(board::HARDWARE, settings) {
            Ok(sup) => Ok(slot.write(Machine::DrumBelt(sup))),
            Err(_) => Err(slot),
        }
    }

    /// Profile B, in its own stack frame.
    #[cfg(feature = "profile-b")]
    #[inline(never)]
    fn build_seedling_belt(
        slot: &'static mut MaybeUninit<Machine>,
        settings: Settings,
    ) -> Result<&'static mut Machine, &'static mut MaybeUninit<Machine>> {
        match BeltMachine::new(settings, ProfileBHardware::BOARD) {
            Ok(belt) => Ok(slot.write(Machine::SeedlingBelt(belt))),
            Err(_) => Err(slot),
        }
    }

    /// The drum driver's link in its static slot: a Modbus master when the
    /// settings name a driver (profile A only), else none.
    #[cfg(feature = "drive-link")]
    #[inline(never)]
    fn build_drive(
        slot: &'static mut MaybeUninit<DriveState>,
        machine: &Machine,
    ) -> &'static mut DriveState {
        #[allow(unreachable_patterns)]
        let link = match machine {
            #[cfg(feature = "profile-a")]
            Machine::DrumBelt(sup) => sup.settings().drive_link.config().ok().flatten(),
            _ => None,
        };
        // The empty state first, then the link built in its place (built
        // aside and moved in, it was copied field by field: 140 B of flash).
        let state = slot.write(DriveState {
            link: None,
            enabled: None,
        });
        if let Some((p, config)) = link {
            defmt::info!(
                "drive link: slave {=u8} at {=u32} baud, reply timeout {=u32} us, retry gap {=u32} us, driver offline time {=u16} ms",
                p.slave,
                p.baud,
                config.reply_timeout_us,
                config.retry_gap_us,
                config.offline_time_ms
            );
            state.link = Some(Link::new(p, config));
        }
        state
    }

    /// Without the link (feature `drive-link` off): an empty state.
    #[cfg(not(feature = "drive-link"))]
    fn build_drive(
        slot: &'static mut MaybeUninit<DriveState>,
        _machine: &Machine,
    ) -> &'static mut DriveState {
        slot.write(DriveState {})
    }

    /// Builds the screen link in its static slot.
    #[inline(never)]
    fn build_hmi(slot: &'static mut MaybeUninit<Hmi>, machine: &Machine) -> &'static mut Hmi {
        slot.write(Hmi::new(
            machine.screen_settings(),
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

    /// The stop input (a normally closed contact on PB10): outputs off at
    /// once, in the interrupt, then the latch.
    ///
    /// - Priority 5 (highest): nothing delays a stop.
    /// - Released by each edge of the contact (a bouncing contact: a few per
    ///   operation).
    /// - Budget: 1 µs (register writes only); the alarm and the log follow
    ///   in the next control period.
    #[task(binds = EXTI15_10, priority = 5, shared = [stop])]
    fn stop_input(mut cx: stop_input::Context) {
        cx.shared.stop.lock(|stop| {
            stop.pin.clear_interrupt();
            if stop.pin.is_open() {
                board::stop_outputs();
                stop.latch.trip();
            }
        });
    }

    /// The touchscreen's USART1: each byte in goes to the queue of [`hmi`]
    /// with its arrival time; bytes out go from the transmit ring while the
    /// data register is empty (TXE).
    ///
    /// - Priority 4 (highest but the stop input): the F103's USART has no
    ///   FIFO, so a byte must be read within one character time (87 µs at
    ///   115200 baud).
    /// - Released by RXNE and TXE (and pended by [`hmi`] to start sending),
    ///   at most 11.5 k times a second each way.
    /// - Budget: 2 µs.
    #[task(binds = USART1, priority = 4, local = [hmi_rx, hmi_tx, bytes_in, tx_out])]
    fn usart1(cx: usart1::Context) {
        let now = uptime_ms();
        // A few bytes at most are pending; the bound keeps an error storm
        // from holding the CPU.
        for _ in 0..4 {
            match cx.local.hmi_rx.read() {
                Ok(byte) => {
                    stats::HMI_RX_BYTES.inc();
                    if cx
                        .local
                        .bytes_in
                        .try_send(LineItem::new(byte, now))
                        .is_err()
                    {
                        stats::HMI_RX_DROPPED.inc();
                    }
                }
                Err(nb::Error::WouldBlock) => break,
                Err(nb::Error::Other(_)) => stats::HMI_RX_ERRORS.inc(),
            }
        }
        cx.local.hmi_tx.send(cx.local.tx_out);
    }

    /// USART2, the RS-485 line to the drum driver: the next byte out (TXE),
    /// driver-enable low once the last stop bit has left (TC), each byte
    /// in (RXNE) with its time.
    ///
    /// - Priority 3: a byte must be taken within one character (87 µs at
    ///   115 200 baud); DE must drop before the driver answers (≥ 3.5
    ///   characters).
    /// - Released by each byte in or out and by TC: ≤ 11.5 k times a second.
    /// - Budget: 2 µs.
    #[cfg(feature = "drive-link")]
    #[task(binds = USART2, priority = 3, shared = [drive_line])]
    fn usart2(mut cx: usart2::Context) {
        let now = board::now_us64();
        cx.shared.drive_line.lock(|line| line.on_interrupt(now));
    }

    /// The drum driver's Modbus master (`drive_link::link`, sans-IO): hands
    /// it the line's events and sends what it asks, never waiting on the
    /// line (the bytes go out in [`usart2`]).
    ///
    /// - Priority 3 (below the stop input and the screen's bytes, above
    ///   the control task, which it never blocks).
    /// - Period 1 ms while the settings name a driver; not started
    ///   otherwise.
    /// - Budget: 20 µs (a frame's encoding or a reply's parse).
    #[cfg(feature = "drive-link")]
    #[task(priority = 3, shared = [drive, drive_line])]
    async fn drive_link(mut cx: drive_link::Context) {
        let baud = cx
            .shared
            .drive
            .lock(|d| d.link.as_ref().map(|l| l.profile().baud));
        let Some(baud) = baud else {
            return;
        };
        cx.shared.drive_line.lock(|line| line.set_baud(baud));
        loop {
            let now = board::now_us64();
            let event = (&mut cx.shared.drive, &mut cx.shared.drive_line).lock(|d, line| {
                let link = d.link.as_mut()?;
                let mut buf = [0u8; ::drive_link::rtu::MAX_FRAME + 1];
                let mut event = None;
                if let Some(t) = line.sent(now) {
                    link.sent(t);
                }
                if let Some(n) = line.receive(now, &mut buf) {
                    event = link.received(now, buf.get(..n).unwrap_or(&[]));
                }
                if line.receiving(now) {
                    link.line_busy(now);
                }
                event = event.or(link.tick(now));
                if let Some(n) = link.next_frame(now, &mut buf) {
                    line.send(buf.get(..n).unwrap_or(&[]), now);
                }
                if event == Some(LinkEvent::Restored) {
                    // The operator-facing latch is the supervisor's alarm;
                    // the link's own clears so that a next loss reports.
                    link.acknowledge();
                }
                event
            });
            match event {
                Some(LinkEvent::Lost) => {
                    let cause = cx
                        .shared
                        .drive
                        .lock(|d| d.link.as_ref().and_then(Link::loss_cause));
                    log_link_loss(cause);
                }
                Some(LinkEvent::Restored) => defmt::info!("drive link: the driver answers again"),
                Some(LinkEvent::Faults(word)) => {
                    defmt::warn!("drive link: driver fault word {=u16:#06x}", word)
                }
                None => {}
            }
            // Until the next tick of the 1 kHz monotonic: every 1 ms.
            // (`Mono::delay(1 ms)` waits a tick more, "at least" 1 ms: 2 ms
            // here; seen on the twin, tests/tests/twin_drive_link.rs.)
            Mono::delay_until(Mono::now() + 1.millis()).await;
        }
    }

    /// The log line of a lost link: what the last attempt met, so that a
    /// technician knows whether to check the wiring or the profile.
    #[cfg(feature = "drive-link")]
    fn log_link_loss(cause: Option<LossCause>) {
        match cause {
            Some(LossCause::Refused {
                function,
                register,
                code,
            }) => defmt::warn!(
                "drive link: lost: the driver refuses function {=u8} on register {=u16:#06x} (exception {=u8}): check the driver profile",
                function,
                register,
                code
            ),
            Some(LossCause::Unfit { function, register }) => defmt::warn!(
                "drive link: lost: the driver's replies to function {=u8} on register {=u16:#06x} do not fit the request (register width, function): check the driver profile",
                function,
                register
            ),
            Some(LossCause::Corrupt) => defmt::warn!(
                "drive link: lost: corrupt replies after the retries (noise, termination, baud)"
            ),
            Some(LossCause::Setup(SetupFault::MaxSpeed { driver, needed })) => defmt::warn!(
                "drive link: refused: the driver's maximum speed register holds {=u16}; the drum's top speed needs {=u32} through the gearbox: raise it (ZLAC8015D 0x2008, at most 1000 r/min) or use a smaller ratio",
                driver,
                needed
            ),
            Some(LossCause::Setup(SetupFault::Resolution(value))) => defmt::warn!(
                "drive link: refused: the driver's speed resolution register holds {=u16}; set 1 to 10 (ZLAC8015D 0x2022: 1 = 1 r/min, 10 = 0.1 r/min)",
                value
            ),
            _ => defmt::warn!(
                "drive link: lost: no reply after the retries (wiring, power, slave id, baud)"
            ),
        }
    }

    /// The link's sample for a control step (profile A).
    #[cfg(all(feature = "profile-a", feature = "drive-link"))]
    fn link_sample(d: &DriveState, now_us: u64) -> supervisor::drive_link::LinkSample {
        let Some(link) = d.link.as_ref() else {
            return supervisor::drive_link::LinkSample::default();
        };
        supervisor::drive_link::LinkSample {
            speed: link.speed().map(|s| supervisor::drive_link::ReadBack {
                drum_milli_rpm: s.drum_milli_rpm,
                age_us: u32::try_from(now_us.saturating_sub(s.sampled_at_us)).unwrap_or(u32::MAX),
            }),
            lost: link.is_lost(),
            setup: match link.loss_cause() {
                Some(LossCause::Setup(f)) => Some(f.into()),
                _ => None,
            },
            refused: matches!(
                link.loss_cause(),
                Some(LossCause::Refused { .. } | LossCause::Unfit { .. })
            ),
            answering: link.is_answering(),
            fault_word: link.fault_word(),
            fault_reads: link.counters().fault_reads,
        }
    }

    /// The link's clock (µs), for the read-back's age.
    #[cfg(all(feature = "profile-a", feature = "drive-link"))]
    fn link_now() -> u64 {
        board::now_us64()
    }

    /// Without the link: no clock needed.
    #[cfg(all(feature = "profile-a", not(feature = "drive-link")))]
    fn link_now() -> u64 {
        0
    }

    /// Without the link: no sample.
    #[cfg(all(feature = "profile-a", not(feature = "drive-link")))]
    fn link_sample(_: &DriveState, _: u64) -> supervisor::drive_link::LinkSample {
        supervisor::drive_link::LinkSample::default()
    }

    /// Without the link: nothing to tell the driver.
    #[cfg(all(feature = "profile-a", not(feature = "drive-link")))]
    fn link_apply(_: &mut DriveState, _: bool, _: Option<i32>, _: bool) {}

    /// The control step's decisions for the driver: its enable through the
    /// control word (on a change), the bus speed command, a clear request.
    #[cfg(all(feature = "profile-a", feature = "drive-link"))]
    fn link_apply(d: &mut DriveState, enabled: bool, command: Option<i32>, clear: bool) {
        let Some(link) = d.link.as_mut() else {
            return;
        };
        if clear {
            link.control(ControlAction::ClearAlarm);
            d.enabled = None;
        } else if d.enabled != Some(enabled) {
            link.control(if enabled {
                ControlAction::Enable
            } else {
                ControlAction::Disable
            });
            d.enabled = Some(enabled);
        }
        link.set_speed_command(command);
    }

    /// Hall edges: timestamps each tooth of the 25-tooth gear.
    ///
    /// - Priority 3: the capture register latches the edge time in hardware,
    ///   so latency only has to stay below the shortest period (1 ms).
    /// - Released by TIM2 capture (≤ 1 kHz) and overflow (15.3 Hz).
    /// - Budget: 2 µs.
    #[task(binds = TIM2, priority = 3, local = [edges_in, drop_mark: DropMark = DropMark::new()], shared = [hall])]
    fn hall_capture(mut cx: hall_capture::Context) {
        if let Some(edge) = cx.shared.hall.lock(|h| h.on_interrupt()) {
            stats::HALL_EDGES.inc();
            if edge.after_lost {
                stats::HALL_EDGES_LOST.inc();
            }
            // A full queue (the control task late) drops the edge; the next
            // one queued follows a loss (firmware/src/edge_queue.rs).
            let edges_in = &mut cx.local.edges_in;
            if !cx
                .local
                .drop_mark
                .queue(edge, |e| e.after_lost = true, |e| edges_in.enqueue(e))
            {
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
    #[task(priority = 2, local = [sensors, work_switch, actuators, watchdog, edges_out], shared = [machine, hmi, hall, stop, drive])]
    async fn control(mut cx: control::Context) {
        let mut next = mono_now();
        #[cfg(feature = "profile-a")]
        let (mut last_alarm, mut last_run) = (None::<Alarm>, RunState::Stopped);
        // The work switch (PB11), debounced here every period (profile A;
        // docs/firmware.md "Work switch").
        #[cfg(feature = "profile-a")]
        let mut work = WorkSwitch::new();
        #[cfg(feature = "profile-b")]
        let (mut last_belt_alarm, mut last_belt_state) =
            (None::<PlanterAlarm>, PlanterState::Stopped);
        loop {
            let sample = cx.local.sensors.sample(uptime_ms());
            #[cfg(feature = "profile-a")]
            let now = Ticks(cx.shared.hall.lock(|h| h.now()));
            // The stop input: sampled every period (the interrupt has
            // already switched the outputs off on an opening).
            let (stop_change, stop_latched) = cx.shared.stop.lock(|stop| {
                let open = stop.pin.is_open();
                let change = stop.latch.sample(open, CONTROL_PERIOD_MS * 1000);
                (change, stop.latch.is_latched())
            });
            #[cfg(feature = "profile-a")]
            let work_change =
                work.sample(cx.local.work_switch.is_closed(), CONTROL_PERIOD_MS * 1000);
            #[cfg(feature = "profile-a")]
            let work_down = work.is_down();
            // In a block: the step's values are not kept across the await
            // below (the task's future is a static).
            {
                #[cfg(feature = "profile-a")]
                let drive = &mut cx.shared.drive;
                let edges_out = &mut cx.local.edges_out;
                let step = cx.shared.machine.lock(|m| {
                    if stop_latched {
                        // Idempotent: the machine stays stopped while latched.
                        let _ = m.command(hmi_proto::screen::Command::Stop);
                    }
                    match m {
                        #[cfg(feature = "profile-a")]
                        Machine::DrumBelt(sup) => {
                            while let Some(edge) = edges_out.dequeue() {
                                if edge.after_lost {
                                    sup.hall_edges_lost();
                                }
                                sup.hall_edge(Ticks(edge.stamp));
                            }
                            for &edge in &sample.hall_edges {
                                sup.hall_edge(Ticks(edge));
                            }
                            // Idempotent; a change begins or ends a pass.
                            sup.set_work_switch(work_down);
                            sup.set_link_sample(drive.lock(|d| link_sample(d, link_now())));
                            let a = sup.control_step(now, sample.drum_encoder);
                            let bus = (sup.bus_speed_command(), sup.take_driver_clear());
                            Step::Drum(a, sup.alarm(), sup.run_state(), bus)
                        }
                        #[cfg(feature = "profile-b")]
                        Machine::SeedlingBelt(belt) => {
                            // Profile B wiring: TIM3 counts the ground-wheel encoder,
                            // TIM2 captures one index pulse per feeding-roller turn.
                            let mut pulses = sample.hall_edges.len() as u32;
                            while let Some(edge) = edges_out.dequeue() {
                                // A pulse after an overcapture hides at least one more.
                                pulses = pulses.saturating_add(1 + u32::from(edge.after_lost));
                            }
                            let c = belt.control_step(sample.drum_encoder, pulses);
                            let snap = belt.planter().snapshot();
                            Step::Belt(c, snap.alarm, snap.state)
                        }
                    }
                });
                // (Only the QEMU board's edges come this way: on the real board
                // the capture interrupt is the counter's one writer.)
                if !sample.hall_edges.is_empty() {
                    stats::HALL_EDGES.add(sample.hall_edges.len() as u32);
                }

                // The outputs are written under the stop input's lock: an
                // opening between the step and here cannot be overwritten.
                let actuators = &mut *cx.local.actuators;
                cx.shared.stop.lock(|stop| {
                    if stop.latch.is_latched() {
                        board::stop_outputs();
                        return;
                    }
                    #[allow(unreachable_patterns)]
                    match (&step, actuators) {
                        #[cfg(feature = "profile-a")]
                        (Step::Drum(a, ..), Actuators::Drum(drum)) => {
                            drum.set_enabled(a.driver_enabled);
                            drum.set_compare(a.ccr);
                        }
                        #[cfg(feature = "profile-b")]
                        (Step::Belt(c, ..), Actuators::Steppers(steppers)) => {
                            steppers.set(c.feed_step_hz, c.plant_step_hz, c.enabled);
                        }
                        // The outputs were built for the machine: never mixed.
                        _ => board::safe_state(),
                    }
                });
                #[cfg(feature = "profile-a")]
                #[allow(irrefutable_let_patterns)]
                if let Step::Drum(a, _, _, (command, clear)) = &step {
                    let on = a.driver_enabled && !stop_latched;
                    let command = if on { *command } else { None };
                    cx.shared.drive.lock(|d| link_apply(d, on, command, *clear));
                }
                match stop_change {
                    Some(StopChange::Opened) => {
                        defmt::warn!(
                            "stop input: open, outputs off (latched until closed and Start)"
                        );
                        cx.shared.hmi.lock(|hmi| {
                            if hmi.show_alarm(STOP_INPUT_ALARM).is_err() {
                                stats::HMI_TX_DROPPED.inc();
                            }
                        });
                    }
                    Some(StopChange::Closed) => defmt::info!("stop input: closed, Start allowed"),
                    None => {}
                }

                match step {
                    #[cfg(feature = "profile-a")]
                    Step::Drum(actuation, alarm, run, _) => {
                        if alarm != last_alarm {
                            match alarm {
                                Some(a) => {
                                    defmt::warn!("alarm: {}", a);
                                    cx.shared.hmi.lock(|hmi| show_alarm(hmi, a));
                                }
                                None => defmt::info!("alarm cleared"),
                            }
                            last_alarm = alarm;
                        }
                        if let Some(change) = work_change {
                            cx.shared
                                .machine
                                .lock(|m| log_work_change(m, change, last_run));
                        }
                        if run != last_run {
                            defmt::info!("drum: {}", run);
                            if last_run == RunState::Running {
                                // Stop (or an alarm) ends the pass in progress.
                                cx.shared.machine.lock(|m| log_quality(m, "stop"));
                            }
                            last_run = run;
                        }
                        // The simulated machine's own view next to the firmware's,
                        // ten times a second, for the QEMU tests and the main job's
                        // log (the real board has no such truth).
                        #[cfg(feature = "board-qemu")]
                        if stats::CONTROL_LOOPS.get().is_multiple_of(10) {
                            let (v, n, plants, pos, edges) = cx.local.sensors.truth();
                            #[allow(unreachable_patterns)]
                            let target = cx.shared.machine.lock(|m| match m {
                                Machine::DrumBelt(sup) => sup.snapshot().target_drum_rpm_x1000,
                                _ => 0,
                            });
                            defmt::info!(
                            "sim: ground {=u32} um/s, drum {=u32} mr/min, target {=u32} mr/min, ccr {=u16}, plants {=u32}, ground position {=u32} mm, hall edges {=u32}",
                            v,
                            n,
                            target,
                            actuation.ccr,
                            plants,
                            pos,
                            edges
                        );
                        }
                        #[cfg(not(feature = "board-qemu"))]
                        let _ = actuation;
                    }
                    #[cfg(feature = "profile-b")]
                    Step::Belt(command, alarm, state) => {
                        if alarm != last_belt_alarm {
                            if let Some(a) = alarm {
                                defmt::warn!("planter: {}", a);
                                let text = match a {
                                    PlanterAlarm::TooFast => "Too fast for the stepper motors",
                                    PlanterAlarm::OutOfRange => "Travel speed out of range",
                                };
                                cx.shared.hmi.lock(|hmi| {
                                    let _ = hmi.show_message(text);
                                });
                            }
                            last_belt_alarm = alarm;
                        }
                        if state != last_belt_state {
                            defmt::info!("planter: {}", state);
                            last_belt_state = state;
                        }
                        #[cfg(feature = "board-qemu")]
                        if stats::CONTROL_LOOPS.get().is_multiple_of(10) {
                            let (plants, mean_um, cv_x100, pos) = cx.local.sensors.truth_b();
                            defmt::info!(
                            "sim-b: plants {=u32}, mean spacing {=u32} um, cv {=u32} x0.01%, ground position {=u32} mm, feed {=u32} mHz, plant {=u32} mHz",
                            plants,
                            mean_um,
                            cv_x100,
                            pos,
                            command.feed_step_hz.to_milli(),
                            command.plant_step_hz.to_milli()
                        );
                        }
                        #[cfg(not(feature = "board-qemu"))]
                        let _ = command;
                    }
                }
            }
            stats::CONTROL_LOOPS.inc();
            next += CONTROL_PERIOD_MS.millis();
            if mono_now() > next {
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
    ///   link (handshake retries, heartbeats, `get` timeouts).
    /// - Budget: 1 ms (the bytes received, a tick, the events, a page's
    ///   instructions encoded and moved to the transmit ring: `cargo xtask
    ///   bench`'s `hmi_wake`, 26 312 instructions with a second page change);
    ///   it never waits on the line: [`usart1`] sends the bytes.
    #[task(priority = 1, local = [bytes_out, tx_in, saves_in, boot_notice], shared = [machine, hmi, stop])]
    async fn hmi(mut cx: hmi::Context) {
        // Whether the screen has answered, or its silence was logged, since boot.
        let mut link_reported = false;
        loop {
            let first = Mono::timeout_after(HMI_TICK_MS.millis(), cx.local.bytes_out.recv()).await;
            let bytes_out = &mut cx.local.bytes_out;
            cx.shared.hmi.lock(|hmi| {
                let now = uptime_ms();
                // One call site: the link's receive path is inlined once.
                let mut item = first.ok().and_then(Result::ok);
                while let Some(i) = item {
                    screen_line::deliver(hmi, i, now);
                    item = bytes_out.try_recv().ok();
                }
                hmi.tick(now);
            });
            while let Some(event) = cx.shared.hmi.lock(|hmi| hmi.poll_event()) {
                link_reported |= matches!(event, Event::Connected);
                handle_event(&mut cx, event);
            }
            if !link_reported && uptime_ms() >= hmi_proto::hmi::LINK_TIMEOUT_MS {
                defmt::warn!("touchscreen silent since boot: running on the saved settings");
                link_reported = true;
            }
            // The queued instructions to the transmit ring (on the QEMU
            // board, whose interrupt empties it at once, again until the
            // link's queue is empty).
            let tx_in = &mut cx.local.tx_in;
            while cx.shared.hmi.lock(|hmi| screen_line::refill(hmi, tx_in)) > 0 {
                board::kick_screen_tx();
                if !cfg!(feature = "board-qemu") {
                    break;
                }
            }
        }
    }

    #[inline(never)]
    fn handle_event(cx: &mut hmi::Context, event: Event) {
        match event {
            Event::Command(cmd) => {
                defmt::info!("screen: {}", cmd);
                let effect = match cmd {
                    Command::SelectProfile(p) if !built_in(profile_of(p)) => {
                        // Put the screen's selector back as well.
                        refresh_settings(cx);
                        Effect::Message(NOT_BUILT_IN)
                    }
                    // Page 10 is read-only on an image without the link
                    // (either machine).
                    #[cfg(not(feature = "drive-link"))]
                    Command::SetLinkValue(_) => Effect::Message(NO_DRIVE_LINK),
                    _ => {
                        // Start only with the stop input proven closed; it
                        // also releases the stop latch. (One lock site for
                        // every command: each costs flash.)
                        let refused = match cmd {
                            Command::Start => cx.shared.stop.lock(|s| s.latch.start()).err(),
                            _ => None,
                        };
                        match refused {
                            Some(e) => Effect::Message(e.message()),
                            None => cx.shared.machine.lock(|m| m.command(cmd)),
                        }
                    }
                };
                match effect {
                    Effect::None => {}
                    Effect::SettingsChanged => {
                        refresh_settings(cx);
                    }
                    Effect::Save => {
                        if cx.local.saves_in.try_send(()).is_err() {
                            say(cx, "Save already in progress");
                        }
                    }
                    Effect::Message(text) => {
                        defmt::warn!("screen message: {=str}", text);
                        if cmd == Command::AcknowledgeAlarm {
                            // The alarm stays latched (the driver still
                            // silent): the screen has left its page, and
                            // no page leads back, so it comes back with
                            // the reason (page 5 has no message box).
                            cx.shared.hmi.lock(|hmi| {
                                let _ = hmi.show_alarm(text);
                            });
                        } else {
                            // A value the machine refused goes back to the
                            // one in force on the screen (the screen link
                            // took it).
                            refresh_settings(cx);
                            say(cx, text);
                        }
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
                defmt::info!("touchscreen connected");
                refresh_settings(cx);
                // An alarm latched while the screen was away, or before it
                // restarted, goes back on it.
                // (Both read first, then one lock of the screen: each lock
                // site costs flash.)
                #[cfg(feature = "profile-a")]
                let alarm = cx.shared.machine.lock(|m| latched_alarm(m));
                let stop_latched = cx.shared.stop.lock(|s| s.latch.is_latched());
                cx.shared.hmi.lock(|hmi| {
                    #[cfg(feature = "profile-a")]
                    if let Some(alarm) = alarm {
                        show_alarm(hmi, alarm);
                    }
                    if stop_latched {
                        let _ = hmi.show_alarm(STOP_INPUT_ALARM);
                    }
                });
                if let Some(notice) = cx.local.boot_notice.take() {
                    say(cx, notice);
                }
            }
            Event::Disconnected => {
                defmt::warn!("touchscreen silent: running on the last settings");
            }
            Event::ScreenError(code) => defmt::warn!("screen error: {}", code),
            Event::ReplyTimeout(field) => defmt::warn!("screen reply timeout: {}", field),
        }
    }

    /// Shows `text` in the screen's message box (hmi task; one copy of the
    /// lock for the event handler's messages, to keep the image small).
    #[inline(never)]
    fn say(cx: &mut hmi::Context, text: &str) {
        cx.shared.hmi.lock(|hmi| {
            let _ = hmi.show_message(text);
        });
    }

    /// Writes the machine's settings to the screen (hmi task; what changed
    /// since the screen last got them).
    #[inline(never)]
    fn refresh_settings(cx: &mut hmi::Context) {
        let screen = cx.shared.machine.lock(|m| m.screen_settings());
        cx.shared.hmi.lock(|hmi| {
            let _ = hmi.set_settings(screen);
        });
    }

    /// A change of the work switch, and at a lift the figures of the pass
    /// that ended (profile A; `running`: the drum was running).
    #[cfg(feature = "profile-a")]
    fn log_work_change(machine: &Machine, change: WorkChange, running: RunState) {
        #[allow(unreachable_patterns)]
        let sup = match machine {
            Machine::DrumBelt(sup) => sup,
            _ => return,
        };
        let ground_mm = u32::try_from(sup.ground_distance_um() / 1000).unwrap_or(u32::MAX);
        let lifted = change == WorkChange::Lifted;
        defmt::info!(
            "work switch: {=str} at ground {=u32} mm",
            if lifted { "up" } else { "down" },
            ground_mm
        );
        if lifted && running == RunState::Running && sup.settings().work_switch_fitted {
            log_quality(machine, "lift");
        }
    }

    /// The planting quality of the pass that ended (`why`: "lift" or
    /// "stop") and since Start, in the log (profile A; docs/firmware.md,
    /// "Work switch"). Shares and CV in 0.1 %.
    #[cfg(feature = "profile-a")]
    fn log_quality(machine: &Machine, why: &str) {
        #[allow(unreachable_patterns)]
        let sup = match machine {
            Machine::DrumBelt(sup) => sup,
            _ => return,
        };
        for (what, q) in [
            ("pass", sup.quality_of_pass()),
            ("since Start", sup.quality_since_start()),
        ] {
            defmt::info!(
                "quality: {=str} ({=str}): plants {=u32}, spacings {=u32}, distance {=u32} mm, per m {=u32} x0.01, multiples {=u16} misses {=u16} qf {=u16} cv {=u16} within10 {=u16} x0.1%",
                what,
                why,
                q.plants,
                q.spacings,
                q.distance_mm,
                q.plants_per_m_x100,
                q.multiples_x10,
                q.misses_x10,
                q.quality_of_feed_x10,
                q.cv_x10,
                q.within_10_pct_x10
            );
        }
    }

    /// The stop input's alarm text (both machines).
    const STOP_INPUT_ALARM: &str = "Stop input open (stop switch)";

    /// Profile A's alarm on the screen's alarm page.
    #[cfg(feature = "profile-a")]
    fn show_alarm(hmi: &mut Hmi, alarm: Alarm) {
        let mut text: heapless::String<40> = heapless::String::new();
        let _ = alarm.write_text(&mut text);
        if hmi.show_alarm(&text).is_err() {
            stats::HMI_TX_DROPPED.inc();
        }
    }

    /// Profile A's latched alarm, if that is the machine running.
    #[cfg(feature = "profile-a")]
    fn latched_alarm(machine: &Machine) -> Option<Alarm> {
        #[allow(unreachable_patterns)]
        match machine {
            Machine::DrumBelt(sup) => sup.alarm(),
            _ => None,
        }
    }

    /// The settings' profile for the screen's.
    const fn profile_of(p: MachineProfile) -> Profile {
        supervisor::machine::profile_from_screen(p)
    }

    /// Live status on the screen and a 1 Hz summary in the log; ends a QEMU
    /// run at its time limit.
    ///
    /// - Priority 1.
    /// - Period 200 ms (5 Hz).
    /// - Budget: 2 ms.
    #[task(priority = 1, local = [led, run_limit_ms], shared = [machine, hmi])]
    async fn status(mut cx: status::Context) {
        let mut next = mono_now();
        let mut runs: u32 = 0;
        loop {
            let uptime = uptime_ms();
            cx.local.led.set(runs.is_multiple_of(2));
            // The log line and the screen's values from one lock (one lock
            // site less in flash; the line shows the same instant).
            let screen = cx.shared.machine.lock(|m| {
                if runs.is_multiple_of(STATUS_LOG_EVERY) {
                    log_status(m, uptime);
                }
                m.screen_status()
            });
            cx.shared.hmi.lock(|hmi| {
                if hmi.write_status(&screen).is_err() {
                    stats::HMI_TX_DROPPED.inc();
                }
            });
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

    /// The 1 Hz summary line of the log: everything `cargo xtask report`
    /// plots from a field capture (state, spacing setting, travel, drum
    /// target and actual, compare value, plants, distance, alarm) and the
    /// health counters. Under 80 bytes a second on RTT (defmt sends the
    /// arguments, not the text); alarms and state changes have their own
    /// lines when they happen.
    fn log_status(machine: &Machine, uptime: u32) {
        match machine {
            #[cfg(feature = "profile-a")]
            Machine::DrumBelt(sup) => {
                let snapshot = sup.snapshot();
                defmt::info!(
                    "status: uptime {=u32} ms, {} {}, spacing {=u16} mm, travel {=u32} m/h, drum target {=u32} actual {=u32} mr/min, ccr {=u16}, plants {=u32}, distance {=u32} mm, alarm {}, loops {=u32} (overruns {=u32}), hall edges {=u32} (after lost {=u32}), hmi rx {=u32} B",
                    uptime,
                    sup.settings().mode,
                    sup.run_state(),
                    sup.settings().spacing.raw(),
                    snapshot.travel_speed_kmh_x1000,
                    snapshot.target_drum_rpm_x1000,
                    snapshot.actual_drum_rpm_x1000,
                    snapshot.ccr,
                    snapshot.plants,
                    snapshot.distance_mm,
                    sup.alarm(),
                    stats::CONTROL_LOOPS.get(),
                    stats::CONTROL_OVERRUNS.get(),
                    stats::HALL_EDGES.get(),
                    stats::HALL_EDGES_LOST.get(),
                    stats::HMI_RX_BYTES.get()
                );
            }
            #[cfg(feature = "profile-b")]
            Machine::SeedlingBelt(belt) => {
                let s = belt.planter().snapshot();
                defmt::info!(
                    "status: uptime {=u32} ms, profile B {}, travel {=u32} mm/s, n1 {=u32} n2 {=u32} mr/min, j {=u32}, radius {=u32} um, {}, alarm {}, loops {=u32} (overruns {=u32}), hmi rx {=u32} B, roller pulses after lost {=u32}",
                    uptime,
                    s.state,
                    s.travel_speed.to_milli(),
                    s.planting_speed.to_milli(),
                    s.feeding_speed.to_milli(),
                    s.roller_turns,
                    s.roller_radius.to_milli().saturating_mul(1000),
                    s.action,
                    s.alarm,
                    stats::CONTROL_LOOPS.get(),
                    stats::CONTROL_OVERRUNS.get(),
                    stats::HMI_RX_BYTES.get(),
                    stats::HALL_EDGES_LOST.get()
                );
            }
        }
    }

    /// Whether the machine's motors are commanded to run (profile A: the
    /// drum; profile B: the steppers).
    fn motors_commanded(machine: &Machine) -> bool {
        match machine {
            #[cfg(feature = "profile-a")]
            Machine::DrumBelt(sup) => sup.run_state() == RunState::Running,
            #[cfg(feature = "profile-b")]
            Machine::SeedlingBelt(belt) => belt.planter().state() == PlanterState::Running,
        }
    }

    /// Control periods the settings task waits for the drivers' enable to
    /// go low after a Stop before it refuses to save.
    const SAVE_WAIT_PERIODS: u32 = 3;

    /// Persists the settings when the operator saves, only while the motors
    /// are stopped: a flash page erase stalls the CPU, and with it the
    /// control loop, for up to 40 ms.
    ///
    /// The screen's Save was accepted with the motors stopped, but a Start
    /// in the same batch of touches may have run since. So the run state is
    /// checked again here, right before the erase, together with the
    /// drivers' enable pin as the control task last set it (after a Stop it
    /// goes low at the next control period; the task waits up to three).
    /// That check and the erase are one stretch of code with no `await`:
    /// the hmi task, which takes Start, shares priority 1 with this task,
    /// and RTIC 2 runs tasks of one priority to completion between awaits,
    /// so no command can come in between; the tasks above (control at 2,
    /// Hall at 3, USART at 4) never start the motors by themselves. A Save
    /// refused here says so on the screen and in the log and changes
    /// nothing stored.
    ///
    /// - Priority 1.
    /// - Released by each Save.
    /// - Budget: 50 ms (one page erase and ≤ 130 half-word programs), plus
    ///   up to 30 ms of waiting (not CPU time).
    #[task(priority = 1, local = [saves_out, store], shared = [machine, hmi])]
    async fn settings(mut cx: settings::Context) {
        while let Ok(()) = cx.local.saves_out.recv().await {
            let mut waited = 0;
            let text = loop {
                // The check and the save under one lock (one lock site in
                // flash; nothing can start the motors in between).
                let store = &mut *cx.local.store;
                let done = cx.shared.machine.lock(|m| {
                    if motors_commanded(m) {
                        defmt::warn!("settings: save refused, the motors were started after Save");
                        Some("Motors running: settings not saved")
                    } else if !board::drivers_enabled() {
                        // From here to the end of the save: no await.
                        Some(save_settings(store, m))
                    } else {
                        None
                    }
                });
                if let Some(text) = done {
                    break text;
                }
                if waited >= SAVE_WAIT_PERIODS {
                    defmt::warn!("settings: save refused, the motor drivers are still enabled");
                    break "Motors running: settings not saved";
                }
                waited += 1;
                Mono::delay(CONTROL_PERIOD_MS.millis()).await;
            };
            cx.shared.hmi.lock(|hmi| {
                let _ = hmi.show_message(text);
            });
        }
    }

    /// The save itself, in its own stack frame: inlined into the priority-1
    /// tasks' dispatcher, its record buffers (≈ 0.7 KB) sat under every
    /// priority-1 task and under the control task preempting them.
    #[inline(never)]
    fn save_settings(store: &mut Option<Store>, machine: &Machine) -> &'static str {
        match store.as_mut().map(|s| s.save(machine.settings())) {
            Some(Ok(sequence)) => {
                defmt::info!("settings: saved as record {=u32}", sequence);
                "Settings saved"
            }
            Some(Err(e)) => {
                defmt::error!("settings: save failed: {}", e);
                "Save failed: settings not stored"
            }
            None => "No settings store on this board",
        }
    }
}

/// Panic: outputs to their safe state first, then a log line, then a
/// HardFault (an attached probe-rs halts there and prints the backtrace).
///
/// The real board logs no panic location or message: keeping them links
/// every panic site's file path and `core::fmt` into the image (≈ 2.5 KB of
/// the 32 KB flash budget), and the defmt log is only ever read with a probe
/// attached, which prints the backtrace of the `udf` below anyway. The QEMU
/// board, with no flash budget, logs the location for the tests.
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
