//! Field metrics of the planted row as streaming accumulators (no lists: the
//! model runs without a heap on the QEMU board).
//!
//! With `X` the target spacing and `s` each spacing between consecutive
//! plants (ISO 7256-1 classes):
//!
//! * multiples index `D` = share of spacings with `s ≤ 0.5·X` (percent);
//! * miss index `M` = share of spacings with `s > 1.5·X`;
//! * quality of feed `A = 100 − D − M` (the "singles", `0.5·X < s ≤ 1.5·X`);
//! * precision `C` = coefficient of variation (sample SD / mean) of the
//!   singles, percent; [`FieldMetrics::precision_vs_target_pct`] gives the
//!   Kachman–Smith variant (SD of the singles / X);
//! * mean, sample SD and CV of all spacings (JB/T 10291, paper B's `S_X`, `CV_X`);
//! * spacing qualification rate (paper A Table 17, DB62/T 4505): this crate's
//!   definition is the share of spacings with `|s − X| ≤ tol·X`
//!   (`tol` = [`crate::Config::qualified_tolerance`], default 0.2);
//! * count error: `(plants − L/X) / (L/X)` with `L` the ground travelled since
//!   the metrics were reset (paper A Table 16's "theoretical count").

/// Streaming mean and variance (Welford), f64 so that long runs stay exact.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct Welford {
    n: u32,
    mean: f64,
    m2: f64,
}

impl Welford {
    const ZERO: Self = Self {
        n: 0,
        mean: 0.0,
        m2: 0.0,
    };

    fn push(&mut self, x: f64) {
        self.n = self.n.saturating_add(1);
        let d = x - self.mean;
        self.mean += d / f64::from(self.n);
        self.m2 += d * (x - self.mean);
    }

    /// Sample standard deviation (n − 1); 0 with fewer than two values.
    fn sd(&self) -> f64 {
        if self.n < 2 {
            0.0
        } else {
            libm::sqrt(self.m2 / f64::from(self.n - 1))
        }
    }
}

/// The streaming accumulator behind [`FieldMetrics`] (about 90 bytes).
///
/// Usable on its own, e.g. to check a list of measured spacings:
///
/// ```
/// use machine_sim::SpacingAccumulator;
/// let mut acc = SpacingAccumulator::new(0.10, 0.2).unwrap();
/// for p in [0.0, 0.10, 0.20, 0.25, 0.45] {
///     acc.push_plant(p);
/// }
/// // Spacings 0.10, 0.10, 0.05, 0.20: 0.05 ≤ 0.5·X is a multiple, 0.20 > 1.5·X a miss.
/// let m = acc.metrics(0.45);
/// assert_eq!(m.spacings, 4);
/// assert!((m.multiple_index_pct - 25.0).abs() < 1e-9);
/// assert!((m.miss_index_pct - 25.0).abs() < 1e-9);
/// assert!((m.quality_of_feed_pct - 50.0).abs() < 1e-9);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpacingAccumulator {
    target_m: f64,
    tolerance: f64,
    start_m: f64,
    /// Position of the last plant (meaningful when `plants > 0`).
    last_m: f64,
    plants: u32,
    multiples: u32,
    misses: u32,
    qualified: u32,
    all: Welford,
    singles: Welford,
}

/// Why a metric setting was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MetricsError {
    /// Target spacing not finite or outside (0, 10] m.
    TargetSpacing,
    /// Qualification tolerance not finite or outside (0, 1].
    Tolerance,
}

impl core::fmt::Display for MetricsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            MetricsError::TargetSpacing => "target spacing must be in (0, 10] m",
            MetricsError::Tolerance => "qualification tolerance must be in (0, 1]",
        })
    }
}

impl core::error::Error for MetricsError {}

impl SpacingAccumulator {
    /// An empty accumulator for target spacing `target_m` and qualification
    /// tolerance `tolerance` (fraction of X), starting at ground position 0.
    pub fn new(target_m: f64, tolerance: f64) -> Result<Self, MetricsError> {
        if !(target_m.is_finite() && target_m > 0.0 && target_m <= 10.0) {
            return Err(MetricsError::TargetSpacing);
        }
        if !(tolerance.is_finite() && tolerance > 0.0 && tolerance <= 1.0) {
            return Err(MetricsError::Tolerance);
        }
        Ok(Self::new_unchecked(target_m, tolerance))
    }

    /// As [`SpacingAccumulator::new`] for values already checked.
    pub(crate) const fn new_unchecked(target_m: f64, tolerance: f64) -> Self {
        Self {
            target_m,
            tolerance,
            start_m: 0.0,
            last_m: 0.0,
            plants: 0,
            multiples: 0,
            misses: 0,
            qualified: 0,
            all: Welford::ZERO,
            singles: Welford::ZERO,
        }
    }

    /// Clears the counts; the theoretical count starts at ground `start_m`.
    pub fn reset(&mut self, start_m: f64) {
        *self = Self {
            target_m: self.target_m,
            tolerance: self.tolerance,
            start_m,
            last_m: 0.0,
            plants: 0,
            multiples: 0,
            misses: 0,
            qualified: 0,
            all: Welford::default(),
            singles: Welford::default(),
        };
    }

    /// Target spacing X, metres.
    #[must_use]
    pub fn target_m(&self) -> f64 {
        self.target_m
    }

    /// Records a plant at ground position `pos_m` (positions in planting order).
    pub fn push_plant(&mut self, pos_m: f64) {
        if self.plants > 0 {
            self.push_spacing(pos_m - self.last_m);
        }
        self.plants = self.plants.saturating_add(1);
        self.last_m = pos_m;
    }

    fn push_spacing(&mut self, s: f64) {
        let x = self.target_m;
        self.all.push(s);
        if s <= 0.5 * x {
            self.multiples = self.multiples.saturating_add(1);
        } else if s > 1.5 * x {
            self.misses = self.misses.saturating_add(1);
        } else {
            self.singles.push(s);
        }
        if (s - x).abs() <= self.tolerance * x {
            self.qualified = self.qualified.saturating_add(1);
        }
    }

    /// The metrics, with `ground_now_m` the current ground position (for the
    /// theoretical count `L/X`).
    #[must_use]
    pub fn metrics(&self, ground_now_m: f64) -> FieldMetrics {
        let n = self.all.n;
        let pct = |k: u32| {
            if n == 0 {
                0.0
            } else {
                100.0 * f64::from(k) / f64::from(n)
            }
        };
        let multiple = pct(self.multiples);
        let miss = pct(self.misses);
        let distance = ground_now_m - self.start_m;
        let theoretical = distance / self.target_m;
        let cv = |w: &Welford| {
            if w.mean > 0.0 {
                100.0 * w.sd() / w.mean
            } else {
                0.0
            }
        };
        FieldMetrics {
            target_spacing_m: self.target_m,
            plants: self.plants,
            spacings: n,
            distance_m: distance,
            theoretical_count: theoretical,
            count_error_pct: if theoretical > 0.0 {
                100.0 * (f64::from(self.plants) - theoretical) / theoretical
            } else {
                0.0
            },
            mean_spacing_m: self.all.mean,
            sd_spacing_m: self.all.sd(),
            cv_pct: cv(&self.all),
            multiple_index_pct: multiple,
            miss_index_pct: miss,
            quality_of_feed_pct: if n == 0 { 0.0 } else { 100.0 - multiple - miss },
            precision_pct: cv(&self.singles),
            precision_vs_target_pct: 100.0 * self.singles.sd() / self.target_m,
            qualified_pct: pct(self.qualified),
        }
    }
}

/// A snapshot of the field metrics (see the module documentation for the
/// definitions). Percentages are 0 … 100.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldMetrics {
    /// Target spacing X, metres.
    pub target_spacing_m: f64,
    /// Plants recorded.
    pub plants: u32,
    /// Spacings recorded (plants − 1, or 0).
    pub spacings: u32,
    /// Ground travelled since the metrics were reset, metres.
    pub distance_m: f64,
    /// Theoretical plant count `distance / X`.
    pub theoretical_count: f64,
    /// `(plants − theoretical) / theoretical`, percent.
    pub count_error_pct: f64,
    /// Mean spacing, metres.
    pub mean_spacing_m: f64,
    /// Sample standard deviation of the spacings, metres.
    pub sd_spacing_m: f64,
    /// Coefficient of variation of all spacings, percent.
    pub cv_pct: f64,
    /// ISO 7256-1 multiples index D (share of `s ≤ 0.5·X`), percent.
    pub multiple_index_pct: f64,
    /// ISO 7256-1 miss index M (share of `s > 1.5·X`), percent.
    pub miss_index_pct: f64,
    /// ISO 7256-1 quality of feed A = 100 − D − M, percent.
    pub quality_of_feed_pct: f64,
    /// Precision C: CV of the singles (`0.5·X < s ≤ 1.5·X`), percent.
    pub precision_pct: f64,
    /// Precision as SD of the singles over X (Kachman–Smith), percent.
    pub precision_vs_target_pct: f64,
    /// Spacing qualification rate: share of `|s − X| ≤ tol·X`, percent.
    pub qualified_pct: f64,
}
