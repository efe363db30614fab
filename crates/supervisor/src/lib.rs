//! The transplanter's supervisor, free of hardware so that it is tested on the
//! host: persisted settings ([`settings`], [`settings::store`]), and the operating logic
//! — the drum machine ([`drum`], profile A), the belt machine ([`belt`],
//! profile B) and the one the firmware runs ([`machine`]).
#![no_std]
#![cfg_attr(not(test), forbid(unsafe_code))]

#[cfg(test)]
extern crate std;

pub mod belt;
pub mod drive;
pub mod drive_link;
pub mod drum;
pub mod effect;
pub mod ground;
pub mod machine;
pub mod machine_step;
pub mod migrate;
pub mod phase;
pub mod planter;
pub mod quality;
pub mod settings;
pub mod stop_input;
pub mod work_switch;
