//! The touchscreen's task: the screen link (`hmi_proto::hmi`) fed with the
//! bytes the USART1 interrupt received, its events applied to the machine,
//! its instructions moved to the transmit ring.

use hmi_proto::hmi::Event;
use hmi_proto::screen::Command;
use rtic::Mutex as _;
use rtic_monotonics::systick::prelude::*;
use supervisor::drum::Effect;

use super::notices::{latched_alarm, show_alarm, STOP_INPUT_ALARM};
use crate::app::hmi;
use crate::{board, screen_line, uptime_ms, Mono};

/// The hmi task ticks the screen link at least this often.
const HMI_TICK_MS: u32 = 20;

/// The touchscreen: bytes in, events to the supervisor, instructions out.
///
/// - Priority 1.
/// - Released by received bytes, and at least every 20 ms to time the
///   link (handshake retries, heartbeats, `get` timeouts).
/// - Budget: 1 ms (the bytes received, a tick, the events, a page's
///   instructions encoded and moved to the transmit ring: `cargo xtask
///   bench`'s `hmi_wake`, 26 312 instructions with a second page change);
///   it never waits on the line: the USART1 interrupt sends the bytes.
pub async fn hmi(mut cx: hmi::Context<'_>) {
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

/// One event of the screen link.
fn handle_event(cx: &mut hmi::Context<'_>, event: Event) {
    match event {
        Event::Command(cmd) => {
            defmt::info!("screen: {}", cmd);
            // Start only with the stop input proven closed; it also
            // releases the stop latch.
            let refused = match cmd {
                Command::Start => cx.shared.stop.lock(|s| s.latch.start()).err(),
                _ => None,
            };
            let effect = match refused {
                Some(e) => Effect::Message(e.message()),
                None => cx.shared.machine.lock(|m| m.command(cmd)),
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
            let alarm = cx.shared.machine.lock(|m| latched_alarm(m));
            let stop_latched = cx.shared.stop.lock(|s| s.latch.is_latched());
            cx.shared.hmi.lock(|hmi| {
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

/// Shows `text` in the screen's message box (hmi task).
fn say(cx: &mut hmi::Context<'_>, text: &str) {
    cx.shared.hmi.lock(|hmi| {
        let _ = hmi.show_message(text);
    });
}

/// Writes the machine's settings to the screen (hmi task; what changed
/// since the screen last got them).
fn refresh_settings(cx: &mut hmi::Context<'_>) {
    let screen = cx.shared.machine.lock(|m| m.screen_settings());
    cx.shared.hmi.lock(|hmi| {
        let _ = hmi.set_settings(screen);
    });
}
