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
                edges, drum_counts, ..
            } => {
                let um = match self.calibration_kind {
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
            // Profile B's live values: not this machine's.
            ..screen::Status::default()
        }
    }
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
        let table = match self.calibration_kind {
            CalibrationKind::SpeedK1 => &settings.calibration.k1,
            CalibrationKind::SlipK2 => &settings.calibration.k2,
            CalibrationKind::BeltK3 => &settings.calibration.k3,
        };
        let k_x1000 = i32::try_from(coefficient_milli(table.eval(at))).unwrap_or(i32::MAX);
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
        }
    }
}
