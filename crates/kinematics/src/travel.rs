//! Travel speed V1 (paper A eq. 2–3) with the k1/k2/k3 calibration tables.
//!
//! The chain, from the estimator's raw gear speed `n_raw` (r/min, no k1):
//!
//! 1. monitored speed `v_mon = π·(D1+2H1)·n_raw/60` (what the sensor alone says);
//! 2. `k1 = K1(v_mon)` (table over monitored km/h), `n_teeth = k1·n_raw` (eq. 2);
//! 3. wheel speed `v_wheel = π·(D1+2H1)·n_teeth/60`;
//! 4. `k2 = K2(v_wheel)` (table over wheel km/h), `V1 = k2·v_wheel` (eq. 3).

use fixed::types::U16F16;

use crate::consts::{self, Gear};
use crate::fx;
use crate::table::{CoeffTable, TableError, TablePoint, TABLE_BYTES_MAX};
use crate::units::{Coefficient, KilometresPerHour, MetresPerSecond, RevPerMin};
use crate::Error;

/// Version byte of the serialised [`Calibration`].
pub const CALIBRATION_FORMAT_VERSION: u8 = 1;
/// Size of a serialised [`Calibration`]: version + three padded tables.
pub const CALIBRATION_BYTES: usize = 1 + 3 * TABLE_BYTES_MAX;

/// The three correction tables of paper A Section 3.
///
/// * `k1`: speed-measurement correction over the *monitored* travel speed (km/h);
/// * `k2`: track-slip correction over the k1-corrected *wheel* speed (km/h);
/// * `k3`: belt-slip correction over the *set* drum speed (r/min).
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Calibration {
    /// k1 over monitored km/h.
    pub k1: CoeffTable,
    /// k2 over wheel km/h.
    pub k2: CoeffTable,
    /// k3 over set drum r/min.
    pub k3: CoeffTable,
}

/// k1 table of paper A Table 11: (monitored km/h, k1).
pub const PAPER_K1: [(&str, &str); 6] = [
    ("0.32", "1.031"),
    ("0.51", "1.020"),
    ("0.88", "0.966"),
    ("1.42", "0.986"),
    ("2.21", "0.995"),
    ("3.66", "0.997"),
];
/// k2 table of paper A Table 12: (wheel km/h = 3.6·theoretical distance/time, k2).
/// The speeds are computed from Table 12's raw columns (see the tests).
pub const PAPER_K2: [(&str, &str); 6] = [
    ("0.3190", "0.972"),
    ("0.5277", "0.966"),
    ("0.8618", "0.963"),
    ("1.4233", "0.956"),
    ("2.2794", "0.952"),
    ("3.8053", "0.941"),
];
/// k3 table of paper A Table 13: (set drum r/min, k3).
pub const PAPER_K3: [(&str, &str); 5] = [
    ("5", "0.993"),
    ("10", "0.982"),
    ("15", "0.986"),
    ("20", "0.994"),
    ("25", "0.980"),
];

/// Builds table points from decimal literals at compile time (used only to
/// define the `const` point arrays below, so no string is parsed at run time:
/// the parser alone would cost the firmware ~10 KB of flash).
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
const fn points_from_lits<const N: usize>(lits: [(&str, &str); N]) -> [TablePoint; N] {
    let mut out = [TablePoint::new(U16F16::ZERO, Coefficient::ONE); N];
    let mut i = 0;
    while i < N {
        out[i] = TablePoint::new(U16F16::lit(lits[i].0), Coefficient::lit(lits[i].1));
        i += 1;
    }
    out
}

const PAPER_K1_POINTS: [TablePoint; 6] = points_from_lits(PAPER_K1);
const PAPER_K2_POINTS: [TablePoint; 6] = points_from_lits(PAPER_K2);
const PAPER_K3_POINTS: [TablePoint; 5] = points_from_lits(PAPER_K3);

fn table_from_points(points: &[TablePoint]) -> CoeffTable {
    CoeffTable::new(points).unwrap_or_default()
}

impl Calibration {
    /// The tables measured in paper A (Tables 11, 12 and 13).
    #[must_use]
    pub fn paper_defaults() -> Self {
        Self {
            k1: table_from_points(&PAPER_K1_POINTS),
            k2: table_from_points(&PAPER_K2_POINTS),
            k3: table_from_points(&PAPER_K3_POINTS),
        }
    }

    /// Constant k1 and k2 of one gear preset, with the paper's k3 table.
    #[must_use]
    pub fn for_gear(gear: Gear) -> Self {
        let p = gear.preset();
        Self {
            k1: CoeffTable::constant(p.k1).unwrap_or_default(),
            k2: CoeffTable::constant(p.k2).unwrap_or_default(),
            k3: table_from_points(&PAPER_K3_POINTS),
        }
    }

    /// All coefficients 1 (no correction).
    #[must_use]
    pub fn identity() -> Self {
        Self {
            k1: CoeffTable::one(),
            k2: CoeffTable::one(),
            k3: CoeffTable::one(),
        }
    }

    /// k1 at a monitored travel speed.
    #[must_use]
    pub fn k1_at(&self, monitored: KilometresPerHour) -> Coefficient {
        self.k1.eval(monitored.table_x())
    }

    /// k2 at a (k1-corrected) wheel speed.
    #[must_use]
    pub fn k2_at(&self, wheel: KilometresPerHour) -> Coefficient {
        self.k2.eval(wheel.table_x())
    }

    /// k3 at a set drum speed.
    #[must_use]
    pub fn k3_at(&self, drum: RevPerMin) -> Coefficient {
        self.k3.eval(drum.table_x())
    }

    /// Serialises: `[version, k1 table, k2 table, k3 table]`, each table
    /// padded to [`TABLE_BYTES_MAX`] so the layout is fixed.
    #[must_use]
    pub fn to_bytes(&self) -> [u8; CALIBRATION_BYTES] {
        let mut out = [0u8; CALIBRATION_BYTES];
        if let Some(v) = out.first_mut() {
            *v = CALIBRATION_FORMAT_VERSION;
        }
        let tables = [&self.k1, &self.k2, &self.k3];
        for (chunk, t) in out
            .get_mut(1..)
            .unwrap_or(&mut [])
            .chunks_exact_mut(TABLE_BYTES_MAX)
            .zip(tables)
        {
            let _ = t.write_bytes(chunk);
        }
        out
    }

    /// Parses and validates [`Calibration::to_bytes`] output.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, TableError> {
        let mut cal = Self::paper_defaults();
        cal.read_from(bytes)?;
        Ok(cal)
    }

    /// [`Calibration::from_bytes`] into `self`, table by table in place
    /// ([`CoeffTable::read_from`]). On an error `self` holds valid tables
    /// but not the ones asked for: decode into a scratch value.
    pub fn read_from(&mut self, bytes: &[u8]) -> Result<(), TableError> {
        let (&v, rest) = bytes.split_first().ok_or(TableError::BadLength)?;
        if v != CALIBRATION_FORMAT_VERSION {
            return Err(TableError::BadVersion);
        }
        let mut chunks = rest.chunks_exact(TABLE_BYTES_MAX);
        for table in [&mut self.k1, &mut self.k2, &mut self.k3] {
            table.read_from(chunks.next().ok_or(TableError::BadLength)?)?;
        }
        Ok(())
    }
}

impl Default for Calibration {
    fn default() -> Self {
        Self::paper_defaults()
    }
}

/// The corrected travel speed and every intermediate of eq. 2–3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TravelSpeed {
    /// Gear speed as measured, without k1 (r/min).
    pub raw_gear_speed: RevPerMin,
    /// The travel speed the sensor alone indicates (no k1, no k2).
    pub monitored: KilometresPerHour,
    /// k1 applied.
    pub k1: Coefficient,
    /// `n_teeth = k1 · n_raw` (eq. 2).
    pub gear_speed: RevPerMin,
    /// k2 applied.
    pub k2: Coefficient,
    /// `V1 = k2 · π(D1+2H1) · n_teeth / 60` (eq. 3).
    pub travel_speed: MetresPerSecond,
}

impl TravelSpeed {
    /// V1 in km/h.
    pub fn travel_speed_kmh(&self) -> Result<KilometresPerHour, Error> {
        self.travel_speed.to_kmh()
    }
}

/// Linear speed (m/s) of the track for a gear speed: `π·(D1+2H1)·n/60`.
pub fn wheel_surface_speed(gear_speed: RevPerMin) -> Result<MetresPerSecond, Error> {
    let circ = consts::w::WHEEL_CIRC;
    MetresPerSecond::try_from_w(fx::div_int(fx::mul(circ, gear_speed.w())?, 60)?)
}

/// Gear speed (r/min) for a track speed: `60·v/(π·(D1+2H1))`.
pub fn gear_speed_for(speed: MetresPerSecond) -> Result<RevPerMin, Error> {
    let circ = consts::w::WHEEL_CIRC;
    RevPerMin::try_from_w(fx::div(fx::mul_int(speed.w(), 60)?, circ)?)
}

/// Applies k1 and k2 to a raw gear speed (eq. 2–3).
///
/// ```
/// use kinematics::travel::{travel_speed, Calibration};
/// use kinematics::units::RevPerMin;
/// // Low 2 as monitored (0.51 km/h ⇒ n_raw = 0.51/3.6·60/(π·0.2) = 13.53 r/min).
/// let n_raw = RevPerMin::from_f64(13.5282).unwrap();
/// let t = travel_speed(n_raw, &Calibration::paper_defaults())?;
/// assert!((t.monitored.to_f64() - 0.51).abs() < 1e-4);
/// // k1(0.51) = 1.020 ⇒ wheel 0.5202 km/h; k2 between (0.3190, 0.972) and
/// // (0.5277, 0.966): 0.972 − 0.006·(0.2012/0.2087) = 0.96622;
/// // V1 = 0.5202 · 0.96622 = 0.50263 km/h.
/// let v1 = t.travel_speed_kmh()?.to_f64();
/// assert!((v1 - 0.50263).abs() < 1e-4, "{v1}");
/// # Ok::<(), kinematics::Error>(())
/// ```
pub fn travel_speed(raw_gear_speed: RevPerMin, cal: &Calibration) -> Result<TravelSpeed, Error> {
    let monitored = wheel_surface_speed(raw_gear_speed)?.to_kmh()?;
    let k1 = cal.k1_at(monitored);
    let gear_speed = RevPerMin::try_from_w(fx::mul(raw_gear_speed.w(), k1.w())?)?;
    let wheel = wheel_surface_speed(gear_speed)?;
    let k2 = cal.k2_at(wheel.to_kmh()?);
    let travel_speed = MetresPerSecond::try_from_w(fx::mul(wheel.w(), k2.w())?)?;
    Ok(TravelSpeed {
        raw_gear_speed,
        monitored,
        k1,
        gear_speed,
        k2,
        travel_speed,
    })
}
