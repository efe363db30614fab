//! The drum machine as the screen shows it.

use super::*;

impl Supervisor {
    /// The status as the screen shows it.
    #[inline(never)]
    pub fn screen_status(&self) -> screen::Status {
        let s = self.snapshot;
        // Thousandths to hundredths for a person: rounded.
        let x100 = |v: u32| u16::try_from(v.saturating_add(5) / 10).unwrap_or(u16::MAX);
        let (measured_distance_cm, calibration_result_x1000) = match self.calibration_run {
            CalibrationRun::Measured {
                edges,
                drum_counts,
                wheel_counts,
                ..
            } => {
                let um = match self.calibration_kind {
                    // The wheel's counts at its counts per metre in force.
                    CalibrationKind::GroundWheel => u64::try_from(wheel_counts)
                        .unwrap_or(0)
                        .saturating_mul(1_000_000_000)
                        .checked_div(u64::from(self.settings.ground_wheel.counts_per_m_x1000))
                        .unwrap_or(0),
                    // The Hall teeth counted, as track.
                    CalibrationKind::SpeedK1 | CalibrationKind::SlipK2 => {
                        u64::from(edges).saturating_mul(EDGE_UM)
                    }
                    // The belt the drum turns imply: π·0.070 m per turn.
                    CalibrationKind::BeltK3 => drum_counts
                        .saturating_mul(BELT_PER_DRUM_TURN_UM)
                        .checked_div(u64::from(self.hw.encoder_counts_per_drum_rev))
                        .unwrap_or(0),
                };
                (u32::try_from(um / 10_000).unwrap_or(u32::MAX), 0)
            }
            CalibrationRun::Computed { k, .. } => {
                (0, u16::try_from(coefficient_milli(k)).unwrap_or(u16::MAX))
            }
            CalibrationRun::WheelComputed { counts_per_m_x1000 } => {
                (0, wheel_factor_milli(counts_per_m_x1000))
            }
            _ => (0, 0),
        };
        // The model measured (until saved) or the one in force.
        let q = self.quality_since_start();
        let shown_drive = match self.identify_state() {
            IdentifyState::Done(model) => model,
            _ => self.settings.drive,
        };
        screen::Status {
            travel_speed_kmh_x100: x100(s.travel_speed_kmh_x1000),
            target_drum_rpm_x100: x100(s.target_drum_rpm_x1000),
            actual_drum_rpm_x100: x100(s.actual_drum_rpm_x1000),
            plants: s.plants,
            distance_dm: s.distance_mm / 100,
            measured_distance_cm,
            calibration_result_x1000,
            drive_n_max_x100: shown_drive.n_max_x100(),
            drive_tau_x10_ms: shown_drive.tau_x10_ms(),
            drive_dead_time_x10_ms: shown_drive.dead_time_x10_ms(),
            drive_identification: match self.identify_state() {
                IdentifyState::Idle => 0,
                IdentifyState::Running => 1,
                IdentifyState::Done(_) => 2,
                IdentifyState::Failed(_) => 3,
            },
            quality_of_feed_x10: q.quality_of_feed_x10,
            multiples_x10: q.multiples_x10,
            misses_x10: q.misses_x10,
            precision_cv_x10: q.cv_x10,
            within_10_pct_x10: q.within_10_pct_x10,
            plants_per_m_x100: u16::try_from(q.plants_per_m_x100).unwrap_or(u16::MAX),
            track_slip_x10: s.track_slip_x10.unwrap_or(screen::SLIP_UNKNOWN),
            travel_source_in_use: s.travel_source,
            // Profile B's live values: not this machine's.
            ..screen::Status::default()
        }
    }
}

/// The ground wheel's counts per metre as a factor of the nominal wheel's,
/// thousandths, rounded (page 4 shows it as the wheel's coefficient).
fn wheel_factor_milli(counts_per_m_x1000: u32) -> u16 {
    let n = u64::from(crate::settings::wheel::NOMINAL_COUNTS_PER_M_X1000);
    let m = u64::from(counts_per_m_x1000)
        .saturating_mul(1000)
        .saturating_add(n / 2)
        .checked_div(n)
        .unwrap_or(0);
    u16::try_from(m).unwrap_or(u16::MAX)
}

/// A coefficient in thousandths, rounded to the nearest (the screen's
/// unit): `Coefficient::to_milli` rounds down, and a value set from a
/// decimal (0.800 is 0.799 999 999 8 in 2⁻³⁰ steps) read one less.
fn coefficient_milli(k: kinematics::units::Coefficient) -> u32 {
    // bits < 2³², × 1000 < 2⁴².
    let m = (u64::from(k.to_bits())
        .saturating_mul(1000)
        .saturating_add(1 << 29))
        >> 30;
    u32::try_from(m).unwrap_or(u32::MAX)
}

impl Supervisor {
    /// The settings as the screen shows them (its own scaled integers); the
    /// calibration coefficient shown is the selected one (k1, k2 or k3) at
    /// the selected gear's speed (k3: at the Fixed-mode drum speed).
    pub fn screen_settings(&self) -> screen::Settings {
        let settings = &self.settings;
        let at = self.hand_set_abscissa();
        let k_x1000 = match self.calibration_kind {
            CalibrationKind::SpeedK1 => coefficient_milli(settings.calibration.k1.eval(at)),
            CalibrationKind::SlipK2 => coefficient_milli(settings.calibration.k2.eval(at)),
            CalibrationKind::BeltK3 => coefficient_milli(settings.calibration.k3.eval(at)),
            CalibrationKind::GroundWheel => {
                u32::from(wheel_factor_milli(settings.ground_wheel.counts_per_m_x1000))
            }
        };
        let k_x1000 = i32::try_from(k_x1000).unwrap_or(i32::MAX);
        screen::Settings {
            spacing: settings.spacing,
            fixed_drum_speed: settings.fixed_drum_speed,
            motor_coefficient: settings.motor_coefficient,
            gear: settings::gear_to_screen(settings.gear),
            calibration_coefficient: screen::CalibrationCoefficient::new(k_x1000)
                .unwrap_or_default(),
            calibration_distance: screen::CalibrationDistance::default(),
            brightness: settings.brightness,
            calibration_kind: self.calibration_kind,
            profile: settings::screen_profile(settings.profile),
            belt: settings::belt::belt_to_screen(&settings.belt),
            drum_encoder_reversed: settings.drum_encoder_reversed,
            work_switch_fitted: settings.work_switch_fitted,
            first_plant_distance: settings.first_plant_distance,
            speed_following: settings.placement == Placement::SpeedFollowing,
            link_parameter: self.link_parameter,
            link_value: settings.drive_link.value(self.link_parameter),
            travel_source: settings.ground_wheel.source,
            ground_wheel_reversed: settings.ground_wheel.reversed,
        }
    }
}
