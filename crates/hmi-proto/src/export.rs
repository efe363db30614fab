//! The screen contract as JSON, for screens built outside the firmware
//! (feature `std`): the browser screen (`web/`, docs/screen-web.md) is
//! generated from it, so that a page or component added to
//! [`COMPONENTS`] appears on the page.
//!
//! Everything a screen must know comes from the contract itself: page ids
//! and names, component ids, names, kinds and decimals, which events send
//! the component's id (press and release for Stop and the motor-starting
//! buttons, release only for the other buttons: docs/hmi.md §3), the
//! accepted range of every input and, for a person reading the page, a
//! label and a unit for every value. The labels are exhaustive matches: a
//! new field, status value or page is a build error here until it has one.
//! Button captions are the designer's texts of docs/hmi.md §6.
//!
//! ```
//! let json = hmi_proto::export::contract_json();
//! assert!(json.contains(r#""name":"bstart""#));
//! ```

use std::fmt::Write as _;
use std::string::String;

use crate::screen::{
    Action, Component, Field, Kind, MachineProfile, Page, Role, StatusField, StatusText, COMPONENTS,
};

/// The page's title for a person.
pub const fn page_title(page: Page) -> &'static str {
    match page {
        Page::Boot => "Connecting",
        Page::Mode => "Mode",
        Page::Fixed => "Fixed mode",
        Page::Adaptive => "Speed-Adaptive",
        Page::Calibration => "Calibration",
        Page::Alarm => "Alarm",
        Page::Settings => "Settings",
        Page::Belt => "Belt planter",
        Page::BeltParameters => "Belt parameters",
        Page::Drive => "Drum drive",
        Page::Link => "Driver link",
    }
}

/// Label and unit of an input field (the unit as the screen shows it, after
/// the Xfloat's decimals).
pub const fn field_label(field: Field) -> (&'static str, &'static str) {
    match field {
        Field::MotorCoefficient => ("Motor coefficient", ""),
        Field::FixedDrumSpeed => ("Drum speed", "r/min"),
        Field::Spacing => ("Plant spacing", "cm"),
        Field::CalibrationDistance => ("Tape distance", "m"),
        Field::CalibrationCoefficient => ("Coefficient by hand", ""),
        Field::Brightness => ("Brightness", "%"),
        Field::BeltSpacing => ("Plant spacing X", "cm"),
        Field::SeedlingPitch => ("Belt pitch B", "cm"),
        Field::ClampAngle => ("Clamp angle β", "°"),
        Field::ClampCount => ("Seedlings clamped N", ""),
        Field::RollerRadius => ("Roller radius r", "mm"),
        Field::BeltThickness => ("Belt thickness h", "mm"),
        Field::SpeedThreshold => ("Speed threshold Y", "m/s"),
        Field::FirstPlantDistance => ("First plant after lowering", "cm"),
        Field::LinkValue => ("Value", ""),
    }
}

/// Label and unit of a live value.
pub const fn status_label(field: StatusField) -> (&'static str, &'static str) {
    match field {
        StatusField::TravelSpeed => ("Travel speed", "km/h"),
        StatusField::TargetDrumSpeed => ("Drum target", "r/min"),
        StatusField::ActualDrumSpeed => ("Drum speed", "r/min"),
        StatusField::Plants => ("Plants", ""),
        StatusField::Distance => ("Distance", "m"),
        StatusField::MeasuredDistance => ("Measured distance", "m"),
        StatusField::CalibrationResult => ("Computed coefficient", ""),
        StatusField::TravelSpeedMps => ("Travel speed", "m/s"),
        StatusField::PlantMotorSpeed => ("Planting motor n1", "r/min"),
        StatusField::FeedMotorSpeed => ("Feeding motor n2", "r/min"),
        StatusField::RollerTurns => ("Roller turns j", ""),
        StatusField::RollerRadius => ("Roller radius r'", "mm"),
        StatusField::DriveNMax => ("Drive n max", "r/min"),
        StatusField::DriveTau => ("Time constant τ", "ms"),
        StatusField::DriveDeadTime => ("Dead time", "ms"),
        StatusField::DriveIdentification => ("Identification (0 idle 1 run 2 done 3 failed)", ""),
        StatusField::QualityOfFeed => ("Quality of feed", "%"),
        StatusField::Multiples => ("Multiples", "%"),
        StatusField::Misses => ("Misses", "%"),
        StatusField::PrecisionCv => ("Precision CV", "%"),
        StatusField::Within10Pct => ("Within ±10 %", "%"),
        StatusField::PlantsPerMetre => ("Plants per metre", "/m"),
    }
}

/// Label of a text component the MCU writes (`None`: the page's message
/// box, whose text speaks for itself).
pub const fn text_label(role: Role) -> Option<&'static str> {
    match role {
        Role::GearLabel => Some("Gear"),
        Role::CalibrationLabel => Some("Coefficient measured"),
        Role::ProfileLabel => Some("Machine"),
        Role::Version => Some("Firmware"),
        Role::EncoderDirectionLabel => Some("Drum encoder"),
        Role::WorkSwitchLabel => Some("Work switch"),
        Role::PlacementLabel => Some("Placement"),
        Role::LinkParameterLabel => Some("Setting"),
        Role::TravelSourceLabel => Some("Travel source"),
        Role::GroundWheelDirectionLabel => Some("Ground wheel encoder"),
        Role::StatusText(StatusText::TrackSlip) => Some("Track slip"),
        Role::StatusText(StatusText::TravelSourceInUse) => Some("Ground measured by"),
        Role::AlarmText => Some("Alarm"),
        Role::Message | Role::Action(_) | Role::Input(_) | Role::Status(_) => None,
    }
}

/// The screen file sends the component's id when it is pressed (Stop and
/// the motor-starting buttons: docs/hmi.md §3).
pub fn sends_press(c: &Component) -> bool {
    matches!(c.role, Role::Action(a) if a == Action::Stop || a.starts_motor())
}

/// The screen file sends the component's id when it is released (every
/// button).
pub fn sends_release(c: &Component) -> bool {
    c.kind() == Kind::Button
}

/// Appends `s` as a JSON string.
fn string(out: &mut String, s: &str) {
    out.push('"');
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if u32::from(c) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

/// The role's kind and its detail (the action, field or status value), as
/// the page reads them.
fn role_json(out: &mut String, role: Role) {
    let (kind, detail) = match role {
        Role::Action(a) => ("action", std::format!("{a:?}")),
        Role::Input(f) => ("input", std::format!("{f:?}")),
        Role::Status(f) => ("status", std::format!("{f:?}")),
        Role::Message => ("message", String::new()),
        Role::AlarmText => ("alarm", String::new()),
        other => ("text", std::format!("{other:?}")),
    };
    out.push_str("\"role\":");
    string(out, kind);
    out.push_str(",\"detail\":");
    string(out, &detail);
}

/// The whole contract as one JSON object: `pages` (id, name, title, the
/// profile whose home it is), `profiles` (label, home page id) and
/// `components` (page, id, name, kind, decimals, role and detail, press
/// and release, motor start, label, unit, min and max of an input).
pub fn contract_json() -> String {
    let mut out = String::from("{\"pages\":[");
    for (i, p) in Page::ALL.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let _ = write!(out, "{{\"id\":{},\"name\":", p.id());
        string(&mut out, p.name());
        out.push_str(",\"title\":");
        string(&mut out, page_title(*p));
        out.push('}');
    }
    out.push_str("],\"profiles\":[");
    for (i, m) in MachineProfile::ALL.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str("{\"label\":");
        string(&mut out, m.label());
        let _ = write!(out, ",\"home\":{}}}", m.home().id());
    }
    out.push_str("],\"components\":[");
    for (i, c) in COMPONENTS.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let (kind, decimals) = match c.kind() {
            Kind::Button => ("button", 0),
            Kind::Text => ("text", 0),
            Kind::Number => ("number", 0),
            Kind::Xfloat(d) => ("xfloat", d),
        };
        let _ = write!(
            out,
            "{{\"page\":{},\"id\":{},\"name\":",
            c.page.id(),
            c.id()
        );
        string(&mut out, c.name());
        out.push_str(",\"kind\":");
        string(&mut out, kind);
        let _ = write!(out, ",\"decimals\":{decimals},");
        role_json(&mut out, c.role);
        let starts_motor = matches!(c.role, Role::Action(a) if a.starts_motor());
        let stop = matches!(c.role, Role::Action(Action::Stop));
        let _ = write!(
            out,
            ",\"press\":{},\"release\":{},\"starts_motor\":{starts_motor},\"stop\":{stop}",
            sends_press(c),
            sends_release(c)
        );
        let (label, unit, range) = match c.role {
            Role::Input(f) => {
                let (l, u) = field_label(f);
                (Some(l), u, Some(f.range()))
            }
            Role::Status(f) => {
                let (l, u) = status_label(f);
                (Some(l), u, None)
            }
            r => (text_label(r), "", None),
        };
        out.push_str(",\"label\":");
        match label {
            Some(l) => string(&mut out, l),
            None => out.push_str("null"),
        }
        out.push_str(",\"unit\":");
        string(&mut out, unit);
        match range {
            Some((min, max)) => {
                let _ = write!(out, ",\"min\":{min},\"max\":{max}");
            }
            None => out.push_str(",\"min\":null,\"max\":null"),
        }
        out.push('}');
    }
    out.push_str("]}");
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    /// Every component of the contract is in the export once, with its
    /// page, id and name, and the press/release rule of docs/hmi.md §3.
    #[test]
    fn every_component_is_exported_with_its_events() {
        let json = contract_json();
        for c in COMPONENTS {
            let head = std::format!(
                "{{\"page\":{},\"id\":{},\"name\":\"{}\"",
                c.page.id(),
                c.id(),
                c.name()
            );
            assert_eq!(json.matches(&head).count(), 1, "{head}");
            let at = json.find(&head).unwrap();
            let row = &json[at..at + json[at..].find('}').unwrap()];
            let press = matches!(
                c.role,
                Role::Action(Action::Stop | Action::Start | Action::IdentifyDrive)
            );
            assert!(row.contains(&std::format!("\"press\":{press}")), "{row}");
            assert!(
                row.contains(&std::format!("\"release\":{}", c.kind() == Kind::Button)),
                "{row}"
            );
        }
        for p in Page::ALL {
            assert!(json.contains(&std::format!(
                "{{\"id\":{},\"name\":\"{}\"",
                p.id(),
                p.name()
            )));
        }
    }

    #[test]
    fn inputs_carry_their_range() {
        let json = contract_json();
        let at = json.find("\"name\":\"nspacing\"").unwrap();
        let row = &json[at..at + json[at..].find('}').unwrap()];
        assert!(row.contains("\"min\":30,\"max\":500"), "{row}");
    }

    #[test]
    fn strings_are_escaped() {
        let mut s = String::new();
        string(&mut s, "a\"b\\c\nd");
        assert_eq!(s, "\"a\\\"b\\\\c\\u000ad\"");
    }
}
