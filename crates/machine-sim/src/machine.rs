//! The machine: drum motor and driver, belt, track, sensors, faults, metrics.

use kinematics::consts::{self, Gear};

use crate::config::{Config, Error, Profile};
use crate::metrics::{FieldMetrics, MetricsError, SpacingAccumulator};
use crate::rng::{hash_signed_unit, splitmix64, Rng};
use crate::tables;

/// Slots of the transport-delay line (one per millisecond): up to
/// [`crate::config::MAX_TRANSPORT_DELAY_MS`]. Each slot holds the duty in `u16`
/// fractions of 1 (1/65 535, far finer than the PWM's 1/3600).
const RING: usize = crate::config::MAX_TRANSPORT_DELAY_MS as usize + 1;
/// Scale of a delay-line slot (see [`RING`]).
const DUTY_SCALE: f32 = 65_535.0;
/// The model's internal grid: sub-steps never cross a millisecond boundary.
const GRID_US: u32 = 1000;
const TWO_PI: f32 = core::f32::consts::TAU;

// Low-pass noise processes tick once per millisecond: x ← x + a·(c·ξ − x)
// with ξ ~ N(0,1), a = 1 ms / τ and c = √((2 − a)/a), which makes the
// stationary SD of x exactly 1 (var = a·c²/(2 − a)).
/// Motor speed ripple, τ = 20 ms: a = 0.05, c = √39.
const SPEED_NOISE: (f32, f32) = (0.05, 6.244_998);
/// Belt speed noise, τ = 0.2 s: a = 0.005, c = √399.
const BELT_NOISE: (f32, f32) = (0.005, 19.974_984);
/// Slip variation, τ = 1 s: a = 0.001, c = √1999.
const SLIP_NOISE: (f32, f32) = (0.001, 44.710_18);
/// The ground wheel's own slip: τ = 20 s (the soil under a free-rolling
/// wheel changes by patches, not by the track's load swings);
/// c = √((2 − a)/a).
const WHEEL_SLIP_NOISE: (f32, f32) = (0.000_05, 199.997_5);

/// What the controller drives during one step.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Inputs {
    /// PWM duty to the drum-motor driver, 0 … 1 (clamped; NaN reads as 0).
    pub drum_duty: f32,
    /// Driver enable line; when false the motor coasts down through its lag.
    pub driver_enabled: bool,
    /// Profile B: step rate commanded to the seedling-feeding stepper, Hz.
    pub feed_step_rate_hz: f32,
    /// Profile B: step rate commanded to the planting stepper, Hz.
    pub plant_step_rate_hz: f32,
}

/// Something that happened inside a step, in time order per kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A Hall edge latched by the 1 MHz capture timer (wrapping ticks).
    HallEdge(u32),
    /// A plant reached the ground.
    Plant {
        /// Ground position of the plant, metres from the start.
        ground_m: f64,
        /// Simulation time of the drop, µs.
        time_us: u64,
    },
}

/// Faults that tests and scenarios can inject.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// The drum motor is jammed: speed 0, encoder frozen, belt stopped.
    DrumStall,
    /// The Hall sensor delivers no edges.
    HallLoss,
    /// The drum encoder counter stops counting (the drum still turns).
    EncoderLoss,
    /// The ground wheel's encoder stops counting: the wheel is lifted,
    /// blocked or clogged (it does not turn), or its encoder is dead.
    GroundEncoderLoss,
    /// The Hall sensor's output sticks high (a broken wire or a dead
    /// sensor: the pull-up holds the line). The falling edges the firmware
    /// captures stop; if a tooth was in front of the sensor (the line low),
    /// the line rises, which is no captured edge. Cleared while a tooth is
    /// in front, the line falls: one edge at that moment.
    HallStuckHigh,
    /// The Hall sensor's output sticks low (its transistor shorted, or
    /// the cable shorted to ground). If the line was high (no tooth in
    /// front) it falls at that moment: **one spurious edge** part-way
    /// through a gap, then none. Cleared, the line follows the teeth again
    /// (the next falling edge is the next tooth's).
    HallStuckLow,
}

impl Fault {
    const fn bit(self) -> u8 {
        match self {
            Fault::DrumStall => 1,
            Fault::HallLoss => 2,
            Fault::EncoderLoss => 4,
            Fault::GroundEncoderLoss => 8,
            Fault::HallStuckHigh => 16,
            Fault::HallStuckLow => 32,
        }
    }
}

/// `Machine::faults` bit: a Hall edge to deliver at the start of the next
/// sub-step (the line fell when a stuck-low fault came or a stuck-high one
/// went).
const PENDING_EDGE: u8 = 64;

/// Share of a pitch the Hall sensor's output is low (a tooth in front of
/// it), from the tooth's falling edge: teeth and gaps of equal width.
pub const HALL_TOOTH_SHARE: f64 = 0.5;

/// A first-order low-pass noise process with unit stationary SD.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct LpNoise(f32);

impl LpNoise {
    fn tick(&mut self, rng: &mut Rng, (a, c): (f32, f32)) {
        self.0 += a * (c * rng.normal() - self.0);
    }
}

/// `1 − e^(−h/τ)`: the exact step of a first-order lag (1 for τ = 0).
fn lag_alpha(h_s: f32, tau_s: f32) -> f32 {
    if tau_s > 0.0 {
        1.0 - libm::expf(-h_s / tau_s)
    } else {
        1.0
    }
}

fn sanitize(v: f32, hi: f32) -> f32 {
    if v.is_finite() {
        v.clamp(0.0, hi)
    } else {
        0.0
    }
}

/// Rounds `x ≥ 0` down to an integer count (saturating).
fn floor_count(x: f64) -> i64 {
    libm::floor(x) as i64
}

/// The simulated machine. Build it with [`Config::build`], drive it with
/// [`Machine::step`] and read the sensors with the getters.
#[derive(Clone, Debug, PartialEq)]
pub struct Machine {
    cfg: Config,
    rng: Rng,
    now_us: u64,
    faults: u8,
    // Drum motor.
    delay_head: u8,
    delay_line: [u16; RING],
    motor_alpha_1ms: f32,
    drum_rpm: f32,
    speed_noise: LpNoise,
    drum_turns: f64,
    drum_counts_seen: i64,
    drum_encoder: u16,
    // Belt.
    belt_m: f64,
    belt_m_s: f32,
    belt_noise: LpNoise,
    next_drop_m: f64,
    partitions: u32,
    plants: u32,
    // Track.
    gear: Option<Gear>,
    base_m_s: f32,
    step_factor: f32,
    stopped: bool,
    track_alpha_1ms: f32,
    wheel_m_s: f32,
    ground_m_s: f32,
    slip_noise: LpNoise,
    terrain_phase: f32,
    terrain_step: f32,
    next_terrain_step_us: u64,
    next_stop_us: u64,
    stop_until_us: u64,
    wheel_turns: f64,
    /// Turns of the Hall gear (wheel turns / k1′).
    hall_turns: f64,
    ground_m: f64,
    next_edge: u64,
    hall_edges: u32,
    // Profile B.
    ground_counts_seen: i64,
    ground_encoder: u16,
    /// Ground the wheel rolled (its own slip and the clods taken off), m.
    wheel_ground_m: f64,
    /// Ground left of the clod under the wheel, m.
    clod_left_m: f32,
    /// The clods' own random stream: a wheel with clods sees the same
    /// terrain as one without.
    wheel_rng: Rng,
    wheel_slip_noise: LpNoise,
    feed_steps: f64,
    plant_steps: f64,
    feed_belt_m: f64,
    next_seedling_m: f64,
    // Field metrics.
    metrics: SpacingAccumulator,
}

/// When the next stop of the terrain starts: `interval_s` after `from_us`
/// when the stops are regular (no random draw), else at random.
fn stop_time_us(rng: &mut Rng, cfg: &Config, from_us: u64) -> u64 {
    if cfg.terrain_stops_regular && cfg.terrain_stop_interval_s > 0.0 {
        from_us.saturating_add((f64::from(cfg.terrain_stop_interval_s) * 1.0e6) as u64)
    } else {
        event_time_us(rng, cfg.terrain_stop_interval_s, from_us)
    }
}

fn event_time_us(rng: &mut Rng, mean_s: f32, now_us: u64) -> u64 {
    if mean_s > 0.0 {
        let dt = (rng.exponential(mean_s) * 1.0e6).max(1000.0);
        now_us.saturating_add(dt as u64)
    } else {
        u64::MAX
    }
}

impl Config {
    /// Checks every field and builds the machine at rest at t = 0.
    pub fn build(self) -> Result<Machine, Error> {
        self.validate()?;
        Ok(Machine::new(self))
    }
}

impl Machine {
    /// Builds the machine at rest (the configuration is already validated).
    pub(crate) fn new(cfg: Config) -> Self {
        let mut rng = Rng::new(cfg.seed);
        let next_terrain_step_us = event_time_us(&mut rng, cfg.terrain_step_interval_s, 0);
        let next_stop_us = stop_time_us(&mut rng, &cfg, 0);
        // The ranges were checked by `Config::validate`.
        let metrics = SpacingAccumulator::new_unchecked(
            f64::from(cfg.target_spacing_m),
            f64::from(cfg.qualified_tolerance),
        );
        let mut m = Self {
            cfg,
            rng,
            now_us: 0,
            faults: 0,
            delay_head: 0,
            delay_line: [0; RING],
            motor_alpha_1ms: lag_alpha(1.0e-3, cfg.motor_tau_s),
            drum_rpm: 0.0,
            speed_noise: LpNoise::default(),
            drum_turns: 0.0,
            drum_counts_seen: 0,
            drum_encoder: 0,
            belt_m: 0.0,
            belt_m_s: 0.0,
            belt_noise: LpNoise::default(),
            next_drop_m: consts::L_CLAP_F64 * (1.0 - f64::from(cfg.belt_initial_phase)),
            partitions: 0,
            plants: 0,
            gear: None,
            base_m_s: 0.0,
            step_factor: 1.0,
            stopped: false,
            track_alpha_1ms: lag_alpha(1.0e-3, cfg.track_tau_s),
            wheel_m_s: 0.0,
            ground_m_s: 0.0,
            slip_noise: LpNoise::default(),
            terrain_phase: 0.0,
            terrain_step: 0.0,
            next_terrain_step_us,
            next_stop_us,
            stop_until_us: 0,
            wheel_turns: 0.0,
            hall_turns: 0.0,
            ground_m: 0.0,
            next_edge: 1,
            hall_edges: 0,
            ground_counts_seen: 0,
            ground_encoder: 0,
            wheel_ground_m: 0.0,
            clod_left_m: 0.0,
            wheel_rng: Rng::new(cfg.seed ^ 0x05EE_D0FC_10D0),
            wheel_slip_noise: LpNoise::default(),
            feed_steps: 0.0,
            plant_steps: 0.0,
            feed_belt_m: 0.0,
            next_seedling_m: f64::from(cfg.seedling_pitch_m),
            metrics,
        };
        if let Some(g) = cfg.initial_gear {
            m.set_gear(g);
            if cfg.track_tau_s <= 0.0 {
                m.wheel_m_s = m.base_m_s;
            }
        }
        m
    }

    // ------------------------------------------------------------------
    // Stepping
    // ------------------------------------------------------------------

    /// Advances the machine by `dt_us` microseconds with the given inputs,
    /// passing each Hall-edge capture timestamp (1 MHz ticks, wrapping) to
    /// `on_hall_edge` in time order. Internally the model runs in sub-steps
    /// that never cross a millisecond boundary.
    pub fn step(&mut self, dt_us: u32, inputs: &Inputs, on_hall_edge: &mut impl FnMut(u32)) {
        self.step_events(dt_us, inputs, &mut |e| {
            if let Event::HallEdge(t) = e {
                on_hall_edge(t);
            }
        });
    }

    /// As [`Machine::step`], reporting every [`Event`] (Hall edges and plants).
    pub fn step_events(&mut self, dt_us: u32, inputs: &Inputs, sink: &mut impl FnMut(Event)) {
        let mut left = dt_us;
        while left > 0 {
            let into_ms = (self.now_us % u64::from(GRID_US)) as u32;
            let h = left.min(GRID_US - into_ms);
            self.substep(h, inputs, sink);
            left -= h;
        }
    }

    /// Once per millisecond: sample the duty into the delay line, tick the
    /// noise processes and the random terrain events.
    fn tick_grid(&mut self, inputs: &Inputs) {
        let duty = if inputs.driver_enabled {
            sanitize(inputs.drum_duty, 1.0)
        } else {
            0.0
        };
        self.delay_head = (self.delay_head + 1) % RING as u8;
        if let Some(slot) = self.delay_line.get_mut(usize::from(self.delay_head)) {
            // `duty` is sanitised to 0 … 1: the product fits u16.
            *slot = libm::roundf(duty * DUTY_SCALE) as u16;
        }
        let c = &self.cfg;
        if c.speed_noise > 0.0 {
            self.speed_noise.tick(&mut self.rng, SPEED_NOISE);
        }
        if c.belt_slip_noise > 0.0 {
            self.belt_noise.tick(&mut self.rng, BELT_NOISE);
        }
        if c.ground_wheel_slip_noise > 0.0 {
            self.wheel_slip_noise
                .tick(&mut self.wheel_rng, WHEEL_SLIP_NOISE);
        }
        if c.track_slip_noise > 0.0 {
            self.slip_noise.tick(&mut self.rng, SLIP_NOISE);
        }
        if self.now_us >= self.next_terrain_step_us {
            self.terrain_step = c.terrain_step_amplitude * self.rng.signed();
            self.next_terrain_step_us =
                event_time_us(&mut self.rng, c.terrain_step_interval_s, self.now_us);
        }
        if self.now_us >= self.next_stop_us {
            self.stop_until_us = self
                .now_us
                .saturating_add((c.terrain_stop_duration_s * 1.0e6) as u64);
            self.next_stop_us = stop_time_us(&mut self.rng, c, self.stop_until_us);
        }
    }

    /// The duty the driver acts on now (after the transport delay).
    fn delayed_duty(&self, inputs: &Inputs) -> f32 {
        let d = usize::from(self.cfg.transport_delay_ms);
        if d == 0 {
            return if inputs.driver_enabled {
                sanitize(inputs.drum_duty, 1.0)
            } else {
                0.0
            };
        }
        let idx = (usize::from(self.delay_head) + RING - d) % RING;
        self.delay_line
            .get(idx)
            .map_or(0.0, |&d| f32::from(d) / DUTY_SCALE)
    }

    /// Speed the driver steers towards for duty `d` (dead band, droop, ripple, saturation).
    fn drum_target(&self, d: f32) -> f32 {
        let c = &self.cfg;
        if d < c.dead_band_duty || d <= 0.0 {
            return 0.0;
        }
        let mut n = d * c.n_max_rpm;
        if c.load_droop > 0.0 {
            // Phase of the belt within the current partition pitch, 0 … 1.
            let phase = 1.0 - ((self.next_drop_m - self.belt_m) / consts::L_CLAP_F64) as f32;
            n *= 1.0 - c.load_droop * 0.5 * (1.0 - libm::cosf(TWO_PI * phase));
        }
        if c.speed_noise > 0.0 {
            n *= 1.0 + c.speed_noise * self.speed_noise.0;
        }
        n.clamp(0.0, c.n_max_rpm)
    }

    /// Wheel (track rolling) speed commanded by gear/override/step/terrain.
    fn wheel_command(&mut self, h_s: f32) -> f32 {
        let c = &self.cfg;
        if self.stopped || self.now_us < self.stop_until_us {
            return 0.0;
        }
        let mut f = self.step_factor + self.terrain_step;
        if c.terrain_amplitude > 0.0 {
            self.terrain_phase += h_s / c.terrain_period_s;
            if self.terrain_phase >= 1.0 {
                self.terrain_phase -= 1.0;
            }
            f += c.terrain_amplitude * libm::sinf(TWO_PI * self.terrain_phase);
        }
        (self.base_m_s * f).max(0.0)
    }

    /// Tooth position error of edge `k` in pitches (fixed per tooth and seed).
    fn pitch_error(&self, k: u64) -> f64 {
        let e = self.cfg.hall_pitch_error;
        if e <= 0.0 {
            return 0.0;
        }
        let tooth = k % u64::from(self.cfg.hall_teeth);
        let h = splitmix64(self.cfg.seed ^ 0x4841_4C4C_0000_0000 ^ tooth);
        f64::from(e * hash_signed_unit(h))
    }

    #[allow(clippy::too_many_lines)]
    fn substep(&mut self, h: u32, inputs: &Inputs, sink: &mut impl FnMut(Event)) {
        let t0 = self.now_us;
        if t0.is_multiple_of(u64::from(GRID_US)) {
            self.tick_grid(inputs);
        }
        let full = h == GRID_US;
        let hf = h as f32;
        let hs = hf * 1.0e-6;
        let hs64 = f64::from(h) * 1.0e-6;

        // ---- drum motor: delay → dead band/droop → first-order lag ----
        let n0 = self.drum_rpm;
        let n1 = if self.fault_active(Fault::DrumStall) {
            0.0
        } else {
            let target = self.drum_target(self.delayed_duty(inputs));
            let a = if full {
                self.motor_alpha_1ms
            } else {
                lag_alpha(hs, self.cfg.motor_tau_s)
            };
            n0 + (target - n0) * a
        };
        self.drum_rpm = n1;
        let n_avg = if self.fault_active(Fault::DrumStall) {
            0.0
        } else {
            0.5 * (n0 + n1)
        };
        self.drum_turns += f64::from(n_avg) * hs64 / 60.0;
        let cpr =
            f64::from(self.cfg.encoder_counts_per_motor_turn) * f64::from(self.cfg.gear_ratio);
        let total = floor_count(self.drum_turns * cpr);
        let delta = total - self.drum_counts_seen;
        self.drum_counts_seen = total;
        if !self.fault_active(Fault::EncoderLoss) {
            self.drum_encoder = self.drum_encoder.wrapping_add(delta as u16);
        }

        // ---- belt: V2 = k3·π·(D2 + 2H2)·n/60 (eq. 6) with noise ----
        let k3 = 1.0 - self.cfg.belt_slip_scale * (1.0 - tables::k3_at(n_avg));
        let mut v_belt =
            k3 * (core::f64::consts::PI * consts::DRUM_EFFECTIVE_DIAMETER_F64) as f32 * n_avg
                / 60.0;
        if self.cfg.belt_slip_noise > 0.0 {
            v_belt *= 1.0 + self.cfg.belt_slip_noise * self.belt_noise.0;
        }
        let v_belt = v_belt.max(0.0);
        self.belt_m_s = v_belt;
        let b0 = self.belt_m;
        let b1 = b0 + f64::from(v_belt) * hs64;
        self.belt_m = b1;

        // ---- track: command → lag → slip (Table 12) → ground ----
        let cmd = self.wheel_command(hs);
        let v_prev = self.wheel_m_s;
        self.wheel_m_s = if self.cfg.track_tau_s > 0.0 {
            let a = if full {
                self.track_alpha_1ms
            } else {
                lag_alpha(hs, self.cfg.track_tau_s)
            };
            self.wheel_m_s + (cmd - self.wheel_m_s) * a
        } else {
            cmd
        };
        if self.cfg.track_decel_limit_mm_s2 > 0 {
            // Friction: the track slows by at most the limit × h.
            let limit = f32::from(self.cfg.track_decel_limit_mm_s2) * 1.0e-3;
            self.wheel_m_s = self.wheel_m_s.max(v_prev - limit * hs);
        }
        let v_wheel = self.wheel_m_s;
        let mut slip = self.cfg.track_slip_scale * tables::track_slip_at(v_wheel * 3.6);
        if self.cfg.track_slip_noise > 0.0 {
            slip *= 1.0 + self.cfg.track_slip_noise * self.slip_noise.0;
        }
        let slip = slip.clamp(0.0, 0.95);
        self.ground_m_s = v_wheel * (1.0 - slip);
        let g0 = self.ground_m;
        let g1 = g0 + f64::from(self.ground_m_s) * hs64;
        self.ground_m = g1;
        let w0 = self.wheel_turns;
        let w1 = w0 + f64::from(v_wheel) * hs64 / consts::ROLLING_CIRCUMFERENCE_M_F64;
        self.wheel_turns = w1;

        // ---- Hall edges: tooth k (with its pitch error) passes the sensor ----
        // The gear reads low by paper A's k1 (Table 11) at this wheel speed.
        let k1 = 1.0 + self.cfg.hall_k1_scale * (tables::k1_at(v_wheel * 3.6) - 1.0);
        let h0 = self.hall_turns;
        let h1 = h0 + (w1 - w0) / f64::from(k1);
        self.hall_turns = h1;
        let z = f64::from(self.cfg.hall_teeth);
        let (p0, p1) = (h0 * z, h1 * z);
        if self.faults & PENDING_EDGE != 0 {
            // The line fell at the fault's change, at the start of this sub-step.
            self.faults &= !PENDING_EDGE;
            self.hall_edges = self.hall_edges.wrapping_add(1);
            sink(Event::HallEdge(
                self.cfg.timer_start_ticks.wrapping_add(t0 as u32),
            ));
        }
        if p1 > p0 {
            loop {
                let thr = self.next_edge as f64 + self.pitch_error(self.next_edge);
                if thr > p1 {
                    break;
                }
                self.next_edge += 1;
                if self.hall_silent() {
                    continue;
                }
                self.hall_edges = self.hall_edges.wrapping_add(1);
                let frac = (((thr - p0) / (p1 - p0)) as f32).clamp(0.0, 1.0);
                let jitter = if self.cfg.hall_jitter_us > 0 {
                    self.rng.signed() * self.cfg.hall_jitter_us as f32
                } else {
                    0.0
                };
                let off = (frac * hf + jitter).clamp(0.0, hf) as u32;
                let ticks = self
                    .cfg
                    .timer_start_ticks
                    .wrapping_add(t0 as u32)
                    .wrapping_add(off);
                sink(Event::HallEdge(ticks));
            }
        }

        match self.cfg.profile {
            Profile::A => self.belt_drops(t0, hf, (b0, b1), (g0, g1), sink),
            Profile::B => self.profile_b(t0, hs64, inputs, (g0, g1), sink),
        }
        self.ground_wheel(g1 - g0);
        self.now_us = t0 + u64::from(h);
    }

    /// Profile A: a plant drops each time a partition passes the drop point.
    fn belt_drops(
        &mut self,
        t0: u64,
        hf: f32,
        (b0, b1): (f64, f64),
        (g0, g1): (f64, f64),
        sink: &mut impl FnMut(Event),
    ) {
        while self.next_drop_m <= b1 {
            let frac = if b1 > b0 {
                ((self.next_drop_m - b0) / (b1 - b0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            self.next_drop_m += consts::L_CLAP_F64;
            self.partitions = self.partitions.wrapping_add(1);
            self.plant(t0, hf, frac, (g0, g1), sink);
        }
    }

    /// Records a plant at fraction `frac` of the sub-step (unless the cell is empty).
    fn plant(
        &mut self,
        t0: u64,
        hf: f32,
        frac: f64,
        (g0, g1): (f64, f64),
        sink: &mut impl FnMut(Event),
    ) {
        let p_empty = self.cfg.empty_partition_rate;
        if p_empty > 0.0 && self.rng.uniform() < p_empty {
            return;
        }
        let mut pos = g0 + frac * (g1 - g0);
        if self.cfg.plant_scatter_m > 0.0 {
            pos += f64::from(self.cfg.plant_scatter_m * self.rng.normal());
        }
        self.plants = self.plants.wrapping_add(1);
        self.metrics.push_plant(pos);
        sink(Event::Plant {
            ground_m: pos,
            time_us: t0 + (frac as f32 * hf) as u64,
        });
    }

    /// Profile B: steppers, seedling belt from the growing roller (eq. 8), ground encoder.
    fn profile_b(
        &mut self,
        t0: u64,
        hs64: f64,
        inputs: &Inputs,
        (g0, g1): (f64, f64),
        sink: &mut impl FnMut(Event),
    ) {
        let c = self.cfg;
        let max = c.stepper_max_rate_hz;
        let feed = f64::from(sanitize(inputs.feed_step_rate_hz, max));
        let plant = f64::from(sanitize(inputs.plant_step_rate_hz, max));
        let spr = f64::from(c.stepper_steps_per_rev);
        // j: completed roller revolutions; r' = r + h·j (paper B eq. 8).
        let j = libm::floor(self.feed_steps / spr);
        let radius = f64::from(c.feed_roller_radius_m) + f64::from(c.feed_belt_thickness_m) * j;
        let d_turns = feed * hs64 / spr;
        self.feed_steps += feed * hs64;
        self.plant_steps += plant * hs64;
        let l0 = self.feed_belt_m;
        let l1 = l0 + core::f64::consts::TAU * radius * d_turns;
        self.feed_belt_m = l1;
        let hf = (hs64 * 1.0e6) as f32;
        while self.next_seedling_m <= l1 {
            let frac = if l1 > l0 {
                ((self.next_seedling_m - l0) / (l1 - l0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            self.next_seedling_m += f64::from(c.seedling_pitch_m);
            self.partitions = self.partitions.wrapping_add(1);
            self.plant(t0, hf, frac, (g0, g1), sink);
        }
    }

    /// The ground wheel (profile B's, machine A's optional one): it rolls
    /// `dg` of ground less its own slip, not at all on a clod, and its
    /// encoder counts the turns of its real circumference.
    fn ground_wheel(&mut self, dg: f64) {
        let c = self.cfg;
        let mut rolled = dg;
        if c.ground_wheel_clod_rate_per_m > 0.0 && dg > 0.0 {
            if self.clod_left_m <= 0.0
                && f64::from(self.wheel_rng.uniform())
                    < dg * f64::from(c.ground_wheel_clod_rate_per_m)
            {
                self.clod_left_m = c.ground_wheel_clod_m;
            }
            if self.clod_left_m > 0.0 {
                self.clod_left_m -= dg as f32;
                rolled = 0.0;
            }
        }
        if c.ground_wheel_slip > 0.0 {
            let mut slip = f64::from(c.ground_wheel_slip);
            if c.ground_wheel_slip_noise > 0.0 {
                slip *= 1.0 + f64::from(c.ground_wheel_slip_noise * self.wheel_slip_noise.0);
            }
            rolled *= 1.0 - slip.clamp(0.0, 0.5);
        }
        self.wheel_ground_m += rolled;
        let circ = core::f64::consts::PI
            * f64::from(c.ground_wheel_diameter_m)
            * (1.0 + f64::from(c.ground_wheel_diameter_error));
        let total =
            floor_count(self.wheel_ground_m / circ * f64::from(c.ground_encoder_counts_per_turn));
        let delta = total - self.ground_counts_seen;
        self.ground_counts_seen = total;
        if !self.fault_active(Fault::GroundEncoderLoss) {
            let delta = if c.ground_wheel_reversed {
                -delta
            } else {
                delta
            };
            self.ground_encoder = self.ground_encoder.wrapping_add(delta as u16);
        }
    }

    // ------------------------------------------------------------------
    // Travel commands
    // ------------------------------------------------------------------

    /// Engages a gear: the wheel runs at its Table 11 actual speed (clears
    /// any speed override and resumes travel).
    pub fn set_gear(&mut self, gear: Gear) {
        self.gear = Some(gear);
        self.base_m_s = (gear.preset().actual_kmh_f64 / 3.6) as f32;
        self.stopped = false;
    }

    /// Overrides the wheel (track rolling) speed, m/s (clamped to 0 … 20;
    /// NaN reads as 0). The gear is forgotten; travel resumes.
    pub fn set_travel_speed_m_s(&mut self, v: f32) {
        self.gear = None;
        self.base_m_s = sanitize(v, 20.0);
        self.stopped = false;
    }

    /// Multiplies the commanded speed by `1 + rel` (e.g. `0.1` for a +10 %
    /// step, `-0.1` for −10 %), clamped to ±50 % (NaN: no step); replaces
    /// an earlier step.
    pub fn inject_speed_step(&mut self, rel: f32) {
        self.step_factor = if rel.is_finite() {
            1.0 + rel.clamp(-0.5, 0.5)
        } else {
            1.0
        };
    }

    /// Removes an injected speed step.
    pub fn clear_speed_step(&mut self) {
        self.step_factor = 1.0;
    }

    /// Stops the track (wheel command 0) until [`Machine::resume_travel`].
    pub fn stop_travel(&mut self) {
        self.stopped = true;
    }

    /// Resumes travel at the gear/override speed.
    pub fn resume_travel(&mut self) {
        self.stopped = false;
    }

    /// The engaged gear (`None` under a speed override or at start).
    #[must_use]
    pub fn gear(&self) -> Option<Gear> {
        self.gear
    }

    // ------------------------------------------------------------------
    // Faults
    // ------------------------------------------------------------------

    /// Activates a fault.
    pub fn inject_fault(&mut self, fault: Fault) {
        let was_silent = self.hall_silent();
        if fault == Fault::HallStuckLow && !was_silent && !self.hall_line_low() {
            // The line falls now: a spurious edge part-way through a gap.
            self.faults |= PENDING_EDGE;
        }
        self.faults |= fault.bit();
    }

    /// Clears a fault.
    pub fn clear_fault(&mut self, fault: Fault) {
        let high = self.fault_active(Fault::HallStuckHigh);
        self.faults &= !fault.bit();
        if fault == Fault::HallStuckHigh && high && !self.hall_silent() && self.hall_line_low() {
            // Released while a tooth is in front: the line falls now.
            self.faults |= PENDING_EDGE;
        }
    }

    /// No Hall edges are delivered (a lost signal or a stuck output).
    fn hall_silent(&self) -> bool {
        self.faults
            & (Fault::HallLoss.bit() | Fault::HallStuckHigh.bit() | Fault::HallStuckLow.bit())
            != 0
    }

    /// Whether a working sensor's output would be low now: a tooth is in
    /// front of it ([`HALL_TOOTH_SHARE`] of a pitch from its falling edge).
    #[must_use]
    pub fn hall_line_low(&self) -> bool {
        let last = self.next_edge.saturating_sub(1);
        let edge = last as f64 + self.pitch_error(last);
        let p = self.hall_turns * f64::from(self.cfg.hall_teeth);
        p >= edge && p - edge < HALL_TOOTH_SHARE
    }

    /// Whether a fault is active.
    #[must_use]
    pub fn fault_active(&self, fault: Fault) -> bool {
        self.faults & fault.bit() != 0
    }

    // ------------------------------------------------------------------
    // Metrics
    // ------------------------------------------------------------------

    /// Field metrics of the plants since the start or the last reset.
    #[must_use]
    pub fn metrics(&self) -> FieldMetrics {
        self.metrics.metrics(self.ground_m)
    }

    /// Forgets the plants so far; the theoretical count restarts here.
    pub fn reset_metrics(&mut self) {
        self.metrics.reset(self.ground_m);
    }

    /// Changes the target spacing X of the metrics (and resets them).
    pub fn set_target_spacing(&mut self, x_m: f32) -> Result<(), MetricsError> {
        let mut acc =
            SpacingAccumulator::new(f64::from(x_m), f64::from(self.cfg.qualified_tolerance))?;
        acc.reset(self.ground_m);
        self.metrics = acc;
        self.cfg.target_spacing_m = x_m;
        Ok(())
    }

    // ------------------------------------------------------------------
    // Getters
    // ------------------------------------------------------------------

    /// The configuration the machine was built with.
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Simulation time, µs since build.
    #[must_use]
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// The free-running 1 MHz capture timer now (wrapping).
    #[must_use]
    pub fn capture_ticks(&self) -> u32 {
        self.cfg.timer_start_ticks.wrapping_add(self.now_us as u32)
    }

    /// Drum encoder counter (timer in encoder mode, wrapping u16).
    #[must_use]
    pub fn drum_encoder_count(&self) -> u16 {
        self.drum_encoder
    }

    /// Drum speed, r/min (drum shaft).
    #[must_use]
    pub fn drum_speed_rpm(&self) -> f32 {
        self.drum_rpm
    }

    /// Drum revolutions since build.
    #[must_use]
    pub fn drum_turns(&self) -> f64 {
        self.drum_turns
    }

    /// Belt speed, m/s.
    #[must_use]
    pub fn belt_speed_m_s(&self) -> f32 {
        self.belt_m_s
    }

    /// Belt travel since build, m.
    #[must_use]
    pub fn belt_position_m(&self) -> f64 {
        self.belt_m
    }

    /// Partitions (profile B: seedling pitches) that passed the drop point.
    #[must_use]
    pub fn partitions_passed(&self) -> u32 {
        self.partitions
    }

    /// Plants that reached the ground since build.
    #[must_use]
    pub fn plants_dropped(&self) -> u32 {
        self.plants
    }

    /// True travel (ground) speed, m/s.
    #[must_use]
    pub fn travel_speed_m_s(&self) -> f32 {
        self.ground_m_s
    }

    /// Track rolling (wheel) speed, m/s: what the Hall gear sees.
    #[must_use]
    pub fn wheel_speed_m_s(&self) -> f32 {
        self.wheel_m_s
    }

    /// Ground travelled since build, m.
    #[must_use]
    pub fn ground_position_m(&self) -> f64 {
        self.ground_m
    }

    /// Track drive-wheel revolutions since build.
    #[must_use]
    pub fn wheel_turns(&self) -> f64 {
        self.wheel_turns
    }

    /// The track's rolling distance since build, m (its drive wheel's turns ×
    /// its rolling circumference): `1 − Δground / Δtrack` is the track's true
    /// slip over a span.
    #[must_use]
    pub fn track_position_m(&self) -> f64 {
        self.wheel_turns * consts::ROLLING_CIRCUMFERENCE_M_F64
    }

    /// Where the Hall gear's edge `k` lies, in pitches of the gear (the
    /// edges numbered from 1 at build, as delivered while the sensor has no
    /// fault): `k` plus that tooth's position error. The difference of two
    /// is the true ground between those edges, in pitches.
    #[must_use]
    pub fn hall_edge_place_pitches(&self, k: u64) -> f64 {
        k as f64 + self.pitch_error(k)
    }

    /// Hall edges delivered since build (lost edges not counted).
    #[must_use]
    pub fn hall_edges(&self) -> u32 {
        self.hall_edges
    }

    /// The ground wheel's encoder counter (wrapping u16; profile B's wheel,
    /// machine A's optional one).
    #[must_use]
    pub fn ground_encoder_count(&self) -> u16 {
        self.ground_encoder
    }

    /// Profile B: steps the feeding stepper made.
    #[must_use]
    pub fn feed_motor_steps(&self) -> u64 {
        libm::floor(self.feed_steps) as u64
    }

    /// Profile B: steps the planting stepper made.
    #[must_use]
    pub fn plant_motor_steps(&self) -> u64 {
        libm::floor(self.plant_steps) as u64
    }

    /// Profile B: completed feed-roller revolutions `j`.
    #[must_use]
    pub fn feed_roller_turns(&self) -> u32 {
        (libm::floor(self.feed_steps) as u64 / u64::from(self.cfg.stepper_steps_per_rev)) as u32
    }

    /// Profile B: seedling belt unwound from the roller, m.
    #[must_use]
    pub fn feed_belt_position_m(&self) -> f64 {
        self.feed_belt_m
    }
}
