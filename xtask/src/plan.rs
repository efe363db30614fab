//! `cargo xtask plan --spacing 7cm --speed 0.51km/h [--gear low2] [--arr N]`:
//! a planning calculator for operators. Every number is computed by the
//! `kinematics` crate; this file only parses and prints (f64 for that only).
//!
//! `--speed` is the travel speed the Hall sensor monitors (before k1/k2); if
//! omitted, the gear's monitored speed (paper A Table 11) is used. With
//! `--gear`, that gear's k1 and k2 are used as constants; without it, the
//! k1/k2 tables are interpolated over speed. `--arr` is ARR2 of the drum PWM
//! timer (default 3599: 20 kHz at 72 MHz).

use kinematics::consts::{self, Gear};
use kinematics::drum::{DrumSettings, DrumTarget};
use kinematics::travel::{gear_speed_for, travel_speed, Calibration};
use kinematics::units::{KilometresPerHour, Metres, MetresPerSecond};

const USAGE: &str = "usage: cargo xtask plan --spacing <7cm|70mm|0.07m> [--speed <0.51km/h|0.14m/s>] [--gear low1..high3] [--arr N]";
const DEFAULT_ARR: u16 = 3599;

fn parse_length(s: &str) -> Result<Metres, String> {
    let (num, scale) = if let Some(v) = s.strip_suffix("mm") {
        (v, 0.001)
    } else if let Some(v) = s.strip_suffix("cm") {
        (v, 0.01)
    } else if let Some(v) = s.strip_suffix('m') {
        (v, 1.0)
    } else {
        return Err(format!("spacing '{s}' needs a unit: mm, cm or m"));
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("bad spacing '{s}'"))?;
    Metres::from_f64(v * scale).ok_or_else(|| format!("spacing '{s}' out of range"))
}

fn parse_speed(s: &str) -> Result<MetresPerSecond, String> {
    let lower = s.to_ascii_lowercase();
    if let Some(v) = lower
        .strip_suffix("km/h")
        .or_else(|| lower.strip_suffix("kmh"))
    {
        let v: f64 = v.trim().parse().map_err(|_| format!("bad speed '{s}'"))?;
        let kmh =
            KilometresPerHour::from_f64(v).ok_or_else(|| format!("speed '{s}' out of range"))?;
        kmh.to_mps().map_err(|e| e.to_string())
    } else if let Some(v) = lower.strip_suffix("m/s") {
        let v: f64 = v.trim().parse().map_err(|_| format!("bad speed '{s}'"))?;
        MetresPerSecond::from_f64(v).ok_or_else(|| format!("speed '{s}' out of range"))
    } else {
        Err(format!("speed '{s}' needs a unit: km/h or m/s"))
    }
}

struct Args {
    spacing: Metres,
    speed: Option<MetresPerSecond>,
    gear: Option<Gear>,
    arr: u16,
}

fn parse_args(args: &[String]) -> Result<Args, String> {
    let mut spacing = None;
    let mut speed = None;
    let mut gear = None;
    let mut arr = DEFAULT_ARR;
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
            "--spacing" => spacing = Some(parse_length(&value)?),
            "--speed" => speed = Some(parse_speed(&value)?),
            "--gear" => {
                gear = Some(
                    Gear::parse(&value)
                        .ok_or_else(|| format!("unknown gear '{value}' (low1..high3)"))?,
                )
            }
            "--arr" => {
                arr = value
                    .parse()
                    .map_err(|_| format!("--arr must be 0..65535, got '{value}'"))?
            }
            other => return Err(format!("unknown option '{other}'\n{USAGE}")),
        }
    }
    Ok(Args {
        spacing: spacing.ok_or_else(|| format!("--spacing is required\n{USAGE}"))?,
        speed,
        gear,
        arr,
    })
}

/// Runs the calculator with the arguments after `plan`.
pub fn run(args: &[String]) -> Result<(), String> {
    let a = parse_args(args)?;
    let e = |err: kinematics::Error| err.to_string();
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
        .map_err(|err| err.to_string())?;
    let raw = gear_speed_for(speed).map_err(e)?;
    let t = travel_speed(raw, &cal).map_err(e)?;
    let v1_kmh = t.travel_speed_kmh().map_err(e)?;
    let target = plan.target(&t, &cal).map_err(e)?;
    let vmax = plan.max_travel_speed(&cal).map_err(e)?;
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
    println!("duty                     {:.2} %", c.duty.to_f64() * 100.0);
    println!(
        "CCR                      {} of ARR+1 = {}",
        c.ccr,
        u32::from(a.arr) + 1
    );
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
