//! The work switch and the live planting quality on the host: the supervisor
//! against the machine simulator, as the firmware's 10 ms task runs it.
//! Expected values come from the simulator's own plant drops (their true
//! ground positions) through an f64 form of the ISO 7256-1 indices written
//! here, never from the code under test.
#![allow(
    clippy::unwrap_used,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap,
    clippy::indexing_slicing
)]

use hmi_proto::screen::{Command, FirstPlantDistance, Mode, Spacing};
use kinematics::consts::Gear;
use kinematics::units::Ticks;
use machine_sim::{Config, Event, Inputs, Machine};
use supervisor::drum::work::WORK_RAMP_RPM_PER_S;
use supervisor::drum::{Actuation, Hardware, RunState, Supervisor};
use supervisor::settings::Settings;

const HW: Hardware = Hardware::BOARD;

struct Rig {
    sup: Supervisor,
    m: Machine,
    act: Actuation,
    /// Every plant dropped: (ground m, unit down when it dropped).
    drops: Vec<f64>,
}

impl Rig {
    fn new(settings: Settings) -> Self {
        Self::on(Config::noiseless(), settings)
    }

    /// On the machine `config` describes, at Low 2.
    fn on(config: Config, settings: Settings) -> Self {
        let config = Config {
            initial_gear: Some(Gear::Low2),
            ..config
        };
        Self {
            sup: Supervisor::new(HW, settings).unwrap(),
            m: config.build().unwrap(),
            act: Actuation::OFF,
            drops: Vec::new(),
        }
    }

    fn period(&mut self) {
        let inputs = Inputs {
            drum_duty: f32::from(self.act.ccr) / f32::from(HW.pwm_arr + 1),
            driver_enabled: self.act.driver_enabled,
            ..Inputs::default()
        };
        let sup = &mut self.sup;
        let drops = &mut self.drops;
        self.m.step_events(10_000, &inputs, &mut |e| match e {
            Event::HallEdge(t) => sup.hall_edge(Ticks(t)),
            Event::Plant { ground_m, .. } => drops.push(ground_m),
        });
        self.act = self
            .sup
            .control_step(Ticks(self.m.capture_ticks()), self.m.drum_encoder_count());
    }

    fn drive_to(&mut self, ground_m: f64) {
        while self.m.ground_position_m() < ground_m {
            self.period();
        }
    }
}

#[test]
fn a_lift_pauses_planting_and_the_quality_figures_match_the_drops() {
    // Noiseless: the control alone.
    lift_and_lower_cv_tolerance(Config::noiseless(), 0.5);
}

#[test]
fn with_terrain_load_and_sensor_noise_the_quality_figures_still_match_the_drops() {
    // Terrain, seedling load, tooth pitch errors, capture jitter, speed
    // ripple: the model's noise except what no sensor of the machine sees —
    // the landing scatter (the figures are the control's, not the
    // seedlings' fall) and the random variation of the track and belt slip
    // around their calibrated means (the Hall gear turns with the track,
    // the encoder with the drum: a slip change moves the true plant against
    // the measured ground unseen). With those on, the drops' CV here is
    // 1.1 % against the firmware's 0.6 %: that difference is the slip's,
    // not the figures'. With the distance-locked loop (issue 19) the drum
    // follows the Hall-edge ground, whose between-edge steps show in the
    // drops' CV (1.36 %) but not in the ∫V1 dt ground the figures use
    // (0.7 %): the CV gets 1 point here, the other indices 0.5.
    lift_and_lower_cv_tolerance(
        Config {
            plant_scatter_m: 0.0,
            track_slip_noise: 0.0,
            belt_slip_noise: 0.0,
            ..Config::default()
        },
        1.0,
    );
}

/// Speed-Adaptive, 7 cm, Low 2; work switch fitted, first plant 100 mm
/// after the lowering. Start at 2 m (the tractor at speed), lift at 10 m,
/// lower at 12 m, stop at 20 m.
fn lift_and_lower_cv_tolerance(config: Config, cv_tolerance: f64) {
    let x = 0.07;
    let settings = Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(70).unwrap(),
        gear: Gear::Low2,
        work_switch_fitted: true,
        first_plant_distance: FirstPlantDistance::new(100).unwrap(),
        ..Settings::default()
    };
    let mut rig = Rig::on(config, settings);
    rig.sup.set_work_switch(true);
    rig.drive_to(2.0);
    rig.sup.command(Command::Start);
    let start_m = rig.m.ground_position_m();
    rig.drive_to(10.0);
    let lift_m = rig.m.ground_position_m();
    let v_lift = f64::from(rig.m.travel_speed_m_s());
    rig.sup.set_work_switch(false);
    let first_pass = rig.sup.quality_since_start();
    rig.drive_to(12.0);
    assert_eq!(rig.sup.run_state(), RunState::Running, "no Start needed");
    let plants_lifted = rig.sup.snapshot().plants;
    let lower_m = rig.m.ground_position_m();
    rig.sup.set_work_switch(true);
    rig.drive_to(20.0);
    let shown = rig.sup.quality_since_start();
    let stop_m = rig.m.ground_position_m();
    rig.sup.command(Command::Stop);

    // The ramp: at WORK_RAMP_RPM_PER_S from the drum speed eq. 7 gives for
    // the true ground speed at the lift (f64 reference), then the drive's
    // 25 ms lag and the 30 ms debounce the firmware adds: at most one
    // partition can leave after the lift, within the ground the tractor
    // covers meanwhile.
    let v = v_lift;
    let ramp_s = machine_sim::reference::eq7_drum_speed(v, x) / f64::from(WORK_RAMP_RPM_PER_S);
    let ramp_ground = v * (ramp_s + 0.025 + 0.03);
    let in_ramp: Vec<f64> = rig
        .drops
        .iter()
        .copied()
        .filter(|&g| g >= lift_m && g < lower_m)
        .collect();
    println!("lift at {lift_m:.4} m: drops while up {in_ramp:?} (ramp {ramp_s:.3} s)");
    assert!(in_ramp.len() <= 1, "{in_ramp:?}");
    assert!(
        in_ramp.iter().all(|&g| g <= lift_m + ramp_ground),
        "{in_ramp:?} beyond {:.4} m",
        lift_m + ramp_ground
    );
    // The count paused: what the screen counts while up is the ramp's one
    // partition at most.
    assert!(rig.sup.snapshot().plants >= plants_lifted);

    // The two passes as the simulator dropped them.
    let pass1: Vec<f64> = rig
        .drops
        .iter()
        .copied()
        .filter(|&g| g >= start_m && g < lift_m)
        .collect();
    let pass2: Vec<f64> = rig
        .drops
        .iter()
        .copied()
        .filter(|&g| g >= lower_m && g < stop_m)
        .collect();
    // The first plant after the lowering at the set 100 mm from where the
    // switch closed (the firmware is told at once here: no debounce), ±5 %.
    let first_after = (pass2[0] - lower_m) * 1000.0;
    println!("first plant after the lowering: {first_after:.1} mm (set 100 mm)");
    assert!(
        (first_after - 100.0).abs() <= 5.0,
        "first plant {first_after:.1} mm after the lowering"
    );
    // Counts per pass against distance / X: within two plants (the pass's
    // start and end fractions).
    for (pass, from, to) in [(&pass1, start_m, lift_m), (&pass2, lower_m, stop_m)] {
        let expected = (to - from) / x;
        assert!(
            (pass.len() as f64 - expected).abs() <= 2.0,
            "{} plants over {:.3} m ({expected:.1} expected)",
            pass.len(),
            to - from
        );
    }
    // The supervisor's figures since Start against the drops, ±0.5
    // percentage points (the tolerance on the screen), the plant
    // count exactly (± the ramp's partition and the one in flight).
    let want = machine_sim::reference::iso_indices(&[pass1.clone(), pass2.clone()], x);
    let got = [
        shown.multiples_x10,
        shown.misses_x10,
        shown.quality_of_feed_x10,
        shown.cv_x10,
        shown.within_10_pct_x10,
    ]
    .map(|v| f64::from(v) / 10.0);
    println!("since Start: firmware {got:?} vs drops {want:?}");
    for (i, name) in ["D", "M", "A", "CV", "±10 %"].iter().enumerate() {
        let tolerance = if *name == "CV" { cv_tolerance } else { 0.5 };
        assert!(
            (got[i] - want[i]).abs() <= tolerance,
            "{name}: {} vs {}",
            got[i],
            want[i]
        );
    }
    let plants = (pass1.len() + pass2.len()) as i64;
    assert!(
        (i64::from(shown.plants) - plants).abs() <= 1,
        "{} vs {plants}",
        shown.plants
    );
    // The first pass's figures were final at the lift.
    assert_eq!(first_pass.plants as usize, pass1.len());
}

#[test]
fn without_a_work_switch_the_unit_counts_as_down() {
    // The default: no work switch fitted. The switch's input is ignored and
    // the machine plants from Start to Stop.
    let mut rig = Rig::new(Settings {
        mode: Mode::SpeedAdaptive,
        gear: Gear::Low2,
        ..Settings::default()
    });
    assert!(rig.sup.unit_down());
    rig.drive_to(1.0);
    rig.sup.command(Command::Start);
    rig.sup.set_work_switch(false);
    assert!(rig.sup.unit_down());
    let from = rig.drops.len();
    rig.drive_to(3.0);
    // 2 m at 7 cm: 28.6 plants.
    let n = rig.drops.len() - from;
    assert!((27..=30).contains(&n), "{n}");
    assert!(rig.sup.quality_since_start().plants >= 27);
}

/// A work switch contact with its bounce: closed (unit down) or open, each
/// change bouncing for 40 ms with toggles 0.2–5 ms apart (seeded), then
/// settled; read at any microsecond.
struct Contact {
    /// (time µs, closed after it) of every toggle, in order.
    toggles: Vec<(u64, bool)>,
}

impl Contact {
    fn new() -> Self {
        Self {
            toggles: vec![(0, false)],
        }
    }

    /// The contact settles `closed` at `at_us` after 40 ms of bounce.
    fn change(&mut self, at_us: u64, closed: bool, rng: &mut u64) {
        let mut t = at_us;
        let mut level = closed;
        while t < at_us + 40_000 {
            self.toggles.push((t, level));
            // xorshift: 0.2–5 ms to the next toggle.
            *rng ^= *rng << 13;
            *rng ^= *rng >> 7;
            *rng ^= *rng << 17;
            t += 200 + *rng % 4_800;
            level = !level;
        }
        self.toggles.push((at_us + 40_000, closed));
    }

    /// A clean opening from `at_us` for `us` (a bump lifting the frame).
    fn open_for(&mut self, at_us: u64, us: u64) {
        self.toggles.push((at_us, false));
        self.toggles.push((at_us + us, true));
    }

    /// When the contact last went from closed to open (its last bounce
    /// before it settled open).
    fn last_opening(&self) -> u64 {
        self.toggles
            .windows(2)
            .rev()
            .find(|w| w[0].1 && !w[1].1)
            .map_or(0, |w| w[1].0)
    }

    fn closed(&self, t_us: u64) -> bool {
        self.toggles
            .iter()
            .rev()
            .find(|(at, _)| *at <= t_us)
            .is_some_and(|&(_, c)| c)
    }
}

/// The work switch as the firmware reads it (sampled every 10 ms, debounced,
/// then given to the supervisor), on bouncing transitions (0.2–5 ms toggles
/// for 40 ms, seed 19), at 7 cm and Low 2 on the default terrain without
/// landing scatter (seed 8): lowered at 2 m, an 80 ms opening at 8 m (a
/// bump), lifted at 12 m and lowered 1.5 m later (a stone: within the row),
/// Stop at 20 m. Expected: exactly one pass per real lowering (two), none
/// for the bump or the bounces; every plant after the lift (the contact's
/// opening) drops within the documented bound: from the contact's last
/// bounce to open, the lift time plus a period plus the ramp (the drum's
/// target when the lift is confirmed / 250 r/min per s) plus the drive's
/// 30 ms (docs/firmware.md, "Work switch"); and the hole the lift leaves in
/// the row, from the last plant before it to the first after the
/// lowering, counts as a miss in the figures since Start, which match the
/// drops (f64 reference over the passes and that gap). Before, the bump
/// was a lift and a lowering (three passes) and its 146–151 mm hole (2.1 X)
/// was counted nowhere.
#[test]
fn a_bouncing_switch_and_a_bump_give_one_pass_per_lowering_and_the_hole_is_a_miss() {
    // Lifts at five places between two plants, so that plants fall due
    // while each lift is confirmed.
    let mut after_lift = 0;
    for k in 0..5 {
        after_lift += bouncing_row(12.0 + 0.014 * f64::from(k), 8, 19);
    }
    assert!(
        after_lift > 0,
        "no plant fell due while a lift was confirmed"
    );
}

/// The same rows on seeds the case above does not use: the machine's
/// terrain (seeds 2, 5, 6) and the contact's bounces (seeds 3, 11, 42), the
/// lift at five places between two plants.
#[test]
fn a_bouncing_switch_on_unseen_rows_gives_one_pass_per_lowering_within_the_bound() {
    for machine in [2u64, 5, 6] {
        for bounces in [3u64, 11, 42] {
            for k in 0..5 {
                bouncing_row(12.0 + 0.014 * f64::from(k) + 0.003, machine, bounces);
            }
        }
    }
}

/// One row of [`a_bouncing_switch_and_a_bump_give_one_pass_per_lowering_and_the_hole_is_a_miss`]
/// with the lift at `lift_at_m`, the machine's seed `machine` and the
/// bounces' seed `bounces`; the plants that dropped after the contact
/// opened.
fn bouncing_row(lift_at_m: f64, machine: u64, bounces: u64) -> usize {
    use supervisor::work_switch::{WorkChange, WorkSwitch, WORK_LIFT_CONFIRM_US};
    let x = 0.07;
    let settings = Settings {
        mode: Mode::SpeedAdaptive,
        spacing: Spacing::new(70).unwrap(),
        gear: Gear::Low2,
        work_switch_fitted: true,
        first_plant_distance: FirstPlantDistance::new(100).unwrap(),
        ..Settings::default()
    };
    let mut rig = Rig::on(
        Config {
            seed: machine,
            plant_scatter_m: 0.0,
            ..Config::default()
        },
        settings,
    );
    let mut ws = WorkSwitch::new();
    let mut contact = Contact::new();
    let mut rng = bounces;
    let mut lowered = 0;
    let mut lifted = 0;
    // The drum's target when the lift was confirmed (r/min): the ramp to
    // rest starts there.
    let mut confirmed_rpm = 0.0;
    // Drop times, for the bound after the lift.
    let mut drop_times: Vec<(f64, u64)> = Vec::new();
    let mut period = |rig: &mut Rig, contact: &Contact, ws: &mut WorkSwitch| {
        let before = rig.drops.len();
        rig.period();
        let now = rig.m.now_us();
        for &g in &rig.drops[before..] {
            drop_times.push((g, now));
        }
        // The firmware samples the pin at the start of each period.
        match ws.sample(contact.closed(now), 10_000) {
            Some(WorkChange::Lowered) => lowered += 1,
            Some(WorkChange::Lifted) => {
                lifted += 1;
                confirmed_rpm = f64::from(rig.sup.snapshot().target_drum_rpm_x1000) / 1000.0;
            }
            None => {}
        }
        rig.sup.set_work_switch(ws.is_down());
    };
    rig.sup.command(Command::Start);
    while rig.m.ground_position_m() < 2.0 {
        period(&mut rig, &contact, &mut ws);
    }
    let lower1_m = rig.m.ground_position_m();
    contact.change(rig.m.now_us(), true, &mut rng);
    while rig.m.ground_position_m() < 8.0 {
        period(&mut rig, &contact, &mut ws);
    }
    contact.open_for(rig.m.now_us(), 80_000);
    while rig.m.ground_position_m() < lift_at_m {
        period(&mut rig, &contact, &mut ws);
    }
    let (lift_m, lift_us) = (rig.m.ground_position_m(), rig.m.now_us());
    let v = f64::from(rig.m.travel_speed_m_s());
    contact.change(lift_us, false, &mut rng);
    // The lift's 200 ms count from the contact's last bounce to open.
    let settled_us = contact.last_opening();
    assert!((lift_us..=lift_us + 40_000).contains(&settled_us));
    while rig.m.ground_position_m() < lift_m + 1.5 {
        period(&mut rig, &contact, &mut ws);
    }
    let lower2_m = rig.m.ground_position_m();
    contact.change(rig.m.now_us(), true, &mut rng);
    while rig.m.ground_position_m() < 20.0 {
        period(&mut rig, &contact, &mut ws);
    }
    let stop_m = rig.m.ground_position_m();
    let shown = rig.sup.quality_since_start();
    rig.sup.command(Command::Stop);
    println!("lowered {lowered}, lifted {lifted}");
    assert_eq!((lowered, lifted), (2, 1), "one pass per real lowering");

    // After the lift: the last plant within the bound, the ramp from the
    // drum's target when the lift was confirmed (eq. 7 at the speed then,
    // with the phase loop's correction: up to 110 % of it).
    assert!(confirmed_rpm > 0.0);
    println!(
        "drum at the confirmation {confirmed_rpm:.2} r/min (eq. 7 at the lift's speed {:.2})",
        machine_sim::reference::eq7_drum_speed(v, x)
    );
    let ramp_s = confirmed_rpm / f64::from(WORK_RAMP_RPM_PER_S);
    let bound_us = (settled_us - lift_us) as f64
        + f64::from(WORK_LIFT_CONFIRM_US)
        + 10_000.0
        + (ramp_s + 0.03) * 1e6;
    let late: Vec<f64> = drop_times
        .iter()
        .filter(|&&(g, t)| g >= lift_m && g < lower2_m && t > lift_us)
        .map(|&(_, t)| (t - lift_us) as f64 / 1e3)
        .collect();
    println!(
        "drops after the contact first opened: {late:?} ms (bound {:.0} ms: settled open \
         after {} ms)",
        bound_us / 1e3,
        (settled_us - lift_us) / 1000
    );
    assert!(late.iter().all(|&ms| ms * 1e3 <= bound_us), "{late:?}");
    assert!(late.len() <= 2, "{late:?}");

    // The figures since Start against the drops: the two passes (the
    // plants while the lift was confirmed belong to the first) and the hole.
    let last_up = drop_times
        .iter()
        .filter(|&&(g, _)| g < lower2_m)
        .map(|&(g, _)| g)
        .fold(f64::MIN, f64::max);
    let pass1: Vec<f64> = rig
        .drops
        .iter()
        .copied()
        .filter(|&g| g >= lower1_m && g <= last_up)
        .collect();
    let pass2: Vec<f64> = rig
        .drops
        .iter()
        .copied()
        .filter(|&g| g >= lower2_m && g < stop_m)
        .collect();
    let hole = pass2[0] - pass1[pass1.len() - 1];
    println!(
        "hole across the lift: {:.1} mm ({:.2} X)",
        hole * 1e3,
        hole / x
    );
    assert!(hole > 1.5 * x);
    let mut all = pass1.clone();
    all.extend(&pass2);
    // As one pass, the hole is one of its spacings (a miss).
    let want = machine_sim::reference::iso_indices(&[all], x);
    let got_m = f64::from(shown.misses_x10) / 10.0;
    println!(
        "since Start: misses {got_m} % (drops {:.2} %), plants {} vs {}",
        want[1],
        shown.plants,
        pass1.len() + pass2.len()
    );
    assert!(
        got_m > 0.0 && (got_m - want[1]).abs() <= 0.5,
        "{got_m} vs {}",
        want[1]
    );
    // The count: every plant of the two passes, but those that left after
    // the contact opened may not count (the unit is up once the lift is
    // confirmed: not planted), and the figures may still wait for the
    // newest one (they are live one tooth gap late).
    let dropped = (pass1.len() + pass2.len()) as i64;
    let shown_plants = i64::from(shown.plants);
    assert!(
        (dropped - late.len() as i64 - 1..=dropped).contains(&shown_plants),
        "{shown_plants} shown, {dropped} dropped, {} after the contact opened",
        late.len()
    );
    late.len()
}
