//! The drum driver's RS-485 link (docs/drive-link.md): USART2's interrupt,
//! the Modbus master's task (started only when the settings name a driver)
//! and what they share with the control task.

use ::drive_link::link::{ControlAction, Event as LinkEvent, Link, LossCause, SetupFault};
use rtic::mutex::prelude::*;
use rtic_monotonics::systick::prelude::*;

use crate::app::{drive_link, usart2};
use crate::{board, Mono};

/// The drum driver's link as the control task and the link task share it.
pub struct DriveState {
    /// The master, when the settings name a driver (profile A).
    pub link: Option<Link>,
    /// The driver's enable as last asked through its control word.
    pub enabled: Option<bool>,
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
pub fn usart2(mut cx: usart2::Context<'_>) {
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
pub async fn drive_link(mut cx: drive_link::Context<'_>) {
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

/// The link's sample for a control step (the default without a driver).
pub fn link_sample(d: &DriveState, now_us: u64) -> supervisor::drive_link::LinkSample {
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

/// The control step's decisions for the driver: its enable through the
/// control word (on a change), the bus speed command, a clear request.
pub fn link_apply(d: &mut DriveState, enabled: bool, command: Option<i32>, clear: bool) {
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
