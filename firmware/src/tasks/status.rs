//! The status task: live values on the screen, the 1 Hz summary line.

use rtic::Mutex as _;
use rtic_monotonics::systick::prelude::*;
use supervisor::machine::Machine;

use crate::app::status;
use crate::{board, stats, uptime_ms, Mono};

/// Status period (5 Hz).
const STATUS_PERIOD_MS: u32 = 200;
/// The status task logs every this many runs (1 Hz).
const STATUS_LOG_EVERY: u32 = 5;

/// Live status on the screen and a 1 Hz summary in the log; ends a QEMU
/// run at its time limit.
///
/// - Priority 1.
/// - Period 200 ms (5 Hz).
/// - Budget: 2 ms.
pub async fn status(mut cx: status::Context<'_>) {
    let mut next = Mono::now();
    let mut runs: u32 = 0;
    loop {
        let uptime = uptime_ms();
        cx.local.led.set(runs.is_multiple_of(2));
        // The log line and the screen's values from one lock: the line
        // shows the same instant.
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
