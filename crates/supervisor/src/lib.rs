//! The transplanter's supervisor, free of hardware so that it is tested on the
//! host: persisted settings ([`settings`], [`store`]), and the operating logic
//! — modes, faults and the 10 ms control step ([`control`]).
#![no_std]
#![cfg_attr(not(test), forbid(unsafe_code))]

#[cfg(test)]
extern crate std;

pub mod control;
pub mod crc;
pub mod drive;
pub mod drive_link;
pub mod machine;
pub mod phase;
pub mod planting;
pub mod profile_b;
pub mod quality;
pub mod settings;
pub mod stop_input;
pub mod store;
pub mod work_switch;
