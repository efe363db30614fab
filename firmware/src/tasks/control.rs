//! The control task: every 10 ms, the sensors, one step of the machine, the
//! actuators, the notices.

use rtic::Mutex as _;
use rtic_monotonics::systick::prelude::*;
use supervisor::machine_step::{PulseEdge, StepInputs, StepOutputs};
use supervisor::stop_input::StopChange;
use supervisor::work_switch::{WorkChange, WorkSwitch};

use super::drive_link::{link_apply, link_sample};
use super::notices::Notices;
use crate::app::control;
use crate::{board, stats, uptime_ms, Mono};

/// Control period.
pub const CONTROL_PERIOD_MS: u32 = 10;

/// The motor outputs of the machine in force.
pub enum Actuators {
    /// Profile A: the drum motor's PWM and enable.
    Drum(board::DrumDrive),
    /// Profile B: the two step-pulse outputs.
    Steppers(board::Steppers),
}

/// What the sensors read for one period.
pub struct Sensed {
    /// The machine's inputs.
    pub inputs: StepInputs,
    /// The board's sample (the QEMU board's edges and truth come with it).
    pub sample: board::SensorSample,
    /// The stop input opened or closed this period.
    pub stop_change: Option<StopChange>,
    /// The work switch went down or up this period.
    pub work_change: Option<WorkChange>,
}

/// The control loop: sensors → one `step` of the machine
/// (`supervisor::machine_step`) → actuators → notices.
///
/// - Priority 2: preempted only by the byte and edge interrupts.
/// - Period 10 ms, released on an absolute schedule (no drift); a run that
///   ends after its next release is counted as an overrun and does not
///   feed the watchdog.
/// - Budget: 1 ms (measured cost: docs/PERFORMANCE.md).
pub async fn control(mut cx: control::Context<'_>) {
    let mut next = Mono::now();
    // The work switch (PB11), debounced here every period (docs/firmware.md
    // "Work switch").
    let mut work = WorkSwitch::new();
    let mut notices = Notices::default();
    loop {
        // In a block: the period's values are not kept across the await
        // below (the task's future is a static).
        {
            let sensed = read_sensors(&mut cx, &mut work);
            let edges_out = &mut cx.local.edges_out;
            let outputs = cx.shared.machine.lock(|m| {
                let queued = core::iter::from_fn(|| edges_out.dequeue()).map(|e| PulseEdge {
                    stamp: e.stamp,
                    after_lost: e.after_lost,
                });
                let sampled = sensed.sample.hall_edges.iter().map(|&stamp| PulseEdge {
                    stamp,
                    after_lost: false,
                });
                m.step(&sensed.inputs, queued.chain(sampled))
            });
            write_actuators(&mut cx, &outputs, sensed.inputs.stop_latched);
            notices.report(&mut cx, &outputs, sensed.stop_change, sensed.work_change);
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

/// The period's inputs: the board's sample, TIM2's clock, the stop input
/// (sampled every period; its interrupt has already switched the outputs
/// off on an opening), the work switch, the drive link's sample.
fn read_sensors(cx: &mut control::Context<'_>, work: &mut WorkSwitch) -> Sensed {
    let sample = cx.local.sensors.sample(uptime_ms());
    // (Only the QEMU board's edges come this way: on the real board the
    // capture interrupt is the counter's one writer.)
    if !sample.hall_edges.is_empty() {
        stats::HALL_EDGES.add(sample.hall_edges.len() as u32);
    }
    let now = cx.shared.hall.lock(|h| h.now());
    let (stop_change, stop_latched) = cx.shared.stop.lock(|stop| {
        let open = stop.pin.is_open();
        let change = stop.latch.sample(open, CONTROL_PERIOD_MS * 1000);
        (change, stop.latch.is_latched())
    });
    let work_change = work.sample(cx.local.work_switch.is_closed(), CONTROL_PERIOD_MS * 1000);
    let link = cx.shared.drive.lock(|d| link_sample(d, board::now_us64()));
    Sensed {
        inputs: StepInputs {
            now,
            encoder: sample.drum_encoder,
            stop_latched,
            work_down: work.is_down(),
            link,
            ground_wheel: sample.ground_wheel,
        },
        sample,
        stop_change,
        work_change,
    }
}

/// The motor outputs, written under the stop input's lock (an opening
/// between the step and here cannot be overwritten), then the drum
/// driver's enable and command over the link.
fn write_actuators(cx: &mut control::Context<'_>, outputs: &StepOutputs, stop_latched: bool) {
    let actuators = &mut *cx.local.actuators;
    cx.shared.stop.lock(|stop| {
        if stop.latch.is_latched() {
            board::stop_outputs();
            return;
        }
        match (outputs, actuators) {
            (StepOutputs::Drum { actuation, .. }, Actuators::Drum(drum)) => {
                drum.set_enabled(actuation.driver_enabled);
                drum.set_compare(actuation.ccr);
            }
            (StepOutputs::Belt { command, .. }, Actuators::Steppers(steppers)) => {
                steppers.set(command.feed_step_hz, command.plant_step_hz, command.enabled);
            }
            // The outputs were built for the machine: never mixed.
            _ => board::safe_state(),
        }
    });
    if let StepOutputs::Drum {
        actuation,
        bus_command,
        clear_driver,
        ..
    } = *outputs
    {
        let on = actuation.driver_enabled && !stop_latched;
        let command = if on { bus_command } else { None };
        cx.shared
            .drive
            .lock(|d| link_apply(d, on, command, clear_driver));
    }
}
