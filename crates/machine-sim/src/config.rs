//! Parameters of the model, with documented defaults, validated by
//! [`Config::build`].

use kinematics::consts::{self, Gear};

/// Longest transport delay the delay line holds, milliseconds: enough for
/// drives with their own speed loop, ramp or RS-485 read-back (20–60 ms).
pub const MAX_TRANSPORT_DELAY_MS: u8 = 63;

/// Which machine the plants come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Profile {
    /// Paper A: drum motor → partitioned belt; a plant drops each time a
    /// partition passes the drop point.
    #[default]
    A,
    /// Paper B: feeding stepper unwinds the seedling belt (pitch B) from a
    /// roller whose radius grows `r + h·j`; each delivered seedling is planted.
    B,
}

/// Every parameter of the simulator. Start from [`Config::default`] (a
/// realistic machine with noise) or [`Config::noiseless`] (ideal sensors and
/// terrain, Table 12/13 slip still applied), change fields, then
/// [`Config::build`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Seed of the pseudo-random generator (same seed → same run).
    pub seed: u64,
    /// Which plant mechanism feeds the field metrics. Default [`Profile::A`].
    pub profile: Profile,

    // ----- drum motor and driver (SPEC §3) -----
    /// Drum speed at 100 % duty, r/min (drum shaft). Default 44.7 (`consts::N_MAX_F64`).
    pub n_max_rpm: f32,
    /// Time constant of the driver + motor first-order lag, s. Default 0.025.
    pub motor_tau_s: f32,
    /// Transport delay from duty to driver response, ms (0 …
    /// [`MAX_TRANSPORT_DELAY_MS`]). Default 5.
    pub transport_delay_ms: u8,
    /// Duty below which the driver does not start the motor. Default 0.03.
    pub dead_band_duty: f32,
    /// Largest relative speed droop under the seedlings' load; the droop
    /// varies 0 … this value as each partition passes the drop point. Default 0.05.
    pub load_droop: f32,
    /// Relative SD of the motor speed ripple (low-pass noise, τ = 20 ms). Default 0.003.
    pub speed_noise: f32,
    /// Drum encoder counts per motor turn (after quadrature). Default 400.
    pub encoder_counts_per_motor_turn: u32,
    /// Motor turns per drum turn. Default 118 (`consts::DRUM_GEAR_RATIO`).
    pub gear_ratio: u32,

    // ----- belt (SPEC §3, Table 13) -----
    /// Scale of the Table 13 belt slip `1 − k3` (0 = no slip). Default 1.
    pub belt_slip_scale: f32,
    /// Relative SD of belt speed noise (low-pass, τ = 0.2 s). Default 0.003.
    pub belt_slip_noise: f32,
    /// Probability that a partition carries no seedling. Default 0.
    pub empty_partition_rate: f32,
    /// SD of where a plant lands around the drop point, m. Default 0.002.
    pub plant_scatter_m: f32,
    /// Share of a partition pitch already travelled at start, 0 … 1. Default 0.
    pub belt_initial_phase: f32,

    // ----- track (SPEC §2, §4) -----
    /// Gear engaged at start (`None`: standing). Default `None`.
    pub initial_gear: Option<Gear>,
    /// Chassis lag of the wheel speed behind its command, s (0 = steps are
    /// instantaneous). Default 0.
    pub track_tau_s: f32,
    /// Largest deceleration of the wheel (track rolling) speed, mm/s² (0 =
    /// no limit; an integer so that the model stays within its 592 bytes).
    /// A tracked chassis whose tracks do not skid slows down at most as fast
    /// as the friction between track and ground allows (μ·g,
    /// docs/machine-sim.md); with `track_tau_s` 0 a stop is then a constant
    /// deceleration at this limit. Default 0.
    pub track_decel_limit_mm_s2: u16,
    /// Scale of the Table 12 track slip `1 − k2` (0 = no slip). Default 1.
    pub track_slip_scale: f32,
    /// Relative variation (SD) of the slip (low-pass, τ = 1 s). Default 0.1.
    pub track_slip_noise: f32,
    /// Amplitude of the slow terrain sinusoid, relative speed. Default 0.03.
    pub terrain_amplitude: f32,
    /// Period of the terrain sinusoid, s. Default 8.
    pub terrain_period_s: f32,
    /// Largest random terrain speed step, relative (uniform ±). Default 0.02.
    pub terrain_step_amplitude: f32,
    /// Mean interval between random terrain steps, s (0 = none). Default 5.
    pub terrain_step_interval_s: f32,
    /// Mean interval between random stops, s (0 = none). Default 0.
    pub terrain_stop_interval_s: f32,
    /// Duration of a random stop, s. Default 1.
    pub terrain_stop_duration_s: f32,
    /// Stop-and-go: the stops come exactly `terrain_stop_interval_s` after
    /// the end of the previous one (the first at `terrain_stop_interval_s`)
    /// instead of at random. Default false.
    pub terrain_stops_regular: bool,

    // ----- Hall sensor (SPEC §2) -----
    /// Teeth of the Hall gear. Default 25 (`consts::Z1`).
    pub hall_teeth: u8,
    /// Largest tooth position error, fraction of a pitch (fixed per tooth,
    /// drawn from the seed), 0 … 0.25. Default 0.02.
    pub hall_pitch_error: f32,
    /// How much of paper A's speed-measurement error the Hall gear shows,
    /// 0 … 1: the gear turns at wheel speed / k1′ with
    /// k1′ = 1 + scale·(k1 − 1), k1 from Table 11 at the wheel speed, so the
    /// monitored speed reads as low (or high) as the paper measured and the
    /// firmware's k1 correction has something real to correct. Default 1;
    /// 0 makes the gear turn exactly with the wheel.
    pub hall_k1_scale: f32,
    /// Capture jitter, ± µs (uniform). Default 10.
    pub hall_jitter_us: u32,
    /// Value of the 1 MHz capture timer at t = 0 (to test the wrap). Default 0.
    pub timer_start_ticks: u32,

    // ----- the ground wheel (profile B's, and machine A's optional one) -----
    /// Ground-wheel diameter, m (unpublished). Default 0.25.
    pub ground_wheel_diameter_m: f32,
    /// Ground-wheel encoder counts per turn (600 ppr × 4 in quadrature). Default 2400.
    pub ground_encoder_counts_per_turn: u32,
    /// The wheel's real rolling diameter against
    /// [`Config::ground_wheel_diameter_m`], fraction (−0.2 … 0.2: tyre wear,
    /// soil on the tread, a wheel other than the one set). Default 0.
    pub ground_wheel_diameter_error: f32,
    /// The wheel's own slip on the soil, fraction (0 … 0.05: it rolls this
    /// much less than the ground; a trailed wheel's 0–1 %). Default 0.
    pub ground_wheel_slip: f32,
    /// Relative noise of the wheel's own slip (0 … 1: its SD against the
    /// mean), a low-pass process of 20 s (the soil under a free-rolling wheel
    /// changes by patches). Default 0.
    pub ground_wheel_slip_noise: f32,
    /// Clods that lift the wheel off the soil, per metre of ground (0 … 5).
    /// Default 0.
    pub ground_wheel_clod_rate_per_m: f32,
    /// Ground a clod keeps the wheel off the soil (it does not turn), m
    /// (0 … 1). Default 0.03.
    pub ground_wheel_clod_m: f32,
    /// The wheel's encoder counts backwards when the machine moves forward
    /// (A/B swapped). Default `false`.
    pub ground_wheel_reversed: bool,
    /// Steps per revolution of both steppers. Default 1600
    /// (`ProfileBSettings::default().feeding_steps_per_rev`).
    pub stepper_steps_per_rev: u32,
    /// Highest step rate the steppers follow, Hz (faster commands are clamped). Default 40 000.
    pub stepper_max_rate_hz: f32,
    /// Empty feed-roller radius `r`, m (unpublished). Default 0.025
    /// (`ProfileBSettings::default().roller_radius`).
    pub feed_roller_radius_m: f32,
    /// Seedling-belt thickness `h`, m (unpublished). Default 0.001 as the
    /// firmware stores it (`ProfileBSettings::default().belt_thickness`,
    /// U12F20: 0.001 000 4 m).
    pub feed_belt_thickness_m: f32,
    /// Seedling pitch on the belt `B`, m. Default 0.10 (paper B;
    /// `ProfileBSettings::default().belt_pitch`, U12F20: 0.100 000 4 m).
    pub seedling_pitch_m: f32,

    // ----- field metrics -----
    /// Target plant spacing X for the metrics, m. Default 0.07 (Codonopsis).
    pub target_spacing_m: f32,
    /// Qualification tolerance: a spacing is qualified when
    /// `|s − X| ≤ tol·X`. Default 0.2.
    pub qualified_tolerance: f32,
}

impl Default for Config {
    fn default() -> Self {
        let pb = kinematics::profile_b::ProfileBSettings::default();
        Self {
            seed: 1,
            profile: Profile::A,
            n_max_rpm: consts::N_MAX_F64 as f32,
            motor_tau_s: 0.025,
            transport_delay_ms: 5,
            dead_band_duty: 0.03,
            load_droop: 0.05,
            speed_noise: 0.003,
            encoder_counts_per_motor_turn: 400,
            gear_ratio: u32::from(consts::DRUM_GEAR_RATIO),
            belt_slip_scale: 1.0,
            belt_slip_noise: 0.003,
            empty_partition_rate: 0.0,
            plant_scatter_m: 0.002,
            belt_initial_phase: 0.0,
            initial_gear: None,
            track_tau_s: 0.0,
            track_decel_limit_mm_s2: 0,
            track_slip_scale: 1.0,
            track_slip_noise: 0.1,
            terrain_amplitude: 0.03,
            terrain_period_s: 8.0,
            terrain_step_amplitude: 0.02,
            terrain_step_interval_s: 5.0,
            terrain_stop_interval_s: 0.0,
            terrain_stop_duration_s: 1.0,
            terrain_stops_regular: false,
            hall_teeth: consts::Z1,
            hall_pitch_error: 0.02,
            hall_k1_scale: 1.0,
            hall_jitter_us: 10,
            timer_start_ticks: 0,
            ground_wheel_diameter_m: 0.25,
            ground_encoder_counts_per_turn: 2400,
            ground_wheel_diameter_error: 0.0,
            ground_wheel_slip: 0.0,
            ground_wheel_slip_noise: 0.0,
            ground_wheel_clod_rate_per_m: 0.0,
            ground_wheel_clod_m: 0.03,
            ground_wheel_reversed: false,
            // Profile B: the machine the firmware's defaults describe.
            stepper_steps_per_rev: pb.feeding_steps_per_rev,
            stepper_max_rate_hz: 40_000.0,
            feed_roller_radius_m: pb.roller_radius.to_f64() as f32,
            feed_belt_thickness_m: pb.belt_thickness.to_f64() as f32,
            seedling_pitch_m: pb.belt_pitch.to_f64() as f32,
            target_spacing_m: 0.07,
            qualified_tolerance: 0.2,
        }
    }
}

impl Config {
    /// Travel-speed profile "hills": the speed swings ±20 %
    /// around the gear's speed in random steps (uniform ±20 %, one every 3 s
    /// on average, drawn from the seeded RNG), through the chassis's 0.5 s
    /// time constant; the slow terrain sinusoid is off. Other fields kept.
    #[must_use]
    pub fn hills(self) -> Self {
        Self {
            terrain_amplitude: 0.0,
            terrain_step_amplitude: 0.2,
            terrain_step_interval_s: 3.0,
            track_tau_s: 0.5,
            ..self
        }
    }

    /// Travel-speed profile "stop-and-go": every 10 s the
    /// tractor comes to rest for 2 s and drives on (regular stops), through
    /// the chassis's 0.5 s time constant; the default terrain stays on.
    #[must_use]
    pub fn stop_and_go(self) -> Self {
        Self {
            terrain_stop_interval_s: 10.0,
            terrain_stop_duration_s: 2.0,
            terrain_stops_regular: true,
            track_tau_s: 0.5,
            ..self
        }
    }
}

/// A configuration field out of its documented range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// The named field is NaN/infinite or outside its documented range.
    OutOfRange(&'static str),
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::OutOfRange(name) => write!(f, "machine-sim config: `{name}` out of range"),
        }
    }
}

impl core::error::Error for Error {}

fn check(name: &'static str, v: f32, lo: f32, hi: f32) -> Result<(), Error> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(Error::OutOfRange(name))
    }
}

fn check_pos(name: &'static str, v: f32, hi: f32) -> Result<(), Error> {
    if v.is_finite() && v > 0.0 && v <= hi {
        Ok(())
    } else {
        Err(Error::OutOfRange(name))
    }
}

fn check_u32(name: &'static str, v: u32, lo: u32, hi: u32) -> Result<(), Error> {
    if (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(Error::OutOfRange(name))
    }
}

impl Config {
    /// The default machine without noise, jitter, pitch error, terrain
    /// disturbance, droop or scatter; the Table 12/13 slips remain (set
    /// `track_slip_scale`/`belt_slip_scale` to 0 for a slip-free machine).
    #[must_use]
    pub fn noiseless() -> Self {
        Self {
            load_droop: 0.0,
            speed_noise: 0.0,
            belt_slip_noise: 0.0,
            plant_scatter_m: 0.0,
            track_slip_noise: 0.0,
            terrain_amplitude: 0.0,
            terrain_step_amplitude: 0.0,
            terrain_step_interval_s: 0.0,
            terrain_stop_interval_s: 0.0,
            hall_pitch_error: 0.0,
            hall_jitter_us: 0,
            ..Self::default()
        }
    }

    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), Error> {
        check_pos("n_max_rpm", self.n_max_rpm, 1000.0)?;
        check("motor_tau_s", self.motor_tau_s, 0.0, 10.0)?;
        if self.transport_delay_ms > MAX_TRANSPORT_DELAY_MS {
            return Err(Error::OutOfRange("transport_delay_ms"));
        }
        check("dead_band_duty", self.dead_band_duty, 0.0, 0.5)?;
        check("load_droop", self.load_droop, 0.0, 0.5)?;
        check("speed_noise", self.speed_noise, 0.0, 0.2)?;
        check_u32(
            "encoder_counts_per_motor_turn",
            self.encoder_counts_per_motor_turn,
            1,
            1_000_000,
        )?;
        check_u32("gear_ratio", self.gear_ratio, 1, 10_000)?;
        check("belt_slip_scale", self.belt_slip_scale, 0.0, 10.0)?;
        check("belt_slip_noise", self.belt_slip_noise, 0.0, 0.2)?;
        check("empty_partition_rate", self.empty_partition_rate, 0.0, 1.0)?;
        check("plant_scatter_m", self.plant_scatter_m, 0.0, 1.0)?;
        if !(self.belt_initial_phase.is_finite()
            && self.belt_initial_phase >= 0.0
            && self.belt_initial_phase < 1.0)
        {
            return Err(Error::OutOfRange("belt_initial_phase"));
        }
        check("track_tau_s", self.track_tau_s, 0.0, 60.0)?;
        check("track_slip_scale", self.track_slip_scale, 0.0, 10.0)?;
        check("track_slip_noise", self.track_slip_noise, 0.0, 1.0)?;
        check("terrain_amplitude", self.terrain_amplitude, 0.0, 0.5)?;
        check_pos("terrain_period_s", self.terrain_period_s, 1.0e6)?;
        check(
            "terrain_step_amplitude",
            self.terrain_step_amplitude,
            0.0,
            0.5,
        )?;
        check(
            "terrain_step_interval_s",
            self.terrain_step_interval_s,
            0.0,
            1.0e6,
        )?;
        check(
            "terrain_stop_interval_s",
            self.terrain_stop_interval_s,
            0.0,
            1.0e6,
        )?;
        check(
            "terrain_stop_duration_s",
            self.terrain_stop_duration_s,
            0.0,
            1.0e4,
        )?;
        if self.hall_teeth == 0 {
            return Err(Error::OutOfRange("hall_teeth"));
        }
        check("hall_pitch_error", self.hall_pitch_error, 0.0, 0.25)?;
        check("hall_k1_scale", self.hall_k1_scale, 0.0, 1.0)?;
        check_u32("hall_jitter_us", self.hall_jitter_us, 0, 500)?;
        check_pos(
            "ground_wheel_diameter_m",
            self.ground_wheel_diameter_m,
            10.0,
        )?;
        check_u32(
            "ground_encoder_counts_per_turn",
            self.ground_encoder_counts_per_turn,
            1,
            1_000_000,
        )?;
        check(
            "ground_wheel_diameter_error",
            self.ground_wheel_diameter_error,
            -0.2,
            0.2,
        )?;
        check("ground_wheel_slip", self.ground_wheel_slip, 0.0, 0.05)?;
        check(
            "ground_wheel_slip_noise",
            self.ground_wheel_slip_noise,
            0.0,
            1.0,
        )?;
        check(
            "ground_wheel_clod_rate_per_m",
            self.ground_wheel_clod_rate_per_m,
            0.0,
            5.0,
        )?;
        check("ground_wheel_clod_m", self.ground_wheel_clod_m, 0.0, 1.0)?;
        check_u32(
            "stepper_steps_per_rev",
            self.stepper_steps_per_rev,
            1,
            1_000_000,
        )?;
        check_pos("stepper_max_rate_hz", self.stepper_max_rate_hz, 1.0e6)?;
        check_pos("feed_roller_radius_m", self.feed_roller_radius_m, 10.0)?;
        check(
            "feed_belt_thickness_m",
            self.feed_belt_thickness_m,
            0.0,
            0.1,
        )?;
        check_pos("seedling_pitch_m", self.seedling_pitch_m, 10.0)?;
        check_pos("target_spacing_m", self.target_spacing_m, 10.0)?;
        check_pos("qualified_tolerance", self.qualified_tolerance, 1.0)?;
        Ok(())
    }
}
