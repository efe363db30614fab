//! What the control task tells the operator and the log after each step:
//! the stop input's changes, alarms and state changes when they happen
//! (edge-triggered), the work switch and the planting quality of a pass,
//! and on the QEMU board the simulated machine's own view.

use hmi_proto::hmi::Hmi;
use hmi_proto::screen::TravelSourceInUse;
use rtic::Mutex as _;
use supervisor::drum::{Alarm, RunState};
use supervisor::machine::Machine;
use supervisor::machine_step::StepOutputs;
use supervisor::planter::{PlanterAlarm, PlanterState};
use supervisor::stop_input::StopChange;
use supervisor::work_switch::WorkChange;

use crate::app::control;
use crate::stats;

/// The stop input's alarm text (both machines).
pub const STOP_INPUT_ALARM: &str = "Stop input open (stop switch)";

/// What the notices last reported, to report changes only.
pub struct Notices {
    alarm: Option<Alarm>,
    run: RunState,
    belt_alarm: Option<PlanterAlarm>,
    belt_state: PlanterState,
    travel_source: TravelSourceInUse,
    track_slip_x10: Option<i16>,
}

impl Default for Notices {
    fn default() -> Self {
        Self {
            alarm: None,
            run: RunState::Stopped,
            belt_alarm: None,
            belt_state: PlanterState::Stopped,
            travel_source: TravelSourceInUse::HallGear,
            track_slip_x10: None,
        }
    }
}

impl Notices {
    /// Reports this period's changes.
    pub fn report(
        &mut self,
        cx: &mut control::Context<'_>,
        outputs: &StepOutputs,
        stop_change: Option<StopChange>,
        work_change: Option<WorkChange>,
    ) {
        match stop_change {
            Some(StopChange::Opened) => {
                defmt::warn!("stop input: open, outputs off (latched until closed and Start)");
                cx.shared.hmi.lock(|hmi| {
                    if hmi.show_alarm(STOP_INPUT_ALARM).is_err() {
                        stats::HMI_TX_DROPPED.inc();
                    }
                });
            }
            Some(StopChange::Closed) => defmt::info!("stop input: closed, Start allowed"),
            None => {}
        }
        match *outputs {
            StepOutputs::Drum { alarm, run, .. } => {
                if alarm != self.alarm {
                    match alarm {
                        Some(a) => {
                            defmt::warn!("alarm: {}", a);
                            cx.shared.hmi.lock(|hmi| show_alarm(hmi, a));
                        }
                        None => defmt::info!("alarm cleared"),
                    }
                    self.alarm = alarm;
                }
                if let Some(change) = work_change {
                    let running = self.run;
                    cx.shared
                        .machine
                        .lock(|m| log_work_change(m, change, running));
                }
                let (source, slip) = cx.shared.machine.lock(|m| match m {
                    Machine::DrumBelt(sup) => {
                        let s = sup.snapshot();
                        (s.travel_source, s.track_slip_x10)
                    }
                    Machine::SeedlingBelt(_) => (TravelSourceInUse::HallGear, None),
                });
                self.report_ground(source, slip);
                if run != self.run {
                    defmt::info!("drum: {}", run);
                    if self.run == RunState::Running {
                        // Stop (or an alarm) ends the pass in progress.
                        cx.shared.machine.lock(|m| log_quality(m, "stop"));
                    }
                    self.run = run;
                }
            }
            StepOutputs::Belt { alarm, state, .. } => {
                if alarm != self.belt_alarm {
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
                    self.belt_alarm = alarm;
                }
                if state != self.belt_state {
                    defmt::info!("planter: {}", state);
                    self.belt_state = state;
                }
            }
        }
        #[cfg(feature = "board-qemu")]
        log_truth(cx, outputs);
    }

    /// Machine A's travel source in use and the track's live slip, when
    /// they change (`supervisor::ground`): `travel source: GroundWheel`
    /// (`HallGear`, `HallStandIn`: the Hall gear standing in for a wheel
    /// that does not turn), and each new slip the ground wheel measures
    /// against the Hall gear, `track slip: N x0.1%`.
    fn report_ground(&mut self, source: TravelSourceInUse, slip: Option<i16>) {
        if source != self.travel_source {
            defmt::info!("travel source: {}", source);
            self.travel_source = source;
        }
        if slip != self.track_slip_x10 {
            if let Some(s) = slip {
                defmt::info!("track slip: {=i16} x0.1%", s);
            }
            self.track_slip_x10 = slip;
        }
    }
}

/// The simulated machine's own view next to the firmware's, ten times a
/// second, for the QEMU tests and the main job's log (the real board has no
/// such truth).
#[cfg(feature = "board-qemu")]
fn log_truth(cx: &mut control::Context<'_>, outputs: &StepOutputs) {
    if !stats::CONTROL_LOOPS.get().is_multiple_of(10) {
        return;
    }
    match outputs {
        StepOutputs::Drum { actuation, .. } => {
            let (v, n, plants, pos, edges) = cx.local.sensors.truth();
            let target = cx.shared.machine.lock(|m| match m {
                Machine::DrumBelt(sup) => sup.snapshot().target_drum_rpm_x1000,
                Machine::SeedlingBelt(_) => 0,
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
        StepOutputs::Belt { command, .. } => {
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
    }
}

/// A change of the work switch, and at a lift the figures of the pass
/// that ended (profile A; `running`: the drum was running).
fn log_work_change(machine: &Machine, change: WorkChange, running: RunState) {
    let Machine::DrumBelt(sup) = machine else {
        return;
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
fn log_quality(machine: &Machine, why: &str) {
    let Machine::DrumBelt(sup) = machine else {
        return;
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

/// Profile A's alarm on the screen's alarm page.
pub fn show_alarm(hmi: &mut Hmi, alarm: Alarm) {
    let mut text: heapless::String<40> = heapless::String::new();
    let _ = alarm.write_text(&mut text);
    if hmi.show_alarm(&text).is_err() {
        stats::HMI_TX_DROPPED.inc();
    }
}

/// Profile A's latched alarm, if that is the machine running.
pub fn latched_alarm(machine: &Machine) -> Option<Alarm> {
    match machine {
        Machine::DrumBelt(sup) => sup.alarm(),
        Machine::SeedlingBelt(_) => None,
    }
}
