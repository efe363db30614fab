//! Machine A's ground wheel: which travel source the machine uses, the
//! wheel's counts per metre and its direction (settings format 7).

use core::fmt;

use hmi_proto::screen::TravelSource;

/// Bytes of the ground-wheel block: source, flags, counts per metre × 1000
/// (u32).
pub const GROUND_WHEEL_BYTES: usize = 6;

/// The product's ground wheel: a 600-pulse quadrature encoder (2400 counts a
/// turn) on a wheel of 250 mm diameter, counts per metre × 1000:
/// 2400 / (π · 0.250 m) = 3055.775 counts/m.
pub const NOMINAL_COUNTS_PER_M_X1000: u32 = 3_055_775;

/// The lowest and highest counts per metre (× 1000) a setting may hold: a
/// wheel with 100 … 20 000 counts a metre (from a 100-pulse encoder on a
/// 1.3 m wheel to a 5000-pulse one on a 0.3 m wheel).
pub const COUNTS_PER_M_X1000_RANGE: core::ops::RangeInclusive<u32> = 100_000..=20_000_000;

/// A calibration run's result farther than this from the nominal wheel
/// ([`NOMINAL_COUNTS_PER_M_X1000`]), percent, is refused: a wrong distance
/// typed, a wheel that slipped or lifted, or another wheel fitted.
pub const CALIBRATION_TOLERANCE_PCT: u32 = 20;

/// Flags byte of the block, bit 0: the wheel counts backwards.
const FLAG_REVERSED: u8 = 1;

/// The ground wheel's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GroundWheelSettings {
    /// Where the travel speed and the ground distance come from. Default:
    /// the Hall gear (paper A).
    pub source: TravelSource,
    /// Encoder counts per metre of ground, × 1000. Default: the nominal
    /// wheel's.
    pub counts_per_m_x1000: u32,
    /// The wheel's counts run backwards while the machine moves forward (A/B
    /// swapped): the supervisor negates them. Default: `false`.
    pub reversed: bool,
}

impl Default for GroundWheelSettings {
    fn default() -> Self {
        Self {
            source: TravelSource::HallGear,
            counts_per_m_x1000: NOMINAL_COUNTS_PER_M_X1000,
            reversed: false,
        }
    }
}

/// Why a ground-wheel block or value is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GroundWheelError {
    /// Unknown source byte.
    Source(u8),
    /// Flag bits this firmware does not know.
    Flags(u8),
    /// Counts per metre (× 1000) outside [`COUNTS_PER_M_X1000_RANGE`].
    CountsPerMetre(u32),
}

impl fmt::Display for GroundWheelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Source(b) => write!(f, "invalid travel source byte {b}"),
            Self::Flags(b) => write!(f, "invalid ground wheel flags {b}"),
            Self::CountsPerMetre(v) => write!(
                f,
                "ground wheel counts per metre {}.{:03} outside 100 … 20000",
                v / 1000,
                v % 1000
            ),
        }
    }
}

const fn source_byte(s: TravelSource) -> u8 {
    match s {
        TravelSource::HallGear => 1,
        TravelSource::GroundWheel => 2,
        TravelSource::Both => 3,
    }
}

impl GroundWheelSettings {
    /// The block as stored: source (1 Hall gear, 2 ground wheel, 3 both),
    /// flags (bit 0 reversed), counts per metre × 1000 (u32 LE).
    #[must_use]
    pub fn to_bytes(&self) -> [u8; GROUND_WHEEL_BYTES] {
        let [c0, c1, c2, c3] = self.counts_per_m_x1000.to_le_bytes();
        [
            source_byte(self.source),
            if self.reversed { FLAG_REVERSED } else { 0 },
            c0,
            c1,
            c2,
            c3,
        ]
    }

    /// Parses and validates a block written by [`Self::to_bytes`].
    pub fn from_bytes(bytes: &[u8; GROUND_WHEEL_BYTES]) -> Result<Self, GroundWheelError> {
        let [s, flags, c0, c1, c2, c3] = *bytes;
        let source = match s {
            1 => TravelSource::HallGear,
            2 => TravelSource::GroundWheel,
            3 => TravelSource::Both,
            other => return Err(GroundWheelError::Source(other)),
        };
        if flags & !FLAG_REVERSED != 0 {
            return Err(GroundWheelError::Flags(flags));
        }
        let counts_per_m_x1000 = checked_counts(u32::from_le_bytes([c0, c1, c2, c3]))?;
        Ok(Self {
            source,
            counts_per_m_x1000,
            reversed: flags & FLAG_REVERSED != 0,
        })
    }
}

/// A counts-per-metre value (× 1000) inside [`COUNTS_PER_M_X1000_RANGE`].
pub fn checked_counts(v: u32) -> Result<u32, GroundWheelError> {
    if COUNTS_PER_M_X1000_RANGE.contains(&v) {
        Ok(v)
    } else {
        Err(GroundWheelError::CountsPerMetre(v))
    }
}

/// Why a ground-wheel calibration run is refused (nothing is saved).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WheelCalibrationError {
    /// The wheel did not count during the run.
    NoPulses,
    /// The wheel counted backwards during the run: its direction setting
    /// (or its A/B wiring) is wrong.
    Backwards,
    /// The result is more than [`CALIBRATION_TOLERANCE_PCT`] % from the
    /// nominal wheel; carries it, counts per metre × 1000.
    OutOfTolerance(u32),
}

impl fmt::Display for WheelCalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoPulses => f.write_str("no ground wheel pulses in the run"),
            Self::Backwards => f.write_str("the ground wheel counted backwards"),
            Self::OutOfTolerance(v) => write!(
                f,
                "{}.{:03} counts/m is more than {CALIBRATION_TOLERANCE_PCT} % from the nominal wheel",
                v / 1000,
                v % 1000
            ),
        }
    }
}

/// A calibration run's counts per metre × 1000: `counts` over a taped
/// `distance_mm`, checked against the nominal wheel. `counts` is signed
/// (after the direction setting): a run that counted backwards is refused.
pub fn calibrate(counts: i64, distance_mm: u32) -> Result<u32, WheelCalibrationError> {
    if counts < 0 {
        return Err(WheelCalibrationError::Backwards);
    }
    if counts == 0 || distance_mm == 0 {
        return Err(WheelCalibrationError::NoPulses);
    }
    // counts × 10⁶ / mm = counts per metre × 1000, rounded to nearest.
    let d = u64::from(distance_mm);
    let v = u64::try_from(counts)
        .unwrap_or(u64::MAX)
        .saturating_mul(1_000_000)
        .saturating_add(d / 2)
        .checked_div(d)
        .unwrap_or(0);
    let nominal = u64::from(NOMINAL_COUNTS_PER_M_X1000);
    let tol = nominal.saturating_mul(u64::from(CALIBRATION_TOLERANCE_PCT)) / 100;
    let v32 = u32::try_from(v).unwrap_or(u32::MAX);
    if v < nominal.saturating_sub(tol) || v > nominal.saturating_add(tol) {
        return Err(WheelCalibrationError::OutOfTolerance(v32));
    }
    Ok(v32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nominal_wheel_is_2400_counts_on_250_mm() {
        let f64_model = 2400.0 / (core::f64::consts::PI * 0.250) * 1000.0;
        assert!((f64::from(NOMINAL_COUNTS_PER_M_X1000) - f64_model).abs() < 1.0);
    }

    #[test]
    fn every_block_round_trips_and_bad_bytes_are_refused() {
        for source in [
            TravelSource::HallGear,
            TravelSource::GroundWheel,
            TravelSource::Both,
        ] {
            for reversed in [false, true] {
                for counts_per_m_x1000 in [100_000, NOMINAL_COUNTS_PER_M_X1000, 20_000_000] {
                    let s = GroundWheelSettings {
                        source,
                        counts_per_m_x1000,
                        reversed,
                    };
                    assert_eq!(GroundWheelSettings::from_bytes(&s.to_bytes()), Ok(s));
                }
            }
        }
        let good = GroundWheelSettings::default().to_bytes();
        for b in [0u8, 4, 0xFF] {
            let mut x = good;
            x[0] = b;
            assert_eq!(
                GroundWheelSettings::from_bytes(&x),
                Err(GroundWheelError::Source(b))
            );
        }
        for b in 2u8..=255 {
            let mut x = good;
            x[1] = b;
            assert_eq!(
                GroundWheelSettings::from_bytes(&x),
                Err(GroundWheelError::Flags(b))
            );
        }
        for v in [0u32, 99_999, 20_000_001, u32::MAX] {
            let mut x = good;
            x[2..].copy_from_slice(&v.to_le_bytes());
            assert_eq!(
                GroundWheelSettings::from_bytes(&x),
                Err(GroundWheelError::CountsPerMetre(v))
            );
        }
    }

    #[test]
    fn a_calibration_run_is_counts_over_the_taped_distance_within_20_percent() {
        // 30.000 m taped, 91 673 counts: 3055.767 counts/m.
        assert_eq!(calibrate(91_673, 30_000), Ok(3_055_767));
        // Exactly at the bounds (nominal ± 20 %: 2444.620 … 3666.930).
        let lo = NOMINAL_COUNTS_PER_M_X1000 - NOMINAL_COUNTS_PER_M_X1000 / 5;
        let hi = NOMINAL_COUNTS_PER_M_X1000 + NOMINAL_COUNTS_PER_M_X1000 / 5;
        // (counts over 1 km: counts per metre × 1000 = the counts.)
        assert_eq!(calibrate(i64::from(lo), 1_000_000), Ok(lo));
        assert_eq!(calibrate(i64::from(hi), 1_000_000), Ok(hi));
        assert_eq!(
            calibrate(i64::from(lo - 1), 1_000_000),
            Err(WheelCalibrationError::OutOfTolerance(lo - 1))
        );
        assert_eq!(
            calibrate(i64::from(hi + 1), 1_000_000),
            Err(WheelCalibrationError::OutOfTolerance(hi + 1))
        );
        assert_eq!(calibrate(0, 30_000), Err(WheelCalibrationError::NoPulses));
        assert_eq!(calibrate(5, 0), Err(WheelCalibrationError::NoPulses));
        assert_eq!(
            calibrate(-91_673, 30_000),
            Err(WheelCalibrationError::Backwards)
        );
        assert!(matches!(
            calibrate(i64::MAX, 1),
            Err(WheelCalibrationError::OutOfTolerance(_))
        ));
    }
}
