//! The on-screen calibration of k1, k2 and k3 (page 4).

use super::*;
use crate::settings::wheel::NOMINAL_COUNTS_PER_M_X1000;

impl Supervisor {
    /// Page 4: chooses the coefficient (k1, k2 or k3) to calibrate.
    pub(super) fn select_calibration(&mut self, kind: CalibrationKind) -> Effect {
        self.calibration_kind = kind;
        self.calibration_run = CalibrationRun::Idle;
        Effect::SettingsChanged
    }

    /// Page 4: a calibration run starts counting.
    pub(super) fn calibration_start(&mut self) -> Effect {
        self.calibration_run = CalibrationRun::Counting {
            start_edges: self.edges,
            start_steps: self.snapshot.steps,
            start_drum_counts: self.drum_counts_total,
            start_wheel_counts: self.ground.wheel_counts(),
        };
        Effect::None
    }

    /// Page 4: the calibration run stops counting.
    pub(super) fn calibration_stop(&mut self) -> Effect {
        if let CalibrationRun::Counting {
            start_edges,
            start_steps,
            start_drum_counts,
            start_wheel_counts,
        } = self.calibration_run
        {
            self.calibration_run = CalibrationRun::Measured {
                edges: self.edges.wrapping_sub(start_edges),
                steps: self.snapshot.steps.wrapping_sub(start_steps),
                drum_counts: self.drum_counts_total.saturating_sub(start_drum_counts),
                wheel_counts: self
                    .ground
                    .wheel_counts()
                    .saturating_sub(start_wheel_counts),
            };
        }
        Effect::None
    }

    /// Page 4: a coefficient typed by hand, at the selected gear's speed.
    /// For the ground wheel it is the wheel's counts per metre as a factor
    /// of the nominal wheel's (0.800–1.200: within the ±20 % a calibration
    /// run may give).
    pub(super) fn set_coefficient_by_hand(&mut self, k: screen::CalibrationCoefficient) -> Effect {
        if self.calibration_kind == CalibrationKind::GroundWheel {
            let v = u64::from(NOMINAL_COUNTS_PER_M_X1000)
                .saturating_mul(u64::from(k.raw()))
                .saturating_add(500)
                / 1000;
            return match u32::try_from(v)
                .ok()
                .map(crate::settings::wheel::checked_counts)
            {
                Some(Ok(v)) => {
                    self.settings.ground_wheel.counts_per_m_x1000 = v;
                    Effect::SettingsChanged
                }
                _ => Effect::Message("Coefficient rejected"),
            };
        }
        let k = kinematics::units::Coefficient::from_ratio(u32::from(k.raw()), 1000);
        let at = self.hand_set_abscissa();
        match k.map(|k| self.set_table_point(self.calibration_kind, at, k)) {
            Some(Ok(())) => Effect::SettingsChanged,
            _ => Effect::Message("Coefficient rejected"),
        }
    }

    /// Where a coefficient typed by hand goes in its table: at the selected
    /// gear's monitored (k1) or actual (k2) speed, at the Fixed-mode drum
    /// speed (k3).
    pub(super) fn hand_set_abscissa(&self) -> U16F16 {
        let gear = self.settings.gear;
        match self.calibration_kind {
            CalibrationKind::SpeedK1 => gear.monitored().table_x(),
            CalibrationKind::SlipK2 => gear.actual().table_x(),
            CalibrationKind::GroundWheel => U16F16::ZERO,
            CalibrationKind::BeltK3 => {
                U16F16::saturating_from_num(self.settings.fixed_drum_speed.raw())
                    .checked_div_int(100)
                    .unwrap_or(U16F16::ZERO)
            }
        }
    }

    /// Duration of `steps` control periods, µs, in `u64`: a calibration
    /// run of paper A's 400 m at Low 1 lasts 4645 s, beyond the 4295 s of
    /// a `u32`.
    pub(super) fn run_us(&self, steps: u32) -> u64 {
        u64::from(steps).saturating_mul(u64::from(self.hw.control_period_us))
    }

    /// The coefficient of the selected kind from the last run and the taped
    /// length (docs/hmi.md page 4).
    pub(super) fn compute_coefficient(&mut self, taped_cm: u32) -> Effect {
        let CalibrationRun::Measured {
            edges,
            steps,
            drum_counts,
            wheel_counts,
        } = self.calibration_run
        else {
            return Effect::Message("Run a calibration first");
        };
        if self.calibration_kind == CalibrationKind::GroundWheel {
            use crate::settings::wheel::{calibrate, WheelCalibrationError as E};
            return match calibrate(wheel_counts, taped_cm.saturating_mul(10)) {
                Ok(counts_per_m_x1000) => {
                    self.calibration_run = CalibrationRun::WheelComputed { counts_per_m_x1000 };
                    Effect::None
                }
                Err(E::NoPulses) => Effect::Message(WHEEL_NO_PULSES_TEXT),
                Err(E::Backwards) => Effect::Message(WHEEL_BACKWARDS_RUN_TEXT),
                Err(E::OutOfTolerance(_)) => Effect::Message(WHEEL_TOLERANCE_TEXT),
            };
        }
        let us = self.run_us(steps);
        let taped_um = taped_cm.saturating_mul(10_000);
        let kind = self.calibration_kind;
        let result = match kind {
            CalibrationKind::SlipK2 => {
                // k2 = taped / (wheel turns · π·0.20 m), turns = edges / Z1.
                let turns = U16F16::checked_from_num(edges)
                    .and_then(|e| e.checked_div_int(u32::from(consts::Z1)));
                let ms = u32::try_from(us / 1000).unwrap_or(u32::MAX);
                let time = kinematics::units::Seconds::from_ratio(ms, 1000);
                let distance = Metres::from_mm(taped_cm.saturating_mul(10));
                turns.zip(time).and_then(|(turns, time)| {
                    kinematics::calib::k2_from_wheel_turns(turns, distance, time)
                        .ok()
                        .map(|r| (r.wheel_speed.table_x(), r.k2))
                })
            }
            CalibrationKind::SpeedK1 => {
                // Speeds in m/h (km/h × 1000): µm / µs · 3600.
                let mph = |um: u64| u32::try_from(um.saturating_mul(3_600).checked_div(us)?).ok();
                let monitored = mph(u64::from(edges).saturating_mul(EDGE_UM));
                let actual = mph(u64::from(taped_um));
                monitored.zip(actual).and_then(|(monitored, actual)| {
                    let monitored =
                        kinematics::units::KilometresPerHour::from_ratio(monitored, 1000)?;
                    let actual = kinematics::units::KilometresPerHour::from_ratio(actual, 1000)?;
                    // k1 takes what k2 does not explain, so that the shown
                    // travel speed (k2·k1·monitored) equals the taped speed.
                    let k2 = self.settings.calibration.k2_at(monitored).to_fixed();
                    let corrected = kinematics::units::KilometresPerHour::from_fixed(
                        monitored
                            .to_fixed()
                            // U2F30 → U10F22: drop 8 fractional bits
                            // (rounding down, as `fixed`'s conversion); k2 < 4
                            // always fits.
                            .saturating_mul(fixed::types::U10F22::from_bits(k2.to_bits() >> 8)),
                    );
                    kinematics::calib::k1_from_speeds(actual, corrected)
                        .ok()
                        .map(|r| (monitored.table_x(), r.k1))
                })
            }
            // Handled above.
            CalibrationKind::GroundWheel => None,
            CalibrationKind::BeltK3 => {
                // Mean drum speed: counts · 60 / (counts per turn · s).
                let rpm_x1000 = drum_counts
                    .saturating_mul(60_000_000_000)
                    .checked_div(u64::from(self.hw.encoder_counts_per_drum_rev).saturating_mul(us))
                    .and_then(|v| u32::try_from(v).ok());
                // µm / µs = m/s, U8F24 bits (taped_um < 2³⁰: no overflow).
                let belt = (u64::from(taped_um) << 24)
                    .checked_div(us)
                    .and_then(|bits| u32::try_from(bits).ok())
                    .map(kinematics::units::MetresPerSecond::from_bits);
                rpm_x1000
                    .and_then(|n| RevPerMin::from_ratio(n, 1000))
                    .zip(belt)
                    .and_then(|(n, belt)| {
                        kinematics::calib::k3_from_belt_test(n, belt)
                            .ok()
                            .map(|r| (n.table_x(), r.k3))
                    })
            }
        };
        match result {
            Some((at, k)) => {
                self.calibration_run = CalibrationRun::Computed { kind, at, k };
                Effect::None
            }
            None => Effect::Message("Calibration run too short"),
        }
    }

    pub(super) fn accept_coefficient(&mut self) -> Effect {
        if let CalibrationRun::WheelComputed { counts_per_m_x1000 } = self.calibration_run {
            self.settings.ground_wheel.counts_per_m_x1000 = counts_per_m_x1000;
            self.calibration_run = CalibrationRun::Idle;
            return Effect::SettingsChanged;
        }
        let CalibrationRun::Computed { kind, at, k } = self.calibration_run else {
            return Effect::Message("Nothing to accept");
        };
        match self.set_table_point(kind, at, k) {
            Ok(()) => {
                self.calibration_run = CalibrationRun::Idle;
                Effect::SettingsChanged
            }
            Err(()) => Effect::Message("Coefficient out of range 0.8-1.2"),
        }
    }

    /// Puts `(at, k)` into the table of `kind`: replaces the point nearest to
    /// `at` when within 0.05 (km/h or r/min), otherwise inserts it (a table
    /// holds at most 8 points; the validated table is built before anything
    /// changes, so a rejected point changes nothing).
    pub(super) fn set_table_point(
        &mut self,
        kind: CalibrationKind,
        x: U16F16,
        k: kinematics::units::Coefficient,
    ) -> Result<(), ()> {
        let cal = &mut self.settings.calibration;
        let table = match kind {
            CalibrationKind::SpeedK1 => &mut cal.k1,
            CalibrationKind::SlipK2 => &mut cal.k2,
            CalibrationKind::BeltK3 => &mut cal.k3,
            CalibrationKind::GroundWheel => return Err(()),
        };
        let near = const { U16F16::lit("0.05") };
        let mut points: heapless::Vec<TablePoint, 8> = heapless::Vec::new();
        let mut placed = false;
        for p in table.points() {
            if !placed && p.x.abs_diff(x) <= near {
                points.push(TablePoint::new(x, k)).map_err(|_| ())?;
                placed = true;
            } else if !placed && p.x > x {
                points.push(TablePoint::new(x, k)).map_err(|_| ())?;
                points.push(*p).map_err(|_| ())?;
                placed = true;
            } else {
                points.push(*p).map_err(|_| ())?;
            }
        }
        if !placed {
            points.push(TablePoint::new(x, k)).map_err(|_| ())?;
        }
        *table = CoeffTable::new(&points).map_err(|_| ())?;
        Ok(())
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

    /// A coefficient typed on page 4 is shown back as typed, over the
    /// whole range the screen accepts (0.800–1.200, docs/hmi.md), for each
    /// table. Before: `Coefficient` holds 0.800 as 0.799 999 99… (2⁻³⁰
    /// steps) and the screen value was its thousandths rounded *down*:
    /// 1.200 showed 1.199, 0.980 showed 0.979, and 0.800 read 799, outside
    /// the screen's range, so the screen showed the default 1.000.
    #[test]
    fn a_coefficient_set_on_the_screen_is_shown_as_set() {
        use hmi_proto::screen::CalibrationCoefficient;
        let mut sup = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
        for kind in [
            CalibrationKind::SpeedK1,
            CalibrationKind::SlipK2,
            CalibrationKind::BeltK3,
        ] {
            sup.command(Command::SelectCalibration(kind));
            for v in [800, 801, 980, 993, 1000, 1031, 1199, 1200] {
                let k = CalibrationCoefficient::new(v).unwrap();
                assert_eq!(
                    sup.command(Command::SetCalibrationCoefficient(k)),
                    Effect::SettingsChanged
                );
                assert_eq!(
                    sup.screen_settings().calibration_coefficient.raw(),
                    v as u16,
                    "{kind:?}"
                );
            }
        }
    }

    /// Paper A's own k2 procedure (Table 12, SPEC §4) at Low 1: 400 m
    /// taped, 655.08 wheel turns (16 377 Hall edges) in 4645.16 s — longer
    /// than the 4295 s a `u32` of µs holds. Expected (Table 12, by hand):
    /// k2 = 400 / (655.08 · π · 0.20) = 0.9719, at the wheel speed
    /// 3.6 · 411.61 / 4645.16 = 0.3190 km/h (`PAPER_K2`'s abscissa). Before,
    /// the run's duration saturated at 4295 s: the point went in at
    /// 0.345 km/h, 8 % off. The k1 and k3 runs shared the duration.
    #[test]
    #[allow(clippy::arithmetic_side_effects)]
    fn a_calibration_run_longer_than_71_minutes_keeps_its_duration() {
        use hmi_proto::screen::CalibrationDistance;
        let mut sup = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
        sup.command(Command::SelectCalibration(CalibrationKind::SlipK2));
        let steps = 464_516u32; // 4645.16 s of 10 ms periods
        let gap = 4_645_160_000u64 / 16_377; // µs per Hall edge
        let mut next_edge = 0u64;
        sup.control_step(Ticks(0), 0);
        sup.command(Command::CalibrationStart);
        for period in 1..=steps {
            let now = u64::from(period) * 10_000;
            while next_edge + gap <= now {
                next_edge += gap;
                sup.hall_edge(Ticks(next_edge as u32));
            }
            sup.control_step(Ticks(now as u32), 0);
        }
        sup.command(Command::CalibrationStop);
        let CalibrationRun::Measured {
            edges, steps: s, ..
        } = sup.calibration_run()
        else {
            panic!("{:?}", sup.calibration_run());
        };
        assert_eq!((edges, s), (16_377, steps));
        sup.command(Command::CalibrationActualDistance(
            CalibrationDistance::new(40_000).unwrap(),
        ));
        let CalibrationRun::Computed { at, k, .. } = sup.calibration_run() else {
            panic!("{:?}", sup.calibration_run());
        };
        let k2 = 400.0 / (655.08 * core::f64::consts::PI * 0.20);
        assert!((k.to_f64() - k2).abs() < 0.0005, "k2 {}", k.to_f64());
        let v = 3.6 * 16_377.0 / 25.0 * core::f64::consts::PI * 0.20 / 4645.16;
        assert!((at.to_num::<f64>() - v).abs() < 0.002, "at {at} vs {v}");
    }

    /// Page 4: a coefficient typed by hand (0.800–1.200, docs/hmi.md §4)
    /// and taken is shown back as typed, for each kind. Measured before the
    /// fix: 0.800 was taken and the screen then showed 1.000 (0.8 in U2F30
    /// is 1 bit below 0.8, `to_milli` rounds down to 799, out of range,
    /// and the screen got the default), and 0.801 showed 0.800.
    #[test]
    fn every_hand_set_coefficient_is_shown_as_typed() {
        let mut wrong = std::vec::Vec::new();
        for kind in [
            CalibrationKind::SpeedK1,
            CalibrationKind::SlipK2,
            CalibrationKind::BeltK3,
        ] {
            for raw in 800..=1200 {
                let mut sup = Supervisor::new(Hardware::BOARD, Settings::default()).unwrap();
                sup.command(Command::SelectCalibration(kind));
                let k = screen::CalibrationCoefficient::new(raw).unwrap();
                let effect = sup.command(Command::SetCalibrationCoefficient(k));
                let shown = sup.screen_settings().calibration_coefficient.raw();
                if effect != Effect::SettingsChanged || i32::from(shown) != raw {
                    wrong.push((kind, raw, effect, shown));
                }
            }
        }
        assert!(
            wrong.is_empty(),
            "{} wrong, e.g. {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(4)]
        );
    }
}
