//! Fixed-point fuzzy gain tuner (direct inference) and its lookup-table twin.
//!
//! # Inference
//!
//! 1. `e` and `ec` (r/min, r/min per sample) are scaled onto the fuzzy domain
//!    `[−3, 3]` (`Ke = 3/e_domain`, `Kec = 3/ec_domain`) and saturated there.
//!    Both steps are folded into one multiply-add that gives the *position* of
//!    the input on the partition, `pos = x·(n−1)/(2·domain) + (n−1)/2 ∈ [0, n−1]`.
//! 2. The `n` sets are triangles with peaks evenly spaced over `[−3, 3]`
//!    (shoulders at both ends, which the saturation makes implicit). At any
//!    input at most two neighbouring sets are active, with degrees `1 − w` and
//!    `w`, where `w = frac(pos)`. So at most 2×2 rules fire.
//! 3. AND is the product (default) or the minimum of the two degrees.
//! 4. Defuzzification is the weighted average of the rule singletons
//!    (`label/3 · range`). With the product, the four firing strengths are
//!    `(1−w)(1−v), w(1−v), (1−w)v, wv` and sum to exactly 1 — in fixed point too,
//!    because they are formed as `m11 = w·v`, `m10 = w − m11`, `m01 = v − m11`,
//!    `m00 = 1 − w − v + m11` — so the weighted average needs **no division**.
//!    With the minimum the strengths sum to `s ∈ [1, 2]` and one reciprocal per
//!    step is needed (the lookup table removes it).
//!
//! # Formats
//!
//! Inputs, positions, degrees and outputs are `I16F16`. The weighted sums are
//! accumulated in `i64` (`Q16 · Q16 → Q32`, four terms of at most `2^16 · 2^31`
//! each, far from `i64` overflow) and rounded once back to `I16F16`.

use fixed::types::I16F16;

use crate::rules::{GainOutput, RuleBase, RuleBaseSize, Table, MAX_SETS};
use crate::{Error, Gains};

type Fix = I16F16;

/// Number of grid points per axis of the lookup table (13: the fuzzy domain
/// `[−3, 3]` in steps of 0.5, which contains the peaks of the 3-, 5- and 7-set
/// partitions).
pub const LUT_POINTS: usize = 13;

/// Largest accepted basic-domain half-width of `e` or `ec` (r/min). Keeps the
/// scale factor `3/domain` resolvable in `I16F16` to better than 0.01 %.
pub const MAX_INPUT_DOMAIN: Fix = Fix::lit("500");
/// Smallest accepted basic-domain half-width of `e` or `ec`.
pub const MIN_INPUT_DOMAIN: Fix = Fix::lit("0.01");
/// Largest accepted output range (ΔK half-width).
pub const MAX_OUTPUT_RANGE: Fix = Fix::lit("1000");

/// How the degrees of `e` and `ec` combine into a rule's firing strength.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AndOperator {
    /// Product: strengths sum to 1, the surface is bilinear between the set
    /// peaks, and defuzzification needs no division (default).
    #[default]
    Product,
    /// Minimum: classic Mamdani AND; needs one reciprocal per direct step.
    Min,
}

/// Configuration of the fuzzy tuner (SPEC §5 defaults).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FuzzyConfig {
    /// The rule base (size and the three tables).
    pub rules: RuleBase,
    /// AND operator.
    pub and: AndOperator,
    /// Half-width of the basic domain of `e`, r/min (25).
    pub e_domain: Fix,
    /// Half-width of the basic domain of `ec`, r/min per sample (10).
    pub ec_domain: Fix,
    /// Half-widths of the output domains: ΔKp 5, ΔKi 1.25, ΔKd 2.5.
    pub range: Gains,
}

impl Default for FuzzyConfig {
    fn default() -> Self {
        Self::paper(RuleBaseSize::Seven)
    }
}

impl FuzzyConfig {
    /// SPEC §5: the paper's tables at `size`, product AND, `e ∈ [−25, 25]`,
    /// `ec ∈ [−10, 10]`, ΔKp ∈ ±5, ΔKi ∈ ±1.25, ΔKd ∈ ±2.5.
    #[must_use]
    pub fn paper(size: RuleBaseSize) -> Self {
        Self {
            rules: RuleBase::paper(size),
            and: AndOperator::Product,
            e_domain: const { Fix::lit("25") },
            ec_domain: const { Fix::lit("10") },
            range: Gains {
                kp: const { Fix::lit("5") },
                ki: const { Fix::lit("1.25") },
                kd: const { Fix::lit("2.5") },
            },
        }
    }

    fn validate(&self) -> Result<(), Error> {
        for d in [self.e_domain, self.ec_domain] {
            if !(MIN_INPUT_DOMAIN..=MAX_INPUT_DOMAIN).contains(&d) {
                return Err(Error::InputDomain);
            }
        }
        let r = self.range;
        for (v, o) in [
            (r.kp, GainOutput::Kp),
            (r.ki, GainOutput::Ki),
            (r.kd, GainOutput::Kd),
        ] {
            if v <= Fix::ZERO || v > MAX_OUTPUT_RANGE {
                return Err(Error::OutputRange(o));
            }
        }
        Ok(())
    }
}

/// Maps a physical input onto cell index and fraction of an evenly spaced
/// partition with `last_cell + 2` points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Axis {
    /// Half-width of the basic domain: inputs saturate to `±domain`.
    domain: Fix,
    /// `(points − 1) / (2·domain)` in Q32 (r/min → position units), so that
    /// the scale factor is exact to 2^-32 (an `I16F16` factor such as
    /// `3/25 = 0.12` would be off by 4·10⁻⁵ relative).
    gain_q32: i64,
    /// `(points − 1) / 2`: position of input 0.
    offset: Fix,
    /// `points − 1`: the largest position.
    max_pos: Fix,
    /// `points − 2`: index of the last cell.
    last_cell: usize,
}

impl Axis {
    fn new(points: usize, domain: Fix) -> Result<Self, Error> {
        let cells = points.checked_sub(1).ok_or(Error::RuleBaseSize(points))?;
        let last_cell = cells.checked_sub(1).ok_or(Error::RuleBaseSize(points))?;
        let cells_i = i64::try_from(cells).map_err(|_| Error::RuleBaseSize(points))?;
        let max_pos = i32::try_from(cells)
            .ok()
            .and_then(Fix::checked_from_num)
            .ok_or(Error::RuleBaseSize(points))?;
        let offset = max_pos.checked_div_int(2).ok_or(Error::InputDomain)?;
        if domain <= Fix::ZERO {
            return Err(Error::InputDomain);
        }
        // gain = cells / (2·domain); domain = bits/2^16 ⇒
        // gain_q32 = cells·2^48 / (2·bits), rounded (build time only).
        let den = i64::from(domain.to_bits()).saturating_mul(2);
        let gain_q32 = cells_i
            .checked_shl(48)
            .and_then(|n| n.checked_add(den.wrapping_shr(1)))
            .and_then(|n| n.checked_div(den))
            .ok_or(Error::InputDomain)?;
        Ok(Self {
            domain,
            gain_q32,
            offset,
            max_pos,
            last_cell,
        })
    }

    /// Cell index and fraction `w ∈ [0, 1]` of a physical input (saturated).
    /// Not inlined: one body for both inputs.
    #[inline(never)]
    fn locate(&self, x: Fix) -> (usize, Fix) {
        // Saturate in physical units first: then |x_bits·gain_q32| ≤
        // cells·2^47 ≤ 12·2^47 < 2^51, well inside i64.
        let x = x.max(self.domain.saturating_neg()).min(self.domain);
        let scaled = i64::from(x.to_bits())
            .wrapping_mul(self.gain_q32)
            .wrapping_add(1 << 31)
            .wrapping_shr(32);
        let scaled = Fix::from_bits(i32::try_from(scaled).unwrap_or(0));
        self.locate_pos(scaled.saturating_add(self.offset))
    }

    /// Cell index and fraction of a position (saturated to `[0, max_pos]`).
    #[inline]
    fn locate_pos(&self, pos: Fix) -> (usize, Fix) {
        let pos = pos.max(Fix::ZERO).min(self.max_pos);
        let cell = usize::try_from(pos.to_bits().wrapping_shr(Fix::FRAC_NBITS)).unwrap_or(0);
        if cell > self.last_cell {
            (self.last_cell, Fix::ONE)
        } else {
            (cell, pos.frac())
        }
    }
}

/// The four firing strengths of the active 2×2 rules, `[m00, m10, m01, m11]`
/// (first index: e cell side, second: ec cell side), and their sum's reciprocal
/// if it is not 1.
#[inline]
fn strengths(and: AndOperator, w: Fix, v: Fix) -> ([Fix; 4], Option<Fix>) {
    let w0 = Fix::ONE.saturating_sub(w);
    let v0 = Fix::ONE.saturating_sub(v);
    match and {
        AndOperator::Product => {
            // Exact partition of unity: m00 + m10 + m01 + m11 == 1 bit for bit.
            let m11 = crate::smul(w, v);
            let m10 = w.saturating_sub(m11);
            let m01 = v.saturating_sub(m11);
            let m00 = w0.saturating_sub(m01);
            ([m00, m10, m01, m11], None)
        }
        AndOperator::Min => {
            let m = [w0.min(v0), w.min(v0), w0.min(v), w.min(v)];
            let s = m.iter().fold(Fix::ZERO, |acc, &x| acc.saturating_add(x));
            // s ∈ [1, 2] for a triangular partition, so the reciprocal exists.
            (m, Fix::ONE.checked_div(s))
        }
    }
}

/// `Σ m_k · c_k` over four terms, accumulated in `i64` and rounded once.
#[inline]
fn weighted(m: &[Fix; 4], c: [Fix; 4]) -> Fix {
    // |m| ≤ 2^16 and |c| < 2^31: each product < 2^47, the sum < 2^49.
    let acc = m.iter().zip(c).fold(0_i64, |acc, (mk, ck)| {
        acc.wrapping_add(i64::from(mk.to_bits()).wrapping_mul(i64::from(ck.to_bits())))
    });
    // Round half up, back to Q16.
    let q = acc
        .wrapping_add(1 << (Fix::FRAC_NBITS - 1))
        .wrapping_shr(Fix::FRAC_NBITS);
    Fix::from_bits(i32::try_from(q).unwrap_or(if q < 0 { i32::MIN } else { i32::MAX }))
}

#[inline]
fn clamp_sym(x: Fix, r: Fix) -> Fix {
    x.max(r.saturating_neg()).min(r)
}

/// Direct fixed-point fuzzy inference over the active rules.
///
/// Stores the rule consequents as their `i8` labels (3 × 49 bytes) plus, per
/// output, the seven singleton values `label/3 · range` for `label ∈ −3..=3`
/// (computed once in [`new`](Self::new), truncated exactly as before), so a
/// firing rule costs one table read and no multiply beyond the weighting:
/// 280 bytes on thumbv7m instead of about 650 for an `I16F16` singleton per
/// cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FuzzyTuner {
    e: Axis,
    ec: Axis,
    and: AndOperator,
    /// Consequent labels `[ΔKp, ΔKi, ΔKd][e set][ec set]`, `−3..=3`; zero
    /// outside the `n × n` corner.
    labels: [Table; 3],
    /// Singletons `label/3 · range` indexed by `label + 3`, per output.
    /// `values[o][6]` is the output's range itself.
    values: [[Fix; 7]; 3],
}

/// The singleton of `label` from one output's value row (0 for a label outside
/// `−3..=3`, which a validated rule base never holds).
#[inline]
fn singleton(values: &[Fix; 7], label: i8) -> Fix {
    usize::try_from(i16::from(label).wrapping_add(3))
        .ok()
        .and_then(|k| values.get(k))
        .copied()
        .unwrap_or(Fix::ZERO)
}

impl FuzzyTuner {
    /// Validates `cfg` and precomputes scale factors and rule singletons.
    #[inline(never)]
    pub fn new(cfg: &FuzzyConfig) -> Result<Self, Error> {
        cfg.validate()?;
        let n = cfg.rules.size();
        let e = Axis::new(n, cfg.e_domain)?;
        let ec = Axis::new(n, cfg.ec_domain)?;
        // Built in place: the rule base's tables, zeroed outside the `n × n`
        // corner, and the singletons.
        let mut t = Self {
            e,
            ec,
            and: cfg.and,
            labels: *cfg.rules.tables(),
            values: [[Fix::ZERO; 7]; 3],
        };
        for table in &mut t.labels {
            for (row, line) in table.iter_mut().enumerate() {
                for (col, l) in line.iter_mut().enumerate() {
                    if row >= n || col >= n {
                        *l = 0;
                    }
                }
            }
        }
        let ranges = [cfg.range.kp, cfg.range.ki, cfg.range.kd];
        for (vals, r) in t.values.iter_mut().zip(ranges) {
            for (label, v) in (-3_i32..=3).zip(vals.iter_mut()) {
                // Exactly the former per-cell singleton: r·label, then
                // truncated division by 3 (|r| ≤ 1000: |r·label| < 2^28).
                *v = Fix::from_bits(r.to_bits().wrapping_mul(label).wrapping_div(3));
            }
        }
        Ok(t)
    }

    /// ΔKp, ΔKi, ΔKd for error `e` (r/min, `target − measured`) and error change
    /// `ec` (r/min per sample). Any input is accepted; outside the basic
    /// domains it saturates. Each output lies within `±range`.
    ///
    /// ```
    /// use fuzzy_pid::{FuzzyConfig, FuzzyTuner, I16F16};
    ///
    /// let tuner = FuzzyTuner::new(&FuzzyConfig::default())?;
    /// // e = 2 r/min with the 7 sets 25/3 r/min apart: 24 % of the way from
    /// // ZO to PS; ec = 0 (ZO). Rules (ZO, ZO) and (PS, ZO) fire with 0.76
    /// // and 0.24. From SPEC §5's tables: ΔKp = 0.24·NS(−5/3) = −0.4,
    /// // ΔKi = 0.24·PS(1.25/3) = 0.1, ΔKd = 0.76·NS(−2.5/3) = −0.6333.
    /// let g = tuner.infer(I16F16::from_num(2), I16F16::ZERO);
    /// assert!((g.kp.to_num::<f64>() + 0.4).abs() < 1e-3);
    /// assert!((g.ki.to_num::<f64>() - 0.1).abs() < 1e-3);
    /// assert!((g.kd.to_num::<f64>() + 0.6333).abs() < 1e-3);
    /// // Far outside the domain the input saturates at PB: the corner rule.
    /// let far = tuner.infer(I16F16::from_num(1000), I16F16::ZERO);
    /// assert_eq!(far, tuner.infer(I16F16::from_num(25), I16F16::ZERO));
    /// # Ok::<(), fuzzy_pid::Error>(())
    /// ```
    #[must_use]
    pub fn infer(&self, e: Fix, ec: Fix) -> Gains {
        let (i, w) = self.e.locate(e);
        let (j, v) = self.ec.locate(ec);
        self.infer_cell(i, w, j, v)
    }

    /// Inference at cell `(i, j)` with fractions `(w, v)`.
    fn infer_cell(&self, i: usize, w: Fix, j: usize, v: Fix) -> Gains {
        let (m, recip) = strengths(self.and, w, v);
        // `locate` never returns a cell beyond `MAX_SETS − 2`; saying so lets
        // the compiler drop the twelve bounds checks below.
        let i = i.min(MAX_SETS - 2);
        let j = j.min(MAX_SETS - 2);
        let i1 = i.saturating_add(1);
        let j1 = j.saturating_add(1);
        let mut out = [Fix::ZERO; 3];
        // One loop body for the three outputs (smaller code than three
        // inlined copies; same arithmetic in the same order).
        for ((slot, table), values) in out.iter_mut().zip(&self.labels).zip(&self.values) {
            let at = |r: usize, c: usize| {
                let label = table
                    .get(r)
                    .and_then(|line| line.get(c))
                    .copied()
                    .unwrap_or(0);
                singleton(values, label)
            };
            let mut x = weighted(&m, [at(i, j), at(i1, j), at(i, j1), at(i1, j1)]);
            if let Some(r) = recip {
                x = crate::smul(x, r);
            }
            *slot = clamp_sym(x, values[6]);
        }
        let [kp, ki, kd] = out;
        Gains { kp, ki, kd }
    }

    /// Number of fuzzy sets per input.
    #[must_use]
    pub const fn sets(&self) -> usize {
        self.e.last_cell.saturating_add(2)
    }
}

/// The fuzzy gain surface precomputed on a 13×13 grid over the fuzzy domain,
/// read back by bilinear interpolation. Same inputs and outputs as
/// [`FuzzyTuner::infer`], no division per step whatever the AND operator.
///
/// Entries are stored as `i16` in Q15 of each output's range (1 014 bytes
/// instead of 2 028 for `I16F16`), resolution `range / 32768`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LutTuner {
    e: Axis,
    ec: Axis,
    /// `[e point][ec point][ΔKp, ΔKi, ΔKd]`, Q15 of `range`.
    table: [[[i16; 3]; LUT_POINTS]; LUT_POINTS],
    range: Gains,
}

impl LutTuner {
    /// Validates `cfg`, builds the direct tuner and samples it onto the grid.
    pub fn new(cfg: &FuzzyConfig) -> Result<Self, Error> {
        let fuzzy = FuzzyTuner::new(cfg)?;
        let e = Axis::new(LUT_POINTS, cfg.e_domain)?;
        let ec = Axis::new(LUT_POINTS, cfg.ec_domain)?;
        let sets = i32::try_from(fuzzy.sets()).map_err(|_| Error::RuleBaseSize(fuzzy.sets()))?;
        let steps = i32::try_from(LUT_POINTS.saturating_sub(1)).unwrap_or(12);
        // Grid point g sits at fuzzy position g·(n−1)/12 of the direct tuner.
        let pos = |g: usize| {
            i32::try_from(g)
                .ok()
                .and_then(|g| g.checked_mul(sets.saturating_sub(1)))
                .and_then(Fix::checked_from_num)
                .and_then(|x| x.checked_div_int(steps))
                .unwrap_or(Fix::ZERO)
        };
        let q15 = |x: Fix, r: Fix| -> i16 {
            let n = x.checked_div(r).unwrap_or(Fix::ZERO);
            let q = n.to_bits().wrapping_shr(1);
            i16::try_from(q.clamp(-32767, 32767)).unwrap_or(0)
        };
        let mut table = [[[0_i16; 3]; LUT_POINTS]; LUT_POINTS];
        for (gi, line) in table.iter_mut().enumerate() {
            let (i, w) = fuzzy.e.locate_pos(pos(gi));
            for (gj, cell) in line.iter_mut().enumerate() {
                let (j, v) = fuzzy.ec.locate_pos(pos(gj));
                let g = fuzzy.infer_cell(i, w, j, v);
                *cell = [
                    q15(g.kp, cfg.range.kp),
                    q15(g.ki, cfg.range.ki),
                    q15(g.kd, cfg.range.kd),
                ];
            }
        }
        Ok(Self {
            e,
            ec,
            table,
            range: cfg.range,
        })
    }

    /// ΔKp, ΔKi, ΔKd by bilinear interpolation of the precomputed surface.
    ///
    /// All in 32-bit integers: with product weights `m ∈ [0, 2^16]` summing
    /// to exactly `2^16` and Q15 entries `|c| ≤ 32767`, `|Σ m·c| ≤ 2^16·32767
    /// < 2^31`; one 64-bit multiply per output scales to the range.
    ///
    /// ```
    /// use fuzzy_pid::{FuzzyConfig, LutTuner, I16F16};
    ///
    /// let lut = LutTuner::new(&FuzzyConfig::default())?;
    /// // The same point as `FuzzyTuner::infer`'s example. The 13 grid points
    /// // split each of the 6 rule cells in two, so with product AND the
    /// // table reproduces the bilinear rule surface up to its Q15 rounding
    /// // (range/32768): e = 2 r/min sits 48 % of the way from grid point
    /// // 6 (e = 0: ΔKp 0, ΔKd −0.8333) to 7 (e = 4.1667: ΔKp −0.8333,
    /// // ΔKd −0.4167), so ΔKp = −0.4 and ΔKd = −0.6333.
    /// let g = lut.infer(I16F16::from_num(2), I16F16::ZERO);
    /// assert!((g.kp.to_num::<f64>() + 0.4).abs() < 1e-3);
    /// assert!((g.ki.to_num::<f64>() - 0.1).abs() < 1e-3);
    /// assert!((g.kd.to_num::<f64>() + 0.6333).abs() < 1e-3);
    /// # Ok::<(), fuzzy_pid::Error>(())
    /// ```
    #[must_use]
    pub fn infer(&self, e: Fix, ec: Fix) -> Gains {
        let (i, w) = self.e.locate(e);
        let (j, v) = self.ec.locate(ec);
        // `locate` never returns a cell beyond `LUT_POINTS − 2`; the clamp
        // lets the compiler drop the bounds checks of the reads below.
        let i = i.min(LUT_POINTS - 2);
        let j = j.min(LUT_POINTS - 2);
        // Product weights, as `strengths` computes them, in plain integers:
        // w, v ∈ [0, 2^16], so every difference below stays in [0, 2^16].
        let (w, v) = (w.to_bits(), v.to_bits());
        let m11 = i32::try_from(i64::from(w).wrapping_mul(i64::from(v)) >> 16).unwrap_or(0);
        let m10 = w.wrapping_sub(m11);
        let m01 = v.wrapping_sub(m11);
        let m00 = (1_i32 << 16).wrapping_sub(w).wrapping_sub(m01);
        let row = |r: usize| self.table.get(r).unwrap_or(&[[0; 3]; LUT_POINTS]);
        let (r0, r1) = (row(i), row(i.saturating_add(1)));
        let cell = |line: &[[i16; 3]; LUT_POINTS], c: usize| line.get(c).copied().unwrap_or([0; 3]);
        let j1 = j.saturating_add(1);
        let (c00, c10, c01, c11) = (cell(r0, j), cell(r1, j), cell(r0, j1), cell(r1, j1));
        let out = |k: usize, r: Fix| {
            let at = |c: [i16; 3]| i32::from(c.get(k).copied().unwrap_or(0));
            // Bounded as above: no wrap can occur.
            let acc = m00
                .wrapping_mul(at(c00))
                .wrapping_add(m10.wrapping_mul(at(c10)))
                .wrapping_add(m01.wrapping_mul(at(c01)))
                .wrapping_add(m11.wrapping_mul(at(c11)));
            // acc = value/range · 2^31; · range (Q16) / 2^31, rounded.
            let q = i64::from(acc)
                .wrapping_mul(i64::from(r.to_bits()))
                .wrapping_add(1 << 30)
                .wrapping_shr(31);
            Fix::from_bits(i32::try_from(q).unwrap_or(0))
        };
        Gains {
            kp: out(0, self.range.kp),
            ki: out(1, self.range.ki),
            kd: out(2, self.range.kd),
        }
    }
}
