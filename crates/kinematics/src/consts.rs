//! Machine constants of SPEC §2–4 (profile A), each as a typed fixed-point
//! value for the firmware and as an `f64` (`*_F64`) for host references and
//! the machine simulator, plus the six gear presets (paper A Tables 11–12).
//!
//! ```
//! use kinematics::consts::{self, Gear};
//! // One Hall pulse is 25.13 mm of track: π·(D1 + 2·H1) / Z1.
//! let pulse_mm = consts::ROLLING_CIRCUMFERENCE_M_F64 / f64::from(consts::Z1) * 1000.0;
//! assert!((pulse_mm - 25.13).abs() < 0.01);
//! assert_eq!(Gear::Low2.preset().k2_f64, 0.966);
//! ```

use crate::units::{Coefficient, KilometresPerHour, Metres, RevPerMin};

/// Teeth on the Hall speed-measuring gear (paper A Table 10).
pub const Z1: u8 = 25;
/// Track drive wheel root diameter D1, metres.
pub const D1_F64: f64 = 0.16;
/// Track thickness H1, metres.
pub const H1_F64: f64 = 0.02;
/// Effective track wheel diameter D1 + 2·H1, metres.
pub const WHEEL_EFFECTIVE_DIAMETER_F64: f64 = D1_F64 + 2.0 * H1_F64;
/// Rolling circumference π·(D1 + 2·H1) = 0.6283 m.
pub const ROLLING_CIRCUMFERENCE_M_F64: f64 = core::f64::consts::PI * WHEEL_EFFECTIVE_DIAMETER_F64;
/// Drum diameter D2, metres.
pub const D2_F64: f64 = 0.060;
/// Belt thickness H2, metres.
pub const H2_F64: f64 = 0.005;
/// Effective drum diameter D2 + 2·H2, metres.
pub const DRUM_EFFECTIVE_DIAMETER_F64: f64 = D2_F64 + 2.0 * H2_F64;
/// Belt partition (clapboard) pitch Lclap, metres.
pub const L_CLAP_F64: f64 = 0.05;
/// Drum motor maximum speed in normal operation (drum shaft), r/min.
pub const N_MAX_F64: f64 = 44.7;
/// Drum motor rated speed (drum shaft), r/min.
pub const N_RATED_F64: f64 = 25.21;
/// Drum motor gearbox ratio.
pub const DRUM_GEAR_RATIO: u8 = 118;
/// Capture timer tick rate (1 MHz on the board), Hz.
pub const CAPTURE_TIMER_HZ: u32 = 1_000_000;
/// Largest pulse rate the NPN Hall proximity switch supports, Hz.
pub const HALL_MAX_HZ: u32 = 1_000;
/// Track per Hall edge, µm: `π·(D1 + 2·H1) / Z1` = π·0.20 m / 25 = 25 132.7 µm
/// (SPEC §2), rounded.
pub const HALL_GAP_UM: u32 = 25_133;
/// The fastest a tracked chassis can slow down, mm/s² of track speed: 1 g.
///
/// Without skidding the track rolls with the ground, so its speed can drop
/// only as fast as friction decelerates the machine, `μ·g`. Rubber tracks
/// reach a friction coefficient of about 0.5–0.8 on field soil and about
/// 0.8–0.9 on dry concrete; μ = 1 is above every surface the machine works
/// on (docs/kinematics.md, "Hall silence"). A track that locks and skids is
/// not a normal stop.
pub const CHASSIS_DECEL_LIMIT_MM_S2: u32 = 9_810;
/// MCU system clock (paper A eq. 1 `Hclk`), Hz.
pub const HCLK_HZ: u32 = 72_000_000;

/// D1 as a typed value.
pub const D1: Metres = Metres::lit("0.16");
/// H1 as a typed value.
pub const H1: Metres = Metres::lit("0.02");
/// D1 + 2·H1 as a typed value.
pub const WHEEL_EFFECTIVE_DIAMETER: Metres = Metres::lit("0.20");
/// D2 as a typed value.
pub const D2: Metres = Metres::lit("0.060");
/// H2 as a typed value.
pub const H2: Metres = Metres::lit("0.005");
/// D2 + 2·H2 as a typed value.
pub const DRUM_EFFECTIVE_DIAMETER: Metres = Metres::lit("0.070");
/// Lclap as a typed value.
pub const L_CLAP: Metres = Metres::lit("0.05");
/// n_max as a typed value.
pub const N_MAX: RevPerMin = RevPerMin::lit("44.7");
/// Rated drum speed as a typed value.
pub const N_RATED: RevPerMin = RevPerMin::lit("25.21");

/// The six operator-selectable gears of the tracked chassis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gear {
    /// Low-speed first gear (≈0.31–0.33 km/h).
    Low1,
    /// Low-speed second gear (≈0.51 km/h).
    Low2,
    /// Low-speed third gear (≈0.85 km/h).
    Low3,
    /// High-speed first gear (≈1.4 km/h).
    High1,
    /// High-speed second gear (≈2.2 km/h).
    High2,
    /// High-speed third gear (≈3.6 km/h).
    High3,
}

/// What paper A measured for one gear (Tables 11 and 12).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GearPreset {
    /// The gear.
    pub gear: Gear,
    /// Short name as the operator sees it, e.g. `"Low 1"`.
    pub name: &'static str,
    /// Actual travel speed on a hard surface (Table 11), km/h.
    pub actual_kmh_f64: f64,
    /// Speed the Hall sensor monitored (Table 11), km/h.
    pub monitored_kmh_f64: f64,
    /// k1 as printed in Table 11.
    pub k1_f64: f64,
    /// k2 as printed in Table 12.
    pub k2_f64: f64,
    /// Actual speed, typed.
    pub actual: KilometresPerHour,
    /// Monitored speed, typed.
    pub monitored: KilometresPerHour,
    /// k1, typed.
    pub k1: Coefficient,
    /// k2, typed.
    pub k2: Coefficient,
}

macro_rules! preset {
    ($g:ident, $name:literal, $act:literal, $mon:literal, $k1:literal, $k2:literal) => {
        GearPreset {
            gear: Gear::$g,
            name: $name,
            actual_kmh_f64: $act,
            monitored_kmh_f64: $mon,
            k1_f64: $k1,
            k2_f64: $k2,
            actual: KilometresPerHour::lit(stringify!($act)),
            monitored: KilometresPerHour::lit(stringify!($mon)),
            k1: Coefficient::lit(stringify!($k1)),
            k2: Coefficient::lit(stringify!($k2)),
        }
    };
}

/// The six gear presets, Low 1 … High 3 (paper A Tables 11 and 12).
pub const GEAR_PRESETS: [GearPreset; 6] = [
    preset!(Low1, "Low 1", 0.33, 0.32, 1.031, 0.972),
    preset!(Low2, "Low 2", 0.52, 0.51, 1.020, 0.966),
    preset!(Low3, "Low 3", 0.85, 0.88, 0.966, 0.963),
    preset!(High1, "High 1", 1.40, 1.42, 0.986, 0.956),
    preset!(High2, "High 2", 2.20, 2.21, 0.995, 0.952),
    preset!(High3, "High 3", 3.65, 3.66, 0.997, 0.941),
];

impl Gear {
    /// All gears, slowest first.
    pub const ALL: [Gear; 6] = [
        Gear::Low1,
        Gear::Low2,
        Gear::Low3,
        Gear::High1,
        Gear::High2,
        Gear::High3,
    ];

    /// The preset measured for this gear.
    #[must_use]
    pub const fn preset(self) -> &'static GearPreset {
        match self {
            Gear::Low1 => &GEAR_PRESETS[0],
            Gear::Low2 => &GEAR_PRESETS[1],
            Gear::Low3 => &GEAR_PRESETS[2],
            Gear::High1 => &GEAR_PRESETS[3],
            Gear::High2 => &GEAR_PRESETS[4],
            Gear::High3 => &GEAR_PRESETS[5],
        }
    }

    /// The speed the Hall sensor monitored in this gear (paper A Table 11):
    /// `self.preset().monitored`, without linking the whole preset table
    /// (its `f64` columns are for the host) into an image.
    #[must_use]
    pub const fn monitored(self) -> KilometresPerHour {
        match self {
            Gear::Low1 => GEAR_PRESETS[0].monitored,
            Gear::Low2 => GEAR_PRESETS[1].monitored,
            Gear::Low3 => GEAR_PRESETS[2].monitored,
            Gear::High1 => GEAR_PRESETS[3].monitored,
            Gear::High2 => GEAR_PRESETS[4].monitored,
            Gear::High3 => GEAR_PRESETS[5].monitored,
        }
    }

    /// The actual travel speed in this gear (paper A Table 11):
    /// `self.preset().actual`, as [`Gear::monitored`].
    #[must_use]
    pub const fn actual(self) -> KilometresPerHour {
        match self {
            Gear::Low1 => GEAR_PRESETS[0].actual,
            Gear::Low2 => GEAR_PRESETS[1].actual,
            Gear::Low3 => GEAR_PRESETS[2].actual,
            Gear::High1 => GEAR_PRESETS[3].actual,
            Gear::High2 => GEAR_PRESETS[4].actual,
            Gear::High3 => GEAR_PRESETS[5].actual,
        }
    }

    /// Parses `low1`, `Low 1`, `LOW-1`, `high3`, … (case and separators ignored).
    #[must_use]
    pub fn parse(s: &str) -> Option<Gear> {
        let mut buf = [0u8; 8];
        let mut n = 0usize;
        for b in s.bytes() {
            if b == b' ' || b == b'-' || b == b'_' {
                continue;
            }
            let slot = buf.get_mut(n)?;
            *slot = b.to_ascii_lowercase();
            n = n.checked_add(1)?;
        }
        match buf.get(..n)? {
            b"low1" | b"l1" => Some(Gear::Low1),
            b"low2" | b"l2" => Some(Gear::Low2),
            b"low3" | b"l3" => Some(Gear::Low3),
            b"high1" | b"h1" => Some(Gear::High1),
            b"high2" | b"h2" => Some(Gear::High2),
            b"high3" | b"h3" => Some(Gear::High3),
            _ => None,
        }
    }
}

impl core::fmt::Display for Gear {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.preset().name)
    }
}

/// Geometry in the working precision (`U32F32`), so that the calibration
/// arithmetic reproduces the paper's tables to their printed digits.
pub(crate) mod w {
    use crate::fx::{const_div, const_mul, PI, W};
    use fixed::types::U32F32;
    /// D1 + 2·H1.
    pub(crate) const WHEEL_D: W = U32F32::lit("0.2").to_bits();
    /// D2 + 2·H2.
    pub(crate) const DRUM_D: W = U32F32::lit("0.07").to_bits();
    /// Lclap.
    pub(crate) const L_CLAP: W = U32F32::lit("0.05").to_bits();
    /// π·(D1 + 2·H1), rounded down as the product of the two above.
    pub(crate) const WHEEL_CIRC: W = const_mul(PI, WHEEL_D);
    /// π·(D2 + 2·H2), rounded down as the product of the two above.
    pub(crate) const DRUM_CIRC: W = const_mul(PI, DRUM_D);
    /// Eq. 7's geometry times the spacing: `(D1+2H1)/(D2+2H2) · Lclap`, metres.
    pub(crate) const GEOM_M: W = const_div(const_mul(WHEEL_D, L_CLAP), DRUM_D);
    /// Travel speed (km/h) the belt allows per drum r/min and metre of
    /// spacing: `π·(D2+2H2)/60 / Lclap · 3.6` (k3 = 1).
    #[allow(clippy::arithmetic_side_effects)]
    pub(crate) const VMAX_PER_RPM_M: W = const_div(DRUM_CIRC * 18 / 300, L_CLAP);
}
