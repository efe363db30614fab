//! Rule tables against the text of SPEC §5, sampling, and configuration errors.

use crate::rules::{PAPER_KD, PAPER_KI, PAPER_KP};
use crate::{
    AntiWindup, Config, Error, FuzzyConfig, GainOutput, Gains, RuleBase, RuleBaseSize, Schedule,
    I16F16,
};

/// Verbatim copy of the SPEC §5 table block (rows e NB→PB, `|` separates rows).
const SPEC: &str = "
ΔKp: PB PB PM PM PS ZO ZO | PB PB PM PS PS ZO NS | PM PM PM PS ZO NS NS | PM PM PS ZO NS NM NM
     PS PS ZO NS NS NM NM | PS ZO NS NM NM NM NB | ZO ZO NM NM NM NB NB
ΔKi: NB NB NM NM NS ZO ZO | NB NB NM NS NS ZO ZO | NB NM NS NS ZO PS PS | NM NM NS ZO PS PM PM
     NM NS ZO PS PS PM PB | ZO ZO PS PS PM PB PB | ZO ZO PS PM PM PB PB
ΔKd: PS NS NB NB NB NM PS | PS NS NB NM NM NS ZO | ZO NS NM NM NS NS ZO | ZO NS NS NS NS NS ZO
     ZO ZO ZO ZO ZO ZO ZO | PB NS PS PS PS PS PB | PB PM PM PM PS PS PB
";

fn parse() -> [[[i8; 7]; 7]; 3] {
    let labels = ["NB", "NM", "NS", "ZO", "PS", "PM", "PB"];
    let mut out = [[[0; 7]; 7]; 3];
    let words: std::vec::Vec<&str> = SPEC
        .split_whitespace()
        .filter(|w| labels.contains(w))
        .collect();
    assert_eq!(words.len(), 3 * 49);
    for (k, w) in words.iter().enumerate() {
        let v = labels.iter().position(|l| l == w).unwrap() as i8 - 3;
        out[k / 49][(k % 49) / 7][k % 7] = v;
    }
    out
}

#[test]
fn paper_tables_match_spec_text() {
    let [kp, ki, kd] = parse();
    assert_eq!(kp, PAPER_KP);
    assert_eq!(ki, PAPER_KI);
    assert_eq!(kd, PAPER_KD);
    // SPEC's remark: large positive E with ZO change lowers Kp (NM), large
    // negative E raises it (PM).
    assert_eq!(PAPER_KP[6][3], -2);
    assert_eq!(PAPER_KP[0][3], 2);
}

#[test]
fn sampled_rule_bases() {
    let spec = parse();
    for (size, keep) in [
        (RuleBaseSize::Three, &[0_usize, 3, 6][..]),
        (RuleBaseSize::Five, &[0, 2, 3, 4, 6][..]),
    ] {
        let rb = RuleBase::paper(size);
        assert_eq!(rb.size(), keep.len());
        for (o, t) in [GainOutput::Kp, GainOutput::Ki, GainOutput::Kd]
            .into_iter()
            .zip(&spec)
        {
            for (r, &rr) in keep.iter().enumerate() {
                for (c, &cc) in keep.iter().enumerate() {
                    assert_eq!(rb.label(o, r, c), Some(t[rr][cc]));
                }
                assert_eq!(rb.label(o, r, keep.len()), None);
            }
        }
    }
}

#[test]
fn custom_rule_base_is_validated() {
    let mut bad = PAPER_KP;
    bad[2][4] = 4;
    assert_eq!(
        RuleBase::custom(7, bad, PAPER_KI, PAPER_KD),
        Err(Error::RuleLabel {
            output: GainOutput::Kp,
            row: 2,
            col: 4,
            label: 4
        })
    );
    // Outside the used 3×3 corner the label is ignored.
    assert!(RuleBase::custom(3, bad, PAPER_KI, PAPER_KD).is_ok());
    assert_eq!(
        RuleBase::custom(8, PAPER_KP, PAPER_KI, PAPER_KD),
        Err(Error::RuleBaseSize(8))
    );
    assert_eq!(
        RuleBase::custom(1, PAPER_KP, PAPER_KI, PAPER_KD),
        Err(Error::RuleBaseSize(1))
    );
    // A 4-set custom base builds and the display of an error is readable.
    let rb = RuleBase::custom(4, PAPER_KP, PAPER_KI, PAPER_KD).unwrap();
    let f = FuzzyConfig {
        rules: rb,
        ..FuzzyConfig::default()
    };
    assert!(Config::with_schedule(Schedule::Fuzzy(f)).build().is_ok());
    assert!(Config::with_schedule(Schedule::Lookup(f))
        .build_lut()
        .is_ok());
    assert!(Config::with_schedule(Schedule::Lookup(f))
        .build_any()
        .is_ok());
    // `build` holds a direct tuner only: a lookup table needs its own type.
    assert_eq!(
        Config::with_schedule(Schedule::Lookup(f)).build().err(),
        Some(Error::LookupSchedule)
    );
    assert_eq!(
        Config::with_schedule(Schedule::Fuzzy(f)).build_lut().err(),
        Some(Error::LookupSchedule)
    );
    let msg = std::format!(
        "{}",
        Error::RuleLabel {
            output: GainOutput::Ki,
            row: 1,
            col: 2,
            label: -5
        }
    );
    assert_eq!(msg, "ΔKi rule (1, 2) has label -5, outside -3..=3");
}

#[test]
fn config_errors() {
    let ok = Config::default();
    assert!(ok.build().is_ok());
    let f = FuzzyConfig::default();
    let cases: [(Config, Error); 7] = [
        (
            Config {
                output_min: I16F16::from_num(50),
                ..ok
            },
            Error::OutputLimits,
        ),
        (
            Config {
                base: Gains {
                    kp: I16F16::from_num(-1),
                    ..ok.base
                },
                ..ok
            },
            Error::NegativeGain,
        ),
        (
            Config {
                derivative_filter: I16F16::ZERO,
                ..ok
            },
            Error::DerivativeFilter,
        ),
        (
            Config {
                anti_windup: AntiWindup {
                    clamping: true,
                    back_calculation: I16F16::from_num(2),
                },
                ..ok
            },
            Error::BackCalculation,
        ),
        (
            Config::with_schedule(Schedule::Fuzzy(FuzzyConfig {
                e_domain: I16F16::ZERO,
                ..f
            })),
            Error::InputDomain,
        ),
        (
            Config::with_schedule(Schedule::Lookup(FuzzyConfig {
                ec_domain: I16F16::from_num(600),
                ..f
            })),
            Error::InputDomain,
        ),
        (
            Config::with_schedule(Schedule::Fuzzy(FuzzyConfig {
                range: Gains {
                    ki: I16F16::ZERO,
                    ..f.range
                },
                ..f
            })),
            Error::OutputRange(GainOutput::Ki),
        ),
    ];
    for (cfg, err) in cases {
        assert_eq!(cfg.build_any().err(), Some(err));
    }
}
