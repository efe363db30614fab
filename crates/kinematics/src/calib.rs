//! Calibration procedures of paper A Section 3 as pure functions. Each
//! returns the table point it measured, ready for [`crate::table::CoeffTable`].

use fixed::types::{I16F16, U16F16};

use crate::consts;
use crate::fx;
use crate::table::TablePoint;
use crate::units::{Coefficient, KilometresPerHour, Metres, MetresPerSecond, RevPerMin, Seconds};
use crate::Error;

/// Result of a k1 run: `k1 = actual / monitored` (Table 11).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct K1Result {
    /// Actual travel speed of the run.
    pub actual: KilometresPerHour,
    /// Travel speed the Hall sensor monitored (without k1).
    pub monitored: KilometresPerHour,
    /// The coefficient.
    pub k1: Coefficient,
}

impl K1Result {
    /// The table point `(monitored km/h, k1)`.
    #[must_use]
    pub fn point(&self) -> TablePoint {
        TablePoint::new(self.monitored.table_x(), self.k1)
    }
}

/// k1 from an actual and a monitored speed (paper A Table 11).
///
/// ```
/// use kinematics::calib::k1_from_speeds;
/// use kinematics::units::KilometresPerHour as Kmh;
/// // Low 1: 0.33 / 0.32 = 1.03125 → printed 1.031.
/// let r = k1_from_speeds(Kmh::lit("0.33"), Kmh::lit("0.32"))?;
/// assert!((r.k1.to_f64() - 1.03125).abs() < 1e-6);
/// # Ok::<(), kinematics::Error>(())
/// ```
pub fn k1_from_speeds(
    actual: KilometresPerHour,
    monitored: KilometresPerHour,
) -> Result<K1Result, Error> {
    let k1 = Coefficient::try_from_w(fx::div(actual.w(), monitored.w())?)?;
    Ok(K1Result {
        actual,
        monitored,
        k1,
    })
}

/// k1 from a timed run over a measured section (e.g. 200 m on a hard
/// surface): actual speed = `distance / time`.
pub fn k1_from_timed_run(
    distance: Metres,
    time: Seconds,
    monitored: KilometresPerHour,
) -> Result<K1Result, Error> {
    let actual = MetresPerSecond::try_from_w(fx::div(distance.w(), time.w())?)?.to_kmh()?;
    k1_from_speeds(actual, monitored)
}

/// Result of a k2 run (paper A eq. 22–23, Table 12).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlipResult {
    /// Distance the wheel turns imply: turns · π·(D1+2H1).
    pub theoretical_distance: Metres,
    /// Wheel (k1-corrected) speed of the run: theoretical distance / time.
    pub wheel_speed: KilometresPerHour,
    /// Slip `s = (V1 − L/T)/V1` as a fraction (negative if the track skidded forward).
    pub slip: I16F16,
    /// `k2 = 1 − s`.
    pub k2: Coefficient,
}

#[cfg(feature = "defmt")]
impl defmt::Format for SlipResult {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "SlipResult(dist={}, v={}, slip={=i32}/65536, k2={})",
            self.theoretical_distance,
            self.wheel_speed,
            self.slip.to_bits(),
            self.k2
        );
    }
}

impl SlipResult {
    /// The table point `(wheel km/h, k2)`.
    #[must_use]
    pub fn point(&self) -> TablePoint {
        TablePoint::new(self.wheel_speed.table_x(), self.k2)
    }
}

/// k2 from the mean wheel turns over a measured distance `distance` driven
/// in `time` (eq. 22–23): `V1 = turns·π(D1+2H1)/T`, `s = (V1 − L/T)/V1`,
/// `k2 = 1 − s = L / (turns·π(D1+2H1))`.
///
/// ```
/// use kinematics::calib::k2_from_wheel_turns;
/// use kinematics::units::{Metres, Seconds};
/// use fixed::types::U16F16;
/// // Table 12, Low 1: 655.09 turns, 400 m, 4645.16 s → 411.61 m, 2.82 %, 0.972.
/// let r = k2_from_wheel_turns(U16F16::lit("655.09"), Metres::lit("400"), Seconds::lit("4645.16"))?;
/// assert_eq!((r.theoretical_distance.to_f64() * 100.0).round(), 41161.0);
/// assert!((r.slip.to_num::<f64>() - 0.0282).abs() < 0.00005);
/// assert!((r.k2.to_f64() - 0.972).abs() < 0.0005);
/// # Ok::<(), kinematics::Error>(())
/// ```
pub fn k2_from_wheel_turns(
    turns: U16F16,
    distance: Metres,
    time: Seconds,
) -> Result<SlipResult, Error> {
    let theo = fx::mul(fx::widen_bits(turns.to_bits(), 16), consts::w::WHEEL_CIRC)?;
    let theoretical_distance = Metres::try_from_w(theo)?;
    let v = MetresPerSecond::try_from_w(fx::div(theo, time.w())?)?;
    let k2w = fx::div(distance.w(), theo)?;
    let k2 = Coefficient::try_from_w(k2w)?;
    // s = 1 − k2, signed.
    let s = i32::try_from(fx::ONE.abs_diff(k2w) >> 16).map_err(|_| Error::Overflow)?;
    let slip = I16F16::from_bits(if k2w <= fx::ONE { s } else { s.wrapping_neg() });
    Ok(SlipResult {
        theoretical_distance,
        wheel_speed: v.to_kmh()?,
        slip,
        k2,
    })
}

/// Result of a belt test (paper A Table 13).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct K3Result {
    /// The drum speed that was set.
    pub set_drum_speed: RevPerMin,
    /// Theoretical belt speed `π·(D2+2H2)·n/60`.
    pub theoretical_belt_speed: MetresPerSecond,
    /// Measured belt speed.
    pub measured_belt_speed: MetresPerSecond,
    /// `k3 = measured / theoretical`.
    pub k3: Coefficient,
}

impl K3Result {
    /// The table point `(set r/min, k3)`.
    #[must_use]
    pub fn point(&self) -> TablePoint {
        TablePoint::new(self.set_drum_speed.table_x(), self.k3)
    }
}

/// Theoretical belt speed for a drum speed: `π·(D2+2H2)·n/60` (eq. 6 without k3).
pub fn belt_speed(drum_speed: RevPerMin) -> Result<MetresPerSecond, Error> {
    let circ = consts::w::DRUM_CIRC;
    MetresPerSecond::try_from_w(fx::div_int(fx::mul(circ, drum_speed.w())?, 60)?)
}

/// k3 from a belt test: set a drum speed, measure the belt speed.
///
/// ```
/// use kinematics::calib::k3_from_belt_test;
/// use kinematics::units::{MetresPerSecond, RevPerMin};
/// // Table 13, 5 r/min: π·0.07·5/60 = 0.018326 m/s; 0.0182/0.018326 = 0.9931 → 0.993.
/// let r = k3_from_belt_test(RevPerMin::lit("5"), MetresPerSecond::lit("0.0182"))?;
/// assert!((r.k3.to_f64() - 0.9931).abs() < 1e-4);
/// # Ok::<(), kinematics::Error>(())
/// ```
pub fn k3_from_belt_test(
    set_drum_speed: RevPerMin,
    measured: MetresPerSecond,
) -> Result<K3Result, Error> {
    let theo = belt_speed(set_drum_speed)?;
    let k3 = Coefficient::try_from_w(fx::div(measured.w(), theo.w())?)?;
    Ok(K3Result {
        set_drum_speed,
        theoretical_belt_speed: theo,
        measured_belt_speed: measured,
        k3,
    })
}
