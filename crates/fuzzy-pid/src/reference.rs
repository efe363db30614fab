//! `f64` reference of the controller, for host tests and benchmarks only
//! (compiled under `cfg(test)` or the `reference` feature, never by the
//! firmware).
//!
//! It is written independently of the fixed-point shortcuts: it evaluates the
//! membership of **every** set with the triangle formula, fires **all** `n²`
//! rules and divides `Σ μ·c` by `Σ μ`, exactly as the textbook weighted average
//! (paper A eq. 16–18). Agreement with [`FuzzyTuner`](crate::FuzzyTuner) thus
//! checks the active-rule selection, the division-free defuzzification and the
//! fixed-point formats.

use crate::fuzzy::{AndOperator, FuzzyConfig};
use crate::pid::{Config, Schedule};
use crate::rules::{GainOutput, MAX_SETS};

/// `[ΔKp, ΔKi, ΔKd]` or `[Kp, Ki, Kd]` in `f64`.
pub type Gains64 = [f64; 3];

/// f64 fuzzy inference over all rules.
#[derive(Clone, Debug)]
pub struct RefFuzzy {
    n: usize,
    and: AndOperator,
    e_domain: f64,
    ec_domain: f64,
    range: Gains64,
    /// `[output][e set][ec set]` labels.
    labels: [[[i8; MAX_SETS]; MAX_SETS]; 3],
}

impl RefFuzzy {
    /// From the same configuration as the fixed-point tuner.
    #[must_use]
    pub fn new(cfg: &FuzzyConfig) -> Self {
        let n = cfg.rules.size();
        let mut labels = [[[0_i8; MAX_SETS]; MAX_SETS]; 3];
        for (o, t) in [GainOutput::Kp, GainOutput::Ki, GainOutput::Kd]
            .into_iter()
            .zip(labels.iter_mut())
        {
            for (r, row) in t.iter_mut().enumerate() {
                for (c, x) in row.iter_mut().enumerate() {
                    *x = cfg.rules.label(o, r, c).unwrap_or(0);
                }
            }
        }
        Self {
            n,
            and: cfg.and,
            e_domain: cfg.e_domain.to_num(),
            ec_domain: cfg.ec_domain.to_num(),
            range: [
                cfg.range.kp.to_num(),
                cfg.range.ki.to_num(),
                cfg.range.kd.to_num(),
            ],
            labels,
        }
    }

    /// Degree of membership of fuzzy value `x ∈ [−3, 3]` in set `k`
    /// (triangles with peaks evenly spaced over `[−3, 3]`, shoulders at the ends).
    #[must_use]
    pub fn membership(&self, x: f64, k: usize) -> f64 {
        let h = 6.0 / (self.n as f64 - 1.0);
        let peak = -3.0 + k as f64 * h;
        if (k == 0 && x <= peak) || (k.saturating_add(1) == self.n && x >= peak) {
            return 1.0;
        }
        (1.0 - (x - peak).abs() / h).max(0.0)
    }

    /// `[ΔKp, ΔKi, ΔKd]` for `e`, `ec` in physical units.
    #[must_use]
    pub fn infer(&self, e: f64, ec: f64) -> Gains64 {
        let xe = (e * 3.0 / self.e_domain).clamp(-3.0, 3.0);
        let xc = (ec * 3.0 / self.ec_domain).clamp(-3.0, 3.0);
        let mut num = [0.0; 3];
        let mut den = 0.0;
        for i in 0..self.n {
            let mi = self.membership(xe, i);
            for j in 0..self.n {
                let mj = self.membership(xc, j);
                let w = match self.and {
                    AndOperator::Product => mi * mj,
                    AndOperator::Min => mi.min(mj),
                };
                den += w;
                for ((acc, table), range) in num.iter_mut().zip(&self.labels).zip(self.range) {
                    let label = table.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0);
                    *acc += w * f64::from(label) / 3.0 * range;
                }
            }
        }
        num.map(|x| x / den)
    }
}

/// f64 version of [`Controller`](crate::Controller) in auto mode (same
/// algorithm, for closed-loop comparisons).
#[derive(Clone, Debug)]
pub struct RefPid {
    fuzzy: Option<RefFuzzy>,
    base: Gains64,
    floor: Gains64,
    min: f64,
    max: f64,
    alpha: f64,
    clamping: bool,
    kb: f64,
    primed: bool,
    prev_e: f64,
    prev_y: f64,
    d: f64,
    /// Integral term.
    pub integral: f64,
}

impl RefPid {
    /// From the same configuration as the fixed-point controller, started.
    #[must_use]
    pub fn new(cfg: &Config) -> Self {
        let fuzzy = match &cfg.schedule {
            Schedule::Conventional => None,
            Schedule::Fuzzy(f) | Schedule::Lookup(f) => Some(RefFuzzy::new(f)),
        };
        Self {
            fuzzy,
            base: [
                cfg.base.kp.to_num(),
                cfg.base.ki.to_num(),
                cfg.base.kd.to_num(),
            ],
            floor: [
                cfg.min_gains.kp.to_num(),
                cfg.min_gains.ki.to_num(),
                cfg.min_gains.kd.to_num(),
            ],
            min: cfg.output_min.to_num(),
            max: cfg.output_max.to_num(),
            alpha: cfg.derivative_filter.to_num(),
            clamping: cfg.anti_windup.clamping,
            kb: cfg.anti_windup.back_calculation.to_num(),
            primed: false,
            prev_e: 0.0,
            prev_y: 0.0,
            d: 0.0,
            integral: 0.0,
        }
    }

    /// One step in auto mode; returns the output.
    pub fn step(&mut self, target: f64, measured: f64, ff: f64) -> f64 {
        let e = target - measured;
        if !self.primed {
            self.prev_e = e;
            self.prev_y = measured;
            self.d = 0.0;
            self.primed = true;
        }
        let ec = e - self.prev_e;
        let delta = self.fuzzy.as_ref().map_or([0.0; 3], |f| f.infer(e, ec));
        let [kp, ki, kd] = [0, 1, 2].map(|k| {
            (self.base.get(k).copied().unwrap_or(0.0) + delta.get(k).copied().unwrap_or(0.0))
                .max(self.floor.get(k).copied().unwrap_or(0.0))
        });
        self.d += self.alpha * ((self.prev_y - measured) - self.d);
        let lim = self.max - self.min;
        let base = ff + kp * e + kd * self.d;
        let di = ki * e;
        let mut i = (self.integral + di).clamp(-lim, lim);
        let mut v = base + i;
        if self.clamping && ((v > self.max && di > 0.0) || (v < self.min && di < 0.0)) {
            i = self.integral;
            v = base + i;
        }
        let u = v.clamp(self.min, self.max);
        if self.kb != 0.0 && u != v {
            i = (i + self.kb * (u - v)).clamp(-lim, lim);
        }
        self.integral = i;
        self.prev_e = e;
        self.prev_y = measured;
        u
    }
}
