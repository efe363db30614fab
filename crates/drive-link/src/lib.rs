//! The drum driver's RS-485 link (paper A §2.2.3, §2.4.3): a Modbus RTU
//! master that reads the driver's speed and faults and writes its commands.
//!
//! - [`rtu`]: frames (modbus-core PDUs, CRC-16/MODBUS from the `crc` crate);
//! - [`timing`]: character time and the 3.5-character silent interval;
//! - [`profile`]: driver profiles as data (the ZLAC8015D, and generic
//!   settings validated by `build()`);
//! - [`link`]: the sans-IO master: schedule, timeouts, retries, link loss;
//! - [`cross_check`]: encoder against read-back.
//!
//! `no_std`, no heap, no panics on any input.
#![no_std]

#[cfg(any(test, feature = "std"))]
extern crate std;

pub mod cross_check;
pub mod link;
pub mod profile;
pub mod rtu;
pub mod timing;
#[cfg(feature = "std")]
pub mod virtual_driver;
