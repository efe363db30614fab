//! Live planting quality: the ISO 7256-1 indices of the *commanded*
//! spacings, per pass and since Start, in integers.
//!
//! The firmware knows, for every partition that leaves the belt, the
//! ground distance at that moment ([`Quality::plant`]); the spacing is the
//! ground distance between two consecutive partitions of the same pass
//! (a pass runs from the work switch's lowering to its lift, or from Start
//! to Stop without a work switch). **These figures describe the control,
//! not the seedlings' fall**: where a seedling lands also depends on how it
//! falls, bounces and is covered, which no sensor of this machine sees.
//!
//! For a target spacing X and the spacings `s` of the pass (or of every
//! pass since Start; the gap of a lifted unit is no spacing):
//!
//! - multiples index D: share of `s ≤ 0.5·X`;
//! - miss index M: share of `s > 1.5·X`;
//! - quality of feed A: the rest, `0.5·X < s ≤ 1.5·X` (the singles);
//! - precision C: coefficient of variation (sample standard deviation over
//!   the mean) of the singles — as `machine_sim::metrics` and the QEMU run
//!   report compute it;
//! - the share of spacings within ±10 % of X (`|s − X| ≤ 0.1·X`);
//! - plants, distance with the unit down, plants per metre.
//!
//! Shares are reported in 0.1 % (rounded to the nearest), the CV in 0.1 %,
//! plants per metre in 0.01. Every spacing is held exactly in µm; the
//! singles' deviations from X (|s − X| ≤ 0.5·X ≤ 250 mm) are summed in
//! `i64` and their squares in `u64`, exact for 1.4 · 10⁸ singles (10 000 km
//! at 7 cm); beyond, the sums saturate.
//!
//! ```
//! use supervisor::quality::Quality;
//!
//! let mut q = Quality::new();
//! q.start(70_000); // X = 70 mm
//! q.begin_pass(0);
//! // Plants at 100, 170, 240, 260 (a multiple: 20 mm) and 400 mm (a
//! // miss: 140 mm > 105 mm).
//! for mm in [100, 170, 240, 260, 400] {
//!     q.plant(mm * 1000);
//! }
//! q.end_pass(500_000);
//! let i = q.pass();
//! assert_eq!(i.plants, 5);
//! assert_eq!(i.spacings, 4);
//! assert_eq!(i.multiples_x10, 250); // 1 of 4: 25.0 %
//! assert_eq!(i.misses_x10, 250);
//! assert_eq!(i.quality_of_feed_x10, 500);
//! assert_eq!(i.within_10_pct_x10, 500); // 70 and 70 mm
//! assert_eq!(i.cv_x10, 0); // the singles are 70 and 70 mm
//! assert_eq!(i.distance_mm, 500);
//! assert_eq!(i.plants_per_m_x100, 1000); // 5 plants in 0.5 m
//! ```

/// A lowering less than this much ground (µm) after the last plant before
/// the lift closes a gap in the row, not a headland: 3 m. A stone, a ditch or a correction of the operator's is
/// crossed within a metre or two; a tracked transplanter's turn at the row's
/// end covers more (half a turn around the next ridge, and the track moves
/// while it pivots). The spacing across such a gap, from the last plant
/// before the lift to the first after the lowering, counts in the figures
/// since Start when it is a miss (more than 1.5 X): the row has a hole
/// there. A shorter one is left out: the first plant after a lowering is
/// placed by its own setting, not at X.
pub const ROW_GAP_MAX_UP_UM: u64 = 3_000_000;

/// "No ground distance" in [`Quality`]'s positions (2⁶⁴ − 1 µm is never
/// reached: 18 million km).
const NONE: u64 = u64::MAX;

/// Running sums of one pass, or of every pass since Start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tally {
    /// Plants (partitions that left with the unit down).
    plants: u32,
    /// Spacings (consecutive plants of one pass).
    spacings: u32,
    /// `s ≤ 0.5·X`.
    multiples: u32,
    /// `s > 1.5·X`.
    misses: u32,
    /// `|s − X| ≤ 0.1·X`.
    within: u32,
    /// Ground distance with the unit down, µm.
    distance_um: u64,
    /// Σ (s − X) over the singles, µm.
    sum_dev: i64,
    /// Σ (s − X)² over the singles, µm².
    sum_sq_dev: u64,
}

/// The indices of a [`Tally`], for the screen and the log.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Indices {
    /// Plants.
    pub plants: u32,
    /// Spacings counted (the indices' denominator).
    pub spacings: u32,
    /// Distance with the unit down, mm.
    pub distance_mm: u32,
    /// Plants per metre × 100.
    pub plants_per_m_x100: u32,
    /// Multiples index D, 0.1 %.
    pub multiples_x10: u16,
    /// Miss index M, 0.1 %.
    pub misses_x10: u16,
    /// Quality of feed A, 0.1 %.
    pub quality_of_feed_x10: u16,
    /// Precision C (CV of the singles), 0.1 %.
    pub cv_x10: u16,
    /// Share of spacings within ±10 % of X, 0.1 %.
    pub within_10_pct_x10: u16,
}

/// `num / den` in 0.1 %, rounded to the nearest (0 when `den` is 0).
fn per_mille(num: u32, den: u32) -> u16 {
    u16::try_from(per_mille_u64(u64::from(num), u64::from(den))).unwrap_or(u16::MAX)
}

/// `num · 1000 / den`, rounded to the nearest (0 when `den` is 0);
/// `num < 2⁵³` (every caller's bound) keeps `num · 1000` in range.
fn per_mille_u64(num: u64, den: u64) -> u64 {
    num.wrapping_mul(1000)
        .wrapping_add(den / 2)
        .checked_div(den)
        .unwrap_or(0)
}

/// ⌊√v⌋ (bit by bit, no floating point).
fn isqrt(v: u64) -> u64 {
    let mut rem = v;
    let mut root = 0u64;
    let mut bit = 1u64 << 62;
    while bit > v {
        bit >>= 2;
    }
    while bit != 0 {
        let trial = root.saturating_add(bit);
        if rem >= trial {
            rem = rem.saturating_sub(trial);
            root = (root >> 1).saturating_add(bit);
        } else {
            root >>= 1;
        }
        bit >>= 2;
    }
    root
}

impl Tally {
    /// Nothing counted.
    const ZERO: Self = Self {
        plants: 0,
        spacings: 0,
        multiples: 0,
        misses: 0,
        within: 0,
        distance_um: 0,
        sum_dev: 0,
        sum_sq_dev: 0,
    };

    #[inline(never)]
    fn add_spacing(&mut self, s_um: u64, x_um: u32) {
        self.spacings = self.spacings.saturating_add(1);
        // s ≤ 0.5·X ⇔ s ≤ ⌊X/2⌋ and s > 1.5·X ⇔ s > ⌊3X/2⌋ (s and X whole
        // µm): exact. X ≤ 500 mm, so 3X fits u32.
        let x = u64::from(x_um);
        if s_um <= x / 2 {
            self.multiples = self.multiples.saturating_add(1);
        } else if s_um > x.wrapping_mul(3) / 2 {
            self.misses = self.misses.saturating_add(1);
        } else {
            // A single: |s − X| ≤ X/2 < 2¹⁸ µm, so the deviation fits i32
            // and its square (< 2³⁶) is a 32 × 32-bit product.
            let dev = i32::try_from(s_um)
                .unwrap_or(i32::MAX)
                .wrapping_sub(i32::try_from(x_um).unwrap_or(i32::MAX));
            let mag = u64::from(dev.unsigned_abs());
            self.sum_dev = self.sum_dev.saturating_add(i64::from(dev));
            self.sum_sq_dev = self.sum_sq_dev.saturating_add(mag.wrapping_mul(mag));
            // Within ±10 %: |s − X| ≤ X/10 ⇔ 10·|s − X| ≤ X (a subset of
            // the singles).
            if mag.wrapping_mul(10) <= x {
                self.within = self.within.saturating_add(1);
            }
        }
    }

    /// The indices for target spacing `x_um`.
    ///
    /// Plain (wrapping) arithmetic where the bounds below hold, to keep the
    /// image small: counts ≤ 2³², so `count · 1000 < 2⁴²` and
    /// `plants · 10⁸ < 2⁶³`; the CV's terms under the exactness limit of the
    /// module docs.
    #[inline(never)]
    fn indices(&self, x_um: u32) -> Indices {
        let n = self.spacings;
        // multiples + misses ≤ spacings by construction.
        let singles = n.wrapping_sub(self.multiples).wrapping_sub(self.misses);
        // Sample SD of the singles: with the integer m = T / k (truncated),
        // Σ(d − m)² = S − m·(2T − k·m) exactly; m is within 1 µm of the
        // mean, whose fraction is left in (≤ k µm² on ≥ k·σ²).
        let cv_x10 = if singles >= 2 {
            let k = i64::from(singles);
            let t = self.sum_dev;
            let m = t.checked_div(k).unwrap_or(0);
            let s = i64::try_from(self.sum_sq_dev).unwrap_or(i64::MAX);
            let ss =
                s.wrapping_sub(m.wrapping_mul(t.wrapping_mul(2).wrapping_sub(k.wrapping_mul(m))));
            let var = ss
                .max(0)
                .unsigned_abs()
                .checked_div(u64::from(singles.wrapping_sub(1)))
                .unwrap_or(0);
            // The mean ≥ X/2 > 0.
            let mean_um = i64::from(x_um).wrapping_add(m).max(1).unsigned_abs();
            per_mille_u64(isqrt(var), mean_um)
        } else {
            0
        };
        Indices {
            plants: self.plants,
            spacings: n,
            distance_mm: u32::try_from(self.distance_um / 1000).unwrap_or(u32::MAX),
            // plants / m × 100 = plants · 10⁸ / distance µm, rounded.
            plants_per_m_x100: u32::try_from(per_mille_u64(
                u64::from(self.plants).wrapping_mul(100_000),
                self.distance_um,
            ))
            .unwrap_or(u32::MAX),
            multiples_x10: per_mille(self.multiples, n),
            misses_x10: per_mille(self.misses, n),
            // A is the singles' share, rounded on its own.
            quality_of_feed_x10: per_mille(singles, n),
            cv_x10: u16::try_from(cv_x10).unwrap_or(u16::MAX),
            within_10_pct_x10: per_mille(self.within, n),
        }
    }
}

/// The planting quality since Start and of the pass in progress (or the
/// last one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Quality {
    /// Target spacing X, µm (0 before [`start`](Self::start)).
    x_um: u32,
    /// Since Start: every plant and spacing, the distance of the passes
    /// ended.
    total: Tally,
    /// The pass in progress (or the last one, after its end).
    pass: Tally,
    /// Where the pass in progress began (ground distance, µm), or [`NONE`]
    /// (a sentinel rather than an `Option`: 16 bytes less in the
    /// supervisor).
    pass_from_um: u64,
    /// The last plant of this pass, ground distance µm, or [`NONE`].
    last_plant_um: u64,
    /// The last plant before the last lift (ground µm + 1; 0: none to
    /// count): the gap to the next pass's first plant may be a hole in the
    /// row ([`ROW_GAP_MAX_UP_UM`]).
    gap_from: u64,
}

impl Quality {
    /// Nothing counted.
    pub const fn new() -> Self {
        Self {
            x_um: 0,
            total: Tally::ZERO,
            pass: Tally::ZERO,
            pass_from_um: NONE,
            last_plant_um: NONE,
            gap_from: 0,
        }
    }

    /// Start: everything since the last Start is forgotten; `x_um` is the
    /// target spacing. No pass is open until [`begin_pass`](Self::begin_pass).
    pub fn start(&mut self, x_um: u32) {
        *self = Self::new();
        self.x_um = x_um;
    }

    /// The unit went down at ground distance `at_um`: a new pass.
    pub fn begin_pass(&mut self, at_um: u64) {
        if self.pass_from_um != NONE {
            self.end_pass(at_um);
        }
        self.pass = Tally::default();
        self.pass_from_um = at_um.min(NONE - 1);
        self.last_plant_um = NONE;
    }

    /// The unit went up (or Stop) at `at_um`: the pass ends, its distance
    /// joins the total. Returns whether a pass was open.
    pub fn end_pass(&mut self, at_um: u64) -> bool {
        let from = core::mem::replace(&mut self.pass_from_um, NONE);
        if from == NONE {
            return false;
        }
        let d = at_um.saturating_sub(from);
        self.pass.distance_um = d;
        self.total.distance_um = self.total.distance_um.saturating_add(d);
        self.gap_from = self.last_plant_um.wrapping_add(1); // NONE → 0
        true
    }

    /// Whether a pass is open (plants count).
    pub fn in_pass(&self) -> bool {
        self.pass_from_um != NONE
    }

    /// A partition left at ground distance `at_um` (ignored outside a pass).
    pub fn plant(&mut self, at_um: u64) {
        if self.pass_from_um == NONE {
            return;
        }
        self.pass.plants = self.pass.plants.saturating_add(1);
        self.total.plants = self.total.plants.saturating_add(1);
        let last = self.last_plant_um;
        if last != NONE {
            let s = at_um.saturating_sub(last);
            self.pass.add_spacing(s, self.x_um);
            self.total.add_spacing(s, self.x_um);
        } else if self.gap_from != 0 {
            // The pass's first plant after a gap in the row (lowered within
            // [`ROW_GAP_MAX_UP_UM`] of the last plant before the lift): a
            // miss since Start if the hole is more than 1.5 X.
            let from = self.gap_from.wrapping_sub(1);
            let s = at_um.saturating_sub(from);
            if self.pass_from_um.saturating_sub(from) < ROW_GAP_MAX_UP_UM
                && s > u64::from(self.x_um).wrapping_mul(3) / 2
            {
                self.total.add_spacing(s, self.x_um);
            }
        }
        self.gap_from = 0;
        // (A position is never [`NONE`].)
        self.last_plant_um = at_um;
    }

    /// The pass in progress up to `now_um` (or the last one ended).
    fn pass_tally(&self, now_um: u64) -> Tally {
        let mut t = self.pass;
        let from = self.pass_from_um;
        if from != NONE {
            t.distance_um = now_um.saturating_sub(from);
        }
        t
    }

    /// The indices of the last pass ended (of the one in progress, its
    /// distance not yet counted: [`pass_at`](Self::pass_at) counts it).
    pub fn pass(&self) -> Indices {
        self.pass.indices(self.x_um)
    }

    /// The indices of the pass in progress up to ground distance `now_um`
    /// (of the last pass when none is open).
    pub fn pass_at(&self, now_um: u64) -> Indices {
        self.pass_tally(now_um).indices(self.x_um)
    }

    /// The indices since Start, the pass in progress counted up to `now_um`.
    pub fn since_start(&self, now_um: u64) -> Indices {
        let mut t = self.total;
        let from = self.pass_from_um;
        if from != NONE {
            t.distance_um = t.distance_um.saturating_add(now_um.saturating_sub(from));
        }
        t.indices(self.x_um)
    }
}

#[cfg(test)]
mod tests {
    #![allow(
        clippy::unwrap_used,
        clippy::arithmetic_side_effects,
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::indexing_slicing
    )]
    use super::*;
    use proptest::prelude::*;
    use std::vec::Vec;

    /// The f64 reference, written from the definitions (module docs), not
    /// from the code: classes by `s/X`, sample SD over mean of the singles.
    struct Reference {
        plants: usize,
        n: usize,
        d: f64,
        m: f64,
        a: f64,
        cv: f64,
        within: f64,
        per_m: f64,
    }

    fn reference(passes: &[(f64, Vec<f64>, f64)], x: f64) -> Reference {
        let mut spacings = Vec::new();
        let mut plants = 0;
        let mut distance = 0.0;
        // The last plant of the pass before.
        let mut before: Option<f64> = None;
        for (from, plants_at, to) in passes {
            plants += plants_at.len();
            distance += to - from;
            // Lowered within 3 m of the last plant before the lift: a gap in
            // the row, the spacing across it counts when it is a miss.
            if let (Some(last), Some(first)) = (before, plants_at.first()) {
                if from - last < 3e6 && (first - last) / x > 1.5 {
                    spacings.push(first - last);
                }
            }
            for w in plants_at.windows(2) {
                spacings.push(w[1] - w[0]);
            }
            before = plants_at.last().copied();
        }
        let n = spacings.len();
        let share = |f: &dyn Fn(f64) -> bool| {
            if n == 0 {
                0.0
            } else {
                100.0 * spacings.iter().filter(|&&s| f(s)).count() as f64 / n as f64
            }
        };
        let singles: Vec<f64> = spacings
            .iter()
            .copied()
            .filter(|&s| s / x > 0.5 && s / x <= 1.5)
            .collect();
        let cv = if singles.len() >= 2 {
            let k = singles.len() as f64;
            let mean = singles.iter().sum::<f64>() / k;
            let var = singles.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (k - 1.0);
            100.0 * var.sqrt() / mean
        } else {
            0.0
        };
        Reference {
            plants,
            n,
            d: share(&|s| s / x <= 0.5),
            m: share(&|s| s / x > 1.5),
            a: share(&|s| s / x > 0.5 && s / x <= 1.5),
            cv,
            within: share(&|s| ((s - x) / x).abs() <= 0.1),
            per_m: if distance > 0.0 {
                plants as f64 / distance
            } else {
                0.0
            },
        }
    }

    /// Random passes: spacings around X with a spread, some multiples and
    /// misses, positions in whole µm (what the firmware holds).
    fn passes() -> impl Strategy<Value = (u32, Vec<(u64, Vec<u64>, u64)>)> {
        (
            30_000u32..=500_000,
            proptest::collection::vec(
                (
                    0u64..4_000_000,
                    proptest::collection::vec((0u32..100, -300i32..300), 0..120),
                    0u64..500_000,
                ),
                1..4,
            ),
        )
            .prop_map(|(x, raw)| {
                let mut at = 0u64;
                let mut out = Vec::new();
                for (gap, steps, tail) in raw {
                    at += gap;
                    let from = at;
                    let mut plants = Vec::new();
                    for (kind, dev_permille) in steps {
                        // 5 % multiples (0–50 % of X), 5 % misses (150–300 %),
                        // the rest X ± 30 %.
                        let s = if kind < 5 {
                            u64::from(x) * u64::from(kind) / 10
                        } else if kind < 10 {
                            u64::from(x) * (15 + u64::from(kind)) / 10
                        } else {
                            (i64::from(x) + i64::from(x) * i64::from(dev_permille) / 1000) as u64
                        };
                        at += s;
                        plants.push(at);
                    }
                    at += tail;
                    out.push((from, plants, at));
                }
                (x, out)
            })
    }

    fn run(x: u32, passes: &[(u64, Vec<u64>, u64)]) -> Indices {
        let mut q = Quality::new();
        q.start(x);
        for (from, plants, to) in passes {
            q.begin_pass(*from);
            for &p in plants {
                q.plant(p);
            }
            q.end_pass(*to);
        }
        q.since_start(u64::MAX)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// Since Start over random passes: every index within its rounding
        /// (0.05 % for shares; CV 0.05 % plus the integer SD's < 1 µm).
        #[test]
        fn since_start_matches_the_f64_reference((x, passes) in passes()) {
            let got = run(x, &passes);
            // In µm as f64 (whole numbers, exact), so that a spacing exactly
            // on a class boundary (the generator makes some) compares as it
            // is: a quotient that is exactly 0.1 rounds to the literal 0.1.
            let as_um: Vec<(f64, Vec<f64>, f64)> = passes
                .iter()
                .map(|(f, p, t)| (*f as f64, p.iter().map(|&v| v as f64).collect(), *t as f64))
                .collect();
            let mut r = reference(&as_um, f64::from(x));
            r.per_m *= 1e6;
            prop_assert_eq!(got.plants as usize, r.plants);
            prop_assert_eq!(got.spacings as usize, r.n);
            let close = |got: u16, want: f64| (f64::from(got) / 10.0 - want).abs() <= 0.05 + 1e-9;
            prop_assert!(close(got.multiples_x10, r.d), "D {} vs {}", got.multiples_x10, r.d);
            prop_assert!(close(got.misses_x10, r.m), "M {} vs {}", got.misses_x10, r.m);
            prop_assert!(close(got.quality_of_feed_x10, r.a), "A {} vs {}", got.quality_of_feed_x10, r.a);
            prop_assert!(close(got.within_10_pct_x10, r.within), "±10 % {} vs {}", got.within_10_pct_x10, r.within);
            // The SD is floored to whole µm: at most 1 µm / (0.5·X) more.
            let cv_slack = 0.05 + 100.0 * 1.0 / (0.5 * f64::from(x)) + 1e-9;
            prop_assert!(
                (f64::from(got.cv_x10) / 10.0 - r.cv).abs() <= cv_slack,
                "CV {} vs {}", got.cv_x10, r.cv
            );
            let per_m = f64::from(got.plants_per_m_x100) / 100.0;
            prop_assert!((per_m - r.per_m).abs() <= 0.005 + 1e-9 || r.per_m > 1e6, "{per_m} vs {}", r.per_m);
        }
    }

    #[test]
    fn isqrt_is_the_floor_of_the_root() {
        for v in (0..100_000u64).chain([u64::MAX, u64::MAX - 1, 1 << 62, (1 << 32) - 1]) {
            let r = isqrt(v);
            assert!(u128::from(r) * u128::from(r) <= u128::from(v), "{v}");
            assert!(u128::from(r + 1) * u128::from(r + 1) > u128::from(v), "{v}");
        }
    }

    #[test]
    fn plants_outside_a_pass_do_not_count_and_a_hole_in_the_row_is_a_miss() {
        let mut q = Quality::new();
        q.start(70_000);
        q.plant(10_000); // before any pass: ignored
        q.begin_pass(0);
        q.plant(70_000);
        q.plant(140_000);
        q.end_pass(150_000);
        // Lifted: ignored.
        q.plant(200_000);
        // Lowered 860 mm after the last plant (within the row: under 3 m):
        // the hole from the plant at 140 mm to the next at 1070 mm (13.3 X)
        // is a miss.
        q.begin_pass(1_000_000);
        q.plant(1_070_000);
        q.plant(1_140_000);
        q.end_pass(1_200_000);
        let i = q.since_start(1_200_000);
        assert_eq!((i.plants, i.spacings), (4, 3));
        // 1 of 3.
        assert_eq!(i.misses_x10, 333);
        // Distance with the unit down: 150 mm + 200 mm.
        assert_eq!(i.distance_mm, 350);
        // The pass's own figures: its own spacing only.
        let p = q.pass_at(1_200_000);
        assert_eq!((p.plants, p.spacings, p.distance_mm), (2, 1, 200));
        // Lowered over 3 m after the last plant (a headland): no hole in the
        // row; nor is a gap
        // of at most 1.5 X (the first plant is placed by its own setting).
        q.begin_pass(4_300_000);
        q.plant(4_400_000);
        q.end_pass(4_420_000);
        q.begin_pass(4_430_000);
        q.plant(4_500_000); // 100 mm after the last: 1.43 X
        let i = q.since_start(4_700_000);
        assert_eq!((i.plants, i.spacings, i.misses_x10), (6, 3, 333));
    }
}
