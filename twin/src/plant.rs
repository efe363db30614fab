//! The machine (`machine-sim`) wired to the twin's pins and timers, as on
//! the real board (README pin map):
//!
//! - profile A: TIM1 CH1 duty on PA8 and the enable PB12 drive the drum
//!   motor; the drum encoder counts in TIM3 (encoder mode, PA6/PA7); the
//!   ground wheel's encoder in TIM4 (encoder mode, PB6/PB7); Hall edges are
//!   falling edges on PA0 captured by TIM2 CH1 (after the IC1F filter delay);
//! - profile B: the step pulses on PA8 (TIM1 CH1, planting motor) and PB6
//!   (TIM4 CH1, feeding motor), counted pulse by pulse, drive the steppers
//!   while PB12 enables them; the ground-wheel encoder counts in TIM3; one
//!   index pulse per feeding-roller turn falls on PA0.
//!
//! The model steps every millisecond with the outputs as they are at the
//! start of the step; the edges it produces are delivered at their own
//! times.

use std::collections::VecDeque;

use machine_sim::{Inputs, Machine};

use crate::periph::{Bus, EncoderWiring, Level, Ticks, NEVER, TICKS_PER_S};

/// Model step, µs.
pub const STEP_US: u32 = 1000;
const STEP_TICKS: Ticks = STEP_US as u64 * TICKS_PER_S / 1_000_000;

/// Which machine is on the pins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wiring {
    /// Drum-belt transplanter.
    ProfileA,
    /// Seedling-belt planter.
    ProfileB,
}

/// The machine and its wiring.
pub struct Plant {
    /// The model (tests change its travel, inject faults).
    pub machine: Machine,
    /// The wiring.
    pub wiring: Wiring,
    /// Encoder A/B swapped on the machine (the count runs backwards).
    pub encoder_swapped: bool,
    /// Profile A's ground-wheel encoder A/B swapped.
    pub wheel_swapped: bool,
    next_step: Ticks,
    edges: VecDeque<Ticks>,
    last_count: u16,
    count_pending: Option<u16>,
    last_wheel: u16,
    wheel_pending: Option<u16>,
    /// Ground-wheel counts the board's TIM4 took (profile A), signed.
    pub wheel_counted: i64,
    pulses: (u64, u64),
    roller_turns: u32,
    /// Step pulses delivered to the steppers: (planting, feeding).
    pub steps_delivered: (u64, u64),
    /// Hall edges delivered to PA0.
    pub edges_delivered: u64,
    /// The inputs of the last step (what the machine saw).
    pub last_inputs: Inputs,
}

impl Plant {
    /// Wires `machine` to the board from twin time `now` on.
    pub fn new(machine: Machine, wiring: Wiring, now: Ticks) -> Self {
        let last_count = match wiring {
            Wiring::ProfileA => machine.drum_encoder_count(),
            Wiring::ProfileB => machine.ground_encoder_count(),
        };
        let roller_turns = machine.feed_roller_turns();
        let last_wheel = machine.ground_encoder_count();
        Self {
            machine,
            wiring,
            encoder_swapped: false,
            wheel_swapped: false,
            next_step: now,
            edges: VecDeque::new(),
            last_count,
            count_pending: None,
            last_wheel,
            wheel_pending: None,
            wheel_counted: 0,
            pulses: (0, 0),
            roller_turns,
            steps_delivered: (0, 0),
            edges_delivered: 0,
            last_inputs: Inputs::default(),
        }
    }

    /// The MCU was reset (the machine runs on; the pulse counters restart).
    pub fn mcu_reset(&mut self) {
        self.pulses = (0, 0);
    }

    /// The next time the plant needs the twin.
    pub fn next_event(&self) -> Ticks {
        self.next_step
            .min(self.edges.front().copied().unwrap_or(NEVER))
    }

    /// Brings the machine to `now`: due edges delivered, the model stepped.
    pub fn service(&mut self, now: Ticks, bus: &mut Bus) {
        while let Some(&t) = self.edges.front() {
            if t > now {
                break;
            }
            self.edges.pop_front();
            bus.hall_edge(t.max(bus_now(bus, t)));
            self.edges_delivered += 1;
        }
        while self.next_step <= now {
            let ts = self.next_step;
            bus.advance(ts);
            if let Some(c) = self.count_pending.take() {
                let delta = c.wrapping_sub(self.last_count) as i16;
                self.last_count = c;
                bus.encoder_input(
                    EncoderWiring::TIM3_PA6_PA7,
                    i32::from(delta),
                    self.encoder_swapped,
                    STEP_TICKS,
                );
            }
            if let Some(c) = self.wheel_pending.take() {
                let delta = c.wrapping_sub(self.last_wheel) as i16;
                self.last_wheel = c;
                self.wheel_counted += i64::from(bus.encoder_input(
                    EncoderWiring::TIM4_PB6_PB7,
                    i32::from(delta),
                    self.wheel_swapped,
                    STEP_TICKS,
                ));
            }
            let inputs = self.inputs(bus);
            self.last_inputs = inputs;
            let c0 = self.machine.capture_ticks();
            let filter = {
                let t2 = &bus.tim[1];
                t2.ic1_filter_clocks() * TICKS_PER_S / bus.clocks().tim_apb1.max(1)
            };
            let mut new_edges = Vec::new();
            self.machine.step(STEP_US, &inputs, &mut |t| {
                let off = u64::from(t.wrapping_sub(c0));
                new_edges.push(ts + off * (TICKS_PER_S / 1_000_000) + filter);
            });
            if self.wiring == Wiring::ProfileA {
                self.edges.extend(new_edges);
            } else {
                let turns = self.machine.feed_roller_turns();
                while self.roller_turns != turns {
                    self.roller_turns = self.roller_turns.wrapping_add(1);
                    self.edges.push_back(ts + STEP_TICKS + filter);
                }
            }
            let count = match self.wiring {
                Wiring::ProfileA => self.machine.drum_encoder_count(),
                Wiring::ProfileB => self.machine.ground_encoder_count(),
            };
            self.count_pending = Some(count);
            if self.wiring == Wiring::ProfileA {
                self.wheel_pending = Some(self.machine.ground_encoder_count());
            }
            self.next_step = ts + STEP_TICKS;
        }
    }

    fn inputs(&mut self, bus: &Bus) -> Inputs {
        let enabled = bus.pin_level(1, 12) == Level::High;
        match self.wiring {
            Wiring::ProfileA => {
                let duty = if bus.pin_level(0, 8) == Level::HiZ {
                    0.0
                } else {
                    bus.tim[0].ch1_duty().unwrap_or(0.0)
                };
                Inputs {
                    drum_duty: duty as f32,
                    driver_enabled: enabled,
                    ..Inputs::default()
                }
            }
            Wiring::ProfileB => {
                let plant = bus.tim[0].oc1_pulses;
                let feed = bus.tim[3].oc1_pulses;
                let driven =
                    |port, pin| matches!(bus.pin_level(port, pin), Level::High | Level::Low);
                let dp = if driven(0, 8) {
                    plant.saturating_sub(self.pulses.0)
                } else {
                    0
                };
                let df = if driven(1, 6) {
                    feed.saturating_sub(self.pulses.1)
                } else {
                    0
                };
                self.pulses = (plant, feed);
                let (dp, df) = if enabled { (dp, df) } else { (0, 0) };
                self.steps_delivered.0 += dp;
                self.steps_delivered.1 += df;
                let hz = |n: u64| n as f32 * 1e6 / STEP_US as f32;
                Inputs {
                    drum_duty: 0.0,
                    driver_enabled: enabled,
                    feed_step_rate_hz: hz(df),
                    plant_step_rate_hz: hz(dp),
                }
            }
        }
    }
}

fn bus_now(_bus: &Bus, t: Ticks) -> Ticks {
    t
}
