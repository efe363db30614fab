//! The drum drive's model: its gain (`n_max`, the drum speed at 100 %
//! duty), time constant τ and dead time, as persisted in the settings
//! (format version 3) and used by the feed-forward and the controller's
//! drum model.

use core::fmt;

/// The drum drive's first-order-plus-dead-time model, validated.
///
/// Speed at duty `d` (0–1): `n_max · d`, reached through a first-order lag
/// of time constant τ after a dead time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveModel {
    n_max_x100: u16,
    tau_x10_ms: u16,
    dead_time_x10_ms: u16,
}

/// Which parameter of a [`DriveModel`] is out of range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveModelError {
    /// `n_max` outside [`DriveModel::N_MAX_RANGE`] (r/min × 100).
    NMax(u16),
    /// τ outside [`DriveModel::TAU_RANGE`] (0.1 ms).
    Tau(u16),
    /// Dead time above [`DriveModel::DEAD_TIME_MAX`] (0.1 ms).
    DeadTime(u16),
}

impl fmt::Display for DriveModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NMax(v) => write!(f, "drive n_max {v} (r/min x100) outside 1000-9000"),
            Self::Tau(v) => write!(f, "drive time constant {v} (0.1 ms) outside 10-5000"),
            Self::DeadTime(v) => write!(f, "drive dead time {v} (0.1 ms) above 2000"),
        }
    }
}

/// Bytes of [`DriveModel::to_bytes`].
pub const DRIVE_MODEL_BYTES: usize = 6;

impl DriveModel {
    /// Accepted `n_max`, r/min × 100: 10–90 r/min (the paper's drive is
    /// 44.7; identification covers ±30 % and more).
    pub const N_MAX_RANGE: core::ops::RangeInclusive<u16> = 1000..=9000;
    /// Accepted τ, 0.1 ms: 1–500 ms.
    pub const TAU_RANGE: core::ops::RangeInclusive<u16> = 10..=5000;
    /// Largest accepted dead time, 0.1 ms: 200 ms.
    pub const DEAD_TIME_MAX: u16 = 2000;

    /// The drive the firmware was designed on (SPEC §3, paper A): `n_max`
    /// 44.70 r/min, τ 25 ms, dead time 5 ms. Used until an identification
    /// is saved.
    pub const DEFAULT: Self = Self {
        n_max_x100: 4470,
        tau_x10_ms: 250,
        dead_time_x10_ms: 50,
    };

    /// A validated model: `n_max` in r/min × 100, τ and dead time in 0.1 ms.
    pub fn new(
        n_max_x100: u16,
        tau_x10_ms: u16,
        dead_time_x10_ms: u16,
    ) -> Result<Self, DriveModelError> {
        if !Self::N_MAX_RANGE.contains(&n_max_x100) {
            return Err(DriveModelError::NMax(n_max_x100));
        }
        if !Self::TAU_RANGE.contains(&tau_x10_ms) {
            return Err(DriveModelError::Tau(tau_x10_ms));
        }
        if dead_time_x10_ms > Self::DEAD_TIME_MAX {
            return Err(DriveModelError::DeadTime(dead_time_x10_ms));
        }
        Ok(Self {
            n_max_x100,
            tau_x10_ms,
            dead_time_x10_ms,
        })
    }

    /// Drum speed at 100 % duty, r/min × 100.
    pub const fn n_max_x100(&self) -> u16 {
        self.n_max_x100
    }

    /// Time constant, 0.1 ms.
    pub const fn tau_x10_ms(&self) -> u16 {
        self.tau_x10_ms
    }

    /// Dead time, 0.1 ms.
    pub const fn dead_time_x10_ms(&self) -> u16 {
        self.dead_time_x10_ms
    }

    /// `[n_max, τ, dead time]`, each u16 little endian.
    pub fn to_bytes(&self) -> [u8; DRIVE_MODEL_BYTES] {
        let [a0, a1] = self.n_max_x100.to_le_bytes();
        let [b0, b1] = self.tau_x10_ms.to_le_bytes();
        let [c0, c1] = self.dead_time_x10_ms.to_le_bytes();
        [a0, a1, b0, b1, c0, c1]
    }

    /// Parses and validates [`DriveModel::to_bytes`].
    pub fn from_bytes(b: &[u8; DRIVE_MODEL_BYTES]) -> Result<Self, DriveModelError> {
        let [a0, a1, b0, b1, c0, c1] = *b;
        Self::new(
            u16::from_le_bytes([a0, a1]),
            u16::from_le_bytes([b0, b1]),
            u16::from_le_bytes([c0, c1]),
        )
    }
}

impl Default for DriveModel {
    fn default() -> Self {
        Self::DEFAULT
    }
}
