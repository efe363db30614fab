//! Eq. 7 and eq. 10 against hand-computed values, and the whole chain
//! against an independent f64 model (proptest).
#![allow(
    clippy::arithmetic_side_effects,
    clippy::unwrap_used,
    clippy::float_arithmetic,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)]

use kinematics::drum::{DrumSettings, DrumTarget};
use kinematics::table::CoeffTable;
use kinematics::travel::{gear_speed_for, travel_speed, Calibration, PAPER_K1, PAPER_K2, PAPER_K3};
use kinematics::units::{Coefficient, KilometresPerHour, Metres, MetresPerSecond, RevPerMin};
use proptest::prelude::*;

fn cal_k3(k3: f64) -> Calibration {
    Calibration {
        k3: CoeffTable::constant(Coefficient::from_f64(k3).unwrap()).unwrap(),
        ..Calibration::identity()
    }
}

/// (spacing m, n_teeth r/min, k2, k3, ARR, hand n_roll, hand CCR).
/// n_roll = k2/k3 · (0.2/0.07) · (0.05/L) · n_teeth, CCR = round(n_roll/44.7 · (ARR+1)) ≤ ARR+1:
/// 1. 2.857143·0.714286·10 = 20.40816; 20.40816/44.7·1000 = 456.56 → 457
/// 2. 2.857143·0.277778·20 = 15.87302; ·1000/44.7 = 355.10 → 355
/// 3. 0.972/0.993 = 0.978852; ·2.857143·1·8.2 = 22.93310; ·3600/44.7 = 1846.96 → 1847
/// 4. 0.95·2.857143·0.5·30 = 40.71429; ·100/44.7 = 91.08 → 91
/// 5. 2.857143·1.666667·5 = 23.80952; ·65536/44.7 = 34907.85 → 34908
/// 6. 1/0.98·2.857143·0.2·100 = 58.30904 > n_max; 1304.45 → capped at ARR+1 = 1000
/// 7. 0.966/0.986 = 0.979716; ·2.857143·0.416667·12.5 = 14.57911; ·2000/44.7 = 652.31 → 652
const CASES: [(f64, f64, f64, f64, u16, f64, u16); 7] = [
    (0.07, 10.0, 1.0, 1.0, 999, 20.40816, 457),
    (0.18, 20.0, 1.0, 1.0, 999, 15.87302, 355),
    (0.05, 8.2, 0.972, 0.993, 3599, 22.93310, 1847),
    (0.10, 30.0, 0.95, 1.0, 99, 40.71429, 91),
    (0.03, 5.0, 1.0, 1.0, 65535, 23.80952, 34908),
    (0.25, 100.0, 1.0, 0.98, 999, 58.30904, 1000),
    (0.12, 12.5, 0.966, 0.986, 1999, 14.57911, 652),
];

#[test]
fn eq7_and_eq10_hand_computed() {
    for (l, n, k2, k3, arr, n_roll, ccr) in CASES {
        let plan = DrumSettings::new(Metres::from_f64(l).unwrap(), arr)
            .build()
            .unwrap();
        let got = plan
            .drum_speed(
                RevPerMin::from_f64(n).unwrap(),
                Coefficient::from_f64(k2).unwrap(),
                &cal_k3(k3),
            )
            .unwrap();
        // 2e-5 relative: the spacing is stored to 1 µm (9e-6 relative at 3 cm).
        assert!(
            (got.to_f64() - n_roll).abs() / n_roll < 2e-5,
            "n_roll for {l} m: {got}"
        );
        assert_eq!(plan.ccr(got).unwrap(), ccr, "CCR for {l} m");
    }
}

#[test]
fn feasibility_limits_of_the_spec() {
    // SPEC §3: 7 cm caps travel at about 0.83 km/h, 18 cm at about 2.1 km/h.
    // With k3 = 1: π·0.07·44.7/60·(L/0.05)·3.6 = 0.8259 (7 cm), 2.1237 (18 cm) km/h.
    for (l, vmax) in [(0.07, 0.8259), (0.18, 2.1237)] {
        let plan = DrumSettings::new(Metres::from_f64(l).unwrap(), 999)
            .build()
            .unwrap();
        let got = plan
            .max_travel_speed(&Calibration::identity())
            .unwrap()
            .to_f64();
        assert!((got - vmax).abs() < 1e-3, "{l}: {got}");
    }
    // Just above the limit saturates with the limit attached; just below follows.
    let plan = DrumSettings::new(Metres::from_f64(0.07).unwrap(), 999)
        .build()
        .unwrap();
    let cal = Calibration::identity();
    let at = |kmh: f64| {
        let v = KilometresPerHour::from_f64(kmh).unwrap().to_mps().unwrap();
        plan.target(
            &travel_speed(gear_speed_for(v).unwrap(), &cal).unwrap(),
            &cal,
        )
        .unwrap()
    };
    assert!(matches!(at(0.82), DrumTarget::Follow(_)));
    match at(0.84) {
        DrumTarget::Saturated {
            max_travel_speed,
            command,
            requested,
        } => {
            assert!((max_travel_speed.to_f64() - 0.8259).abs() < 1e-3);
            assert_eq!(command.ccr, 1000);
            assert!(requested.to_f64() > 44.7);
        }
        DrumTarget::Follow(_) => panic!("0.84 km/h at 7 cm must saturate"),
    }
}

#[test]
fn settings_are_validated() {
    assert!(DrumSettings::new(Metres::from_f64(0.005).unwrap(), 999)
        .build()
        .is_err());
    assert!(DrumSettings::new(Metres::from_f64(1.5).unwrap(), 999)
        .build()
        .is_err());
    let mut s = DrumSettings::new(Metres::from_f64(0.07).unwrap(), 999);
    s.n_max = RevPerMin::ZERO;
    assert!(s.build().is_err());
}

// ---------------------------------------------------------------- f64 model

fn parse_table(t: &[(&str, &str)]) -> Vec<(f64, f64)> {
    t.iter()
        .map(|(x, k)| (x.parse().unwrap(), k.parse().unwrap()))
        .collect()
}

/// Piecewise-linear, clamped (the SPEC §4 decision).
fn interp(t: &[(f64, f64)], x: f64) -> f64 {
    if x <= t[0].0 {
        return t[0].1;
    }
    for w in t.windows(2) {
        if x < w[1].0 {
            return w[0].1 + (w[1].1 - w[0].1) * (x - w[0].0) / (w[1].0 - w[0].0);
        }
    }
    t[t.len() - 1].1
}

struct Model {
    n_teeth: f64,
    v1: f64,
    n_roll: f64,
    ccr: f64,
    vmax_kmh: f64,
    per_min: f64,
}

/// Paper A eq. 2, 3, 7, 10 in f64 from a monitored speed (km/h).
fn model(v_mon_kmh: f64, spacing: f64, arr: u16) -> Model {
    let (k1t, k2t, k3t) = (
        parse_table(&PAPER_K1),
        parse_table(&PAPER_K2),
        parse_table(&PAPER_K3),
    );
    let circ = std::f64::consts::PI * 0.2;
    let n_raw = v_mon_kmh / 3.6 * 60.0 / circ;
    let n_teeth = interp(&k1t, v_mon_kmh) * n_raw;
    let wheel = circ * n_teeth / 60.0;
    let k2 = interp(&k2t, wheel * 3.6);
    let v1 = k2 * wheel;
    // Solve n·k3(n) = u to convergence (independent of the crate's 2 iterations).
    let u = k2 * (0.2 / 0.07) * (0.05 / spacing) * n_teeth;
    let mut n = u;
    for _ in 0..50 {
        n = u / interp(&k3t, n);
    }
    let ccr = (n / 44.7 * (f64::from(arr) + 1.0))
        .round()
        .min(f64::from(arr) + 1.0);
    let vmax =
        interp(&k3t, 44.7) * std::f64::consts::PI * 0.07 * 44.7 / 60.0 * spacing / 0.05 * 3.6;
    Model {
        n_teeth,
        v1,
        n_roll: n,
        ccr,
        vmax_kmh: vmax,
        per_min: 60.0 * v1 / spacing,
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-12)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn chain_matches_f64_model(kmh in 0.1f64..5.0, cm in 3.0f64..50.0, arr in 99u16..=4999) {
        let spacing = cm / 100.0;
        let m = model(kmh, spacing, arr);
        let cal = Calibration::paper_defaults();
        let v = KilometresPerHour::from_f64(kmh).unwrap().to_mps().unwrap();
        let t = travel_speed(gear_speed_for(v).unwrap(), &cal).unwrap();
        prop_assert!(rel(t.gear_speed.to_f64(), m.n_teeth) <= 1e-3);
        prop_assert!(rel(t.travel_speed.to_f64(), m.v1) <= 1e-3);
        let plan = DrumSettings::new(Metres::from_f64(spacing).unwrap(), arr).build().unwrap();
        let n = plan.drum_speed(t.gear_speed, t.k2, &cal).unwrap();
        prop_assert!(rel(n.to_f64(), m.n_roll) <= 1e-3, "n_roll {} vs {}", n, m.n_roll);
        let ccr = f64::from(plan.ccr(n).unwrap());
        // 1e-3 relative, or the one count a rounding boundary can flip.
        prop_assert!((ccr - m.ccr).abs() <= (m.ccr * 1e-3).max(1.0), "ccr {ccr} vs {}", m.ccr);
        prop_assert!(rel(plan.max_travel_speed(&cal).unwrap().to_f64(), m.vmax_kmh) <= 1e-3);
        prop_assert!(rel(plan.plants_per_minute(t.travel_speed).unwrap().to_f64(), m.per_min) <= 1e-3);
        let target = plan.target(&t, &cal).unwrap();
        prop_assert_eq!(target.is_saturated(), m.n_roll > 44.7 + 1e-6 || (n.to_f64() > 44.7));
        if !target.is_saturated() {
            prop_assert!(rel(target.command().duty.to_f64(), m.n_roll / 44.7) <= 1e-3);
        }
    }

    #[test]
    fn conversions_never_panic(bits in any::<u32>(), arr in any::<u16>(), mm in any::<u32>()) {
        let cal = Calibration::paper_defaults();
        let _ = travel_speed(RevPerMin::from_bits(bits), &cal);
        let _ = KilometresPerHour::from_bits(bits).to_mps();
        let _ = MetresPerSecond::from_bits(bits).to_kmh();
        if let Ok(plan) = DrumSettings::new(Metres::from_mm(mm), arr).build() {
            let _ = plan.drum_speed(RevPerMin::from_bits(bits), Coefficient::from_bits(bits), &cal);
            let _ = plan.ccr(RevPerMin::from_bits(bits));
        }
    }
}
