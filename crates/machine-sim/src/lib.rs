//! Deterministic model of the transplanter for host simulations and the
//! QEMU board: drum motor and driver, partitioned belt, tracked chassis with
//! slip and terrain, Hall gear, encoders, profile-B steppers, fault
//! injection and streaming field metrics (ISO 7256-1, paper A's spacing
//! qualification rate). See `docs/machine-sim.md` for the model.
//!
//! `no_std`, no heap, f32/f64 soft-float (it never runs on the real board);
//! the `std` feature adds `Recorder`, a plant-position list for reports.
//!
//! # Example: feed-forward drum duty in a 1 ms loop
//!
//! Low 1 at 7 cm spacing: the feed-forward of SPEC eq. 7–8 from the Hall
//! period, applied open loop; after 30 s the field metrics are close to the
//! target.
//!
//! ```
//! use kinematics::consts::Gear;
//! use machine_sim::{Config, Inputs};
//!
//! let mut m = Config { initial_gear: Some(Gear::Low1), ..Config::default() }.build()?;
//! let (mut last_edge, mut period_us) = (None::<u32>, 0u32);
//! let mut inputs = Inputs { driver_enabled: true, ..Inputs::default() };
//! for ms in 0..30_000 {
//!     if ms == 2_000 {
//!         m.reset_metrics(); // ignore the start-up
//!     }
//!     m.step(1000, &inputs, &mut |t| {
//!         if let Some(prev) = last_edge {
//!             period_us = t.wrapping_sub(prev);
//!         }
//!         last_edge = Some(t);
//!     });
//!     if period_us > 0 {
//!         // Gear speed n_teeth = 60 / (25 · T) r/min; eq. 7 with k2/k3 = 0.972/0.99:
//!         let n_teeth = 60.0e6 / (25.0 * period_us as f32);
//!         let n_roll = 0.972 / 0.99 * (0.20 / 0.07) * (0.05 / 0.07) * n_teeth;
//!         inputs.drum_duty = n_roll / 44.7; // eq. 8
//!     }
//! }
//! let fm = m.metrics();
//! // 28 s · 0.0917 m/s · (1 − 2.8 % slip) = 2.49 m of ground → 35.6 plants at 7 cm.
//! assert!(fm.plants > 30, "{} plants", fm.plants);
//! assert!((fm.mean_spacing_m - 0.07).abs() < 0.005, "mean {}", fm.mean_spacing_m);
//! assert!(fm.count_error_pct.abs() < 5.0);
//! # Ok::<(), machine_sim::Error>(())
//! ```
#![no_std]
// This crate is a simulator, not on the MCU control path (SPEC: the control
// path is fixed point). Float ↔ integer conversions and plain float
// arithmetic are its whole purpose, so the workspace's control-path lints on
// arithmetic and casts are relaxed here; indexing and unwrap stay forbidden.
#![allow(
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss,
    clippy::cast_possible_wrap
)]

#[cfg(any(test, feature = "std"))]
extern crate std;

mod config;
mod machine;
mod metrics;
#[cfg(feature = "std")]
mod recorder;
#[cfg(feature = "std")]
pub mod reference;
mod rng;
pub mod tables;

pub use config::{Config, Error, Profile, MAX_TRANSPORT_DELAY_MS};
pub use machine::{Event, Fault, Inputs, Machine, HALL_TOOTH_SHARE};
pub use metrics::{FieldMetrics, MetricsError, SpacingAccumulator};
#[cfg(feature = "std")]
pub use recorder::Recorder;

#[cfg(test)]
mod tests;
