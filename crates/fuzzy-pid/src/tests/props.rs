//! Property tests: any input, extremes included, never panics and stays in range.

use proptest::prelude::*;

use crate::{
    AndOperator, Config, FuzzyConfig, FuzzyTuner, LutTuner, RuleBaseSize, Schedule, I16F16,
};

fn fix() -> impl Strategy<Value = I16F16> {
    prop_oneof![
        any::<i32>().prop_map(I16F16::from_bits),
        Just(I16F16::MIN),
        Just(I16F16::MAX),
        Just(I16F16::ZERO),
        (-60.0..60.0_f64).prop_map(I16F16::from_num),
    ]
}

fn size() -> impl Strategy<Value = RuleBaseSize> {
    prop_oneof![
        Just(RuleBaseSize::Three),
        Just(RuleBaseSize::Five),
        Just(RuleBaseSize::Seven)
    ]
}

fn and() -> impl Strategy<Value = AndOperator> {
    prop_oneof![Just(AndOperator::Product), Just(AndOperator::Min)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn tuners_stay_in_range(size in size(), and in and(), e in fix(), ec in fix()) {
        let cfg = FuzzyConfig { and, ..FuzzyConfig::paper(size) };
        let r = cfg.range;
        for g in [FuzzyTuner::new(&cfg).unwrap().infer(e, ec), LutTuner::new(&cfg).unwrap().infer(e, ec)] {
            prop_assert!(g.kp.abs() <= r.kp && g.ki.abs() <= r.ki && g.kd.abs() <= r.kd, "{g:?}");
        }
    }

    #[test]
    fn controller_output_within_limits(
        size in size(),
        kind in 0..4_u8,
        steps in proptest::collection::vec((fix(), fix(), fix(), 0..12_u8), 1..40),
    ) {
        let f = FuzzyConfig::paper(size);
        let schedule = match kind {
            0 => Schedule::Conventional,
            1 => Schedule::Fuzzy(f),
            2 => Schedule::Lookup(f),
            _ => Schedule::Fuzzy(FuzzyConfig { and: AndOperator::Min, ..f }),
        };
        let cfg = Config::with_schedule(schedule);
        let mut c = cfg.build_any().unwrap();
        c.start();
        for (sp, y, ff, action) in steps {
            match action {
                0 => c.stop(),
                1 => c.start(),
                2 => c.set_manual(ff),
                3 => c.set_auto(),
                4 => c.reset(),
                _ => {}
            }
            let u = c.step(sp, y, ff);
            prop_assert!(u >= cfg.output_min && u <= cfg.output_max);
            prop_assert!(c.integral().abs() <= cfg.output_max - cfg.output_min);
            let g = c.status().gains;
            prop_assert!(g.kp >= 0 && g.ki >= 0 && g.kd >= 0);
        }
    }
}
