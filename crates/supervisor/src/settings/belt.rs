//! Profile B's parameters as the screen shows and sets them.

use fixed::types::U16F16;
use hmi_proto::screen::{self, Command};
use kinematics::profile_b::ProfileBSettings;
use kinematics::units::{Metres, MetresPerSecond};

use crate::planter::{Error as BeltError, ProfileBConfig};

/// Profile B's parameters as the screen shows them (its scaled integers).
pub fn belt_to_screen(c: &ProfileBConfig) -> screen::BeltSettings {
    let s = c.settings();
    let int = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
    // Metres → mm, 0.1 mm, 0.01 mm; m/s → mm/s (rounded to the nearest).
    // U12F20 / U8F24 bits × units per metre, rounded to the nearest.
    let round_shift = |x: u64, frac: u32| {
        let half = 1u64.checked_shl(frac.saturating_sub(1)).unwrap_or(0);
        int(
            u32::try_from(x.saturating_add(half).checked_shr(frac).unwrap_or(0))
                .unwrap_or(u32::MAX),
        )
    };
    let scaled = |m: Metres, per_m: u32| {
        round_shift(u64::from(m.to_bits()).saturating_mul(u64::from(per_m)), 20)
    };
    let mm_s = |v: MetresPerSecond| round_shift(u64::from(v.to_bits()).saturating_mul(1000), 24);
    screen::BeltSettings {
        spacing: screen::BeltSpacing::new(scaled(s.plant_spacing, 1000)).unwrap_or_default(),
        seedling_pitch: screen::SeedlingPitch::new(scaled(s.belt_pitch, 1000)).unwrap_or_default(),
        // Whole degrees: the integer bits (`to_num::<u32>()` rounds down
        // the same way, through `fixed`'s generic conversion).
        clamp_angle: screen::ClampAngle::new(int(s.clamping_angle_deg.to_bits() >> 16))
            .unwrap_or_default(),
        clamp_count: screen::ClampCount::new(i32::from(s.seedlings_clamped)).unwrap_or_default(),
        roller_radius: screen::RollerRadius::new(scaled(s.roller_radius, 10_000))
            .unwrap_or_default(),
        belt_thickness: screen::BeltThickness::new(scaled(s.belt_thickness, 100_000))
            .unwrap_or_default(),
        speed_threshold: screen::SpeedThreshold::new(mm_s(s.threshold)).unwrap_or_default(),
    }
}

/// Applies one profile B parameter from the screen to `c`; the result is
/// validated as a whole (the screen checked each value's own range).
pub fn belt_with(c: &ProfileBConfig, cmd: Command) -> Option<Result<ProfileBConfig, BeltError>> {
    let mut s: ProfileBSettings = *c.settings();
    // `num / den` metres, rounded to the nearest bit like the limits
    // `ProfileBConfig::new` checks (`Metres::lit`): `from_ratio` rounds
    // down, and 0.1 m (X = 10.0 cm, the screen's minimum) fell half a bit
    // below the check's 0.10.
    let metres = |num: u16, den: u32| {
        Some(Metres::from_bits(nearest_bits(
            u32::from(num),
            den,
            fixed::types::U12F20::FRAC_NBITS,
        )?))
    };
    match cmd {
        Command::SetBeltSpacing(v) => s.plant_spacing = metres(v.raw(), 1000)?,
        Command::SetSeedlingPitch(v) => s.belt_pitch = metres(v.raw(), 1000)?,
        Command::SetClampAngle(v) => s.clamping_angle_deg = U16F16::from_num(v.raw()),
        Command::SetClampCount(v) => s.seedlings_clamped = v.raw(),
        Command::SetRollerRadius(v) => s.roller_radius = metres(v.raw(), 10_000)?,
        Command::SetBeltThickness(v) => s.belt_thickness = metres(v.raw(), 100_000)?,
        Command::SetSpeedThreshold(v) => {
            s.threshold = MetresPerSecond::from_bits(nearest_bits(
                u32::from(v.raw()),
                1000,
                fixed::types::U8F24::FRAC_NBITS,
            )?);
        }
        _ => return None,
    }
    Some(ProfileBConfig::new(s))
}

/// The bits of `num / den` in a fixed-point type with `frac` fractional
/// bits, rounded to the nearest; `None` if `den` is 0 or it does not fit.
fn nearest_bits(num: u32, den: u32, frac: u32) -> Option<u32> {
    let scaled = u64::from(num).checked_shl(frac)?;
    let bits = scaled
        .checked_add(u64::from(den / 2))?
        .checked_div(u64::from(den))?;
    u32::try_from(bits).ok()
}

/// A short text for the screen.
pub fn belt_error_text(e: BeltError) -> &'static str {
    match e {
        BeltError::Range(field) => field.text(),
        _ => "Parameters rejected",
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_screens_belt_defaults_are_the_kinematics_defaults() {
        // hmi-proto writes profile B's defaults as scaled integers (it does
        // not depend on kinematics); they must be ProfileBSettings::default().
        assert_eq!(
            belt_to_screen(&ProfileBConfig::default()),
            screen::BeltSettings::default()
        );
    }

    #[test]
    fn each_screen_parameter_lands_in_its_field_and_reads_back() {
        let c = ProfileBConfig::default();
        let set = |cmd| belt_with(&c, cmd).unwrap().unwrap();
        // r = 30.0 mm entered as 300 (0.1 mm).
        let r = set(Command::SetRollerRadius(
            screen::RollerRadius::new(300).unwrap(),
        ));
        assert_eq!(belt_to_screen(&r).roller_radius.raw(), 300);
        assert!((r.settings().roller_radius.to_f64() - 0.030).abs() < 1e-6);
        // h = 2.50 mm entered as 250 (0.01 mm).
        let h = set(Command::SetBeltThickness(
            screen::BeltThickness::new(250).unwrap(),
        ));
        assert_eq!(belt_to_screen(&h).belt_thickness.raw(), 250);
        // Y = 35 mm/s.
        let y = set(Command::SetSpeedThreshold(
            screen::SpeedThreshold::new(35).unwrap(),
        ));
        assert_eq!(belt_to_screen(&y).speed_threshold.raw(), 35);
        // X = 40 cm, B = 12 cm, β = 90°, N = 3.
        let x = set(Command::SetBeltSpacing(
            screen::BeltSpacing::new(400).unwrap(),
        ));
        assert_eq!(belt_to_screen(&x).spacing.raw(), 400);
        let b = set(Command::SetSeedlingPitch(
            screen::SeedlingPitch::new(120).unwrap(),
        ));
        assert_eq!(belt_to_screen(&b).seedling_pitch.raw(), 120);
        let a = set(Command::SetClampAngle(screen::ClampAngle::new(90).unwrap()));
        assert_eq!(belt_to_screen(&a).clamp_angle.raw(), 90);
        let n = set(Command::SetClampCount(screen::ClampCount::new(3).unwrap()));
        assert_eq!(belt_to_screen(&n).clamp_count.raw(), 3);
        // Not a profile B parameter.
        assert!(belt_with(&c, Command::Start).is_none());
    }
}
