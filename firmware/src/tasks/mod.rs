//! The RTIC tasks' bodies (declared in `main.rs`'s app), one module each.
//!
//! Task map (higher number = higher priority):
//!
//! | task | priority | release | budget |
//! |---|---|---|---|
//! | [`stop_input::stop_input`] | 5 | each edge of the stop input (PB10, EXTI10) | 1 µs |
//! | [`screen_bytes::usart1`] | 4 | each touchscreen byte in or out (≤ 11.5 kHz each way) | 2 µs |
//! | [`hall_capture::hall_capture`] | 3 | each Hall edge (≤ 1 kHz) and TIM2 overflow | 2 µs |
//! | [`drive_link::usart2`] | 3 | each RS-485 byte in or out (≤ 11.5 kHz), TC, while a driver profile is set | 2 µs |
//! | [`drive_link::drive_link`] | 3 | every 1 ms while a driver profile is set | 20 µs |
//! | [`control::control`] | 2 | every 10 ms | 1 ms |
//! | [`hmi::hmi`] | 1 | touchscreen bytes, the transmit ring at half, at least every 20 ms | 1 ms |
//! | [`status::status`] | 1 | every 200 ms (5 Hz) | 2 ms |
//! | [`settings::settings`] | 1 | each Save (drum stopped) | 50 ms (a flash page erase) |
//! | `idle` | 0 | — | sleeps in `wfi` |

pub mod control;
pub mod drive_link;
pub mod hall_capture;
pub mod hmi;
pub mod notices;
pub mod screen_bytes;
pub mod settings;
pub mod status;
pub mod stop_input;
