//! One control period of whichever machine runs, as one call:
//! [`Machine::step`] takes what the sensors read ([`StepInputs`] and the
//! period's pulse edges) and returns what the actuators and the notices need
//! ([`StepOutputs`]).

use hmi_proto::screen::Command;
use kinematics::units::Ticks;

use crate::drive_link::LinkSample;
use crate::drum::{Actuation, Alarm, RunState};
use crate::machine::Machine;
use crate::planter::{PlanterAlarm, PlanterState, StepperCommand};

/// One edge of the pulse input (TIM2 CH1): profile A's Hall tooth, profile
/// B's feeding-roller index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PulseEdge {
    /// Its capture time (TIM2 ticks).
    pub stamp: u32,
    /// At least one edge before it was lost (an overcapture or a full
    /// queue).
    pub after_lost: bool,
}

/// What the sensors read for one control period.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepInputs {
    /// TIM2's clock now (profile A's time base).
    pub now: u32,
    /// The drum encoder's counter (profile A) or the ground wheel's
    /// (profile B): TIM3.
    pub encoder: u16,
    /// The stop input is latched: the machine stays stopped.
    pub stop_latched: bool,
    /// The work switch, debounced: the planting unit is down (profile A).
    pub work_down: bool,
    /// The drum driver's link (profile A; the default without a driver).
    pub link: LinkSample,
    /// Profile A: the ground wheel's encoder counter (TIM4, wraps at 2¹⁶),
    /// `None` where the board does not read it.
    pub ground_wheel: Option<u16>,
}

/// What one control period decided, per machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepOutputs {
    /// Profile A.
    Drum {
        /// The drum motor's PWM and enable.
        actuation: Actuation,
        /// The latched alarm.
        alarm: Option<Alarm>,
        /// The run state.
        run: RunState,
        /// The drum driver's speed command over the link, if it takes it.
        bus_command: Option<i32>,
        /// The operator's acknowledgement asks the driver to clear its
        /// alarm.
        clear_driver: bool,
    },
    /// Profile B.
    Belt {
        /// The two step-pulse rates and the drivers' enable.
        command: StepperCommand,
        /// The planter's alarm.
        alarm: Option<PlanterAlarm>,
        /// The planter's state.
        state: PlanterState,
    },
}

impl Machine {
    /// One control period: the edges and `inputs` in, the decisions out.
    pub fn step(
        &mut self,
        inputs: &StepInputs,
        edges: impl IntoIterator<Item = PulseEdge>,
    ) -> StepOutputs {
        if inputs.stop_latched {
            // Idempotent: the machine stays stopped while latched.
            let _ = self.command(Command::Stop);
        }
        match self {
            Self::DrumBelt(sup) => {
                for edge in edges {
                    if edge.after_lost {
                        sup.hall_edges_lost();
                    }
                    sup.hall_edge(Ticks(edge.stamp));
                }
                // Idempotent; a change begins or ends a pass.
                sup.set_work_switch(inputs.work_down);
                sup.set_link_sample(inputs.link);
                if let Some(count) = inputs.ground_wheel {
                    sup.ground_wheel_count(count);
                }
                let actuation = sup.control_step(Ticks(inputs.now), inputs.encoder);
                StepOutputs::Drum {
                    actuation,
                    alarm: sup.alarm(),
                    run: sup.run_state(),
                    bus_command: sup.bus_speed_command(),
                    clear_driver: sup.take_driver_clear(),
                }
            }
            Self::SeedlingBelt(belt) => {
                // One index pulse per feeding-roller turn; a pulse after an
                // overcapture hides at least one more.
                let pulses = edges.into_iter().fold(0u32, |n, e| {
                    n.saturating_add(1).saturating_add(u32::from(e.after_lost))
                });
                let command = belt.control_step(inputs.encoder, pulses);
                let snapshot = belt.planter().snapshot();
                StepOutputs::Belt {
                    command,
                    alarm: snapshot.alarm,
                    state: snapshot.state,
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::belt::BeltMachine;
    use crate::drum::{Hardware, Supervisor};
    use crate::planter::ProfileBHardware;
    use crate::settings::{Profile, Settings};

    /// The step of profile A is the supervisor's own sequence (edges, work
    /// switch, link sample, control step), and a latched stop stops it.
    #[test]
    fn profile_a_steps_as_the_supervisor_and_a_latched_stop_stops_it() {
        let settings = Settings {
            mode: hmi_proto::screen::Mode::Fixed,
            ..Settings::default()
        };
        let mut m = Machine::DrumBelt(Supervisor::new(Hardware::BOARD, settings.clone()).unwrap());
        let mut direct = Supervisor::new(Hardware::BOARD, settings).unwrap();
        let _ = m.command(Command::Start);
        let _ = direct.command(Command::Start);
        let mut encoder: u16 = 0;
        for period in 0..20u32 {
            let inputs = StepInputs {
                now: period * 10_000,
                encoder,
                work_down: true,
                ..StepInputs::default()
            };
            let edge = PulseEdge {
                stamp: period * 10_000 + 5,
                after_lost: false,
            };
            let out = m.step(&inputs, [edge]);
            direct.hall_edge(Ticks(edge.stamp));
            direct.set_work_switch(true);
            direct.set_link_sample(LinkSample::default());
            let a = direct.control_step(Ticks(inputs.now), encoder);
            match out {
                StepOutputs::Drum { actuation, run, .. } => {
                    assert_eq!(actuation, a);
                    assert_eq!(run, direct.run_state());
                }
                StepOutputs::Belt { .. } => panic!("profile A stepped as B"),
            }
            encoder = encoder.wrapping_add(157);
        }
        let stopped = StepInputs {
            stop_latched: true,
            ..StepInputs::default()
        };
        match m.step(&stopped, []) {
            StepOutputs::Drum { run, .. } => assert_eq!(run, RunState::Stopped),
            StepOutputs::Belt { .. } => panic!("profile A stepped as B"),
        }
    }

    /// Profile B counts one roller turn per edge, two after a loss.
    #[test]
    fn profile_b_counts_an_edge_after_a_loss_twice() {
        let settings = Settings {
            profile: Profile::SeedlingBelt,
            ..Settings::default()
        };
        let count = |edges: &[PulseEdge]| {
            let mut m = Machine::SeedlingBelt(
                BeltMachine::new(settings.clone(), ProfileBHardware::BOARD).unwrap(),
            );
            let mut direct = BeltMachine::new(settings.clone(), ProfileBHardware::BOARD).unwrap();
            let out = m.step(&StepInputs::default(), edges.iter().copied());
            let pulses = edges.iter().map(|e| 1 + u32::from(e.after_lost)).sum();
            let c = direct.control_step(0, pulses);
            (out, c)
        };
        for edges in [
            &[][..],
            &[PulseEdge {
                stamp: 1,
                after_lost: true,
            }][..],
        ] {
            let (out, c) = count(edges);
            match out {
                StepOutputs::Belt { command, .. } => assert_eq!(command, c),
                StepOutputs::Drum { .. } => panic!("profile B stepped as A"),
            }
        }
    }
}
