//! The operating logic of profile B (SPEC §8, paper B): two steppers — the
//! planting disc at `n1` (eq. 4) and the seedling-belt feeding roller at `n2`
//! with the growing radius `r + h·j` (eq. 9) — linked to the travel speed by
//! paper B's threshold-Y rule.
//!
//! [`BeltPlanter`] is hardware-free and is driven by:
//!
//! - [`BeltPlanter::control_step`] every control period (10 ms) with the
//!   ground-wheel encoder counter and the roller's completed turns `j`,
//!   returning the two step-pulse rates for the timers ([`StepperCommand`]);
//! - [`BeltPlanter::start`] / [`BeltPlanter::stop`] from the operator;
//! - [`BeltPlanter::snapshot`] for the screen and the log.
//!
//! # Travel speed
//!
//! The 600 ppr ground-wheel encoder in ×4 quadrature gives 2400 counts per
//! turn; on the 0.25 m wheel ([`ProfileBHardware::BOARD`]) a count is
//! `π·0.25/2400` = 0.327 mm of ground. `Vm` is the count over the last
//! [`ProfileBHardware::speed_window_periods`] periods (default 20, i.e.
//! 200 ms) divided by that time:
//!
//! | speed | counts / 200 ms | resolution (1 count) |
//! |---|---|---|
//! | 0.2 m/s | 122 | 0.0016 m/s (0.8 %) |
//! | 0.3 m/s | 183 | 0.0016 m/s (0.5 %) |
//! | 0.4 m/s | 244 | 0.0016 m/s (0.4 %) |
//!
//! The estimate describes the middle of the window: its latency is half the
//! window, 100 ms. One period alone (10 ms, 6 counts at 0.2 m/s) would
//! resolve only ±16 %, far coarser than the threshold Y = 0.02 m/s. After a
//! start or a standstill the window refills: `Vm` is taken over the periods
//! filled so far, and when the window is full for the first time the linkage
//! is re-armed so that the speeds are computed once from the full-resolution
//! estimate (otherwise a coarse early estimate within Y of the true speed
//! would be held for the whole row).
//!
//! # Standstill
//!
//! `Vm` is zero when the ground encoder did not count during the last
//! [`ProfileBHardware::standstill_periods`] periods (default 1): the slowest
//! travel speed told apart from a standstill is one count per that time,
//! 0.327 mm / 10 ms = 0.033 m/s (0.12 km/h), a sixth of paper B's slowest
//! operating speed. In that same control step both step rates are set to 0
//! (without the acceleration limit: a stop must be immediate; at paper B's
//! speeds the feeding roller turns at most ≈ 1 r/s, which a step-servo stops
//! from without losing position). The drivers stay enabled to hold the
//! motors.
//!
//! # Linkage and acceleration limits
//!
//! [`kinematics::profile_b::Linkage`] decides each period: recompute both
//! speeds when `|Vm − V0| > Y`, recompute `n2` when `j` increments, hold
//! otherwise, stop at `Vm = 0`. Its step rates are the *targets*; the rates
//! sent to the timers move towards them by at most
//! [`ProfileBHardware::max_step_change_hz`] per period (default 40 Hz per
//! 10 ms = 4 kHz/s = 2.5 rev/s² at 1600 steps/rev), the acceleration a
//! step-servo follows in sync with the pulse train; a larger step in pulse
//! rate than the rotor can follow is what makes a stepper lose steps. At
//! 0.4 m/s the feeding motor starts to its 1630 Hz in 0.41 s.
//!
//! Radius compensation (eq. 8) can be switched off
//! ([`BeltPlanter::set_radius_compensation`]): `n2` is then computed with `r`
//! for every `j`, as eq. 7, which the benchmark uses to show what eq. 9 buys.
//!
//! # Position-locked feeding
//!
//! On by default ([`BeltPlanter::set_position_lock`]): the belt fed since
//! Start (the pulses sent × `2π·(r + h·j)` per roller turn) is kept at
//! `ground · B / X` by adding the lag, taken up over
//! [`POSITION_LOCK_TIME_MS`], to eq. 9's rate, within
//! ±[`POSITION_LOCK_MAX_PERMILLE`] ‰ of it (docs/profile-b.md).
//!
//! # Faults
//!
//! A step rate above [`ProfileBHardware::max_step_hz`] is clamped there and
//! reported ([`PlanterAlarm::TooFast`], not latched). A travel speed whose
//! motor speeds do not fit the fixed-point types (a broken encoder reading
//! hundreds of m/s) stops both motors and reports
//! [`PlanterAlarm::OutOfRange`] for as long as it lasts.

mod config;

pub use config::{
    ConfigField, Error, ProfileBConfig, ProfileBHardware, CONFIG_BYTES, SPEED_WINDOW_MAX,
};

use kinematics::profile_b::{Linkage, LinkageAction};
use kinematics::units::{Hertz, Metres, MetresPerSecond, RevPerMin};

/// Position-locked feeding: the belt's lag is taken up over this time.
pub const POSITION_LOCK_TIME_MS: u32 = 250;
/// Position-locked feeding: the correction is at most this share of the
/// linkage's rate, ‰ (so no seedling is fed closer than ≈ 0.9 B apart).
pub const POSITION_LOCK_MAX_PERMILLE: u32 = 100;

/// What the step-pulse timers must produce after a control step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepperCommand {
    /// Feeding (seedling-belt roller) motor step rate.
    pub feed_step_hz: Hertz,
    /// Planting (flexible disc) motor step rate.
    pub plant_step_hz: Hertz,
    /// Both drivers enabled (holding torque when the rates are 0).
    pub enabled: bool,
}

impl StepperCommand {
    /// Both motors off, drivers disabled.
    pub const OFF: Self = Self {
        feed_step_hz: Hertz::ZERO,
        plant_step_hz: Hertz::ZERO,
        enabled: false,
    };
}

/// Whether the operator started the planter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlanterState {
    /// Drivers disabled, no pulses.
    Stopped,
    /// Motors linked to the travel speed.
    Running,
}

/// A condition the operator must see (none is latched).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlanterAlarm {
    /// A step rate was clamped at the hardware maximum: travel slower.
    TooFast,
    /// The travel speed gave motor speeds out of range (encoder fault?):
    /// both motors stopped.
    OutOfRange,
}

/// Live values for the screen and the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProfileBSnapshot {
    /// Operator state.
    pub state: PlanterState,
    /// Measured travel speed Vm (windowed).
    pub travel_speed: MetresPerSecond,
    /// The linkage's decision this period.
    pub action: LinkageAction,
    /// The travel speed the motor speeds were computed for (V0).
    pub computed_for: MetresPerSecond,
    /// Planting motor speed n1 (eq. 4) the linkage holds.
    pub planting_speed: RevPerMin,
    /// Feeding motor speed n2 (eq. 9) the linkage holds.
    pub feeding_speed: RevPerMin,
    /// Feeding roller turns j as read.
    pub roller_turns: u32,
    /// Roller radius used for n2 (`r + h·j`, or `r` without compensation).
    pub roller_radius: Metres,
    /// Target step rates (the linkage's), before the acceleration limit.
    pub target_feed_step_hz: Hertz,
    /// Target planting step rate.
    pub target_plant_step_hz: Hertz,
    /// Step rates sent to the timers.
    pub feed_step_hz: Hertz,
    /// Planting step rate sent to the timer.
    pub plant_step_hz: Hertz,
    /// Current alarm.
    pub alarm: Option<PlanterAlarm>,
    /// Ground distance since Start, mm.
    pub distance_mm: u32,
    /// Control steps since boot.
    pub steps: u32,
}

/// Profile B's operating logic: speed measurement, linkage, acceleration
/// limits and standstill stop. See the [module documentation](self).
#[derive(Clone, Debug)]
pub struct BeltPlanter {
    hw: ProfileBHardware,
    /// Travel speed of one ground count per period, `MetresPerSecond` bits
    /// (U8F24) × 2^16: `π·D/(counts_per_turn·T)`.
    vm_per_count_q16: u64,
    /// Ground per count, nm: `π·D/counts_per_turn`.
    nm_per_count: u64,
    config: ProfileBConfig,
    linkage: Linkage,
    compensation: bool,
    state: PlanterState,
    last_counter: Option<u16>,
    /// Ground counts of the last periods (ring), how many are valid, where
    /// the next goes.
    window: [u16; SPEED_WINDOW_MAX],
    filled: u8,
    head: u8,
    /// Consecutive periods without a ground count.
    silent: u8,
    /// Ground counts since Start.
    counts_since_start: u64,
    /// Position-locked feeding on (the default) or the paper's speed
    /// linkage alone.
    position_lock: bool,
    /// Seedling belt fed since Start by the pulses already sent, nm.
    belt_fed_nm: u64,
    feed: Hertz,
    plant: Hertz,
    snapshot: ProfileBSnapshot,
}

impl BeltPlanter {
    /// A stopped planter.
    pub fn new(config: ProfileBConfig, hw: ProfileBHardware) -> Result<Self, Error> {
        hw.validate()?;
        let s = config.settings();
        // π as 355/113 (relative error 8.5e-8). D ≤ 2 m, so D_bits ≤ 2^21 and
        // every product below fits u64 (no u128 arithmetic on the MCU).
        let d = u64::from(hw.ground_wheel_diameter.to_bits());
        let cpr = u64::from(hw.ground_counts_per_turn);
        // U8F24 bits = D_bits(U12F20)·2^4 · 10^6/T_us · π / cpr, then × 2^16.
        let num = d.saturating_mul(355 * 16 * 1_000_000);
        let den = cpr
            .saturating_mul(u64::from(hw.control_period_us))
            .saturating_mul(113);
        let vm_per_count_q16 = mul_div_q16(num, den).ok_or(Error::Hardware)?;
        // nm = D_bits · 10^9 / 2^20 · π / cpr.
        let nm_per_count = d
            .saturating_mul(355 * 1_000_000_000)
            .checked_div(cpr.saturating_mul(113 << 20))
            .ok_or(Error::Hardware)?;
        Ok(Self {
            hw,
            vm_per_count_q16,
            nm_per_count,
            config,
            linkage: Linkage::new(*config.plan()),
            compensation: true,
            state: PlanterState::Stopped,
            last_counter: None,
            window: [0; SPEED_WINDOW_MAX],
            filled: 0,
            head: 0,
            silent: 0,
            counts_since_start: 0,
            position_lock: true,
            belt_fed_nm: 0,
            feed: Hertz::ZERO,
            plant: Hertz::ZERO,
            snapshot: ProfileBSnapshot {
                state: PlanterState::Stopped,
                travel_speed: MetresPerSecond::ZERO,
                action: LinkageAction::Stop,
                computed_for: MetresPerSecond::ZERO,
                planting_speed: RevPerMin::ZERO,
                feeding_speed: RevPerMin::ZERO,
                roller_turns: 0,
                roller_radius: s.roller_radius,
                target_feed_step_hz: Hertz::ZERO,
                target_plant_step_hz: Hertz::ZERO,
                feed_step_hz: Hertz::ZERO,
                plant_step_hz: Hertz::ZERO,
                alarm: None,
                distance_mm: 0,
                steps: 0,
            },
        })
    }

    /// The settings in use.
    #[must_use]
    pub const fn config(&self) -> &ProfileBConfig {
        &self.config
    }

    /// The hardware description in use.
    #[must_use]
    pub const fn hardware(&self) -> &ProfileBHardware {
        &self.hw
    }

    /// Replaces the settings; only while stopped.
    pub fn set_config(&mut self, config: ProfileBConfig) -> Result<(), Error> {
        if self.state == PlanterState::Running {
            return Err(Error::Running);
        }
        self.config = config;
        self.linkage = Linkage::new(*config.plan());
        Ok(())
    }

    /// Switches the roller-radius compensation (eq. 8/9) on or off; off
    /// computes `n2` with `r` for every `j` (eq. 7). On by default; for the
    /// benchmark.
    pub fn set_radius_compensation(&mut self, on: bool) {
        self.compensation = on;
    }

    /// Switches position-locked feeding on (the default) or off (paper B's
    /// speed linkage alone; for comparison). See [`BeltPlanter::control_step`].
    pub fn set_position_lock(&mut self, on: bool) {
        self.position_lock = on;
    }

    /// Whether feeding is position-locked.
    #[must_use]
    pub const fn position_lock(&self) -> bool {
        self.position_lock
    }

    /// Seedling belt the feeding roller should have fed since Start for the
    /// ground covered (`ground · B / X`) minus what the pulses sent have fed,
    /// in µm (positive: the belt is behind).
    #[must_use]
    pub fn belt_lag_um(&self) -> i64 {
        self.belt_lag_nm() / 1000
    }

    /// `belt_target_nm − belt_fed_nm`, saturated (both < 2^63 for any
    /// reachable row).
    fn belt_lag_nm(&self) -> i64 {
        let target = i64::try_from(self.belt_target_nm()).unwrap_or(i64::MAX);
        let fed = i64::try_from(self.belt_fed_nm).unwrap_or(i64::MAX);
        target.saturating_sub(fed)
    }

    /// Whether the radius compensation is on.
    #[must_use]
    pub const fn radius_compensation(&self) -> bool {
        self.compensation
    }

    /// Operator Start: link the motors to the travel speed.
    pub fn start(&mut self) {
        if self.state == PlanterState::Stopped {
            self.state = PlanterState::Running;
            self.counts_since_start = 0;
            self.belt_fed_nm = 0;
            self.restart_measurement();
        }
    }

    /// A new seedling-belt roll is loaded (page 7 *New roll*): only while
    /// stopped ([`Error::Running`] otherwise). The caller's roller turn
    /// count `j` must start again from 0 with it (`BeltMachine` does).
    ///
    /// What follows `j` here: the snapshot's `j` and radius show `j = 0`
    /// and `r` at once, and the linkage forgets the `n2` it held (it is
    /// rebuilt every stopped period anyway). Nothing else holds `j`: the
    /// feeding rate (eq. 9) and the position lock's belt per step
    /// `2π·(r + h·j)/steps` are computed each period from the `j` passed
    /// to [`BeltPlanter::control_step`], and the lock's account (ground
    /// and belt since Start) restarts at every [`BeltPlanter::start`]. As
    /// this is refused while running, no rate jumps.
    pub fn new_roll(&mut self) -> Result<(), Error> {
        if self.state == PlanterState::Running {
            return Err(Error::Running);
        }
        self.linkage = Linkage::new(*self.config.plan());
        self.snapshot.roller_turns = 0;
        self.snapshot.roller_radius = self.config.settings().roller_radius;
        Ok(())
    }

    /// Operator Stop: both motors off at the next control step.
    pub fn stop(&mut self) {
        self.state = PlanterState::Stopped;
    }

    /// Operator state.
    #[must_use]
    pub const fn state(&self) -> PlanterState {
        self.state
    }

    /// Live values of the last control step.
    #[must_use]
    pub const fn snapshot(&self) -> &ProfileBSnapshot {
        &self.snapshot
    }

    fn restart_measurement(&mut self) {
        self.filled = 0;
        self.head = 0;
        self.linkage = Linkage::new(*self.config.plan());
    }

    /// Travel speed over the filled part of the window:
    /// `Vm = π·D·counts / (counts_per_turn · periods · T)`.
    fn travel_speed(&self) -> MetresPerSecond {
        let n = usize::from(self.filled);
        // ≤ 32 × 65 535 counts.
        let counts: u64 = self
            .window
            .iter()
            .take(n)
            .map(|&c| u64::from(c))
            .fold(0, u64::saturating_add);
        let bits = counts
            .saturating_mul(self.vm_per_count_q16)
            .checked_div(u64::from(self.filled) << 16)
            .unwrap_or(0);
        MetresPerSecond::from_bits(u32::try_from(bits).unwrap_or(u32::MAX))
    }

    /// Moves `cur` towards `target` by at most the acceleration limit.
    fn slew(&self, cur: Hertz, target: Hertz) -> Hertz {
        let d = self.hw.max_step_change_hz;
        if target >= cur {
            cur.saturating_add(target.saturating_sub(cur).min(d))
        } else {
            cur.saturating_sub(cur.saturating_sub(target).min(d))
        }
    }

    /// The control step, once per control period.
    ///
    /// `ground_encoder` is the free-running ground-wheel encoder counter
    /// (forward counts up; a backwards reading counts as no motion);
    /// `roller_turns` the feeding roller's completed turns `j` from its
    /// encoder.
    pub fn control_step(&mut self, ground_encoder: u16, roller_turns: u32) -> StepperCommand {
        self.snapshot.steps = self.snapshot.steps.wrapping_add(1);
        let delta = match self.last_counter {
            Some(prev) => {
                let d = ground_encoder.wrapping_sub(prev);
                if d > u16::MAX / 2 {
                    0
                } else {
                    d
                }
            }
            None => 0,
        };
        self.last_counter = Some(ground_encoder);

        // Standstill: no count for `standstill_periods` periods.
        if delta == 0 {
            self.silent = self.silent.saturating_add(1);
        } else {
            self.silent = 0;
        }
        let standstill = self.silent >= self.hw.standstill_periods;

        // The speed window (restarted at standstill so that old counts do
        // not linger into the next start).
        let full_before = usize::from(self.filled) >= usize::from(self.hw.speed_window_periods);
        if standstill {
            self.filled = 0;
            self.head = 0;
        } else {
            if let Some(slot) = self.window.get_mut(usize::from(self.head)) {
                *slot = delta;
            }
            self.head = self.head.saturating_add(1);
            if self.head >= self.hw.speed_window_periods {
                self.head = 0;
            }
            self.filled = self
                .filled
                .saturating_add(1)
                .min(self.hw.speed_window_periods);
        }
        let full_now = usize::from(self.filled) >= usize::from(self.hw.speed_window_periods);
        let vm = if standstill {
            MetresPerSecond::ZERO
        } else {
            self.travel_speed()
        };
        self.snapshot.travel_speed = vm;

        let mut cmd = StepperCommand::OFF;
        let mut alarm = None;
        if self.state == PlanterState::Running {
            self.counts_since_start = self.counts_since_start.saturating_add(u64::from(delta));
            // The pulses sent last period have fed this much belt.
            let fed = self.belt_per_period_nm(self.feed, self.radius_turns(roller_turns));
            self.belt_fed_nm = self.belt_fed_nm.saturating_add(fed);
            if full_now && !full_before {
                // First full-resolution estimate: compute the speeds from it.
                self.linkage = Linkage::new(*self.config.plan());
            }
            let j = if self.compensation { roller_turns } else { 0 };
            match self.linkage.step(vm, j) {
                Ok(m) if m.action != LinkageAction::Stop => {
                    let max = self.hw.max_step_hz;
                    if m.feeding_step_hz > max || m.planting_step_hz > max {
                        alarm = Some(PlanterAlarm::TooFast);
                    }
                    let tf = m.feeding_step_hz.min(max);
                    let fed = if self.position_lock {
                        self.locked_feed(tf, j).min(max)
                    } else {
                        tf
                    };
                    let tp = m.planting_step_hz.min(max);
                    self.feed = self.slew(self.feed, fed);
                    self.plant = self.slew(self.plant, tp);
                    self.snapshot.action = m.action;
                    self.snapshot.computed_for = m.computed_for;
                    self.snapshot.planting_speed = m.planting_speed;
                    self.snapshot.feeding_speed = m.feeding_speed;
                    self.snapshot.target_feed_step_hz = tf;
                    self.snapshot.target_plant_step_hz = tp;
                    cmd = StepperCommand {
                        feed_step_hz: self.feed,
                        plant_step_hz: self.plant,
                        enabled: true,
                    };
                }
                Ok(_) => {
                    self.halt(LinkageAction::Stop);
                    cmd.enabled = true;
                }
                Err(_) => {
                    alarm = Some(PlanterAlarm::OutOfRange);
                    self.halt(LinkageAction::Stop);
                    // Forget V0: recompute once the speed is sane again.
                    self.linkage = Linkage::new(*self.config.plan());
                    cmd.enabled = true;
                }
            }
        } else {
            self.halt(LinkageAction::Stop);
            self.linkage = Linkage::new(*self.config.plan());
        }
        // Also while stopped: the screen shows the turns made while a roll
        // is threaded, and `j = 0` after *New roll*.
        self.snapshot.roller_turns = roller_turns;
        self.snapshot.roller_radius = self
            .config
            .plan()
            .roller_radius(self.radius_turns(roller_turns))
            .unwrap_or(self.config.settings().roller_radius);
        self.snapshot.state = self.state;
        self.snapshot.alarm = alarm;
        self.snapshot.feed_step_hz = cmd.feed_step_hz;
        self.snapshot.plant_step_hz = cmd.plant_step_hz;
        self.snapshot.distance_mm = self.distance_mm();
        cmd
    }

    fn halt(&mut self, action: LinkageAction) {
        self.feed = Hertz::ZERO;
        self.plant = Hertz::ZERO;
        self.snapshot.action = action;
        self.snapshot.computed_for = MetresPerSecond::ZERO;
        self.snapshot.planting_speed = RevPerMin::ZERO;
        self.snapshot.feeding_speed = RevPerMin::ZERO;
        self.snapshot.target_feed_step_hz = Hertz::ZERO;
        self.snapshot.target_plant_step_hz = Hertz::ZERO;
    }

    /// The roller turns the radius is computed for: `j`, or 0 without the
    /// radius compensation (the belt geometry the firmware believes in).
    const fn radius_turns(&self, roller_turns: u32) -> u32 {
        if self.compensation {
            roller_turns
        } else {
            0
        }
    }

    /// Belt per feeding step at roller turn `j`, nm: `2π·(r + h·j) / steps`
    /// (π as 355/113). `None` for an impossible radius.
    fn belt_per_step_nm(&self, j: u32) -> Option<u64> {
        let r = self.config.plan().roller_radius(j).ok()?;
        let spr = u64::from(self.config.settings().feeding_steps_per_rev);
        // r ≤ 4096 m as U12F20 bits < 2^32; × 710 × 10^9 < 2^72 would
        // overflow: r is validated ≤ 0.2 m + h·j, so r_bits < 2^28 and the
        // product < 2^68 — divide by 2^20 first (loses < 1 nm).
        let r_nm = u64::from(r.to_bits())
            .checked_mul(1_000_000_000)?
            .checked_shr(20)?;
        r_nm.checked_mul(710)?
            .checked_div(113_u64.checked_mul(spr)?)
    }

    /// Belt fed by `rate` over one control period at roller turn `j`, nm.
    fn belt_per_period_nm(&self, rate: Hertz, j: u32) -> u64 {
        // Steps × 10^6 = rate_bits · T_us / 2^16 (≤ 2^32 · 2^20 / 2^16).
        let micro_steps =
            u64::from(rate.to_bits()).saturating_mul(u64::from(self.hw.control_period_us)) >> 16;
        self.belt_per_step_nm(j)
            .map_or(0, |nm| micro_steps.saturating_mul(nm) / 1_000_000)
    }

    /// The belt the ground covered since Start asks for, nm: `ground·B/X`.
    fn belt_target_nm(&self) -> u64 {
        let ground_nm = self.counts_since_start.saturating_mul(self.nm_per_count);
        let s = self.config.settings();
        ground_nm
            .saturating_mul(u64::from(s.belt_pitch.to_bits()))
            .checked_div(u64::from(s.plant_spacing.to_bits()))
            .unwrap_or(0)
    }

    /// Position lock: the linkage's feeding rate `ff` plus the belt's lag
    /// behind `ground·B/X` taken up over [`POSITION_LOCK_TIME_MS`], the
    /// correction limited to ±[`POSITION_LOCK_MAX_PERMILLE`] ‰ of `ff` (no
    /// correction at rest: the stop stays immediate).
    fn locked_feed(&self, ff: Hertz, j: u32) -> Hertz {
        let Some(per_step) = self.belt_per_step_nm(j).filter(|&n| n > 0) else {
            return ff;
        };
        let per_step = i64::try_from(per_step).unwrap_or(i64::MAX);
        // Steps behind × 1000 / lock time (ms) = Hz; in U16F16 bits.
        let hz_bits = self
            .belt_lag_nm()
            .saturating_mul(1 << 16)
            .checked_div(per_step)
            .unwrap_or(0)
            .saturating_mul(1000)
            .checked_div(i64::from(POSITION_LOCK_TIME_MS))
            .unwrap_or(0);
        let ff_bits = i64::from(ff.to_bits());
        let bound = ff_bits.saturating_mul(i64::from(POSITION_LOCK_MAX_PERMILLE)) / 1000;
        let rate = ff_bits.saturating_add(hz_bits.clamp(bound.saturating_neg(), bound));
        Hertz::from_bits(u32::try_from(rate.max(0)).unwrap_or(u32::MAX))
    }

    /// Ground since Start, mm.
    fn distance_mm(&self) -> u32 {
        let nm = self.counts_since_start.saturating_mul(self.nm_per_count);
        u32::try_from(nm / 1_000_000).unwrap_or(u32::MAX)
    }
}

/// `num · 2^16 / den` without overflow for `den < 2^47`; `None` if `den` is 0.
fn mul_div_q16(num: u64, den: u64) -> Option<u64> {
    let q = num.checked_div(den)?;
    let r = num.checked_rem(den)?;
    Some(
        q.saturating_mul(1 << 16)
            .saturating_add((r << 16).checked_div(den)?),
    )
}
