//! The simulated machine (`machine_sim`) behind the sensor interface,
//! stepped by the control task every period under the outputs' stand-ins.

use core::sync::atomic::Ordering::Relaxed;

use machine_sim::{Event, Fault, Inputs, Machine};
use stm32f1xx_hal::pac;

use crate::board::SensorSample;

use super::clocks::now_us;
use super::drive_sim::{read_drive, write_truth, DriveSim, DRIVE_BUS_COMMAND, DRIVE_ENABLED};
use super::drum_pwm::{DRIVER_ENABLE, DRUM_CCR, DRUM_PERIOD};
use super::gate::GATE_BYTES;
use super::hall_capture::HALL_TIMER_NOW;
use super::outputs::{STOP_OPENED_US, STOP_SAFE_US};
use super::pins::{STOP_INPUT_OPEN, WORK_SWITCH_CLOSED};
use super::scenario::{Scenario, WORK_CLOSED, WORK_GROUND, WORK_VALUE};
use super::sh;
use super::steppers::{FEED_STEP_BITS, PLANT_STEP_BITS};

/// The simulated machine, read like the real board's sensors.
pub struct Sensors {
    pub(super) machine: &'static mut Machine,
    pub(super) scenario: Scenario,
    pub(super) now_ms: u32,
    /// Feeding-roller turns already reported as index pulses (profile B).
    pub(super) roller_turns_seen: u32,
    /// Profile B: when the steppers came to rest after the tractor stopped.
    pub(super) stop_watch: StopWatch,
    /// The scenario's work switch changes done (bit i: entry i).
    pub(super) work_fired: u8,
    /// Machine A reads its ground wheel (the real board's TIM4).
    pub(super) ground_wheel: bool,
    /// The lock-step gate: a host FIFO read once per control period.
    pub(super) gate: Option<usize>,
    /// Screen bytes from the gate, to [`HmiRx`](super::HmiRx).
    pub(super) gate_in: heapless::spsc::Producer<'static, u8>,
    /// The host's virtual drum driver (`drive_link=1`), in a static.
    pub(super) drive: Option<&'static mut DriveSim>,
}

/// Profile B's stop check, on the simulator's side: after the scenario's
/// `stop`, the sample time of the last ground-encoder count and the first
/// sample that finds both step rates at zero, logged once as
/// `sim-b: steppers at rest at T ms, last ground count at C ms`.
#[derive(Default)]
pub(super) struct StopWatch {
    last_ground_count: u16,
    last_count_ms: u32,
    reported: bool,
}

fn due(at: Option<u32>, from: u32, to: u32) -> bool {
    at.is_some_and(|t| t > from && t <= to)
}

impl Sensors {
    /// Machine A: the simulated machine's ground-wheel counter stands in
    /// for TIM4's from now on.
    pub fn with_ground_wheel(&'static mut self, _tim4: super::Tim4Pins) -> &'static mut Self {
        self.ground_wheel = true;
        self
    }

    /// Advances the machine to `now_ms` under the current PWM output and
    /// reads the encoder and the Hall edges that happened meanwhile.
    ///
    /// Lock-step (`gate=PATH`, under QEMU's `-icount`): first reads the
    /// next message from the host FIFO — a count `n` (≤ 32) and `n` bytes
    /// the screen sent during the period — blocking the whole emulation
    /// until the test allows one more control period, so that firmware time
    /// never runs ahead of the virtual touchscreen and a busy host cannot
    /// make a period late. The screen's bytes then reach the USART1
    /// interrupt task (pended here) as if the emulated USART had received
    /// them. At end of file (the test closed its end) the board runs free.
    pub fn sample(&mut self, now_ms: u32) -> SensorSample {
        if let (Some(_), Some(d)) = (self.gate, self.drive.as_deref_mut()) {
            write_truth(d, self.machine.drum_speed_rpm());
        }
        if let Some(h) = self.gate {
            let mut count = [0u8; 1];
            let mut bytes = [0u8; GATE_BYTES];
            let ok = sh::read(h, &mut count)
                && {
                    let n = usize::from(count[0]).min(GATE_BYTES);
                    bytes
                        .get_mut(..n)
                        .is_some_and(|b| b.is_empty() || sh::read(h, b))
                }
                && self.drive.as_deref_mut().is_none_or(|d| read_drive(h, d));
            if ok {
                let n = usize::from(count[0]).min(GATE_BYTES);
                for &b in bytes.get(..n).unwrap_or(&[]) {
                    let _ = self.gate_in.enqueue(b);
                }
                if n > 0 {
                    pac::NVIC::pend(pac::Interrupt::USART1);
                }
            } else {
                self.gate = None;
            }
        }
        let mut edges = heapless::Vec::new();
        let (from, to) = (self.now_ms, now_ms);
        let s = self.scenario;
        for (at, pct) in s.step.iter().flatten() {
            if due(Some(*at), from, to) {
                self.machine.inject_speed_step(*pct as f32 / 100.0);
                defmt::info!("sim: travel speed step {=i32} %", pct);
            }
        }
        if due(s.metrics_from, from, to) {
            self.machine.reset_metrics();
            defmt::info!("sim: field metrics restarted");
        }
        if due(s.stop, from, to) {
            self.machine.stop_travel();
            defmt::info!("sim: tractor stops");
        }
        if due(s.stop_input, from, to) {
            // The contact opens now: the pin goes high and its interrupt is
            // pended (EXTI15_10, priority 5, runs before this returns).
            STOP_INPUT_OPEN.store(true, Relaxed);
            STOP_OPENED_US.store(now_us(), Relaxed);
            pac::NVIC::pend(pac::Interrupt::EXTI15_10);
            defmt::warn!(
                "sim: stop input opened at {=u32} us, outputs safe at {=u32} us",
                STOP_OPENED_US.load(Relaxed),
                STOP_SAFE_US.load(Relaxed)
            );
        }
        if due(s.stop_input_close, from, to) {
            STOP_INPUT_OPEN.store(false, Relaxed);
            pac::NVIC::pend(pac::Interrupt::EXTI15_10);
            defmt::info!("sim: stop input closed");
        }
        let ground_mm = (self.machine.ground_position_m() * 1000.0) as u32;
        for (i, &w) in s.work.iter().enumerate() {
            let bit = 1u8 << i;
            let value = w & WORK_VALUE;
            let now = if w & WORK_GROUND != 0 {
                ground_mm >= value
            } else {
                value <= to
            };
            if w != 0 && now && self.work_fired & bit == 0 {
                self.work_fired |= bit;
                let closed = w & WORK_CLOSED != 0;
                WORK_SWITCH_CLOSED.store(closed, Relaxed);
                defmt::info!(
                    "sim: work switch {=str} at ground {=u32} mm",
                    if closed { "closed (down)" } else { "open (up)" },
                    ground_mm
                );
            }
        }
        if due(s.stack_overflow, from, to) {
            defmt::warn!("sim: stack overflow injected");
            exhaust_stack(0);
        }
        if due(s.stall, from, to) {
            self.machine.inject_fault(Fault::DrumStall);
            defmt::warn!("sim: drum stall injected");
        }
        if due(s.hall_loss, from, to) {
            self.machine.inject_fault(Fault::HallLoss);
            defmt::warn!("sim: Hall signal loss injected");
        }
        if due(s.enc_loss, from, to) {
            self.machine.inject_fault(Fault::EncoderLoss);
            defmt::warn!("sim: encoder loss injected");
        }
        if due(s.wheel_loss, from, to) {
            self.machine.inject_fault(Fault::GroundEncoderLoss);
            defmt::warn!("sim: ground wheel stops turning");
        }
        if due(s.wheel_back, from, to) {
            self.machine.clear_fault(Fault::GroundEncoderLoss);
            defmt::info!("sim: ground wheel turns again");
        }
        let hz = |bits: u32| bits as f32 / 65_536.0;
        let steppers_on = DRIVER_ENABLE.load(Relaxed);
        let mut drum_duty = f32::from(DRUM_CCR.load(Relaxed)) / f32::from(DRUM_PERIOD);
        let mut drum_on = steppers_on;
        if let Some(d) = self.drive.as_deref() {
            // The virtual driver's motor: enabled by PB12 and its control
            // word; on its bus command (its own speed loop, modelled as the
            // command over the drive's n_max) or the PWM duty.
            drum_on = drum_on && d.flags & DRIVE_ENABLED != 0;
            if d.flags & DRIVE_BUS_COMMAND != 0 {
                let n_max = self.machine.config().n_max_rpm;
                drum_duty = (d.command_milli_rpm as f32 / 1000.0 / n_max).clamp(0.0, 1.0);
            }
        }
        let inputs = Inputs {
            drum_duty,
            driver_enabled: drum_on,
            feed_step_rate_hz: if steppers_on {
                hz(FEED_STEP_BITS.load(Relaxed))
            } else {
                0.0
            },
            plant_step_rate_hz: if steppers_on {
                hz(PLANT_STEP_BITS.load(Relaxed))
            } else {
                0.0
            },
        };
        let dt_us = to.saturating_sub(from).saturating_mul(1000);
        // Plants dropped in this sample: one per 50 mm belt partition, so
        // at most one per 10 ms sample at any reachable belt speed.
        let mut plants: heapless::Vec<f64, 4> = heapless::Vec::new();
        self.machine.step_events(dt_us, &inputs, &mut |e| match e {
            Event::HallEdge(t) => {
                let _ = edges.push(t);
            }
            Event::Plant { ground_m, .. } => {
                let _ = plants.push(ground_m);
            }
        });
        if s.plant_log {
            let first = self
                .machine
                .plants_dropped()
                .wrapping_sub(plants.len() as u32);
            for (i, ground_m) in plants.iter().enumerate() {
                defmt::info!(
                    "sim: plant {=u32} at {=u32} um",
                    first.wrapping_add(i as u32).wrapping_add(1),
                    (ground_m * 1e6) as u32
                );
            }
        }
        self.now_ms = to;
        let now_ticks = self.machine.capture_ticks();
        HALL_TIMER_NOW.store(now_ticks, Relaxed);
        if self.scenario.profile_b {
            // Profile B wiring: TIM3 counts the ground-wheel encoder and TIM2
            // captures one index pulse per feeding-roller turn (there is no
            // Hall gear on this machine).
            edges.clear();
            let count = self.machine.ground_encoder_count();
            let watch = &mut self.stop_watch;
            if count != watch.last_ground_count {
                watch.last_ground_count = count;
                watch.last_count_ms = to;
            }
            let at_rest = inputs.feed_step_rate_hz == 0.0 && inputs.plant_step_rate_hz == 0.0;
            if s.stop.is_some_and(|t| to > t) && at_rest && !watch.reported {
                watch.reported = true;
                defmt::info!(
                    "sim-b: steppers at rest at {=u32} ms, last ground count at {=u32} ms",
                    to,
                    watch.last_count_ms
                );
            }
            let turns = self.machine.feed_roller_turns();
            while self.roller_turns_seen < turns {
                self.roller_turns_seen = self.roller_turns_seen.wrapping_add(1);
                let _ = edges.push(now_ticks);
            }
            return SensorSample {
                drum_encoder: self.machine.ground_encoder_count(),
                hall_edges: edges,
                ground_wheel: None,
            };
        }
        SensorSample {
            drum_encoder: self.machine.drum_encoder_count(),
            hall_edges: edges,
            // Machine A's wheel, on TIM4 on the real board.
            ground_wheel: self
                .ground_wheel
                .then(|| self.machine.ground_encoder_count()),
        }
    }
}

/// Recurses until the stack runs off the bottom of RAM (`stack_overflow=T`).
/// Each level writes a frame and reads it back only after the call below
/// it returns, which it never does: only a fault stops it.
#[inline(never)]
fn exhaust_stack(depth: u32) -> u32 {
    if depth == u32::MAX {
        return depth;
    }
    let mut frame = [depth; 16];
    core::hint::black_box(&mut frame);
    let below = exhaust_stack(depth.wrapping_add(1));
    frame
        .iter()
        .fold(below, |sum, &word| sum.wrapping_add(word))
}
