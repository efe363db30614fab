//! Rule bases: the paper's 7×7 self-tuning tables, their 3×3 and 5×5 samplings,
//! and validated custom tables.
//!
//! A rule table is indexed `[row = e set][column = ec set]`, both from NB to PB.
//! Each entry is a consequent *label* in `−3..=3` (NB = −3, NM = −2, NS = −1,
//! ZO = 0, PS = 1, PM = 2, PB = 3); the label is turned into a singleton value
//! `label / 3 · range` of the output (ΔKp, ΔKi or ΔKd) when the tuner is built.

use crate::Error;

/// Largest supported number of fuzzy sets per input.
pub const MAX_SETS: usize = 7;

/// One rule table: `[e set][ec set]` → consequent label in `−3..=3`.
/// Only the leading `size × size` corner is used.
pub type Table = [[i8; MAX_SETS]; MAX_SETS];

/// Which of the three outputs a rule table (or an error) refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GainOutput {
    /// ΔKp.
    Kp,
    /// ΔKi.
    Ki,
    /// ΔKd.
    Kd,
}

impl core::fmt::Display for GainOutput {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Kp => "ΔKp",
            Self::Ki => "ΔKi",
            Self::Kd => "ΔKd",
        })
    }
}

/// Number of fuzzy sets per input of the built-in rule bases (paper A Table 8).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RuleBaseSize {
    /// 3×3: the 7×7 tables sampled at {NB, ZO, PB}.
    Three,
    /// 5×5: the 7×7 tables sampled at {NB, NS, ZO, PS, PB}.
    Five,
    /// 7×7: the full tables of SPEC §5 (the default).
    #[default]
    Seven,
}

impl RuleBaseSize {
    /// Number of sets per input (3, 5 or 7).
    #[must_use]
    pub const fn sets(self) -> usize {
        match self {
            Self::Three => 3,
            Self::Five => 5,
            Self::Seven => 7,
        }
    }

    /// Indices into the 7 paper sets (NB…PB = 0…6) that this size keeps.
    const fn sample(self) -> &'static [usize] {
        match self {
            Self::Three => &[0, 3, 6],
            Self::Five => &[0, 2, 3, 4, 6],
            Self::Seven => &[0, 1, 2, 3, 4, 5, 6],
        }
    }
}

/// ΔKp table of SPEC §5 (rows e NB→PB, columns ec NB→PB).
pub const PAPER_KP: Table = [
    [3, 3, 2, 2, 1, 0, 0],
    [3, 3, 2, 1, 1, 0, -1],
    [2, 2, 2, 1, 0, -1, -1],
    [2, 2, 1, 0, -1, -2, -2],
    [1, 1, 0, -1, -1, -2, -2],
    [1, 0, -1, -2, -2, -2, -3],
    [0, 0, -2, -2, -2, -3, -3],
];

/// ΔKi table of SPEC §5 (rows e NB→PB, columns ec NB→PB).
pub const PAPER_KI: Table = [
    [-3, -3, -2, -2, -1, 0, 0],
    [-3, -3, -2, -1, -1, 0, 0],
    [-3, -2, -1, -1, 0, 1, 1],
    [-2, -2, -1, 0, 1, 2, 2],
    [-2, -1, 0, 1, 1, 2, 3],
    [0, 0, 1, 1, 2, 3, 3],
    [0, 0, 1, 2, 2, 3, 3],
];

/// ΔKd table of SPEC §5 (rows e NB→PB, columns ec NB→PB).
pub const PAPER_KD: Table = [
    [1, -1, -3, -3, -3, -2, 1],
    [1, -1, -3, -2, -2, -1, 0],
    [0, -1, -2, -2, -1, -1, 0],
    [0, -1, -1, -1, -1, -1, 0],
    [0, 0, 0, 0, 0, 0, 0],
    [3, -1, 1, 1, 1, 1, 3],
    [3, 2, 2, 2, 1, 1, 3],
];

/// A validated rule base: `size × size` rules for each of ΔKp, ΔKi, ΔKd.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RuleBase {
    size: usize,
    /// `[ΔKp, ΔKi, ΔKd]`, each `[e set][ec set]`.
    tables: [Table; 3],
}

impl Default for RuleBase {
    fn default() -> Self {
        Self::paper(RuleBaseSize::Seven)
    }
}

impl RuleBase {
    /// The paper's tables (SPEC §5), sampled down to `size` sets per input.
    #[must_use]
    pub fn paper(size: RuleBaseSize) -> Self {
        // Sampled at compile time: at run time this is a copy of a constant.
        match size {
            RuleBaseSize::Three => const { Self::sampled(RuleBaseSize::Three) },
            RuleBaseSize::Five => const { Self::sampled(RuleBaseSize::Five) },
            RuleBaseSize::Seven => const { Self::sampled(RuleBaseSize::Seven) },
        }
    }

    /// The paper's tables sampled down to `size` sets per input (compile time).
    #[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
    const fn sampled(size: RuleBaseSize) -> Self {
        let mut tables = [[[0_i8; MAX_SETS]; MAX_SETS]; 3];
        let src = [&PAPER_KP, &PAPER_KI, &PAPER_KD];
        let sample = size.sample();
        let mut o = 0;
        while o < 3 {
            let mut r = 0;
            while r < sample.len() {
                let mut c = 0;
                while c < sample.len() {
                    tables[o][r][c] = src[o][sample[r]][sample[c]];
                    c += 1;
                }
                r += 1;
            }
            o += 1;
        }
        Self {
            size: size.sets(),
            tables,
        }
    }

    /// A custom rule base with `size` sets per input (2 ≤ size ≤ 7). Only the
    /// `size × size` corner of each table is read; every label there must lie in
    /// `−3..=3`.
    pub fn custom(size: usize, kp: Table, ki: Table, kd: Table) -> Result<Self, Error> {
        if !(2..=MAX_SETS).contains(&size) {
            return Err(Error::RuleBaseSize(size));
        }
        let tables = [kp, ki, kd];
        let outputs = [GainOutput::Kp, GainOutput::Ki, GainOutput::Kd];
        for (table, output) in tables.iter().zip(outputs) {
            for (row, line) in table.iter().take(size).enumerate() {
                for (col, &label) in line.iter().take(size).enumerate() {
                    if !(-3..=3).contains(&label) {
                        return Err(Error::RuleLabel {
                            output,
                            row,
                            col,
                            label,
                        });
                    }
                }
            }
        }
        Ok(Self { size, tables })
    }

    /// The three tables `[ΔKp, ΔKi, ΔKd]` (only the `size × size` corner is
    /// meaningful).
    pub(crate) const fn tables(&self) -> &[Table; 3] {
        &self.tables
    }

    /// Number of fuzzy sets per input.
    #[must_use]
    pub const fn size(&self) -> usize {
        self.size
    }

    /// The consequent label of rule (`row` = e set, `col` = ec set) for `output`,
    /// or `None` outside the `size × size` table.
    #[must_use]
    pub fn label(&self, output: GainOutput, row: usize, col: usize) -> Option<i8> {
        if row >= self.size || col >= self.size {
            return None;
        }
        let [kp, ki, kd] = &self.tables;
        let t = match output {
            GainOutput::Kp => kp,
            GainOutput::Ki => ki,
            GainOutput::Kd => kd,
        };
        t.get(row).and_then(|r| r.get(col)).copied()
    }
}
