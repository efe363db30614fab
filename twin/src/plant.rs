//! The machine (`machine-sim`) wired to the twin's pins and timers, as on
//! the real board (README pin map):
//!
//! - profile A: TIM1 CH1 duty on PA8 and the enable PB12 drive the drum
//!   motor; the drum encoder counts in TIM3 (encoder mode); Hall edges are
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

use crate::periph::{addr, Bus, Level, Ticks, NEVER, TICKS_PER_S};

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
    next_step: Ticks,
    edges: VecDeque<Ticks>,
    last_count: u16,
    count_pending: Option<u16>,
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
        Self {
            machine,
            wiring,
            encoder_swapped: false,
            next_step: now,
            edges: VecDeque::new(),
            last_count,
            count_pending: None,
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
                self.apply_count(c, bus);
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
            self.next_step = ts + STEP_TICKS;
        }
    }

    fn apply_count(&mut self, count: u16, bus: &mut Bus) {
        let delta = count.wrapping_sub(self.last_count) as i16;
        self.last_count = count;
        // TIM3 counts only with its clock on (RM0008 §7.3.8) and out of reset.
        if !bus.clock_enabled(addr::TIM3) || bus.held_in_reset(addr::TIM3) {
            return;
        }
        let tim3 = &mut bus.tim[2];
        let mode = tim3.encoder_mode();
        if mode == 0 || tim3.cr1 & 1 == 0 {
            return;
        }
        // Encoder mode 3 counts every edge of both channels (×4); modes 1
        // and 2 count the edges of one channel (×2). CC1P/CC2P invert an
        // input, and an odd number of inversions (or swapped wires) runs
        // the count backwards (RM0008 §15.3.12).
        let mut d = i32::from(delta);
        if mode != 3 {
            d /= 2;
        }
        let inv = (tim3.ccer & 2 != 0) ^ (tim3.ccer & 0x20 != 0) ^ self.encoder_swapped;
        if inv {
            d = -d;
        }
        let period = i32::from(tim3.arr_act) + 1;
        let c = (i32::from(tim3.cnt) + d).rem_euclid(period);
        tim3.cnt = c as u16;
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
