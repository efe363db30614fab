//! `cargo xtask plan --spacing 7cm --speed 0.51km/h [--gear low2] [--arr N]`:
//! a planning calculator for operators. Every number is computed by the
//! `kinematics` crate; this file only parses and prints (f64 for that only).
//!
//! `--speed` is the travel speed the Hall sensor monitors (before k1/k2); if
//! omitted, the gear's monitored speed (paper A Table 11) is used. With
//! `--gear`, that gear's k1 and k2 are used as constants; without it, the
//! k1/k2 tables are interpolated over speed. `--arr` is ARR2 of the drum PWM
//! timer (default 3599: 20 kHz at 72 MHz).
//!
//! Input rules (each refusal names the option and the value given):
//! - units are case-insensitive, for every option alike (`7cm`, `7CM`,
//!   `0.51km/h`, `0.51KM/H`): nothing here can be mistaken for another unit
//!   (no mega-metres on a transplanter), so the friendlier rule costs nothing;
//! - `--speed` must be above 0 and at most what the Hall switch can count
//!   (1 kHz × 25.13 mm = 90.48 km/h), the largest speed the calculator's
//!   fixed-point chain represents without saturating;
//! - `--arr` must be 1 … 65535: at ARR 0 the timer does not count (RM0008
//!   §15.3.1: "the counter is blocked while the auto-reload value is null"),
//!   so there is no PWM; the duty line shows the applied duty
//!   `CCR/(ARR+1)` next to eq. 8's when the timer's resolution moves it;
//! - an option given twice is refused (it used to win silently).

use kinematics::consts::{self, Gear};
use kinematics::drum::{DrumSettings, DrumTarget};
use kinematics::travel::{gear_speed_for, travel_speed, Calibration};
use kinematics::units::{KilometresPerHour, Metres, MetresPerSecond};

const USAGE: &str = "usage: cargo xtask plan --spacing <7cm|70mm|0.07m> [--speed <0.51km/h|0.14m/s>] [--gear low1..high3] [--arr 1..65535]  (units in any case)";
const DEFAULT_ARR: u16 = 3599;

/// The fastest travel the Hall switch can count: its 1 kHz limit times one
/// gear gap (25.133 mm of track), m/s.
fn max_speed_m_s() -> f64 {
    f64::from(consts::HALL_MAX_HZ) * consts::ROLLING_CIRCUMFERENCE_M_F64 / f64::from(consts::Z1)
}

fn parse_length(s: &str) -> Result<Metres, String> {
    let lower = s.trim().to_ascii_lowercase();
    let (num, scale) = if let Some(v) = lower.strip_suffix("mm") {
        (v, 0.001)
    } else if let Some(v) = lower.strip_suffix("cm") {
        (v, 0.01)
    } else if let Some(v) = lower.strip_suffix('m') {
        (v, 1.0)
    } else {
        return Err(format!("--spacing '{s}' needs a unit: mm, cm or m"));
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("--spacing '{s}' is not a number with a unit"))?;
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("--spacing '{s}' must be above 0"));
    }
    Metres::from_f64(v * scale).ok_or_else(|| format!("--spacing '{s}' out of range"))
}

fn parse_speed(s: &str) -> Result<MetresPerSecond, String> {
    let lower = s.trim().to_ascii_lowercase();
    let (num, to_m_s) = if let Some(v) = lower
        .strip_suffix("km/h")
        .or_else(|| lower.strip_suffix("kmh"))
    {
        (v, 1.0 / 3.6)
    } else if let Some(v) = lower.strip_suffix("m/s") {
        (v, 1.0)
    } else {
        return Err(format!("--speed '{s}' needs a unit: km/h or m/s"));
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("--speed '{s}' is not a number with a unit"))?;
    let max = max_speed_m_s();
    if !(v.is_finite() && v > 0.0 && v * to_m_s <= max) {
        return Err(format!(
            "--speed '{s}' out of range: above 0 and at most {:.2} km/h ({max:.2} m/s), \
             the fastest the Hall switch can count (1 kHz x 25.13 mm)",
            max * 3.6
        ));
    }
    if to_m_s == 1.0 {
        MetresPerSecond::from_f64(v)
    } else {
        KilometresPerHour::from_f64(v).and_then(|k| k.to_mps().ok())
    }
    .ok_or_else(|| format!("--speed '{s}' out of range"))
}

fn parse_arr(s: &str) -> Result<u16, String> {
    match s.trim().parse::<u16>() {
        Ok(0) => Err(format!(
            "--arr '{s}': ARR must be 1..65535 (at ARR 0 the timer does not count: no PWM, RM0008 15.3.1)"
        )),
        Ok(v) => Ok(v),
        Err(_) => Err(format!("--arr '{s}': ARR must be a whole number 1..65535")),
    }
}

struct Args {
    spacing: Metres,
    /// `--spacing` as given, for messages.
    spacing_raw: String,
    /// `--speed` as given, for messages.
    speed_raw: Option<String>,
    speed: Option<MetresPerSecond>,
    gear: Option<Gear>,
    arr: u16,
}

/// Stores an option's value, refusing a second one.
fn once<T>(slot: &mut Option<(T, String)>, name: &str, raw: &str, value: T) -> Result<(), String> {
    if let Some((_, first)) = slot {
        return Err(format!(
            "{name} given twice ('{first}' and '{raw}'): give it once\n{USAGE}"
        ));
    }
    *slot = Some((value, raw.to_string()));
    Ok(())
}

fn parse_args(args: &[String]) -> Result<Args, String> {
    let mut spacing = None;
    let mut speed = None;
    let mut gear = None;
    let mut arr = None;
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let (name, inline) = match flag.split_once('=') {
            Some((n, v)) => (n, Some(v.to_string())),
            None => (flag.as_str(), None),
        };
        if name == "-h" || name == "--help" {
            return Err(USAGE.to_string());
        }
        let value = match inline {
            Some(v) => v,
            None => it
                .next()
                .cloned()
                .ok_or_else(|| format!("{name} needs a value\n{USAGE}"))?,
        };
        match name {
            "--spacing" => once(&mut spacing, name, &value, parse_length(&value)?)?,
            "--speed" => once(&mut speed, name, &value, parse_speed(&value)?)?,
            "--gear" => {
                let g = Gear::parse(&value)
                    .ok_or_else(|| format!("--gear '{value}' unknown (low1..high3)"))?;
                once(&mut gear, name, &value, g)?;
            }
            "--arr" => once(&mut arr, name, &value, parse_arr(&value)?)?,
            other => return Err(format!("unknown option '{other}'\n{USAGE}")),
        }
    }
    let spacing = spacing.ok_or_else(|| format!("--spacing is required\n{USAGE}"))?;
    Ok(Args {
        spacing: spacing.0,
        spacing_raw: spacing.1,
        speed_raw: speed.as_ref().map(|(_, raw)| raw.clone()),
        speed: speed.map(|(v, _)| v),
        gear: gear.map(|(g, _)| g),
        arr: arr.map_or(DEFAULT_ARR, |(a, _)| a),
    })
}

/// The duty line: eq. 8's duty, and the duty the timer applies
/// (`CCR/(ARR+1)`) when the timer's steps make it show differently.
fn duty_line(duty: f64, ccr: u16, arr: u16) -> String {
    let period = f64::from(u32::from(arr) + 1);
    let wanted = format!("{:.2}", duty * 100.0);
    let applied = format!("{:.2}", f64::from(ccr) / period * 100.0);
    if wanted == applied {
        format!("duty                     {wanted} %")
    } else {
        format!(
            "duty                     {wanted} % (eq. 8), applied {applied} % (CCR/(ARR+1), steps of {:.3} %)",
            100.0 / period
        )
    }
}

/// Runs the calculator with the arguments after `plan`.
pub fn run(args: &[String]) -> Result<(), String> {
    let a = parse_args(args)?;
    // Past the parsers every input is in range; should a computation still
    // fail, the message names what it was given.
    let inputs = match (&a.speed_raw, a.gear) {
        (Some(v), _) => format!("--spacing {} --speed {v}", a.spacing_raw),
        (None, Some(g)) => format!("--spacing {} at {g}'s speed", a.spacing_raw),
        (None, None) => format!("--spacing {}", a.spacing_raw),
    };
    let e = |err: kinematics::Error| format!("cannot plan {inputs}: {err}");
    let speed = match (a.speed, a.gear) {
        (Some(v), _) => v,
        (None, Some(g)) => g.preset().monitored.to_mps().map_err(e)?,
        (None, None) => return Err(format!("give --speed or --gear\n{USAGE}")),
    };
    let cal = match a.gear {
        Some(g) => Calibration::for_gear(g),
        None => Calibration::paper_defaults(),
    };
    let plan = DrumSettings::new(a.spacing, a.arr)
        .build()
        .map_err(|err| format!("--spacing '{}' / --arr {}: {err}", a.spacing_raw, a.arr))?;
    let raw = gear_speed_for(speed).map_err(e)?;
    let t = travel_speed(raw, &cal).map_err(e)?;
    let v1_kmh = t.travel_speed_kmh().map_err(e)?;
    let vmax = plan.max_travel_speed(&cal).map_err(e)?;
    // Far beyond n_max the drum speed eq. 7 asks for leaves r/min's range
    // (4096): say so in the machine's terms, not the arithmetic's.
    let target = plan.target(&t, &cal).map_err(|err| match err {
        kinematics::Error::Overflow => format!(
            "cannot plan {inputs}: the drum would have to turn faster than 4096 r/min \
             (n_max {:.1}); {} allows at most {:.2} km/h",
            consts::N_MAX_F64,
            a.spacing_raw,
            vmax.to_f64()
        ),
        other => e(other),
    })?;
    let per_min = plan.plants_per_minute(t.travel_speed).map_err(e)?;

    let gear_txt = a.gear.map_or_else(
        || "interpolated tables".to_string(),
        |g| format!("{g} preset"),
    );
    println!(
        "plant spacing            {:.1} cm",
        a.spacing.to_f64() * 100.0
    );
    println!(
        "monitored travel speed   {:.3} km/h  ({gear_txt})",
        t.monitored.to_f64()
    );
    println!(
        "Hall gear speed          {:.3} r/min raw, n_teeth = {:.3} r/min (k1 = {:.4})",
        t.raw_gear_speed.to_f64(),
        t.gear_speed.to_f64(),
        t.k1.to_f64()
    );
    println!(
        "corrected travel speed   {:.3} km/h = {:.4} m/s (k2 = {:.4})",
        v1_kmh.to_f64(),
        t.travel_speed.to_f64(),
        t.k2.to_f64()
    );
    let c = target.command();
    match target {
        DrumTarget::Follow(_) => {
            println!(
                "target drum speed        {:.3} r/min (k3 = {:.4})",
                c.drum_speed.to_f64(),
                c.k3.to_f64()
            );
        }
        DrumTarget::Saturated { requested, .. } => {
            println!(
                "target drum speed        {:.3} r/min needed > n_max {:.1} r/min: SATURATED, drum capped",
                requested.to_f64(),
                consts::N_MAX_F64
            );
        }
    }
    let period = u32::from(a.arr) + 1;
    println!("{}", duty_line(c.duty.to_f64(), c.ccr, a.arr));
    println!("CCR                      {} of ARR+1 = {period}", c.ccr);
    println!(
        "max travel speed         {:.3} km/h at this spacing",
        vmax.to_f64()
    );
    println!("plants per minute (row)  {:.1}", per_min.to_f64());
    if target.is_saturated() {
        println!(
            "WARNING: travel speed too high for {:.1} cm spacing; slow down to at most {:.2} km/h",
            a.spacing.to_f64() * 100.0,
            vmax.to_f64()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| (*x).to_string()).collect()
    }

    #[test]
    fn parses_units() {
        assert!((parse_length("7cm").unwrap().to_f64() - 0.07).abs() < 1e-6);
        assert!((parse_length("180mm").unwrap().to_f64() - 0.18).abs() < 1e-6);
        assert!((parse_speed("0.51km/h").unwrap().to_f64() - 0.141_667).abs() < 1e-5);
        assert!((parse_speed("0.2m/s").unwrap().to_f64() - 0.2).abs() < 1e-6);
        assert!(parse_length("7").is_err());
        assert!(parse_speed("fast").is_err());
    }

    /// Units are case-insensitive for every option alike (`7CM` as well as
    /// `0.51KM/H`).
    #[test]
    fn units_are_case_insensitive_for_every_option() {
        for (upper, lower) in [
            ("7CM", "7cm"),
            ("70MM", "70mm"),
            ("0.07M", "0.07m"),
            ("7Cm", "7cm"),
        ] {
            assert_eq!(parse_length(upper), parse_length(lower), "{upper}");
        }
        for (upper, lower) in [
            ("0.51KM/H", "0.51km/h"),
            ("0.51KMH", "0.51kmh"),
            ("0.14M/S", "0.14m/s"),
        ] {
            assert_eq!(parse_speed(upper), parse_speed(lower), "{upper}");
        }
        run(&s(&["--spacing", "7CM", "--speed", "0.51KM/H"])).unwrap();
    }

    /// `--arr 0` was accepted and printed "duty 62.11 %" next to "CCR 1 of
    /// ARR+1 = 1" (100 %). ARR 0 stops TIM1 (RM0008 §15.3.1), so it is
    /// refused, naming the input.
    #[test]
    fn arr_0_is_refused_naming_the_input() {
        let err = parse_args(&s(&["--spacing", "7cm", "--arr", "0"]))
            .err()
            .unwrap();
        assert!(
            err.contains("--arr '0'") && err.contains("1..65535"),
            "{err}"
        );
        let err = parse_args(&s(&["--spacing", "7cm", "--arr=70000"]))
            .err()
            .unwrap();
        assert!(err.contains("--arr '70000'"), "{err}");
        assert!(run(&s(&["--spacing", "7cm", "--gear", "low2", "--arr", "0"])).is_err());
        assert_eq!(
            parse_args(&s(&["--spacing", "7cm", "--arr", "1"]))
                .unwrap()
                .arr,
            1
        );
    }

    /// The duty shown is the one applied once the timer's steps move it.
    /// By hand: eq. 8 asks 62.11 %; with ARR 1 the compare value rounds to
    /// 1 of 2 (50 %); with ARR 3599 to 2236 of 3600 = 62.11 %.
    #[test]
    fn the_duty_line_shows_the_applied_duty_when_the_steps_move_it() {
        assert_eq!(
            duty_line(0.6211, 1, 1),
            "duty                     62.11 % (eq. 8), applied 50.00 % (CCR/(ARR+1), steps of 50.000 %)"
        );
        assert_eq!(
            duty_line(0.6211, 2236, 3599),
            "duty                     62.11 %"
        );
    }

    /// `--speed 1000km/h` said "value out of fixed-point range" without
    /// naming the input. The limit is what the Hall switch can count:
    /// 1 kHz × π·0.20 m / 25 = 25.13 m/s = 90.48 km/h (hand-computed);
    /// everything up to it runs through the whole chain.
    #[test]
    fn an_impossible_speed_is_refused_naming_the_input_and_the_limit() {
        for bad in [
            "1000km/h", "90.5km/h", "25.2m/s", "0km/h", "-1km/h", "NaNkm/h",
        ] {
            let err = parse_args(&s(&["--spacing", "7cm", "--speed", bad]))
                .err()
                .unwrap();
            assert!(err.contains(&format!("--speed '{bad}'")), "{bad}: {err}");
            assert!(err.contains("90.48 km/h"), "{bad}: {err}");
        }
        for good in ["90.4km/h", "25.1m/s", "0.001km/h"] {
            run(&s(&["--spacing", "50cm", "--speed", good])).unwrap();
        }
        // At 3 cm eq. 7 asks 2400 r/min of gear × 2.857 × 5/3 ≈ 11 000 r/min
        // of drum at 90 km/h: refused in the machine's terms, naming the
        // inputs and the spacing's limit (0.35 km/h at 3 cm: 0.81 · 3/7).
        let err = run(&s(&["--spacing", "3cm", "--speed", "90km/h"]))
            .err()
            .unwrap();
        assert!(
            err.contains("--spacing 3cm")
                && err.contains("faster than 4096 r/min")
                && err.contains("at most 0.3"),
            "{err}"
        );
        run(&s(&[
            "--spacing",
            "3cm",
            "--speed",
            "20km/h",
            "--arr",
            "65535",
        ]))
        .unwrap();
    }

    /// A repeated option used to win silently; now it is refused, naming
    /// both values.
    #[test]
    fn a_repeated_option_is_refused() {
        for (args, want) in [
            (
                &["--spacing", "7cm", "--spacing", "18cm"][..],
                "--spacing given twice ('7cm' and '18cm')",
            ),
            (
                &["--spacing=7cm", "--speed", "1km/h", "--speed=2km/h"][..],
                "--speed given twice ('1km/h' and '2km/h')",
            ),
            (
                &["--spacing", "7cm", "--gear", "low1", "--gear", "LOW1"][..],
                "--gear given twice ('low1' and 'LOW1')",
            ),
            (
                &["--spacing", "7cm", "--arr", "999", "--arr", "999"][..],
                "--arr given twice ('999' and '999')",
            ),
        ] {
            let err = parse_args(&s(args)).err().unwrap();
            assert!(err.contains(want), "{args:?}: {err}");
        }
    }

    #[test]
    fn runs_the_issue_example() {
        run(&s(&[
            "--spacing",
            "7cm",
            "--speed",
            "0.51km/h",
            "--gear",
            "low2",
            "--arr",
            "999",
        ]))
        .unwrap();
        run(&s(&["--spacing=18cm", "--gear=high2"])).unwrap();
        assert!(run(&s(&["--speed", "1km/h"])).is_err());
        assert!(run(&s(&["--spacing", "7cm", "--bogus", "1"])).is_err());
    }
}
