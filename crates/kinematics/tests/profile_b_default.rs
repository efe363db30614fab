//! `ProfileB::default()` is what validating the default settings gives.

use kinematics::profile_b::{ProfileB, ProfileBSettings};

#[test]
fn the_default_plan_is_the_validated_default_settings() {
    assert_eq!(ProfileBSettings::default().build(), Ok(ProfileB::default()));
}
