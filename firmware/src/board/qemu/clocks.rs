//! The clocks: QEMU runs on the HSI and has no clock security system.

/// Firmware time in µs (32 bits, wrapping after 71 minutes).
pub(super) fn now_us() -> u32 {
    crate::board::now_us64() as u32
}

/// Whether the clock security system saw the HSE fail: QEMU runs on the
/// HSI and has no CSS.
pub fn clock_failed() -> bool {
    false
}
