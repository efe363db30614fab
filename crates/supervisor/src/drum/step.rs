//! The control step: sense → estimate → plan → supervise → control →
//! report.

use super::*;
use crate::ground::GroundFault;
use hmi_proto::screen::TravelSource;

/// Smoothing of the reported drum speed: `Ts / (Ts + τ)` with `τ` = 0.5 s.
/// The seedlings load the drum once per partition (1.5 Hz at 20 r/min), a
/// ripple of about ±1 % that the operator need not watch; the mean, which the
/// controller holds, is what the screen and the log show.
const REPORT_ALPHA: I16F16 = I16F16::lit("0.0196");

/// Smoothing of the drum speed k3 is looked up at: `Ts / (Ts + τ)` with
/// `τ` = 30 ms. One encoder count in 10 ms is 0.13 r/min; across a corner
/// of the k3 table (20 r/min) that quantisation biased the mean k3 and moved
/// the belt's phase by 2.2 mm per 300 m of ground (40 cm at High 2,
/// noiseless). Short enough that the lookup follows a start (the reported
/// speed's 0.5 s held k3 at its rest value while the drum ran up, 1.3 %).
const K3_SPEED_ALPHA: I16F16 = I16F16::lit("0.25");

/// What the step sensed of the drum.
struct Sensed {
    /// Encoder counts forward since the last step.
    encoder_delta: u16,
    /// Counts of the feedback in use (the encoder's, or the driver's
    /// read-back's).
    delta: u16,
    /// The period's length, µs.
    elapsed_us: u32,
    /// The drum speed the feedback gives, r/min.
    measured: I16F16,
}

/// What the step estimated of the travel.
struct Estimate {
    /// The Hall estimator's update.
    m: kinematics::speed::TravelMeasurement,
    /// The travel speed (eq. 1–3), if the gear speed gives one.
    travel: Option<travel::TravelSpeed>,
    /// The travel speed shown, km/h × 1000.
    travel_kmh_x1000: u32,
    /// The travel speed integrated, m/s (U8F24 bits).
    travel_mps: u32,
    /// k3 at the drum's speed.
    k3: kinematics::units::Coefficient,
    /// The ground wheel's step (a wheel source), or `None` (the Hall gear).
    ground: Option<crate::ground::GroundStep>,
}

impl Supervisor {
    /// The time since the last control step, µs, from the Hall timer: the
    /// encoder delta is divided by the time it really took, so a control
    /// step released late (a busy CPU, an emulator's host) does not read as
    /// a speed change. The nominal period when there is no previous step, or
    /// when the timer disagrees with the schedule by more than ×4 either way
    /// (a timer fault must not scale the measurement).
    pub(super) fn elapsed_us(&self, now: Ticks) -> u32 {
        let nominal = self.hw.control_period_us;
        match self.last_step_at {
            Some(prev) => {
                let e = now.0.wrapping_sub(prev.0);
                if e >= nominal / 4 && e <= nominal.saturating_mul(4) {
                    e
                } else {
                    nominal
                }
            }
            None => nominal,
        }
    }

    /// Measured drum speed from the encoder delta over `elapsed_us`.
    pub(super) fn drum_speed_of(&self, counts: u16, elapsed_us: u32) -> I16F16 {
        // r/min = counts · 60 / (counts_per_rev · period): I16F16 bits.
        let num = i64::from(counts)
            .saturating_mul(60 * 65_536)
            .saturating_mul(1_000_000);
        let den =
            i64::from(self.hw.encoder_counts_per_drum_rev).saturating_mul(i64::from(elapsed_us));
        let bits = num.checked_div(den).unwrap_or(0);
        I16F16::from_bits(i32::try_from(bits).unwrap_or(i32::MAX))
    }

    /// The control step, once per control period.
    ///
    /// `now` is the Hall timer's time (1 MHz, extended); `drum_encoder` the
    /// free-running encoder counter.
    ///
    /// ```
    /// use hmi_proto::screen::{Command, DrumSpeed, Mode};
    /// use kinematics::units::Ticks;
    /// use supervisor::drum::{Alarm, Hardware, Supervisor};
    /// use supervisor::settings::Settings;
    ///
    /// let settings = Settings {
    ///     mode: Mode::Fixed,
    ///     fixed_drum_speed: DrumSpeed::new(2000).expect("20.00 r/min is in range"),
    ///     ..Settings::default()
    /// };
    /// let mut sup = Supervisor::new(Hardware::BOARD, settings).expect("default settings");
    /// sup.command(Command::Start);
    /// // First period, drum at rest as the drum model expects: no error, so
    /// // the output is the feed-forward alone, eq. 10 with TIM1's ARR 3599:
    /// // 20 / 44.7 × 3600 = 1610.74 → compare value 1611.
    /// let act = sup.control_step(Ticks(0), 0);
    /// assert!(act.driver_enabled);
    /// assert_eq!(act.ccr, 1611);
    /// // The encoder never moves: after more than 200 ms (21 periods of
    /// // 10 ms on the Hall timer's clock) without a count the drum is
    /// // stalled: PWM 0, latched alarm.
    /// for period in 2..=21 {
    ///     let act = sup.control_step(Ticks((period - 1) * 10_000), 0);
    ///     assert_eq!(act.ccr == 0, period == 21, "period {period}");
    /// }
    /// assert_eq!(sup.alarm(), Some(Alarm::DrumStall));
    /// ```
    #[inline(never)]
    pub fn control_step(&mut self, now: Ticks, drum_encoder: u16) -> Actuation {
        self.ensure_controller();
        self.snapshot.steps = self.snapshot.steps.wrapping_add(1);
        let sensed = self.sense(now, drum_encoder);
        let est = self.estimate(now, &sensed);
        let (target, too_fast) = self.plan_target(&est);
        self.warn(now, &est, too_fast);
        // The work switch up: the target ramps to rest (the pass's ramp).
        let target = self.work_ramp(target, sensed.elapsed_us);
        // The link's alarms first: one that latches stops the drum (also
        // an identification) in this very step.
        self.link_alarms(sensed.encoder_delta, sensed.elapsed_us);
        let actuation = self.control(&sensed, &est, target);
        self.report(now, &sensed, &est, target, actuation);
        actuation
    }

    /// Sense: the drum encoder's counts since the last step (forward only),
    /// the period's length, the feedback in use and the drum speed it gives.
    fn sense(&mut self, now: Ticks, drum_encoder: u16) -> Sensed {
        let delta = match self.last_encoder {
            // Forward only: a backwards jitter reads as standstill. With the
            // encoder reversed (A/B swapped, `Settings::drum_encoder_reversed`)
            // the delta is negated first, so that the drum turning forward
            // counts forward.
            Some(prev) => {
                let d = if self.settings.drum_encoder_reversed {
                    prev.wrapping_sub(drum_encoder)
                } else {
                    drum_encoder.wrapping_sub(prev)
                };
                if d > u16::MAX / 2 {
                    self.encoder_back = d.wrapping_neg();
                    0
                } else {
                    self.encoder_back = 0;
                    d
                }
            }
            None => 0,
        };
        self.last_encoder = Some(drum_encoder);
        self.phase.clear_events();
        let elapsed_us = self.elapsed_us(now);
        self.last_step_at = Some(now);
        let encoder_delta = delta;
        let delta = self.feedback_counts(encoder_delta, elapsed_us);
        self.link.bus = false;
        let measured = self.drum_speed_of(delta, elapsed_us);
        self.reported = smooth(self.reported, measured, REPORT_ALPHA);
        Sensed {
            encoder_delta,
            delta,
            elapsed_us,
            measured,
        }
    }

    /// Estimate: the travel speed (eq. 1–3, predicted across the gap since
    /// the last Hall edge), k3 at the drum's speed, the ground and belt
    /// positions of the phase loop.
    fn estimate(&mut self, now: Ticks, sensed: &Sensed) -> Estimate {
        // Travel speed (eq. 1–3).
        let m = self.estimator.update(now);
        let gear_speed = self.predictor.predict(&m, now);
        self.snapshot.measured_gear_rpm_x1000 = m.gear_speed.to_milli();
        self.snapshot.predicted_gear_rpm_x1000 = gear_speed.to_milli();
        let hall_travel = travel::travel_speed(gear_speed, &self.settings.calibration).ok();
        // The ground wheel, when it is the source (crate::ground): its speed
        // in place of the Hall gear's, as the gear speed that gives it with
        // k1 = k2 = 1 (eq. 7 then needs nothing else).
        let ground = self.ground_step(&m, hall_travel.as_ref(), sensed.elapsed_us);
        let travel = match ground {
            Some(g) if g.in_use != hmi_proto::screen::TravelSourceInUse::HallStandIn => {
                wheel_travel(g.speed_bits)
            }
            Some(g) => wheel_travel(g.speed_bits).or(hall_travel),
            None => hall_travel,
        };
        // Shown to a person: rounded to m/h. The distance below integrates
        // the speed itself.
        let travel_kmh_x1000 = travel
            .and_then(|t| t.travel_speed_kmh().ok())
            .map_or(0, |v| v.to_milli());
        let travel_mps = travel.map_or(0, |t| t.travel_speed.to_bits());

        // k3 at the drum speed these counts were turned at (measured, not
        // the target: the belt slips at the speed it turns, and after a Stop
        // the counts still coasting in keep the k3 of their own speed),
        // smoothed over a few periods ([`K3_SPEED_ALPHA`]), at the
        // coefficient's full precision.
        self.k3_speed = smooth(self.k3_speed, sensed.measured, K3_SPEED_ALPHA);
        let k3 = self.settings.calibration.k3_at(fix_to_rpm(self.k3_speed));
        // Positions for the phase loop: the ground while running, the belt
        // always (a coasting drum still moves partitions).
        self.phase.set_fine_ground(ground.is_some());
        if let (RunState::Running, Some(g)) = (self.run, ground) {
            self.phase.advance_ground_by(g.distance_nm, g.speed_bits);
        } else if self.run == RunState::Running {
            let k1k2 = travel.map(|t| crate::phase::k1k2_q30(t.k1, t.k2));
            // The ground moves on between edges at the M/T speed (the last
            // tooth gap's), not at the predictor's: the slope between two
            // single-gap estimates is mostly the gear's ±2 % tooth errors,
            // which the feed-forward can average but a position cannot
            // (docs/placement.md, "Positions").
            let raw = travel::travel_speed(m.gear_speed, &self.settings.calibration)
                .map_or(0, |t| t.travel_speed.to_bits());
            self.phase.advance_ground(
                self.teeth,
                self.pitches_q16,
                self.estimator.next_gap_pitches_q16(),
                m.since_edge_ticks,
                raw,
                k1k2,
            );
        }
        self.phase.advance_belt(sensed.delta, k3);
        Estimate {
            m,
            travel,
            travel_kmh_x1000,
            travel_mps,
            k3,
            ground,
        }
    }

    /// The travel source's step (crate::ground): the Hall side's view in,
    /// the wheel's ground (or its stand-in's) out; `None` with the Hall gear
    /// as the source.
    fn ground_step(
        &mut self,
        m: &kinematics::speed::TravelMeasurement,
        hall: Option<&travel::TravelSpeed>,
        elapsed_us: u32,
    ) -> Option<crate::ground::GroundStep> {
        // The Hall side's view only where the wheel is read: with the Hall
        // gear as the source the step only counts the wheel (calibration).
        let view = if !self.settings.ground_wheel.source.uses_wheel() {
            crate::ground::HallView::default()
        } else {
            crate::ground::HallView {
                teeth: self.teeth,
                pitches_q16: self.pitches_q16,
                travel_bits: hall.map_or(0, |t| t.travel_speed.to_bits()),
                track_bits: hall
                    .and_then(|t| travel::wheel_surface_speed(t.gear_speed).ok())
                    .map_or(0, |v| v.to_bits()),
                k1_q30: hall.map(|t| u64::from(t.k1.to_bits())),
                since_edge_us: if self.edges == 0 {
                    u32::MAX
                } else {
                    m.since_edge_ticks
                },
            }
        };
        let step = self.ground.step(
            &self.settings.ground_wheel,
            &view,
            self.hw.control_period_us,
            elapsed_us,
        );
        self.snapshot.track_slip_x10 = self.ground.slip_x10().filter(|_| step.is_some());
        self.snapshot.travel_source = self.ground.in_use();
        self.snapshot.wheel_counts = self.ground.wheel_counts();
        step
    }

    /// Plan: the drum target of the mode in force (Fixed, or eq. 7 times
    /// the motor coefficient plus the phase loop's correction), held at the
    /// drum's limit, and the *Too fast* warning if it was held.
    fn plan_target(&mut self, est: &Estimate) -> (I16F16, Option<Alarm>) {
        let mut too_fast = None;
        let target = match self.settings.mode {
            // Capped at the drive's n_max (a drive slower than the screen's
            // 44.70 r/min range cannot do more).
            Mode::Fixed => centi_to_fix(self.settings.fixed_drum_speed.raw()).min(self.law.n_max),
            Mode::SpeedAdaptive => {
                match est
                    .travel
                    .map(|t| self.plan.target(&t, &self.settings.calibration))
                {
                    Some(Ok(target)) => {
                        // Eq. 7 as asked (also beyond the plan's n_max)
                        // times the motor coefficient, then held at the
                        // drum's limit: the paper's 44.7 r/min, or a drive
                        // identified slower its own. (Holding eq. 7 at
                        // n_max before the coefficient ran the drum slow
                        // under a coefficient below 1.)
                        let asked = match target {
                            DrumTarget::Follow(c) => c.drum_speed,
                            DrumTarget::Saturated { requested, .. } => requested,
                        };
                        let n = rpm_to_fix(asked)
                            .saturating_mul_int(i32::from(self.settings.motor_coefficient.raw()))
                            .checked_div_int(100)
                            .unwrap_or(I16F16::ZERO);
                        let cap = self.drum_cap();
                        if n > cap {
                            too_fast = Some(Alarm::TooFast {
                                max_kmh_x100: self.max_travel_kmh_x100(),
                            });
                        }
                        let n = n.min(cap);
                        let distance_locked = self.settings.placement == Placement::DistanceLocked
                            && self.run == RunState::Running;
                        let correction = if distance_locked {
                            let c = self.phase.correction(n);
                            // Smoothed through the link, and while the Hall
                            // gaps read noisy (teeth not learnt yet): an
                            // unlearnt edge is up to ±2 % of a pitch off its
                            // place, and the ground's step there moved the
                            // drum by up to 3 % in one period (not before a
                            // pass's first plant: the drum catches up with
                            // it at up to +100 %, late if smoothed). Leaving
                            // it, the smoothing fades out over 0.5 s.
                            self.phase_alpha = if self.link_in_force.delays_control()
                                || (self.estimator.is_noisy() && self.phase.pass_started())
                            {
                                PHASE_SMOOTHING
                            } else {
                                self.phase_alpha.saturating_add(PHASE_FADE).min(I16F16::ONE)
                            };
                            self.phase_smoothed = smooth(self.phase_smoothed, c, self.phase_alpha);
                            self.phase_smoothed
                        } else {
                            self.phase.update_error();
                            self.phase_smoothed = I16F16::ZERO;
                            I16F16::ZERO
                        };
                        // The next edge is long overdue (four gaps: the tractor
                        // has come to rest, or the sensor died) and the next
                        // plant's place lies beyond that edge: the drum waits
                        // at rest for it, so that no plant leaves for a place
                        // the ground may never reach (on the decaying speed
                        // the belt crept on and dropped plants anywhere).
                        // And the next plant never leaves for a place
                        // beyond the ground known: the drum holds at its
                        // boundary (crate::phase, "Holding at the boundary").
                        // (Asked every period: it keeps track of the belt
                        // nearing the boundary.)
                        let near = self.phase.must_hold(self.k3_speed);
                        // The next edge more than `gaps` tooth periods late.
                        let overdue_by = |gaps: u32| {
                            est.m.state == MotionState::Decaying
                                && est.m.since_edge_ticks.checked_div(gaps).unwrap_or(0)
                                    > self.predictor.period
                        };
                        // Holding: two gaps late at a steady speed (no
                        // chassis stops that fast: the sensor may have
                        // died); four while the tractor slows, where a late
                        // edge is expected.
                        let hold_after = if self.predictor.slowing() { 4 } else { 2 };
                        let wait = (overdue_by(4) && self.phase.next_place_beyond_reach())
                            || (overdue_by(hold_after) && near);
                        if distance_locked && self.phase.partitions_left() > 0 && wait {
                            I16F16::ZERO
                        } else {
                            n.saturating_add(correction).max(I16F16::ZERO).min(cap)
                        }
                    }
                    _ => I16F16::ZERO,
                }
            }
        };
        (target, too_fast)
    }

    /// Supervise the travel: the *Too fast* and *No travel pulses*
    /// warnings, under the latched alarms.
    fn warn(&mut self, now: Ticks, est: &Estimate, too_fast: Option<Alarm>) {
        // The too-fast warning follows the speed (with the unit down: a
        // lifted unit plants nothing); latched alarms and the instability
        // warning stay.
        let too_fast = too_fast.filter(|_| self.unit_down());
        // No travel pulses: the Hall silent for NO_PULSES_US since the last
        // edge, or since the watch began (Start, a lowering,
        // Speed-Adaptive chosen), with the drum running in Speed-Adaptive
        // and the unit down. Before it (and otherwise) the watch restarts.
        let watching = self.run == RunState::Running
            && self.settings.mode == Mode::SpeedAdaptive
            && self.unit_down();
        if !watching {
            self.quiet_from = now.0;
        }
        let since_edge = if self.edges == 0 {
            u32::MAX
        } else {
            est.m.since_edge_ticks
        };
        // With the ground wheel: its silence (alone), or the silence of
        // both (with the Hall gear: either one turning is travel).
        let source = self.settings.ground_wheel.source;
        let wheel_quiet = self
            .ground
            .wheel_silent_periods()
            .saturating_mul(self.hw.control_period_us);
        let since_pulse = match source {
            TravelSource::HallGear => since_edge,
            TravelSource::GroundWheel => wheel_quiet,
            TravelSource::Both => since_edge.min(wheel_quiet),
        };
        let quiet = since_pulse.min(now.0.wrapping_sub(self.quiet_from));
        let ground_fault = est.ground.and(self.ground.fault()).map(|f| match f {
            GroundFault::WheelStopped => Alarm::GroundWheelStopped,
            GroundFault::WheelBackwards => Alarm::GroundWheelBackwards {
                alone: source == TravelSource::GroundWheel,
            },
            GroundFault::HallStopped => Alarm::HallGearStopped,
        });
        let warning = if watching && quiet > NO_PULSES_US {
            Some(if source == TravelSource::HallGear {
                Alarm::NoTravelPulses
            } else {
                Alarm::NoWheelPulses
            })
        } else if ground_fault.is_some() {
            ground_fault
        } else {
            too_fast
        };
        match (self.alarm, warning) {
            (Some(a), _) if a.is_latched() || a == Alarm::DrumUnstable => {}
            (_, Some(w)) if w.is_latched() && self.run == RunState::Running => self.latch(w),
            (_, Some(w)) if self.run == RunState::Running => self.alarm = Some(w),
            (
                Some(
                    Alarm::TooFast { .. }
                    | Alarm::NoTravelPulses
                    | Alarm::NoWheelPulses
                    | Alarm::GroundWheelStopped
                    | Alarm::GroundWheelBackwards { .. }
                    | Alarm::HallGearStopped,
                ),
                _,
            ) => self.alarm = None,
            _ => {}
        }
    }

    /// Control: the identification's duty, or, running, the faults that stop
    /// the drum (stall, lost Hall signal), the reference model, the
    /// instability supervisor and the controller's output.
    fn control(&mut self, s: &Sensed, est: &Estimate, target: I16F16) -> Actuation {
        let mut actuation = Actuation::OFF;
        if self.run == RunState::Identifying {
            actuation = self.identify_step(s.measured, s.delta, s.elapsed_us);
        }
        if self.run == RunState::Running {
            // Fault: drum commanded but not turning (with both feedbacks:
            // neither turning; the encoder alone still is the cross-check's).
            let stalled = self.stall_watch(
                target >= STALL_MIN_COMMAND && s.delta == 0 && !self.driver_turning(),
                s.elapsed_us,
            );
            // Fault: in Speed-Adaptive mode, the next Hall edge is later
            // than any stop the chassis can make allows. Without such
            // evidence the silence is a stop: the estimator's speed decays
            // to zero and the drum with it.
            // (With a ground wheel the Hall gear is not the source: its
            // silence is the cross-check's, crate::ground.)
            let hall_lost = self.settings.mode == Mode::SpeedAdaptive
                && est.ground.is_none()
                && self
                    .estimator
                    .next_edge_overdue(est.m.since_edge_ticks, &self.hall_silence);
            if let Some(alarm) = stalled {
                self.latch(alarm);
            } else if hall_lost {
                self.latch(Alarm::HallLost);
            } else {
                // What the measurement should read from the feed-forward
                // alone; then advance the model with the target of
                // `ref_delay − 1` periods ago (the drive's dead time).
                let expected = self.reference;
                // The read-back as feedback is older by its age: the model's
                // input is delayed by as many periods more.
                let back = self
                    .law
                    .ref_delay
                    .saturating_sub(2)
                    .saturating_add(self.readback_delay_periods())
                    .min(REF_HISTORY - 1);
                let delayed = self
                    .ref_history
                    .get(
                        self.ref_head
                            .wrapping_add(REF_HISTORY)
                            .wrapping_sub(back)
                            .checked_rem(REF_HISTORY)
                            .unwrap_or(0),
                    )
                    .map_or(target, |&v| I16F16::from_bits(i32::from(v) << 8));
                self.reference = smooth(self.reference, delayed, self.law.ref_alpha);
                self.push_reference_input(target);
                let saturated = self.snapshot.ccr == 0
                    || u32::from(self.snapshot.ccr) > u32::from(self.hw.pwm_arr);
                if !self.fallback
                    && self
                        .monitor
                        .step(expected, s.measured, target, s.elapsed_us, saturated)
                {
                    self.fall_back();
                }
                let out = match &mut self.drum {
                    Drum::Control(c) => c.step(expected, s.measured, target),
                    Drum::Unbuilt | Drum::Identify(_) => I16F16::ZERO,
                };
                actuation = self.drum_output(out);
            }
        }
        if self.run != RunState::Running {
            // Restart from the drum's actual speed (it may still coast).
            self.reference = s.measured;
            self.ref_history = [to_i16_x256(s.measured); REF_HISTORY];
            self.monitor = Monitor::default();
        }
        actuation
    }

    /// Report: the counts, the snapshot for the screen and the log, the
    /// ground distance and the plants that left.
    fn report(
        &mut self,
        now: Ticks,
        s: &Sensed,
        est: &Estimate,
        target: I16F16,
        actuation: Actuation,
    ) {
        self.belt_counts_k3 = self
            .belt_counts_k3
            .saturating_add(u64::from(s.delta).wrapping_mul(u64::from(est.k3.to_bits())));
        self.drum_counts_total = self.drum_counts_total.saturating_add(u64::from(s.delta));
        self.snapshot.travel_speed_kmh_x1000 = est.travel_kmh_x1000;
        self.snapshot.target_drum_rpm_x1000 = if self.run == RunState::Running {
            milli(target)
        } else {
            0
        };
        self.snapshot.actual_drum_rpm_x1000 = milli(self.reported);
        self.snapshot.ccr = actuation.ccr;
        if self.link.bus {
            // The Modbus command path: the PWM is 0; the log and the
            // instability supervisor see the equivalent duty.
            self.snapshot.ccr = self.link.bus_ccr;
        }
        self.snapshot.hall_edges = self.edges;
        let partitions_x1e6 = self.partitions_x1e6();
        self.snapshot.plants = u32::try_from(partitions_x1e6 / 1_000_000).unwrap_or(u32::MAX);
        if let (RunState::Running, Some(g)) = (self.run, est.ground) {
            // The ground wheel's distance (its stand-in's), nm; the
            // remainder below a µm carried.
            let nm = g.distance_nm.saturating_add(self.distance_frac);
            self.distance_um = self.distance_um.wrapping_add(nm / 1000);
            self.distance_frac = nm % 1000;
        } else if self.run == RunState::Running {
            // ∫ V1 dt: m/s (U8F24) · µs = µm · 2²⁴, the fraction (< 2²⁴)
            // carried: < 2⁶⁴. µm since Start wrap after 1.8·10¹³ m.
            let acc = u64::from(est.travel_mps)
                .wrapping_mul(u64::from(s.elapsed_us))
                .wrapping_add(self.distance_frac);
            self.distance_um = self.distance_um.wrapping_add(acc >> 24);
            self.distance_frac = acc & 0xFF_FFFF;
        }
        self.snapshot.distance_mm = u32::try_from(self.distance_um / 1000).unwrap_or(u32::MAX);
        self.count_plants(
            partitions_x1e6,
            (self.teeth, self.last_tooth_at),
            now.0,
            s.elapsed_us,
        );
    }

    /// With both feedbacks: the driver's read-back says the drum turns (at
    /// least the cross-check's floor, 1 r/min), so a still encoder is the
    /// cross-check's alarm, not a stall.
    /// One period of the stall watch: `still`, the drum commanded shows no
    /// forward motion. The alarm once the stall time is over: turning
    /// backwards if it did for more than half of it
    /// ([`Alarm::DrumBackwards`]; the first period after Start has no
    /// encoder difference yet), else [`Alarm::DrumStall`].
    pub(super) fn stall_watch(&mut self, still: bool, elapsed_us: u32) -> Option<Alarm> {
        if !still {
            self.stall_us = 0;
            return None;
        }
        if self.stall_us == 0 {
            self.stall_back_us = 0;
        }
        if self.turning_backwards() {
            self.stall_back_us = self.stall_back_us.saturating_add(elapsed_us);
        }
        self.stall_us = self.stall_us.saturating_add(elapsed_us);
        (self.stall_us > STALL_TIME_US).then_some(if self.stall_back_us > self.stall_us / 2 {
            Alarm::DrumBackwards
        } else {
            Alarm::DrumStall
        })
    }

    /// The feedback in force moved against the drum's direction this
    /// period: the encoder (alone or with the driver) by
    /// [`BACKWARD_MIN_COUNTS`], the driver's read-back below −1 r/min.
    pub(super) fn turning_backwards(&self) -> bool {
        if self.link_in_force.feedback == crate::drive_link::FeedbackSource::Driver
            && self.link_in_use()
        {
            self.link
                .readback_milli_rpm(self.link_in_force.readback_max_age_us())
                .is_some_and(|n| i64::from(n) < -drive_link::cross_check::MARGIN_FLOOR_MILLI_RPM)
        } else {
            self.encoder_back >= BACKWARD_MIN_COUNTS
        }
    }

    pub(super) fn driver_turning(&self) -> bool {
        self.link_in_force.feedback == crate::drive_link::FeedbackSource::Both
            && self
                .link
                .readback_milli_rpm(self.link_in_force.readback_max_age_us())
                .is_some_and(|n| i64::from(n) > drive_link::cross_check::MARGIN_FLOOR_MILLI_RPM)
    }

    /// The drum's output for the controller's `out` (r/min): the PWM
    /// compare value, or with the Modbus command path the driver's speed
    /// command (PWM 0).
    pub(super) fn drum_output(&mut self, out: I16F16) -> Actuation {
        let ccr = self.ccr_of(out);
        if self.link_in_force.command == crate::drive_link::CommandPath::Modbus {
            self.link.bus_command = i32::try_from(milli(out)).unwrap_or(i32::MAX);
            self.link.bus_ccr = ccr;
            self.link.bus = true;
            Actuation {
                ccr: 0,
                driver_enabled: true,
            }
        } else {
            Actuation {
                ccr,
                driver_enabled: true,
            }
        }
    }

    pub(super) fn push_reference_input(&mut self, target: I16F16) {
        self.ref_head = self
            .ref_head
            .wrapping_add(1)
            .checked_rem(REF_HISTORY)
            .unwrap_or(0);
        if let Some(slot) = self.ref_history.get_mut(self.ref_head) {
            *slot = to_i16_x256(target);
        }
    }

    /// Eq. 10 with the drive model's gain: the compare value for `out`
    /// r/min, `out / n_max · (ARR + 1)`, rounded, within 0 … ARR + 1.
    pub(super) fn ccr_of(&self, out: I16F16) -> u16 {
        let arr1 = i64::from(self.hw.pwm_arr).saturating_add(1);
        let ccr = i64::from(out.to_bits())
            .max(0)
            .saturating_mul(arr1)
            .saturating_mul(100)
            .checked_div(i64::from(self.law.n_max_x100))
            .unwrap_or(0)
            .saturating_add(1 << 15)
            >> 16;
        u16::try_from(ccr.min(arr1)).unwrap_or(0)
    }
}
#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]
mod tests {
    use super::*;
    use hmi_proto::screen::DrumSpeed;
    use proptest::prelude::*;

    /// A commissioning error: the drum turns (20 r/min fixed: 157 counts a
    /// period) but the encoder counts backwards (A/B swapped, or the motor
    /// wired the wrong way). Before, this latched "Drum stalled or encoder
    /// lost" and sent the technician looking for a jam; now the alarm says
    /// backwards, after the same 200 ms, outputs off. With the encoder
    /// direction setting reversed the same counts run the drum; a still
    /// drum whose encoder jitters one count back is a stall.
    #[test]
    fn an_encoder_counting_backwards_is_named_not_a_stall() {
        use hmi_proto::screen::Mode;
        let run = |reversed: bool, per_period: i32| {
            let settings = Settings {
                mode: Mode::Fixed,
                fixed_drum_speed: DrumSpeed::new(2000).unwrap(),
                drum_encoder_reversed: reversed,
                ..Settings::default()
            };
            let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
            sup.command(Command::Start);
            let mut encoder: u16 = 30_000;
            let mut alarm_at = None;
            let mut act = Actuation::OFF;
            for period in 0..50u32 {
                act = sup.control_step(Ticks(period * 10_000), encoder);
                if alarm_at.is_none() && sup.alarm().is_some() {
                    alarm_at = Some(period);
                }
                // A jitter of one count back every other period.
                let step = if per_period == -1 && period % 2 == 1 {
                    0
                } else {
                    per_period
                };
                encoder = encoder.wrapping_add_signed(step as i16);
            }
            (sup.alarm(), alarm_at, act)
        };
        let (alarm, at, act) = run(false, -157);
        assert_eq!(alarm, Some(Alarm::DrumBackwards));
        // 200 ms of stall time, counted from the first step: 21 periods.
        assert_eq!(at, Some(20));
        assert_eq!(act, Actuation::OFF);
        let mut text = heapless::String::<40>::new();
        Alarm::DrumBackwards.write_text(&mut text).unwrap();
        assert_eq!(text.as_str(), "Drum turns backwards: check direction");
        assert_eq!(run(true, -157).0, None);
        assert_eq!(run(false, -1).0, Some(Alarm::DrumStall));
        assert_eq!(run(false, 0).0, Some(Alarm::DrumStall));
    }

    /// Speed-Adaptive at a constant travel speed (one Hall edge every
    /// 90 ms: ≈ 26.7 r/min at the gear, ≈ 1 km/h), speed-following
    /// placement; returns the drum target of the last step (r/min) and the
    /// alarm.
    #[allow(clippy::arithmetic_side_effects)]
    fn adaptive_target(spacing_mm: i32, coefficient: i32) -> (f64, Option<Alarm>) {
        use hmi_proto::screen::{MotorCoefficient, Spacing};
        let settings = Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(spacing_mm).unwrap(),
            motor_coefficient: MotorCoefficient::new(coefficient).unwrap(),
            placement: Placement::SpeedFollowing,
            ..Settings::default()
        };
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        let mut next_edge = 5_000u32;
        for period in 0..300u32 {
            let now = period * 10_000;
            while next_edge <= now {
                sup.hall_edge(Ticks(next_edge));
                next_edge += 90_000;
            }
            // The drum follows its target (no stall alarm).
            let n = f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0;
            encoder = encoder.wrapping_add((n / 60.0 * 47_200.0 * 0.01).round() as u16);
            sup.control_step(Ticks(now), encoder);
        }
        (
            f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0,
            sup.alarm(),
        )
    }

    /// docs/firmware.md, control step 3: the target is eq. 7 *times the
    /// motor coefficient*, held at `n_max` (with the warning) only when that
    /// product exceeds it. Eq. 7 is inversely proportional to the spacing,
    /// so eq. 7 at 7 cm is twice eq. 7 at 14 cm (k3 is flat at 0.980 above
    /// 25 r/min, Table 13 clamped): at ≈ 26 r/min for 14 cm, eq. 7 at 7 cm
    /// asks ≈ 52 r/min, beyond 44.7; with a coefficient of 0.80 the drum
    /// must run at 0.80 × 52 ≈ 41.6 r/min, within `n_max`, without a
    /// warning. Before: eq. 7 was held at 44.7 first, then × 0.80 = 35.76
    /// r/min (14 % slow: plants 16 % too far apart) under a *Too fast*
    /// warning.
    #[test]
    fn the_motor_coefficient_applies_before_the_n_max_limit() {
        let (n14, alarm) = adaptive_target(140, 100);
        assert_eq!(alarm, None);
        assert!(n14 > 25.0 && n14 < 27.0, "{n14}");
        let (n7, alarm) = adaptive_target(70, 80);
        let expected = 0.8 * 2.0 * n14;
        assert!((n7 - expected).abs() < 0.02, "{n7} vs {expected}");
        assert_eq!(alarm, None);
        // A coefficient of 1.20 at 14 cm (≈ 31 r/min) still follows …
        let (n, alarm) = adaptive_target(140, 120);
        assert!((n - 1.2 * n14).abs() < 0.02, "{n}");
        assert_eq!(alarm, None);
        // … and at 7 cm (≈ 62 r/min) is held at n_max with the warning.
        let (n, alarm) = adaptive_target(70, 120);
        assert!((n - 44.7).abs() < 0.01, "{n}");
        // The maximum shown is the speed at which 1.20 × eq. 7 reaches
        // 44.7 r/min: V = k3·n_max·π·0.070 m/60 · X/Lclap / 1.20 =
        // 0.980 · 44.7 · 0.219 911 / 60 · 1.4 / 1.2 = 0.1873 m/s =
        // 0.674 km/h (hand-computed; Table 13's k3 clamped at 0.980).
        assert!(
            matches!(
                alarm,
                Some(Alarm::TooFast {
                    max_kmh_x100: 66..=68
                })
            ),
            "{alarm:?}"
        );
    }

    /// The work switch up (the unit lifted on the headland or between
    /// rows): the drum ramps to rest and nothing is planted, so no travel
    /// speed is too fast for the spacing and the *Too fast* warning (page
    /// 2) stays down; lowered at the same speed, it comes up. Edges every
    /// 40 ms (2.26 km/h at the gear) against the ≈ 0.81 km/h 7 cm allows.
    /// Before: the warning stood the whole headland.
    #[test]
    #[allow(clippy::arithmetic_side_effects)]
    fn a_lifted_unit_raises_no_too_fast_warning() {
        use hmi_proto::screen::Spacing;
        let settings = Settings {
            mode: Mode::SpeedAdaptive,
            spacing: Spacing::new(70).unwrap(),
            work_switch_fitted: true,
            ..Settings::default()
        };
        let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
        sup.command(Command::Start);
        let mut encoder: u16 = 0;
        let mut next_edge = 5_000u32;
        for period in 0..400u32 {
            let now = period * 10_000;
            // Lowered for the last second.
            sup.set_work_switch(period >= 300);
            while next_edge <= now {
                sup.hall_edge(Ticks(next_edge));
                next_edge += 40_000;
            }
            let n = f64::from(sup.snapshot().target_drum_rpm_x1000) / 1000.0;
            encoder = encoder.wrapping_add((n / 60.0 * 47_200.0 * 0.01).round() as u16);
            sup.control_step(Ticks(now), encoder);
            if period == 299 {
                assert_eq!(sup.alarm(), None);
            }
        }
        assert!(
            matches!(sup.alarm(), Some(Alarm::TooFast { .. })),
            "{:?}",
            sup.alarm()
        );
    }

    proptest! {
        /// Fixed mode, every drum speed the screen accepts (0–44.70 r/min):
        /// the target in the snapshot (log) and on the screen is the set
        /// speed itself (r/min × 100 from the screen, × 10 for the log).
        #[test]
        fn every_fixed_drum_speed_is_reported_as_set(raw in DrumSpeed::MIN..=DrumSpeed::MAX) {
            let settings = Settings {
                mode: Mode::Fixed,
                fixed_drum_speed: DrumSpeed::new(i32::from(raw)).unwrap(),
                ..Settings::default()
            };
            let mut sup = Supervisor::new(Hardware::BOARD, settings).unwrap();
            sup.command(Command::Start);
            sup.control_step(Ticks(0), 0);
            prop_assert_eq!(sup.snapshot().target_drum_rpm_x1000, u32::from(raw) * 10);
            prop_assert_eq!(sup.screen_status().target_drum_rpm_x100, raw);
        }
    }
}
